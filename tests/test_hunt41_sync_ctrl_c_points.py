"""Hunt 41: a Ctrl-C landing at each request boundary of a synchronous Robot call.

Hunt 38 cancelled each ``tmmaster.aio`` call at each of its requests; this is the
synchronous analogue. Each call of ``Robot`` (``move_to`` PTP and Line, also as the
Robot's first command, ``move_arc``, ``move_joints``, ``move_by``, ``start_move`` +
``wait``, a started move's ``wait()``, ``gripper.close()``/``open()``, ``play()`` (of a
stopped project and of a paused move), ``pause()`` (idle and of a moving arm),
``stop()``, ``io.set_do()`` and ``close()`` itself), on both profiles where the call
exists, takes a Ctrl-C (``signal.raise_signal(SIGINT)``: a KeyboardInterrupt in the main
thread) right before or right after one of its Modbus requests, the request named by its
function code and address and its occurrence within the call (never a global count): the
first occurrence of each request the call makes, and the second where it repeats (a
wait's second poll, a press's first poll after the press).

Where the boundary is: a request the main thread hands to the driver's loop
(``LoopTransport._hand_over``: a write, a single read, the first and last read of a
chained read) takes it in the main thread itself, before the hand-over (nothing sent)
or after its answer came back (the answer lost with the Ctrl-C). A request the loop
sends on its own (the polls of a wait, which run on the loop; a chained read's middle
reads) raises SIGINT from the loop thread at that point and holds the loop there until
the main thread's handler ran (or a ``deferred`` section recorded it), so the Ctrl-C
lands while the loop sits exactly at that boundary.

Then the KeyboardInterrupt leaves the ``with Robot(...)`` block (its close must withdraw
or stop what the call left), the simulator runs 20 ticks and 5 more, and:

- the KeyboardInterrupt came out of the call (never swallowed, never late);
- no motion started after it came out, except the call's own command when its write
  had gone (then it is stopped or finished, and close() says True);
- nothing started after close() ended, but the robot acting on a write of the call's
  answered before the Ctrl-C (``Case.acts_on``); no motion ran twice
  (``safety_invariant.check``); the arm is at rest; a move believed done is at its
  target, and one that ran is not said withdrawn;
- a new Robot on the same simulator moves once, from where the arm is, to its end;
- no thread, socket or default-driver share is left (the suite's ``no_leaks``).

``TMMASTER_HUNT41=full`` runs every point (372 boundaries, and a guard that the points
are every request each call makes: about 2.5 min on two busy cores, ``-n 2``); by default
the compact subset below and the regressions (about 9 s).

Found (hunt 41), the full matrix: the synchronous API gave every call up as documented
at every boundary, on both profiles; nothing ran late or twice, close() told the truth,
no thread or driver share was left. One defect, in the simulator: it acted on the Stop
and Play/Pause coils pressed within one robot tick in a fixed order, Stop first, where
TMflow takes each press as received. A Ctrl-C right after ``pause()``'s press was
answered (or before its first poll) of a moving arm: ``pause()`` presses Stop on giving
up, both presses landed in one tick, the simulator stopped the project and then toggled
the stopped project, which is Play: it started over while the arm braked, the robot
program failed (ChangeTCP while the arm moves: robot error) and the next Robot's
``play()`` raised RobotFaultError (``pause moving-5@7104#1-after``, and the polls after
the press when they fell in the same tick). Fixed in ``sim/_sequence.py`` (presses in the
order written), with ``test_a_pause_then_a_stop_within_one_tick_pause_then_stop`` and
``test_a_ctrl_c_right_after_a_pause_press_of_a_moving_arm_leaves_the_robot_usable``.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from types import FrameType
from typing import Any

import pytest

from safety_invariant import Issued, check, wait_braked
from test_interrupt_ctrl_c_race import NEEDS_MAIN_THREAD_CTRL_C
from tmmaster import Motion, PollPolicy, Pose, ProjectState, Robot, TimeoutPolicy
from tmmaster._fleet import LoopTransport, _ChainedRead
from tmmaster._registers import Table
from tmmaster.sim import MotionRecord, Simulator
from tmmaster.sim._sequence import SequenceController

Factory = Callable[..., Simulator]
Point = tuple[int, int]  # function code, address

START = Pose(300, -200, 150, 180, 0, 90)
END = Pose(300, -200, 180, 180, 0, 90)
NEXT = Pose(280, -180, 165, 180, 0, 90)
VIA = Pose(320, -170, 165, 180, 0, 90)
ARC_END = Pose(300, -140, 150, 180, 0, 90)
JOINTS = (10.0, -5.0, 100.0, -5.0, 90.0, 10.0)
#: Robot ticks the simulator runs after the close: a command left armed is taken by then.
AFTER_TICKS = 20
#: How long the loop waits at a boundary for the main thread to take the Ctrl-C, s.
LAND_S = 2.0
#: The simulator's time scale: a move of 30 mm at 20 % lasts a few polls.
SLOW = 8.0


@dataclass
class CtrlC:
    """Raises SIGINT at one request boundary of the call under test; records the call's
    requests (function code, address) in the order sent."""

    point: Point | None = None
    occurrence: int = 1
    when: str = "before"
    active: bool = False
    seen: list[Point] = field(default_factory=list)
    fired: bool = False
    landed: threading.Event = field(default_factory=threading.Event)
    #: Loop-side boundaries whose Ctrl-C the main thread did not take in time.
    unlanded: int = 0

    def handler(self, _signum: int, _frame: FrameType | None) -> None:
        """Python's own Ctrl-C, noting that it landed."""
        self.landed.set()
        raise KeyboardInterrupt

    def boundary(self, point: Point, when: str) -> None:
        """At ``when`` ("before"/"after") of a request to ``point`` of the call."""
        if not self.active:
            return
        if when == "before":
            self.seen.append(point)
        if self.fired or point != self.point or when != self.when:
            return
        if self.seen.count(point) != self.occurrence:
            return
        self.fired = True
        self.active = False  # the call's requests end here: the clean-up is not counted
        signal.raise_signal(signal.SIGINT)
        if threading.current_thread() is threading.main_thread():
            return  # raised at the next bytecode, here
        # The loop: held at this boundary until the main thread took the Ctrl-C (or a
        # deferred section recorded it: it is delivered when that section ends).
        deadline = time.monotonic() + LAND_S
        while not self.landed.is_set() and time.monotonic() < deadline:
            if getattr(signal.getsignal(signal.SIGINT), "deferring", False):
                time.sleep(0.06)  # past the main thread's slice: recorded by now
                return
            time.sleep(0.0005)
        if not self.landed.is_set():
            self.unlanded += 1


