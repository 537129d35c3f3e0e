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
from dataclasses import dataclass
from typing import Annotated, Any, Literal, get_args

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PositiveFloat,
    model_validator,
)

from .. import _cell
from .. import _kinematics as kin
from .._checks import is_finite_number, shown
from .._error_root import ConfigError
from .._pose import Pose
from ._backend import ObjectState

#: Height of the table top in the robot base frame, mm: the default cell's
#: (:data:`tmmaster._cell.DEFAULT_TABLE_TOP_Z_MM`), which the master's default
#: :class:`~tmmaster.Workspace` keeps the tool above.
DEFAULT_TABLE_TOP_Z_MM = _cell.DEFAULT_TABLE_TOP_Z_MM

#: Size of the default part (a 30 mm cube), mm.
DEFAULT_PART_SIZE_MM = (30.0, 30.0, 30.0)

#: Pick position of the part in the article's pick-and-place example: its centre, the
#: part resting on the default table (z = 85 + 15 = 100 mm).
DEFAULT_PART_POSE = Pose(
    300.0, -200.0, DEFAULT_TABLE_TOP_Z_MM + DEFAULT_PART_SIZE_MM[2] / 2, 180.0, 0.0, 90.0
)

#: Standard gravity, m/s^2.
GRAVITY_M_S2 = 9.81

#: Centre (x, y) and half size (x, y) of the table's top in the robot base frame, mm: a
#: 0.6 x 1.1 m table in front of the arm. Parts rest on the table's plane anywhere (the
#: falling rule); an arm collision with the table counts only over its top.
TABLE_CENTRE_XY_MM = (450.0, 0.0)
TABLE_HALF_SIZE_XY_MM = (300.0, 550.0)


