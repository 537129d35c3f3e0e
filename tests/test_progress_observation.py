"""The wait reads the robot's pace from the poses it reports, not from the model alone.

* :class:`PathGauge`: how much of a move's path a reported pose has covered (a Line's
  projection; a PTP's joint interpolation, by the model's forward kinematics).
* A profile whose poll carries no pose (tmflow) reads it on the polls the schedule
  asks to observe, and only on those.
* :class:`FollowState` hands each new pose to the schedule: the predicted end moves.
"""

from __future__ import annotations

import threading
from typing import Any

import pytest

import tmmaster
from tmmaster import MotionType, PollPolicy, Pose, TimeoutPolicy
from tmmaster._channels import Command, CommandKind, Ticket, channel_for
from tmmaster._following import FollowState, Overdue
from tmmaster._profiles import robot_profile
from tmmaster._robot_models import PathGauge, trapezoid_progress
from tmmaster._status import MovePhase

TM5 = tmmaster.robot_model("tm5-700")
START = Pose(300, -200, 250, 180, 0, 90)
TARGET = Pose(-100, 350, 150, 180, 0, 0)


def test_a_line_is_gauged_along_its_segment() -> None:
    gauge = PathGauge.of(
        TM5,
        START,
        TARGET,
        motion=MotionType.LINE,
        start_joints_deg=None,
        target_joints_deg=TM5.inverse(TARGET),
        tool=None,
    )
    halfway = Pose(100, 75, 200, 180, 0, 45)
    assert gauge.fraction(halfway) == pytest.approx(0.5)
    assert gauge.fraction(START) == 0.0
    assert gauge.fraction(TARGET) == 1.0


@pytest.mark.parametrize("progress", [0.1, 0.3, 0.5, 0.8])
def test_a_ptp_is_gauged_by_its_joint_path(progress: float) -> None:
    first = TM5.inverse(START)
    last = TM5.inverse(TARGET, seed_deg=first)
    gauge = PathGauge.of(
        TM5,
        START,
        TARGET,
        motion=MotionType.PTP,
        start_joints_deg=first,
        target_joints_deg=last,
        tool=None,
    )
    on_the_way = TM5.forward([a + (b - a) * progress for a, b in zip(first, last, strict=True)])
    # The straight-line distance would say otherwise: the TCP swings round the base.
    fraction = gauge.fraction(on_the_way)
    assert fraction == pytest.approx(progress, abs=0.01)


class _NoIO:
    stats = tmmaster.TransportStats()
    state = tmmaster.ConnectionState.CONNECTED
    epoch = 0

    def __getattr__(self, name: str) -> Any:
        raise AssertionError(f"a poll used the transport directly ({name})")


def _run_poll(channel: Any, ticket: Ticket, values: dict[str, Any]) -> tuple[Any, list[str]]:
    steps = channel.poll_steps(ticket)
    read: list[str] = []
    fields = next(steps)
    while True:
        read += [f.name for f in fields]
        try:
            fields = steps.send({f.name: values.get(f.name, 0) for f in fields})
        except StopIteration as finished:
            return finished.value, read


def test_a_tmflow_poll_reads_the_pose_only_when_asked() -> None:
    channel = channel_for(robot_profile("tmflow"), _NoIO())  # type: ignore[arg-type]
    ticket = Ticket(Command(CommandKind.PTP, TARGET, 50), [], 0.0, seq=1)
    running = {
        "ack_seq": 1,
        "done_seq": 0,
        "robot_state": 1,
        "project_running": True,
        **dict(zip(("tcp_x", "tcp_y", "tcp_z", "tcp_rx", "tcp_ry", "tcp_rz"), START, strict=True)),
    }
    observation, read = _run_poll(channel, ticket, running)
    assert observation.pose is None
    assert "tcp_x" not in read
    ticket.observe_pose = True
    observation, read = _run_poll(channel, ticket, running)
    assert observation.pose == START
    assert "tcp_x" in read
    assert not ticket.observe_pose  # once per request


