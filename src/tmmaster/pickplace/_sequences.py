"""Built-in sequences: the article's pick & place, palletizing, and sequences read from TOML.

Each function only builds a :class:`TaskSequence` (states and what to do in them); the
:class:`Runner` runs it with the shared policies.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from numbers import Real
from pathlib import Path
from typing import Annotated, Any, Literal, TypeVar
from weakref import WeakSet

from pydantic import BaseModel, ConfigDict, Field, StrictBool, ValidationError, model_validator

from .._exceptions import ConfigError, GraspFailedError
from .._gripper import NoGripper
from .._pose import MotionType, Pose
from .._robot import Robot
from ._config import (
    PickPlaceConfig,
    PoseValue,
    Speed,
    format_validation_error,
    read_config_data,
    units_problem,
)
from ._steps import (
    Action,
    Cycles,
    PlannedMove,
    RetryRule,
    StepContext,
    TaskSequence,
    refuse_held_part,
    require_count,
)

#: The article's states, in order (IDLE, DONE and ERROR are every machine's own).
#: The states of :func:`pick_and_place`, in order.
PICK_AND_PLACE_STATES = (
    "MOVE_TO_APPROACH",
    "MOVE_TO_PICK",
    "GRIPPER_CLOSE",
    "CHECK_GRASP",
    "MOVE_TO_LIFT",
    "MOVE_TO_PLACE",
    "GRIPPER_OPEN",
    "MOVE_TO_HOME",
)


#: The actions of this module that use the gripper: a robot without one refuses the
#: sequences that have them before anything moves (:func:`check_gripper_steps`).
_GRIPPER_ACTIONS: WeakSet[Action] = WeakSet()
_A = TypeVar("_A", bound=Action)


def _uses_gripper(action: _A) -> _A:
    _GRIPPER_ACTIONS.add(action)
    return action


def moves_no_arm(action: Action | None) -> bool:
    """Whether ``action`` is None or one of this module's gripper actions, which move no
    arm (a ``prepare`` of the user's code may: the runner checks the plan after it)."""
    return action is None or action in _GRIPPER_ACTIONS


def check_gripper_steps(robot: Robot, sequence: TaskSequence, source: str) -> None:
    """Refuse a sequence whose start or steps use the gripper on a robot that has none.

    Only the library's gripper actions are known (a TOML sequence's, the built-in ones);
    a Python step's own code is not.

    Raises:
        ConfigError: Naming the step (``steps.N``, its state) and ``source``.
    """
    if not isinstance(robot.gripper, NoGripper):
        return
    users = [
        f"steps.{i} ({s.name})"
        for i, s in enumerate(sequence.steps)
        if s.action in _GRIPPER_ACTIONS
    ]
    if sequence.prepare in _GRIPPER_ACTIONS:
        users.insert(0, "the start (open_at_start)")
    if users:
        raise ConfigError(
            f"{source}: {users[0]} uses the gripper, and this robot has none"
            f" (gripper kind 'none'){f' (and {len(users) - 1} more)' if users[1:] else ''}"
        )


def grasp_detected(ctx: StepContext) -> bool:
    """Guard: the last gripper reading saw an object between the fingers.

    Args:
        ctx: The step context.

    Returns:
        Whether an object was held at the last reading.
    """
    return ctx.last_gripper is not None and ctx.last_gripper.holding


@_uses_gripper
def _open(ctx: StepContext) -> None:
    ctx.open_gripper()


@_uses_gripper
def _require_empty(ctx: StepContext) -> None:
    """The start of a cycle that begins with a pick, without opening: a part the gripper
    reports holding would be carried down onto the next part."""
    if ctx.part_held(start=True):
        raise refuse_held_part(ctx.robot, opening=False)


@_uses_gripper
def _release(ctx: StepContext) -> None:
    """Open at the place, once the gripper still reports the part: one that slipped out
    on the way (a grip too weak to carry it) is a failure, never a part placed. A gripper
    that cannot tell (None) is opened as before. The runner's ``held_input`` (the robot's
    DI, read now) says it where the gripper's flag is only what its close recorded."""
    if ctx.part_held() is False:
        raise GraspFailedError(
            f"{ctx.state}: the gripper no longer holds the part it gripped: lost on the way"
            " from the pick (a grip too weak to carry it?); the fingers were left closed"
        )
    ctx.open_gripper()


@_uses_gripper
def _release_gripped(ctx: StepContext) -> None:
    """A TOML release: after a grip or check that saw a part (the last gripper reading),
    that part must still be held (:func:`_release`); with none seen, a plain open."""
    if grasp_detected(ctx):
        _release(ctx)
    else:
        ctx.open_gripper()


@_uses_gripper
def _close(ctx: StepContext) -> None:
    ctx.close_gripper()


@_uses_gripper
def _check(ctx: StepContext) -> None:
    ctx.check_holding(True)


def pick_and_place(config: PickPlaceConfig | None = None) -> TaskSequence:
    """The article's cycle: approach, pick, close, check, lift, place, open, home.

    A failed grasp opens the fingers and goes back to the approach, up to
    ``run.grasp_retries`` times. The start opens the gripper (``gripper.open_at_start``;
    the runner refuses to open one that holds a part unless
    ``gripper.release_held_part_at_start``); without the open, a gripper that holds a
    part fails the start (ConfigError), nothing moved.

    Args:
        config: Poses, speeds, motion types, retries and the error reaction; None: the
            defaults (the built-in cell).

    Returns:
        The sequence (:data:`PICK_AND_PLACE_STATES`).
    """
    cfg = config if config is not None else PickPlaceConfig()
    poses = cfg.poses.resolved()
    # A pose not written derives from pick: errors name what was written.
    derived = {
        name: f"poses.pick + {name}_z_offset"
        for name in ("approach", "lift")
        if getattr(cfg.poses, name) is None
    }
    moves = {
        name: PlannedMove(
            state=f"MOVE_TO_{name.upper()}",
            pose=poses[name],
            speed=getattr(cfg.speeds, name),
            motion=getattr(cfg.motion, name),
            source=derived.get(name, f"poses.{name}"),
        )
        for name in ("approach", "pick", "lift", "place", "home")
    }
    retreat = PlannedMove(
        state="RETREAT",
        pose=cfg.retreat_pose(),
        speed=cfg.on_error.speed,
        motion=cfg.on_error.motion,
        source="on_error.pose" if cfg.on_error.pose is not None else "poses.home",
    )
    seq = TaskSequence(
        "pick-and-place",
        retreat=retreat if cfg.on_error.reaction == "retreat" else None,
        default_cycles=cfg.run.cycles,
        prepare=_open if cfg.gripper.open_at_start else _require_empty,
    )
    seq.add("MOVE_TO_APPROACH", move=moves["approach"], description="above the pick pose")
    seq.add("MOVE_TO_PICK", move=moves["pick"], description="down to the part")
    seq.add("GRIPPER_CLOSE", _close, description="close the fingers")
    seq.add(
        "CHECK_GRASP",
        _check,
        retry=RetryRule("MOVE_TO_APPROACH", cfg.run.grasp_retries, recover=_open),
        guard=grasp_detected,
        description="require an object; else open, re-approach, try again",
    )
    seq.add("MOVE_TO_LIFT", move=moves["lift"], description="lift the part")
    seq.add("MOVE_TO_PLACE", move=moves["place"], description="to the place pose")
    seq.add("GRIPPER_OPEN", _release, description="release the part (still held)")
    seq.add("MOVE_TO_HOME", move=moves["home"], description="back home")
    return seq


# -- palletizing -----------------------------------------------------------------------


@dataclass(frozen=True)
class Pallet:
    """A grid of ``rows`` x ``cols`` slots with pitch ``dx``, ``dy``; ``layers`` high.

    Raises:
        ConfigError: A count that is not a whole number >= 1 (a fraction, a bool), or a
            pitch that is not a finite number.
    """

    #: The TCP pose of slot 0 (row 0, column 0, bottom layer).
    origin: Pose
    #: Rows, along y.
    rows: int
    #: Columns, along x.
    cols: int
    #: Pitch between columns, mm.
    dx: float
    #: Pitch between rows, mm.
    dy: float
    #: Layers, along z.
    layers: int = 1
    #: Pitch between layers, mm.
    dz: float = 0.0

    def __post_init__(self) -> None:
        # A fractional count (2.5 rows) made 2.5 cycles: 2 checked, 3 run, the third
        # into a row the pallet does not have. numpy's integers and floats are whole
        # numbers and numbers, as a Pose takes them; a count is kept as an int.
        for name in ("rows", "cols", "layers"):
            object.__setattr__(self, name, require_count(getattr(self, name), f"pallet {name}"))
        for name in ("dx", "dy", "dz"):
            pitch = getattr(self, name)
            if isinstance(pitch, bool) or not isinstance(pitch, Real):
                raise ConfigError(f"pallet {name} must be a finite number, got {pitch!r}")
            if not math.isfinite(pitch):
                raise ConfigError(f"pallet {name} must be a finite number")

    @property
    def size(self) -> int:
        """Number of slots."""
        return self.rows * self.cols * self.layers

    def slot(self, index: int) -> Pose:
        """Pose of slot ``index`` (0-based): row by row, then layer by layer.

        Args:
            index: The slot, 0 .. ``size`` - 1.

        Returns:
            Its TCP pose (the origin's orientation).

        Raises:
            ConfigError: An index outside the pallet.
        """
        if not 0 <= index < self.size:
            raise ConfigError(f"slot {index} outside the pallet (0..{self.size - 1})")
        per_layer = self.rows * self.cols
        layer, rest = divmod(index, per_layer)
        row, col = divmod(rest, self.cols)
        return self.origin.offset(dx=col * self.dx, dy=row * self.dy, dz=layer * self.dz)


def palletizing(
    *,
    pick: Pose,
    pallet: Pallet,
    home: Pose,
    approach_dz: float = 100.0,
    speed: int = 30,
    slow_speed: int = 10,
    grasp_retries: int = 2,
    retreat_speed: int = 10,
) -> TaskSequence:
    """Pick parts from one spot and place cycle k into slot k of ``pallet``, then go home.

    Args:
        pick: Where each part is picked.
        pallet: The slots; one cycle per slot (its default cycle count).
        home: Where the arm goes at the end of each cycle.
        approach_dz: Height of the approach above the pick and the slots, mm.
        speed: Speed of the travel moves, %.
        slow_speed: Speed into and out of the pick and the slots, %.
        grasp_retries: Attempts after a failed grasp (open, re-approach).
        retreat_speed: Speed of the retreat home after a failure, %.

    Returns:
        The sequence.
    """
    above_pick = pick.offset(dz=approach_dz)
    ptp, line = MotionType.PTP, MotionType.LINE

    def slot(cycle: int) -> Pose:
        return pallet.slot(cycle - 1)

    def above_slot(cycle: int) -> PlannedMove:
        return PlannedMove(
            "MOVE_TO_SLOT_ABOVE", slot(cycle).offset(dz=approach_dz), speed, ptp, f"slot {cycle}"
        )

    def into_slot(cycle: int) -> PlannedMove:
        return PlannedMove("MOVE_TO_SLOT", slot(cycle), slow_speed, line, f"slot {cycle}")

    def clear_slot(cycle: int) -> PlannedMove:
        return PlannedMove(
            "MOVE_TO_SLOT_CLEAR",
            slot(cycle).offset(dz=approach_dz),
            slow_speed,
            line,
            f"slot {cycle}",
        )

    seq = TaskSequence(
        "palletizing",
        retreat=PlannedMove("RETREAT", home, retreat_speed, ptp, "home"),
        default_cycles=pallet.size,
        prepare=_open,
    )
    seq.add(
        "MOVE_TO_APPROACH", move=PlannedMove("MOVE_TO_APPROACH", above_pick, speed, ptp, "pick")
    )
    seq.add("MOVE_TO_PICK", move=PlannedMove("MOVE_TO_PICK", pick, slow_speed, line, "pick"))
    seq.add("GRIPPER_CLOSE", _close)
    seq.add(
        "CHECK_GRASP",
        _check,
        retry=RetryRule("MOVE_TO_APPROACH", grasp_retries, recover=_open),
        guard=grasp_detected,
    )
    seq.add("MOVE_TO_LIFT", move=PlannedMove("MOVE_TO_LIFT", above_pick, slow_speed, line, "pick"))
    seq.add("MOVE_TO_SLOT_ABOVE", move=above_slot)
    seq.add("MOVE_TO_SLOT", move=into_slot)
    seq.add("GRIPPER_OPEN", _release)
    seq.add("MOVE_TO_SLOT_CLEAR", move=clear_slot)
    seq.add(
        "MOVE_TO_HOME", move=PlannedMove("MOVE_TO_HOME", home, speed, ptp, "home"), when=Cycles.LAST
    )
    return seq


# -- sequences described as data ------------------------------------------------------------


class _DataStep(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    #: State name (UPPER_CASE by convention); default: the action and its position.
    state: str | None = None
    #: Run always, only in the first cycle, or only in the last.
    when: Cycles = Cycles.ALWAYS


class _Retrying(_DataStep):
    #: On a failed grasp: open, go back to this (earlier) state, try again.
    retry_from: str | None = None
    retries: Annotated[int, Field(ge=0, le=20, strict=True)] = 0

    @model_validator(mode="after")
    def _pair(self) -> _Retrying:
        if self.retries and self.retry_from is None:
            raise ValueError("retries needs retry_from (the state to go back to)")
        return self


class MoveStep(_DataStep):
    """Move to a pose (a name from [poses] or six numbers)."""

    do: Literal["move"]
    pose: str | PoseValue
    speed: Speed
    motion: MotionType = MotionType.PTP
    #: Added to the pose's z, mm (e.g. 100 above a named pose).
    z_offset: Annotated[float, Field(strict=True)] = 0.0


class GripStep(_Retrying):
    """Close the gripper and require an object."""

    do: Literal["grip"]


class ReleaseStep(_DataStep):
    """Open the gripper."""

    do: Literal["release"]


class WaitStep(_DataStep):
    """Dwell (interruptible by a stop request)."""

    do: Literal["wait"]
    seconds: Annotated[float, Field(gt=0, le=3600, strict=True)]


class CheckStep(_Retrying):
    """Require the gripper to hold (or not hold) an object."""

    do: Literal["check"]
    holding: StrictBool = True


DataStep = Annotated[
    MoveStep | GripStep | ReleaseStep | WaitStep | CheckStep, Field(discriminator="do")
]


class RetreatSpec(BaseModel):
    """Safe pose for the "retreat" error reaction."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    pose: str | PoseValue
    speed: Speed = 10
    motion: MotionType = MotionType.PTP


class SequenceFile(BaseModel):
    """A sequence described as data (TOML)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    name: Annotated[str, Field(min_length=1)]
    cycles: Annotated[int, Field(ge=1, le=1_000_000, strict=True)] = 1
    open_at_start: StrictBool = True
    #: Refuse a pose of this file that looks like metres or radians; false: take them
    #: as mm and degrees.
    check_units: StrictBool = True
    poses: dict[str, PoseValue] = {}
    steps: Annotated[list[DataStep], Field(min_length=1)]
    retreat: RetreatSpec | None = None


def _action_of(step: GripStep | ReleaseStep | WaitStep | CheckStep) -> Action:
    """What a step that is not a move does."""
    if isinstance(step, GripStep):
        return _grip
    if isinstance(step, ReleaseStep):
        return _release_gripped
    if isinstance(step, WaitStep):
        return _waiter(step.seconds)
    return _checker(step.holding)


def sequence_from_data(data: Mapping[str, Any], *, source: str = "<data>") -> TaskSequence:
    """Build a sequence from a mapping (a parsed TOML file); errors name key and source.

    Args:
        data: The sequence's keys (docs/pickplace.md describes the file).
        source: Where the data comes from, for the messages.

    Returns:
        The sequence.

    Raises:
        ConfigError: An invalid key or value, naming it and ``source``.
    """
    try:
        spec = SequenceFile.model_validate(dict(data))
    except ValidationError as exc:
        raise ConfigError(format_validation_error(exc, source)) from None
    if spec.check_units:
        _check_units(spec, source)

    def pose_of(value: str | tuple[float, ...], where: str) -> Pose:
        if isinstance(value, str):
            if value not in spec.poses:
                known = ", ".join(sorted(spec.poses)) or "none"
                raise ConfigError(f"{source}: {where}: unknown pose {value!r} (known: {known})")
            return Pose.from_sequence(spec.poses[value])
        return Pose.from_sequence(value)

    seq = TaskSequence(
        spec.name, default_cycles=spec.cycles, prepare=_open if spec.open_at_start else None
    )
    for index, step in enumerate(spec.steps):
        name = step.state or f"{step.do.upper()}_{index + 1}"
        where = f"steps.{index}"
        action: Action | None = None
        planned: PlannedMove | None = None
        retry: RetryRule | None = None
        if isinstance(step, MoveStep):
            pose = pose_of(step.pose, f"{where}.pose").offset(dz=step.z_offset)
            planned = PlannedMove(name, pose, step.speed, step.motion, f"{where}.pose")
        else:
            action = _action_of(step)
        if isinstance(step, _Retrying) and step.retry_from is not None:
            retry = RetryRule(step.retry_from, step.retries, recover=_open)
        try:
            when = None if step.when is Cycles.ALWAYS else step.when
            seq.add(name, action, move=planned, retry=retry, when=when)
        except ConfigError as exc:
            raise ConfigError(f"{source}: {where}.state: {exc}") from None
    try:
        seq.validate()
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None

    if spec.retreat is not None:
        seq.retreat = PlannedMove(
            "RETREAT",
            pose_of(spec.retreat.pose, "retreat.pose"),
            spec.retreat.speed,
            spec.retreat.motion,
            "retreat.pose",
        )
    return seq


def _check_units(spec: SequenceFile, source: str) -> None:
    """Refuse a pose of the file that looks like metres or radians, quoting it as written."""
    given: list[tuple[str, str | tuple[float, ...]]] = [
        *((f"poses.{name}", values) for name, values in spec.poses.items()),
        *(
            (f"steps.{index}.pose", step.pose)
            for index, step in enumerate(spec.steps)
            if isinstance(step, MoveStep)
        ),
    ]
    if spec.retreat is not None:
        given.append(("retreat.pose", spec.retreat.pose))
    for where, values in given:
        if isinstance(values, str):
            continue  # a name from [poses], checked there
        problem = units_problem(where, values, "check_units = false at the top of the file")
        if problem is not None:
            raise ConfigError(f"{source}: {problem}")


def load_sequence(path: str | Path) -> TaskSequence:
    """Read a sequence described in a TOML file (see docs/pickplace.md).

    Args:
        path: The file.

    Returns:
        The sequence.

    Raises:
        ConfigError: An unreadable file or an invalid sequence, naming the file.
    """
    return sequence_from_data(read_config_data(path), source=str(path))


@_uses_gripper
def _grip(ctx: StepContext) -> None:
    ctx.grip()


def _waiter(seconds: float) -> Action:
    def wait(ctx: StepContext) -> None:
        ctx.wait(seconds)

    return wait


def _checker(holding: bool) -> Action:
    @_uses_gripper
    def check(ctx: StepContext) -> None:
        ctx.check_holding(holding)

    return check
