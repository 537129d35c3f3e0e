"""The pacing loop and the predictive schedule of a move, without sockets or sleeps."""

from __future__ import annotations

import itertools
import math
import threading

import pytest

from tmmaster import ConfigError, Poller, PollPolicy, StopRequestedError
from tmmaster._poller import ACK_DELAY_S, DENSE_S, STRETCH, MotionSchedule
from tmmaster._robot_models import trapezoid_progress

NOMINAL = 0.05


def polls_of(
    schedule: MotionSchedule,
    *,
    sent_at: float,
    ack_at: float,
    expected_s: float,
    until: float,
    since: float | None = None,
) -> list[float]:
    """The poll times the schedule asks for, from the write until ``until``."""
    times: list[float] = []
    now = sent_at
    anchored = False
    while True:
        acknowledged = now >= ack_at
        if acknowledged and not anchored:
            schedule.acknowledged(ack_at, expected_s, since=since)
            anchored = True
        nxt = schedule.next_poll(now, acknowledged=acknowledged)
        assert nxt >= now
        if nxt > until:
            return times
        times.append(nxt)
        now = nxt


@pytest.mark.parametrize("expected_s", [0.3, 0.8, 1.0, 2.5, 8.0])
def test_a_move_costs_no_more_polls_than_nominal_polling(expected_s: float) -> None:
    ack_at = 0.021
    end = ack_at + expected_s
    until = end + 2 * TICK
    schedule = MotionSchedule(PollPolicy(), 0.0)
    times = polls_of(schedule, sent_at=0.0, ack_at=ack_at, expected_s=expected_s, until=until)
    assert len(times) <= until / NOMINAL + 1
    # Dense from the expected end to a robot tick after it, where a robot on the model
    # reports it: a completion reported there is seen within one dense interval.
    near_end = [t for t in times if end <= t <= end + TICK + DENSE_S]
    gaps = [b - a for a, b in itertools.pairwise(near_end)]
    assert len(near_end) >= 2
    assert max(gaps) <= DENSE_S + 1e-9
    assert near_end[0] <= end + DENSE_S + 1e-9
    assert near_end[-1] >= end + TICK - 1e-9
    # Never stretched beyond STRETCH x nominal in the middle.
    all_gaps = [b - a for a, b in itertools.pairwise(times)]
    assert max(all_gaps) <= NOMINAL * STRETCH + 1e-9


def test_the_first_poll_follows_the_robots_next_tick() -> None:
    schedule = MotionSchedule(PollPolicy(), sent_at=10.0)
    assert schedule.next_poll(10.0, acknowledged=False) == pytest.approx(10.0 + ACK_DELAY_S)
    # Dense for a robot tick, then nominal.
    assert schedule.next_poll(10.025, acknowledged=False) == pytest.approx(10.025 + DENSE_S)
    assert schedule.next_poll(10.5, acknowledged=False) == pytest.approx(10.55)


def test_predictive_polling_can_be_switched_off() -> None:
    schedule = MotionSchedule(PollPolicy(predictive=False), sent_at=0.0)
    assert schedule.next_poll(0.0, acknowledged=False) == pytest.approx(NOMINAL)
    schedule.acknowledged(0.02, 1.0)
    assert schedule.next_poll(1.0, acknowledged=True) == pytest.approx(1.0 + NOMINAL)


def test_a_very_short_move_is_polled_densely_until_a_tick_after_its_end() -> None:
    schedule = MotionSchedule(PollPolicy(), sent_at=0.0)
    schedule.acknowledged(0.02, 0.01)
    seen = 0.02 + 0.01 + DENSE_S
    assert schedule.next_poll(0.02, acknowledged=True) == pytest.approx(seen)
    assert schedule.next_poll(seen, acknowledged=True) == pytest.approx(seen + DENSE_S)
    # Past the robot's tick after the end: the nominal pace.
    assert schedule.next_poll(0.051, acknowledged=True) == pytest.approx(0.051 + NOMINAL)


@pytest.mark.parametrize("expected_s", [0.3, 0.313, 0.34, 0.5])
def test_a_short_move_on_the_model_is_seen_within_a_dense_interval(expected_s: float) -> None:
    # Every move has its window, a short one too: the robot's report at its next tick
    # is seen within a dense interval (not a tick later), early enough for the next
    # command to make the robot's following tick.
    late, polls = seen_after_the_end(1.0, expected_s, observe=False)
    reported_after = math.ceil((0.021 + expected_s) / TICK) * TICK - (0.021 + expected_s)
    assert late <= reported_after + DENSE_S + 1e-9
    assert polls <= (0.021 + expected_s) / NOMINAL + 3


