"""Hunt 38: an awaited call cancelled at each point of its request sequence.

Earlier hunts (8, 22, 27, 32) cancelled awaited moves at a few chosen moments. Here a
matrix: each public coroutine of ``aio.AsyncRobot`` (and of its gripper and a started
move's handle), on each profile where it exists, is cancelled (``task.cancel()``, or an
``asyncio.timeout`` made to expire then) while one request of its sequence is in flight:
a FaultProxy holds that request (``hold``: the frame stuck in the network, landing only
after the ``CancelledError``) or its answer (``delay_answer``: executed, answer late),
both released by the test once the cancel reached the robot (its stop request set). The
point is the function code and address of the request (the first of the call's), never a
count or a sleep.

What must hold after each cancel, judged on the simulator:

- nothing the robot does starts after the ``CancelledError`` reached the caller (the
  motion log, ``safety_invariant.check`` for the moves), and the arm is still some
  ticks later (nothing resumed, no late frame ran);
- the same AsyncRobot's next move (after Play on tmflow) runs once, from where the arm
  is, to its end;
- no thread, task or socket is left (the suite's ``no_leaks``).

And the clean-up itself cancelled again (a second ``task.cancel()``) while its withdraw
or Stop is in flight: the ``CancelledError`` comes only after it, and the move is given
up; ``close()`` cancelled twice while its Stop is in flight; ``connect()`` cancelled at
each of its reads. ``TMMASTER_HUNT38=full`` runs every point (327 cases, about 5 min on
two busy cores); by default the compact subset below (about 8 s).

Found (hunt 38), the full matrix run on both profiles: the aio layer gave every move,
gripper command and wait up as documented at every point, and nothing ran late or
twice. One defect, in the press of a TMflow project: a ``pause()`` or ``play()``
cancelled while its press (coil 7104) was in flight pressed Stop, the press then landed
after that Stop and started the project over (documented), and the same robot's next
``play()`` waited its whole timeout for its own Stop to show, then raised RobotError
and pressed Stop (7 of the 8 press points): fixed, with
``test_the_next_play_after_a_cancelled_pause_whose_press_landed_late_runs``.
"""

from __future__ import annotations

import asyncio
import os
import threading
import time
from collections.abc import Callable, Coroutine, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import pytest

import tmmaster
from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, check
from test_aio import NOTHING_LATER_TICKS, given_up, run, ticks_pass, until
from tmmaster import PollPolicy, Pose, ProjectState, TimeoutPolicy, aio
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]
START = Pose(300, -200, 150, 180, 0, 90)
END = Pose(300, -200, 180, 180, 0, 90)
NEXT = Pose(250, 0, 160, 180, 0, 90)
VIA = Pose(320, -170, 165, 180, 0, 90)
ARC_END = Pose(300, -140, 150, 180, 0, 90)
JOINTS = (10.0, -5.0, 100.0, -5.0, 90.0, 10.0)
Point = tuple[int, int]  # function code, address

Call = Callable[[aio.AsyncRobot], Coroutine[Any, Any, Any]]


@dataclass(frozen=True)
class Case:
    call: Call
    #: The requests of the call, in order (tests/hunt38: recorded on the simulator).
    points: tuple[Point, ...]
    #: The pose the call sends the arm to (for ``check``), if any.
    target: Pose | None = None
    #: Made before the call (a started move whose wait or progress is the call).
    before: Callable[[aio.AsyncRobot], Coroutine[Any, Any, Any]] | None = None
    #: The project is stopped first (Play's subject).
    stopped: bool = False
    #: The move ``before`` starts never ends by itself (a stall): a cancel finds it under
    #: way, on a loaded machine too (5 % at 40x, 21 ms, ended first beside four CPU hogs).
    stall: bool = False


_HANDLE: dict[int, aio.AsyncMotion] = {}


