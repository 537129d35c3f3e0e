"""The same Robot object after each kind of failure: its next commands tell the truth.

Hunt 32. Real scripts catch an error and carry on with the same ``Robot``. For each
failure (an e-stop and its reset, a robot error and its reset, a motion timeout, a stop
request then ``clear_stop_request()``, ``Motion.cancel()``, a link lost mid-move that came
back, ``close()`` then ``connect()``, a controller restart, the TMflow project stopped
and played again), on each profile where it applies, the failure hits a move toward
``FAILED`` and the same object then moves to ``NEXT``. What is judged:

- the robot ran each issued command at most once, none after its give-up, and ``NEXT``
  exactly once (``safety_invariant.check`` on the simulator's motion log);
- the next move is planned from where the simulator has the arm (``motion.start``), not
  from the failed move's target; its expected time is the one a fresh ``Robot`` plans for
  the same move from there (the same arm, the same target), so its timeout is sane;
- its wait returns only once the simulator finished the move, with the arm at ``NEXT``;
- ``last_motion``, ``progress()`` and ``status()`` tell the truth afterwards;
- the gripper's next commands run once each, in order;
- the failed move's handle still says FAILED, its wait raises, and neither sends a thing.

Also: a give-up the lost link left owed, delivered once by the next call (both
profiles); ``tmmaster.aio`` after an e-stop, a ``cancel()`` and a cancelled task; the
gripper's next commands after a gripper close stopped by an e-stop or a stop request; a
controller restart between moves; ``move_by`` after a failure (resolved where the arm
stopped). ``close()`` then ``connect()`` on the same object is refused as documented
("create a new Robot"), and a new Robot carries on.

Found here, fixed with their own deterministic tests: ``test_hunt32_stop_shows.py``
(``play()`` of a new Robot right after ``close()`` stopped the arm returned RUNNING on a
project about to stop) and ``test_hunt32_reset_while_braking.py`` (the article
simulator reported moving forever after a reset that came while the arm braked).
"""

from __future__ import annotations

import asyncio
import math
import threading
from collections.abc import Callable
from contextlib import ExitStack
from typing import Any

import pytest

from fault_proxy import FaultProxy
from safety_invariant import Issued, at_rest, check
from sim_speeds import QUICK
from test_controller_restart import restart_controller
from tmmaster import (
    CommandStateUnknownError,
    ConnectError,
    PollPolicy,
    Pose,
    ProjectState,
    RetryPolicy,
    Robot,
    StopRequestedError,
    TimeoutPolicy,
    TMMasterError,
    aio,
)
from tmmaster._status import MovePhase
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]

START = Pose(220, -200, 200, 180, 0, 90)
#: The failed move's target: a long PTP from START, so the faults hit it mid-way.
FAILED = Pose(220, 200, 250, 180, 0, 90)
NEXT = Pose(300, 0, 180, 180, 0, 90)
#: The article's gripper has no busy flag: its settle time at 100x real time.
#: The failed move stops halfway and stays busy, so a cancel or an interrupt sent once it
#: started finds it running however late a loaded machine runs the test's thread (at 100x
#: the whole move takes some 30 ms: under load it could end first).
STILL_MOVING = "stall:at_move=1"
TIMEOUTS = TimeoutPolicy(motion_margin_s=0.5, ack_timeout_s=2.0, gripper_settle_s=0.05)


def started(sim: Simulator, count: int) -> None:
    """Wait until the robot started its ``count``-th motion (the failed one runs)."""
    sim.wait_for(lambda: len([m for m in sim.motion_log() if m.target]) >= count, timeout=5.0)


def recover(robot: Robot, sim: Simulator) -> None:
    """What a script does after the failure: reset on the pendant, Play, the arm at rest."""
    sim.clear_error()
    if sim.profile.name == "tmflow":
        robot.play()  # waits for the master's own Stop to show first (robot-api.md)
        assert robot.project_state() is ProjectState.RUNNING
    robot.wait_until_at_rest()


def fail_estop(robot: Robot, sim: Simulator, issued: list[Issued]) -> None:
    sim.inject("estop:at_move=1")
    # article reports an e-stop as its error code only (docs/robot-api.md).
    expected = "EmergencyStopError" if sim.profile.name == "tmflow" else "RobotFaultError"
    attempt_failing(robot, issued, expected)


def fail_robot_error(robot: Robot, sim: Simulator, issued: list[Issued]) -> None:
    sim.inject("robot_error:at_move=1,code=0x22")
    attempt_failing(robot, issued, "RobotFaultError")


