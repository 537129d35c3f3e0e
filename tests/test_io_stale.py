"""A digital output never ends at an older value than the latest one asked for.

A fault proxy holds the first FC 05 to control box DO 3 (matched by function code and
address) and delivers it late, after the master timed out, reconnected and retried it,
and after a later write asked for the other value. The judge is the simulator's own
coil and its request log, and the master's read-back.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from fault_proxy import FaultProxy, Rule
from tmmaster import (
    ResponseTimeoutError,
    RetryPolicy,
    Robot,
    StopRequestedError,
    TimeoutPolicy,
    aio,
)
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

#: The master's answer timeout, s: the held frame times out, the retry goes through.
TIMEOUT_S = 0.2
#: The retry policy's total time is also how long the master watches for a late frame
#: (a bound these tests never wait for: the late frame lands well before it).
RETRY = RetryPolicy(attempts=4, total_time_s=3.0, initial_backoff_s=0.01, jitter_s=0)
DO = 3


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("tmflow")


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def coil_writes(sim: Simulator, address: int = DO) -> list[bool]:
    """The values of every FC 05 write to ``address`` the simulator executed, in order."""
    return [
        bool(r.values[0])
        for r in sim.request_log
        if r.function_code == 5 and r.address == address and r.values
    ]


def coil_reads(sim: Simulator, address: int = DO) -> int:
    return sum(1 for r in sim.request_log if r.function_code == 1 and r.address == address)


def wrote_false(sim: Simulator) -> Callable[[], bool]:
    return lambda: False in coil_writes(sim)


@contextlib.contextmanager
def held_until(proxy: FaultProxy, condition: Callable[[], bool]) -> Iterator[Rule]:
    """Hold the first FC 05 to DO 3 until ``condition`` holds (at the latest, the block's
    end), then let it land: after the master gave it up, retried, and wrote again."""
    release, done = threading.Event(), threading.Event()
    rule = proxy.add(Rule("hold", function_code=5, address=DO, release=release))

    def watch() -> None:
        while not condition() and not done.wait(0.005):
            pass
        release.set()

    thread = threading.Thread(target=watch, name="release-held-frame")
    thread.start()
    try:
        yield rule
    finally:
        done.set()
        thread.join(5)


def landed(sim: Simulator, proxy: FaultProxy) -> None:
    """Wait until the held frame reached the simulator (True written twice: retry + late)."""
    proxy.wait_held()
    sim.wait_for(lambda: coil_writes(sim).count(True) >= 2, timeout=3)


def test_a_late_write_lands_and_the_output_still_ends_at_the_latest_value(
    sim: Simulator, proxy: FaultProxy
) -> None:
    with Robot(
        "127.0.0.1", proxy.port, retry=RETRY, timeouts=TimeoutPolicy(request_s=TIMEOUT_S)
    ) as robot:
        sim.clear_request_log()
        with held_until(proxy, wrote_false(sim)) as held:
            robot.io.set_do(DO, True)  # times out, reconnects, retries: True
            assert held.times == 0  # the hold fired on that write
            robot.io.set_do(DO, False)
            landed(sim, proxy)
        # The late True reached the robot after the False; the master undid it.
        writes = coil_writes(sim)
        assert writes[:3] == [True, False, True], writes
        assert writes[-1] is False
        assert sim.do(DO) is False
        assert robot.io.do(DO) is False


def test_a_write_that_failed_is_still_watched_for(sim: Simulator, proxy: FaultProxy) -> None:
    """No retry: the first write raises, its frame still on its way; the next one wins."""
    with Robot(
        "127.0.0.1",
        proxy.port,
        retry=RetryPolicy(attempts=1),
        # No request is retried either: each gets a loaded machine's margin (0.2 s, then
        # 0.5 s, failed once each: the write after the held one went unanswered).
        timeouts=TimeoutPolicy(request_s=1.0),
    ) as robot:
        sim.clear_request_log()
        with held_until(proxy, wrote_false(sim)):
            with pytest.raises(ResponseTimeoutError):
                robot.io.set_do(DO, True)
            robot.io.set_do(DO, False)
            proxy.wait_held()
            sim.wait_for(lambda: True in coil_writes(sim), timeout=3)
        assert coil_writes(sim)[:2] == [False, True]
        assert coil_writes(sim)[-1] is False
        assert sim.do(DO) is False
        assert robot.io.do(DO) is False


def test_a_write_in_doubt_that_never_lands_is_watched_for_a_bounded_time(
    sim: Simulator, proxy: FaultProxy
) -> None:
    """The first write is lost for good: the next write of the other value reads the coil
    back until the retry policy's total time since the lost write has passed, then returns.
    Once nothing is in doubt any more, a write is one FC 05 again and reads nothing."""
    retry = RetryPolicy(attempts=4, total_time_s=0.6, initial_backoff_s=0.01, jitter_s=0)
    with Robot(
        "127.0.0.1", proxy.port, retry=retry, timeouts=TimeoutPolicy(request_s=TIMEOUT_S)
    ) as robot:
        sim.clear_request_log()
        proxy.add(Rule("drop_request", function_code=5, address=DO))
        robot.io.set_do(DO, True)
        robot.io.set_do(DO, False)
        assert coil_writes(sim) == [True, False]  # nothing to undo
        assert coil_reads(sim) >= 1  # but the coil was read back
        assert sim.do(DO) is False
        sim.clear_request_log()
        robot.io.set_do(DO, True)
        robot.io.set_do(DO, False)
        assert coil_writes(sim) == [True, False]
        assert coil_reads(sim) == 0


def test_a_stop_request_ends_the_watch_and_says_so(sim: Simulator, proxy: FaultProxy) -> None:
    """While a late frame may still land, a stop request ends the watch: no write follows
    a stop, so set_do raises StopRequestedError saying the output may still change."""
    with Robot(
        "127.0.0.1", proxy.port, retry=RETRY, timeouts=TimeoutPolicy(request_s=TIMEOUT_S)
    ) as robot:
        sim.clear_request_log()
        with held_until(proxy, lambda: False):  # lands once the block is over
            robot.io.set_do(DO, True)
            # Interrupt once set_do(False) has written its value and is watching.
            stopper = threading.Thread(
                target=lambda: (sim.wait_for(wrote_false(sim), timeout=3), robot.interrupt())
            )
            stopper.start()
            try:
                with pytest.raises(StopRequestedError, match="could still land"):
                    robot.io.set_do(DO, False)
            finally:
                stopper.join(5)
        proxy.wait_held()
        robot.clear_stop_request()


def test_a_stop_request_ends_a_wait_behind_another_robots_watch(
    sim: Simulator, proxy: FaultProxy
) -> None:
    """Two Robots of one process share an output's watch (docs/safety.md): the second's
    set_do waits while the first watches for its late frame, and a stop request ends
    that wait at once, nothing written, not once the first's watch is over."""
    # A loaded machine's margins, neither the subject: each connect's first read is not
    # retried (TIMEOUT_S is short for it beside CPU hogs), and the first Robot's watch
    # must outlast the steps below, while its bound (the retry's total time since the
    # held write) runs on the clock. The held frame lands at the block's end all the same.
    options: dict[str, Any] = dict(
        retry=RetryPolicy(attempts=4, total_time_s=10.0, initial_backoff_s=0.01, jitter_s=0),
        timeouts=TimeoutPolicy(request_s=1.0),
    )
    with (
        Robot("127.0.0.1", proxy.port, **options) as first,
        Robot("127.0.0.1", proxy.port, **options) as second,
    ):
        sim.clear_request_log()
        with held_until(proxy, lambda: False):  # lands once the block is over
            first.io.set_do(DO, True)
            watch = threading.Thread(target=first.io.set_do, args=(DO, False))
            watch.start()  # writes False, then watches for the held True
            sim.wait_for(wrote_false(sim), timeout=3)
            refused: list[BaseException] = []

            def second_sets() -> None:
                try:
                    second.io.set_do(DO, True)
                except StopRequestedError as exc:
                    refused.append(exc)

            waiting = threading.Thread(target=second_sets)
            waiting.start()
            second.interrupt()
            waiting.join(5)
            assert refused, "the second Robot's set_do did not end on its stop request"
            assert watch.is_alive()  # it did not wait for the first Robot's watch
        watch.join(10)
        proxy.wait_held()
    assert coil_writes(sim) == [True, False, True, False]  # nothing of the second's