async def _started(robot: aio.AsyncRobot) -> None:
    # 21 ms of wall time at 40x: the cases that cancel it stall it first (Case.stall),
    # so that it is under way still when the cancel comes, on a loaded machine too.
    _HANDLE[id(robot)] = await robot.start_move(END, speed=5)


def _handle(robot: aio.AsyncRobot) -> aio.AsyncMotion:
    return _HANDLE[id(robot)]


MOVE = ((3, 9015), (16, 9000), (3, 9100), (2, 7201), (2, 7207), (4, 7001))
POLL = ((3, 9100), (2, 7201), (2, 7207))
PROJECT = ((3, 9100), (4, 7013), (4, 7101), (4, 7320), (2, 7201), (2, 7207))
CASES: dict[tuple[str, str], Case] = {
    ("tmflow", "move_to"): Case(lambda r: r.move_to(END, speed=20), MOVE, END),
    ("tmflow", "move_by"): Case(
        lambda r: r.move_by(dz=30, motion="line", speed=20), ((4, 7001), *MOVE), END
    ),
    ("tmflow", "move_joints"): Case(lambda r: r.move_joints(JOINTS, speed=20), MOVE),
    ("tmflow", "move_arc"): Case(
        lambda r: r.move_arc(VIA, ARC_END, speed_mm_s=100), ((4, 7001), *MOVE[:-1]), ARC_END
    ),
    ("tmflow", "start_move"): Case(lambda r: r.start_move(END, speed=20), MOVE[:2], END),
    ("tmflow", "motion.wait"): Case(lambda r: _handle(r).wait(), (*POLL, (4, 7001)), END, _started),
    ("tmflow", "await motion"): Case(lambda r: _await(_handle(r)), POLL, END, _started),
    ("tmflow", "motion.progress"): Case(
        lambda r: _handle(r).progress(), (*POLL, (4, 7025)), END, _started
    ),
    ("tmflow", "motion.cancel"): Case(
        lambda r: _handle(r).cancel(), (*POLL, (16, 9014)), END, _started, stall=True
    ),
    ("tmflow", "wait_until_ready"): Case(lambda r: r.wait_until_ready(timeout_s=5), PROJECT),
    ("tmflow", "wait_until_at_rest"): Case(
        lambda r: r.wait_until_at_rest(), ((3, 9100), (4, 7013), (4, 7949))
    ),
    ("tmflow", "gripper.close"): Case(
        lambda r: r.gripper.close(), ((3, 9015), (16, 9014), (3, 9100), (2, 7201), (3, 9105))
    ),
    ("tmflow", "stop"): Case(lambda r: r.stop(), ((5, 7105),)),
    ("tmflow", "pause"): Case(lambda r: r.pause(), (*PROJECT[:1], (5, 7104))),
    ("tmflow", "play"): Case(lambda r: r.play(), ((3, 9100), (5, 7104)), stopped=True),
    ("article", "move_to"): Case(
        lambda r: r.move_to(END, speed=20), ((3, 512), (16, 512), (3, 519), (3, 0)), END
    ),
    ("article", "start_move"): Case(
        lambda r: r.start_move(END, speed=20), ((3, 512), (16, 512)), END
    ),
    ("article", "motion.wait"): Case(
        lambda r: _handle(r).wait(), ((3, 519), (3, 0)), END, _started
    ),
    ("article", "motion.cancel"): Case(
        lambda r: _handle(r).cancel(), ((3, 519), (3, 0), (16, 519)), END, _started, stall=True
    ),
    ("article", "wait_until_at_rest"): Case(lambda r: r.wait_until_at_rest(), ((3, 0),)),
    ("article", "gripper.close"): Case(lambda r: r.gripper.close(), ((3, 0), (16, 528))),
    ("article", "stop"): Case(lambda r: r.stop(), ((16, 519),)),
}


async def _await(handle: aio.AsyncMotion) -> Any:
    return await handle


