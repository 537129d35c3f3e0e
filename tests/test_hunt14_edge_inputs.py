"""Speed, acceleration, timeout and I/O arguments at their edges, on a connected robot.

docs/safety.md, "Validate, send nothing": every value is checked before the first byte.
``tests/test_bad_input.py`` holds a few edges of each argument against a Robot that never
connected (a tmflow one). Here the robot is connected, on both profiles, ready and at
rest, and every public verb gets each argument at its edges (0, negative, NaN,
infinity, an int too large for a float, a bool, a string, a fraction where an integer
is due, one past the range): each must raise ``ConfigError`` naming the argument, the
simulator must have seen no request at all (its request log), and the arm must not
have moved (its motion log). An awaited call (``aio.AsyncRobot``) runs the same checks.

Found by this hunt (fails without its fix): on ``article``, whose command block has no
acceleration time, ``accel_time_ms`` was taken and never sent. The master planned the
move with it (a 1500 ms ramp: the expected time and the motion timeout, ``motion.accel_s``)
while the robot ramped at its own 200 ms; a value outside 0..10000 ms (-1, 100000), which
docs/robot-api.md says is refused, ran the move, and 10**400 raised ``OverflowError``.
``accel_time_ms`` is now refused on a profile without the field, as ``speed_mm_s`` is,
before anything is read or sent. And ``dwell(1e10)`` (any time past a thread wait's
``threading.TIMEOUT_MAX``, 9.2e9 s) raised ``OverflowError`` at once instead of waiting
or naming ``seconds``: a dwell is now refused past 1e9 s (31 years).

Found later (helper H16, fails without its fix): ``move_by`` checked its speed, its
timeout and (tmflow) its acceleration time's range only after it had read the pose it
resolves the offset against, and ``move_arc`` its timeout after reading its start: a
read reached the robot before the ``ConfigError``. They are now checked with the other
move arguments (``Robot._move_arguments``) before any request. And ``Pose(numpy.True_,
...)`` was a pose at x = 1 mm: a coordinate is now a real number but a bool.
"""

from __future__ import annotations

import asyncio
import functools
import math
from collections.abc import Callable, Coroutine
from decimal import Decimal
from fractions import Fraction
from typing import Any

import pytest

from tmmaster import ConfigError, PollPolicy, Pose, Robot, aio
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]
NAN, INF = math.nan, math.inf
#: An int no float holds.
HUGE = 10**400
START = Pose(300, -200, 200, 180, 0, 90)
TARGET = Pose(320, -180, 220, 180, 0, 90)
VIA = Pose(330, -190, 200, 180, 0, 90)
READY = [0, 0, 90, 0, 90, 0]

#: Values no integer-percent speed may take.
BAD_SPEEDS = [0, -1, 101, 30.5, NAN, INF, HUGE, True, "30", [30]]
#: Values no timeout (a finite number of seconds > 0) may take.
BAD_TIMEOUTS = [0, -1, -0.0, NAN, INF, -INF, HUGE, True, False, "5", [5]]
#: Values no acceleration time (tmflow: an integer, 0 or TMflow's 150..9999 ms) may take.
BAD_ACCELS = [-1, 10001, 1.5, NAN, INF, HUGE, True, "200"]
#: Values no TCP speed (an integer 1..1100 mm/s on a TM5-700) may take.
BAD_MM_S = [0, -1, 1101, 99.5, NAN, INF, HUGE, True, "100"]

#: (verb, argument named, the call with one value, the bad values)
Case = tuple[str, str, Callable[[Robot, Any], object], list[Any]]


def _move_by(**kwargs: Any) -> Callable[[Robot, Any], object]:
    """``move_by(dz=10, ...)`` with the value as its one keyword argument."""
    (name,) = kwargs
    return lambda r, v: r.move_by(dz=10, **{name: v})


