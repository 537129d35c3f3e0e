"""Cartesian poses and motion types shared by the master and the simulator."""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Iterator, Sequence
from enum import StrEnum
from numbers import Real
from typing import Any

from pydantic import ConfigDict, Field, ValidationError, field_validator
from pydantic.dataclasses import dataclass
from pydantic_core import PydanticCustomError

from ._checks import shown
from ._error_root import ConfigError

_POSE_FIELDS = ("x", "y", "z", "rx", "ry", "rz")


class MotionType(StrEnum):
    """How the robot interpolates a move: in joint space (PTP) or along a straight line."""

    PTP = "ptp"
    LINE = "line"


@dataclass(frozen=True, config=ConfigDict(allow_inf_nan=False, extra="forbid"))
class Pose:
    """A TCP pose in the robot base frame: position in mm, orientation in degrees.

    The orientation is Techman's: ``Rz(rz) @ Ry(ry) @ Rx(rx)``, as TMflow shows it.
    Every coordinate must be a finite real number (``numbers.Real``): an int, a float,
    numpy's integers and floats, a Fraction. Not a str, not a bool (Python's or numpy's),
    which pydantic's lax mode would convert, nor a Decimal or a numpy array: anything
    else raises :class:`~tmmaster.ConfigError` naming the coordinate.

    Example:
        ```python
        from tmmaster import Pose

        pick = Pose(300, -200, 200, 180, 0, 90)
        above = pick.offset(dz=100)  # 100 mm higher, same orientation
        print(above.distance_to(pick))  # 100.0
        ```
    """

    #: Position along the base's x axis, mm.
    x: float = Field(strict=True)
    #: Position along the base's y axis, mm.
    y: float = Field(strict=True)
    #: Position along the base's z axis, mm.
    z: float = Field(strict=True)
    #: Rotation about x, degrees.
    rx: float = Field(strict=True)
    #: Rotation about y, degrees.
    ry: float = Field(strict=True)
    #: Rotation about z, degrees.
    rz: float = Field(strict=True)

    # Pydantic's strict float alone takes whatever has ``__float__`` but a bool or a str:
    # numpy's bool (as 1.0), a 0-d array, a Decimal.
    @field_validator(*_POSE_FIELDS, mode="before")
    @classmethod
    def _real(cls, value: object) -> object:
        """A coordinate as given, when it is a real number (``numbers.Real``) but a bool."""
        if isinstance(value, float) or (isinstance(value, Real) and not isinstance(value, bool)):
            return value  # a float first: the common case, without the ABC's check
        raise PydanticCustomError("float_type", "Input should be a valid number")

    @classmethod
    def from_sequence(cls, values: Sequence[float]) -> Pose:
        """Build a pose from ``[x, y, z, rx, ry, rz]``.

        Args:
            values: Six numbers, mm and degrees.

        Returns:
            The pose.

        Raises:
            ValueError: Not six values (a ConfigError when one is not a finite number).
        """
        if len(values) != 6:
            raise ConfigError(pose_count_problem(values))
        return cls(*values)

    @classmethod
    def parse(cls, text: str) -> Pose:
        """A pose from ``"X,Y,Z,RX,RY,RZ"`` (a command-line option's text).

        Args:
            text: six comma-separated numbers, mm and degrees.

        Returns:
            The pose.

        Raises:
            ConfigError: not six numbers, or one that is not finite (naming it).
        """
        parts = text.split(",")
        if len(parts) != 6:
            raise ConfigError(f"need 6 comma-separated numbers, got {len(parts)}")
        try:
            values = [float(part) for part in parts]
        except ValueError as exc:
            raise ConfigError(f"not a number: {exc}") from None
        return cls(*values)

    def as_list(self) -> list[float]:
        """The six coordinates as a list.

        Returns:
            ``[x, y, z, rx, ry, rz]``.
        """
        return [self.x, self.y, self.z, self.rx, self.ry, self.rz]

    def __iter__(self) -> Iterator[float]:
        return iter(self.as_list())

    def distance_to(self, other: Pose) -> float:
        """Euclidean distance between the two positions, in mm.

        Args:
            other: The other pose (its orientation is ignored).

        Returns:
            The distance, mm.
        """
        return math.dist((self.x, self.y, self.z), (other.x, other.y, other.z))

    def rotation_to(self, other: Pose) -> float:
        """The angle of the rotation from this orientation to ``other``'s, in degrees (0..180).

        Compared as rotations, not angle by angle: Euler angles that describe the same
        orientation (``(0, 180, -90)`` and ``(180, 0, 90)``, ``rz`` = 180 and -180, any
        ``rx``/``rz`` split at ``ry`` = ±90) are 0 degrees apart, as a robot reporting its
        own Euler angles may describe a pose it reached exactly.

        Args:
            other: the other pose (its position is ignored).

        Returns:
            The geodesic angle between the two orientations.
        """
        w1, x1, y1, z1 = _quaternion(self.rx, self.ry, self.rz)
        w2, x2, y2, z2 = _quaternion(other.rx, other.ry, other.rz)
        # The relative rotation conj(q1) * q2: its vector part's norm and its scalar part
        # give the angle without acos' loss of precision near 0.
        w = w1 * w2 + x1 * x2 + y1 * y2 + z1 * z2
        x = w1 * x2 - x1 * w2 - y1 * z2 + z1 * y2
        y = w1 * y2 + x1 * z2 - y1 * w2 - z1 * x2
        z = w1 * z2 - x1 * y2 + y1 * x2 - z1 * w2
        return math.degrees(2.0 * math.atan2(math.sqrt(x * x + y * y + z * z), abs(w)))

    def is_close(self, other: Pose, *, mm: float = 0.5, deg: float = 0.5) -> bool:
        """True when both position and orientation agree within the tolerances.

        Args:
            other: The other pose.
            mm: Largest distance between the positions, mm.
            deg: Largest rotation between the orientations (:meth:`rotation_to`), deg.

        Returns:
            Whether both agree.
        """
        return self.distance_to(other) <= mm and self.rotation_to(other) <= deg

    def offset(self, *, dx: float = 0.0, dy: float = 0.0, dz: float = 0.0) -> Pose:
        """This pose translated by the given offsets (in the base frame), same orientation.

        Args:
            dx: Offset along x, mm.
            dy: Offset along y, mm.
            dz: Offset along z, mm.

        Returns:
            The translated pose.
        """
        return Pose(self.x + dx, self.y + dy, self.z + dz, self.rx, self.ry, self.rz)

    def __str__(self) -> str:
        return (
            f"({self.x:.2f}, {self.y:.2f}, {self.z:.2f} mm; "
            f"{self.rx:.2f}, {self.ry:.2f}, {self.rz:.2f} deg)"
        )