def _all_points() -> Iterator[Any]:
    for (profile, name), case in CASES.items():
        for point in case.points:
            for action in ("hold", "delay_answer"):
                for how in ("cancel", "timeout"):
                    yield pytest.param(
                        profile,
                        name,
                        point,
                        action,
                        how,
                        id=f"{profile}-{name}-{point[0]}@{point[1]}-{action}-{how}",
                    )


FULL = os.environ.get("TMMASTER_HUNT38") == "full"


def _late(proxy: FaultProxy, action: Any, point: Point, release: threading.Event) -> None:
    """The next request at ``point``: held (``hold``) or its answer (``delay_answer``)."""
    proxy.add(Rule(action, function_code=point[0], address=point[1], release=release))


def _open(sim: Simulator, proxy: FaultProxy) -> aio.AsyncRobot:
    return aio.connect(
        "127.0.0.1",
        proxy.port,
        profile=sim.profile,
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(request_s=2.0, ack_timeout_s=2.0, gripper_settle_s=0.05),
    )


async def _cancelled_at(
    robot: aio.AsyncRobot,
    call: Coroutine[Any, Any, Any],
    proxy: FaultProxy,
    action: str,
    release: threading.Event,
    how: str,
) -> None:
    """Run ``call``, cancel it once the rule played, then let the held frame go."""
    scope: list[asyncio.Timeout] = []

    async def timed() -> Any:
        async with asyncio.timeout(None) as cm:
            scope.append(cm)
            return await call

    task = asyncio.ensure_future(timed() if how == "timeout" else call)
    await until(lambda: proxy.played(action) or task.done())  # type: ignore[arg-type]
    assert not task.done(), f"the call ended before the point: {task.result()}"
    if how == "timeout":
        scope[0].reschedule(asyncio.get_running_loop().time())
    else:
        task.cancel()
    await until(lambda: robot.robot._stop_event.is_set() or task.done())
    release.set()
    with pytest.raises(TimeoutError if how == "timeout" else asyncio.CancelledError):
        await task


async def _scenario(
    sim: Simulator,
    proxy: FaultProxy,
    case: Case,
    point: Point,
    action: str,
    how: str,
    release: threading.Event,
    issued: list[Issued],
) -> None:
    async with _open(sim, proxy) as robot:
        await robot.wait_until_ready(timeout_s=5)
        await robot.move_to(START, speed=100)
        issued.append(Issued(START, 0.0, 0.0, "done"))
        if case.stopped:
            await robot.stop()
            await ticks_pass(sim, 3)
        if case.target is not None:
            issued.append(Issued(case.target, time.monotonic()))
        if case.stall:
            sim.inject("stall:at_move=1")
        if case.before is not None:
            await case.before(robot)
        before = len(sim.motion_log())
        _late(proxy, action, point, release)
        await _cancelled_at(robot, case.call(robot), proxy, action, release, how)
        ended_at = time.monotonic()  # the motion log's clock
        if case.stall:
            sim.clear_faults()  # a move withdrawn before it started leaves the stall armed
        if case.target is not None:
            issued[-1].ended_at = time.monotonic()
            issued[-1].outcome = "CancelledError"
        if action == "hold" and proxy.played("hold"):
            await asyncio.to_thread(proxy.wait_held)
        await ticks_pass(sim, NOTHING_LATER_TICKS)
        late = [m for m in sim.motion_log()[before:] if m.wall_time > ended_at]
        if point == (16, 528):  # the article's gripper register: a level, like an output
            # A held frame lands unseen and the fingers act on it (docs/safety.md,
            # "Digital outputs": the master cannot recall a frame).
            late = [m for m in late if not m.kind.startswith("gripper")]
        assert not late, f"started after the CancelledError: {late}"
        rest = sim.tcp_pose()
        await ticks_pass(sim, NOTHING_LATER_TICKS)
        assert sim.tcp_pose().is_close(rest, mm=0.01, deg=0.01), "the arm moves on"
        motion = _HANDLE[id(robot)].motion if case.before else robot.last_motion
        if motion is not None and case.target is not None:
            # Given up (withdrawn, or its stop delivered), or believed done only at its end.
            aim = motion.command.target
            done_there = motion.done and aim is not None and rest.is_close(aim, mm=0.1)
            assert done_there or given_up(motion), motion
        # The next move of the same robot runs once, from where the arm is.
        if sim.profile.name == "tmflow":
            assert await robot.play() is ProjectState.RUNNING
        await robot.wait_until_at_rest()
        here = sim.tcp_pose()
        issued.append(Issued(NEXT, time.monotonic()))
        handle = await robot.start_move(NEXT, speed=100)
        await handle
        issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "done"
        assert handle.motion.start is not None
        assert handle.motion.start.is_close(here, mm=1.0, deg=0.5), (handle.motion.start, here)
        assert sim.tcp_pose().is_close(NEXT, mm=0.05, deg=0.05)


