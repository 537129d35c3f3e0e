"""Objects on the simulated table and the rule that decides whether a grasp succeeds.

The world is deliberately simple: objects have a position and a width across the
fingers, nothing falls, nothing collides. A held object's pose *is* the TCP pose, so
releasing it leaves it exactly where the TCP was.
"""

from __future__ import annotations

from collections.abc import Iterable

from pydantic import BaseModel, ConfigDict, Field

from .._pose import Pose
from ._backend import ObjectState

#: Pick position of the part in the article's pick-and-place example.
DEFAULT_PART_POSE = Pose(300.0, -200.0, 100.0, 180.0, 0.0, 90.0)


class TableObject(BaseModel):
    """An object lying on the table that the gripper can pick up."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str = Field(min_length=1)
    pose: Pose
    #: Size across the fingers, mm.
    width_mm: float = Field(default=30.0, gt=0)
    #: How far the TCP may be from the object's position for a grasp to work, mm.
    grasp_tolerance_mm: float = Field(default=5.0, ge=0)


class World:
    """The objects on the table, which one the gripper holds, and the grasp rule."""

    def __init__(self, objects: Iterable[TableObject] | None = None) -> None:
        items = [TableObject(name="part", pose=DEFAULT_PART_POSE)] if objects is None else objects
        self._objects: dict[str, TableObject] = {}
        for item in items:
            if item.name in self._objects:
                raise ValueError(f"duplicate object name {item.name!r}")
            self._objects[item.name] = item
        self._held: str | None = None

    @property
    def held(self) -> TableObject | None:
        """The object between the fingers, or None."""
        return None if self._held is None else self._objects[self._held]

    def get(self, name: str) -> TableObject:
        """Return the object called ``name`` with its current pose."""
        try:
            return self._objects[name]
        except KeyError:
            raise KeyError(f"no object named {name!r}") from None

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

    def follow(self, tcp: Pose) -> None:
        """Move the held object (if any) rigidly with the TCP."""
        if self._held is not None:
            self._objects[self._held] = self._objects[self._held].model_copy(update={"pose": tcp})

    def release(self, tcp: Pose) -> TableObject | None:
        """Let go of the held object where the TCP is; return it (None if nothing was held)."""
        if self._held is None:
            return None
        self.follow(tcp)
        released = self._objects[self._held]
        self._held = None
        return released

    def states(self) -> list[ObjectState]:
        """Every object's name, pose and whether it is held."""
        return [
            ObjectState(name=obj.name, pose=obj.pose, held=obj.name == self._held)
            for obj in self._objects.values()
        ]
