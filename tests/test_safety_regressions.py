"""One regression test per failure of issue 8, reproduced the way the issue describes it.

Each test checks what the robot actually did (the simulator's motion log, its registers),
not what the master believes. The numbers are the issue's.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

import tmmaster
from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, check
from sim_speeds import SUITE_TICK_HZ, SUITE_TIME_SCALE
from tmmaster import Checks, GripperDevice, PollPolicy, Pose, RetryPolicy, Robot, TimeoutPolicy
from tmmaster.pickplace import Runner, TaskSequence
from tmmaster.sim import RobotSetup, Simulator, Timing

SimFactory = Callable[..., Simulator]

A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(300, -200, 180, 180, 0, 90)
C = Pose(250, 0, 160, 180, 0, 90)
COMMAND_BLOCK = {"article": 0x0200, "tmflow": 9000}
REQUEST_TIMEOUT_S = 0.15
#: The suite's 40x at 100 Hz (sim_speeds.SUITE_TIME_SCALE), for the tests whose faults are the
#: simulator's own (in simulated seconds, scaled here to keep their wall-clock timing) and
#: whose operator waits count the simulator's ticks: each tick is 0.4 simulated s at both
#: speeds, so the same ticks take half the wall time.
FAST = {"time_scale": SUITE_TIME_SCALE, "timing": Timing(tick_hz=SUITE_TICK_HZ)}


@pytest.fixture
def tm_simulator_factory(tm_simulator_factory: SimFactory) -> SimFactory:
    """The plugin's own 20x and 50 Hz: these faults are timed against the wall clock."""

    def make(profile: str = "article", **options: Any) -> Simulator:
        options.setdefault("time_scale", 20.0)
        options.setdefault("timing", Timing(tick_hz=50.0))
        return tm_simulator_factory(profile, **options)

    return make


@pytest.fixture(params=["thread", "fleet"])
def robots(request: pytest.FixtureRequest) -> Iterator[Callable[..., Robot]]:
    """Open robots with short timeouts; all closed after the test.

    Twice: each robot polling its own waits, and each in a Fleet (its waits polled on
    the fleet's event loop).
    """
    opened: list[Robot] = []
    fleet = tmmaster.Fleet() if request.param == "fleet" else None

    def make(port: int, profile: str, **options: Any) -> Robot:
        options.setdefault("gripper", None)
        options.setdefault("polling", PollPolicy(interval_s=0.01))
        options.setdefault(
            "timeouts",
            TimeoutPolicy(
                request_s=REQUEST_TIMEOUT_S, ack_timeout_s=0.5, in_flight_s=0.5, motion_margin_s=1.0
            ),
        )
        options.setdefault(
            "retry",
            RetryPolicy(attempts=8, total_time_s=2.0, initial_backoff_s=0.02, max_backoff_s=0.3),
        )
        robot = Robot("127.0.0.1", port, profile=profile, link=fleet, **options)
        opened.append(robot)
        robot.connect()
        return robot

    yield make
    for robot in opened:
        robot.close()
    if fleet is not None:
        fleet.close()


def attempt(robot: Robot, target: Pose, issued: list[Issued], **kw: Any) -> str:
    """move_to, recording the command and how the call ended; returns the outcome."""
    command = Issued(target, time.monotonic())
    issued.append(command)
    try:
        robot.move_to(target, speed=kw.pop("speed", 80), **kw)
    except tmmaster.TMMasterError as exc:
        command.outcome = type(exc).__name__
    else:
        command.outcome = "done"
    command.ended_at = time.monotonic()
    return command.outcome


def let_run(sim: Simulator, ticks: int) -> None:
    """Wait until the simulator has run ``ticks`` more control ticks (0.4 simulated s each).

    Counted on the simulator's own clock, so a simulator slowed by load is never looked
    at too early; a pending command is taken at the next tick.
    """
    start = sim.ticks
    sim.wait_for(lambda: sim.ticks >= start + ticks, timeout=5.0)