#: The points run by default (the whole file in about 8 s): the command write executed
#: with its answer late, cancel() cancelled during its own withdraw, a gripper command's
#: frame landing after the give-up, and the article's write; the other tests' likewise.
COMPACT = {
    "tmflow-move_to-16@9000-delay_answer-cancel",
    "tmflow-motion.cancel-16@9014-delay_answer-cancel",
    "tmflow-gripper.close-16@9014-hold-timeout",
    "article-move_to-16@512-delay_answer-cancel",
    "tmflow-withdraw-cancel",
    "tmflow-stop-timeout",
    "tmflow-stop-then-record-cancel",
    "article-stop-timeout",
    "tmflow-close",
    "4@7354-delay_answer-cancel",
}


def _subset(every: Iterable[Any]) -> list[Any]:
    """Every case with ``TMMASTER_HUNT38=full``, else those in COMPACT."""
    return [p for p in every if FULL or p.id in COMPACT]


@pytest.mark.parametrize(("profile", "name", "point", "action", "how"), _subset(_all_points()))
def test_a_call_cancelled_while_one_of_its_requests_is_in_flight(
    tm_simulator_factory: Factory, profile: str, name: str, point: Point, action: str, how: str
) -> None:
    case = CASES[(profile, name)]
    sim = tm_simulator_factory(profile)
    release = threading.Event()
    issued: list[Issued] = []
    try:
        with FaultProxy(sim.port) as proxy:
            run(lambda: _scenario(sim, proxy, case, point, action, how, release, issued))
    finally:
        release.set()
    # A joint move's target is not a pose issued here: judged by the late check above.
    check(issued, [m for m in sim.motion_log() if m.target is None or _posed(m.target)])


def _posed(target: Pose) -> bool:
    return any(target.distance_to(p) <= 0.05 for p in (START, END, NEXT, ARC_END))


#: The give-up's own request, per profile and kind: the cancel record (tmflow) or the Stop.
CLEAN_UPS = [
    ("tmflow", "sent", (16, 9014), "tmflow-withdraw"),
    ("tmflow", "running", (5, 7105), "tmflow-stop"),
    ("tmflow", "running", (16, 9014), "tmflow-stop-then-record"),
    ("article", "running", (16, 519), "article-stop"),
]