BOTH: list[Case] = [
    ("move_to", "speed", lambda r, v: r.move_to(TARGET, speed=v), BAD_SPEEDS),
    ("move_to", "timeout", lambda r, v: r.move_to(TARGET, timeout=v), BAD_TIMEOUTS),
    ("start_move", "speed", lambda r, v: r.start_move(TARGET, speed=v), BAD_SPEEDS),
    ("move_by", "dz", lambda r, v: r.move_by(dz=v), [NAN, INF, HUGE, True, "10", None]),
    ("gripper.close", "timeout_s", lambda r, v: r.gripper.close(timeout_s=v), BAD_TIMEOUTS),
    ("gripper.open", "timeout_s", lambda r, v: r.gripper.open(timeout_s=v), BAD_TIMEOUTS),
    ("wait_until_ready", "timeout_s", lambda r, v: r.wait_until_ready(v), BAD_TIMEOUTS),
    ("dwell", "seconds", lambda r, v: r.dwell(v), [-1, NAN, INF, True, "1", 1e10, 1e308]),
]
TMFLOW: list[Case] = [
    ("move_to", "accel_time", lambda r, v: r.move_to(TARGET, accel_time_ms=v), BAD_ACCELS),
    (
        "move_to",
        "speed_mm_s",
        lambda r, v: r.move_to(TARGET, motion="line", speed_mm_s=v),
        BAD_MM_S,
    ),
    ("move_by", "speed_mm_s", _move_by(speed_mm_s=None), BAD_MM_S),
    ("move_joints", "speed", lambda r, v: r.move_joints(READY, speed=v), BAD_SPEEDS),
    ("move_joints", "accel_time", lambda r, v: r.move_joints(READY, accel_time_ms=v), BAD_ACCELS),
    ("move_arc", "speed", lambda r, v: r.move_arc(VIA, TARGET, speed=v), BAD_SPEEDS),
    ("move_arc", "speed_mm_s", lambda r, v: r.move_arc(VIA, TARGET, speed_mm_s=v), BAD_MM_S),
    ("io.set_do", "DO", lambda r, v: r.io.set_do(v, True), [-1, 16, 1.0, True, "1"]),
    ("io.set_do", "value", lambda r, v: r.io.set_do(1, v), [0, 1, NAN, "True", None]),
    ("play", "timeout_s", lambda r, v: r.play(v), BAD_TIMEOUTS),
    ("pause", "timeout_s", lambda r, v: r.pause(v), BAD_TIMEOUTS),
]
#: article: its command block has no acceleration time, so any value is one the robot
#: would never get (the defect this hunt found: taken, planned with, never sent).
ARTICLE: list[Case] = [
    (
        "move_to",
        "accel_time_ms",
        lambda r, v: r.move_to(TARGET, accel_time_ms=v),
        [1500, 0, -1, 100000, HUGE, 1.5],
    ),
    ("start_move", "accel_time_ms", lambda r, v: r.start_move(TARGET, accel_time_ms=v), [1500]),
    ("move_by", "accel_time_ms", _move_by(accel_time_ms=None), [1500, -1, HUGE]),
]


def _params(cases: dict[str, list[Case]]) -> list[Any]:
    return [
        pytest.param(profile, named, call, values, id=f"{profile}-{verb}-{named}")
        for profile, listed in cases.items()
        for verb, named, call, values in listed
    ]


def ready_robot(factory: Factory, profile: str) -> tuple[Simulator, Robot]:
    """A connected robot moved to START, its simulator's request log cleared after."""
    sim = factory(profile)
    robot = Robot(sim.url, profile=profile, polling=PollPolicy(interval_s=0.01))
    robot.connect()
    robot.wait_until_ready(timeout_s=5)
    robot.move_to(START, speed=100)
    sim.clear_request_log()
    return sim, robot


def _refused_unsent(sim: Simulator, named: str, value: Any, call: Callable[[], object]) -> None:
    """``call()`` raises ConfigError naming ``named``; no request reached the robot."""
    sim.clear_request_log()
    moves = len(sim.motion_log())
    with pytest.raises(ConfigError) as refused:
        call()
    assert named in str(refused.value), f"{value!r}: {refused.value}"
    assert list(sim.request_log) == [], f"{value!r} sent {list(sim.request_log)}"
    assert len(sim.motion_log()) == moves


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: Factory) -> Factory:
    return memory_simulator_factory