@pytest.fixture
def ctrl_c(monkeypatch: pytest.MonkeyPatch) -> Iterator[CtrlC]:
    """The boundaries hooked; Python's Ctrl-C handler that notes where it landed."""
    if NEEDS_MAIN_THREAD_CTRL_C.args[0]:  # the skipif's condition
        pytest.skip(NEEDS_MAIN_THREAD_CTRL_C.kwargs["reason"])
    at = CtrlC()
    hand_over, chained_next, chained_read = (
        LoopTransport._hand_over,
        _ChainedRead.next,
        _ChainedRead._read,
    )

    def on_hand_over(
        self: LoopTransport, what: str, bound: float, latch: Any, start: Any, *args: Any
    ) -> Any:
        if not at.active or threading.current_thread() is not threading.main_thread():
            return hand_over(self, what, bound, latch, start, *args)
        chain = getattr(start, "__self__", None)
        if isinstance(chain, _ChainedRead):
            chain.from_main = True  # type: ignore[attr-defined]
        points = hand_over_points(self, start, args)
        if points:
            at.boundary(points[0], "before")
        result = hand_over(self, what, bound, latch, start, *args)
        if points and (not isinstance(chain, _ChainedRead) or len(result[0]) == len(points)):
            at.boundary(points[-1], "after")
        return result

    def on_next(self: _ChainedRead) -> None:
        index = len(self.answers)
        first_of_main = index == 0 and getattr(self, "from_main", False)
        if index < len(self.requests) and self.transport._link.connected and not first_of_main:
            _what, code, block = self.requests[index]
            at.boundary((code, block.address), "before")
        chained_next(self)

    def on_read(self: _ChainedRead, words: list[int]) -> None:
        index = len(self.answers)
        _what, code, block = self.requests[index]
        last_of_main = index == len(self.requests) - 1 and getattr(self, "from_main", False)
        if len(words) == block.count and not last_of_main:
            at.boundary((code, block.address), "after")
        chained_read(self, words)

    monkeypatch.setattr(LoopTransport, "_hand_over", on_hand_over)
    monkeypatch.setattr(_ChainedRead, "next", on_next)
    monkeypatch.setattr(_ChainedRead, "_read", on_read)
    previous = signal.signal(signal.SIGINT, at.handler)
    try:
        yield at
    finally:
        at.active = False
        signal.signal(signal.SIGINT, previous)