@pytest.mark.parametrize(
    ("profile", "state", "clean_up", "how"),
    _subset(
        pytest.param(profile, state, clean_up, how, id=f"{name}-{how}")
        for profile, state, clean_up, name in CLEAN_UPS
        for how in ("cancel", "timeout")
    ),
)
def test_a_second_cancel_while_the_give_up_is_in_flight_does_not_cut_it_short(
    tm_simulator_factory: Factory, profile: str, state: str, clean_up: Point, how: str
) -> None:
    # "sent": the wait is cancelled while the answer to its first poll is held (the
    # robot's program has not taken the number: late_ack); "running": once the arm moves.
    if state == "sent":
        sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=20"])
    else:  # a move of seconds
        sim = tm_simulator_factory(profile, time_scale=4.0)
    first, second = threading.Event(), threading.Event()
    issued: list[Issued] = []

    async def scenario() -> None:
        with FaultProxy(sim.port) as proxy:
            async with _open(sim, proxy) as robot:
                await robot.wait_until_ready(timeout_s=5)
                issued.append(Issued(END, time.monotonic()))
                handle = await robot.start_move(END, speed=20)
                if state == "running":
                    await until(lambda: bool(sim.motion_log()))
                _late(proxy, "delay_answer", (3, 9100) if profile == "tmflow" else (3, 0), first)
                _late(proxy, "delay_answer", clean_up, second)
                scope: list[asyncio.Timeout] = []

                async def timed() -> Any:
                    async with asyncio.timeout(None) as cm:
                        scope.append(cm)
                        return await handle.wait()

                task = asyncio.ensure_future(timed() if how == "timeout" else handle.wait())
                await until(lambda: proxy.played("delay_answer"))
                task.cancel() if how == "cancel" else scope[0].reschedule(0)
                await until(robot.robot._stop_event.is_set)
                first.set()
                await until(lambda: len([s for s in proxy.seen if s.action == "delay_answer"]) >= 2)
                task.cancel()  # a second Ctrl-C while the give-up's request is in flight
                for _ in range(20):
                    await asyncio.sleep(0)
                assert not task.done(), "the CancelledError came before the give-up was answered"
                second.set()
                with pytest.raises((asyncio.CancelledError, TimeoutError)):
                    await task
                issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "CancelledError"
                motion = handle.motion
                assert given_up(motion), motion
                sim.clear_faults()
                await ticks_pass(sim, NOTHING_LATER_TICKS)
                rest = sim.tcp_pose()
                await ticks_pass(sim, NOTHING_LATER_TICKS)
                assert sim.tcp_pose().is_close(rest, mm=0.01, deg=0.01), "the arm moves on"

    try:
        run(scenario)
    finally:
        first.set()
        second.set()
    check(issued, sim.motion_log())
    if state == "sent":
        assert [m for m in sim.motion_log() if m.target is not None] == []


@pytest.mark.parametrize(
    ("profile", "stop"),
    _subset(
        pytest.param(profile, stop, id=f"{profile}-close")
        for profile, stop in [("tmflow", (5, 7105)), ("article", (16, 519))]
    ),
)
def test_close_cancelled_twice_while_its_stop_is_in_flight_still_stops_the_arm(
    tm_simulator_factory: Factory, profile: str, stop: Point
) -> None:
    sim = tm_simulator_factory(profile, time_scale=4.0)  # a move of seconds
    release = threading.Event()
    issued: list[Issued] = []

    async def scenario() -> None:
        with FaultProxy(sim.port) as proxy:
            robot = _open(sim, proxy)
            await robot.connect()
            await robot.wait_until_ready(timeout_s=5)
            issued.append(Issued(END, time.monotonic()))
            handle = await robot.start_move(END, speed=20)
            await until(lambda: bool(sim.motion_log()))
            _late(proxy, "delay_answer", stop, release)
            task = asyncio.ensure_future(robot.close())
            await until(lambda: proxy.played("delay_answer"))
            task.cancel()
            for _ in range(20):
                await asyncio.sleep(0)
            task.cancel()
            for _ in range(20):
                await asyncio.sleep(0)
            assert not task.done(), "close() gave up before its Stop was answered"
            release.set()
            with pytest.raises(asyncio.CancelledError):
                await task
            issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "CancelledError"
            assert handle.motion.stop_delivered is True, handle.motion
            await ticks_pass(sim, NOTHING_LATER_TICKS)
            rest = sim.tcp_pose()
            await ticks_pass(sim, NOTHING_LATER_TICKS)
            assert sim.tcp_pose().is_close(rest, mm=0.01, deg=0.01), "the arm moves on"
            assert not rest.is_close(END), "the move ran to its end"
            with pytest.raises(tmmaster.TransportClosedError):
                await robot.status()

    try:
        run(scenario)
    finally:
        release.set()
    check(issued, sim.motion_log())


