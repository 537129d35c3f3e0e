"""What a sequence is made of: named steps (states) with actions, retry rules and guards.

A :class:`TaskSequence` only says *what* to do in each state. Polling, timeouts, retries,
stop requests, logging and timing are the runner's business, the same for every
sequence: the built-in pick & place, palletizing, a Python sequence or a TOML one.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TypeVar

from .._exceptions import ConfigError, GraspFailedError
from .._pose import MotionType, Pose

if TYPE_CHECKING:
    from ._runner import StepContext

#: What a step does; its return value is ignored, an exception fails (or retries) the step.
Action = Callable[["StepContext"], Any]
#: A yes/no question about the run, asked without I/O (guards, skip conditions).
Predicate = Callable[["StepContext"], bool]

ActionT = TypeVar("ActionT", bound=Action)

#: States every machine has; a sequence may not reuse these names.
RESERVED_STATES = ("IDLE", "DONE", "ERROR")


@dataclass(frozen=True)
class RetryRule:
    """When the step fails with one of ``on``: run ``recover``, go back to ``back_to``."""

    back_to: str
    attempts: int
    #: Makes a new attempt possible, e.g. open the gripper; runs before going back.
    recover: Action | None = None
    on: tuple[type[BaseException], ...] = (GraspFailedError,)


@dataclass(frozen=True)
class PlannedMove:
    """A move a sequence will make, known before the run (validated, shown by --dry-run)."""

    state: str
    pose: Pose
    speed: int
    motion: MotionType
    #: Which configuration key the pose came from (named in validation errors).
    source: str = ""


@dataclass(frozen=True)
class Step:
    """One state of a sequence and the action run while in it."""

    name: str
    action: Action
    retry: RetryRule | None = None
    #: Must hold to leave the state forward (checked by the machine, after the action).
    guard: Predicate | None = None
    guard_name: str | None = None
    #: When given and false, the action is skipped (the state is still passed through).
    when: Predicate | None = None
    description: str = ""


@dataclass
class TaskSequence:
    """An ordered list of steps, run once per cycle by a :class:`Runner`.

    Build one in Python::

        seq = TaskSequence("inspect")

        @seq.step("MOVE_TO_CAMERA")
        def to_camera(ctx):
            ctx.move(CAMERA, speed=30)
    """

    name: str
    steps: list[Step] = field(default_factory=list)
    #: Moves of cycle k (1-based) of n, known in advance: validated before the first byte.
    plan: Callable[[int, int], list[PlannedMove]] | None = None
    #: Where the "retreat" error reaction goes, at its low speed.
    retreat: PlannedMove | None = None
    #: Cycles to run when the caller does not say.
    default_cycles: int = 1
    #: Runs once in IDLE before the first step (e.g. open the gripper).
    prepare: Action | None = None

    def add(
        self,
        name: str,
        action: Action,
        *,
        retry: RetryRule | None = None,
        guard: Predicate | None = None,
        guard_name: str | None = None,
        when: Predicate | None = None,
        description: str = "",
    ) -> TaskSequence:
        """Append a step; returns the sequence so calls can be chained."""
        if not name or not name.replace("_", "").isalnum():
            raise ConfigError(f"step name {name!r}: use letters, digits and underscores")
        if name in RESERVED_STATES:
            raise ConfigError(f"step name {name!r} is reserved ({', '.join(RESERVED_STATES)})")
        if any(s.name == name for s in self.steps):
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
            )
        )
        return self

    def step(
        self,
        name: str,
        *,
        retry: RetryRule | None = None,
        guard: Predicate | None = None,
        when: Predicate | None = None,
    ) -> Callable[[ActionT], ActionT]:
        """Decorator form of :meth:`add`."""

        def register(action: ActionT) -> ActionT:
            self.add(name, action, retry=retry, guard=guard, when=when)
            return action

        return register

    def validate(self) -> None:
        """Check the structure: at least one step, retry targets exist and come earlier."""
        if not self.steps:
            raise ConfigError(f"sequence {self.name!r} has no steps")
        names = [s.name for s in self.steps]
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

    def planned_moves(self, cycles: int) -> Iterable[PlannedMove]:
        """Every move known in advance over ``cycles`` cycles, then the retreat."""
        if self.plan is not None:
            for cycle in range(1, cycles + 1):
                yield from self.plan(cycle, cycles)
        if self.retreat is not None:
            yield self.retreat