def hand_over_points(transport: LoopTransport, start: Any, args: tuple[Any, ...]) -> list[Point]:
    """The requests a hand-over to the driver's loop sends (``LoopTransport._hand_over``'s
    ``start`` and its ``args``), as (function code, address): every block of a chained
    read, or the link's one request; none for any other job (a connect, a close)."""
    chain = getattr(start, "__self__", None)
    if isinstance(chain, _ChainedRead):
        return [(code, block.address) for _what, code, block in chain.requests]
    return [(args[1], args[2])] if start == transport._link.start else []


def let_run(sim: Simulator, ticks: int) -> None:
    start = sim.ticks
    sim.wait_for(lambda: sim.ticks >= start + ticks, timeout=5.0)


def open_robot(sim: Simulator) -> Robot:
    return Robot(
        "127.0.0.1",
        sim.port,
        profile=sim.profile,
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(request_s=2.0, ack_timeout_s=2.0, gripper_settle_s=0.05),
    )


Call = Callable[[Robot], Any]
Before = Callable[[Robot, Simulator], Any]


@dataclass(frozen=True)
class Case:
    call: Call
    #: The (point, occurrence) boundaries to take the Ctrl-C at: each request the call
    #: makes (recorded on the simulator, ``test_the_points_are_the_requests_the_call_makes``),
    #: its first occurrence, and its second where it repeats.
    points: tuple[tuple[Point, int], ...]
    #: The pose the call (or ``before``) sends the arm to, if any.
    target: Pose | None = None
    #: Made before the call (a move started, a project stopped or paused).
    before: Before | None = None
    #: The gripper action the call starts ("gripper_close"/"gripper_open"), if any.
    grip: str | None = None
    #: The write the robot acts on a tick after its answer, so after a Ctrl-C that came
    #: after that answer possibly after close() too: the article's gripper register
    #: (``LEVEL_WRITE``: a level, like a digital output, it holds, docs/safety.md,
    #: "Digital outputs"), the Play/Pause coil.
    acts_on: Point | None = None
    #: The motion kind the call starts, where its target is no pose issued here (joints).
    kind: str | None = None
    #: The call is the Robot's first command (it claims the robot: the heartbeat's first beat).
    first: bool = False


_STARTED: dict[int, Motion] = {}


def _start(robot: Robot, sim: Simulator) -> None:
    """A move under way (seen in the simulator's motion log)."""
    count = len(sim.motion_log())
    _STARTED[id(robot)] = robot.start_move(END, speed=5)
    sim.wait_for(lambda: len(sim.motion_log()) > count, timeout=5)


