"""Every wait keeps its deadline, whatever the poll interval; close() ends a withdraw's wait.

The numeric options of a Robot have one range each, checked alike by the constructor and
the setters. A sleep between two polls never lasts past the wait's deadline, so a wait
with the longest interval allowed (5 s) still ends at its deadline. A close() from another
thread ends the robot thread's wait for a withdraw's answer (that command is stopped
instead), and close()'s own wait for its withdraw's answer is bounded by its timeout_s.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

import tmmaster
from sim_speeds import SUITE_TICK_HZ
from tmmaster import (
    AcknowledgeTimeoutError,
    Checks,
    ConfigError,
    MotionTimeoutError,
    Poller,
    PollPolicy,
    Pose,
    Robot,
    StopRequestedError,
    TimeoutPolicy,
)
from tmmaster._checks import Policy
from tmmaster.sim import Simulator, Timing

SimFactory = Callable[..., Simulator]
APPROACH = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 200, 150, 180, 0, 90)
#: The longest poll interval a Robot takes, s.
LONGEST_INTERVAL_S = 5.0
#: How far past its deadline a wait may end here: the polls and requests at the deadline,
#: on a loaded machine; far less than the 5 s interval a sleep used to run to its end.
SLACK_S = 1.5


@pytest.fixture(params=["thread", "fleet"])
def robots(request: pytest.FixtureRequest) -> Iterator[Callable[..., Robot]]:
    """Connected robots with the longest poll interval, polling their own waits or in a
    Fleet (the fleet's event loop polls their waits); all closed after the test."""
    opened: list[Robot] = []
    fleet = tmmaster.Fleet() if request.param == "fleet" else None

    def make(sim: Simulator, **options: Any) -> Robot:
        options.setdefault("profile", sim.profile)
        options.setdefault("gripper", None)
        options.setdefault("polling", PollPolicy(interval_s=LONGEST_INTERVAL_S))
        robot = Robot("127.0.0.1", sim.port, link=fleet, **options)
        opened.append(robot)
        robot.connect()
        return robot

    yield make
    for robot in opened:
        robot.close()
    if fleet is not None:
        fleet.close()


# -- the options' ranges ------------------------------------------------------------------


#: A Robot property with a setter -> where the constructor takes it (argument, field).
OPTION_AT: dict[str, tuple[type[Policy], str]] = {
    "poll_interval_s": (PollPolicy, "interval_s"),
    "request_timeout_s": (TimeoutPolicy, "request_s"),
    "gripper_settle_s": (TimeoutPolicy, "gripper_settle_s"),
    "position_tolerance_mm": (Checks, "position_tolerance_mm"),
    "orientation_tolerance_deg": (Checks, "orientation_tolerance_deg"),
    "max_speed_percent": (Checks, "max_speed_percent"),
}


def made_with(option: str, value: object) -> Robot:
    """A Robot given ``value`` for ``option`` in the option object that holds it."""
    kind, field = OPTION_AT[option]
    return Robot("127.0.0.1", 1, profile="article", **{kind.argument: kind(**{field: value})})


def named(option: str) -> str:
    """``option`` as the constructor's message names it: ``polling.interval_s``."""
    kind, field = OPTION_AT[option]
    return rf"{kind.argument}\.{field}"


def test_an_absurd_poll_interval_is_refused_by_the_constructor_and_the_setter() -> None:
    with pytest.raises(
        ConfigError, match=r"polling\.interval_s must be a number in \[0\.001, 5\] s"
    ):
        Robot("127.0.0.1", 1, profile="article", polling=PollPolicy(interval_s=1e9))
    robot = Robot(
        "127.0.0.1", 1, profile="article", polling=PollPolicy(interval_s=LONGEST_INTERVAL_S)
    )
    with pytest.raises(ConfigError, match=r"poll_interval_s .*\[0\.001, 5\] s.*1000000000"):
        robot.poll_interval_s = 1e9
    assert robot.poll_interval_s == LONGEST_INTERVAL_S
    robot.poll_interval_s = 0.001  # the other end of the range
    assert robot.poll_interval_s == 0.001


@pytest.mark.parametrize(
    ("option", "good"),
    [
        ("poll_interval_s", 0.02),
        ("position_tolerance_mm", 50),
        ("orientation_tolerance_deg", 45),
        ("max_speed_percent", 1),
    ],
)
@pytest.mark.parametrize("bad", [math.nan, -1, "x", 1e9, True])
def test_a_setter_refuses_what_the_constructor_refuses(option: str, good: float, bad: Any) -> None:
    with pytest.raises(ConfigError, match=named(option)):
        made_with(option, bad)
    robot = Robot("127.0.0.1", 1, profile="article")
    before = getattr(robot, option)
    with pytest.raises(ConfigError, match=option):
        setattr(robot, option, bad)
    assert getattr(robot, option) == before  # a refused value changes nothing
    setattr(robot, option, good)  # a value in range is taken
    assert getattr(robot, option) == good


@pytest.mark.parametrize(
    ("option", "bad", "range_text"),
    [
        ("poll_interval_s", 5.5, r"\[0\.001, 5\] s"),
        ("poll_interval_s", 0.0005, r"\[0\.001, 5\] s"),
        ("request_timeout_s", 61, r"\(0, 60\] s"),
        ("position_tolerance_mm", 1000, r"\(0, 50\] mm"),
        ("orientation_tolerance_deg", 90, r"\(0, 45\] deg"),
        ("gripper_settle_s", 3600, r"\(0, 60\] s"),
        ("max_speed_percent", 50.5, r"\[1, 100\] %"),
        ("max_speed_percent", "x", r"\[1, 100\] %"),
    ],
)
def test_an_option_out_of_its_range_is_refused_naming_the_range(
    option: str, bad: object, range_text: str
) -> None:
    with pytest.raises(ConfigError, match=rf"{named(option)} must be .*{range_text}, got"):
        made_with(option, bad)


@pytest.mark.parametrize("option", ["timeouts", "polling"])
@pytest.mark.parametrize("bad", ["x", {"ack_timeout_s": 1.0}, None])
def test_a_policy_setter_takes_only_its_policy(option: str, bad: object) -> None:
    robot = Robot("127.0.0.1", 1, profile="article")
    before = getattr(robot, option)
    with pytest.raises(ConfigError, match=option):
        setattr(robot, option, bad)
    assert getattr(robot, option) is before
    if bad is not None:
        with pytest.raises(ConfigError, match=option):
            Robot("127.0.0.1", 1, profile="article", **{option: bad})


# -- sleeps end at the deadline -------------------------------------------------------------


def test_a_pollers_sleep_ends_at_its_deadline_not_an_interval_later() -> None:
    started = time.monotonic()
    poller = Poller(LONGEST_INTERVAL_S, threading.Event(), deadline=started + 0.05)
    poller.sleep()
    assert time.monotonic() - started < SLACK_S
    poller.sleep()  # past the deadline: at once
    poller.sleep_until(started + 1000)
    assert time.monotonic() - started < SLACK_S
    with pytest.raises(ConfigError, match="deadline"):
        Poller(1.0, deadline=math.nan)


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_ready_wait_ends_at_its_deadline_with_the_longest_interval(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    # Initialising for good: start() returns without waiting for the start-up.
    sim = tm_simulator_factory(
        profile, timing=Timing(tick_hz=SUITE_TICK_HZ, init_time_s=1000.0), wait_ready=False
    )
    robot = robots(sim)
    started = time.monotonic()
    with pytest.raises(MotionTimeoutError, match=r"not ready after 0\.3 s"):
        robot.wait_until_ready(0.3)
    assert time.monotonic() - started < 0.3 + SLACK_S


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_an_acknowledgement_wait_ends_at_its_deadline_with_the_longest_interval(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    # The robot takes the command 25 s of wall time late; the master waits 0.3 s for it.
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=1000"])
    robot = robots(sim, timeouts=TimeoutPolicy(ack_timeout_s=0.3))
    motion = robot.start_move(APPROACH, speed=30)
    started = time.monotonic()
    with pytest.raises(AcknowledgeTimeoutError):
        motion.wait()
    # The acknowledgement's 0.3 s, then (tmflow) the cancel's answer, waited for as long.
    assert time.monotonic() - started < 0.6 + SLACK_S
    assert motion.withdrawn is True or motion.stop_delivered is True


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_motion_wait_ends_at_its_deadline_with_the_longest_interval(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    # A slow move (several s of wall time) given 0.4 s: polls spaced by up to 3 nominal
    # intervals in the middle of a move still end at the motion's deadline.
    sim = tm_simulator_factory(
        profile, time_scale=1, timing=Timing(tick_hz=SUITE_TICK_HZ, init_time_s=0.0)
    )
    robot = robots(sim)
    robot.wait_until_ready(5)
    started = time.monotonic()
    with pytest.raises(MotionTimeoutError):
        robot.move_to(FAR, speed=5, timeout=0.4)
    assert time.monotonic() - started < 0.4 + SLACK_S
    assert robot.last_motion is not None
    assert robot.last_motion.stop_delivered is True


# -- close() and a withdraw's wait ----------------------------------------------------------


def test_close_from_another_thread_ends_a_pending_withdraw_within_its_timeout(
    tm_simulator_factory: SimFactory,
) -> None:
    # The program holds its link for 10 s of wall time (40x): it answers neither the
    # command nor its cancel before then. The robot's thread gives the command up (a
    # stop request) and waits for the cancel's answer, for up to 20 s.
    sim = tm_simulator_factory("tmflow", faults=["late_ack:delay_s=400"])
    robot = Robot(
        sim.url,
        gripper=None,
        timeouts=TimeoutPolicy(ack_timeout_s=20),
        polling=PollPolicy(interval_s=0.01),
    )
    robot.connect()
    robot.wait_until_ready(5)
    motion = robot.start_move(APPROACH, speed=30)
    ended: list[BaseException] = []

    def follow() -> None:
        try:
            motion.wait()
        except BaseException as exc:  # recorded for the test
            ended.append(exc)

    waiter = threading.Thread(target=follow)
    waiter.start()
    try:
        sim.wait_for(lambda: int(sim.field("seq")) == motion.ticket.seq, timeout=5)
        robot.interrupt()
        deadline = time.monotonic() + 5
        while not motion.abandoned and time.monotonic() < deadline:
            time.sleep(0.005)  # the robot's thread is withdrawing
        assert motion.abandoned
        started = time.monotonic()
        closed = robot.close(timeout_s=1.0)
        elapsed = time.monotonic() - started
    finally:
        robot.close(timeout_s=1.0)
        waiter.join(timeout=25)
    # The robot's thread stopped the command instead of waiting for the cancel's answer;
    # close() found it settled, within its timeout: nothing can run.
    assert closed is True
    assert elapsed < 1.0
    assert motion.stop_delivered is True
    assert [type(exc) for exc in ended] == [StopRequestedError]


def test_close_bounds_its_own_wait_for_a_withdraws_answer_by_its_timeout(
    tm_simulator_factory: SimFactory,
) -> None:
    # As above, with no other thread: close() withdraws the command itself, and the
    # program answers the cancel only 10 s later. close() waits up to its timeout_s for
    # the answer, then stops the command.
    sim = tm_simulator_factory("tmflow", faults=["late_ack:delay_s=400"])
    robot = Robot(
        sim.url,
        gripper=None,
        timeouts=TimeoutPolicy(ack_timeout_s=20),
        polling=PollPolicy(interval_s=0.01),
    )
    robot.connect()
    robot.wait_until_ready(5)
    motion = robot.start_move(APPROACH, speed=30)
    sim.wait_for(lambda: int(sim.field("seq")) == motion.ticket.seq, timeout=5)
    started = time.monotonic()
    closed = robot.close(timeout_s=0.3)
    assert time.monotonic() - started < 0.3 + SLACK_S
    assert closed is True
    assert motion.withdrawn is False
    assert motion.stop_delivered is True


def test_close_still_waits_for_its_own_withdraws_answer(
    tm_simulator_factory: SimFactory,
) -> None:
    # The program answers the cancel 0.2 s of wall time after the command: the close that
    # ends other threads' waits does not end its own, so the command is withdrawn, and
    # the project is not stopped.
    sim = tm_simulator_factory("tmflow", faults=["late_ack:delay_s=8"])
    robot = Robot(sim.url, gripper=None, polling=PollPolicy(interval_s=0.01))
    robot.connect()
    robot.wait_until_ready(5)
    motion = robot.start_move(APPROACH, speed=30)
    sim.wait_for(lambda: int(sim.field("seq")) == motion.ticket.seq, timeout=5)
    assert robot.close(timeout_s=5) is True
    assert motion.withdrawn is True
    assert motion.stop_delivered is None
