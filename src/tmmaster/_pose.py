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
    """A TCP pose in the robot base frame: position in mm, orientation in degrees."""

    x: float
    y: float
    z: float
    rx: float = 0.0
    ry: float = 0.0
    rz: float = 0.0

    @classmethod
    def from_sequence(cls, values: Sequence[float]) -> Pose:
        """Build a pose from ``[x, y, z, rx, ry, rz]``."""
        if len(values) != 6:
            raise ValueError(f"a pose needs 6 values [x, y, z, rx, ry, rz], got {len(values)}")
        return cls(*values)

    def as_list(self) -> list[float]:
        """Return ``[x, y, z, rx, ry, rz]``."""
        return [self.x, self.y, self.z, self.rx, self.ry, self.rz]

    def __iter__(self) -> Iterator[float]:
        return iter(self.as_list())

    def distance_to(self, other: Pose) -> float:
        """Euclidean distance between the two positions, in mm."""
        return math.dist((self.x, self.y, self.z), (other.x, other.y, other.z))

    def rotation_to(self, other: Pose) -> float:
        """Largest change of one orientation angle, in degrees (wrapped to ±180)."""
        return max(
            abs(_wrap(b - a))
            for a, b in zip(
                (self.rx, self.ry, self.rz), (other.rx, other.ry, other.rz), strict=True
            )
        )

    def is_close(self, other: Pose, *, mm: float = 0.5, deg: float = 0.5) -> bool:
        """True when both position and orientation agree within the tolerances."""
        return self.distance_to(other) <= mm and self.rotation_to(other) <= deg

    def offset(self, *, dx: float = 0.0, dy: float = 0.0, dz: float = 0.0) -> Pose:
        """Return this pose translated by the given offsets."""
        return Pose(self.x + dx, self.y + dy, self.z + dz, self.rx, self.ry, self.rz)

    def __str__(self) -> str:
        return (
            f"({self.x:.2f}, {self.y:.2f}, {self.z:.2f} mm; "
            f"{self.rx:.2f}, {self.ry:.2f}, {self.rz:.2f} deg)"
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


def _wrap(angle: float) -> float:
    return (angle + 180.0) % 360.0 - 180.0