def _paused(robot: Robot, sim: Simulator) -> None:
    """A move under way, paused (the robot still follows it: Play may resume it)."""
    _start(robot, sim)
    robot.pause()


def _stopped(robot: Robot, sim: Simulator) -> None:
    robot.stop()
    wait_braked(sim, ticks=3)


def _points(*requests: Point) -> tuple[tuple[Point, int], ...]:
    """Each request's first occurrence, and its second where ``requests`` repeats it."""
    seen: list[Point] = []
    points: list[tuple[Point, int]] = []
    for point in requests:
        seen.append(point)
        if seen.count(point) <= 2:
            points.append((point, seen.count(point)))
    return tuple(points)


TM_POLL = ((3, 9100), (2, 7201), (2, 7207))
TM_MOVE = ((3, 9015), (16, 9000), *TM_POLL, *TM_POLL, (4, 7001))
#: The first command: the robot claimed (its session read, the first beat), the arm read.
TM_CLAIM = ((3, 9052), (16, 9050), (2, 7201), (2, 7207), (3, 9015), (3, 9100), (4, 7001))
TM_FIRST = (*TM_CLAIM, (16, 9000), *TM_POLL, *TM_POLL, (4, 7001))
TM_GRIP = ((3, 9015), (16, 9014), *TM_POLL, *TM_POLL, (3, 9105))
TM_PROJECT = ((3, 9100), (4, 7013), (4, 7101), (4, 7320), (2, 7201), (2, 7207))
#: The Play/Pause coil.
PRESS = (5, 7104)
TM_PRESS = (*TM_PROJECT, (5, 7104), *TM_PROJECT, *TM_PROJECT)
AR_MOVE = ((3, 512), (16, 512), (3, 519), (3, 0), (3, 0))
AR_GRIP = ((3, 0), (16, 528), (3, 0), (3, 0))
#: The article's gripper register write.
LEVEL_WRITE = (16, 528)


def _move_to(robot: Robot) -> Motion:
    return robot.move_to(END, speed=20)


def _line(robot: Robot) -> Motion:
    return robot.move_to(END, speed=20, motion="line")


def _move_by(robot: Robot) -> Motion:
    return robot.move_by(dz=30, motion="line", speed=20)


def _arc(robot: Robot) -> Motion:
    return robot.move_arc(VIA, ARC_END, speed_mm_s=100)


def _joints(robot: Robot) -> Motion:
    return robot.move_joints(JOINTS, speed=20)


def _start_wait(robot: Robot) -> None:
    robot.start_move(END, speed=20).wait()


def _play(robot: Robot) -> ProjectState:
    return robot.play()


def _wait(robot: Robot) -> None:
    _STARTED[id(robot)].wait()


