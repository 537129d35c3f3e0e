"""StatusMonitor: many robots' statuses from one thread, read-only, failures kept per robot."""

from __future__ import annotations

import socket
import sys
import time
from collections.abc import Callable
from typing import Any

import pytest

import tmmaster
from tmmaster import (
    ConfigError,
    ConnectError,
    MonitoredStatus,
    Robot,
    RobotStatus,
    StatusMonitor,
    TransportError,
)
from tmmaster.sim import Listen, Simulator

SimFactory = Callable[..., Simulator]

#: Fast enough that a few polls take tens of milliseconds.
RATE_HZ = 100.0

MonitorFactory = Callable[..., StatusMonitor]


@pytest.fixture(params=["asyncio", "uvloop"])
def make_monitor(request: pytest.FixtureRequest) -> MonitorFactory:
    """``StatusMonitor`` on each event loop it supports (uvloop: the ``monitor`` extra)."""
    if request.param == "uvloop":
        pytest.importorskip("uvloop", reason="uvloop is the monitor extra")

    def make(**options: Any) -> StatusMonitor:
        monitor = StatusMonitor(event_loop=request.param, **options)
        assert monitor.event_loop == request.param
        return monitor

    return make


def wait_for(
    monitor: StatusMonitor,
    name: str,
    check: Callable[[MonitoredStatus], bool],
    timeout_s: float = 2.0,
) -> MonitoredStatus:
    """Wait until ``check`` holds for the robot's latest entry; return that entry."""
    deadline = time.monotonic() + timeout_s
    while True:
        seen = monitor.latest(name)
        if check(seen):
            return seen
        if time.monotonic() > deadline:
            pytest.fail(f"{name}: condition not met within {timeout_s} s; last seen {seen}")
        time.sleep(0.005)


def polled(after: int = 1) -> Callable[[MonitoredStatus], bool]:
    """A check: at least ``after`` polls answered."""
    return lambda seen: seen.polls >= after


def ready(seen: MonitoredStatus) -> bool:
    """A check: the last status says the robot can take a command."""
    return seen.status is not None and seen.status.ready


def same_status(a: RobotStatus, b: RobotStatus) -> None:
    """The fields that do not change on an idle robot are equal."""
    assert (a.mode, a.moving, a.error, a.error_code, a.estop, a.holding) == (
        b.mode,
        b.moving,
        b.error,
        b.error_code,
        b.estop,
        b.holding,
    )
    assert a.pose.is_close(b.pose, mm=0.01)
    assert set(a.raw) == set(b.raw)


