"""The next command's checks may reuse what the poll that saw the last one finished read.

Only that read (never one from before the done), only once, only while fresh
(``REUSE_DONE_READ_S``, one robot tick), only on the same connection with nothing written
since; and the checks on it are the same: an error or e-stop in it blocks the write.
These tests are about the rule, not the machine's speed: where a reuse is expected, the
record's age is set to "just read" first, so a slow machine cannot make them flaky.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest

import tmmaster
import tmmaster._robot as robot_module
from tmmaster import PollPolicy, Pose, Robot
from tmmaster._channels import REUSE_DONE_READ_S
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]

APPROACH = Pose(300, -200, 200, 180, 0, 90)
PICK = Pose(300, -200, 150, 180, 0, 90)
COMMAND_BLOCK = {"article": 0x0200, "tmflow": 9000}
#: What the checks read before the write when they cannot reuse the done poll's read.
FULL_CHECK = {
    "article": [(3, 0x0200), (3, 0x0000)],  # command block, status block
    # tmflow's last read: the joints and the TCP pose with the frames, 7001-7060 in one
    # request.
    "tmflow": [(2, 7201), (2, 7207), (3, 9015), (3, 9100), (4, 7001)],
}
#: ... and when they can: article the command block; tmflow ``seq`` (the pose and the
#: joints are the final at-target check's).
REUSED_CHECK = {"article": [(3, 0x0200)], "tmflow": [(3, 9015)]}


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: SimFactory) -> SimFactory:
    """Simulators in memory: the subject is the master's reads, not TCP."""
    return memory_simulator_factory


def reads_before_write(sim: Simulator) -> list[tuple[int, int]]:
    """(function code, address) of each request before the command write."""
    start = COMMAND_BLOCK[sim.profile.name]
    reads: list[tuple[int, int]] = []
    for r in sim.request_log:
        if r.function_code == 16 and r.address == start:
            return reads
        reads.append((r.function_code, r.address))
    raise AssertionError("no command write in the request log")


def command_writes(sim: Simulator) -> int:
    start = COMMAND_BLOCK[sim.profile.name]
    return sum(1 for r in sim.request_log if r.function_code == 16 and r.address == start)


