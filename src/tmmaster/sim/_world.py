"""Objects on the simulated table, the grasp rule and the falling rule.

Every object is a box with a size (along its own x, y, z axes) and a mass; its pose is
the pose of its centre, which is also the point the fingers grip (a held object's pose
*is* the TCP pose). The table is a horizontal plane at :attr:`World.table_top_z_mm`.

The falling rule (the same for every backend, see ``docs/simulator-model.md``): an
object the gripper lets go of drops straight down, keeping its x, y and orientation,
onto the highest support below it: the table top, or the top of another object whose
footprint overlaps its own. Nothing tips over, slides or bounces in this analytic
world; a physics backend (MuJoCo) may add that, and the place check only relies on the
resting x-y and on *what* the object rests on.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, PositiveFloat, model_validator

from .. import _kinematics as kin
from .._pose import Pose
from ._backend import ObjectState

#: Pick position of the part in the article's pick-and-place example.
DEFAULT_PART_POSE = Pose(300.0, -200.0, 100.0, 180.0, 0.0, 90.0)

#: Size of the default part (a 30 mm cube), mm.
DEFAULT_PART_SIZE_MM = (30.0, 30.0, 30.0)

#: Height of the table top in the robot base frame, mm: the default part (centre at
#: DEFAULT_PART_POSE, 30 mm high) rests on it exactly where it starts.
DEFAULT_TABLE_TOP_Z_MM = DEFAULT_PART_POSE.z - DEFAULT_PART_SIZE_MM[2] / 2

#: A support may be this far above an object's bottom and still carry it (float slack).
SUPPORT_TOLERANCE_MM = 0.5

#: Name :attr:`ObjectState.resting_on` gives the table.
TABLE = "table"


class TableObject(BaseModel):
    """A box lying on the table that the gripper can pick up."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str = Field(min_length=1)
    #: Pose of the box's centre (the grasp point).
    pose: Pose
    #: Size along the box's own x, y (across the fingers) and z axes, mm.
    size_mm: tuple[PositiveFloat, PositiveFloat, PositiveFloat] = DEFAULT_PART_SIZE_MM
    mass_kg: float = Field(default=0.1, gt=0, le=50)
    #: How far the TCP may be from the object's position for a grasp to work, mm.
    grasp_tolerance_mm: float = Field(default=5.0, ge=0)

    @model_validator(mode="before")
    @classmethod
    def _width_shorthand(cls, data: Any) -> Any:
        # width_mm=W is shorthand for a size of (30, W, 30): W across the fingers.
        if isinstance(data, dict) and "width_mm" in data:
            data = dict(data)
            width = data.pop("width_mm")
            if "size_mm" in data:
                size = tuple(data["size_mm"])
                if len(size) != 3 or size[1] != width:
                    raise ValueError("give width_mm or size_mm, not both")
            else:
                data["size_mm"] = (DEFAULT_PART_SIZE_MM[0], width, DEFAULT_PART_SIZE_MM[2])
        return data

    @property
    def width_mm(self) -> float:
        """Size across the fingers (the box's y), mm."""
        return self.size_mm[1]

    def half_extents_mm(self, pose: Pose | None = None) -> tuple[float, float, float]:
        """Half size of the box's axis-aligned bounding box in the base frame at ``pose``."""
        rot = kin.pose_to_transform(self.pose if pose is None else pose)
        half = [s / 2 for s in self.size_mm]
        return (
            sum(abs(rot[0][j]) * half[j] for j in range(3)),
            sum(abs(rot[1][j]) * half[j] for j in range(3)),
            sum(abs(rot[2][j]) * half[j] for j in range(3)),
        )