CASES: dict[tuple[str, str], Case] = {
    ("tmflow", "move_to ptp"): Case(_move_to, _points(*TM_MOVE), END),
    ("tmflow", "move_to line"): Case(_line, _points(*TM_MOVE), END),
    ("tmflow", "move_to first"): Case(_move_to, _points(*TM_FIRST), END, first=True),
    ("tmflow", "move_arc"): Case(_arc, _points((4, 7001), *TM_MOVE), ARC_END),
    ("tmflow", "move_joints"): Case(_joints, _points(*TM_MOVE), kind="ptp_joints"),
    ("tmflow", "move_by"): Case(_move_by, _points((4, 7001), *TM_MOVE), END),
    ("tmflow", "start_move+wait"): Case(_start_wait, _points(*TM_MOVE), END),
    ("tmflow", "motion.wait"): Case(_wait, _points(*TM_POLL, *TM_POLL, (4, 7001)), END, _start),
    ("tmflow", "gripper.close"): Case(
        lambda r: r.gripper.close(), _points(*TM_GRIP), grip="gripper_close"
    ),
    ("tmflow", "gripper.open"): Case(
        lambda r: r.gripper.open(), _points(*TM_GRIP), grip="gripper_open"
    ),
    ("tmflow", "stop"): Case(lambda r: r.stop(), _points((5, 7105)), END, _start),
    ("tmflow", "io.set_do"): Case(lambda r: r.io.set_do(1, True), _points((5, 1))),
    ("tmflow", "play"): Case(_play, _points(*TM_PRESS), before=_stopped),
    ("tmflow", "play paused move"): Case(_play, _points(*TM_PRESS), END, _paused, acts_on=PRESS),
    ("tmflow", "pause"): Case(lambda r: r.pause(), _points(*TM_PRESS)),
    ("tmflow", "pause moving"): Case(lambda r: r.pause(), _points(*TM_PRESS), END, _start),
    ("tmflow", "close"): Case(
        lambda r: r.close(),
        _points(*TM_POLL, (5, 7105), (16, 9014)),
        END,
        _start,
    ),
    ("article", "move_to ptp"): Case(_move_to, _points(*AR_MOVE), END),
    ("article", "move_to line"): Case(_line, _points(*AR_MOVE), END),
    ("article", "move_by"): Case(_move_by, _points((3, 16), *AR_MOVE), END),
    ("article", "start_move+wait"): Case(_start_wait, _points(*AR_MOVE), END),
    ("article", "motion.wait"): Case(_wait, _points((3, 519), (3, 0), (3, 0)), END, _start),
    ("article", "gripper.close"): Case(
        lambda r: r.gripper.close(), _points(*AR_GRIP), grip="gripper_close", acts_on=LEVEL_WRITE
    ),
    ("article", "gripper.open"): Case(
        lambda r: r.gripper.open(), _points(*AR_GRIP), grip="gripper_open", acts_on=LEVEL_WRITE
    ),
    ("article", "stop"): Case(lambda r: r.stop(), _points((16, 519)), END, _start),
    ("article", "close"): Case(
        lambda r: r.close(), _points((3, 519), (3, 0), (16, 519)), END, _start
    ),
}


def _ready(robot: Robot, sim: Simulator) -> None:
    """Ready to move: the project running (tmflow), the arm at rest (as the simulator
    sees it: ``wait_until_at_rest()`` takes half a second at least)."""
    if sim.profile.name == "tmflow" and robot.project_state() is not ProjectState.RUNNING:
        robot.play()
    robot.wait_until_ready(timeout_s=5)
    wait_braked(sim, ticks=3)


def _record(sim: Simulator, case: Case, ctrl_c: CtrlC) -> list[Point]:
    """The call's requests, in order, run once without a Ctrl-C."""
    with open_robot(sim) as robot:
        _ready(robot, sim)
        if not case.first:
            robot.move_to(START, speed=100)
        if case.before is not None:
            case.before(robot, sim)
        ctrl_c.seen.clear()
        ctrl_c.active = True
        try:
            case.call(robot)
        finally:
            ctrl_c.active = False
    return list(ctrl_c.seen)


FULL = os.environ.get("TMMASTER_HUNT41") == "full"


@pytest.mark.skipif(not FULL, reason="TMMASTER_HUNT41=full: every call run once (about 16 s)")
@pytest.mark.parametrize(("profile", "name"), list(CASES))
def test_the_points_are_the_requests_the_call_makes(
    tm_simulator_factory: Factory, ctrl_c: CtrlC, profile: str, name: str
) -> None:
    sim = tm_simulator_factory(profile, time_scale=SLOW)
    seen = _record(sim, CASES[(profile, name)], ctrl_c)
    missing = set(_points(*seen)) - set(CASES[(profile, name)].points)
    assert not missing, f"{name} makes requests no point covers: {sorted(missing)} of {seen}"


