"""Robot.close() during a digital output's watch: nothing written after close() returns.

``set_do`` watches an output while an earlier write of the other value may still land
(``tests/test_io_stale.py``). ``close()`` from another thread while that watch runs must
end it: the call raises ``StopRequestedError`` and, once ``close()`` has returned, the
master writes that output no more (the held frame, landing then, is the documented
limit: nobody watches it). The judge is the simulator's request log.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy, Rule
from tmmaster import RetryPolicy, Robot, StopRequestedError, TimeoutPolicy
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

RETRY = RetryPolicy(attempts=4, total_time_s=3.0, initial_backoff_s=0.01, jitter_s=0)
DO = 3


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("tmflow")


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def coil_writes(sim: Simulator) -> list[bool]:
    """The values of every FC 05 write to DO 3 the simulator executed, in order."""
    return [
        bool(r.values[0])
        for r in sim.request_log
        if r.function_code == 5 and r.address == DO and r.values
    ]


def test_close_during_a_do_watch_ends_it_and_nothing_is_written_after(
    sim: Simulator, proxy: FaultProxy
) -> None:
    release = threading.Event()
    proxy.add(Rule("hold", function_code=5, address=DO, release=release))
    robot = Robot("127.0.0.1", proxy.port, retry=RETRY, timeouts=TimeoutPolicy(request_s=0.2))
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
