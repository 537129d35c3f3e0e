"""Check every move of a run before the first byte, and estimate how long it takes.

The plan is lazy: a :class:`CyclePlan` makes a cycle's moves when asked, never a list
of every cycle. When the cycles in the middle of a run repeat the same moves, checking
and timing them stops as soon as they fall into a loop (a cycle starting where an
earlier one started: the same checks, the same times); the loop stands for the rest,
so the start-up cost of ``--cycles 1000000`` is that of a few cycles.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Hashable, Iterator
from dataclasses import dataclass
from typing import Generic, TypeVar

from .._exceptions import ConfigError, StopRequestedError, UnreachablePoseError
from .._pose import Pose
from .._robot import Robot
from .._robot_models import RobotModel
from ._sequences import check_gripper_steps
from ._steps import PlannedMove, TaskSequence, require_count

S = TypeVar("S", bound=Hashable)
T = TypeVar("T")


class CyclePlan:
    """The moves of ``cycles`` cycles of ``sequence``, made cycle by cycle when asked.

    Building one costs the same for 1 cycle as for 1,000,000: nothing is planned
    until a cycle's moves are asked for.

    Args:
        sequence: The sequence.
        cycles: How many cycles run.
    """

    def __init__(self, sequence: TaskSequence, cycles: int) -> None:
        require_count(cycles)
        #: The sequence.
        self.sequence = sequence
        #: How many cycles run.
        self.cycles = cycles
        #: The cycles between the first and the last make the same moves (no move is a
        #: function of the cycle, no deprecated ``plan``): they may stand for each other.
        self.repeats = sequence.plan is None and all(
            step.move is None or isinstance(step.move, PlannedMove) for step in sequence.steps
        )

    def moves(self, cycle: int) -> list[PlannedMove]:
        """The moves of cycle ``cycle`` (1-based), in step order.

        Args:
            cycle: The cycle.

        Returns:
            Its moves.
        """
        return self.sequence.moves(cycle, self.cycles)

    def __iter__(self) -> Iterator[tuple[int, list[PlannedMove]]]:
        """Every cycle with its moves, in order, each made when reached."""
        for cycle in range(1, self.cycles + 1):
            yield cycle, self.moves(cycle)

    def states(self) -> list[str]:
        """The states that make a planned move in the run (and the retreat's), sorted.

        A state's name does not depend on the cycle, only on whether its step runs in
        the first, a middle or the last cycle: three cycles say it (every cycle with the
        deprecated ``plan``, which may name anything).

        Returns:
            The state names.
        """
        cycles: Iterator[int] | set[int] = (
            iter(range(1, self.cycles + 1))
            if self.sequence.plan is not None
            else {1, min(2, self.cycles), self.cycles}
        )
        names = {move.state for cycle in cycles for move in self.moves(cycle)}
        if self.sequence.retreat is not None:
            names.add(self.sequence.retreat.state)
        return sorted(names)

    def run(
        self, state: S, run_cycle: Callable[[int, list[PlannedMove], S], tuple[S, T]]
    ) -> Iterator[CycleRun[T]]:
        """Run every cycle through ``run_cycle``, lazily; a loop stands for the rest.

        ``run_cycle(cycle, moves, start)`` returns the state after the cycle and its
        result; it must depend on nothing but its arguments. When the middle cycles
        repeat (:attr:`repeats`) and one starts in a state an earlier middle cycle
        started in, the cycles from there to the last but one go round that loop: each
        cycle of the loop is yielded again with how many more cycles it stands for, and
        the last cycle runs from the state the loop leaves it in.

        Args:
            state: The state before the first cycle.
            run_cycle: Runs one cycle.

        Yields:
            Each cycle run, with how many cycles of the run it stands for.
        """
        last = self.cycles
        seen: dict[S, int] = {}  # a middle cycle's start state -> its index in ``loop``
        loop: list[tuple[int, S, T]] = []
        cycle = 1
        while cycle <= last:
            if self.repeats and 1 < cycle < last:
                if state in seen:
                    first = seen[state]
                    period = loop[first:]
                    full, extra = divmod(last - cycle, len(period))
                    for index, (number, _, result) in enumerate(period):
                        times = full + (1 if index < extra else 0)
                        if times:
                            yield CycleRun(number, result, times)
                    state = period[extra][1]
                    cycle = last
                    continue
                seen[state] = len(loop)
            start = state
            state, result = run_cycle(cycle, self.moves(cycle), start)
            if 1 < cycle < last:
                loop.append((cycle, start, result))
            yield CycleRun(cycle, result, 1)
            cycle += 1


@dataclass(frozen=True)
class CycleRun(Generic[T]):
    """What :meth:`CyclePlan.run` made of one cycle, and how many cycles it stands for."""

    #: The cycle that was run, 1-based.
    cycle: int
    #: What ``run_cycle`` returned for it.
    result: T
    #: How many cycles of the run this result counts for.
    times: int


def validate_plan(
    robot: Robot,
    sequence: TaskSequence,
    cycles: int,
    *,
    source: str,
    start: tuple[Pose, tuple[float, ...]] | None = None,
    stop: threading.Event | None = None,
) -> int:
    """Validate every known move against the profile, arm and limits; returns the count.

    Nothing is sent: a move that cannot be encoded (e.g. beyond +/-327.67 mm in the
    article profile), that the arm cannot take (inverse kinematics from the previous
    move's joints: reach, joint ranges, singularities), a Line whose straight path
    leaves the arm's range, or a move too fast raises :class:`ConfigError` naming the
    configuration key and ``source``; so does a gripper step (the library's: a TOML
    sequence's, the built-in ones) on a robot without a gripper.

    Args:
        robot: The robot that will run it (profile, arm model, tool, limits); it need
            not be connected.
        sequence: The sequence.
        cycles: How many cycles will run.
        source: Where the sequence comes from (a file name), for the messages.
        start: Where the arm is before the first move, its TCP pose and joints (deg),
            as the robot reports them (None: not known; the first move's target alone
            is checked).
        stop: Once set (a stop request: :meth:`Runner.request_stop`), the check ends
            before its next move (a long pallet's check takes seconds).

    Returns:
        How many distinct moves were checked.

    Raises:
        ConfigError: A move that cannot be sent or taken (UnreachablePoseError when the
            arm cannot reach it).
        StopRequestedError: ``stop`` was set before the check was over.
    """
    sequence.validate()
    check_gripper_steps(robot, sequence, source)
    checker = _MoveChecker(robot, source, stop or threading.Event())

    def check_cycle(cycle: int, moves: list[PlannedMove], start: _Where) -> tuple[_Where, None]:
        _ = cycle
        for move in moves:
            start = checker.check(move, start)
        return start, None

    # Each move continues from the previous one's joints; middle cycles that repeat are
    # checked until they loop (the rest would repeat the same checks).
    for _ in CyclePlan(sequence, cycles).run(start, check_cycle):
        pass
    # The retreat starts wherever the run stopped: its path is not known in advance.
    if sequence.retreat is not None:
        checker.check(sequence.retreat, None)
    return checker.count


#: Where the arm is between two checked moves: its pose and joints (None: not known).
_Where = tuple[Pose, tuple[float, ...]] | None


class _MoveChecker:
    """Checks moves on ``robot``, each distinct transition once; counts the checks.
    Once ``stop`` is set, the next check raises StopRequestedError."""

    def __init__(self, robot: Robot, source: str, stop: threading.Event) -> None:
        self.robot = robot
        self.source = source
        self.stop = stop
        self.count = 0
        self._joints_after: dict[tuple[object, ...], tuple[float, ...]] = {}

    def check(self, move: PlannedMove, previous: _Where) -> _Where:
        """Check ``move`` from ``previous``; where the arm is after it."""
        if self.stop.is_set():
            raise StopRequestedError(f"stop requested during the check of the plan ({self.source})")
        key = (previous, move.pose, move.speed, move.motion)
        if key in self._joints_after:
            return (move.pose, self._joints_after[key])
        robot = self.robot
        try:
            joints = robot.check_move(
                move.pose,
                move.speed,
                move.motion,
                start=None if previous is None else previous[0],
                seed_deg=None if previous is None else previous[1],
            )
        except ConfigError as exc:
            message = (
                f"{self.source}: {move.source or move.state} ({move.state}): {exc}"
                f" [profile {robot.profile.name}, model {robot.model.name}]"
            )
            if isinstance(exc, UnreachablePoseError):
                raise UnreachablePoseError(message, reason=exc.reason, pose=exc.pose) from None
            raise ConfigError(message) from None
        self._joints_after[key] = joints
        self.count += 1
        return (move.pose, joints)


@dataclass(frozen=True)
class EstimatedMove:
    """A planned move with its expected duration."""

    #: The cycle, 1-based.
    cycle: int
    #: The move.
    move: PlannedMove
    #: Its expected duration, s (from the arm model).
    expected_s: float
    #: Joints J1..J6 (deg) at the move's target, continuing from the previous move's.
    joints_deg: tuple[float, ...]


def estimate(
    sequence: TaskSequence,
    cycles: int,
    model: RobotModel,
    *,
    start: Pose,
    tool: Pose | None = None,
) -> list[EstimatedMove]:
    """Expected duration and target joints of every planned move, from ``start``.

    Args:
        sequence: The sequence.
        cycles: How many cycles.
        model: The arm model that times the moves.
        start: The TCP pose before the first move.
        tool: The TCP in the flange frame (None: the flange).

    Returns:
        Every move of every cycle, in order (empty when the moves are not known in
        advance): a list as long as the run (:func:`format_plan` times a long run
        without one).

    Raises:
        UnreachablePoseError: A pose the arm cannot reach.
    """
    if not _has_moves(sequence):
        return []
    here: _Arm = (start, model.inverse(start, tool=tool))
    result = []
    for cycle, moves in CyclePlan(sequence, cycles):
        here, estimated = _estimate_cycle(model, tool, cycle, moves, here)
        result.extend(estimated)
    return result


#: The arm between two estimated moves: its TCP pose and joints.
_Arm = tuple[Pose, tuple[float, ...]]


def _has_moves(sequence: TaskSequence) -> bool:
    return any(s.move is not None for s in sequence.steps) or sequence.plan is not None


def _estimate_cycle(
    model: RobotModel, tool: Pose | None, cycle: int, moves: list[PlannedMove], here: _Arm
) -> tuple[_Arm, list[EstimatedMove]]:
    """The estimated moves of one cycle from ``here``, and where the arm is after it."""
    pose, joints = here
    result = []
    for move in moves:
        seconds = model.motion_time(
            pose,
            move.pose,
            speed_percent=move.speed,
            motion=move.motion,
            start_joints_deg=joints,
            tool=tool,
        )
        joints = model.inverse(move.pose, seed_deg=joints, tool=tool)
        result.append(EstimatedMove(cycle, move, seconds, joints))
        pose = move.pose
    return (pose, joints), result


def format_plan(
    sequence: TaskSequence,
    cycles: int,
    model: RobotModel,
    *,
    start: Pose,
    profile: str,
    tool: Pose | None = None,
) -> str:
    """The --dry-run text: every move with pose, joints, speed, motion type and expected time.

    Args:
        sequence: The sequence.
        cycles: How many cycles (the first and the last are listed).
        model: The arm model that times the moves.
        start: The TCP pose before the first move.
        profile: The profile's name, for the header.
        tool: The TCP in the flange frame (None: the flange).

    Returns:
        The text, one line per move, with totals.
    """
    lines = [
        f"sequence {sequence.name}: {cycles} cycle(s), profile {profile}, model {model.name}",
        f"states: IDLE -> {' -> '.join(s.name for s in sequence.steps)} -> DONE | ERROR",
        f"start pose assumed: {start}",
        "",
        f"{'cycle':>5}  {'state':<20} {'pose [x, y, z, rx, ry, rz]':<44} {'speed':>5}"
        f"  {'motion':<6} {'expected':>9}  joints J1..J6 [deg]",
    ]
    # Long runs: the first and last cycle say it all; the total counts every cycle
    # (a loop of repeating middle cycles counted as often as it runs).
    shown: list[EstimatedMove] = []
    total = per_cycle = 0.0
    if _has_moves(sequence):

        def run_cycle(
            cycle: int, moves: list[PlannedMove], here: _Arm
        ) -> tuple[_Arm, list[EstimatedMove]]:
            return _estimate_cycle(model, tool, cycle, moves, here)

        arm: _Arm = (start, model.inverse(start, tool=tool))
        for run in CyclePlan(sequence, cycles).run(arm, run_cycle):
            seconds = sum(m.expected_s for m in run.result)
            total += seconds * run.times
            if run.cycle == 1:
                per_cycle = seconds
            if run.cycle in (1, cycles) and run.times == 1:
                shown.extend(run.result)
    for item in shown:
        pose = ", ".join(f"{v:g}" for v in item.move.pose.as_list())
        joints = ", ".join(f"{q:.1f}" for q in item.joints_deg)
        lines.append(
            f"{item.cycle:>5}  {item.move.state:<20} [{pose}]".ljust(73)
            + f" {item.move.speed:>4}%  {item.move.motion.value:<6} {item.expected_s:>8.2f}s"
            + f"  [{joints}]"
        )
    if cycles > 2:
        middle = "cycle 2" if cycles == 3 else f"cycles 2..{cycles - 1}"
        lines.append(f"  ... {middle}: the same moves")
    lines.append("")
    lines.append(
        f"expected motion time: {per_cycle:.2f} s for cycle 1, {total:.2f} s in total"
        " (gripper and polling time not included)"
    )
    if sequence.retreat is not None:
        r = sequence.retreat
        lines.append(
            f"on error: retreat to {r.pose} at {r.speed} % {r.motion.value}"
            " (never after an e-stop or a robot error)"
        )
    else:
        lines.append("on error: stay where it stopped")
    return "\n".join(lines)
