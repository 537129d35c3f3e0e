"""A step that starts a move and returns does not end while the move still runs.

``StepContext.robot`` is the robot: a Python step may call ``ctx.robot.start_move(...)``
(the handle API) and return without waiting. Found by hunt 20 (fails without its fix):
the runner took the step as done and went on. On ``article`` the next step opened the
gripper while the move was still pending, and the run ended DONE with the arm not yet
moving toward the target (the ``with Robot`` block's close then withdrew the move: the
run reported a cycle whose move never ran). On ``tmflow`` the gripper action was refused
("command 1 is still waiting to be acknowledged") and the run failed. The runner now
waits for a command a step left running before the step ends: the move is done (the
simulator's motion log shows it finished) before the next step begins.

A step that raised after ``start_move`` left its move to run on after the run had failed
(measured: the arm reached the target after ``Runner.run`` returned ERROR, and the
robot refused the next command as still pending). The runner now gives that command up
as an exception escaping a wait does: withdrawn if the robot has not taken it, the arm
stopped if it runs. The same holds for a sequence's ``prepare`` and a retry's
``recover``: a recover that backs the arm off with ``start_move`` and returns had the
retried pass's next move refused as still pending; it now ends with its move done.
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from tmmaster import (
    GraspFailedError,
    MovePhase,
    PollPolicy,
    Pose,
    Robot,
    RobotError,
    TimeoutPolicy,
)
from tmmaster.pickplace import RetryRule, Runner, StepContext, TaskSequence
from tmmaster.sim import Simulator, Timing

Factory = Callable[..., Simulator]
TARGET = Pose(300, -200, 250, 180, 0, 90)
HOME = Pose(250, 0, 300, 180, 0, 90)


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_move_a_step_left_running_is_done_before_the_next_step(
    tm_simulator_factory: Factory, profile: str
) -> None:
    # 10x: the move takes some 0.3 s, far longer than the step that follows takes to start.
    sim = tm_simulator_factory(profile, time_scale=10.0, timing=Timing(tick_hz=25.0))
    seen: list[list[tuple[str, bool]]] = []

    def open_when_moved(ctx: StepContext) -> None:
        seen.append([(m.kind, m.done_wall_time is not None) for m in sim.motion_log()])
        ctx.open_gripper()

    seq = TaskSequence("left-moving")
    seq.add("GO", lambda ctx: ctx.robot.start_move(TARGET, speed=10))
    seq.add("OPEN", open_when_moved)
    with Robot(
        sim.url,
        profile=profile,
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(gripper_settle_s=0.05),
    ) as robot:
        result = Runner(robot).run(seq)
        assert sim.tcp_pose().is_close(TARGET, mm=1.0)  # before the close could withdraw it

    assert result.ok, result.failure
    assert seen == [[("ptp", True)]]  # the move had finished when the gripper opened


@pytest.mark.parametrize("when", ["sent", "running"])
def test_a_step_that_raises_with_its_move_left_running_gives_the_move_up(
    tm_simulator_factory: Factory, when: str
) -> None:
    sim = tm_simulator_factory(time_scale=10.0, timing=Timing(tick_hz=25.0))

    def start_then_fail(ctx: StepContext) -> None:
        # 2 %: 1.2 s of wall time at 10x, so that the give-up comes while it runs, on a
        # loaded machine too (at 10 %, 0.26 s, 3 runs in 8 beside three CPU hogs saw it
        # finish before the Stop landed).
        motion = ctx.robot.start_move(TARGET, speed=2)
        while when == "running" and motion.progress().phase is not MovePhase.RUNNING:
            pass
        raise RobotError("the camera refused the part")

    seq = TaskSequence("raises")
    seq.add("GO", start_then_fail)
    with Robot(sim.url, polling=PollPolicy(interval_s=0.01)) as robot:
        result = Runner(robot).run(seq)
        assert result.failure is not None
        assert result.failure.message == "the camera refused the part"
        assert robot.last_motion is not None
        assert robot.last_motion.abandoned
        if when == "running":  # the report says the arm was stopped
            assert result.stop_delivered is True
        # Given up, not left owned by nobody: the next command is taken (after the Stop
        # that ended a running move, once the project plays again). A "sent" move the
        # robot took before the give-up (a loaded machine) is stopped too.
        if result.stop_delivered:
            robot.play()
        robot.wait_until_ready(5.0)
        robot.move_to(HOME, speed=30)

    # The failed step's move never finished: withdrawn unstarted, or stopped on its way.
    assert [(m.target, m.done_wall_time is None) for m in sim.motion_log()][:-1] in (
        [],
        [(TARGET, True)],
    )
    assert sim.motion_log()[-1].target == HOME


def test_a_recover_that_leaves_its_move_running_ends_with_it_done(
    tm_simulator_factory: Factory,
) -> None:
    sim = tm_simulator_factory(time_scale=10.0, timing=Timing(tick_hz=25.0))

    def grip(ctx: StepContext) -> None:
        if ctx.attempt == 1:
            raise GraspFailedError("no part the first time")

    seq = TaskSequence("recover")
    back_off = RetryRule("GRIP", 1, recover=lambda ctx: ctx.robot.start_move(TARGET, speed=10))
    seq.add("GRIP", grip, retry=back_off)
    seq.add("HOME", lambda ctx: ctx.move(HOME, speed=30))
    with Robot(sim.url, polling=PollPolicy(interval_s=0.01)) as robot:
        result = Runner(robot).run(seq)

    assert result.ok, result.failure
    assert [(m.target, m.done_wall_time is not None) for m in sim.motion_log()] == [
        (TARGET, True),
        (HOME, True),
    ]