def fail_timeout(robot: Robot, sim: Simulator, issued: list[Issued]) -> None:
    sim.inject("stall:at_move=1")
    attempt_failing(robot, issued, "MotionTimeoutError", timeout=0.5)


def fail_interrupt(robot: Robot, sim: Simulator, issued: list[Issued]) -> None:
    sim.inject(STILL_MOVING)
    before = len([m for m in sim.motion_log() if m.target])

    def interrupt() -> None:
        started(sim, before + 1)
        robot.interrupt()

    helper = threading.Thread(target=interrupt)
    helper.start()
    attempt_failing(robot, issued, "StopRequestedError")
    helper.join()
    robot.clear_stop_request()


def fail_cancel(robot: Robot, sim: Simulator, issued: list[Issued]) -> None:
    sim.inject(STILL_MOVING)
    before = len([m for m in sim.motion_log() if m.target])
    issued.append(Issued(FAILED, 0.0))
    motion = robot.start_move(FAILED, speed=20)
    started(sim, before + 1)
    assert motion.cancel()
    issued[-1].outcome = "cancelled"
    assert motion.abandoned
    assert not motion.done


def fail_link(robot: Robot, sim: Simulator, issued: list[Issued]) -> None:
    """The link drops mid-move and comes back: the wait carries on (not a failure)."""
    before = len([m for m in sim.motion_log() if m.target])
    issued.append(Issued(FAILED, 0.0))
    motion = robot.start_move(FAILED, speed=20)
    started(sim, before + 1)
    sim.drop_connections()
    motion.wait()
    issued[-1].outcome = "done"


def fail_close(robot: Robot, sim: Simulator, issued: list[Issued]) -> None:
    """``close()`` mid-move (the arm stopped), then ``connect()`` again: refused, as
    documented (a closed Robot is not reused); nothing is sent."""
    sim.inject(STILL_MOVING)
    before = len([m for m in sim.motion_log() if m.target])
    issued.append(Issued(FAILED, 0.0))
    robot.start_move(FAILED, speed=20)
    started(sim, before + 1)
    assert robot.close()
    issued[-1].outcome = "closed"
    sent = len(sim.request_log)
    with pytest.raises(ConnectError, match="create a new Robot"):
        robot.connect()
    assert len(sim.request_log) == sent


def fail_restart(robot: Robot, sim: Simulator, issued: list[Issued]) -> None:
    """The controller restarts mid-move (tmflow)."""
    before = len([m for m in sim.motion_log() if m.target])
    issued.append(Issued(FAILED, 0.0))
    motion = robot.start_move(FAILED, speed=20)
    started(sim, before + 1)
    restart_controller(sim)
    with pytest.raises(TMMasterError) as failed:
        motion.wait()
    issued[-1].outcome = type(failed.value).__name__


def fail_project_stop(robot: Robot, sim: Simulator, issued: list[Issued]) -> None:
    """The operator stops the TMflow project mid-move (tmflow)."""
    before = len([m for m in sim.motion_log() if m.target])
    issued.append(Issued(FAILED, 0.0))
    motion = robot.start_move(FAILED, speed=20)
    started(sim, before + 1)
    sim.call(lambda: sim._controller.bank.set("stop_project", True))
    with pytest.raises(TMMasterError) as failed:
        motion.wait()
    issued[-1].outcome = type(failed.value).__name__


def attempt_failing(
    robot: Robot, issued: list[Issued], expected: str, timeout: float | None = None
) -> None:
    command = Issued(FAILED, 0.0)
    issued.append(command)
    with pytest.raises(TMMasterError) as failed:
        robot.move_to(FAILED, speed=20, timeout=timeout)
    command.outcome = type(failed.value).__name__
    assert command.outcome == expected, repr(failed.value)


FAILURES: dict[str, Callable[[Robot, Simulator, list[Issued]], None]] = {
    "estop": fail_estop,
    "robot_error": fail_robot_error,
    "timeout": fail_timeout,
    "interrupt": fail_interrupt,
    "cancel": fail_cancel,
    "link": fail_link,
    "close": fail_close,
    "restart": fail_restart,
    "project_stop": fail_project_stop,
}
TMFLOW_ONLY = ("restart", "project_stop")
CASES = [
    pytest.param(profile, kind, id=f"{profile}-{kind}")
    for kind in FAILURES
    for profile in ("article", "tmflow")
    if profile == "tmflow" or kind not in TMFLOW_ONLY
]