@pytest.mark.parametrize(
    ("profile", "named", "call", "values"),
    _params({"tmflow": BOTH + TMFLOW, "article": BOTH + ARTICLE}),
)
def test_an_edge_value_is_refused_naming_it_before_any_request(
    tm_simulator_factory: Factory,
    profile: str,
    named: str,
    call: Callable[[Robot, Any], object],
    values: list[Any],
) -> None:
    sim, robot = ready_robot(tm_simulator_factory, profile)
    try:
        for value in values:
            _refused_unsent(sim, named, value, functools.partial(call, robot, value))
        robot.move_to(TARGET, speed=100)  # the robot still takes a good move, once
        assert sim.motion_log()[-1].target == TARGET
    finally:
        robot.close()


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_an_awaited_call_refuses_an_edge_value_before_any_request(
    tm_simulator_factory: Factory, profile: str
) -> None:
    sim, robot = ready_robot(tm_simulator_factory, profile)
    front = aio.AsyncRobot(robot)
    named = "accel_time" if profile == "tmflow" else "accel_time_ms"
    calls: list[tuple[str, Any, Callable[[], Coroutine[Any, Any, object]]]] = [
        ("speed", 0, lambda: front.move_to(TARGET, speed=0)),
        ("timeout", NAN, lambda: front.move_to(TARGET, timeout=NAN)),
        (named, -1, lambda: front.move_to(TARGET, accel_time_ms=-1)),
        ("dz", INF, lambda: front.move_by(dz=INF)),
        ("timeout_s", 0, lambda: front.gripper.close(timeout_s=0)),
    ]
    try:
        for name, value, call in calls:
            _refused_unsent(sim, name, value, functools.partial(asyncio.run, call()))
    finally:
        asyncio.run(front.close())


#: move_by's arguments whose range was checked only once the target was resolved (after
#: the read of the pose it is resolved against), until helper H16's fix.
RESOLVED_LATE: list[Case] = [
    ("move_by", "speed", _move_by(speed=None), BAD_SPEEDS),
    ("move_by", "timeout", _move_by(timeout=None), BAD_TIMEOUTS),
    ("move_by", "accel_time", _move_by(accel_time_ms=None), [-1, 10001]),
]
#: The same on a profile without an acceleration time (refused at once there).
RESOLVED_LATE_ARTICLE = RESOLVED_LATE[:2]


#: move_arc (tmflow) read its start, as move_by does, before it checked its timeout.
ARC_TIMEOUT: list[Case] = [
    ("move_arc", "timeout", lambda r, v: r.move_arc(VIA, TARGET, timeout=v), BAD_TIMEOUTS),
]


@pytest.mark.parametrize(
    ("profile", "named", "call", "values"),
    _params({"tmflow": RESOLVED_LATE + ARC_TIMEOUT, "article": RESOLVED_LATE_ARTICLE}),
)
def test_a_relative_move_refuses_its_speed_before_reading_the_pose(
    tm_simulator_factory: Factory,
    profile: str,
    named: str,
    call: Callable[[Robot, Any], object],
    values: list[Any],
) -> None:
    # Was a strict xfail (one value each): move_by checked its speed, its timeout and (on
    # tmflow) its acceleration time's range only after it read the pose it resolves
    # against, where its docstring says a bad speed is refused with nothing read or sent.
    sim, robot = ready_robot(tm_simulator_factory, profile)
    try:
        for value in values:
            _refused_unsent(sim, named, value, functools.partial(call, robot, value))
    finally:
        robot.close()


def test_a_numpy_bool_is_no_coordinate() -> None:
    # Was a strict xfail: Pose's coordinates are pydantic strict floats, which take any
    # object with __float__ but a bool or a str: numpy's bool passed as 1.0 mm (or 1 deg),
    # and the move then ran to x = 1 mm, where Pose's docstring says a coordinate is never
    # a bool. A coordinate is now a real number (numbers.Real) but a bool, so a 0-d array
    # and a Decimal (no numbers.Real) are refused as well.
    numpy = pytest.importorskip("numpy")
    for value in (numpy.True_, numpy.False_, numpy.array(True), numpy.array(2.0), Decimal(1)):
        with pytest.raises(ConfigError, match="x must be an int or float"):
            Pose(value, -200, 200, 180, 0, 90)


def test_numpy_numbers_and_fractions_stay_coordinates() -> None:
    numpy = pytest.importorskip("numpy")
    for value in (numpy.float64(300.5), numpy.float32(300.5), numpy.int64(300), Fraction(601, 2)):
        assert Pose(value, -200, 200, 180, 0, 90).x == float(value)