def test_the_next_play_after_a_cancelled_pause_whose_press_landed_late_runs(
    tm_simulator_factory: Factory,
) -> None:
    """A pause() cancelled while its press is held in the network presses Stop (the press
    unanswered); the press landing after that Stop is Play on the stopped project, which
    starts over (docs/safety.md). The same robot's next play() took its own Stop as not
    shown yet (it may take STOP_SHOWS_S, 1 s), waited its whole timeout for a stop that
    had shown and been undone, then raised RobotError ("Stop was pressed (the project
    was running) and the project is running 0.3 s later") and pressed Stop on the
    running project. Now a project started anew (boot_id) since the Stop that pause()
    pressed on giving up is not waited for (the Stop showed, and was undone): play()
    finds the project running and presses nothing. A Stop merely slow to show is still
    waited for, up to timeout_s (tests/test_review_hunt38_slow_stop.py)."""
    sim = tm_simulator_factory("tmflow")
    release = threading.Event()

    async def scenario() -> None:
        with FaultProxy(sim.port) as proxy:
            timeouts = TimeoutPolicy(request_s=0.3, ack_timeout_s=2.0)
            async with aio.connect(
                "127.0.0.1", proxy.port, polling=PollPolicy(interval_s=0.01), timeouts=timeouts
            ) as robot:
                await robot.wait_until_ready(timeout_s=5)
                _late(proxy, "hold", (5, 7104), release)
                task = asyncio.ensure_future(robot.pause())
                await until(lambda: proxy.played("hold"))
                task.cancel()
                with pytest.raises(asyncio.CancelledError):
                    await task  # the press unanswered: Stop pressed before this
                await ticks_pass(sim, 3)  # the Stop taken
                release.set()  # the press lands now: Play on the stopped project
                await asyncio.to_thread(proxy.wait_held)
                await ticks_pass(sim, NOTHING_LATER_TICKS)
                assert await robot.project_state() is ProjectState.RUNNING  # started over
                stops = len([r for r in sim.request_log if r.address == 7105])
                assert await robot.play(timeout_s=0.3) is ProjectState.RUNNING
                assert len([r for r in sim.request_log if r.address == 7105]) == stops

    try:
        run(scenario)
    finally:
        release.set()
    assert [m for m in sim.motion_log() if m.target is not None] == []


CONNECT = [(4, 7001), (4, 7354), (4, 7101)]


CONNECT_POINTS = (
    pytest.param(point, action, how, id=f"{point[0]}@{point[1]}-{action}-{how}")
    for point in CONNECT
    for action in ("hold", "delay_answer")
    for how in ("cancel", "timeout")
)


@pytest.mark.parametrize(("point", "action", "how"), _subset(CONNECT_POINTS))
def test_connect_cancelled_at_each_request_closes_and_a_new_robot_moves(
    tm_simulator_factory: Factory, point: Point, action: str, how: str
) -> None:
    sim = tm_simulator_factory("tmflow")
    release = threading.Event()
    issued: list[Issued] = []

    async def scenario() -> None:
        with FaultProxy(sim.port) as proxy:
            robot = _open(sim, proxy)
            _late(proxy, action, point, release)
            await _cancelled_at(robot, robot.connect(), proxy, action, release, how)
            with pytest.raises(tmmaster.TransportClosedError):
                await robot.status()
            if action == "hold":
                await asyncio.to_thread(proxy.wait_held)
            async with _open(sim, proxy) as again:
                await again.wait_until_ready(timeout_s=5)
                issued.append(Issued(NEXT, time.monotonic()))
                await again.move_to(NEXT, speed=100)
                issued[-1].ended_at, issued[-1].outcome = time.monotonic(), "done"

    try:
        run(scenario)
    finally:
        release.set()
    check(issued, sim.motion_log())