def open_robot(sim: Simulator, *, ready: bool = True, **options: Any) -> Robot:
    options.setdefault("polling", PollPolicy(interval_s=0.01))
    options.setdefault("timeouts", TIMEOUTS)
    robot = Robot(sim.url, profile=sim.profile, **options)
    robot.connect()
    if ready:
        robot.wait_until_ready(timeout_s=5)
    return robot


def next_move_tells_the_truth(robot: Robot, sim: Simulator, issued: list[Issued]) -> None:
    here = sim.tcp_pose()
    issued.append(Issued(NEXT, 0.0))
    motion = robot.start_move(NEXT, speed=30)
    assert robot.last_motion is motion
    assert motion.target is not None
    assert motion.target.is_close(NEXT, mm=1e-6, deg=1e-6)
    # Planned from where the arm is, not from the failed move's target.
    assert motion.start is not None
    assert motion.start.is_close(here, mm=1.0, deg=0.5), (motion.start, here)
    first = motion.progress()
    assert first.phase in (MovePhase.SENT, MovePhase.RUNNING, MovePhase.DONE)
    assert first.expected_s == motion.expected_s > 0
    motion.wait()
    issued[-1].outcome = "done"
    # No false success: the robot itself reported the move finished, at NEXT.
    record = [m for m in sim.motion_log() if m.target is not None][-1]
    assert record.target is not None
    assert record.target.is_close(NEXT, mm=0.05)
    assert record.done_wall_time is not None
    assert sim.tcp_pose().is_close(NEXT, mm=0.05, deg=0.05)
    # Its budget covers its expected time (planned from ``here``, checked above; the wall
    # time the simulator took is not compared: no timed assertion).
    assert motion.timeout_s >= motion.expected_s
    assert motion.done
    assert not motion.abandoned
    assert motion.progress().phase is MovePhase.DONE
    status = robot.status()
    assert not status.moving
    assert not status.error
    assert status.pose.is_close(NEXT, mm=0.1)
    check(issued, sim.motion_log())
    # The gripper's next commands run once each, in order.
    if robot.gripper is not None:
        grips = len(sim.motion_log())
        robot.gripper.close()
        robot.gripper.open()
        kinds = [m.kind for m in sim.motion_log()[grips:]]
        assert kinds == ["gripper_close", "gripper_open"], kinds


