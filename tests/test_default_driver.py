"""The process's default driver: every link not on a user's Fleet, on one loop.

A Robot and an AsyncRobot made without a ``link=``, and a ModbusTransport,
take the default driver (one event-loop thread for the whole process): it starts with
the first connect and ends when the last of them is closed or dropped. In-process
``sim://`` robots stay off it. The driver's loop thread is a daemon: it never keeps the
process alive after the main thread returns.
"""

from __future__ import annotations

import asyncio
import gc
import signal
import threading
import weakref
from collections.abc import Callable
from typing import Any

import pytest

from test_interrupt_ctrl_c_race import NEEDS_MAIN_THREAD_CTRL_C
from tmmaster import Fleet, ModbusTransport, Pose, Robot, _fleet, aio
from tmmaster._fleet import _DEFAULT, LoopTransport, _DefaultDriver
from tmmaster._registers import Table
from tmmaster._transport import AsyncLink
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]

A = Pose(300, -200, 150, 180, 0, 90)


def driver_threads() -> list[threading.Thread]:
    """The loop threads of drivers alive now."""
    return [t for t in threading.enumerate() if t.name == "tmmaster-fleet"]


def robot(sim: Simulator) -> Robot:
    return Robot("127.0.0.1", sim.port, profile=sim.profile, gripper=None)


def test_plain_robots_share_one_loop_thread_that_ends_with_the_last(
    tm_simulator_factory: SimFactory,
) -> None:
    first_sim, second_sim = tm_simulator_factory("article"), tm_simulator_factory("article")
    first, second = robot(first_sim), robot(second_sim)
    assert driver_threads() == []  # nothing runs before a connect
    first.connect()
    second.connect()
    threads = driver_threads()
    assert len(threads) == 1  # one loop for both
    assert threads[0].daemon  # main() returning is never held up by it
    driver = _DEFAULT.fleet
    assert driver is not None
    assert isinstance(first._transport, LoopTransport)
    assert first._transport.fleet is driver
    assert isinstance(second._transport, LoopTransport)
    assert second._transport.fleet is driver
    first.wait_until_ready(timeout_s=5)
    assert first.move_to(A, speed=50).done  # its waits polled on that loop
    first.close()
    assert driver_threads() == threads  # the second still holds it
    second.close()
    assert driver_threads() == []
    assert _DEFAULT.fleet is None


def test_an_async_robot_and_a_transport_use_the_same_driver(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("article")
    sync = robot(sim).connect()
    try:

        async def main() -> None:
            async with aio.connect(
                "127.0.0.1", sim.port, profile="article", gripper=None
            ) as opened:
                link = opened.robot._transport
                assert isinstance(link, LoopTransport)
                assert link.fleet is _DEFAULT.fleet

        asyncio.run(main())
        with ModbusTransport("127.0.0.1", sim.port) as transport:
            assert transport.read_block(Table.HOLDING, 0, 1) is not None
            assert transport.fleet is _DEFAULT.fleet
        assert len(driver_threads()) == 1
    finally:
        sync.close()
    assert driver_threads() == []


def test_a_robot_dropped_unconnected_gives_the_driver_back(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("article")
    made = robot(sim)
    assert _DEFAULT.fleet is not None
    del made
    gc.collect()
    assert _DEFAULT.fleet is None
    assert driver_threads() == []


def test_an_in_process_robot_stays_off_the_driver(
    memory_simulator_factory: SimFactory,
) -> None:
    sim = memory_simulator_factory("article")
    with Robot(sim.url, profile="article", gripper=None) as local:
        assert not isinstance(local._transport, LoopTransport)
        assert _DEFAULT.fleet is None
        assert driver_threads() == []


@NEEDS_MAIN_THREAD_CTRL_C
def test_a_ctrl_c_while_a_link_gives_the_driver_back_comes_after_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A Ctrl-C landing in a link's release (its close handed to the loop) once kept the
    driver's user for good, its finalizer spent: the loop thread ran on after the last
    link (the suite's leak check saw it after its in-process Ctrl-C tests)."""
    transport = ModbusTransport("127.0.0.1", 1)
    assert _DEFAULT.fleet is not None
    call_soon = Fleet._call_soon

    def ctrl_c_inside(fleet: Fleet, callback: Callable[..., object], *args: Any) -> bool:
        if getattr(callback, "__func__", None) is AsyncLink.close:
            signal.raise_signal(signal.SIGINT)  # lands here, before the close is handed over
        return call_soon(fleet, callback, *args)

    monkeypatch.setattr(Fleet, "_call_soon", ctrl_c_inside)
    with pytest.raises(KeyboardInterrupt):
        transport.close()
    assert _DEFAULT.fleet is None  # given back before the Ctrl-C came out
    assert driver_threads() == []


@NEEDS_MAIN_THREAD_CTRL_C
def test_a_ctrl_c_while_a_link_takes_the_driver_leaves_its_release_armed(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A Ctrl-C landing right after a link took the driver, before its release was armed:
    the half-made link is garbage, and its release still gives the driver back."""
    acquire = _DefaultDriver.acquire

    def ctrl_c_after(driver: _DefaultDriver) -> Fleet:
        fleet = acquire(driver)
        signal.raise_signal(signal.SIGINT)  # lands here: taken, no release armed yet
        return fleet

    monkeypatch.setattr(_DefaultDriver, "acquire", ctrl_c_after)
    with pytest.raises(KeyboardInterrupt):
        ModbusTransport("127.0.0.1", 1)
    gc.collect()
    assert _DEFAULT.fleet is None


def test_a_link_gives_its_share_back_to_the_driver_it_took_it_from(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """test_hunt27_event_loops gives its tests a fresh default driver; a link made
    before, collected meanwhile, gave its share back to the fresh one (refused: not its
    fleet) and the first kept it for good: its loop thread outlived every later link (the
    suite's leak check failed in whichever test next used the driver)."""
    transport = ModbusTransport("127.0.0.1", 1)
    first = _fleet._DEFAULT
    assert first.fleet is not None
    monkeypatch.setattr(_fleet, "_DEFAULT", _DefaultDriver())  # as test_hunt27 does
    del transport
    gc.collect()
    assert first.fleet is None


def _armed_releases() -> dict[object, bool]:
    """Every live LoopTransport's release finalizer: whether it runs at exit."""
    registry = weakref.finalize._registry  # type: ignore[attr-defined]
    return {
        f: info.atexit for f, info in registry.items() if isinstance(info.weakref(), LoopTransport)
    }


@NEEDS_MAIN_THREAD_CTRL_C
def test_a_ctrl_c_as_a_link_takes_the_driver_arms_no_exit_hook(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    before = set(_armed_releases())
    acquire = _DefaultDriver.acquire

    def ctrl_c_after(driver: _DefaultDriver) -> Fleet:
        fleet = acquire(driver)
        signal.raise_signal(signal.SIGINT)  # held back, delivered as the section ends
        return fleet

    monkeypatch.setattr(_DefaultDriver, "acquire", ctrl_c_after)
    with pytest.raises(KeyboardInterrupt) as caught:
        ModbusTransport("127.0.0.1", 1)
    try:
        made = {f: atexit for f, atexit in _armed_releases().items() if f not in before}
        assert len(made) == 1  # the half-made link, alive in the traceback
        assert list(made.values()) == [False], "its release would run at exit"
    finally:
        del caught
        gc.collect()
    assert _DEFAULT.fleet is None