@pytest.mark.parametrize("expected_s", [0.3, 0.44, 0.57, 0.6, 0.7, 0.8, 1.0])
def test_a_move_on_the_model_is_seen_by_the_robots_next_tick_whatever_its_length(
    expected_s: float,
) -> None:
    late, _ = seen_after_the_end(1.0, expected_s, observe=False)
    assert late <= TICK + DENSE_S + 1e-9


@pytest.mark.parametrize("expected_s", [0.4, 0.44, 0.5])
def test_a_short_move_is_polled_sparsely_until_its_earliest_end(expected_s: float) -> None:
    # The polls before the earliest plausible end (a robot twice as fast as the model)
    # are spaced, so a short move on the model costs fewer polls than nominal polling,
    # and a twice-as-fast one is still seen within one nominal interval.
    # Polls that see the progress (every article poll, a tmflow poll a third and two
    # thirds in) put the earliest end later still.
    _, polls = seen_after_the_end(1.0, expected_s, observe=True)
    assert polls <= (0.021 + expected_s) / NOMINAL - 1
    _, blind = seen_after_the_end(1.0, expected_s, observe=False)
    assert blind <= (0.021 + expected_s) / NOMINAL
    late, _ = seen_after_the_end(0.5, expected_s, observe=False)
    assert late <= NOMINAL + TICK + 1e-9


def test_a_short_move_the_robot_took_early_is_seen_within_a_dense_interval() -> None:
    # The poll at 21 ms saw the command taken; the write was at 0: the robot took it in
    # between. The window opens at the end of a robot that took it at once.
    schedule = MotionSchedule(PollPolicy(), 0.0)
    schedule.acknowledged(0.021, 0.43, since=0.0)
    polls, now = [], 0.021
    while now < 0.6:
        now = schedule.next_poll(now, acknowledged=True)
        polls.append(now)
    early_report = math.ceil((0.001 + 0.43) / TICK) * TICK  # taken at 1 ms: 0.44 s
    late_report = math.ceil((0.021 + 0.43) / TICK) * TICK  # taken at 21 ms: 0.46 s
    for report in (early_report, late_report):
        assert any(report <= t <= report + DENSE_S + 1e-9 for t in polls)


@pytest.mark.parametrize("bad", [0, -1, float("nan"), float("inf")])
def test_meaningless_intervals_are_refused(bad: float) -> None:
    with pytest.raises(ConfigError):
        Poller(bad)
    with pytest.raises(ConfigError, match="interval_s"):
        PollPolicy(interval_s=bad)


def test_the_schedules_constants_are_not_options() -> None:
    # The dense interval, the robot's tick and the windows are the schedule's own.
    with pytest.raises(ConfigError, match="dense_interval_s"):
        PollPolicy(dense_interval_s=0.005)  # type: ignore[call-arg]


def test_a_stop_request_ends_every_sleep_instead_of_spinning() -> None:
    stop = threading.Event()
    poller = Poller(10.0, stop)
    stop.set()
    with pytest.raises(StopRequestedError):
        poller.sleep()
    with pytest.raises(StopRequestedError):
        poller.sleep_until(1e12)
    with pytest.raises(StopRequestedError):
        poller.check()


@pytest.mark.parametrize("expected_s", [0.8, 1.0, 2.5])
def test_the_window_opens_early_enough_for_an_acknowledgement_seen_late(
    expected_s: float,
) -> None:
    # The robot took the command somewhere between the write (0) and the poll that saw
    # it (21 ms): it may report the end as early as expected_s after the write.
    ack_at, end = 0.021, 0.021 + expected_s
    until = end + 2 * TICK
    plain = MotionSchedule(PollPolicy(), 0.0)
    plain_times = polls_of(plain, sent_at=0.0, ack_at=ack_at, expected_s=expected_s, until=until)
    early = MotionSchedule(PollPolicy(), 0.0)
    early_times = polls_of(
        early, sent_at=0.0, ack_at=ack_at, expected_s=expected_s, until=until, since=0.0
    )
    first_dense = next(a for a, b in itertools.pairwise(early_times) if b - a <= DENSE_S + 1e-9)
    plain_dense = next(a for a, b in itertools.pairwise(plain_times) if b - a <= DENSE_S + 1e-9)
    assert first_dense < plain_dense
    assert first_dense <= expected_s + DENSE_S + 1e-9
    # Still no more polls than nominal polling over the move.
    assert len(early_times) <= until / NOMINAL + 1