@pytest.mark.parametrize(("profile", "kind"), CASES)
def test_the_next_move_after_a_failure(
    tm_simulator_factory: SimFactory, profile: str, kind: str
) -> None:
    sim = tm_simulator_factory(profile, **QUICK)
    issued: list[Issued] = []
    with ExitStack() as stack:
        robot = stack.enter_context(open_robot(sim))
        robot.move_to(START, speed=50)
        issued.append(Issued(START, 0.0, 0.0, "done"))
        FAILURES[kind](robot, sim, issued)
        failed = robot.last_motion
        assert failed is not None
        assert failed.target is not None
        assert failed.target.is_close(FAILED, mm=1e-6, deg=1e-6)
        if kind == "close":  # the same object cannot connect again: a new one carries on
            robot = stack.enter_context(open_robot(sim, ready=False))
        recover(robot, sim)
        # The failed move's handle still tells the truth, and sends nothing.
        sent = len(sim.request_log)
        if kind == "link":  # carried on: it finished
            assert failed.done
        else:
            assert failed.abandoned
            assert not failed.done
            assert failed.progress().phase is MovePhase.FAILED
            with pytest.raises(StopRequestedError):
                failed.wait()
            assert len(sim.request_log) == sent
        check(issued, sim.motion_log())
        next_move_tells_the_truth(robot, sim, issued)


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_the_next_move_after_an_owed_give_up_is_delivered(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    """The link goes down while the arm moves: the wait gives up, its Stop (tmflow: and
    the cancel record) cannot go out, and is owed. Calls while the link is down raise
    ``CommandStateUnknownError``; the link back, the next call delivers it once, and the
    same Robot's next move is planned from where the arm stopped, not from FAILED."""
    sim = tm_simulator_factory(profile, time_scale=10.0)
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy:
        robot = Robot(
            "127.0.0.1",
            proxy.port,
            profile=profile,
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(request_s=0.2, ack_timeout_s=2.0, heartbeat_ttl_s=5.0),
            retry=RetryPolicy(attempts=2, total_time_s=0.15, initial_backoff_s=0.02),
        )
        with robot:
            robot.wait_until_ready(timeout_s=5)
            robot.move_to(START, speed=100)
            issued.append(Issued(START, 0.0, 0.0, "done"))
            issued.append(Issued(FAILED, 0.0))
            motion = robot.start_move(FAILED, speed=2)  # seconds away
            sim.wait_for(lambda: sim.tcp_pose().y > START.y + 10, timeout=10.0)
            proxy.outage(math.inf)  # until the test says it is back
            with pytest.raises(TMMasterError) as failed:
                motion.wait()
            issued[-1].outcome = type(failed.value).__name__
            with pytest.raises(CommandStateUnknownError):
                robot.status()  # still down: nothing else sent, still owed
            proxy._refusing_until = 0.0  # the link is back
            robot.status()  # delivers the give-up first
            assert motion.stop_delivered is True
            sim.wait_for(at_rest(sim), timeout=10.0)
            stopped = sim.tcp_pose()
            assert stopped.distance_to(FAILED) > 50, f"the given-up move ran on to {stopped}"
            stops = len(sim.request_log)
            recover(robot, sim)
            next_move_tells_the_truth(robot, sim, issued)
            # Delivered once: nothing owed is sent again by the next calls.
            assert not any(
                r.function_code == 5 and r.address == 7105 for r in sim.request_log[stops:]
            )
    check(issued, sim.motion_log())


async def _async_case(sim: Simulator, kind: str, issued: list[Issued]) -> None:
    async with aio.connect(
        sim.url, profile=sim.profile, polling=PollPolicy(interval_s=0.01)
    ) as robot:
        await robot.wait_until_ready(timeout_s=5)
        await robot.move_to(START, speed=50)
        issued.append(Issued(START, 0.0, 0.0, "done"))
        issued.append(Issued(FAILED, 0.0))
        if kind == "estop":
            sim.inject("estop:at_move=1")
            with pytest.raises(TMMasterError):
                await robot.move_to(FAILED, speed=20)
        elif kind == "cancel":
            sim.inject(STILL_MOVING)
            motion = await robot.start_move(FAILED, speed=20)
            started(sim, 2)
            assert await motion.cancel()
        elif kind == "interrupt":  # then refused until clear_stop_request(), unsent
            sim.inject(STILL_MOVING)
            task = asyncio.ensure_future(robot.move_to(FAILED, speed=20))
            while len([m for m in sim.motion_log() if m.target]) < 2:
                await asyncio.sleep(0.005)
            robot.interrupt()
            with pytest.raises(StopRequestedError):
                await task
            sent = len(sim.request_log)
            with pytest.raises(StopRequestedError):
                await robot.move_to(NEXT, speed=30)
            assert not [r for r in sim.request_log[sent:] if r.function_code in (5, 15, 16)]
            robot.clear_stop_request()
        else:  # a task cancelled mid-move (asyncio.timeout's way)
            task = asyncio.ensure_future(robot.move_to(FAILED, speed=20))
            while len([m for m in sim.motion_log() if m.target]) < 2:
                await asyncio.sleep(0.005)
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
        issued[-1].outcome = kind
        sim.clear_error()
        if sim.profile.name == "tmflow":
            await robot.play()
        await robot.wait_until_at_rest()
        here = sim.tcp_pose()
        issued.append(Issued(NEXT, 0.0))
        motion = await robot.start_move(NEXT, speed=30)
        assert robot.last_motion is motion.motion
        progress = await motion.progress()
        assert progress.expected_s == motion.motion.expected_s > 0
        start = motion.motion.start
        assert start is not None
        assert start.is_close(here, mm=1.0, deg=0.5), (start, here)
        await motion.wait()
        issued[-1].outcome = "done"
        record = [m for m in sim.motion_log() if m.target is not None][-1]
        assert record.done_wall_time is not None
        assert sim.tcp_pose().is_close(NEXT, mm=0.05, deg=0.05)
        status = await robot.status()
        assert not status.moving
        assert status.pose.is_close(NEXT, mm=0.1)
        if robot.gripper is not None:
            grips = len(sim.motion_log())
            await robot.gripper.close()
            await robot.gripper.open()
            kinds = [m.kind for m in sim.motion_log()[grips:]]
            assert kinds == ["gripper_close", "gripper_open"], kinds


@pytest.mark.parametrize(
    ("profile", "kind"),
    [
        *(("tmflow", "estop"), ("article", "cancel"), ("tmflow", "cancel")),
        *(("tmflow", "task"), ("article", "interrupt")),
    ],
)
def test_the_next_awaited_move_after_a_failure(
    tm_simulator_factory: SimFactory, profile: str, kind: str
) -> None:
    sim = tm_simulator_factory(profile, **QUICK)
    issued: list[Issued] = []
    asyncio.run(_async_case(sim, kind, issued))
    check(issued, sim.motion_log())


@pytest.mark.parametrize(
    ("profile", "kind"), [("article", "interrupt"), ("tmflow", "estop"), ("tmflow", "interrupt")]
)
def test_the_next_gripper_commands_after_a_gripper_failure(
    tm_simulator_factory: SimFactory, profile: str, kind: str
) -> None:
    """A gripper close ends in an e-stop or a stop request while the jaws move: the
    same Robot's next gripper commands run once each, in order, and say the truth."""
    sim = tm_simulator_factory(profile, **QUICK)
    issued: list[Issued] = []
    with open_robot(sim) as robot:
        assert robot.gripper is not None
        robot.move_to(START, speed=50)
        issued.append(Issued(START, 0.0, 0.0, "done"))
        robot.gripper.open()
        before = len(sim.motion_log())

        def fault() -> None:
            sim.wait_for(lambda: len(sim.motion_log()) > before, timeout=5.0)
            if kind == "estop":
                sim.press_estop()
            else:
                robot.interrupt()

        helper = threading.Thread(target=fault)
        helper.start()
        try:
            with pytest.raises(TMMasterError):
                robot.gripper.close()
        finally:
            helper.join()
        if kind == "interrupt":
            robot.clear_stop_request()
        assert [m.kind for m in sim.motion_log()[before:]] == ["gripper_close"]
        recover(robot, sim)
        grips = len(sim.motion_log())
        robot.gripper.open()
        assert not robot.gripper.holding
        robot.gripper.close()
        robot.gripper.open()
        kinds = [m.kind for m in sim.motion_log()[grips:]]
        assert kinds == ["gripper_open", "gripper_close", "gripper_open"], kinds
        next_move_tells_the_truth(robot, sim, issued)
    check(issued, sim.motion_log())


@pytest.mark.parametrize("where", ["idle", "after a failed move"])
def test_the_next_move_after_an_idle_controller_restart(
    tm_simulator_factory: SimFactory, where: str
) -> None:
    """tmflow: the controller restarts between two moves (registers at 0, the program
    afresh): the same Robot's next move runs once, to NEXT, from where the arm is."""
    sim = tm_simulator_factory("tmflow", **QUICK)
    issued: list[Issued] = []
    with open_robot(sim) as robot:
        robot.move_to(START, speed=50)
        issued.append(Issued(START, 0.0, 0.0, "done"))
        if where != "idle":
            fail_robot_error(robot, sim, issued)
            recover(robot, sim)
        restart_controller(sim)
        sim.wait_for(lambda: sim.field("master_session") != 0, timeout=2.0)
        next_move_tells_the_truth(robot, sim, issued)
    check(issued, sim.motion_log())


#: Each failure on each profile, the Line and the PTP taking turns.
RELATIVE = [
    ("article", "estop", "line"),
    ("tmflow", "estop", "ptp"),
    ("article", "timeout", "ptp"),
    ("tmflow", "timeout", "line"),
    ("article", "cancel", "line"),
    ("tmflow", "cancel", "ptp"),
]


@pytest.mark.parametrize(("profile", "kind", "motion"), RELATIVE)
def test_the_next_relative_move_starts_where_the_arm_stopped(
    tm_simulator_factory: SimFactory, profile: str, kind: str, motion: str
) -> None:
    """``move_by`` after a failure: resolved against where the arm stopped, not against
    the failed move's target; a Line from there runs straight, once."""
    sim = tm_simulator_factory(profile, **QUICK)
    issued: list[Issued] = []
    with open_robot(sim) as robot:
        robot.move_to(START, speed=50)
        issued.append(Issued(START, 0.0, 0.0, "done"))
        FAILURES[kind](robot, sim, issued)
        recover(robot, sim)
        here = sim.tcp_pose()
        target = here.offset(dz=-30)
        issued.append(Issued(target, 0.0))
        done = robot.move_by(dz=-30, speed=30, motion=motion)
        issued[-1].outcome = "done"
        assert done.target is not None
        assert done.target.is_close(target, mm=0.5, deg=0.5), (done.target, target)
        assert sim.tcp_pose().is_close(target, mm=0.5, deg=0.5)
    check(issued, sim.motion_log())