def free_port() -> int:
    """A loopback port nobody listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_statuses_match_robot_status_on_both_profiles(
    tm_simulator_factory: SimFactory, make_monitor: MonitorFactory
) -> None:
    sims = {
        "a1": tm_simulator_factory("article"),
        "t1": tm_simulator_factory("tmflow"),
        "a2": tm_simulator_factory("article"),
    }
    with make_monitor(rate_hz=RATE_HZ) as monitor:
        pass  # an empty monitor starts and stops
    monitor = make_monitor(rate_hz=RATE_HZ)
    for name, sim in sims.items():
        monitor.add(name, sim.host, sim.port, profile=sim.profile.name)
    with monitor:
        for name, sim in sims.items():
            seen = wait_for(monitor, name, ready)
            with Robot(sim.host, sim.port, profile=sim.profile, gripper=None) as robot:
                expected = robot.status()
            assert seen.status is not None
            same_status(seen.status, expected)
            assert seen.error is None
            assert seen.read_at is not None
            assert seen.read_at <= time.monotonic()
            later = wait_for(monitor, name, polled(seen.polls + 2))
            assert later.read_at is not None
            assert later.read_at > seen.read_at
        snapshot = monitor.snapshot()
    assert list(snapshot) == ["a1", "t1", "a2"]
    assert all(s.failures == 0 and s.error is None for s in snapshot.values())
    assert isinstance(snapshot["t1"], MonitoredStatus)


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_an_injected_estop_shows_in_the_next_statuses(
    tm_simulator_factory: SimFactory, profile: str, make_monitor: MonitorFactory
) -> None:
    sim = tm_simulator_factory(profile)
    monitor = make_monitor(rate_hz=RATE_HZ)
    monitor.add("r", sim.host, sim.port, profile=profile)
    with monitor:
        wait_for(monitor, "r", ready)
        sim.inject("estop:after_s=0")
        seen = wait_for(monitor, "r", lambda s: s.status is not None and s.status.error)
    assert seen.status is not None
    if profile == "tmflow":
        assert seen.status.estop
        assert seen.status.mode == "estop"
    else:  # the article contract reports an e-stop as error mode with its code
        assert seen.status.error_code == 0x0200
    assert seen.error is None  # a robot fault is a status, not a link failure


def test_a_simulator_closed_mid_run_fails_alone(
    tm_simulator_factory: SimFactory, make_monitor: MonitorFactory
) -> None:
    doomed, alive = tm_simulator_factory("article"), tm_simulator_factory("tmflow")
    monitor = make_monitor(rate_hz=RATE_HZ, timeout_s=0.2)
    monitor.add("doomed", doomed.host, doomed.port, profile="article")
    monitor.add("alive", alive.host, alive.port, profile="tmflow")
    with monitor:
        wait_for(monitor, "doomed", polled())
        doomed.close()
        gone = wait_for(monitor, "doomed", lambda s: s.error is not None)
        assert isinstance(gone.error, TransportError)
        before = monitor.latest("alive").polls
        after = wait_for(monitor, "alive", polled(before + 5))
        assert after.error is None
        assert gone.status is not None  # the last good status is kept
        # Still failing (reconnects refused), and counted.
        wait_for(monitor, "doomed", lambda s: s.failures >= gone.failures + 2)
    assert isinstance(monitor.latest("doomed").error, TransportError)


def test_a_port_nobody_listens_on_is_a_connect_error(
    tm_simulator_factory: SimFactory, make_monitor: MonitorFactory
) -> None:
    sim = tm_simulator_factory("article")
    monitor = make_monitor(rate_hz=RATE_HZ, timeout_s=0.2)
    monitor.add("nobody", "127.0.0.1", free_port())
    monitor.add("somebody", sim.host, sim.port, profile="article")
    with monitor:
        seen = monitor.latest("nobody")  # start() returned after every link tried
        assert isinstance(seen.error, ConnectError)
        assert seen.status is None
        assert seen.failures >= 1
        wait_for(monitor, "somebody", polled(3))
        assert isinstance(monitor.latest("nobody").error, ConnectError)


def test_it_only_reads(tm_simulator_factory: SimFactory, make_monitor: MonitorFactory) -> None:
    sims = [tm_simulator_factory("article"), tm_simulator_factory("tmflow")]
    for sim in sims:
        sim.clear_request_log()
    monitor = make_monitor(rate_hz=RATE_HZ)
    for i, sim in enumerate(sims):
        monitor.add(f"r{i}", sim.host, sim.port, profile=sim.profile)
    with monitor:
        for i in range(len(sims)):
            wait_for(monitor, f"r{i}", polled(3))
    for sim in sims:
        log = sim.request_log
        assert log
        assert {r.function_code for r in log} <= {1, 2, 3, 4}
        assert not any(r.is_write for r in log)
        assert not any(r.refused for r in log)


def test_a_slow_robot_skips_slots_instead_of_bursting(
    tm_simulator_factory: SimFactory, make_monitor: MonitorFactory
) -> None:
    sim = tm_simulator_factory("article")
    sim.inject("slow_responses:delay_s=0.05")  # 5 periods at 100 Hz
    monitor = make_monitor(rate_hz=RATE_HZ)
    monitor.add("slow", sim.host, sim.port, profile="article")
    with monitor:
        seen = wait_for(monitor, "slow", polled(3))
    assert seen.skipped >= 3 * 3  # about 4 slots skipped per answered poll
    assert seen.failures == 0


def test_bad_arguments_name_the_field() -> None:
    with pytest.raises(ConfigError, match="rate_hz"):
        StatusMonitor(rate_hz=0)
    with pytest.raises(ConfigError, match="rate_hz"):
        StatusMonitor(rate_hz=float("nan"))
    with pytest.raises(ConfigError, match="timeout_s"):
        StatusMonitor(timeout_s=-1)
    monitor = StatusMonitor()
    monitor.add("r", "127.0.0.1", 1502)
    with pytest.raises(ConfigError, match="name 'r'"):
        monitor.add("r", "127.0.0.1", 1503)
    with pytest.raises(ConfigError, match="port"):
        monitor.add("p", "127.0.0.1", 70000)
    with pytest.raises(ConfigError, match="host"):
        monitor.add("h", "sim://somewhere")
    with pytest.raises(tmmaster.RegisterMapError, match="no-such"):
        monitor.add("q", "127.0.0.1", profile="no-such")
    with pytest.raises(ConfigError, match=r"known: 'r'"):
        monitor.latest("nobody")
    assert monitor.latest("r") == MonitoredStatus(None, None, None, 0, 0, 0)
    assert list(monitor.snapshot()) == ["r"]
    monitor.close()
    monitor.close()  # twice is fine
    with pytest.raises(ConfigError, match="closed"):
        monitor.start()


def test_the_event_loop_is_chosen_by_name(monkeypatch: pytest.MonkeyPatch) -> None:
    assert StatusMonitor(event_loop="asyncio").event_loop == "asyncio"
    with pytest.raises(ConfigError, match="event_loop"):
        StatusMonitor(event_loop="trio")  # type: ignore[arg-type]
    monkeypatch.setitem(sys.modules, "uvloop", None)  # import uvloop -> ImportError
    assert StatusMonitor().event_loop == "asyncio"  # auto: asyncio's own without uvloop
    with pytest.raises(ConfigError, match=r"tmmaster\[monitor\]"):
        StatusMonitor(event_loop="uvloop")


def test_close_twice_and_add_after_start(
    tm_simulator_factory: SimFactory, make_monitor: MonitorFactory
) -> None:
    sim = tm_simulator_factory("article")
    monitor = make_monitor(rate_hz=RATE_HZ)
    monitor.add("r", sim.host, sim.port, profile="article")
    assert monitor.start() is monitor
    assert monitor.start() is monitor  # already running: nothing more
    with pytest.raises(ConfigError, match=r"before StatusMonitor\.start"):
        monitor.add("late", sim.host, sim.port)
    wait_for(monitor, "r", polled())
    monitor.close()
    monitor.close()
    polls = monitor.latest("r").polls
    time.sleep(0.05)
    assert monitor.latest("r").polls == polls  # stopped


def test_a_refused_read_is_a_modbus_exception_error(
    tm_simulator_factory: SimFactory, make_monitor: MonitorFactory
) -> None:
    sim = tm_simulator_factory("article")
    monitor = make_monitor(rate_hz=RATE_HZ)
    monitor.add("mismatch", sim.host, sim.port, profile="tmflow")  # the wrong profile
    with monitor:
        seen = wait_for(monitor, "mismatch", lambda s: s.failures >= 3)
    assert isinstance(seen.error, tmmaster.IllegalAddressError)
    assert isinstance(seen.error, tmmaster.ModbusExceptionError)
    assert seen.error.code == 2
    assert seen.status is None
    assert seen.polls == 0


def test_a_robot_unreachable_at_start_is_picked_up_later(
    tm_simulator_factory: SimFactory, make_monitor: MonitorFactory
) -> None:
    port = free_port()
    # Refused connects back off (doubling from one period): a short cap keeps the next
    # try within a quarter second of the robot coming up.
    monitor = make_monitor(rate_hz=RATE_HZ, timeout_s=0.2, backoff_max_s=0.25)
    monitor.add("late", "127.0.0.1", port, profile="article")
    with monitor:
        assert isinstance(monitor.latest("late").error, ConnectError)
        tm_simulator_factory("article", listen=Listen(port=port))  # the robot comes up
        seen = wait_for(monitor, "late", lambda s: s.polls >= 2)
    assert seen.error is None
    assert seen.status is not None
    assert seen.failures >= 1
