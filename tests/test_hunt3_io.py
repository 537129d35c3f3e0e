"""A DO watch ended by a stop request is taken up again by the next write of that output.

A stop request ends ``set_do``'s watch for a late frame at once (nothing is written
after a stop), saying an earlier write could still land (docs/safety.md, "Digital
outputs"). Once the request is taken back, the next ``set_do`` of the same value must
still know that frame is out there: a proxy holds the first FC 05 of True to control
box DO 3 through the interrupted watch and lets it land only after that next write.
The output must end at the value last asked for. The judge is the simulator's coil and
its request log.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy
from test_io_stale import DO, RETRY, TIMEOUT_S, coil_writes, held_until, wrote_false
from tmmaster import Robot, StopRequestedError, TimeoutPolicy
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("tmflow")


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def test_a_late_frame_outlasting_an_interrupted_watch_is_undone_by_the_next_write(
    sim: Simulator, proxy: FaultProxy
) -> None:
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