def operator_resets(sim: Simulator) -> None:
    """Reset the error and press Play, then give stale commands time to run (if any).

    A pending command is taken and started within 2 ticks of the robot being able to run
    it (measured: article and tmflow, 40x and 1x): the article robot right away, a tmflow
    project once its program loops again (its heartbeat beats). Then 5 ticks (2
    simulated s), counted on the simulator's clock.
    """
    sim.clear_error()
    sim.press_play()
    if sim.profile.has("project_running"):
        sim.wait_for(lambda: bool(sim.field("project_running")), timeout=5.0)
        beat = sim.field("heartbeat")
        sim.wait_for(lambda: sim.field("heartbeat") != beat, timeout=5.0)
    let_run(sim, 5)


# -- 8.1: a late command write runs twice (article) --------------------------------------


def test_8_1_a_late_write_is_never_written_again_and_runs_once(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("article")
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy:
        # The later frame lands 0.45 s after its write: 0.55 s of the windows to spare for
        # the tick that takes it and the poll that sees it on a loaded machine.
        robot = robots(
            proxy.port,
            "article",
            timeouts=TimeoutPolicy(
                request_s=REQUEST_TIMEOUT_S, ack_timeout_s=1.0, in_flight_s=1.0, motion_margin_s=1.0
            ),
        )
        for delay_s, target in ((0.3, A), (0.45, B)):
            # Delivered after the request timeout, on the connection the master dropped.
            proxy.add(Rule("hold", function_code=16, address=0x0200, delay_s=delay_s))
            assert attempt(robot, target, issued) == "done"
            proxy.clear()
        assert attempt(robot, C, issued) == "done"
        writes = [s for s in proxy.seen if s.function_code == 16 and s.address == 0x0200]
        assert len(writes) == 3  # one write per command: nothing was written again
    let_run(sim, 5)  # 2 simulated s: a command still pending would have started by now
    check(issued, sim.motion_log())
    assert len(sim.motion_log()) == 3


def test_8_1_a_write_later_than_the_in_flight_window_is_reported_not_assumed(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    # The article contract cannot tell a lost frame from a late one: the master must not
    # claim success, must not write again, and withdraws (docs/safety.md says what remains).
    sim = tm_simulator_factory("article")
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy:
        # The write never lands, so nothing races the in-flight window: 0.25 s of it.
        robot = robots(
            proxy.port,
            "article",
            timeouts=TimeoutPolicy(
                request_s=REQUEST_TIMEOUT_S,
                ack_timeout_s=0.5,
                in_flight_s=0.25,
                motion_margin_s=1.0,
            ),
        )
        proxy.add(Rule("drop_request", function_code=16, address=0x0200))
        assert attempt(robot, A, issued) == "CommandStateUnknownError"
        assert robot.last_motion is not None
        assert robot.last_motion.withdrawn is True
        assert [s.action for s in proxy.seen if s.function_code == 16] == ["drop_request", "pass"]
    assert sim.motion_log() == ()
    assert sim.field("command") == 0


def test_8_1_tmflow_a_frame_held_for_any_time_never_runs_after_the_master_gave_up(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("tmflow")
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy:
        robot = robots(proxy.port, "tmflow")
        # Held past the timeout, the resend (same sequence number) and the withdraw:
        # released only once the master has given the command up.
        landed = threading.Event()
        proxy.add(Rule("hold", function_code=16, address=9000, release=landed))
        proxy.add(Rule("drop_request", function_code=16, address=9000, nth=1))
        attempt(robot, A, issued)  # gives up and withdraws after ~0.35 s
        landed.set()
        # The held frame lands after the master gave up. The dropped resend never reaches
        # the robot and the withdraw is written at 9014, so the first command write the
        # robot sees at 9000 is the held frame; then 5 ticks (2 simulated s) for the
        # program to take it, had its number not been used up.
        sim.wait_for(
            lambda: any(r.function_code == 16 and r.address == 9000 for r in sim.request_log),
            timeout=5.0,
        )
        let_run(sim, 5)
        assert attempt(robot, B, issued) == "done"
    check(issued, sim.motion_log())


# -- 8.2: abandoned commands stay armed ---------------------------------------------------


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_8_2_estop_before_the_acknowledgement_leaves_nothing_armed(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    # The ack would come 10 simulated s = 0.25 s wall after the write, long after the e-stop.
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=10"], **FAST)
    robot = robots(sim.port, profile)
    issued: list[Issued] = []
    threading.Timer(0.05, sim.press_estop).start()
    # The article table has no e-stop bit: the robot reports it as an error (code 0x0200).
    expected = {"article": "RobotFaultError", "tmflow": "EmergencyStopError"}[profile]
    assert attempt(robot, A, issued) == expected
    if profile == "tmflow":
        assert robot.last_motion is not None
        assert robot.last_motion.withdrawn is True  # the cancel record
    # (article: the robot discarded the pending command when it entered the error.)
    sim.clear_faults()
    operator_resets(sim)
    assert sim.motion_log() == ()


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_8_2_a_master_that_died_leaves_nothing_the_robot_runs_after_a_reset(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # The master wrote its command and vanished (no withdraw); then an e-stop, a reset
    # and Play. The robot side discards the stale command. The ack would come 10 simulated
    # s = 0.25 s wall after the write: the e-stop comes first.
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=10"], **FAST)
    with Robot("127.0.0.1", sim.port, profile=profile, gripper=None) as robot:
        robot.wait_until_ready(timeout_s=5)
        robot.start_move(A, speed=50)
        sim.press_estop()
        robot._last_motion = None  # simulate a process that died: close() withdraws nothing
    sim.clear_faults()
    operator_resets(sim)
    assert sim.motion_log() == ()


def test_8_2_a_stop_request_while_a_tmflow_command_is_pending_withdraws_it(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    # The ack would come 6 simulated s = 0.15 s wall after the write, 0.1 s after the stop.
    sim = tm_simulator_factory("tmflow", faults=["late_ack:delay_s=6"], **FAST)
    robot = robots(sim.port, "tmflow")
    issued: list[Issued] = []

    def interrupt_once_written() -> None:
        # Once the command is in the robot's registers (a stop request before the write
        # would keep it from being written at all: not this test's subject).
        sim.wait_for(lambda: int(sim.field("seq")) == 1, timeout=5)
        robot.interrupt()

    interrupter = threading.Thread(target=interrupt_once_written)
    interrupter.start()
    assert attempt(robot, A, issued) == "StopRequestedError"
    interrupter.join()
    assert robot.last_motion is not None
    assert robot.last_motion.withdrawn is True
    robot.clear_stop_request()
    let_run(sim, 20)  # 8 simulated s: the late acknowledgement would have come by now
    sim.press_estop()
    operator_resets(sim)
    assert sim.motion_log() == ()
    assert sim.field("result_code") == 5  # the program consumed the cancel


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_8_2_a_stop_during_the_runners_preparation_is_an_interruption(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # Every command acknowledged 10 simulated s = 0.25 s wall late (tmflow's gripper_open
    # too); the article gripper settles for 0.5 s: the stop at 0.1 s comes in preparation.
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=10"], **FAST)
    with Robot(
        "127.0.0.1", sim.port, profile=profile, polling=PollPolicy(interval_s=0.01)
    ) as robot:
        runner = Runner(robot)
        sequence = TaskSequence("one-move", prepare=lambda ctx: ctx.open_gripper())
        sequence.add("MOVE", lambda ctx: ctx.move(A, speed=30))
        threading.Timer(0.1, runner.request_stop).start()
        result = runner.run(sequence)
    assert result.interrupted
    sim.clear_faults()
    operator_resets(sim)
    assert [m for m in sim.motion_log() if m.target is not None] == []


# -- 8.3: a split command block moves toward stale targets --------------------------------


def test_8_3_a_profile_whose_command_block_is_split_is_refused(tmp_path: Path) -> None:
    # The example the register-maps guide used to show: target_y moved out of the block.
    split = tmp_path / "split.toml"
    split.write_text('extends = "article"\nname = "split"\n[fields.target_y]\naddress = 0x0220\n')
    with pytest.raises(tmmaster.RegisterMapError, match=r"contiguous.*target_y \(holding 544\)"):
        tmmaster.load_profile(split)


def test_8_3_a_command_code_equal_to_none_is_refused(tmp_path: Path) -> None:
    zero = tmp_path / "zero.toml"
    zero.write_text(
        'extends = "article"\nname = "zero"\n[fields.command]\n'
        'values = { 0 = "ptp", 2 = "line", 3 = "stop" }\n'
    )
    with pytest.raises(tmmaster.RegisterMapError, match="code 0 of 'ptp' collides"):
        tmmaster.load_profile(zero)


# -- 8.4: a stop request while waiting for readiness --------------------------------------


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_8_4_a_stop_request_ends_the_ready_wait_without_a_busy_loop(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # Initialising for good: start() returns without waiting for the start-up.
    sim = tm_simulator_factory(
        profile, timing=Timing(tick_hz=50.0, init_time_s=1000.0), wait_ready=False
    )
    with Robot(
        "127.0.0.1", sim.port, profile=profile, polling=PollPolicy(interval_s=0.05)
    ) as robot:
        sim.clear_request_log()
        timer = threading.Timer(0.1, robot.interrupt)  # two polls into the wait
        timer.start()
        started = time.monotonic()
        with pytest.raises(tmmaster.StopRequestedError):
            robot.wait_until_ready(timeout_s=8)
        elapsed = time.monotonic() - started
        timer.join()
        requests = len(sim.request_log)
    assert elapsed < 1.0  # honoured at once, not after the 8 s timeout
    # Paced: one status snapshot per 50 ms (1 request for article, 5 for tmflow), no spin.
    per_poll = {"article": 1, "tmflow": 5}[profile]
    assert requests <= (elapsed / 0.05 + 2) * per_poll


# -- 8.5: e-stop during a gripper action ---------------------------------------------------


def test_8_5_estop_ends_an_article_gripper_wait_and_blocks_gripper_writes(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("article")
    with Robot(
        "127.0.0.1",
        sim.port,
        profile="article",
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(gripper_settle_s=5.0),
    ) as robot:
        robot.wait_until_ready(timeout_s=5)
        threading.Timer(0.05, sim.press_estop).start()
        # The article table has no e-stop bit: the robot reports it as an error (0x0200).
        with pytest.raises(tmmaster.RobotFaultError, match="0x0200"):
            robot.gripper.open()  # would wait its 5 s settle time without the robot check
        sim.clear_request_log()
        with pytest.raises(tmmaster.RobotFaultError):
            robot.gripper.close()
    assert not [r for r in sim.request_log if r.is_write]


def test_8_5_estop_ends_an_onrobot_gripper_wait(tm_simulator_factory: SimFactory) -> None:
    sim = tm_simulator_factory("tmflow", robot=RobotSetup(gripper="onrobot-2fg7"))
    with Robot(
        "127.0.0.1",
        sim.port,
        profile="tmflow",
        gripper=GripperDevice("onrobot-2fg7", port=sim.gripper_port),
        polling=PollPolicy(interval_s=0.01),
    ) as robot:
        robot.wait_until_ready(timeout_s=5)
        sim.press_estop()
        sim.clear_request_log()
        with pytest.raises(tmmaster.EmergencyStopError):
            robot.gripper.close()
    assert not [r for r in sim.request_log if r.is_write and r.server == "gripper"]


# -- 8.6: unbounded or meaningless limits --------------------------------------------------


@pytest.mark.parametrize("bad", [math.nan, math.inf, 0, -1])
def test_8_6_meaningless_timeouts_are_refused_before_any_request(
    tm_simulator_factory: SimFactory, bad: float
) -> None:
    sim = tm_simulator_factory("article")
    with Robot("127.0.0.1", sim.port, profile="article") as robot:
        robot.wait_until_ready(timeout_s=5)
        sim.clear_request_log()
        with pytest.raises(tmmaster.ConfigError, match="timeout"):
            robot.move_to(A, speed=30, timeout=bad)
        assert sim.request_log == []


@pytest.mark.parametrize(
    ("kind", "option"),
    [
        (Checks, "position_tolerance_mm"),
        (Checks, "orientation_tolerance_deg"),
        (PollPolicy, "interval_s"),
        (TimeoutPolicy, "request_s"),
        (TimeoutPolicy, "gripper_settle_s"),
    ],
)
@pytest.mark.parametrize("bad", [math.nan, math.inf, 0, -1])
def test_8_6_meaningless_robot_options_are_refused(
    kind: type[Checks | PollPolicy | TimeoutPolicy], option: str, bad: float
) -> None:
    with pytest.raises(tmmaster.ConfigError, match=rf"{kind.argument}\.{option}"):
        Robot("127.0.0.1", 1, profile="article", **{kind.argument: kind(**{option: bad})})


# -- 8.8: outages --------------------------------------------------------------------------


def test_8_8_the_default_retry_policy_rides_out_a_one_second_outage_mid_cycle(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("article")
    issued: list[Issued] = []
    with (
        FaultProxy(sim.port) as proxy,
        Robot(
            "127.0.0.1",
            proxy.port,
            profile="article",
            gripper=None,
            polling=PollPolicy(interval_s=0.01),
        ) as robot,
    ):
        robot.wait_until_ready(timeout_s=5)
        assert attempt(robot, A, issued) == "done"
        proxy.outage(1.0)
        assert attempt(robot, B, issued) == "done"
        assert attempt(robot, C, issued) == "done"
        assert robot.stats.reconnects >= 1
    check(issued, sim.motion_log())
    assert len(sim.motion_log()) == 3


def test_8_8_a_link_loss_mid_move_stops_the_arm_once_the_link_is_back(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("article", faults=["stall:at_move=1"])
    with FaultProxy(sim.port) as proxy:
        robot = robots(
            proxy.port,
            "article",
            # The wait gives up after 0.35 s of outage; the clean-up has its own 0.35 s.
            # No jitter: 0.1 s of it could let an attempt land after the 0.5 s outage,
            # and the test is about the outage outlasting the budget.
            retry=RetryPolicy(
                attempts=20,
                total_time_s=0.35,
                initial_backoff_s=0.05,
                max_backoff_s=0.1,
                jitter_s=0,
            ),
        )
        motion = robot.start_move(A, speed=30)
        sim.wait_for(lambda: sim.field("motion_status") == 1, timeout=5)
        proxy.outage(0.5)  # longer than this robot's retry budget
        with pytest.raises(tmmaster.TransportError):
            motion.wait()
    assert motion.stop_delivered is True
    stops = [r for r in sim.request_log if r.is_write and r.values == (3,)]
    assert len(stops) == 1


# -- shutdown races: close() from another thread, a second Ctrl-C, Fleet.close() ----------


def _finish_first_move(sim: Simulator, robot: Robot, issued: list[Issued]) -> None:
    robot.wait_until_ready(timeout_s=5)
    assert attempt(robot, A, issued) == "done"


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_close_from_another_thread_never_lets_the_next_command_run(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    # The robot's thread is inside a request (it holds the link's lock) on its way to its
    # next command when close() comes from another thread. The last command close() can
    # see is the finished one; the next one must never be written, or be given up. (No
    # fault timed against the wall clock: the suite's 40x, the same ticks in half the time.)
    sim = tm_simulator_factory(profile, **FAST)
    robot = robots(sim.port, profile)
    issued: list[Issued] = []
    _finish_first_move(sim, robot, issued)
    link_lock = robot._transport._lock  # type: ignore[attr-defined]
    prepared = threading.Event()
    real_prepare = robot._channel.prepare

    def prepare_then_hold(*args: Any, **kwargs: Any) -> Any:
        ticket = real_prepare(*args, **kwargs)
        link_lock.acquire()  # a request in flight: the link is busy
        prepared.set()
        time.sleep(0.3)  # close() is called meanwhile, and blocks on the busy link
        return ticket

    def let_go() -> None:
        while link_lock._is_owned():  # type: ignore[attr-defined]
            link_lock.release()

    real_send = robot._channel.send

    def send_then_pause(ticket: Any) -> None:
        real_send(ticket)  # (never reached when close() refuses the command)
        let_go()  # the request is over: close() takes the link and closes it
        time.sleep(0.2)

    robot._channel.prepare = prepare_then_hold  # type: ignore[method-assign]
    robot._channel.send = send_then_pause  # type: ignore[method-assign]

    def next_move() -> None:
        try:
            attempt(robot, B, issued)
        finally:
            let_go()

    mover = threading.Thread(target=next_move)
    mover.start()
    assert prepared.wait(5)
    closed_at = time.monotonic()
    closer = threading.Thread(target=robot.close)
    closer.start()
    mover.join(10)
    closer.join(10)
    assert not mover.is_alive()
    assert not closer.is_alive()
    let_run(sim, 5)  # 2 simulated s: a command left armed is taken within 2 ticks
    started_after_close = [m for m in sim.motion_log() if m.wall_time > closed_at]
    assert started_after_close == [], f"{started_after_close} started after close()"
    check(issued, sim.motion_log())
    assert issued[1].outcome == "StopRequestedError"


@pytest.mark.parametrize("profile", ["article", "tmflow"])
@pytest.mark.parametrize("cut", ["withdraw", "stop"])
def test_a_second_ctrl_c_during_the_clean_up_never_leaves_a_command_armed(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str, cut: str
) -> None:
    # First Ctrl-C: a stop request ends the wait. A second one comes in the middle of the
    # withdraw (the command is pending: its ack comes late) or the stop (the arm moves).
    # The clean-up must still be delivered, and the second Ctrl-C still be raised.
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("SIGINT reaches the main thread only")
    if cut == "withdraw":
        sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=6"], **FAST)
    else:
        sim = tm_simulator_factory(profile)  # 20x: the move lasts long enough to be stopped
    robot = robots(sim.port, profile)
    robot.wait_until_ready(timeout_s=5)
    channel = robot._channel
    real = getattr(channel, cut)

    def second_ctrl_c(*args: Any, **kwargs: Any) -> Any:
        signal.raise_signal(signal.SIGINT)  # handled at the next bytecode boundary
        return real(*args, **kwargs)

    setattr(channel, cut, second_ctrl_c)
    issued = [Issued(A, time.monotonic())]
    motion = robot.start_move(A, speed=5 if cut == "stop" else 80)
    if cut == "stop":
        sim.wait_for(lambda: len(sim.motion_log()) == 1, timeout=5)  # the arm moves
    robot.interrupt()  # the first Ctrl-C
    with pytest.raises(KeyboardInterrupt):
        motion.wait()  # the second one, held back until the clean-up is done
    issued[0].outcome, issued[0].ended_at = "KeyboardInterrupt", time.monotonic()
    setattr(channel, cut, real)
    if cut == "withdraw":
        assert motion.withdrawn is True
    else:
        assert motion.stop_delivered is True
    robot.close()
    # Past the late ack (6 simulated s, 15 ticks, after the write), or past the end of a
    # move not stopped (the whole move at speed 5 takes 5.2 simulated s, 13 ticks).
    let_run(sim, 25 if cut == "withdraw" else 15)
    check(issued, sim.motion_log())
    if cut == "withdraw":
        assert sim.motion_log() == ()
    else:
        assert sim.tcp_pose().distance_to(A) > 1.0, "the arm was not stopped short of A"


_EXIT_WHILE_COMMANDING = """
import sys, threading, time
from tmmaster import PollPolicy, Pose, Robot
robot = Robot("127.0.0.1", int(sys.argv[1]), profile=sys.argv[2], gripper=None,
              polling=PollPolicy(interval_s=0.01))
robot.connect()
robot.wait_until_ready(timeout_s=5)
robot.move_to(Pose(300, -200, 150, 180, 0, 90), speed=80)
link_lock = robot._transport._lock
prepared = threading.Event()
real_prepare, real_send = robot._channel.prepare, robot._channel.send
def prepare_then_hold(*args, **kwargs):
    ticket = real_prepare(*args, **kwargs)
    link_lock.acquire()  # a request in flight when the interpreter exits
    prepared.set()
    time.sleep(0.3)
    return ticket
def send_then_pause(ticket):
    real_send(ticket)
    while link_lock._is_owned():
        link_lock.release()
    time.sleep(0.3)
robot._channel.prepare, robot._channel.send = prepare_then_hold, send_then_pause
def next_move():
    try:
        robot.move_to(Pose(300, -200, 180, 180, 0, 90), speed=80)
    finally:
        while link_lock._is_owned():
            link_lock.release()
threading.Thread(target=next_move, daemon=True).start()
prepared.wait(5)
print("exiting", flush=True)
# The script ends with the robot open: the exit hook closes it.
"""


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_interpreter_exit_while_a_thread_commands_leaves_nothing_armed(
    tm_simulator_factory: SimFactory, profile: str, tmp_path: Path
) -> None:
    sim = tm_simulator_factory(profile, **FAST)  # the suite's 40x: no fault timed in wall time
    script = tmp_path / "exit_while_commanding.py"
    script.write_text(_EXIT_WHILE_COMMANDING)
    env = dict(os.environ)
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[1] / "src")
    proc = subprocess.run(
        [sys.executable, str(script), str(sim.port), profile],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
    )
    exited = time.monotonic()
    assert proc.returncode == 0, proc.stderr
    assert "exiting" in proc.stdout
    let_run(sim, 5)  # 2 simulated s: a command left armed is taken within 2 ticks
    assert len(sim.motion_log()) >= 1
    late = [m.number for m in sim.motion_log()[1:] if m.wall_time > exited]
    assert late == [], f"motions {late} started after the interpreter exited"
    assert len(sim.motion_log()) == 1, "the second command ran"


# -- a paused TMflow project never resumes a move the master gave up on ------------------


@pytest.mark.parametrize("pause", ["estop", "pause_button"])
def test_a_move_interrupted_by_a_resumable_stop_is_stopped_for_good(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], pause: str
) -> None:
    # Resumption Behavior on: an e-stop (or the Pause button) leaves the project paused,
    # and Play would resume the interrupted move (TMflow 2.24 manual, Table 5, p. 53).
    # The master gives the move up, so it presses Stop: Play then starts the project from
    # the beginning, whose start-up rule runs nothing.
    sim = tm_simulator_factory("tmflow", robot=RobotSetup(resume_after_error=True), **FAST)
    robot = robots(sim.port, "tmflow")
    robot.wait_until_ready(timeout_s=5)
    issued = [Issued(A, time.monotonic())]
    # Speed 3: 23 ticks to go, so the press from this thread lands mid-move on a loaded
    # machine too (at speed 10, 7 ticks, it once came after the arm arrived).
    motion = robot.start_move(A, speed=3)
    sim.wait_for(lambda: len(sim.motion_log()) == 1, timeout=5)  # the arm moves
    if pause == "estop":
        sim.press_estop()
        expected: type[Exception] = tmmaster.EmergencyStopError
    else:
        sim.press_play()  # the Play/Pause button: pauses a running project
        expected = tmmaster.ProjectPausedError
    with pytest.raises(expected):
        motion.wait()
    issued[0].outcome, issued[0].ended_at = expected.__name__, time.monotonic()
    assert motion.stop_delivered is True
    let_run(sim, 5)
    assert not sim.field("project_running")  # stopped, not paused: nothing to resume
    stopped_at = sim.tcp_pose()
    operator_resets(sim)  # clear the error, press Play
    # 4 simulated s more: a move resumed at Play moves again within 2 ticks of it
    # (measured without the master's Stop), and is never seen standing still.
    let_run(sim, 10)
    check(issued, sim.motion_log())
    assert len(sim.motion_log()) == 1
    assert sim.tcp_pose().is_close(stopped_at, mm=1e-6, deg=1e-6)
    assert not sim.tcp_pose().is_close(A)
