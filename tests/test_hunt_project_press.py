"""A Play/Pause press whose answer was lost never lands later as a resume.

TMflow's Play/Pause coil (7104) is a toggle, pressed by ``robot.pause()`` and
``robot.play()`` alike. A fault proxy holds the master's press (matched by function code
and address) past the request timeout: the call raises, so the master gave that press
up. The held press lands only once the move is paused (by the operator, or by the
master's own earlier ``pause()``), released on what the test did, never on a time.
Landing on the paused project, a toggle is Play: the paused move would run on. The judge
is the simulator's arm: it must stay where it was once the held press landed.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy
from fault_proxy import Rule as FaultRule
from pendant import press_play_pause
from tmmaster import (
    Motion,
    PollPolicy,
    Pose,
    RetryPolicy,
    Robot,
    RobotError,
    StopRequestedError,
    TimeoutPolicy,
    TransportError,
)
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

#: Techman's Play/Pause coil (TMflow 2.24 appendix C, p. 313).
PLAY_PAUSE = 7104
#: The master's answer timeout, s: a held press times out (0.2 s was too short for a
#: connect's reads on a loaded machine).
TIMEOUT_S = 0.4
RETRY = RetryPolicy(attempts=4, total_time_s=3.0, initial_backoff_s=0.01, jitter_s=0)


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    # Real time: the move must still run while the press times out.
    return tm_simulator_factory("tmflow", time_scale=1.0)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def robot_through(proxy: FaultProxy, request_s: float = TIMEOUT_S) -> Robot:
    """A robot (not yet connected) whose link passes the proxy."""
    return Robot(
        "127.0.0.1",
        proxy.port,
        retry=RETRY,
        timeouts=TimeoutPolicy(request_s=request_s),
        polling=PollPolicy(interval_s=0.01),
    )


def slow_move(robot: Robot, sim: Simulator) -> Motion:
    """A 150 mm move at 5 %, started and running on the robot."""
    robot.wait_until_ready(timeout_s=5)
    motion = robot.start_move(robot.pose().offset(dz=-150), speed=5)
    sim.wait_for(lambda: len(sim.motion_log()) == 1, timeout=2)
    return motion


def hold_the_next_press(proxy: FaultProxy) -> threading.Event:
    """The master's next Play/Pause press is held until the returned event is set."""
    release = threading.Event()
    proxy.add(FaultRule("hold", function_code=5, address=PLAY_PAUSE, release=release))
    return release


def assert_the_arm_stays(sim: Simulator) -> None:
    """Once the robot acted on what landed (3 ticks), the arm does not move for 10 more."""
    ticks = sim.ticks
    sim.wait_for(lambda: sim.ticks >= ticks + 3, timeout=2)
    held: Pose = sim.tcp_pose()
    ticks = sim.ticks
    sim.wait_for(lambda: sim.ticks >= ticks + 10, timeout=2)
    assert sim.tcp_pose().is_close(held, mm=1e-6, deg=1e-6), (held, sim.tcp_pose())


def assert_never_run_on(sim: Simulator, motion: Motion) -> None:
    """The late press landed; the move never ran on and is reported failed, never done
    (the master pressed Stop on the project when the press went unanswered)."""
    assert_the_arm_stays(sim)
    assert sim.motion_log()[0].done_wall_time is None
    assert len(sim.motion_log()) == 1
    with pytest.raises(RobotError):
        motion.wait()


def test_a_pause_press_given_up_never_resumes_a_move_the_operator_paused(
    sim: Simulator, proxy: FaultProxy
) -> None:
    with robot_through(proxy) as robot:
        motion = slow_move(robot, sim)
        release = hold_the_next_press(proxy)
        try:
            with pytest.raises(TransportError):
                robot.pause()  # the press is held: no answer, the call gives it up
            # The operator pauses the move on the pendant (a stopped project stays put),
            # once the robot acted on whatever the master wrote meanwhile.
            ticks = sim.ticks
            sim.wait_for(lambda: sim.ticks >= ticks + 3, timeout=2)
            if sim.field("project_running"):
                press_play_pause(sim)
                sim.wait_for(lambda: bool(sim.field("paused")), timeout=2)
        finally:
            release.set()
        proxy.wait_held()
        assert_never_run_on(sim, motion)


