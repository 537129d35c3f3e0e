"""The robot API against the simulator: handshakes, validation, faults, connection loss."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from typing import Any

import pytest

import tmmaster
from tmmaster import Checks, MovePhase, PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster._channels import Command, CommandKind
from tmmaster.sim import MemoryTransport, RobotSetup, Simulator

SimFactory = Callable[..., Simulator]


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: SimFactory) -> SimFactory:
    """The robot API is the subject here, not TCP: simulators in memory."""
    return memory_simulator_factory


APPROACH = Pose(300, -200, 200, 180, 0, 90)
PICK = Pose(300, -200, 100, 180, 0, 90)
COMMAND_BLOCK = {"article": 0x0200, "tmflow": 9000}


def command_writes(sim: Simulator) -> list[tuple[int, ...]]:
    """Values of every write that reached the command block."""
    start = COMMAND_BLOCK[sim.profile.name]
    return [
        tuple(r.values or ())
        for r in sim.request_log
        if r.function_code == 16 and r.address == start and not r.refused
    ]


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_the_readme_script_runs_on_both_profiles(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile)
    with tmmaster.connect(sim.url, profile=profile) as robot:
        robot.wait_until_ready(timeout_s=5)
        assert robot.status().ready
        robot.move_to(APPROACH, speed=30)
        robot.move_to(PICK, speed=10, motion="line")
        assert robot.gripper.close().holding
        pose = robot.status().pose
    assert pose.is_close(PICK, mm=0.01)
    assert sim.tcp_pose().is_close(PICK, mm=0.01)
    (part,) = sim.objects()
    assert part.held
    assert len(command_writes(sim)) == 2  # the two motion blocks; no resend


# tmflow: DI 7201-7205 and 7207-7208 are two reads (7206 is only a coil in TMflow 2.24
# appendix C: a real robot may refuse a discrete-input read across it).
@pytest.mark.parametrize(("profile", "expected_requests"), [("article", 1), ("tmflow", 6)])
def test_status_reads_each_block_in_one_request(
    tm_simulator_factory: SimFactory,
    robots: Callable[..., Robot],
    profile: str,
    expected_requests: int,
) -> None:
    sim = tm_simulator_factory(profile)
    robot = robots(sim)
    sim.clear_request_log()
    status = robot.status()
    assert len(sim.request_log) == expected_requests
    assert status.pose.is_close(sim.tcp_pose(), mm=0.01)
    assert status.mode in ("auto", "running")
    with pytest.raises(AttributeError):
        status.moving = True  # type: ignore[misc]


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_moves_command_block_is_encoded_once(
    tm_simulator_factory: SimFactory,
    robots: Callable[..., Robot],
    profile: str,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import tmmaster._transport as transport_module

    sim = tm_simulator_factory(profile)
    robot = robots(sim)
    encoded: list[str] = []
    real = transport_module.encoder

    def counting(f: Any) -> Any:
        encoded.append(f.name)
        return real(f)

    robot.move_to(APPROACH, speed=30)  # the first command (tmflow: checked, then claims)
    monkeypatch.setattr(transport_module, "encoder", counting)
    sim.clear_request_log()
    robot.move_to(PICK, speed=30)  # a command not given before
    # The whole block (tmflow: with the extension, zero for a PTP, and the session).
    block = [f.name for f in robot.profile.command_block()]
    assert sorted(encoded) == sorted(block)  # each field once: checked, then written as is
    assert len(command_writes(sim)) == 1


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_command_given_again_is_written_alike_and_refused_alike(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    # A repeated command's block comes from its first encoding: the same words (the
    # tmflow number and session aside), and a refused one is refused every time.
    sim = tm_simulator_factory(profile)
    robot = robots(sim)
    for target in (APPROACH, PICK, APPROACH, PICK):
        robot.move_to(target, speed=30)
    writes = command_writes(sim)
    assert len(writes) == 4
    fixed = 8 if profile == "article" else 15  # the words before tmflow's number (9015)
    assert writes[0][:fixed] == writes[2][:fixed] != writes[1][:fixed]
    assert writes[1][:fixed] == writes[3][:fixed]
    for _ in range(2):
        with pytest.raises(tmmaster.ValueOutOfRangeError):
            robot._channel.check_command(Command(CommandKind.PTP, APPROACH, 70000))
    assert len(command_writes(sim)) == 4


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_move_is_one_write_of_the_whole_command_block(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile)
    robot = robots(sim)
    sim.clear_request_log()
    robot.move_to(APPROACH, speed=30)
    # The heartbeat's writes (tmflow, 9050) are not the move's.
    writes = [r for r in sim.request_log if r.values is not None and r.address != 9050]
    assert len(writes) == 1
    assert writes[0].count == (8 if profile == "article" else 32)


def test_out_of_range_pose_sends_nothing(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("article", robot=RobotSetup(model="tm5-900"))
    robot = robots(sim, model="tm5-900")
    sim.clear_request_log()
    with pytest.raises(tmmaster.ValueOutOfRangeError, match=r"target_x: value 400"):
        robot.move_to(Pose(400, 0, 300, 180, 0, 0), speed=30)
    assert sim.request_log == []


@pytest.mark.parametrize(
    ("target", "speed", "message"),
    [
        (Pose(300, 0, 300, 180, 0, 0), 0, "speed 0 %"),
        (Pose(300, 0, 300, 180, 0, 0), 101, "speed 101 %"),
        (Pose(700, 300, 300, 180, 0, 0), 30, "out of reach"),
        (Pose(300, 0, -50, 180, 0, 0), 30, "z = -50 mm is outside the workspace"),
    ],
)
def test_invalid_moves_are_refused_before_any_request(
    tm_simulator_factory: SimFactory,
    robots: Callable[..., Robot],
    target: Pose,
    speed: int,
    message: str,
) -> None:
    sim = tm_simulator_factory("tmflow")
    robot = robots(sim, checks=Checks(workspace=tmmaster.Workspace(z=(0, 800))))
    sim.clear_request_log()
    with pytest.raises(tmmaster.ConfigError, match=message):
        robot.move_to(target, speed=speed)
    assert sim.request_log == []


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_late_acknowledgement_is_waited_for(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    # 12 simulated s = 0.3 wall s (the suite's 40x) before the robot picks the command up: far past
    # the master's first polls (~40 ms), so returning early shows. The check leaves 0.1 s
    # for a simulator that lagged and catches up (up to 10 ticks at once).
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=12"])
    robot = robots(sim)
    started = time.monotonic()
    motion = robot.move_to(APPROACH, speed=30)
    assert time.monotonic() - started >= 0.2
    # Returned only once the robot really arrived, not when "idle" was first read.
    assert sim.tcp_pose().is_close(APPROACH, mm=0.01)
    assert motion.done
    assert len(command_writes(sim)) == 1


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_unacknowledged_command_times_out_and_is_withdrawn(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    # The ack would come 14 simulated s = 0.35 wall s after the robot sees the command:
    # 0.2 s after the master's 0.15 s ack timeout, room for a master slowed by load.
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=14"])
    robot = robots(sim, timeouts=TimeoutPolicy(ack_timeout_s=0.15))
    home = sim.tcp_pose()
    ticks = sim.ticks
    with pytest.raises(tmmaster.AcknowledgeTimeoutError, match="did not acknowledge"):
        robot.move_to(APPROACH, speed=30)
    motion = robot.last_motion
    assert motion is not None
    # Withdrawn: at once (article), or once the program answered the cancel (tmflow,
    # late too); if it had not answered by then, the project would have been stopped.
    assert motion.withdrawn is True or motion.stop_delivered is True
    # The command must not run later behind the script's back: look once the simulator
    # has run 22 simulated s (55 ticks of 0.4 s) since the write, 8 s past the late ack,
    # on its own clock, so a simulator slowed by load is not looked at too early.
    sim.wait_for(lambda: sim.ticks >= ticks + 55, 5.0)
    assert sim.tcp_pose() == home
    assert not robot.status().moving


@pytest.mark.parametrize(
    ("profile", "error"),
    [("article", tmmaster.RobotFaultError), ("tmflow", tmmaster.RobotFaultError)],
)
def test_robot_error_mid_motion_ends_the_wait_at_once(
    tm_simulator_factory: SimFactory,
    robots: Callable[..., Robot],
    profile: str,
    error: type[Exception],
) -> None:
    sim = tm_simulator_factory(profile, faults=["robot_error:at_move=1,code=0x1F4"])
    robot = robots(sim)
    started = time.monotonic()
    with pytest.raises(error) as info:
        robot.move_to(APPROACH, speed=30, timeout=30)
    assert time.monotonic() - started < 2  # not the 30 s timeout
    assert isinstance(info.value, tmmaster.RobotError)
    assert info.value.error_code == 0x1F4
    assert info.value.pose is not None


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_emergency_stop_during_a_move(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile, faults=["estop:at_move=1"])
    robot = robots(sim)
    with pytest.raises(tmmaster.RobotError) as info:
        robot.move_to(APPROACH, speed=30, timeout=30)
    if profile == "tmflow":
        assert isinstance(info.value, tmmaster.EmergencyStopError)
    else:  # the article contract reports an e-stop as error mode with its code
        assert isinstance(info.value, tmmaster.RobotFaultError)
        assert info.value.error_code == 0x0200
    # A robot in that state refuses the next move before anything is written.
    before = len(command_writes(sim))
    with pytest.raises(tmmaster.RobotError):
        robot.move_to(PICK, speed=10)
    assert len(command_writes(sim)) == before


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_stalled_motion_times_out_with_the_last_pose_and_is_stopped(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile, faults=["stall:at_move=1"])
    robot = robots(sim)
    with pytest.raises(tmmaster.MotionTimeoutError) as info:
        robot.move_to(APPROACH, speed=30, timeout=0.3)  # the stall comes after ~13 ms
    assert isinstance(info.value, TimeoutError)
    assert info.value.pose is not None
    assert not info.value.pose.is_close(APPROACH)
    writes = [
        (r.address, r.values)
        for r in sim.request_log
        if r.values is not None and r.function_code in (5, 15, 16)
    ]
    if profile == "article":
        assert writes[-1] == (0x0207, (3,))
    else:
        # The Stop, then the command's cancel record (command none, its number), which the
        # program acts on where the robot refuses the Stop.
        assert writes[-2] == (7105, (1,))
        assert writes[-1] == (9014, (0, 1))


def test_derived_timeout_follows_the_articles_rule(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("article")
    robot = robots(sim)
    start = robot.pose()
    motion = robot.start_move(APPROACH, speed=30)
    expected = robot.model.motion_time(
        start, APPROACH, speed_percent=30, motion=tmmaster.MotionType.PTP
    )
    assert motion.expected_s == pytest.approx(expected)
    assert motion.timeout_s == pytest.approx(expected * 1.3 + 2.0)
    motion.wait()
    fixed = robots(tm_simulator_factory("article"), timeouts=TimeoutPolicy(motion_timeout_s=7))
    assert fixed.start_move(APPROACH, speed=30).timeout_s == 7
    assert robot.start_move(PICK, speed=10, timeout=3).timeout_s == 3


def test_line_and_ptp_expectations_differ() -> None:
    model = tmmaster.robot_model("tm5-700")
    ptp = model.motion_time(APPROACH, PICK, speed_percent=10, motion=tmmaster.MotionType.PTP)
    line = model.motion_time(APPROACH, PICK, speed_percent=10, motion=tmmaster.MotionType.LINE)
    assert ptp != pytest.approx(line)
    assert TimeoutPolicy().for_motion(10) == pytest.approx(15)


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_non_blocking_move_reports_progress(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    # The move takes ~0.25 s wall at 4x: about ten looks at its progress, 25 ms apart.
    sim = tm_simulator_factory(profile, time_scale=4)
    robot = robots(sim)
    motion = robot.start_move(APPROACH, speed=30)
    assert motion.phase is MovePhase.SENT
    fractions = []
    while not motion.done:
        progress = motion.progress()
        if progress.fraction is not None:
            fractions.append(progress.fraction)
        time.sleep(0.025)
    assert motion.progress().phase is MovePhase.DONE
    assert fractions == sorted(fractions)
    assert 0 < fractions[len(fractions) // 2] < 1
    assert fractions[-1] == pytest.approx(1.0)
    motion.wait()  # already done: returns at once


def test_stop_mid_move_is_not_mistaken_for_arrival(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("article", time_scale=2)
    robot = robots(sim)
    motion = robot.start_move(APPROACH, speed=30)
    while motion.progress().phase is not MovePhase.RUNNING:
        time.sleep(0.01)
    robot.stop()
    with pytest.raises(tmmaster.RobotError, match="TCP is at"):
        motion.wait()
    assert not sim.tcp_pose().is_close(APPROACH)


def test_command_rejected_by_the_robot_program(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    # The master believes in a TM5-700's datasheet reach (700 mm); the simulated arm, the
    # same kinematic chain (so connect's model check passes), refuses past 600 mm.
    short = tmmaster.robot_model("tm5-700").model_copy(update={"reach_mm": 600.0})
    sim = tm_simulator_factory("tmflow", robot=RobotSetup(model=short))
    robot = robots(sim)
    with pytest.raises(tmmaster.CommandRejectedError, match="unreachable") as info:
        robot.move_to(Pose(300, -570, 300, 180, 0, 90), speed=30)
    assert info.value.error_code == 1
    robot.move_to(APPROACH, speed=30)  # the program takes the next command


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_connection_drop_during_the_wait_reconnects_and_never_resends(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile, time_scale=5)
    robot = robots(sim)
    motion = robot.start_move(APPROACH, speed=30)
    # The command is acknowledged: the link drops after the next request, a poll of the
    # wait (the move takes seconds at time_scale 5), however the polls are scheduled.
    sim.inject("drop_connections:after_requests=1")
    motion.wait()
    assert robot.stats.reconnects >= 1
    assert len(command_writes(sim)) == 1
    assert sim.tcp_pose().is_close(APPROACH, mm=0.01)


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_lost_answer_to_the_command_write_is_resolved_without_resending(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile)
    robot = robots(sim)
    sim.inject(f"drop_connections:on_write_to={COMMAND_BLOCK[profile]},lose=answer")
    robot.move_to(APPROACH, speed=30)
    assert robot.stats.reconnects >= 1
    assert len(command_writes(sim)) == 1
    assert sim.tcp_pose().is_close(APPROACH, mm=0.01)


def test_lost_command_write_is_resent_with_the_same_sequence_number(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("tmflow")
    robot = robots(sim)
    sim.inject(f"drop_connections:on_write_to={COMMAND_BLOCK['tmflow']},lose=request")
    robot.move_to(APPROACH, speed=30)
    # Two writes arrived: the lost one was refused unexecuted, the resend was executed,
    # and both carry the same sequence number: the program takes that number at most once.
    start = COMMAND_BLOCK["tmflow"]
    arrived = [r for r in sim.request_log if r.function_code == 16 and r.address == start]
    assert len(arrived) == 2
    assert arrived[0].values == arrived[1].values
    assert len(command_writes(sim)) == 1
    assert sim.tcp_pose().is_close(APPROACH, mm=0.01)


def test_lost_command_write_is_never_resent_on_a_clear_on_accept_profile(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("article")
    robot = robots(sim, timeouts=TimeoutPolicy(in_flight_s=0.15))
    before = sim.tcp_pose()
    sim.inject(f"drop_connections:on_write_to={COMMAND_BLOCK['article']},lose=request")
    # Old targets in the registers cannot prove the write is lost rather than late: the
    # master watches for it during the in-flight window, then withdraws and says so.
    with pytest.raises(tmmaster.CommandStateUnknownError, match="not written again"):
        robot.move_to(APPROACH, speed=30)
    start = COMMAND_BLOCK["article"]
    arrived = [r for r in sim.request_log if r.function_code == 16 and r.address == start]
    assert len(arrived) == 1
    assert command_writes(sim) == []
    assert robot.last_motion is not None
    assert robot.last_motion.withdrawn is True
    assert sim.field("command") == 0
    assert sim.tcp_pose().is_close(before, mm=0.01)


def test_repeating_the_same_target_after_a_lost_answer_cannot_be_proven_and_is_not_resent(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("article")
    robot = robots(sim)
    robot.move_to(APPROACH, speed=30)
    # Same target again, answer lost: registers look the same whether or not it arrived.
    sim.inject("drop_connections:on_write_to=0x0207,lose=answer")
    # Either outcome is safe: the robot had not cleared the command yet (provably landed,
    # waited for), or it had (CommandStateUnknownError, the honest answer). Never a resend.
    with contextlib.suppress(tmmaster.CommandStateUnknownError):
        robot.move_to(APPROACH, speed=30)
    assert len(command_writes(sim)) == 2


def test_a_pending_command_from_someone_else_blocks_a_move(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("article", faults=["late_ack:delay_s=100"])
    robot = robots(sim)
    other = robots(sim)
    other.start_move(APPROACH, speed=30)  # taken only after 2.5 wall s
    before = len(command_writes(sim))
    with pytest.raises(tmmaster.RobotError, match="still pending"):
        robot.move_to(PICK, speed=10)
    assert len(command_writes(sim)) == before


def test_close_is_idempotent_and_connection_state_is_explicit(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("article")
    robot = Robot(sim.url, profile="article")
    assert robot.state is tmmaster.ConnectionState.NEW
    robot.connect()
    assert robot.state is tmmaster.ConnectionState.CONNECTED
    robot.close()
    robot.close()
    assert robot.state is tmmaster.ConnectionState.CLOSED


def test_connect_failure_is_typed() -> None:
    from modbus_test_server import free_port

    robot = Robot(
        "127.0.0.1",
        free_port(),
        profile="article",
        retry=tmmaster.RetryPolicy(attempts=2, initial_backoff_s=0.01),
    )
    with pytest.raises(tmmaster.ConnectError):
        robot.connect()
    robot.close()


def test_tmflow_accepts_commands_again_after_a_stop_and_restart(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("tmflow", faults=["stall:at_move=1"])
    robot = robots(sim)
    with pytest.raises(tmmaster.MotionTimeoutError):
        robot.move_to(APPROACH, speed=30, timeout=0.3)  # stalls; the Stop button is pressed
    sim.wait_for(lambda: not sim.field("project_running"), timeout=2)
    sim.clear_faults()
    # The operator starts the project again (Play on the pendant; here a plain Modbus write).
    profile = robot.profile
    with MemoryTransport(sim, name="pendant") as pendant:
        pendant.write_fields([(profile.field("play_pause"), True)], retry=False)
    robot.wait_until_ready(timeout_s=5)
    # The abandoned command left ack_seq != done_seq; that must not block the next one.
    robot.move_to(APPROACH, speed=30)
    assert sim.tcp_pose().is_close(APPROACH, mm=0.01)


@pytest.mark.parametrize(
    ("profile", "before_ack", "after_ack"), [("article", 2, 1), ("tmflow", 3, 3)]
)
def test_one_request_per_block_per_poll(
    tm_simulator_factory: SimFactory,
    robots: Callable[..., Robot],
    profile: str,
    before_ack: int,
    after_ack: int,
) -> None:
    # 0.3 s of wall time before the acknowledgement; the move itself then takes ~0.3 s.
    sim = tm_simulator_factory(profile, time_scale=5, faults=["late_ack:delay_s=1.5"])
    robot = robots(sim)
    motion = robot.start_move(APPROACH, speed=30)
    sim.clear_request_log()
    motion.progress() if profile == "article" else robot._channel.poll(motion._ticket)
    assert len(sim.request_log) == before_ack
    assert not motion._ticket.acknowledged
    sim.wait_for(lambda: sim.field("motion_status" if profile == "article" else "robot_state") == 1)
    robot._channel.poll(motion._ticket)  # sees the acknowledgement
    sim.clear_request_log()
    robot._channel.poll(motion._ticket)
    assert motion._ticket.acknowledged
    assert len(sim.request_log) == after_ack
    motion.wait()


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_close_says_whether_it_could_confirm_the_clean_up(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # Nothing outstanding: confirmed. A move outstanding on a robot that vanished: the
    # withdraw and the stop cannot be delivered, within the budget: not confirmed.
    sim = tm_simulator_factory(profile)
    robot = Robot(sim.url, profile=profile, gripper=None, polling=PollPolicy(interval_s=0.01))
    robot.connect()
    robot.wait_until_ready(timeout_s=5)
    robot.move_to(APPROACH, speed=80)
    assert robot.close() is True
    assert robot.close() is True  # a second close says the same
    other = tm_simulator_factory(profile, time_scale=1)
    robot = Robot(other.url, profile=profile, gripper=None, polling=PollPolicy(interval_s=0.01))
    robot.connect()
    robot.wait_until_ready(timeout_s=5)
    robot.start_move(APPROACH.offset(dz=-50), speed=5)  # seconds long
    other.close()
    started = time.monotonic()
    assert robot.close(timeout_s=0.5) is False
    assert time.monotonic() - started < 2.0
    assert robot.state is tmmaster.ConnectionState.CLOSED
    with pytest.raises(tmmaster.ConfigError, match="timeout_s"):
        robot.close(timeout_s=0)


@pytest.mark.parametrize(("speaks", "device"), [("article", "tmflow"), ("tmflow", "article")])
def test_a_device_running_another_profile_is_a_profile_mismatch(
    tm_simulator_factory: SimFactory, speaks: str, device: str
) -> None:
    # tmflow reads the arm at connect, article only its status: either way the refused
    # read becomes one ConfigError naming both profiles, the Modbus code said once.
    sim = tm_simulator_factory(device)
    robot = Robot(sim.url, profile=speaks)

    def connect_and_read() -> None:
        robot.connect()
        robot.status()

    try:
        with pytest.raises(tmmaster.ProfileMismatchError) as caught:
            connect_and_read()
    finally:
        robot.close()
    error = caught.value
    assert isinstance(error, tmmaster.ConfigError)
    assert isinstance(error, tmmaster.IllegalAddressError)
    assert (error.profile, error.device_profile, error.code) == (speaks, device, 2)
    assert str(error).count("(Modbus exception code 2)") == 1
    assert f"the device answers the '{device}' profile's status registers" in str(error)
    assert command_writes(sim) == []