class _Motion:
    """What a wait needs of a motion, moving at half the model's pace."""

    def __init__(self, ticket: Ticket) -> None:
        self.ticket = ticket
        self.phase = MovePhase.RUNNING
        self.expected_s = 2.0
        self.timeout_s = 10.0
        self.last_pose: Pose | None = None
        self.start: Pose | None = Pose(0, 0, 300, 180, 0, 0)
        self.target: Pose | None = Pose(100, 0, 300, 180, 0, 0)  # the end of its progress
        self.accel_s = 0.2
        self.timeout_from_model = True

    def path_fraction(self, pose: Pose) -> float | None:
        return pose.x / 100.0  # the test's poses carry their progress in x


def _follow(motion: _Motion) -> FollowState:
    return FollowState(
        motion,
        None,
        stop_event=threading.Event(),
        polling=PollPolicy(),
        timeouts=TimeoutPolicy(ack_timeout_s=1.0, stall_s=1.0),
    )


def _half_pace(motion: _Motion, follow: FollowState) -> None:
    """Anchor the wait, then show it a pose one second in, where the model is at 0.5 s."""
    follow.poll_started = 0.0
    follow.due()
    follow.poll_started = 1.0
    motion.last_pose = Pose(100 * trapezoid_progress(0.5, 2.0, 0.2), 0, 300, 180, 0, 0)
    follow.due()


@pytest.mark.parametrize("from_model", [True, False])
def test_a_robot_seen_moving_slower_than_the_model_gets_more_time(from_model: bool) -> None:
    ticket = Ticket(Command(CommandKind.PTP, TARGET, 50), [], 0.0, seq=1)
    ticket.acknowledged, ticket.acknowledged_at = True, 0.0
    motion = _Motion(ticket)
    motion.timeout_s = 4.6  # 2 s x 1.3 + 2 s: the model's budget
    motion.timeout_from_model = from_model
    follow = _follow(motion)
    _half_pace(motion, follow)
    # A quarter of the model's pace from then on: still moving past the model's budget
    # (its polls see progress), it gets more time.
    for at in (2.0, 3.0, 4.0, 4.6):
        _seen_at(motion, follow, at, _quarter_pace(at))
    assert follow.overdue(4.7) is (None if from_model else Overdue.MOTION)
    for at in (5.5, 6.5, 7.5):
        _seen_at(motion, follow, at, _quarter_pace(at))
    assert follow.overdue(8.4) is (None if from_model else Overdue.MOTION)
    # A timeout the user fixed stays as it is; a grown one needs progress to go on.
    assert follow.overdue(8.6) is Overdue.MOTION


def _quarter_pace(at: float) -> float:
    """How much of its path an arm at a quarter of the model's pace covered at ``at``."""
    return trapezoid_progress(at / 4, 2.0, 0.2)


def _seen_at(motion: _Motion, follow: FollowState, at: float, progress: float) -> None:
    """A poll at ``at`` that sees the arm at ``progress`` of its path."""
    follow.poll_started = at
    motion.last_pose = Pose(100 * progress, 0, 300, 180, 0, 0)
    follow.due()


def _line_at_half_pace() -> tuple[_Motion, FollowState]:
    """A Line acknowledged at 0 with the model's 4.6 s budget, seen at half pace at 1 s."""
    ticket = Ticket(Command(CommandKind.LINE, TARGET, 50), [], 0.0, seq=1)
    ticket.acknowledged, ticket.acknowledged_at = True, 0.0
    motion = _Motion(ticket)
    motion.timeout_s = 4.6
    follow = _follow(motion)
    _half_pace(motion, follow)
    return motion, follow


def test_an_arm_that_stops_is_a_stall_within_the_model_budget() -> None:
    # The arm moves at half the model's pace (the budget would grow to 9.2 s), then
    # stops at 1.5 s: the polls see no progress, and the model's 4.6 s budget stands.
    motion, follow = _line_at_half_pace()
    stopped = trapezoid_progress(0.75, 2.0, 0.2)
    for at in (1.5, 2.0, 3.0, 4.0, 4.5):
        _seen_at(motion, follow, at, stopped)
    assert follow.schedule.pace > 1.0  # the pace alone would have given it more time
    assert follow.overdue(4.55) is None
    assert follow.overdue(4.61) is Overdue.MOTION
    assert follow.applied_budget() == pytest.approx(4.6)
    assert "a stall" in follow.describe_stall()