def _all_points() -> Iterator[Any]:
    for (profile, name), case in CASES.items():
        for point, occurrence in case.points:
            for when in ("before", "after"):
                ident = f"{profile}-{name}-{point[0]}@{point[1]}#{occurrence}-{when}"
                yield pytest.param(profile, name, point, occurrence, when, id=ident)


#: The points run by default (about 10 s with the regressions below): a command write
#: answered, then the Ctrl-C (main thread); a wait's poll (the loop, held there) and a
#: chained read's middle request; a gripper command's write; Play on a paused move and
#: Pause of a moving arm just after the press; close()'s Stop (a deferred section); the
#: article's command write and its gripper register.
COMPACT = {
    "tmflow-move_to ptp-16@9000#1-after",
    "tmflow-start_move+wait-3@9100#2-before",
    "tmflow-motion.wait-2@7201#1-after",
    "tmflow-gripper.close-16@9014#1-after",
    "tmflow-play paused move-5@7104#1-after",
    "tmflow-pause moving-3@9100#2-before",
    "tmflow-close-5@7105#1-after",
    "article-move_by-16@512#1-after",
    "article-gripper.open-16@528#1-after",
}


def _subset() -> list[Any]:
    return [p for p in _all_points() if FULL or p.id in COMPACT]


def _own(case: Case, record: Any) -> bool:
    """Whether a motion the simulator ran is the call's own command."""
    if case.grip is not None or case.kind is not None:
        return bool(record.kind in (case.grip, case.kind))
    target = record.target
    aim = case.target
    return aim is not None and target is not None and target.distance_to(aim) <= 0.05


@pytest.mark.parametrize(("profile", "name", "point", "occurrence", "when"), _subset())
def test_a_ctrl_c_at_a_request_boundary_leaves_nothing_to_run(
    tm_simulator_factory: Factory,
    ctrl_c: CtrlC,
    profile: str,
    name: str,
    point: Point,
    occurrence: int,
    when: str,
) -> None:
    case = CASES[(profile, name)]
    sim = tm_simulator_factory(profile, time_scale=SLOW)
    issued = [] if case.first else [Issued(START, 0.0, 0.0, "done")]
    closes: list[bool] = []
    robot = open_robot(sim)
    real_close = robot.close

    def close(**kwargs: Any) -> bool:
        closes.append(safely := real_close(**kwargs))
        return safely

    robot.close = close  # type: ignore[method-assign]
    out: float | None = None
    raised = False
    count = first = 0
    try:
        with robot:
            _ready(robot, sim)
            if not case.first:
                robot.move_to(START, speed=100)
            if case.target is not None:
                issued.append(Issued(case.target, time.monotonic()))
            first = len(sim.motion_log())
            if case.before is not None:
                case.before(robot, sim)
            count = len(sim.motion_log())
            ctrl_c.point, ctrl_c.occurrence, ctrl_c.when = point, occurrence, when
            ctrl_c.seen.clear()
            ctrl_c.active = True
            try:
                case.call(robot)
            except KeyboardInterrupt:
                out = time.monotonic()
                raise
            finally:
                ctrl_c.active = False
    except KeyboardInterrupt:
        raised = True
    closed_at = time.monotonic()
    assert ctrl_c.fired, f"the call never reached {point}#{occurrence}: {ctrl_c.seen}"
    assert raised, "the Ctrl-C was swallowed"
    assert out is not None, "the KeyboardInterrupt came out of the close, not the call"
    assert ctrl_c.unlanded == 0, "the main thread did not take the Ctrl-C at the boundary"
    if case.target is not None:
        issued[-1].ended_at, issued[-1].outcome = closed_at, "KeyboardInterrupt"
    let_run(sim, AFTER_TICKS)
    log = sim.motion_log()
    late = [m for m in log[count:] if m.wall_time > out]
    assert all(_own(case, m) for m in late), f"started after the Ctrl-C: {late}"
    assert len(late) <= 1, f"more than one motion after the Ctrl-C: {late}"
    rest = sim.tcp_pose()
    after_close = [
        m for m in log if m.wall_time > closed_at and not _acted_late(case, m, ctrl_c, rest)
    ]
    assert not after_close, f"started after close(): {after_close}"
    let_run(sim, 5)
    assert sim.tcp_pose().is_close(rest, mm=0.01, deg=0.01), "the arm moves on"
    assert closes, "close() never ran"
    assert closes[-1] is True, f"close() said {closes}"
    motion = robot.last_motion
    ran = [m for m in log[first:] if _own(case, m)]
    aim = None if motion is None else motion.target
    if motion is not None and aim is not None and case.target is not None and aim == case.target:
        at_target = rest.is_close(case.target, mm=0.1)
        if motion.done:
            assert at_target, f"believed done at {rest}, short of {case.target}"
        if ran and not at_target:
            assert motion.withdrawn is not True, f"said withdrawn, but it ran: {motion}"
            assert motion.stop_delivered is True or motion.done, motion
    next_robot_moves(sim, issued, open_robot(sim))
    check(issued, _not_resumed(sim.motion_log(), case))