def test_a_play_press_given_up_never_resumes_the_paused_move(
    sim: Simulator, proxy: FaultProxy
) -> None:
    # The master's own move, paused by the master; its Play press is held.
    with robot_through(proxy) as robot:
        motion = slow_move(robot, sim)
        robot.pause()
        release = hold_the_next_press(proxy)
        try:
            with pytest.raises(TransportError):
                robot.play()  # the press is held: no answer, the call gives it up
        finally:
            release.set()  # it lands now, after the master gave it up
        proxy.wait_held()
        assert_never_run_on(sim, motion)


@pytest.mark.parametrize("ends", ["timeout", "stop_request"])
def test_a_play_press_a_gateway_answered_and_delivered_late_never_resumes_the_move(
    sim: Simulator, proxy: FaultProxy, ends: str
) -> None:
    # A store-and-forward gateway answers the Play press at once and delivers it later:
    # play() sees the project still paused until it gives up (its timeout, or a stop
    # request); the press lands after that and must not resume the move.
    with robot_through(proxy) as robot:
        motion = slow_move(robot, sim)
        robot.pause()
        release = threading.Event()
        proxy.add(
            FaultRule("hold", function_code=5, address=PLAY_PAUSE, release=release, answer_now=True)
        )
        stopper = threading.Thread(
            target=lambda: (
                sim.wait_for(lambda: proxy.played("hold"), timeout=5),
                robot.interrupt() if ends == "stop_request" else None,
            )
        )
        stopper.start()
        try:
            with pytest.raises(RobotError if ends == "timeout" else StopRequestedError):
                robot.play(timeout_s=0.5 if ends == "timeout" else 30.0)
        finally:
            stopper.join(5)
            release.set()  # the press lands now, after play() gave up
        proxy.wait_held()
        robot.clear_stop_request()
        assert_never_run_on(sim, motion)


def test_a_pause_racing_the_operators_pause_never_leaves_the_move_running(
    sim: Simulator, proxy: FaultProxy
) -> None:
    """The operator and the master press Pause at once; the master's press (answered in
    time) lands second. Whatever pause() then says, the arm must not run on."""
    with robot_through(proxy, request_s=2.0) as robot:
        slow_move(robot, sim)
        release = hold_the_next_press(proxy)

        def operator_pauses_first() -> None:
            proxy.wait_held()
            press_play_pause(sim)
            sim.wait_for(lambda: bool(sim.field("paused")), timeout=2)
            release.set()  # the master's press lands now, on the paused project

        operator = threading.Thread(target=operator_pauses_first, name="operator")
        operator.start()
        try:
            with contextlib.suppress(RobotError):
                robot.pause(timeout_s=0.5)
        finally:
            release.set()
            operator.join(5)
        assert_the_arm_stays(sim)


def test_a_pause_answered_but_never_acted_on_stops_the_project(
    sim: Simulator, proxy: FaultProxy
) -> None:
    """A gateway answers the Pause press and never delivers it: pause() times out, and
    before it raises the master has pressed Stop, so the arm does not run on."""
    with robot_through(proxy, request_s=2.0) as robot:  # every request is answered
        motion = slow_move(robot, sim)
        release = threading.Event()
        proxy.add(
            FaultRule("hold", function_code=5, address=PLAY_PAUSE, release=release, answer_now=True)
        )
        try:
            with pytest.raises(RobotError, match="Pause was pressed"):
                robot.pause(timeout_s=0.3)
            assert_the_arm_stays(sim)
            assert not sim.field("project_running")
        finally:
            release.set()  # lands on the stopped project: it starts from the beginning
        proxy.wait_held()
        assert_never_run_on(sim, motion)