@functools.lru_cache(maxsize=1024)  # poses recur: targets, the poses a cycle reads back
def _quaternion(rx: float, ry: float, rz: float) -> tuple[float, float, float, float]:
    """The unit quaternion (w, x, y, z) of TM's orientation ``Rz(rz) @ Ry(ry) @ Rx(rx)``, deg."""
    cr, sr = math.cos(math.radians(rx) / 2), math.sin(math.radians(rx) / 2)
    cp, sp = math.cos(math.radians(ry) / 2), math.sin(math.radians(ry) / 2)
    cy, sy = math.cos(math.radians(rz) / 2), math.sin(math.radians(rz) / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


class UnitsError(ConfigError):
    """A pose whose values look like metres or radians, where tmmaster takes mm and degrees.

    Raised by :class:`~tmmaster.Robot` for a target (before anything is sent) and for its
    ``tool`` (when the robot is made), naming the values and the rule they match; the
    rules are in docs/robot-api.md ("Units"). ``Robot(checks=Checks(units=False))``
    takes such values as written.
    """


#: Within this (mm) of the base origin on all three axes, a position looks like metres:
#: no TM arm reaches there, and every TM arm's reach is under 2 m.
METRES_LIMIT = 2.0
#: Within this of a multiple of 45 degrees in radians (pi/4 .. 2 pi), an angle looks like
#: radians: 3.14, 3.1416, 1.5708 and 0.785 do, 3, 1.5 and 0.8 do not.
RADIANS_TOLERANCE = 0.005
_QUARTER_TURNS = [k * math.pi / 4 for k in range(1, 9)]
#: Read as radians, a tool z axis within this of straight down (degrees) looks like a
#: tool-down pose written in radians: ``cos(ry) * cos(rx) <= -cos(45 deg)``.
TOOL_DOWN_DEG = 45.0


def written(value: float) -> str:
    """A number as a user writes it: ``300`` for 300.0, ``0.3``, ``3.14159``."""
    number = float(value)
    if math.isfinite(number) and number.is_integer() and abs(number) < 1e15:
        return str(int(number))
    return repr(number)


def written_list(values: Iterable[object]) -> str:
    """Values as a user writes them: ``[0.3, -0.2, 0.1, 180, 0, 90]``."""
    shown = (written(v) if isinstance(v, int | float) else repr(v) for v in values)
    return f"[{', '.join(shown)}]"


def pose_count_problem(values: Sequence[object]) -> str:
    """What is wrong with ``values`` that are not six: the count and the names missing."""
    message = (
        f"{written_list(values)} has {len(values)} value{'' if len(values) == 1 else 's'};"
        " a pose needs all 6: x, y, z (mm), rx, ry, rz (degrees)"
    )
    if len(values) < 6:
        missing = ", ".join(_POSE_FIELDS[len(values) :])
        message += f" ({missing} missing)"
    return message


def suspect_units(values: Sequence[float]) -> str | None:
    """Why ``[x, y, z, rx, ry, rz]`` looks like metres or radians, or None.

    The rules (docs/robot-api.md, "Units"):

    - **metres**: ``|x|``, ``|y|`` and ``|z|`` all under :data:`METRES_LIMIT` (2 mm from
      the base origin, inside the robot's own base) and not all zero;
    - **radians, a quarter turn**: ``|rx|``, ``|ry|`` and ``|rz|`` all at most 2 pi (with
      :data:`RADIANS_TOLERANCE` to spare), and one of them within
      :data:`RADIANS_TOLERANCE` of a multiple of pi/4 (0.785, 1.571, 3.1416, ...);
    - **radians, tool down**: the three angles all at most 2 pi, so that read as degrees
      the tool points within 9 degrees of straight up, and read as radians it points
      within :data:`TOOL_DOWN_DEG` of straight down: ``cos(ry) * cos(rx) <= -cos(45
      deg)`` (the tool z axis's z component under Techman's ``Rz @ Ry @ Rx``).

    Small degree values (0, 1.5, 5, 0.5) and every usual degree pose (180, 0, 90) match
    none of them.

    Args:
        values: the six values, mm and degrees as the user gave them.

    Returns:
        None, or the reason, quoting the values as written.
    """
    x, y, z, rx, ry, rz = (float(v) for v in values)
    position, angles = (x, y, z), (rx, ry, rz)
    if all(abs(v) < METRES_LIMIT for v in position) and any(position):
        first = next(v for v in position if v)
        return (
            f"x, y, z = {', '.join(map(written, position))} look like metres: positions are"
            f" in mm ({written(first)} m is {written(round(first * 1000, 3))} mm)"
        )
    if not all(abs(a) <= 2 * math.pi + RADIANS_TOLERANCE for a in angles):
        return None
    said = f"rx, ry, rz = {', '.join(map(written, angles))} look like radians"
    for angle in angles:
        if any(abs(abs(angle) - q) <= RADIANS_TOLERANCE for q in _QUARTER_TURNS):
            degrees = round(math.degrees(angle))
            return f"{said}: orientations are in degrees ({written(angle)} rad is {degrees} deg)"
    tool_z = math.cos(ry) * math.cos(rx)  # read as radians
    if tool_z <= -math.cos(math.radians(TOOL_DOWN_DEG)):
        down = math.degrees(math.acos(min(1.0, -tool_z)))
        up = math.degrees(math.acos(math.cos(math.radians(ry)) * math.cos(math.radians(rx))))
        return (
            f"{said}: orientations are in degrees (read as radians the tool points"
            f" {down:.0f} deg from straight down, read as degrees {up:.0f} deg from"
            " straight up)"
        )
    return None


def refuse_suspect_units(what: str, pose: Pose) -> None:
    """Raise :class:`UnitsError` when ``pose`` looks like metres or radians.

    Args:
        what: what the pose is, for the message (``"target"``, ``"tool"``).
        pose: the pose as the user gave it.

    Raises:
        UnitsError: naming the values and the rule they match, and the opt-out.
    """
    problem = suspect_units(pose.as_list())
    if problem is not None:
        raise UnitsError(
            f"{what} {written_list(pose)}: {problem}; if these really are mm and degrees,"
            " make the robot with Robot(checks=Checks(units=False))"
        )


_validated_init = Pose.__init__


def _pose_init(self: Pose, *args: Any, **kwargs: Any) -> None:
    # A pose built in code fails as a ConfigError naming the coordinate, like every
    # other invalid input; inside a pydantic model it stays that model's validation error.
    try:
        _validated_init(self, *args, **kwargs)
    except ValidationError as exc:
        problems = []
        missing = []
        for error in exc.errors():
            where = error["loc"][0] if error["loc"] else "pose"
            name = _POSE_FIELDS[where] if isinstance(where, int) and where < 6 else where
            if error["type"] == "missing":
                missing.append(str(name))
            elif error["type"] == "float_type":
                problems.append(f"{name} must be an int or float, got {shown(error['input'])}")
            elif error["type"] != "unexpected_positional_argument":
                problems.append(f"{name}: {error['msg']}")
        given = [shown(a) for a in args] + [f"{k}={shown(v)}" for k, v in kwargs.items()]
        needs = "a pose needs all 6: x, y, z (mm), rx, ry, rz (degrees)"
        if missing:
            problems.insert(0, f"{', '.join(missing)} missing in Pose({', '.join(given)}); {needs}")
        elif len(args) > 6:
            problems.insert(0, f"{len(args)} values in Pose({', '.join(given)}); {needs}")
        raise ConfigError(f"invalid pose: {'; '.join(problems)}") from exc


Pose.__init__ = _pose_init  # type: ignore[method-assign]


#: Home pose of the default pick & place cell: tool down, 250 mm in front of J1. (The
#: article's HOME (0, 0, 300, 180, 0, 0) is out of a TM5's reach: docs/pickplace.md.)
DEFAULT_HOME = Pose(250.0, 0.0, 300.0, 180.0, 0.0, 90.0)
