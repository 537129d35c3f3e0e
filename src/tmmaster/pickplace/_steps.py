"""What a sequence is made of: named steps (states) with actions, retry rules and guards.

A :class:`TaskSequence` only says *what* to do in each state. Polling, timeouts, retries,
stop requests, logging and timing are the runner's business, the same for every
sequence: the built-in pick & place, palletizing, a Python sequence or a TOML one.
The refusal of a start that finds a part in the gripper (:func:`refuse_held_part`) is
part of what a step's context offers: the runner and the sequences raise the same.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from enum import StrEnum
from numbers import Integral
from typing import Any, Literal, Protocol, TypeVar

from .._exceptions import ConfigError, GraspFailedError, TMMasterError
from .._gripper import GripperStatus
from .._pose import MotionType, Pose
from .._robot import Robot


class StepContext(Protocol):
    """What a step's action may use: the robot, the run's position, moves under the policies.

    The runner hands one to every action, guard and skip condition of a run.
    """

    #: The robot of the run.
    robot: Robot
    #: Free space for a sequence's own state between steps (reset per run).
    data: dict[str, Any]
    #: The gripper status of the last gripper action or check.
    last_gripper: GripperStatus | None

    @property
    def state(self) -> str:
        """The current state."""

    @property
    def cycle(self) -> int:
        """The current cycle, from 1."""

    @property
    def cycles(self) -> int:
        """How many cycles this run makes."""

    @property
    def last_cycle(self) -> bool:
        """True during the last cycle."""

    @property
    def attempt(self) -> int:
        """1 + the retries already used by the current step in this cycle."""

    @property
    def stop_requested(self) -> bool:
        """True once a stop was requested (long actions should return early)."""

    def move(
        self,
        pose: Pose,
        *,
        speed: int,
        motion: MotionType | Literal["ptp", "line"] = MotionType.PTP,
    ) -> None:
        """Move and wait until the robot acknowledged and finished (robot API timeouts).

        Args:
            pose: The TCP target.
            speed: Speed, %.
            motion: PTP (joint interpolation) or LINE (a straight TCP path).
        """

    def move_planned(self, planned: PlannedMove) -> None:
        """Make a :class:`PlannedMove`.

        Args:
            planned: The move (pose, speed, motion type).
        """

    def open_gripper(self) -> GripperStatus:
        """Open the fingers and wait until they stopped.

        Returns:
            The gripper's status.
        """

    def close_gripper(self) -> GripperStatus:
        """Close the fingers and wait until they stopped (no check of the object).

        Returns:
            The gripper's status.
        """

    def part_held(self, *, start: bool = False) -> bool | None:
        """Whether the gripper holds a part now: the runner's ``held_input`` when it has
        one (the robot's DI, read directly), else the gripper's report.

        Args:
            start: Asked before the run's first open or pick: a part is held when the
                input or the gripper's report says so.

        Returns:
            Whether a part is held; None when the gripper cannot tell.
        """

    def check_holding(self, expected: bool = True) -> GripperStatus:
        """Read the gripper; raise :class:`GraspFailedError` unless holding == ``expected``.

        Args:
            expected: Whether an object should be held.

        Returns:
            The gripper's status.

        Raises:
            GraspFailedError: It holds, or does not hold, against ``expected``.
        """

    def grip(self) -> GripperStatus:
        """Close and require an object (raises :class:`GraspFailedError`).

        Returns:
            The gripper's status, holding.
        """

    def wait(self, seconds: float) -> None:
        """Dwell for ``seconds``; a stop request ends the dwell at once.

        Args:
            seconds: How long, s.
        """


def refuse_held_part(robot: Robot, *, opening: bool) -> ConfigError:
    """The error a run fails with at its start when the gripper holds a part.

    What a start raises once :meth:`StepContext.part_held` (``start=True``) says a part
    is held: the runner's, before a ``prepare`` opens the gripper, and a sequence's own,
    before a cycle that starts with a pick. Both say it in the same words.

    Args:
        robot: The robot (its pose is read for the message, if it can be).
        opening: Whether the start would open the gripper (else: the sequence starts
            with a pick, with the part still in the fingers).

    Returns:
        The :class:`ConfigError`, naming the situation and the fix.
    """
    held = f"the gripper holds a part at the start of the run (the arm at {arm_at(robot)})"
    if opening:
        return ConfigError(
            f"{held}: opening it would drop the part there, so nothing was moved or opened;"
            " take the part out of the gripper, or set [gripper] release_held_part_at_start"
            " = true (command line: --release-held-part) to release it where the arm is"
        )
    return ConfigError(
        f"{held} and the cycle starts with a pick: nothing was moved or opened; take the"
        " part out of the gripper ([gripper] open_at_start = false: the run does not open it)"
    )


def arm_at(robot: Robot) -> str:
    """Where the arm's TCP is, in words (x, y, z in mm), or "an unread position"."""
    try:
        pose = robot.pose()
    except TMMasterError:
        return "an unread position"
    return f"x {pose.x:.1f}, y {pose.y:.1f}, z {pose.z:.1f} mm"


#: What a step does; its return value is ignored; a :class:`~tmmaster.TMMasterError`
#: fails (or retries) the step, any other exception is a bug and leaves the run.
Action = Callable[[StepContext], Any]
#: A yes/no question about the run, asked without I/O (guards, skip conditions).
Predicate = Callable[[StepContext], bool]

ActionT = TypeVar("ActionT", bound=Action)

#: States every machine has; a sequence may not reuse these names.
RESERVED_STATES = ("IDLE", "DONE", "ERROR")


def require_count(count: object, name: str = "cycles") -> int:
    """A count (of cycles, of a pallet's rows...) that is a whole number >= 1, as an int
    (numpy's integers are whole numbers; a bool is not).

    A fraction (1.5 cycles) was run as 2 cycles (cycle 1 is not the last) but planned as
    1 (``cycle <= 1.5``): its last cycle unchecked.

    Args:
        count: The count given.
        name: What it counts, for the message (``"cycles"``, ``"pallet rows"``).

    Returns:
        The count, an int.

    Raises:
        ConfigError: Naming the count.
    """
    if isinstance(count, bool) or not isinstance(count, Integral) or count < 1:
        raise ConfigError(f"{name} must be a whole number >= 1, got {count!r}")
    return int(count)


class Cycles(StrEnum):
    """In which cycles a step runs, known before the run (the plan follows it)."""

    ALWAYS = "always"
    FIRST = "first_cycle"
    LAST = "last_cycle"

    def applies(self, cycle: int, cycles: int) -> bool:
        """True when a step with this rule runs in cycle ``cycle`` of ``cycles``.

        Args:
            cycle: The cycle, 1-based.
            cycles: How many cycles run.

        Returns:
            Whether the step runs.
        """
        if self is Cycles.FIRST:
            return cycle == 1
        if self is Cycles.LAST:
            return cycle == cycles
        return True

    def __call__(self, ctx: StepContext) -> bool:
        """The same rule as a skip condition on a running context."""
        return self.applies(ctx.cycle, ctx.cycles)


@dataclass(frozen=True)
class RetryRule:
    """When the step fails with one of ``on``: run ``recover``, go back to ``back_to``."""

    #: The step to go back to: this one or an earlier one.
    back_to: str
    #: How many retries a cycle may use (0: none).
    attempts: int
    #: Makes a new attempt possible, e.g. open the gripper; runs before going back.
    recover: Action | None = None
    #: The errors that are retried; any other fails the step.
    on: tuple[type[BaseException], ...] = (GraspFailedError,)


@dataclass(frozen=True)
class PlannedMove:
    """A move a sequence will make, known before the run (validated, shown by --dry-run)."""

    #: The state that makes it.
    state: str
    #: The TCP target.
    pose: Pose
    #: Speed, %.
    speed: int
    #: PTP or LINE.
    motion: MotionType
    #: Which configuration key the pose came from (named in validation errors).
    source: str = ""


#: The move a step makes: one move, or the move of cycle k (1-based), e.g. a pallet slot.
MoveSpec = PlannedMove | Callable[[int], PlannedMove]


@dataclass(frozen=True)
class Step:
    """One state of a sequence and the action run while in it."""

    #: The state's name (letters, digits, underscores).
    name: str
    #: What the step does (called with the StepContext).
    action: Action
    #: What happens when it fails (None: the run fails).
    retry: RetryRule | None = None
    #: Must hold to leave the state forward (checked by the machine, after the action).
    guard: Predicate | None = None
    #: The guard's name in the state diagram.
    guard_name: str | None = None
    #: When given and false, the action is skipped (the state is still passed through).
    #: A :class:`Cycles` rule is also known to the plan; another predicate is not, and
    #: the step's move is then planned (validated, estimated) in every cycle.
    when: Predicate | None = None
    #: What the step does, in words (shown by --dry-run and the diagram).
    description: str = ""
    #: The move this step makes, known before the run: validated before the first byte
    #: and shown by --dry-run. A step given a move and no action just makes the move.
    move: MoveSpec | None = None

    def planned(self, cycle: int, cycles: int) -> PlannedMove | None:
        """This step's move in cycle ``cycle`` of ``cycles``; None when it makes none.

        Args:
            cycle: The cycle, 1-based.
            cycles: How many cycles run.

        Returns:
            The move, named after this step, or None.
        """
        if self.move is None:
            return None
        if isinstance(self.when, Cycles) and not self.when.applies(cycle, cycles):
            return None
        move = self.move if isinstance(self.move, PlannedMove) else self.move(cycle)
        return move if move.state == self.name else replace(move, state=self.name)

    def move_of(self, cycle: int) -> PlannedMove:
        """This step's move in cycle ``cycle`` (raises when the step makes none).

        Args:
            cycle: The cycle, 1-based.

        Returns:
            The move.

        Raises:
            ConfigError: The step makes no planned move.
        """
        if self.move is None:
            raise ConfigError(f"step {self.name} makes no planned move")
        return self.move if isinstance(self.move, PlannedMove) else self.move(cycle)


def move_action(move: MoveSpec) -> Action:
    """The action that makes ``move`` (in the running cycle when it depends on the cycle)."""

    def make_move(ctx: StepContext) -> None:
        ctx.move_planned(move if isinstance(move, PlannedMove) else move(ctx.cycle))

    if isinstance(move, PlannedMove):
        make_move.__name__ = f"move_to_{move.source or move.state.lower()}"
    return make_move


@dataclass
class TaskSequence:
    """An ordered list of steps, run once per cycle by a :class:`Runner`.

    Example:
        ```python
        from tmmaster import Pose
        from tmmaster.pickplace import TaskSequence

        CAMERA = Pose(300, 0, 300, 180, 0, 90)
        seq = TaskSequence("inspect")

        @seq.step("MOVE_TO_CAMERA")
        def to_camera(ctx):
            ctx.move(CAMERA, speed=30)

        seq.add("DWELL", lambda ctx: ctx.wait(0.5), description="let the camera see")
        ```
    """

    #: The sequence's name (in logs and reports).
    name: str
    #: The steps, in order.
    steps: list[Step] = field(default_factory=list)
    #: Deprecated: give the steps their moves (``add(..., move=)``); the plan is derived
    #: from them. When set, these moves of cycle k (1-based) of n replace the derived plan.
    plan: Callable[[int, int], list[PlannedMove]] | None = None
    #: Where the "retreat" error reaction goes, at its low speed.
    retreat: PlannedMove | None = None
    #: Cycles to run when the caller does not say.
    default_cycles: int = 1
    #: Runs once in IDLE before the first step (e.g. open the gripper).
    prepare: Action | None = None
    # The names of ``steps`` as of the last add(): a name used twice is found at once,
    # not by a scan per step (a 1 MiB sequence file took 20 s to load).
    _names: tuple[list[Step], int, set[str]] = field(
        default_factory=lambda: ([], 0, set()), init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        if self.plan is not None:
            warnings.warn(
                "TaskSequence(plan=...) is deprecated: give each step its move"
                " (TaskSequence.add(name, move=...)); the plan is derived from the steps",
                DeprecationWarning,
                stacklevel=3,
            )

    def add(
        self,
        name: str,
        action: Action | None = None,
        *,
        move: MoveSpec | None = None,
        retry: RetryRule | None = None,
        guard: Predicate | None = None,
        guard_name: str | None = None,
        when: Predicate | Cycles | str | None = None,
        description: str = "",
    ) -> TaskSequence:
        """Append a step; returns the sequence so calls can be chained.

        Args:
            name: The state's name: letters, digits and underscores, not IDLE, DONE
                or ERROR, unique in the sequence.
            action: What the step does; None: it makes ``move``.
            move: The move the step makes, known in advance (validated before the run,
                shown by --dry-run); a PlannedMove, or a function of the cycle.
            retry: What happens when the step fails.
            guard: Must hold to leave the state forward.
            guard_name: The guard's name in the diagram (default: its function's).
            when: A :class:`Cycles` rule (or its value, e.g. ``"last_cycle"``) or any
                predicate: when false, the action is skipped.
            description: What the step does, in words.

        Returns:
            The sequence.

        Raises:
            ConfigError: Neither action nor move, a bad or reserved name, a name used
                twice, or an unknown ``when``.
        """
        if action is None:
            if move is None:
                raise ConfigError(f"step {name!r}: give an action, a move, or both")
            action = move_action(move)
        if isinstance(when, str):
            try:
                when = Cycles(when)
            except ValueError:
                choices = ", ".join(c.value for c in Cycles)
                raise ConfigError(f"step {name!r}: when must be one of {choices}") from None
        if not name or not name.replace("_", "").isalnum():
            raise ConfigError(f"step name {name!r}: use letters, digits and underscores")
        if name in RESERVED_STATES:
            raise ConfigError(f"step name {name!r} is reserved ({', '.join(RESERVED_STATES)})")
        steps, count, names = self._names
        if steps is not self.steps or count != len(steps):  # steps changed since: again
            names = {s.name for s in self.steps}
        if name in names:
            raise ConfigError(f"sequence {self.name!r}: step {name!r} defined twice")
        self.steps.append(
            Step(
                name,
                action,
                retry=retry,
                guard=guard,
                guard_name=guard_name or (guard.__name__ if guard is not None else None),
                when=when,
                description=description,
                move=move,
            )
        )
        names.add(name)
        self._names = (self.steps, len(self.steps), names)
        return self

    def step(
        self,
        name: str,
        *,
        retry: RetryRule | None = None,
        guard: Predicate | None = None,
        when: Predicate | None = None,
    ) -> Callable[[ActionT], ActionT]:
        """Decorator form of :meth:`add`.

        Args:
            name: The state's name.
            retry: What happens when the step fails.
            guard: Must hold to leave the state forward.
            when: When false, the action is skipped.

        Returns:
            A decorator that adds the function as the step's action (and returns it).
        """

        def register(action: ActionT) -> ActionT:
            self.add(name, action, retry=retry, guard=guard, when=when)
            return action

        return register

    def validate(self) -> None:
        """Check the structure: at least one step, each name once, retry targets exist and
        come earlier.

        Raises:
            ConfigError: What is wrong, naming the sequence and the step.
        """
        if not self.steps:
            raise ConfigError(f"sequence {self.name!r} has no steps")
        names = [s.name for s in self.steps]
        if len(set(names)) != len(names):  # steps edited in place, past add()'s check
            twice = next(n for i, n in enumerate(names) if n in names[:i])
            raise ConfigError(f"sequence {self.name!r}: step {twice!r} defined twice")
        for index, s in enumerate(self.steps):
            if s.retry is None:
                continue
            if s.retry.back_to not in names:
                raise ConfigError(
                    f"sequence {self.name!r}: step {s.name} retries from unknown step"
                    f" {s.retry.back_to!r}"
                )
            if names.index(s.retry.back_to) > index:
                raise ConfigError(
                    f"sequence {self.name!r}: step {s.name} can only retry from itself or an"
                    f" earlier step, not {s.retry.back_to}"
                )
            if s.retry.attempts < 0:
                raise ConfigError(f"sequence {self.name!r}: step {s.name}: attempts must be >= 0")

    def moves(self, cycle: int, cycles: int) -> list[PlannedMove]:
        """The moves of cycle ``cycle`` of ``cycles``, in step order, from the steps' moves.

        Args:
            cycle: The cycle, 1-based.
            cycles: How many cycles run.

        Returns:
            The moves.
        """
        if self.plan is not None:
            return self.plan(cycle, cycles)
        return [m for s in self.steps if (m := s.planned(cycle, cycles)) is not None]

    def planned_moves(self, cycles: int) -> Iterable[PlannedMove]:
        """Every move known in advance over ``cycles`` cycles, then the retreat.

        Args:
            cycles: How many cycles run.

        Yields:
            The moves, in order.
        """
        for cycle in range(1, cycles + 1):
            yield from self.moves(cycle, cycles)
        if self.retreat is not None:
            yield self.retreat
