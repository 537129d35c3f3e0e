"""The arm's collision shapes, shared by both physics backends, and the tests on them.

One geometry for both backends: the MuJoCo scene (:func:`~tmmaster.sim._mujoco.build_mjcf`)
puts a capsule of :data:`ARM_RADIUS_MM` round each link, and a flange disc and a palm
box of the sizes below (``tests/test_sim_link_collisions.py`` checks its MJCF against
them); the kinematic backend checks the same shapes analytically against the table top
and the scene's fixtures (:class:`Box`): a capsule by its segment's distance to the box
(:func:`segment_depth`), the held part's box by the separating axes (:func:`box_depth`),
the flange's rim and the palm's and pads' corners as points (:meth:`Box.point_depth`).

Pure Python, as the kinematics module: a handful of shapes a tick, most of them skipped
by a bounding-box test before any distance is computed.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

from .. import _kinematics as kin
from .._pose import Pose

#: Radius of the capsule round each arm link (the segment between two consecutive joint
#: origins of the arm model), mm. The wrist's last capsule stops this short of the flange,
#: so the arm's shape ends at the flange plane.
ARM_RADIUS_MM = 45.0
#: The flange: a disc of this radius on the flange plane, mm.
FLANGE_RADIUS_MM = 32.0
#: The palm between the flange and the pads: a box centred here in the TCP frame, mm ...
PALM_CENTRE_MM = (0.0, 0.0, -20.0)
#: ... of these half sizes along the tool's x, y (the fingers' axis) and z, mm.
PALM_HALF_MM = (12.0, 30.0, 4.0)
#: The table is solid this far under its top for the links and the held part (as for
#: the tool's points, whose depth is measured down from the top), mm.
TABLE_DEPTH_MM = 1000.0

#: A few halvings more than needed for 0.01 mm over the longest link.
_INNER_SEARCH_STEPS = 40


def transform_point(t: kin.Transform, point: Sequence[float]) -> kin.Vector:
    """``point`` moved by the transform ``t`` (rotated, then translated).

    Args:
        t: The transform.
        point: The point, mm.

    Returns:
        The moved point, mm.
    """
    x, y, z = point
    return (
        t[0][0] * x + t[0][1] * y + t[0][2] * z + t[0][3],
        t[1][0] * x + t[1][1] * y + t[1][2] * z + t[1][3],
        t[2][0] * x + t[2][1] * y + t[2][2] * z + t[2][3],
    )


@dataclass(frozen=True)
class Box:
    """An obstacle: a box at a pose (the table's top, a fixture), with its bounding box.

    Attributes:
        name: What a collision message calls it ("the table", "fixture jig").
        inverse: The base-to-box transform.
        half: Half its size along its own x, y and z, mm.
        low: The low corner of its axis-aligned bounding box in the base frame, mm.
        high: The high corner of that bounding box, mm.
    """

    name: str
    inverse: kin.Transform
    half: kin.Vector
    low: kin.Vector
    high: kin.Vector

    @classmethod
    def at(cls, name: str, pose: Pose, size_mm: Sequence[float]) -> Box:
        """The box of ``size_mm`` centred at ``pose``.

        Args:
            name: What a collision message calls it.
            pose: Its centre's pose in the base frame.
            size_mm: Its size along its own x, y and z, mm.

        Returns:
            The box.
        """
        frame = kin.pose_to_transform(pose)
        half = (size_mm[0] / 2, size_mm[1] / 2, size_mm[2] / 2)
        reach = [sum(abs(frame[i][j]) * half[j] for j in range(3)) for i in range(3)]
        centre = (frame[0][3], frame[1][3], frame[2][3])
        return cls(
            name,
            kin.invert(frame),
            half,
            (centre[0] - reach[0], centre[1] - reach[1], centre[2] - reach[2]),
            (centre[0] + reach[0], centre[1] + reach[1], centre[2] + reach[2]),
        )

    @classmethod
    def table(cls, top_z_mm: float, centre_xy: Sequence[float], half_xy: Sequence[float]) -> Box:
        """The table: its top's footprint, solid :data:`TABLE_DEPTH_MM` under its top.

        Args:
            top_z_mm: The height of its top, mm.
            centre_xy: The centre of its top, mm.
            half_xy: Half its top's size along x and y, mm.

        Returns:
            The box, named "the table".
        """
        centre = Pose(centre_xy[0], centre_xy[1], top_z_mm - TABLE_DEPTH_MM / 2, 0, 0, 0)
        return cls.at("the table", centre, (2 * half_xy[0], 2 * half_xy[1], TABLE_DEPTH_MM))

    def overlaps(self, low: Sequence[float], high: Sequence[float]) -> bool:
        """Whether the bounding box ``low`` .. ``high`` overlaps this box's (a cheap test).

        Args:
            low: Its low corner in the base frame, mm.
            high: Its high corner, mm.

        Returns:
            False when the two bounding boxes are apart (the shapes in them are too).
        """
        return (
            low[0] <= self.high[0]
            and high[0] >= self.low[0]
            and low[1] <= self.high[1]
            and high[1] >= self.low[1]
            and low[2] <= self.high[2]
            and high[2] >= self.low[2]
        )

    def local(self, point: Sequence[float]) -> kin.Vector:
        """``point`` (base frame) in the box's frame, mm."""
        return transform_point(self.inverse, point)

    def point_depth(self, point: Sequence[float]) -> float:
        """How deep ``point`` is in the box: its distance to the nearest face, mm.

        Args:
            point: A point in the base frame, mm.

        Returns:
            The depth (> 0 inside, 0 on a face), or -1 when the point is outside.
        """
        p = self.local(point)
        h = self.half
        depth = min(h[0] - abs(p[0]), h[1] - abs(p[1]), h[2] - abs(p[2]))
        return depth if depth >= 0 else -1.0


def segment_depth(box: Box, a: Sequence[float], b: Sequence[float], radius_mm: float) -> float:
    """How deep the capsule round the segment ``a`` - ``b`` is in ``box``, mm.

    Outside the box the depth is the radius less the segment's distance to the box (the
    distance is exact: along the segment it is a piecewise quadratic, minimised on each
    piece); a segment running into the box adds how far inside it gets.

    Args:
        box: The obstacle.
        a: One end of the segment in the base frame, mm.
        b: The other end, mm.
        radius_mm: The capsule's radius, mm.

    Returns:
        The depth (>= 0: they touch), or -1 when they are apart.
    """
    la, lb = box.local(a), box.local(b)
    d = (lb[0] - la[0], lb[1] - la[1], lb[2] - la[2])
    h = box.half
    # Where the segment crosses a face's plane: between two crossings each coordinate is
    # below, inside or above the box's slab, and the squared distance a quadratic in t.
    cuts = [0.0, 1.0]
    for i in range(3):
        if d[i] != 0.0:
            for face in (-h[i], h[i]):
                t = (face - la[i]) / d[i]
                if 0.0 < t < 1.0:
                    cuts.append(t)
    cuts.sort()
    best = math.inf
    for t0, t1 in itertools.pairwise(cuts):
        if t1 <= t0:
            continue
        middle = (t0 + t1) / 2
        ed = dd = ee = 0.0
        outside = False
        for i in range(3):
            p = la[i] + middle * d[i]
            if p > h[i]:
                e = la[i] - h[i]
            elif p < -h[i]:
                e = la[i] + h[i]
            else:
                continue
            outside = True
            ed += e * d[i]
            dd += d[i] * d[i]
            ee += e * e
        if not outside:
            return radius_mm + _inner_depth(la, d, h)
        t = t0 if dd == 0.0 else min(max(-ed / dd, t0), t1)
        best = min(best, ee + 2 * t * ed + t * t * dd)
    distance = math.sqrt(max(best, 0.0))
    return radius_mm - distance if distance <= radius_mm else -1.0


def _inner_depth(la: kin.Vector, d: kin.Vector, h: kin.Vector) -> float:
    """The deepest a segment gets inside a box (its local start, direction, half sizes).

    The depth at t, min_i(h_i - |la_i + t d_i|), is concave in t: a ternary search finds
    its top. Only a segment already inside a box gets here (a collision), so it is rare.
    """

    def depth(t: float) -> float:
        return min(h[i] - abs(la[i] + t * d[i]) for i in range(3))

    low, high = 0.0, 1.0
    for _ in range(_INNER_SEARCH_STEPS):
        third = (high - low) / 3
        if depth(low + third) < depth(high - third):
            low += third
        else:
            high -= third
    return max(depth((low + high) / 2), 0.0)


def box_depth(box: Box, frame: kin.Transform, half: Sequence[float]) -> float:
    """How deep another box (``frame``, ``half``) is in ``box``: the shortest move apart, mm.

    The separating axis test of two oriented boxes (Gottschalk's; Ericson, *Real-Time
    Collision Detection*, 4.4.1): the boxes are apart when their projections on one of 15
    axes (each box's 3 face normals, the 9 cross products of their edges) are apart;
    otherwise the smallest overlap along those axes is how far one must move to clear
    the other.

    Args:
        box: The obstacle.
        frame: The other box's centre and axes in the base frame.
        half: Its half sizes along its own axes, mm.

    Returns:
        The depth (>= 0: they touch), or -1 when they are apart.
    """
    inv = box.inverse
    # The other box's axes (columns) and centre in the obstacle's frame.
    r = [[sum(inv[i][k] * frame[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
    t = box.local((frame[0][3], frame[1][3], frame[2][3]))
    a, b = box.half, half
    # The tiny term keeps near-parallel edges from producing a false separating axis.
    ar = [[abs(r[i][j]) + 1e-9 for j in range(3)] for i in range(3)]
    depth = math.inf
    for i in range(3):
        overlap = a[i] + b[0] * ar[i][0] + b[1] * ar[i][1] + b[2] * ar[i][2] - abs(t[i])
        if overlap < 0:
            return -1.0
        depth = min(depth, overlap)
    for j in range(3):
        centre = abs(t[0] * r[0][j] + t[1] * r[1][j] + t[2] * r[2][j])
        overlap = a[0] * ar[0][j] + a[1] * ar[1][j] + a[2] * ar[2][j] + b[j] - centre
        if overlap < 0:
            return -1.0
        depth = min(depth, overlap)
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            length = math.sqrt(max(0.0, 1.0 - r[i][j] * r[i][j]))
            if length < 1e-6:
                continue  # parallel edges: their face normals above decide
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            reach = a[i1] * ar[i2][j] + a[i2] * ar[i1][j] + b[j1] * ar[i][j2] + b[j2] * ar[i][j1]
            centre = abs(t[i2] * r[i1][j] - t[i1] * r[i2][j])
            overlap = (reach - centre) / length
            if overlap < 0:
                return -1.0
            depth = min(depth, overlap)
    return depth


#: An arm link the backends check: its number (the MJCF's body ``link<k>``), the index
#: of the joint origin it starts at, and the fraction of the way to the next one its
#: capsule's axis covers.
Link = tuple[int, int, float]


def arm_links(chain: kin.Chain, radius_mm: float = ARM_RADIUS_MM) -> tuple[Link, ...]:
    """The links the arm is checked with, as capsules round the segments of its chain.

    Link ``k`` runs from joint ``k``'s origin to joint ``k + 1``'s (the MJCF's body
    ``link<k>``): 2 the upper arm, 3 the forearm, 4 and 5 the wrist, whose capsule stops
    ``radius_mm`` short of the flange. Link 1 (the shoulder, turned by J1 about its own
    axis where the arm is mounted) is not one of them, nor is a link of no length.

    Args:
        chain: The arm's joint chain.
        radius_mm: The capsules' radius, mm.

    Returns:
        The links (their lengths do not depend on the joints).
    """
    origins = chain.joint_origins([0.0] * len(chain.origins))
    links = []
    last = len(origins) - 1
    for k in range(1, last):
        length = math.dist(origins[k], origins[k + 1])
        if length <= 1e-6:
            continue
        # The wrist ends at the flange plane.
        keep = max(0.0, 1 - radius_mm / length) if k + 1 == last else 1.0
        links.append((k + 1, k, keep))
    return tuple(links)


def link_contacts(
    origins: Sequence[kin.Vector],
    links: Sequence[Link],
    obstacles: Sequence[Box],
    radius_mm: float = ARM_RADIUS_MM,
) -> list[tuple[int, Box, float]]:
    """The links touching an obstacle, and how deep (:func:`segment_depth`).

    A link is measured against an obstacle only when their bounding boxes overlap (its
    height first: the table is the obstacle of every cell, and the arm mostly far above).

    Args:
        origins: The joints' origins in the base frame now (:meth:`Chain.joint_origins`).
        links: The links (:func:`arm_links`).
        obstacles: The table and the fixtures.
        radius_mm: The capsules' radius, mm.

    Returns:
        (link number, obstacle, depth >= 0) of each contact.
    """
    r = radius_mm
    found = []
    for link, k, keep in links:
        ax, ay, az = origins[k]
        bx, by, bz = origins[k + 1]
        if keep != 1.0:
            bx, by, bz = ax + (bx - ax) * keep, ay + (by - ay) * keep, az + (bz - az) * keep
        z0, z1 = (az - r, bz + r) if az < bz else (bz - r, az + r)
        x0, x1 = (ax - r, bx + r) if ax < bx else (bx - r, ax + r)
        y0, y1 = (ay - r, by + r) if ay < by else (by - r, ay + r)
        for box in obstacles:
            low, high = box.low, box.high
            if (
                z0 > high[2]
                or z1 < low[2]
                or x0 > high[0]
                or x1 < low[0]
                or y0 > high[1]
                or y1 < low[1]
            ):
                continue
            depth = segment_depth(box, (ax, ay, az), (bx, by, bz), r)
            if depth >= 0:
                found.append((link, box, depth))
    return found
