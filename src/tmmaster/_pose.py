"""Cartesian poses and motion types shared by the master and the simulator."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from enum import StrEnum
from typing import Any

from pydantic import ConfigDict, ValidationError
from pydantic.dataclasses import dataclass

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
    Every coordinate must be a finite number: anything else raises
    :class:`~tmmaster.ConfigError` naming the coordinate.

    Example:
        ```python
        from tmmaster import Pose

        pick = Pose(300, -200, 200, 180, 0, 90)
        above = pick.offset(dz=100)  # 100 mm higher, same orientation
        print(above.distance_to(pick))  # 100.0
        ```
    """

    #: Position along the base's x axis, mm.
    x: float
    #: Position along the base's y axis, mm.
    y: float
    #: Position along the base's z axis, mm.
    z: float
    #: Rotation about x, degrees.
    rx: float = 0.0
    #: Rotation about y, degrees.
    ry: float = 0.0
    #: Rotation about z, degrees.
    rz: float = 0.0

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
            raise ValueError(f"a pose needs 6 values [x, y, z, rx, ry, rz], got {len(values)}")
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


_validated_init = Pose.__init__


def _pose_init(self: Pose, *args: Any, **kwargs: Any) -> None:
    # A pose built in code fails as a ConfigError naming the coordinate, like every
    # other invalid input; inside a pydantic model it stays that model's validation error.
    try:
        _validated_init(self, *args, **kwargs)
    except ValidationError as exc:
        problems = []
        for error in exc.errors():
            where = error["loc"][0] if error["loc"] else "pose"
            name = _POSE_FIELDS[where] if isinstance(where, int) and where < 6 else where
            problems.append(f"{name}: {error['msg']}")
        raise ConfigError(f"invalid pose: {'; '.join(problems)}") from exc


Pose.__init__ = _pose_init  # type: ignore[method-assign]


#: Home pose of the default pick & place cell: tool down, 250 mm in front of J1. (The
#: article's HOME (0, 0, 300, 180, 0, 0) is out of a TM5's reach: docs/pickplace.md.)
DEFAULT_HOME = Pose(250.0, 0.0, 300.0, 180.0, 0.0, 90.0)