class GripperGeometry(BaseModel):
    """The two-finger gripper both physics backends model (defaults: an OnRobot 2FG7).

    The fingers close along the tool's y axis, symmetrically about the TCP; each carries a
    flat pad centred on the TCP in the tool's x (depth) and z (height). The grasp rule
    (:func:`grasp_fit`, :meth:`holds`) and the MuJoCo scene are both built from these
    numbers, so the two backends grip, miss and drop the same parts.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: Narrowest finger width, mm (2FG7 external grip: about 1 mm).
    min_width_mm: float = Field(default=1.0, ge=0)
    #: Widest finger width, mm (2FG7 external grip: about 39 mm, a 38 mm stroke).
    max_width_mm: float = Field(default=39.0, gt=0)
    #: Pad size along the tool's x axis (depth), mm.
    pad_depth_mm: float = Field(default=20.0, gt=0)
    #: Pad size along the tool's z axis (height), centred on the TCP, mm.
    pad_height_mm: float = Field(default=24.0, gt=0)
    #: Pad thickness along the closing direction, mm (MuJoCo only: it has volume).
    pad_thickness_mm: float = Field(default=8.0, gt=0)
    #: Friction coefficient between a pad and a part (an assumption, see
    #: docs/simulator-model.md#the-grasp-rule).
    friction: float = Field(default=0.5, gt=0, le=2)
    #: A part is carried when 2 x friction x force >= safety_factor x mass x g: with the
    #: 2FG7's strongest grip (140 N) that is 7.1 kg, its rated force-fit payload (7 kg,
    #: OnRobot's 2FG7 datasheet), so the rule's margin is OnRobot's.
    safety_factor: float = Field(default=2.0, ge=1)
    #: The gripper's own mass, kg, carried by the arm with the part (the arm's payload
    #: counts both): an OnRobot 2FG7 weighs 1.1 kg (OnRobot's 2FG7 datasheet; 1.10 kg in
    #: its description in OnRobot's ROS driver).
    mass_kg: float = Field(default=1.1, ge=0)

    @model_validator(mode="after")
    def _stroke_is_ordered(self) -> GripperGeometry:
        if not self.min_width_mm < self.max_width_mm:
            raise ValueError(
                f"need min_width_mm < max_width_mm, got {self.min_width_mm} and {self.max_width_mm}"
            )
        return self

    def max_mass_kg(self, force_n: float) -> float:
        """The heaviest part a grip of ``force_n`` carries (the friction rule).

        Args:
            force_n: The grip force each finger presses with, N.

        Returns:
            2 x friction x force / (safety_factor x g), kg.
        """
        return 2 * self.friction * force_n / (self.safety_factor * GRAVITY_M_S2)

    def holds(self, mass_kg: float, force_n: float) -> bool:
        """Whether a grip of ``force_n`` carries a part of ``mass_kg`` without slipping.

        Args:
            mass_kg: The part's mass, kg.
            force_n: The grip force each finger presses with, N.

        Returns:
            True when 2 x friction x force >= safety_factor x mass x g.
        """
        return mass_kg <= self.max_mass_kg(force_n) + 1e-12


#: How a backend holds a part between the pads: by friction alone (a part too heavy for
#: the grip force slips out), or welded to the tool once both pads touch it.
GraspMode = Literal["friction", "weld"]
GRASP_MODES: tuple[str, ...] = get_args(GraspMode)

#: The simulated gripper unless told otherwise: an OnRobot 2FG7, fingers inward.
DEFAULT_GRIPPER = GripperGeometry()


def gripper_geometry(
    gripper: GripperGeometry | None,
    min_width_mm: float | None = None,
    max_width_mm: float | None = None,
) -> GripperGeometry:
    """The gripper a backend models: ``gripper``, or the default with another stroke.

    Args:
        gripper: The gripper; None: :data:`DEFAULT_GRIPPER`.
        min_width_mm: The fingers' smallest width (None: the gripper's), mm.
        max_width_mm: The fingers' largest width (None: the gripper's), mm.

    Returns:
        The gripper.

    Raises:
        ValueError: A stroke given twice (``gripper`` and a width), or an empty stroke.
    """
    if gripper is not None and (min_width_mm is not None or max_width_mm is not None):
        raise ValueError("give the stroke in gripper or as widths, not both")
    if gripper is not None:
        return gripper
    if min_width_mm is None and max_width_mm is None:
        return DEFAULT_GRIPPER
    low = DEFAULT_GRIPPER.min_width_mm if min_width_mm is None else min_width_mm
    high = DEFAULT_GRIPPER.max_width_mm if max_width_mm is None else max_width_mm
    if not 0 <= low < high:
        raise ValueError(
            f"need 0 <= gripper_min_width_mm < gripper_max_width_mm, got {low} and {high}"
        )
    return DEFAULT_GRIPPER.model_copy(update={"min_width_mm": low, "max_width_mm": high})


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


_POSE_KEYS = ("x", "y", "z", "rx", "ry", "rz")


def _pose_from_sequence(value: Any) -> Any:
    # A scene file writes a pose as [x, y, z, rx, ry, rz] (mm, deg).
    if isinstance(value, list | tuple):
        if len(value) != 6:
            raise ValueError(f"need 6 numbers [x, y, z, rx, ry, rz] (mm, deg), got {len(value)}")
        return dict(zip(_POSE_KEYS, value, strict=True))
    return value


#: A pose field that also takes ``[x, y, z, rx, ry, rz]``.
PoseField = Annotated[Pose, BeforeValidator(_pose_from_sequence)]


class TableObject(BaseModel):
    """A box lying on the table that the gripper can pick up."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: The object's name (unique in a world).
    name: str = Field(min_length=1)
    #: Pose of the box's centre (the grasp point).
    pose: PoseField
    #: Size along the box's own x, y (across the fingers) and z axes, mm.
    size_mm: tuple[PositiveFloat, PositiveFloat, PositiveFloat] = DEFAULT_PART_SIZE_MM
    #: Its mass, kg.
    mass_kg: float = Field(default=0.1, gt=0, le=50)
    #: An extra limit on how far the TCP may be from the object's centre for a grasp to
    #: work, mm; None: the gripper's geometry alone decides (:func:`grasp_fit`).
    grasp_tolerance_mm: float | None = Field(default=None, ge=0)

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