def next_robot_moves(sim: Simulator, issued: list[Issued], again: Robot) -> None:
    """A new Robot (``again``, closed here) on the same simulator moves once, from where
    the arm is, to its end."""
    with again:
        _ready(again, sim)
        here = sim.tcp_pose()
        issued.append(Issued(NEXT, time.monotonic()))
        moved = again.move_to(NEXT, speed=100)
        issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "done"
        assert moved.start is not None
        assert moved.start.is_close(here, mm=1.0, deg=0.5), (moved.start, here)
        assert sim.tcp_pose().is_close(NEXT, mm=0.05, deg=0.05)


def _acted_late(case: Case, record: MotionRecord, ctrl_c: CtrlC, rest: Pose) -> bool:
    """Whether ``record`` is the robot acting, a tick after close(), on the call's own
    write answered before the Ctrl-C: the level gripper register (it holds), or a Play
    press resuming the paused move, then stopped in the same tick by the Stop that the
    give-up pressed after it (never finished, the arm short of the target)."""
    if case.acts_on is None or case.acts_on not in ctrl_c.seen or not _own(case, record):
        return False
    if (ctrl_c.point, ctrl_c.when) == (case.acts_on, "before"):
        return False  # the Ctrl-C came before that write: nothing was sent
    if case.acts_on == LEVEL_WRITE:
        return True
    target = record.target
    return target is not None and record.done_wall_time is None and not rest.is_close(target)


def _not_resumed(log: tuple[MotionRecord, ...], case: Case) -> list[MotionRecord]:
    """The motion log without a paused move's resumption (the simulator records it anew,
    with the command's number): only ``play()`` of a paused move resumes one."""
    kept: list[MotionRecord] = []
    for record in log:
        if record.seq and any(k.seq == record.seq and k.kind == record.kind for k in kept):
            assert case.before is _paused, f"a move resumed: {record}"
            continue
        kept.append(record)
    if case.kind is None:
        return kept
    # A joint move's target is no pose issued here: once at most, judged by the checks above.
    own = [k for k in kept if k.kind == case.kind]
    assert len(own) <= 1, f"the joint move ran {len(own)} times: {own}"
    return [k for k in kept if k.kind != case.kind]