def test_a_late_frame_outlasting_an_interrupted_watch_is_undone_by_the_next_write(
    sim: Simulator, proxy: FaultProxy
) -> None:
    """Once the stop request is taken back, the next ``set_do`` of the same value still
    knows the interrupted watch's frame is out there: the first True, held through the
    interrupted watch, lands only after that next write, and the output ends at the
    value last asked for."""
    with Robot(
        "127.0.0.1", proxy.port, retry=RETRY, timeouts=TimeoutPolicy(request_s=TIMEOUT_S)
    ) as robot:
        sim.clear_request_log()

        def false_twice() -> bool:  # the interrupted call's and the next call's
            return coil_writes(sim).count(False) >= 2

        with held_until(proxy, false_twice):
            robot.io.set_do(DO, True)  # held: timed out, retried, answered

            def stop_once_watching() -> None:
                sim.wait_for(wrote_false(sim), timeout=3)  # False written: it watches now
                robot.interrupt()

            stopper = threading.Thread(target=stop_once_watching)
            stopper.start()
            try:
                with pytest.raises(StopRequestedError, match="could still land"):
                    robot.io.set_do(DO, False)
            finally:
                stopper.join(5)
            robot.clear_stop_request()
            robot.io.set_do(DO, False)  # the held True lands during this call's watch
            proxy.wait_held()
        writes = coil_writes(sim)
        assert writes[:4] == [True, False, False, True], writes  # the late True landed
        assert writes[-1] is False
        assert sim.do(DO) is False
        assert robot.io.do(DO) is False