class Fixture(BaseModel):
    """A fixed box in the cell (a jig, a wall, a feeder): the arm must not touch it.

    Parts rest on a fixture's top as on the table's; the gripper never picks it up. The
    kinematic backend checks the arm's links, its tool and a held part against it as
    against the table; the MuJoCo backend makes it a static box the arm collides with.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: The fixture's name (unique among the fixtures and the parts of a world).
    name: str = Field(min_length=1)
    #: Pose of the box's centre in the robot base frame, mm / deg.
    pose: PoseField
    #: Size along the box's own x, y and z axes, mm.
    size_mm: tuple[PositiveFloat, PositiveFloat, PositiveFloat]

    def half_extents_mm(self) -> tuple[float, float, float]:
        """Half size of the box's axis-aligned bounding box in the base frame.

        Returns:
            Half the box's extent along x, y and z, mm.
        """
        return _half_extents(self.size_mm, self.pose.rx, self.pose.ry, self.pose.rz)

    def depth_of(self, point: tuple[float, float, float]) -> float:
        """How deep ``point`` is inside the box: its distance to the nearest face, mm.

        Args:
            point: A point in the robot base frame, mm.

        Returns:
            The depth (> 0 inside, 0 on a face), or -1 when the point is outside.
        """
        inverse = _inverse_frame(*self.pose.as_list())
        x, y, z = point
        depth = math.inf
        for i in range(3):
            local = inverse[i][0] * x + inverse[i][1] * y + inverse[i][2] * z + inverse[i][3]
            depth = min(depth, self.size_mm[i] / 2 - abs(local))
        return depth if depth >= 0 else -1.0


@functools.lru_cache(maxsize=256)
def _inverse_frame(x: float, y: float, z: float, rx: float, ry: float, rz: float) -> kin.Transform:
    """The base-to-box transform of a box at this pose (cached: fixtures do not move)."""
    return kin.invert(kin.pose_to_transform(Pose(x, y, z, rx, ry, rz)))


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


@dataclass(frozen=True)
class GraspFit:
    """How a part lies between the fingers at a TCP pose: where they stop on it, and how.

    Made by :func:`grasp_fit` (the grasp rule both backends follow).
    """

    #: The part.
    obj: TableObject
    #: The finger width where the fingers stop on it: its face width across the fingers
    #: or, jammed, its width across its edges, mm.
    width_mm: float
    #: Turned too far from square to the pads for the squeeze to straighten it: held on
    #: two edges, at its width across them, its orientation kept.
    jammed: bool
    #: The part's pose in the TCP frame once squeezed: centred between the fingers,
    #: straightened unless jammed.
    relative: Pose


def in_tool_frame(obj: TableObject, tcp: Pose) -> tuple[kin.Transform, tuple[float, ...]]:
    """The part's transform in the TCP frame and its half extents along the tool's axes.

    Args:
        obj: The part (at its own pose).
        tcp: The TCP pose.

    Returns:
        The transform (mm) and the half extents along the tool's x, y and z, mm.
    """
    rel = kin.multiply(kin.invert(kin.pose_to_transform(tcp)), kin.pose_to_transform(obj.pose))
    half = [s / 2 for s in obj.size_mm]
    extents = tuple(sum(abs(rel[i][j]) * half[j] for j in range(3)) for i in range(3))
    return rel, extents


def grasp_fit(
    obj: TableObject,
    tcp: Pose,
    *,
    opening_mm: float,
    gripper: GripperGeometry = DEFAULT_GRIPPER,
) -> GraspFit | None:
    """Where fingers open ``opening_mm`` at ``tcp`` would close on ``obj``; None: they miss it.

    The rule (docs/simulator-model.md, "The grasp rule"), all of it in the tool frame:

    - the pads must overlap the part in depth (tool x) and height (tool z);
    - its width across the fingers (tool y; a turned part is wider) must be within the
      stroke, and the part between the open fingers (the fingers are rigid and move
      together: a pad that comes down on its edge presses it, a collision, see
      :func:`pad_overlaps`);
    - a part turned about the tool's z is straightened by the squeeze when its contact
      corner's lever beats friction (``|x| > friction * |y|`` at the corner the pad
      touches first: a square jams beyond 45 deg - atan(friction), 18.4 deg at 0.5);
      otherwise it jams, held on two edges at its width across them.

    Args:
        obj: The part.
        tcp: Where the fingers are.
        opening_mm: Their width now (open), mm.
        gripper: The gripper's stroke, pads and friction.

    Returns:
        How the fingers stop on the part, or None.
    """
    if obj.grasp_tolerance_mm is not None and tcp.distance_to(obj.pose) > obj.grasp_tolerance_mm:
        return None
    rel, (ex, ey, ez) = in_tool_frame(obj, tcp)
    cx, cy, cz = rel[0][3], rel[1][3], rel[2][3]
    if abs(cx) >= gripper.pad_depth_mm / 2 + ex or abs(cz) >= gripper.pad_height_mm / 2 + ez:
        return None  # the pads pass beside, above or below it
    across = 2 * ey
    if not gripper.min_width_mm < across <= gripper.max_width_mm:
        return None  # never between the fingers, or too thin to touch
    if abs(cy) + ey > opening_mm / 2 + 1e-6:
        return None  # a pad is on top of it, not beside it (the arm pressed it: a collision)
    # The part's axis nearest the tool's z stands up; the other two lie in the pads' plane.
    up = max(range(3), key=lambda j: abs(rel[2][j]))
    a, b = (j for j in range(3) if j != up)
    half = [s / 2 for s in obj.size_mm]
    phi = math.atan2(rel[1][a], rel[0][a])  # axis a's direction in the tool's x-y plane
    # Angle to the nearest square orientation (a along x or along y), in (-45, 45] deg.
    theta = (phi + math.pi / 4) % (math.pi / 2) - math.pi / 4
    jammed = False
    if abs(theta) > 1e-4:
        s_a, c_a = math.sin(phi), math.cos(phi)
        # The corner the closing pad meets first (largest y) and its lever along x.
        y = abs(half[a] * s_a) + abs(half[b] * c_a)
        x = math.copysign(half[a], s_a) * c_a - math.copysign(half[b], c_a) * s_a
        jammed = abs(x) <= gripper.friction * y
    if jammed:
        rotation = rel
        width = across
    else:
        # Straightened: turned back by theta about the tool's z.
        rotation = kin.multiply(_rot_z(-theta), rel)
        width = 2 * sum(abs(rotation[1][j]) * half[j] for j in range(3))
    centred = (
        (rotation[0][0], rotation[0][1], rotation[0][2], cx),
        (rotation[1][0], rotation[1][1], rotation[1][2], 0.0),
        (rotation[2][0], rotation[2][1], rotation[2][2], cz),
        kin.IDENTITY[3],
    )
    return GraspFit(obj, width, jammed, kin.transform_to_pose(centred))


#: The two pads' overlaps with a part along the tool's x, y and z (negative: apart), mm.
PadOverlaps = tuple[tuple[float, float, float], tuple[float, float, float]]


def pad_overlaps(
    obj: TableObject, tcp: Pose, *, width_mm: float, gripper: GripperGeometry = DEFAULT_GRIPPER
) -> tuple[PadOverlaps, int]:
    """How far each finger pad overlaps ``obj`` along the tool's axes, and which is vertical.

    The pads are boxes in the tool frame; the part is taken as its bounding box along the
    tool's axes. A pad is inside the part when all three overlaps are positive. Compared
    with the overlaps a moment before, they say how it got there: a pad that was right
    above the part (its horizontal overlaps positive, its vertical one not) came down on
    it; one that came in from the side (fingers opening against a neighbour, a wrist
    turning with the fingers open around a part) would push the part aside instead.

    Args:
        obj: The part.
        tcp: Where the fingers are.
        width_mm: Their width, mm.
        gripper: The gripper's pads.

    Returns:
        The two pads' overlaps (x, y, z of the tool, mm) and the index (0, 1, 2) of the
        tool axis nearest the vertical.
    """
    tool = kin.pose_to_transform(tcp)
    vertical = max(range(3), key=lambda i: abs(tool[2][i]))
    rel, (ex, ey, ez) = in_tool_frame(obj, tcp)
    cx, cy, cz = rel[0][3], rel[1][3], rel[2][3]
    inner = width_mm / 2
    outer = inner + gripper.pad_thickness_mm
    depth = gripper.pad_depth_mm / 2 + ex - abs(cx)
    height = gripper.pad_height_mm / 2 + ez - abs(cz)
    left = (depth, min(outer, cy + ey) - max(inner, cy - ey), height)
    right = (depth, min(-inner, cy + ey) - max(-outer, cy - ey), height)
    return (left, right), vertical


class _Stacks:
    """Resting objects grouped by what the grasp and collision rules see of them.

    Objects of one pose, size and grasp tolerance (the parts a feeder keeps waiting at
    one spot) are one stack; a query near a point reads one object per stack, the first
    in the world's order, so a thousand waiting parts cost what one does.
    """

    def __init__(self) -> None:
        self._stacks: dict[tuple[Any, ...], list[tuple[int, str]]] = {}
        self._cells: dict[tuple[int, int], set[tuple[Any, ...]]] = {}
        # name -> (its stack's key, its place in the world's order)
        self._key_of: dict[str, tuple[tuple[Any, ...], int]] = {}
        self._extent: dict[tuple[Any, ...], tuple[float, float, float, float]] = {}

    def add(self, name: str, obj: TableObject, order: int) -> None:
        key = (tuple(obj.pose.as_list()), obj.size_mm, obj.grasp_tolerance_mm)
        if self._key_of.get(name, (None, 0))[0] == key:
            return  # filed again where it was (a part that settled where it started)
        self.remove(name)
        stack = self._stacks.get(key)
        if stack is None:
            stack = self._stacks[key] = []
            hx, hy, _ = obj.half_extents_mm()
            x, y = obj.pose.x, obj.pose.y
            self._extent[key] = (x, y, hx, hy)
            for cell in self._cells_of(x, y, hx, hy):
                self._cells.setdefault(cell, set()).add(key)
        bisect.insort(stack, (order, name))
        self._key_of[name] = (key, order)

    def remove(self, name: str) -> None:
        filed = self._key_of.pop(name, None)
        if filed is None:
            return
        key, order = filed
        stack = self._stacks[key]
        del stack[bisect.bisect_left(stack, (order, name))]
        if not stack:
            del self._stacks[key]
            x, y, hx, hy = self._extent.pop(key)
            for cell in self._cells_of(x, y, hx, hy):
                self._cells[cell].discard(key)

    @staticmethod
    def _cells_of(x: float, y: float, hx: float, hy: float) -> list[tuple[int, int]]:
        cells = _SupportIndex._footprint(x, y, hx, hy)
        return [(0x7FFFFFFF, 0)] if cells is None else cells  # too wide: one shared cell

    def near(self, x: float, y: float, radius: float) -> list[str]:
        keys: set[tuple[Any, ...]] = set(self._cells.get((0x7FFFFFFF, 0), ()))
        cells = _SupportIndex._footprint(x, y, radius, radius)
        if cells is None:  # a query wider than the grid: every stack
            keys.update(self._stacks)
        else:
            for cell in cells:
                keys.update(self._cells.get(cell, ()))
        first = []
        for key in keys:
            ox, oy, ohx, ohy = self._extent[key]
            if abs(ox - x) < ohx + radius and abs(oy - y) < ohy + radius:
                first.append(self._stacks[key][0])
        return [name for _, name in sorted(first)]


class World:
    """The objects on the table, which one the gripper holds, the grasp and falling rules.

    Objects placed in the air drop onto what is under them (the table or another
    object); a released object falls the same way.

    Args:
        objects: The objects; None: one part at ``DEFAULT_PART_POSE``.
        table_top_z_mm: Height of the table top in the robot base frame, mm.
        fixtures: Fixed boxes the arm must not touch; parts rest on their tops.

    Raises:
        ConfigError: A non-finite table height, or two objects or fixtures with one name.
    """

    def __init__(
        self,
        objects: Iterable[TableObject] | None = None,
        *,
        table_top_z_mm: float = DEFAULT_TABLE_TOP_Z_MM,
        fixtures: Iterable[Fixture] = (),
    ) -> None:
        if not is_finite_number(table_top_z_mm):
            raise ConfigError(
                f"table_top_z_mm must be a finite number, got {shown(table_top_z_mm)}"
            )
        #: Height of the table top, mm.
        self.table_top_z_mm = float(table_top_z_mm)
        items = [TableObject(name="part", pose=DEFAULT_PART_POSE)] if objects is None else objects
        self._objects: dict[str, TableObject] = {}
        self._resting_on: dict[str, str | None] = {}
        for item in items:
            if item.name in self._objects:
                raise ConfigError(f"objects: duplicate object name {item.name!r}")
            self._objects[item.name] = item
        #: The fixed boxes of the cell.
        self.fixtures: tuple[Fixture, ...] = tuple(fixtures)
        names = set(self._objects)
        for fixture in self.fixtures:
            if fixture.name in names or fixture.name == TABLE:
                raise ConfigError(f"fixtures: the name {fixture.name!r} is taken")
            names.add(fixture.name)
        self._held: str | None = None
        # The held object's pose in the TCP frame (None: its pose is the TCP's).
        self._relative: kin.Transform | None = None
        self._order = {name: k for k, name in enumerate(self._objects)}
        self._index = _SupportIndex()
        self._stacks = _Stacks()
        # Fixtures support parts as objects do (before every object in the world's order).
        for k, fixture in enumerate(self.fixtures):
            hx, hy, hz = fixture.half_extents_mm()
            pose = fixture.pose
            self._index.add(fixture.name, (pose.x, pose.y, hx, hy, pose.z + hz, k - len(names)))
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
        """What ``name`` rests on ("table", a fixture's or an object's name), None while held.

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
        self,
        tcp: Pose,
        *,
        current_width_mm: float,
        target_width_mm: float,
        gripper: GripperGeometry = DEFAULT_GRIPPER,
    ) -> TableObject | None:
        """The object fingers closing from ``current`` to ``target`` at ``tcp`` would stop on.

        Args:
            tcp: Where the fingers are.
            current_width_mm: Their width now, mm.
            target_width_mm: The width they close to, mm.
            gripper: The gripper's stroke, pads and friction.

        Returns:
            The object (:meth:`grasp_fit` says how they stop on it), or None.
        """
        fit = self.grasp_fit(
            tcp,
            current_width_mm=current_width_mm,
            target_width_mm=target_width_mm,
            gripper=gripper,
        )
        return None if fit is None else fit.obj

    def grasp_fit(
        self,
        tcp: Pose,
        *,
        current_width_mm: float,
        target_width_mm: float,
        gripper: GripperGeometry = DEFAULT_GRIPPER,
        opening_mm: float | None = None,
    ) -> GraspFit | None:
        """How fingers closing from ``current`` to ``target`` at ``tcp`` stop on an object.

        Args:
            tcp: Where the fingers are.
            current_width_mm: Their width now, mm.
            target_width_mm: The width they close to, mm.
            gripper: The gripper's stroke, pads and friction.
            opening_mm: Their width when they started closing (None: ``current``): a part
                between them then is pushed along by the first pad to touch it.

        Returns:
            The fit of the object they meet first (the widest, :func:`grasp_fit`), or None
            (also while one is held).
        """
        if self._held is not None or target_width_mm >= current_width_mm:
            return None
        opening = max(current_width_mm, opening_mm or 0.0)
        reach = math.hypot(gripper.pad_depth_mm, opening + 2 * gripper.pad_thickness_mm)
        fits = []
        for obj in self.near(tcp.x, tcp.y, reach):
            fit = grasp_fit(obj, tcp, opening_mm=opening, gripper=gripper)
            # Fingers already touching (equal width) still count: they are on the object.
            if fit is not None and target_width_mm < fit.width_mm <= current_width_mm + 1e-9:
                fits.append(fit)
        # Closing fingers meet the widest object first.
        return max(fits, key=lambda fit: fit.width_mm, default=None)

    def near(self, x: float, y: float, radius_mm: float) -> list[TableObject]:
        """The objects not held whose footprint comes within ``radius_mm`` of (x, y).

        Of identical objects resting at one spot (a feeder's parts waiting) only the first
        in the world's order is named: the others are the same for every rule.

        Args:
            x: Base x, mm.
            y: Base y, mm.
            radius_mm: The distance, mm.

        Returns:
            The objects, in the world's order.
        """
        return [self._objects[name] for name in self._stacks.near(x, y, radius_mm)]

    def grasp(self, name: str, tcp: Pose, relative: Pose | None = None) -> None:
        """Mark ``name`` as held at ``relative`` to the TCP (None: at the TCP pose itself).

        Args:
            name: The object's name.
            tcp: The TCP pose.
            relative: The object's pose in the TCP frame while held (:attr:`GraspFit.relative`);
                None: its pose is the TCP's.

        Raises:
            RuntimeError: Another object is held.
        """
        if self._held is not None and self._held != name:
            raise RuntimeError(f"already holding {self._held!r}, cannot grasp {name!r}")
        identity = relative is None or relative == Pose(0, 0, 0, 0, 0, 0)
        self._relative = None if identity else kin.pose_to_transform(relative)  # type: ignore[arg-type]
        self._held = name
        self._resting_on[name] = None
        self._index.remove(name)  # a held object supports nothing
        self._stacks.remove(name)
        self.follow(tcp)

    def follow(self, tcp: Pose) -> None:
        """Move the held object (if any) rigidly with the TCP.

        Args:
            tcp: The TCP pose.
        """
        if self._held is None:
            return
        pose = tcp
        if self._relative is not None:
            pose = kin.transform_to_pose(kin.multiply(kin.pose_to_transform(tcp), self._relative))
        self._objects[self._held] = self._objects[self._held].model_copy(update={"pose": pose})

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
            ``("table", height)`` or a fixture's or another object's name and its top, mm.
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
        self._stacks.add(name, obj, self._order[name])
        hx, hy, hz = obj.half_extents_mm()
        entry = (obj.pose.x, obj.pose.y, hx, hy, obj.pose.z + hz, self._order[name])
        self._index.add(name, entry)


def held_frame(world: World, tcp: kin.Transform) -> tuple[TableObject, kin.Transform] | None:
    """The object ``world``'s gripper holds and its frame with the TCP at ``tcp``.

    What :meth:`World.follow` would put it at, without moving it (the kinematic backend
    checks it against the table and the fixtures every tick).

    Args:
        world: The world.
        tcp: The TCP's transform in the base frame.

    Returns:
        The object (its pose not updated) and its centre's transform, or None when none
        is held.
    """
    if world._held is None:
        return None
    relative = world._relative
    frame = tcp if relative is None else kin.multiply(tcp, relative)
    return world._objects[world._held], frame


def _rot_z(angle_rad: float) -> kin.Transform:
    """A rotation about z."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return ((c, -s, 0.0, 0.0), (s, c, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0), kin.IDENTITY[3])