# -- a robot that differs from the model ------------------------------------------------

TICK = 0.02  # the robot's control tick: it reports the end at its next one


def seen_after_the_end(
    pace: float, expected_s: float, *, observe: bool, policy: PollPolicy | None = None
) -> tuple[float, int]:
    """How long after a move really ended the schedule's polls see it, and their count.

    The robot takes the command at 21 ms and moves ``pace`` times slower than the model
    (0.5: twice as fast); it reports the end at its first tick after it. With
    ``observe``, each poll tells the schedule the progress it saw (the model's trapezoid,
    at the robot's pace).
    """
    policy = policy or PollPolicy()
    accel = 0.2
    schedule = MotionSchedule(policy, 0.0, accel_s=accel)
    ack_at = 0.021
    end = ack_at + expected_s * pace
    reported = math.ceil(end / TICK) * TICK
    now, anchored, polls = 0.0, False, 0
    while True:
        acknowledged = now >= ack_at
        if acknowledged and not anchored:
            schedule.acknowledged(ack_at, expected_s)
            anchored = True
        elif anchored and observe:
            elapsed = (now - ack_at) / pace
            schedule.observed(now, trapezoid_progress(elapsed, expected_s, accel))
        if now >= reported:
            return now - end, polls
        now = schedule.next_poll(now, acknowledged=acknowledged)
        polls += 1


@pytest.mark.parametrize("pace", [0.5, 0.7, 1.0, 1.4, 2.0])
@pytest.mark.parametrize("expected_s", [0.4, 1.0, 3.0, 8.0])
@pytest.mark.parametrize("observe", [False, True], ids=["blind", "observing"])
def test_a_robot_faster_or_slower_than_the_model_is_seen_within_one_interval(
    pace: float, expected_s: float, observe: bool
) -> None:
    # Up to twice as fast or twice as slow as the model: the end is seen within one
    # nominal interval and one robot tick, with or without the progress each poll sees.
    late, _ = seen_after_the_end(pace, expected_s, observe=observe)
    assert late <= NOMINAL + TICK + 1e-9


@pytest.mark.parametrize("pace", [0.6, 1.33, 1.57])
def test_the_observed_progress_moves_the_dense_window_to_the_real_end(pace: float) -> None:
    # A long move whose robot is off the model: what the polls see carries the dense
    # window to the real end, so the end is seen within a dense interval of the report.
    blind, _ = seen_after_the_end(pace, 4.0, observe=False)
    late, polls = seen_after_the_end(pace, 4.0, observe=True)
    assert late <= TICK + DENSE_S + 1e-9 < blind
    assert polls <= (4.0 * pace) / NOMINAL + 4


@pytest.mark.parametrize("pace", [1.7, 2.0, 2.3])
@pytest.mark.parametrize("expected_s", [0.5, 1.0, 1.5])
def test_a_look_that_finds_the_robot_braking_still_brings_the_window_to_its_end(
    pace: float, expected_s: float
) -> None:
    # About twice as slow as the model: the second look, timed by the slowest pace the
    # first allowed, finds the robot braking (past 95 % of its path), where its pose
    # bounds the pace only loosely. That bound still carries the dense window to the
    # end: the end is seen before a nominal interval has passed, not one interval late.
    late, _ = seen_after_the_end(pace, expected_s, observe=True)
    assert late < NOMINAL


def test_a_robot_that_speeds_up_after_a_slow_start_is_seen_within_one_interval() -> None:
    # A poll sees the move barely started (a robot far slower than the model, or an
    # operator's speed override turned down): the polls may be spaced again, but never
    # past the model's own end, so a robot that speeds up again is seen in time.
    policy = PollPolicy()
    schedule = MotionSchedule(policy, 0.0, accel_s=0.2)
    schedule.acknowledged(0.0, 2.0)
    schedule.observed(0.9, 0.06)
    assert schedule.expected_end is not None
    assert schedule.expected_end > 2.0
    assert schedule.pace > 1.0
    now = 0.9
    while now < 3.0:
        nxt = schedule.next_poll(now, acknowledged=True)
        if now >= 2.0:
            assert nxt - now <= NOMINAL + 1e-9
        now = nxt