def test_close_during_a_do_watch_ends_it_and_nothing_is_written_after(
    sim: Simulator, proxy: FaultProxy
) -> None:
    # close() from another thread ends the watch; once it returned, the master writes
    # that output no more (the held frame, landing then, is the documented limit).
    release = threading.Event()
    proxy.add(Rule("hold", function_code=5, address=DO, release=release))
    robot = Robot("127.0.0.1", proxy.port, retry=RETRY, timeouts=TimeoutPolicy(request_s=TIMEOUT_S))
    errors: list[BaseException] = []
    try:
        robot.connect()
        robot.io.set_do(DO, True)  # held: timed out, retried, answered

        def set_low() -> None:
            try:
                robot.io.set_do(DO, False)
            except StopRequestedError as exc:
                errors.append(exc)

        thread = threading.Thread(target=set_low)
        thread.start()
        sim.wait_for(lambda: False in coil_writes(sim), timeout=3)  # the watch runs now
        robot.close()
        thread.join(5)
        after_close = len(coil_writes(sim))
        release.set()  # the held True lands, unwatched
        proxy.wait_held()
        sim.wait_for(lambda: len(coil_writes(sim)) > after_close, timeout=2)
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 5, timeout=2)
    finally:
        release.set()
        robot.close()
    assert len(errors) == 1  # the watch was ended, and set_do said so
    assert coil_writes(sim)[after_close:] == [True]  # the late frame only


def test_the_async_front_goes_through_the_same_guard(sim: Simulator, proxy: FaultProxy) -> None:
    """``AsyncRobotIO.set_do`` runs ``RobotIO.set_do`` on the robot's thread: same ending."""

    async def scenario() -> bool:
        async with aio.connect(
            "127.0.0.1", proxy.port, retry=RETRY, timeouts=TimeoutPolicy(request_s=TIMEOUT_S)
        ) as robot:
            sim.clear_request_log()
            with held_until(proxy, wrote_false(sim)):
                await robot.io.set_do(DO, True)
                await robot.io.set_do(DO, False)
                await asyncio.to_thread(landed, sim, proxy)
            return await robot.io.do(DO)

    async def bounded() -> bool:
        async with asyncio.timeout(20):
            return await scenario()

    assert asyncio.run(bounded()) is False
    assert coil_writes(sim)[:3] == [True, False, True]
    assert coil_writes(sim)[-1] is False
    assert sim.do(DO) is False