class HeldButtons:
    """The simulator's Stop and Play/Pause coils left unread while ``held``: presses
    written meanwhile are all acted on at the first tick after, as presses that land within
    one robot tick are."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.held = False
        real = SequenceController._handle_buttons

        def handle(controller: SequenceController) -> None:
            if not self.held:
                real(controller)

        monkeypatch.setattr(SequenceController, "_handle_buttons", handle)


def test_a_pause_then_a_stop_within_one_tick_pause_then_stop(
    tm_simulator_factory: Factory, monkeypatch: pytest.MonkeyPatch
) -> None:
    """TMflow acts on each button press as received (coil 7104 Play/Pause "triggered as
    1 received"). The simulator acted on the presses of a tick in a fixed order, Stop
    first: a Pause and then a Stop written within one tick (pause() given up just after
    its press was answered, a Ctrl-C: the master presses Stop at once) stopped the
    project, then toggled the stopped project, which is Play: it started over while the
    arm still braked, and the robot program failed (ChangeTCP while the arm moves: robot
    error), so the next Robot's play() raised RobotFaultError. Now in the order written."""
    buttons = HeldButtons(monkeypatch)
    sim = tm_simulator_factory("tmflow", time_scale=SLOW)
    with open_robot(sim) as robot:
        _ready(robot, sim)
        robot.move_to(START, speed=100)
        _start(robot, sim)
        buttons.held = True
        robot._transport.write_block(Table.COIL, 7104, [1], retry=False)  # Pause
        robot._transport.write_block(Table.COIL, 7105, [1], retry=False)  # then Stop
        buttons.held = False
        let_run(sim, 3)
        assert robot.project_state() is ProjectState.STOPPED
        wait_braked(sim, ticks=3)
        let_run(sim, 10)
        assert robot.project_state() is ProjectState.STOPPED  # not started over
        assert robot.status().error is False
    assert len(sim.motion_log()) == 2


def test_a_stop_then_a_play_within_one_tick_starts_the_project_over(
    tm_simulator_factory: Factory, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The other order, as written: a press landing after a Stop (hunt 38's late press)
    is Play on the stopped project, which starts over (docs/safety.md)."""
    buttons = HeldButtons(monkeypatch)
    sim = tm_simulator_factory("tmflow", time_scale=SLOW)
    with open_robot(sim) as robot:
        _ready(robot, sim)
        buttons.held = True
        robot._transport.write_block(Table.COIL, 7105, [1], retry=False)  # Stop
        robot._transport.write_block(Table.COIL, 7104, [1], retry=False)  # then the toggle
        buttons.held = False
        let_run(sim, 3)
        assert robot.project_state() is ProjectState.RUNNING


def test_a_ctrl_c_right_after_a_pause_press_of_a_moving_arm_leaves_the_robot_usable(
    tm_simulator_factory: Factory, ctrl_c: CtrlC, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The matrix's ``pause moving-5@7104#1-after`` (and the status polls after the
    press), made deterministic: the Pause press and the Stop that pause() presses on
    giving up act in one robot tick. The next Robot found the robot in error."""
    buttons = HeldButtons(monkeypatch)
    sim = tm_simulator_factory("tmflow", time_scale=SLOW)
    issued = [Issued(START, 0.0, 0.0, "done"), Issued(END, time.monotonic())]
    robot = open_robot(sim)
    raised = False
    try:
        with robot:
            _ready(robot, sim)
            robot.move_to(START, speed=100)
            _start(robot, sim)
            ctrl_c.point, ctrl_c.when, ctrl_c.active = PRESS, "after", True
            buttons.held = True
            try:
                robot.pause()
            finally:
                buttons.held = False
    except KeyboardInterrupt:
        raised = True
    assert raised
    issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "KeyboardInterrupt"
    assert ctrl_c.fired
    motion = robot.last_motion
    assert motion is not None
    # The Stop that pause() pressed on giving up ended the move: close() stopped it again
    # (True), or, its poll coming after the tick that Stop took effect in (a loaded
    # machine), found it ended by the robot (None: nothing left to stop). Never False.
    assert motion.stop_delivered is not False, motion
    let_run(sim, AFTER_TICKS)
    with open_robot(sim) as again:
        _ready(again, sim)
        issued.append(Issued(NEXT, time.monotonic()))
        again.move_to(NEXT, speed=100)
        issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "done"
    check(issued, sim.motion_log())