def test_an_arm_that_stops_past_the_model_budget_is_a_stall_after_its_bound() -> None:
    motion, follow = _line_at_half_pace()
    for at in (2.0, 3.0, 4.0, 5.0, 6.0):
        _seen_at(motion, follow, at, _quarter_pace(at))
    for at in (6.5, 6.9):  # stopped at 6.0
        _seen_at(motion, follow, at, _quarter_pace(6.0))
    assert follow.overdue(6.95) is None
    assert follow.overdue(7.05) is Overdue.MOTION  # 1 s (stall_s) after the last progress
    assert follow.applied_budget() == pytest.approx(7.0)


def test_polls_read_the_pose_from_a_stall_bound_before_the_model_budget_ends() -> None:
    motion, follow = _line_at_half_pace()
    follow.poll_started = 3.7
    follow.due()
    assert motion.ticket.observe_pose


def test_each_new_pose_moves_the_predicted_end() -> None:
    ticket = Ticket(Command(CommandKind.PTP, TARGET, 50), [], 0.0, seq=1)
    ticket.acknowledged, ticket.acknowledged_at = True, 0.0
    motion = _Motion(ticket)
    follow = _follow(motion)
    follow.poll_started = 0.0
    follow.due()
    assert follow.schedule.expected_end == pytest.approx(2.0)
    # One second in, the robot has covered what the model covers in half a second.
    follow.poll_started = 1.0
    motion.last_pose = Pose(100 * trapezoid_progress(0.5, 2.0, 0.2), 0, 300, 180, 0, 0)
    follow.due()
    assert follow.schedule.expected_end == pytest.approx(4.0, rel=0.01)


def test_the_poll_at_a_deadline_counts_before_the_deadline_is_judged() -> None:
    # A poll delayed past the stall window (a starved machine) finds the arm still
    # moving: the wait counts that pose before it judges the deadline, never judging on
    # the poll before it.
    motion, follow = _line_at_half_pace()
    for at in (2.0, 3.0, 4.0, 4.6):
        _seen_at(motion, follow, at, _quarter_pace(at))
    follow.poll_started = 5.7  # 1.1 s after the last: past the 1 s window it began
    motion.last_pose = Pose(100 * _quarter_pace(5.7), 0, 300, 180, 0, 0)
    assert follow.overdue(5.7) is None
    assert follow.last_progress_at == 5.7


@pytest.mark.parametrize("stall_s", [1.0, 0.2])
def test_a_short_moves_stall_window_has_a_floor_unless_stall_s_is_lower(stall_s: float) -> None:
    # A short move (a 0.4 s budget: a quarter is 0.1 s) at a quarter of the model's pace,
    # whose reported pose stands still for 0.3 s past the budget (a status hiccup while
    # the arm moves): not a stall, unless stall_s itself asks for 0.2 s.
    ticket = Ticket(Command(CommandKind.LINE, TARGET, 50), [], 0.0, seq=1)
    ticket.acknowledged, ticket.acknowledged_at = True, 0.0
    motion = _Motion(ticket)
    motion.expected_s, motion.timeout_s, motion.accel_s = 0.3, 0.4, 0.05
    follow = FollowState(
        motion,
        None,
        stop_event=threading.Event(),
        polling=PollPolicy(),
        timeouts=TimeoutPolicy(ack_timeout_s=1.0, stall_s=stall_s),
    )
    quarter = [trapezoid_progress(at / 4, 0.3, 0.05) for at in (0.0, 0.2, 0.4, 0.5)]
    for at, progress in zip((0.0, 0.2, 0.4, 0.5), quarter, strict=True):
        _seen_at(motion, follow, at, progress)
    _seen_at(motion, follow, 0.8, quarter[-1])  # the pose of 0.5 s, reported again at 0.8 s
    assert follow.stall_window() == min(stall_s, 0.5)
    if stall_s < 0.5:
        assert follow.overdue(0.8) is Overdue.MOTION
        return
    assert follow.overdue(0.8) is None
    _seen_at(motion, follow, 0.9, trapezoid_progress(0.9 / 4, 0.3, 0.05))  # moving on
    assert follow.overdue(1.3) is None
    assert follow.overdue(1.41) is Overdue.MOTION  # no progress for 0.5 s after 0.9 s
