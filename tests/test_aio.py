"""tmmaster.aio: the Robot awaited from asyncio, checked on what the simulated robot did.

Cancelling an awaited call must give its command up exactly as a sync wait ended by an
exception does (withdrawn before the robot took it, stopped while it runs), before the
CancelledError reaches the caller, and nothing may start or resume after it: the
simulator's motion log is the judge (``safety_invariant.check``).
"""

from __future__ import annotations

import asyncio
import inspect
import signal
import threading
import time
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

import pytest

import tmmaster
from safety_invariant import Issued, check
from sim_speeds import SUITE_TICK_HZ
from tmmaster import MovePhase, PollPolicy, Pose, Robot, TimeoutPolicy, aio
from tmmaster.sim import Simulator, Timing

SimFactory = Callable[..., Simulator]
T = TypeVar("T")

A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(300, -200, 180, 180, 0, 90)
C = Pose(250, 0, 160, 180, 0, 90)
PROFILES = ["article", "tmflow"]


def slow(time_scale: float) -> dict[str, float]:
    """A simulator ``time_scale`` times real time, ticking at the suite's rate."""
    return {"time_scale": time_scale, "timing": Timing(tick_hz=SUITE_TICK_HZ)}


def open_robot(sim: Simulator, **options: Any) -> aio.AsyncRobot:
    """``aio.connect`` to ``sim`` with the suite's short poll interval."""
    options.setdefault("polling", PollPolicy(interval_s=0.01))
    options.setdefault("timeouts", TimeoutPolicy(gripper_settle_s=0.05))
    return aio.connect("127.0.0.1", sim.port, profile=sim.profile, **options)


def run(scenario: Callable[[], Coroutine[Any, Any, T]]) -> T:
    """The scenario in ``asyncio.run``, bounded (a hang fails instead of blocking the suite)."""

    async def bounded() -> T:
        async with asyncio.timeout(30):
            return await scenario()

    return asyncio.run(bounded())


async def ticks_pass(sim: Simulator, ticks: int) -> None:
    """Until the simulator ran ``ticks`` more control ticks: counted on its own clock, so
    a simulator slowed by load is never looked at too early."""
    start = sim.ticks
    await until(lambda: sim.ticks >= start + ticks)


async def settled_pose(sim: Simulator) -> Pose:
    """Where the arm is once the simulator ran two more ticks (a stop is taken at a tick)."""
    await ticks_pass(sim, 2)
    return sim.tcp_pose()


#: Control ticks that show what the robot does on its own after a move was given up: a
#: move still running goes on at every tick, and a command left armed, with no fault
#: holding it back, starts within a few (tmflow's program reads it in two or three). A
#: late_ack fault holds an armed command for its delay: those tests wait it out.
NOTHING_LATER_TICKS = 10


async def late_ack_over(sim: Simulator, motion: tmmaster.Motion | None) -> None:
    """Until a command left armed under a late_ack fault (cleared by now) would have run,
    then NOTHING_LATER_TICKS more. The article robot takes it at the next tick once the
    fault is cleared; a tmflow program already holding it waits the delay out, then
    answers its number (``ack_seq``), taken or consumed as the cancel it found."""
    assert motion is not None
    seq = motion.ticket.seq  # 0: the article contract numbers nothing
    if seq:
        await until(lambda: int(sim.field("ack_seq")) >= seq)
    await ticks_pass(sim, NOTHING_LATER_TICKS)


async def stays_stopped(sim: Simulator) -> None:
    """Once the stop was taken, the arm stays where it stopped (not resumed)."""
    stopped_at = await settled_pose(sim)
    await ticks_pass(sim, NOTHING_LATER_TICKS)
    assert sim.tcp_pose().is_close(stopped_at)


async def moving(robot: aio.AsyncRobot, sim: Simulator) -> asyncio.Task[tmmaster.Motion]:
    """``robot.move_to(A, speed=10)`` as a task, once the simulated arm has started it."""
    task = asyncio.create_task(robot.move_to(A, speed=10))
    await until(lambda: bool(sim.motion_log()))
    return task


def given_up(motion: tmmaster.Motion | None) -> bool:
    """The move was withdrawn before the robot took it, or the stop was delivered."""
    assert motion is not None
    return motion.abandoned and (motion.withdrawn is True or motion.stop_delivered is True)


async def operator_plays(sim: Simulator) -> None:
    """Press Play (tmflow: after a Stop) and let the project start (at the next tick)."""
    sim.press_play()
    await settled_pose(sim)