class World:
    """The objects on the table, which one the gripper holds, the grasp and falling rules."""

    def __init__(
        self,
        objects: Iterable[TableObject] | None = None,
        *,
        table_top_z_mm: float = DEFAULT_TABLE_TOP_Z_MM,
    ) -> None:
        if not math.isfinite(table_top_z_mm):
            raise ValueError(f"table_top_z_mm must be finite, got {table_top_z_mm}")
        self.table_top_z_mm = float(table_top_z_mm)
        items = [TableObject(name="part", pose=DEFAULT_PART_POSE)] if objects is None else objects
        self._objects: dict[str, TableObject] = {}
        self._resting_on: dict[str, str | None] = {}
        for item in items:
            if item.name in self._objects:
                raise ValueError(f"duplicate object name {item.name!r}")
            self._objects[item.name] = item
        self._held: str | None = None
        # Objects start at rest: each one placed in the air drops onto its support,
        # lowest first (so one standing on another finds it already settled).
        for name in sorted(self._objects, key=lambda n: self._bottom(self._objects[n])):
            self._drop(name)

    @property
    def held(self) -> TableObject | None:
        """The object between the fingers, or None."""
        return None if self._held is None else self._objects[self._held]

    @property
    def objects(self) -> tuple[TableObject, ...]:
        """Every object with its current pose."""
        return tuple(self._objects.values())

    def get(self, name: str) -> TableObject:
        """Return the object called ``name`` with its current pose."""
        try:
            return self._objects[name]
        except KeyError:
            raise KeyError(f"no object named {name!r}") from None

    def resting_on(self, name: str) -> str | None:
        """What ``name`` rests on ("table" or an object's name), None while held."""
        self.get(name)
        return self._resting_on.get(name)

    def grasp_candidate(
        self, tcp: Pose, *, current_width_mm: float, target_width_mm: float
    ) -> TableObject | None:
        """The object fingers closing from ``current`` to ``target`` at ``tcp`` would stop on."""
        if self._held is not None or target_width_mm >= current_width_mm:
            return None
        candidates = [
            obj
            for obj in self._objects.values()
            if tcp.distance_to(obj.pose) <= obj.grasp_tolerance_mm
            # Fingers already touching (equal width) still count: they are on the object.
            and target_width_mm < obj.width_mm <= current_width_mm
        ]
        # Closing fingers meet the widest object first.
        return max(candidates, key=lambda obj: obj.width_mm, default=None)

    def grasp(self, name: str, tcp: Pose) -> None:
        """Mark ``name`` as held; it snaps to the TCP pose."""
        if self._held is not None and self._held != name:
            raise RuntimeError(f"already holding {self._held!r}, cannot grasp {name!r}")
        self._objects[name] = self.get(name).model_copy(update={"pose": tcp})
        self._held = name
        self._resting_on[name] = None

    def follow(self, tcp: Pose) -> None:
        """Move the held object (if any) rigidly with the TCP."""
        if self._held is not None:
            self._objects[self._held] = self._objects[self._held].model_copy(update={"pose": tcp})

    def release(self, tcp: Pose) -> TableObject | None:
        """Let go of the held object at the TCP; it falls onto its support. Return it."""
        if self._held is None:
            return None
        self.follow(tcp)
        name = self._held
        self._held = None
        self._drop(name)
        return self._objects[name]

    def support_below(self, obj: TableObject, pose: Pose | None = None) -> tuple[str, float]:
        """The highest support under ``obj`` (at ``pose``): its name and top height, mm."""
        pose = obj.pose if pose is None else pose
        hx, hy, hz = obj.half_extents_mm(pose)
        bottom = pose.z - hz
        best = (TABLE, self.table_top_z_mm)
        for other in self._objects.values():
            if other.name in (obj.name, self._held):
                continue
            ox, oy, oz = other.half_extents_mm()
            overlaps = abs(other.pose.x - pose.x) < ox + hx and abs(other.pose.y - pose.y) < oy + hy
            top = other.pose.z + oz
            if overlaps and top <= bottom + SUPPORT_TOLERANCE_MM and top > best[1]:
                best = (other.name, top)
        return best

    def states(self) -> list[ObjectState]:
        """Every object's name, pose, size, mass, whether it is held and what it rests on."""
        return [
            ObjectState(
                name=obj.name,
                pose=obj.pose,
                held=obj.name == self._held,
                size_mm=obj.size_mm,
                mass_kg=obj.mass_kg,
                resting_on=self._resting_on.get(obj.name),
            )
            for obj in self._objects.values()
        ]

    def _bottom(self, obj: TableObject) -> float:
        return obj.pose.z - obj.half_extents_mm()[2]

    def _drop(self, name: str) -> None:
        obj = self._objects[name]
        support, top = self.support_below(obj)
        z = top + obj.half_extents_mm()[2]
        pose = obj.pose
        rested = Pose(pose.x, pose.y, z, pose.rx, pose.ry, pose.rz)
        self._objects[name] = obj.model_copy(update={"pose": rested})
        self._resting_on[name] = support