def refresh(robot: Robot) -> None:
    """Make the done poll's record "just read" (the rule under test, not the clock): its
    time an hour ahead, so that however late a loaded machine runs the next call, it is
    within the reuse window."""
    state = robot._channel.after_done
    assert state is not None
    state.read_at = time.monotonic() + 3600.0


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_fresh_done_read_stands_in_for_the_same_reads(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile)
    robot = robots(sim, gripper=None)
    first = robot.move_to(APPROACH, speed=30)
    state = robot._channel.after_done
    assert state is not None
    # Read by the poll that saw the move finished: never before the command was written.
    assert state.read_at > first.ticket.sent_at
    if profile == "tmflow":
        assert state.pose is not None
        assert state.pose.is_close(APPROACH, mm=1)
    refresh(robot)
    sim.clear_request_log()
    motion = robot.start_move(PICK, speed=30)
    assert reads_before_write(sim) == REUSED_CHECK[profile]
    assert robot._channel.after_done is None  # used once
    motion.wait()
    assert motion.start is not None
    assert motion.start.is_close(APPROACH, mm=1)
    assert sim.tcp_pose().is_close(PICK, mm=0.01)
    assert command_writes(sim) == 1


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_stale_done_read_is_read_again(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile)
    robot = robots(sim, gripper=None, polling=PollPolicy(interval_s=0.01))
    robot.move_to(APPROACH, speed=30)
    state = robot._channel.after_done
    assert state is not None
    state.read_at = time.monotonic() - 2 * REUSE_DONE_READ_S  # older than that
    sim.clear_request_log()
    robot.start_move(PICK, speed=30).wait()
    assert reads_before_write(sim) == FULL_CHECK[profile]


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_zero_reuse_window_never_reuses(
    tm_simulator_factory: SimFactory,
    robots: Callable[..., Robot],
    profile: str,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(robot_module, "REUSE_DONE_READ_S", 0.0)
    sim = tm_simulator_factory(profile)
    robot = robots(sim, gripper=None, polling=PollPolicy(interval_s=0.01))
    robot.move_to(APPROACH, speed=30)
    refresh(robot)
    sim.clear_request_log()
    robot.start_move(PICK, speed=30).wait()
    assert reads_before_write(sim) == FULL_CHECK[profile]


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_write_since_the_done_read_forbids_reuse(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile)
    robot = robots(sim, gripper=None)
    robot.move_to(APPROACH, speed=30)
    refresh(robot)
    # A harmless write on the same link (command = none; tmflow takes nothing without a seq).
    command = robot.profile.field("command")
    robot._transport.write_fields([(command, command.code_of("none"))], retry=False)
    sim.clear_request_log()
    robot.start_move(PICK, speed=30).wait()
    assert reads_before_write(sim) == FULL_CHECK[profile]


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_statistics_reset_by_the_user_never_make_a_read_reusable_after_a_write(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    """The reuse rule rests on the link's epoch, not on counters a user may reset."""
    sim = tm_simulator_factory(profile)
    robot = robots(sim, gripper=None)
    robot.move_to(APPROACH, speed=30)
    refresh(robot)
    # A user measuring per move zeroes the counters, then the same link writes once.
    robot.stats.requests_by_function.clear()
    robot.stats.errors = robot.stats.retries = robot.stats.reconnects = 0
    command = robot.profile.field("command")
    robot._transport.write_fields([(command, command.code_of("none"))], retry=False)
    sim.clear_request_log()
    robot.start_move(PICK, speed=30).wait()
    assert reads_before_write(sim) == FULL_CHECK[profile]


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_dropped_connection_since_the_done_read_forbids_reuse(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile)
    robot = robots(sim, gripper=None)
    robot.move_to(APPROACH, speed=30)
    refresh(robot)
    robot._transport._drop()  # type: ignore[attr-defined]  # lost; the next request reconnects
    sim.clear_request_log()
    robot.start_move(PICK, speed=30).wait()
    assert reads_before_write(sim) == FULL_CHECK[profile]


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_read_from_before_the_done_is_never_kept(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile)
    robot = robots(sim, gripper=None)
    robot.move_to(APPROACH, speed=30)
    assert robot._channel.after_done is not None
    motion = robot.start_move(PICK, speed=5)
    robot._channel.poll(motion.ticket)  # a poll that does not see this move finished ...
    assert not motion.done
    assert robot._channel.after_done is None  # ... forgets the previous done read
    motion.wait()


@pytest.mark.parametrize(
    ("profile", "field", "value", "error"),
    [
        ("article", "error_code", 7, tmmaster.RobotFaultError),
        ("article", "robot_mode", 7, tmmaster.RobotFaultError),  # error mode
        ("tmflow", "estop", True, tmmaster.EmergencyStopError),
        ("tmflow", "error", True, tmmaster.RobotFaultError),
        ("tmflow", "project_running", False, tmmaster.RobotFaultError),
    ],
)
def test_an_error_in_the_reused_read_blocks_the_write(
    tm_simulator_factory: SimFactory,
    robots: Callable[..., Robot],
    profile: str,
    field: str,
    value: int | bool,
    error: type[Exception],
) -> None:
    sim = tm_simulator_factory(profile)
    robot = robots(sim, gripper=None)
    robot.move_to(APPROACH, speed=30)
    refresh(robot)
    state = robot._channel.after_done
    assert state is not None
    assert field in state.values
    state.values[field] = value
    sim.clear_request_log()
    with pytest.raises(error):
        robot.start_move(PICK, speed=30)
    assert command_writes(sim) == 0


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_busy_or_pending_state_in_the_reused_read_blocks_the_write(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile)
    robot = robots(sim, gripper=None)
    robot.move_to(APPROACH, speed=30)
    refresh(robot)
    state = robot._channel.after_done
    assert state is not None
    if profile == "article":
        state.values["motion_status"] = 1  # moving
    else:
        state.values["robot_state"] = robot.profile.field("robot_state").code_of("busy")
    sim.clear_request_log()
    with pytest.raises(tmmaster.RobotError, match="still"):
        robot.start_move(PICK, speed=30)
    assert command_writes(sim) == 0
