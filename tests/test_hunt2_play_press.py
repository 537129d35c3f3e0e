"""A Play press whose answer was lost never lands later as a resume (robot.play()).

``robot.play()`` presses the same Play/Pause toggle (7104) as ``robot.pause()``
(``tests/test_hunt_project_press.py``). The master's own move is paused; a fault proxy
holds the master's Play press (matched by function code and address) past the request
timeout, so ``play()`` raises: the master gave the press up. The held press lands only
afterwards (released on what the test did, never on a time): the paused move must never
run on, and the master must never report it done. The judge is the simulator's arm.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy
from fault_proxy import Rule as FaultRule
from tmmaster import (
    PollPolicy,
    Pose,
    RetryPolicy,
    Robot,
    RobotError,
    TimeoutPolicy,
    TransportError,
)
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

#: Techman's Play/Pause coil (TMflow 2.24 appendix C, p. 313).
PLAY_PAUSE = 7104
RETRY = RetryPolicy(attempts=4, total_time_s=3.0, initial_backoff_s=0.01, jitter_s=0)


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("tmflow", time_scale=1.0)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def test_a_play_press_given_up_never_resumes_the_paused_move(
    sim: Simulator, proxy: FaultProxy
) -> None:
    with Robot(
        "127.0.0.1",
        proxy.port,
        retry=RETRY,
        timeouts=TimeoutPolicy(request_s=0.2),
        polling=PollPolicy(interval_s=0.01),
    ) as robot:
        robot.wait_until_ready(timeout_s=5)
        motion = robot.start_move(robot.pose().offset(dz=-150), speed=5)
        sim.wait_for(lambda: len(sim.motion_log()) == 1, timeout=2)
        robot.pause()
        release = threading.Event()
        proxy.add(FaultRule("hold", function_code=5, address=PLAY_PAUSE, release=release))
        try:
            with pytest.raises(TransportError):
                robot.play()  # the press is held: no answer, the call gives it up
        finally:
            release.set()  # it lands now, after the master gave it up
        proxy.wait_held()
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 3, timeout=2)
        held: Pose = sim.tcp_pose()
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 10, timeout=2)
        assert sim.tcp_pose().is_close(held, mm=1e-6, deg=1e-6), (held, sim.tcp_pose())
        assert sim.motion_log()[0].done_wall_time is None
        assert len(sim.motion_log()) == 1
        with pytest.raises(RobotError):
            motion.wait()  # reported failed, never done
