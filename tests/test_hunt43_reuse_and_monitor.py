"""Hunt 43: a Runner run again after a failed run, and status watches over links that go.

1. ``Runner.run`` twice on one Robot, the first run failed (robot error cleared, e-stop
   released, link cut and back, grasp retries exhausted, ``robot.interrupt()`` taken back):
   the second run never resumes or repeats the first run's moves (the simulator's motion
   log), checks its plan from where the arm is now, and its result says only its own.
2. ``StatusMonitor`` and ``Fleet(watch_hz=...)`` over robots whose links close or come
   back: ``latest()`` never shows a status as current once the link is gone, never
   raises an untyped exception, writes nothing, and leaves no thread or socket (conftest).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

import tmmaster.pickplace._runner as runner_module
from sim_speeds import QUICK
from tmmaster import (
    ConnectionLostError,
    Fleet,
    PollPolicy,
    Pose,
    RetryPolicy,
    Robot,
    StatusMonitor,
    TMMasterError,
)
from tmmaster.pickplace import DONE, ERROR, IDLE, Runner, TaskSequence, validate_config
from tmmaster.pickplace import pick_and_place as article_cycle
from tmmaster.sim import Cell, Simulator

SimFactory = Callable[..., Simulator]

A = Pose(300, -200, 200, 180, 0, 90)
B = Pose(300, -100, 200, 180, 0, 90)
C = Pose(350, -100, 250, 180, 0, 90)
D = Pose(250, 0, 300, 180, 0, 90)
PROFILES = ["article", "tmflow"]
WRITES = (5, 6, 15, 16)


def moves(*poses: Pose) -> TaskSequence:
    seq = TaskSequence("moves")
    for i, pose in enumerate(poses):
        seq.add(f"M{i}", lambda ctx, p=pose: ctx.move(p, speed=30))
    return seq


def targets(sim: Simulator, since: int = 0) -> list[Pose]:
    return [m.target for m in sim.motion_log()[since:] if m.target is not None]


def until(predicate: Callable[[], bool], timeout: float = 3.0) -> None:
    """Wait for a state the background reads reach by themselves (not a synchronisation
    of the test's own actions)."""
    end = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < end, "condition not reached in time"
        time.sleep(0.005)


@pytest.fixture
def robot_on(tm_simulator_factory: SimFactory) -> Iterator[Callable[..., tuple[Simulator, Robot]]]:
    opened: list[Robot] = []

    def make(
        profile: str, *, tcp: bool = False, gripper: bool = True, **options: Any
    ) -> tuple[Simulator, Robot]:
        sim = tm_simulator_factory(profile, listen=tcp, **QUICK, **options)
        where = ("127.0.0.1", sim.port) if tcp else (sim.url,)
        robot = Robot(
            *where,
            profile=profile,
            **({} if gripper else {"gripper": None}),
            polling=PollPolicy(interval_s=0.01),
            retry=RetryPolicy(attempts=3, total_time_s=1.0, initial_backoff_s=0.02),
        )
        opened.append(robot)
        robot.connect().wait_until_ready(5.0)
        return sim, robot

    yield make
    for robot in opened:
        robot.close()


def assert_second_run_is_its_own(
    sim: Simulator, runner: Runner, first_moves: int, once: tuple[Pose, ...] = (A, B, C)
) -> None:
    """Run [D] again: only D moves, and the result speaks of this run alone."""
    second = runner.run(moves(D))
    assert targets(sim, first_moves) == [D], "the second run moved something not its own"
    assert second.state == DONE, second.failure
    assert (second.failure, second.stop_delivered, second.reaction) == (None, None, None)
    assert second.cycles_completed == 1
    assert second.retries == 0
    assert [(r.state, r.cycle, r.outcome) for r in second.records] == [
        (IDLE, 0, "ok"),
        ("M0", 1, "ok"),
    ]
    first_run = targets(sim)[:first_moves]
    assert all(first_run.count(p) <= 1 for p in once), "a move of the first run ran twice"


# -- 1. a Runner run again ------------------------------------------------------------


@pytest.mark.parametrize("profile", PROFILES)
@pytest.mark.parametrize("fault", ["robot_error:at_move=2,code=0x22", "estop:at_move=2"])
def test_a_run_after_a_cleared_fault_runs_only_its_own_moves(
    robot_on: Callable[..., tuple[Simulator, Robot]], profile: str, fault: str
) -> None:
    sim, robot = robot_on(profile, gripper=False)
    runner = Runner(robot, error_reaction="retreat", ready_timeout_s=3.0)
    sim.inject(fault)
    first = runner.run(moves(A, B, C))
    assert first.state == ERROR
    assert first.failure is not None
    assert first.failure.state == "M1"
    assert not first.reaction.performed
    n = len(sim.motion_log())
    sim.clear_error()
    if profile == "tmflow":
        robot.play()  # a robot error or e-stop stops the TMflow project
    assert_second_run_is_its_own(sim, runner, n)


@pytest.mark.parametrize("profile", PROFILES)
def test_a_run_after_a_cut_link_runs_only_its_own_moves(
    robot_on: Callable[..., tuple[Simulator, Robot]], profile: str
) -> None:
    sim, robot = robot_on(profile, tcp=True, gripper=False)
    runner = Runner(robot, ready_timeout_s=3.0)

    def cut(event: Any) -> None:
        if event.state == "M1":
            sim.inject("drop_connections:after_requests=1,once=false")

    runner.on_state = cut
    first = runner.run(moves(A, B, C))
    # Given up in M1 or M2, or done when a retried request got through: a move given up
    # never runs, later ones are never sent.
    if first.failure is not None:
        gave_up = {"M1": B, "M2": C}[first.failure.state]
        assert gave_up not in targets(sim)
        assert C not in targets(sim)
    runner.on_state = None
    sim.clear_faults()
    n = len(sim.motion_log())
    assert_second_run_is_its_own(sim, runner, n)


def test_a_run_after_exhausted_grasp_retries_counts_only_its_own(
    robot_on: Callable[..., tuple[Simulator, Robot]],
) -> None:
    sim, robot = robot_on("tmflow", cell=Cell(scene=[]))
    config = validate_config(
        {
            "gripper": {"settle_s": 0.05},
            "run": {"poll_interval_s": 0.02},
            "timeouts": {"ack_s": 0.5, "motion_margin_s": 0.5},
        }
    )
    runner = Runner.from_config(robot, config)
    first = runner.run(article_cycle(config))
    assert first.failure is not None
    assert first.failure.type == "GraspFailedError"
    assert first.retries == 2
    assert_second_run_is_its_own(sim, runner, len(sim.motion_log()), once=())


def test_a_run_after_a_robot_stop_request_taken_back_runs_only_its_own(
    robot_on: Callable[..., tuple[Simulator, Robot]],
) -> None:
    sim, robot = robot_on("article", gripper=False)
    runner = Runner(robot, ready_timeout_s=3.0)
    runner.on_state = lambda event: robot.interrupt() if event.state == "M1" else None
    first = runner.run(moves(A, B, C))
    assert first.interrupted
    assert first.stop_delivered is True
    runner.on_state = None
    robot.clear_stop_request()
    ticks = sim.ticks  # the article robot takes the first run's stop at its next tick
    sim.wait_for(lambda: sim.ticks >= ticks + 3, 5.0)
    assert_second_run_is_its_own(sim, runner, len(sim.motion_log()))


def test_the_second_runs_plan_is_checked_from_where_the_arm_is_now(
    robot_on: Callable[..., tuple[Simulator, Robot]], monkeypatch: pytest.MonkeyPatch
) -> None:
    sim, robot = robot_on("tmflow", gripper=False)
    runner = Runner(robot, ready_timeout_s=3.0)
    sim.inject("robot_error:at_move=2,code=0x22")
    runner.run(moves(A, B, C))
    sim.clear_error()
    robot.play()
    starts: list[Any] = []
    real = runner_module.validate_plan

    def spy(*args: Any, **kwargs: Any) -> None:
        starts.append(kwargs["start"])
        real(*args, **kwargs)

    monkeypatch.setattr(runner_module, "validate_plan", spy)
    here = robot.pose()  # stopped by the error on its way from A to B
    assert here.distance_to(A) > 1
    assert here.distance_to(B) > 1
    runner.run(moves(D))
    assert len(starts) == 1
    assert starts[0] is not None
    assert starts[0][0].distance_to(here) < 0.5


# -- 2. watches over links that go ----------------------------------------------------


@pytest.mark.parametrize("profile", PROFILES)
def test_a_fleet_watch_says_a_lost_link_as_a_monitor_does(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # docs/robot-api.md: fleet.latest(robot) "returns the same MonitoredStatus as
    # StatusMonitor.latest", whose robot with a link down records a ConnectionLostError.
    sim = tm_simulator_factory(profile, **QUICK)
    with Fleet(watch_hz=50) as fleet:
        robot = Robot("127.0.0.1", sim.port, profile=profile, gripper=None, link=fleet)
        try:
            robot.connect().wait_until_ready(5.0)
            until(lambda: fleet.latest(robot).polls >= 2)
            sim.drop_connections()
            until(lambda: fleet.latest(robot).error is not None, 1.0)
            seen = fleet.latest(robot)
            assert isinstance(seen.error, ConnectionLostError)
            read_at = seen.read_at
            robot.status()  # the robot's own request reconnects
            until(lambda: fleet.latest(robot).error is None)
            assert (fleet.latest(robot).read_at or 0) > (read_at or 0)
        finally:
            robot.close()
        assert fleet.latest(robot).polls >= 2  # a closed robot: still answered, typed
    assert not [r for r in sim.request_log if r.function_code in WRITES]


@pytest.mark.parametrize("profile", PROFILES)
def test_a_monitor_over_a_robots_link_never_shows_a_lost_link_as_current(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, **QUICK)
    robot = Robot("127.0.0.1", sim.port, profile=profile, gripper=None).connect()
    monitor = StatusMonitor(rate_hz=50)
    monitor.add_robot(robot, "r")
    try:
        with monitor:
            until(lambda: monitor.latest("r").polls >= 2)
            sim.drop_connections()
            until(lambda: monitor.latest("r").error is not None)
            lost = monitor.latest("r")
            assert isinstance(lost.error, ConnectionLostError)
            assert lost.read_at is not None
            assert lost.read_at < time.monotonic()
            reconnected = time.monotonic()
            robot.status()
            until(lambda: monitor.latest("r").error is None)
            assert (monitor.latest("r").read_at or 0) > reconnected
            robot.close()
            until(lambda: monitor.latest("r").error is not None)
            assert isinstance(monitor.latest("r").error, ConnectionLostError)
    finally:
        robot.close()
    assert not [r for r in sim.request_log if r.function_code in WRITES]


@pytest.mark.parametrize("closing", ["fleet", "monitor"])
def test_a_watch_closed_during_a_slow_read_leaves_nothing_and_raises_nothing_untyped(
    tm_simulator_factory: SimFactory, closing: str
) -> None:
    sim = tm_simulator_factory("tmflow", **QUICK)
    if closing == "fleet":
        fleet = Fleet(watch_hz=50).start()
        robot = Robot("127.0.0.1", sim.port, gripper=None, link=fleet)
        try:
            robot.connect().wait_until_ready(5.0)
            until(lambda: fleet.latest(robot).polls >= 1)
            sim.inject("slow_responses:delay_s=0.2")
            asked = len(sim.request_log)
            until(lambda: len(sim.request_log) > asked)  # the watch reads every 20 ms
            fleet.close()
            seen = fleet.latest(robot)
        finally:
            robot.close()
    else:
        monitor = StatusMonitor(rate_hz=50, timeout_s=1.0)
        monitor.add("own", "127.0.0.1", sim.port)
        monitor.start()
        until(lambda: monitor.latest("own").polls >= 1)
        sim.inject("slow_responses:delay_s=0.2")
        asked = len(sim.request_log)
        until(lambda: len(sim.request_log) > asked)
        monitor.close()
        seen = monitor.latest("own")
    assert seen.error is None or isinstance(seen.error, TMMasterError)
    assert not [r for r in sim.request_log if r.function_code in WRITES]