async def until(condition: Callable[[], bool], timeout_s: float = 5.0) -> None:
    """Poll ``condition`` on the loop (never blocking it) until it holds."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "condition not met in time"
        await asyncio.sleep(0.002)


def written(robot: aio.AsyncRobot) -> bool:
    """True once the robot's last command is in the robot's registers."""
    motion = robot.last_motion
    return motion is not None and not motion.done and motion.ticket.written


def moves(sim: Simulator) -> list[Pose | None]:
    """The targets of the motions the simulator ran (gripper actions left out)."""
    return [m.target for m in sim.motion_log() if m.target is not None]


@pytest.mark.parametrize("profile", PROFILES)
def test_moves_and_the_gripper_are_awaited_and_the_loop_keeps_running(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, **slow(10))  # a move of a few tenths of a second

    async def scenario() -> None:
        beats: list[float] = []

        async def heartbeat() -> None:
            while True:
                beats.append(time.monotonic())
                await asyncio.sleep(0.005)

        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            beating = asyncio.create_task(heartbeat())
            started = time.monotonic()
            motion = await robot.move_to(A, speed=60)
            took = time.monotonic() - started
            beating.cancel()
            assert motion.done
            assert motion.last_pose is not None
            assert motion.last_pose.is_close(A)
            # The loop ran all along (a blocked loop beats once): at least a fifth of the
            # beats a free loop would have made.
            assert len(beats) >= max(3, 0.2 * took / 0.005), (len(beats), took)
            assert (await robot.status()).ready
            assert (await robot.pose()).is_close(A)
            assert not (await robot.gripper.open()).holding
            assert not (await robot.gripper.close()).holding
            assert not await robot.gripper.holding()
            handle = await robot.start_move(B, speed=60)
            assert handle.phase in (MovePhase.SENT, MovePhase.RUNNING, MovePhase.DONE)
            finished = await handle
            assert finished.done
            assert handle.done
            # Decisions run on the robot's own thread; the waits are polled by a Fleet.
            thread = await robot.call(lambda _robot: threading.current_thread())
            assert thread is not threading.current_thread()
            assert robot.robot._shared is not None

    run(scenario)
    assert moves(sim) == [A, B]
    # (An open of open fingers is no motion for the article's register gripper.)
    assert [m.kind for m in sim.motion_log() if m.target is None][-1] == "gripper_close"


def test_digital_io_is_awaited(tm_simulator_factory: SimFactory) -> None:
    sim = tm_simulator_factory("tmflow")
    sim.set_di(2, True)

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            assert "control_box" in robot.io.modules
            await robot.io.set_do(3, True)
            assert await robot.io.do(3)
            assert (await robot.io.dos())[3]
            assert await robot.io.di(2)
            assert (await robot.io.dis())[2]
            with pytest.raises(tmmaster.ConfigError):
                await robot.io.set_do(0, True, module="end_module")  # the gripper's output
            robot.interrupt()
            with pytest.raises(tmmaster.StopRequestedError):
                await robot.io.set_do(4, True)  # refused unsent
            robot.clear_stop_request()

    run(scenario)
    assert sim.do(3)
    assert not sim.do(4)


START = Pose(300, -200, 200, 180, 0, 90)
VIA = Pose(350, -150, 200, 180, 0, 90)
END = Pose(400, -200, 200, 180, 0, 90)
JOINTS = (10.0, -5.0, 100.0, -5.0, 90.0, 10.0)


def test_joint_relative_and_arc_moves_are_awaited(tm_simulator_factory: SimFactory) -> None:
    sim = tm_simulator_factory("tmflow", **slow(10))

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            await robot.move_to(START)  # speed None: 30 %
            joints = await robot.move_joints(JOINTS, speed=60, accel_time_ms=300)
            assert joints.done
            reported = (await robot.status()).joints
            assert reported == pytest.approx(JOINTS, abs=1e-3)
            await robot.move_to(START, speed=60)
            down = await robot.move_by(dz=-30, motion="line", speed_mm_s=300)
            assert down.start is not None
            assert down.start.is_close(START)
            assert (await robot.pose()).is_close(START.offset(dz=-30))
            await robot.move_by(dz=30, frame="tool")  # the tool points down: z up is down
            assert (await robot.pose()).is_close(START.offset(dz=-60))
            await robot.move_to(START, motion="line", speed_mm_s=400)
            arc = await robot.move_arc(VIA, END, speed_mm_s=400)
            assert arc.done
            assert (await robot.pose()).is_close(END)
            handle = await robot.start_move(START, motion="line", speed_mm_s=400)
            await handle

    run(scenario)
    kinds = [m.kind for m in sim.motion_log() if m.target is not None]
    assert kinds == ["ptp", "ptp_joints", "ptp", "line", "ptp", "line", "circle", "line"]
    assert sim.tcp_pose().is_close(START)


@pytest.mark.parametrize("kind", ["joints", "arc"])
def test_cancelling_a_running_joint_move_or_arc_stops_it_and_nothing_moves_later(
    tm_simulator_factory: SimFactory, kind: str
) -> None:
    sim = tm_simulator_factory("tmflow", **slow(2))  # a move of seconds
    issued: list[Issued] = []

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            issued.append(Issued(START, time.monotonic()))
            await robot.move_to(START, speed=100)
            issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "done"
            if kind == "joints":
                target = robot.robot.model.forward(JOINTS, robot.robot.tool)
                move = robot.move_joints(JOINTS, speed=5)
            else:
                target = END
                move = robot.move_arc(VIA, END, speed=5)
            issued.append(Issued(target, time.monotonic()))
            task = asyncio.create_task(move)
            await until(lambda: len(sim.motion_log()) == 2)
            cancelled_at = time.monotonic()
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "CancelledError"
            assert time.monotonic() - cancelled_at < 1.0
            motion = robot.last_motion
            assert motion is not None
            assert motion.stop_delivered is True  # before the CancelledError came
            await stays_stopped(sim)  # stopped, not resumed
            assert not sim.tcp_pose().is_close(target)  # short of its target

    run(scenario)
    assert len(sim.motion_log()) == 2
    check(issued, sim.motion_log())


#: Methods of the sync classes whose awaited twin has a body of its own: a result of
#: another kind (connect: the AsyncRobot), a close that runs beside a running call, the
#: stop request kept apart from a cancelled call's (sync), a property made a read.
OWN_BODY = {"connect", "close", "interrupt", "clear_stop_request", "holding"}


@pytest.mark.parametrize(
    ("front", "sync"),
    [
        (aio.AsyncRobot, Robot),
        (aio.AsyncGripper, tmmaster.Gripper),
        (aio.AsyncRobotIO, tmmaster.RobotIO),
    ],
)
def test_the_awaited_methods_are_made_from_the_sync_ones(front: type, sync: type) -> None:
    """Each awaited method is the sync method of its name, derived: one signature and one
    docstring (its Args, Returns and Raises), never typed again; every move is offered."""
    offered = {
        name
        for name, member in vars(front).items()
        if not name.startswith("_") and callable(member) and callable(getattr(sync, name, None))
    }
    robot_moves = {name for name in dir(Robot) if name.startswith(("move_", "start_move"))}
    assert sync is not Robot or robot_moves <= offered
    for name in sorted(offered - OWN_BODY):
        awaited, method = getattr(front, name), getattr(sync, name)
        assert inspect.iscoroutinefunction(awaited), name
        assert inspect.unwrap(awaited) is method, name
        assert awaited.__qualname__ == f"{front.__name__}.{name}"
        made, typed = inspect.signature(awaited), inspect.signature(method)
        assert made.parameters == typed.parameters, name
        returns = "AsyncMotion" if name == "start_move" else typed.return_annotation
        assert made.return_annotation == returns, name
        doc, sync_doc = inspect.getdoc(awaited) or "", inspect.getdoc(method) or ""
        assert doc.startswith(sync_doc.split("\n")[0]), name
        for section in ("Args:", "Raises:", "Returns:"):
            if section in sync_doc and not (section == "Returns:" and name == "start_move"):
                block = sync_doc.split(section)[1].split("\n\n")[0]
                assert section + block in doc, (name, section)
        assert "```" not in doc, name  # a sync example is left out


@pytest.mark.parametrize("profile", PROFILES)
def test_cancelling_before_the_robot_took_the_command_withdraws_it(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # The acknowledgement would come 20 simulated s (0.5 s) after the write.
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=20"])
    issued: list[Issued] = []

    async def scenario() -> None:
        async with open_robot(
            sim, timeouts=TimeoutPolicy(ack_timeout_s=30, gripper_settle_s=0.05)
        ) as robot:
            await robot.wait_until_ready(timeout_s=5)
            issued.append(Issued(A, time.monotonic()))
            task = asyncio.create_task(robot.move_to(A, speed=60))
            await until(lambda: written(robot))
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "CancelledError"
            motion = robot.last_motion
            assert motion is not None
            # Settled before the CancelledError came: the robot answered the withdraw.
            assert motion.withdrawn is True
            assert motion.stop_delivered is None
            assert motion.phase is MovePhase.FAILED
            sim.clear_faults()
            await late_ack_over(sim, motion)  # a command still armed would run by now
            assert sim.motion_log() == ()

    run(scenario)
    time.sleep(0.1)
    assert sim.motion_log() == ()
    check(issued, sim.motion_log())


@pytest.mark.parametrize("profile", PROFILES)
def test_cancelling_a_running_move_stops_it_and_nothing_moves_later(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, **slow(2))  # a move of seconds
    issued: list[Issued] = []

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            issued.append(Issued(A, time.monotonic()))
            task = await moving(robot, sim)
            cancelled_at = time.monotonic()
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "CancelledError"
            took = time.monotonic() - cancelled_at
            motion = robot.last_motion
            assert motion is not None
            assert motion.stop_delivered is True  # before the CancelledError came
            assert took < 1.0, took
            await stays_stopped(sim)  # stopped, not resumed
            assert not sim.tcp_pose().is_close(A)  # short of its target (seconds away)
            # The robot takes the next command: the cancelled call's stop request is gone
            # (tmflow: the Stop button stopped the project; the operator presses Play).
            if profile == "tmflow":
                await operator_plays(sim)
            await robot.wait_until_ready(timeout_s=5)
            issued.append(Issued(B, time.monotonic()))
            await robot.move_to(B, speed=100)
            issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "done"

    run(scenario)
    assert moves(sim) == [A, B]
    check(issued, sim.motion_log())


@pytest.mark.parametrize("profile", PROFILES)
def test_asyncio_timeout_around_move_to_stops_the_move(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, **slow(2))
    issued: list[Issued] = []

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            issued.append(Issued(A, time.monotonic()))
            with pytest.raises(TimeoutError):
                async with asyncio.timeout(0.4):
                    await robot.move_to(A, speed=10)
            issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "TimeoutError"
            motion = robot.last_motion
            assert motion is not None
            assert motion.abandoned
            assert motion.stop_delivered is True
            await ticks_pass(sim, NOTHING_LATER_TICKS)

    run(scenario)
    assert moves(sim) == [A]
    assert not sim.tcp_pose().is_close(A)
    check(issued, sim.motion_log())


@pytest.mark.parametrize("profile", PROFILES)
def test_ctrl_c_in_asyncio_run_withdraws_and_closes(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        pytest.skip("asyncio.run handles Ctrl-C only where Python's own handler is installed")
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=20"])
    seen: dict[str, Any] = {}

    async def main() -> None:
        async with open_robot(
            sim, timeouts=TimeoutPolicy(ack_timeout_s=30, gripper_settle_s=0.05)
        ) as robot:
            await robot.wait_until_ready(timeout_s=5)
            seen["robot"] = robot
            # Ctrl-C while the command waits for its acknowledgement (asyncio.run's own
            # handler cancels the main task).
            asyncio.get_running_loop().call_later(0.2, signal.raise_signal, signal.SIGINT)
            await robot.move_to(A, speed=60)

    with pytest.raises(KeyboardInterrupt):
        asyncio.run(main())
    robot: aio.AsyncRobot = seen["robot"]
    assert robot.last_motion is not None
    assert robot.last_motion.withdrawn is True
    assert robot.robot.state is tmmaster.ConnectionState.CLOSED
    sim.clear_faults()
    run(lambda: late_ack_over(sim, robot.last_motion))  # a command still armed would run
    assert sim.motion_log() == ()


def test_a_cancelled_start_move_gives_its_move_up(tm_simulator_factory: SimFactory) -> None:
    """A move whose handle never reached the cancelled caller is stopped, never left running."""
    sim = tm_simulator_factory("tmflow", **slow(2))

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            sent = threading.Event()
            real_start = robot.robot.start_move

            def start_then_linger(*args: Any, **kwargs: Any) -> tmmaster.Motion:
                motion = real_start(*args, **kwargs)
                sent.set()
                time.sleep(0.2)  # the caller is cancelled meanwhile
                return motion

            robot.robot.start_move = start_then_linger  # type: ignore[method-assign]
            task = asyncio.create_task(robot.start_move(A, speed=10))
            await until(sent.is_set)
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            assert given_up(robot.last_motion), robot.last_motion
            await stays_stopped(sim)  # stopped, not resumed

    run(scenario)
    assert not sim.tcp_pose().is_close(A)


def test_a_move_sent_just_as_its_caller_is_cancelled_is_given_up(
    tm_simulator_factory: SimFactory,
) -> None:
    """The call ended (its move sent) but its result had not reached the caller yet."""
    sim = tm_simulator_factory("tmflow", **slow(2))

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            returned = threading.Event()
            real_start = robot.robot.start_move

            def start(*args: Any, **kwargs: Any) -> tmmaster.Motion:
                motion = real_start(*args, **kwargs)
                returned.set()
                return motion

            robot.robot.start_move = start  # type: ignore[method-assign]
            task = asyncio.create_task(robot.start_move(A, speed=10))
            await asyncio.sleep(0)  # the call is queued
            # Hold the loop (on purpose) until the call is over: its result waits on the
            # loop when the caller is cancelled.
            assert returned.wait(5)
            time.sleep(0.05)
            task.cancel()
            with pytest.raises(asyncio.CancelledError):
                await task
            assert given_up(robot.last_motion), robot.last_motion
            await stays_stopped(sim)  # stopped, not resumed

    run(scenario)
    assert not sim.tcp_pose().is_close(A)


@pytest.mark.parametrize("profile", PROFILES)
def test_closing_while_a_move_runs_stops_it(tm_simulator_factory: SimFactory, profile: str) -> None:
    sim = tm_simulator_factory(profile, **slow(2))

    async def scenario() -> None:
        robot = await open_robot(sim)
        await robot.wait_until_ready(timeout_s=5)
        task = await moving(robot, sim)
        assert await robot.close() is True
        with pytest.raises(tmmaster.StopRequestedError):
            await task
        motion = robot.last_motion
        assert motion is not None
        assert motion.stop_delivered is True
        with pytest.raises(tmmaster.TransportClosedError):
            await robot.status()
        assert await robot.close() is True  # twice is fine
        await stays_stopped(sim)  # stopped, not resumed

    run(scenario)
    assert moves(sim) == [A]


def test_three_robots_move_at_once_with_gather(tm_simulator_factory: SimFactory) -> None:
    sims = [tm_simulator_factory("tmflow", **slow(10)) for _ in range(3)]

    async def tour(sim: Simulator) -> tuple[float, float]:
        async with open_robot(sim, name=f"r{sim.port}") as robot:
            await robot.wait_until_ready(timeout_s=5)
            started = time.monotonic()
            for target in (A, B, C):
                await robot.move_to(target, speed=80)
            return started, time.monotonic()

    async def scenario() -> list[tuple[float, float]]:
        return await asyncio.gather(*(tour(sim) for sim in sims))

    spans = run(scenario)
    for sim in sims:
        assert moves(sim) == [A, B, C]
    # At once: every tour started before any other ended.
    assert max(start for start, _ in spans) < min(end for _, end in spans)


@pytest.mark.parametrize("profile", PROFILES)
def test_errors_keep_their_classes(tm_simulator_factory: SimFactory, profile: str) -> None:
    sim = tm_simulator_factory(profile, faults=["estop:at_move=1"])
    expected = tmmaster.RobotFaultError if profile == "article" else tmmaster.EmergencyStopError

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            with pytest.raises(tmmaster.ConfigError):
                await robot.move_to(A, speed=0)  # refused before anything is sent
            with pytest.raises(expected) as raised:
                await robot.move_to(A, speed=30)
            assert raised.value.pose is not None
            with pytest.raises(expected):
                await robot.check_fault()

    run(scenario)


def test_a_robot_that_cannot_be_reached_raises_a_connect_error() -> None:
    async def scenario() -> None:
        robot = aio.connect("127.0.0.1", 1, gripper=None)  # nothing listens on port 1
        with pytest.raises(tmmaster.ConnectError):
            await robot
        with pytest.raises(tmmaster.TransportClosedError):
            await robot.status()  # closed by the failed connect

    run(scenario)


def test_a_call_cancelled_before_it_started_never_runs(tm_simulator_factory: SimFactory) -> None:
    sim = tm_simulator_factory("tmflow", **slow(10))

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            first = asyncio.create_task(robot.move_to(A, speed=60))
            queued = asyncio.create_task(robot.move_to(B, speed=60))  # behind the first
            await asyncio.sleep(0.01)
            queued.cancel()
            with pytest.raises(asyncio.CancelledError):
                await queued
            assert (await first).done

    run(scenario)
    assert moves(sim) == [A]


def test_an_interrupt_of_the_users_stands_after_a_cancelled_call(
    tm_simulator_factory: SimFactory,
) -> None:
    # The article profile: its stop leaves the robot ready (tmflow's stops the project,
    # whose "not running" the next move's checks would report first).
    sim = tm_simulator_factory("article", **slow(2))

    async def scenario() -> None:
        async with open_robot(sim) as robot:
            await robot.wait_until_ready(timeout_s=5)
            task = await moving(robot, sim)
            robot.interrupt()
            with pytest.raises(tmmaster.StopRequestedError):
                await task
            await settled_pose(sim)  # the stop taken
            with pytest.raises(tmmaster.StopRequestedError):
                await robot.move_to(B, speed=10)  # refused, unsent, until cleared
            robot.clear_stop_request()
            await robot.wait_until_ready(timeout_s=5)
            await robot.move_to(B, speed=100)

    run(scenario)
    assert moves(sim) == [A, B]


def test_a_robot_of_your_own_fleet_or_in_process_simulator(
    tm_simulator_factory: SimFactory, memory_simulator_factory: SimFactory
) -> None:
    tcp = tm_simulator_factory("tmflow", **slow(10))
    memory = memory_simulator_factory("tmflow", **slow(10))

    async def scenario() -> None:
        with tmmaster.Fleet() as fleet:
            own = aio.AsyncRobot(
                Robot(
                    "127.0.0.1",
                    tcp.port,
                    name="own",
                    polling=PollPolicy(interval_s=0.01),
                    link=fleet,
                )
            )
            async with (
                own,
                aio.connect(memory.url, polling=PollPolicy(interval_s=0.01)) as in_process,
            ):
                assert in_process.robot._shared is None  # its thread polls its waits
                await asyncio.gather(own.move_to(A, speed=80), in_process.move_to(A, speed=80))

    run(scenario)
    assert moves(tcp) == [A]
    assert moves(memory) == [A]


def test_a_held_frame_of_an_awaited_move_never_runs_after_it_was_given_up() -> None:
    # Between the master and the robot: the move's command write is held in the network
    # until the master has given it up, and its resend dropped; the awaited move_to gives
    # up (no acknowledgement) and cancels the sequence number, so the frame that lands
    # later can never run.
    from fault_proxy import FaultProxy, Rule

    async def scenario() -> None:
        issued: list[Issued] = []
        with (
            Simulator("tmflow", time_scale=20.0, timing=Timing(tick_hz=50.0)) as sim,
            FaultProxy(sim.port) as proxy,
        ):
            async with aio.connect(
                "127.0.0.1",
                proxy.port,
                timeouts=TimeoutPolicy(request_s=0.15, ack_timeout_s=0.5, motion_margin_s=1.0),
                retry=tmmaster.RetryPolicy(attempts=8, total_time_s=2.0, initial_backoff_s=0.02),
                polling=PollPolicy(interval_s=0.01),
            ) as robot:
                first = Issued(A, time.monotonic())
                await robot.move_to(A, speed=80)
                first.outcome, first.ended_at = "done", time.monotonic()
                issued.append(first)
                release = threading.Event()
                proxy.add(Rule("hold", function_code=16, address=9000, release=release))
                proxy.add(Rule("drop_request", function_code=16, address=9000, nth=1))
                given_up = Issued(B, time.monotonic())
                issued.append(given_up)
                with pytest.raises(tmmaster.TMMasterError) as info:
                    await robot.move_to(B, speed=80)
                given_up.outcome, given_up.ended_at = type(info.value).__name__, time.monotonic()
                release.set()  # the held frame lands now, after the master gave it up

                def writes() -> int:
                    return len(
                        [r for r in sim.request_log if r.function_code == 16 and r.address == 9000]
                    )

                landed = writes()
                await asyncio.to_thread(sim.wait_for, lambda: writes() > landed, timeout=5.0)
                ticks = sim.ticks
                await asyncio.to_thread(sim.wait_for, lambda: sim.ticks >= ticks + 5, timeout=5.0)
                last = Issued(C, time.monotonic())
                await robot.move_to(C, speed=80)
                last.outcome, last.ended_at = "done", time.monotonic()
                issued.append(last)
            check(issued, sim.motion_log())
            assert [r.target for r in sim.motion_log() if r.target is not None] == [A, C]

    run(scenario)
