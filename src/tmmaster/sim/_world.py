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

import bisect
import functools
import math
from collections.abc import Iterable
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, PositiveFloat, model_validator

from .. import _kinematics as kin
from .._error_root import ConfigError
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

#: Side of the square cells of the support index's floor grid, mm.
_CELL_MM = 100.0

#: Height of the support index's layers (objects grouped by the height of their top), mm.
_LAYER_MM = 10.0

#: An object whose footprint covers more cells than this is kept on one list that every
#: search reads: a huge plate would otherwise fill (or make a search visit) the whole grid.
_MAX_CELLS = 256


class TableObject(BaseModel):
    """A box lying on the table that the gripper can pick up."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: The object's name (unique in a world).
    name: str = Field(min_length=1)
    #: Pose of the box's centre (the grasp point).
    pose: Pose
    #: Size along the box's own x, y (across the fingers) and z axes, mm.
    size_mm: tuple[PositiveFloat, PositiveFloat, PositiveFloat] = DEFAULT_PART_SIZE_MM
    #: Its mass, kg.
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
        """Half size of the box's axis-aligned bounding box in the base frame at ``pose``.

        Args:
            pose: Where the box is; None: its own pose.

        Returns:
            Half the box's extent along x, y and z, mm.
        """
        pose = self.pose if pose is None else pose
        return _half_extents(self.size_mm, pose.rx, pose.ry, pose.rz)


@functools.lru_cache(maxsize=1024)
def _half_extents(
    size_mm: tuple[float, float, float], rx: float, ry: float, rz: float
) -> tuple[float, float, float]:
    # Cached: the parts of a feeder share size and orientation, and a World asks for
    # each object's extents several times while it settles (no trigonometry each time).
    rot = kin.pose_to_transform(Pose(0.0, 0.0, 0.0, rx, ry, rz))
    half = [s / 2 for s in size_mm]
    return (
        sum(abs(rot[0][j]) * half[j] for j in range(3)),
        sum(abs(rot[1][j]) * half[j] for j in range(3)),
        sum(abs(rot[2][j]) * half[j] for j in range(3)),
    )


#: What the support index keeps of a resting object: x, y, half x, half y, top (mm), and
#: its place in the world's order (of two supports as high, the earlier one is named).
_Entry = tuple[float, float, float, float, float, int]


class _SupportIndex:
    """Where the resting objects are, so that finding the support under one is not a scan.

    Each object is filed under the floor cells its footprint covers and, in each cell,
    under the layer of its top's height. A search reads only the cells under the falling
    object and, in each, the layers from its bottom down, highest first, stopping below
    the best support found. So N parts waiting at the same spot (the pick-and-place
    feeder) settle in time linear in N, not quadratic: a part at the same height as the
    others never looks at them.
    """

    def __init__(self) -> None:
        # cell -> layer -> name -> what is kept of the resting object (_Entry).
        self._cells: dict[tuple[int, int], dict[int, dict[str, _Entry]]] = {}
        # cell -> its occupied layers, ascending (a search walks them downwards).
        self._layers: dict[tuple[int, int], list[int]] = {}
        # Objects too wide for the grid, read by every search.
        self._wide: dict[str, _Entry] = {}
        # name -> (its cells, its layer, its entry), to remove it again.
        self._where: dict[str, tuple[list[tuple[int, int]], int, _Entry]] = {}

    @staticmethod
    def _footprint(x: float, y: float, hx: float, hy: float) -> list[tuple[int, int]] | None:
        """The cells under a footprint, or None when there are more than _MAX_CELLS."""
        x0, x1 = math.floor((x - hx) / _CELL_MM), math.floor((x + hx) / _CELL_MM)
        y0, y1 = math.floor((y - hy) / _CELL_MM), math.floor((y + hy) / _CELL_MM)
        if (x1 - x0 + 1) * (y1 - y0 + 1) > _MAX_CELLS:
            return None
        return [(i, j) for i in range(x0, x1 + 1) for j in range(y0, y1 + 1)]

    def add(self, name: str, entry: _Entry) -> None:
        """File ``name`` (not filed yet) resting with ``entry``."""
        x, y, hx, hy, top, _ = entry
        cells = self._footprint(x, y, hx, hy)
        layer = math.floor(top / _LAYER_MM)
        if cells is None:
            self._wide[name] = entry
            self._where[name] = ([], layer, entry)
            return
        for cell in cells:
            layers = self._cells.setdefault(cell, {})
            if layer not in layers:
                layers[layer] = {}
                bisect.insort(self._layers.setdefault(cell, []), layer)
            layers[layer][name] = entry
        self._where[name] = (cells, layer, entry)

    def entry(self, name: str) -> _Entry | None:
        """What is filed for ``name``, or None."""
        where = self._where.get(name)
        return None if where is None else where[2]

    def remove(self, name: str) -> None:
        """Forget ``name`` (safe when not filed)."""
        where = self._where.pop(name, None)
        if where is None:
            return
        cells, layer, _ = where
        self._wide.pop(name, None)
        for cell in cells:
            layers = self._cells[cell]
            del layers[layer][name]
            if not layers[layer]:
                del layers[layer]
                self._layers[cell].remove(layer)

    def highest_below(
        self, x: float, y: float, hx: float, hy: float, limit: float, best: tuple[str, float]
    ) -> tuple[str, float]:
        """The highest filed top <= ``limit`` whose footprint overlaps, if above ``best``.

        Of tops equally high, the object earliest in the world's order is named (as a scan
        of every object in order would name it); ``best`` wins a tie.
        """
        found = (best[0], best[1], -1)

        def consider(name: str, entry: _Entry) -> None:
            nonlocal found
            ox, oy, ohx, ohy, top, order = entry
            if top > limit or abs(ox - x) >= ohx + hx or abs(oy - y) >= ohy + hy:
                return
            if top > found[1] or (top == found[1] and found[2] >= 0 and order < found[2]):
                found = (name, top, order)

        if self._wide:
            for name, entry in self._wide.items():
                consider(name, entry)
        cells = self._footprint(x, y, hx, hy)
        if cells is None:  # wider than the grid allows: read every cell
            cells = list(self._cells)
        top_layer = math.floor(limit / _LAYER_MM)
        for cell in cells:
            layers = self._layers.get(cell)
            if not layers:
                continue
            by_layer = self._cells[cell]
            for k in range(bisect.bisect_right(layers, top_layer) - 1, -1, -1):
                layer = layers[k]
                # Tops in this layer are below (layer + 1) * _LAYER_MM; one layer more of
                # margin for the rounding of top / _LAYER_MM.
                if (layer + 2) * _LAYER_MM <= found[1]:
                    break
                for name, entry in by_layer[layer].items():
                    consider(name, entry)
        return found[0], found[1]


class World:
    """The objects on the table, which one the gripper holds, the grasp and falling rules.

    Objects placed in the air drop onto what is under them (the table or another
    object); a released object falls the same way.

    Args:
        objects: The objects; None: one part at ``DEFAULT_PART_POSE``.
        table_top_z_mm: Height of the table top in the robot base frame, mm.

    Raises:
        ConfigError: A non-finite table height or two objects with one name.
    """

    def __init__(
        self,
        objects: Iterable[TableObject] | None = None,
        *,
        table_top_z_mm: float = DEFAULT_TABLE_TOP_Z_MM,
    ) -> None:
        if not math.isfinite(table_top_z_mm):
            raise ConfigError(f"table_top_z_mm must be finite, got {table_top_z_mm}")
        #: Height of the table top, mm.
        self.table_top_z_mm = float(table_top_z_mm)
        items = [TableObject(name="part", pose=DEFAULT_PART_POSE)] if objects is None else objects
        self._objects: dict[str, TableObject] = {}
        self._resting_on: dict[str, str | None] = {}
        for item in items:
            if item.name in self._objects:
                raise ConfigError(f"objects: duplicate object name {item.name!r}")
            self._objects[item.name] = item
        self._held: str | None = None
        self._order = {name: k for k, name in enumerate(self._objects)}
        self._index = _SupportIndex()
        for name, obj in self._objects.items():
            self._file(name, obj)
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
        """The object called ``name`` with its current pose.

        Args:
            name: An object's name.

        Returns:
            The object.

        Raises:
            KeyError: No such object.
        """
        try:
            return self._objects[name]
        except KeyError:
            raise KeyError(f"no object named {name!r}") from None

    def resting_on(self, name: str) -> str | None:
        """What ``name`` rests on ("table" or an object's name), None while held.

        Args:
            name: An object's name.

        Returns:
            The support's name, or None.

        Raises:
            KeyError: No such object.
        """
        self.get(name)
        return self._resting_on.get(name)

    def grasp_candidate(
        self, tcp: Pose, *, current_width_mm: float, target_width_mm: float
    ) -> TableObject | None:
        """The object fingers closing from ``current`` to ``target`` at ``tcp`` would stop on.

        Args:
            tcp: Where the fingers are.
            current_width_mm: Their width now, mm.
            target_width_mm: The width they close to, mm.

        Returns:
            The widest object between the fingers, or None (also while one is held).
        """
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
        """Mark ``name`` as held; it snaps to the TCP pose.

        Args:
            name: The object's name.
            tcp: The TCP pose.

        Raises:
            RuntimeError: Another object is held.
        """
        if self._held is not None and self._held != name:
            raise RuntimeError(f"already holding {self._held!r}, cannot grasp {name!r}")
        self._objects[name] = self.get(name).model_copy(update={"pose": tcp})
        self._held = name
        self._resting_on[name] = None
        self._index.remove(name)  # a held object supports nothing

    def follow(self, tcp: Pose) -> None:
        """Move the held object (if any) rigidly with the TCP.

        Args:
            tcp: The TCP pose.
        """
        if self._held is not None:
            self._objects[self._held] = self._objects[self._held].model_copy(update={"pose": tcp})

    def release(self, tcp: Pose) -> TableObject | None:
        """Let go of the held object at the TCP; it falls onto its support.

        Args:
            tcp: The TCP pose.

        Returns:
            The released object where it landed, or None when none was held.
        """
        if self._held is None:
            return None
        self.follow(tcp)
        name = self._held
        self._held = None
        self._drop(name)
        return self._objects[name]

    def support_below(self, obj: TableObject, pose: Pose | None = None) -> tuple[str, float]:
        """The highest support under ``obj`` (at ``pose``): its name and top height, mm.

        Args:
            obj: An object.
            pose: Where it is; None: its own pose.

        Returns:
            ``("table", height)`` or another object's name and its top, mm.
        """
        pose = obj.pose if pose is None else pose
        hx, hy, hz = obj.half_extents_mm(pose)
        bottom = pose.z - hz
        # obj itself must not count: out of the index for the search, then back if it was.
        entry = self._index.entry(obj.name)
        self._index.remove(obj.name)
        try:
            return self._index.highest_below(
                pose.x,
                pose.y,
                hx,
                hy,
                bottom + SUPPORT_TOLERANCE_MM,
                (TABLE, self.table_top_z_mm),
            )
        finally:
            if entry is not None:
                self._index.add(obj.name, entry)

    def states(self) -> list[ObjectState]:
        """Every object's name, pose, size, mass, whether it is held and what it rests on.

        Returns:
            One state per object.
        """
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
        self._index.remove(name)  # moving: filed again where it comes to rest
        support, top = self.support_below(obj)
        z = top + obj.half_extents_mm()[2]
        pose = obj.pose
        if z != pose.z:  # a part already at rest (a feeder's) keeps its object: no copy
            rested = Pose(pose.x, pose.y, z, pose.rx, pose.ry, pose.rz)
            obj = self._objects[name] = obj.model_copy(update={"pose": rested})
        self._resting_on[name] = support
        self._file(name, obj)

    def _file(self, name: str, obj: TableObject) -> None:
        """(Re)file ``name`` in the support index at ``obj``'s pose."""
        self._index.remove(name)
        hx, hy, hz = obj.half_extents_mm()
        entry = (obj.pose.x, obj.pose.y, hx, hy, obj.pose.z + hz, self._order[name])
        self._index.add(name, entry)
