"""The arm's body as capsules: self-collision, the mounting plane and the 2FG7's housing.

The links of a TM5-700 / TM5-900 are capsules fitted to Techman's collision meshes
(``TechmanRobotInc/tmr_ros2`` at 684faab, ``tm_description/meshes/tm5-*/collision/*_c.stl``,
placed in each link's frame as ``tm_description/urdf/tm5-*-nominal.urdf`` places them):
each capsule's axis runs along the part's joint axis or its length, its radius is the
larger half-width of the part's cross-section and its segment the part's extent less
0.8 radius at each end (a tube's segment spans its link, joint axis to joint axis; the
camera's front end reaches exactly as far beyond the flange as its mesh). A capsule
reaches up to 0.2 radius past a part's flat ends; the meshes being coarse prisms, the
rims of those ends and the prisms' edges lie partly outside it. Checked against the
meshes themselves on 400 random tool-down targets the master accepted (a TM5-700, the
default cell): of the 56 whose meshes touch (come within 2 mm), 50 are refused and 6
graze (:data:`GRAZE_MM`); 1 whose meshes are 4.8 mm apart is refused. Pairs of links
the robot's SRDF (``tm_moveit_config_tm5-*/config/tm5-*.srdf``) marks as adjacent or
never colliding are not tested.

The gripper's housing is a capsule along the flange's z axis from the flange towards
the fingers: an OnRobot 2FG7 body 144 mm long and 80 mm wide (the figures of OnRobot's
2FG7 datasheet as given to this project; not checked against the datasheet here),
ending 24 mm short of the TCP (the simulated gripper's palm) if that is nearer; a TCP
less than 104 mm beyond the flange (the simulator's default: at the flange) leaves no
room for one.

Pure Python like the kinematics: one check places 14 capsules and measures the pairs
whose bounding spheres meet (most do not).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

from . import _kinematics as kin
from ._exceptions import ConfigError
from ._pose import Pose
from ._robot_models import RobotModel, joint_chain

Vector = tuple[float, float, float]
#: A capsule in its link's frame: link number (0 the base .. 6 the flange, 7 the
#: gripper's housing), name, segment ends (mm), radius (mm).
CapsuleSpec = tuple[int, str, Vector, Vector, float]

# Fitted to tm5-base_c, tmr_400w_01_c, tmr_100w_01_c, tmr_100w_02_c and tmr_ee_c (shared
# by both TM5 models), in the frames of link_0, link_1, link_4, link_5 and link_6.
_COMMON: tuple[CapsuleSpec, ...] = (
    (0, "base", (0.0, 0.0, 33.0), (0.0, 0.0, 33.0), 89.0),
    (1, "shoulder", (0.0, -15.0, 4.0), (0.0, 4.0, 4.0), 76.0),
    (4, "wrist 1", (0.0, -13.3, 2.2), (0.0, 19.3, 2.2), 51.0),
    (5, "wrist 2", (0.0, -20.7, -2.5), (0.0, 21.3, -2.5), 48.0),
    (6, "flange housing", (0.0, -17.9, -31.7), (0.0, -17.9, -31.7), 44.0),
    # Its front end reaches as far beyond the flange as the mesh (52 mm), no further.
    (6, "camera", (-0.5, 76.8, -34.4), (-0.5, 76.8, 15.0), 37.0),
)
# Fitted to tm5-700_arm1_c / tm5-700_arm2_c (link_2, link_3 of the TM5-700) ...
_TM5_700: tuple[CapsuleSpec, ...] = (
    (2, "shoulder housing", (-0.7, 0.0, -177.8), (-0.7, 0.0, -113.4), 62.0),
    (2, "upper arm", (0.0, 2.3, -146.6), (329.0, 2.3, -146.6), 48.0),
    (2, "elbow housing", (330.1, 0.0, -176.0), (330.1, 0.0, -113.2), 61.0),
    (3, "elbow end", (-7.8, 2.0, -20.9), (-7.8, 2.0, -20.9), 61.0),
    (3, "forearm", (0.0, -0.5, -15.7), (311.5, -0.5, -15.7), 38.0),
    (3, "wrist end", (304.7, 0.2, -33.3), (304.7, 0.2, 1.8), 52.0),
)
# ... and to tm5-900_arm1_c / tm5-900_arm2_c (the TM5-900's).
_TM5_900: tuple[CapsuleSpec, ...] = (
    (2, "shoulder housing", (-4.9, 0.0, -173.8), (-4.9, 0.0, -126.2), 65.0),
    (2, "upper arm", (0.0, 0.0, -146.0), (429.0, 0.0, -146.0), 51.0),
    (2, "elbow housing", (433.9, 0.0, -173.8), (433.9, 0.0, -126.2), 65.0),
    (3, "elbow end", (-10.0, 0.0, -25.3), (-10.0, 0.0, -25.3), 65.0),
    (3, "forearm", (0.0, 0.0, -16.3), (411.5, 0.0, -16.3), 38.0),
    (3, "wrist end", (408.3, 0.0, -28.8), (408.3, 0.0, 2.2), 52.0),
)
#: The arms with a body model, by :attr:`RobotModel.name` (others are not checked).
ARM_CAPSULES: dict[str, tuple[CapsuleSpec, ...]] = {
    "tm5-700": _COMMON + _TM5_700,
    "tm5-900": _COMMON + _TM5_900,
}

#: The link pairs never tested: the SRDF's (adjacent, or "Never" for link_0 / link_2),
#: and the housing with the flange it is bolted to and the wrist next to it.
ALLOWED_PAIRS = frozenset({(0, 1), (0, 2), (1, 2), (2, 3), (3, 4), (4, 5), (5, 6), (5, 7), (6, 7)})

#: The gripper housing's link number.
HOUSING_LINK = 7
#: The 2FG7's housing: its length from the flange and its width, mm (OnRobot 2FG7
#: datasheet, as given to this project: 144 x 80 mm).
HOUSING_LENGTH_MM = 144.0
HOUSING_WIDTH_MM = 80.0
#: The housing ends this far short of the TCP (the simulated gripper's palm, 20 mm
#: behind the TCP and 4 mm thick: the default tool extent's), mm.
HOUSING_TCP_CLEARANCE_MM = 24.0
#: Two capsules overlapping by no more than this graze, mm: at such joints Techman's
#: meshes come within 2 mm of each other, touching or not (the fit's own error).
GRAZE_MM = 3.0
#: No link and no housing may come closer than this to the robot's mounting plane, mm.
MOUNT_MARGIN_MM = 2.0
#: Joint travel between two checked samples of a path (the largest joint's), deg.
PTP_SAMPLE_DEG = 5.0


@dataclass(frozen=True)
class Contact:
    """Two parts of the arm that meet, or a part below the mounting plane."""

    #: What touches: "link 3 forearm".
    first: str
    #: What it touches: "link 5 wrist 2", "the mounting plane".
    second: str
    #: The parts' surface distance (negative: they overlap by that much), mm.
    distance_mm: float


@dataclass(frozen=True)
class ArmBody:
    """An arm's capsules with a tool, and the pairs of them to test."""

    specs: tuple[CapsuleSpec, ...]
    names: tuple[str, ...]
    #: The pairs to test, and the distance of their centres beyond which they are apart.
    pairs: tuple[tuple[int, int, float], ...]
    #: Each capsule's centre in its link's frame (its bounding sphere's).
    centres: tuple[Vector, ...]
    #: Each capsule's bounding sphere's radius round that centre, mm.
    radii: tuple[float, ...]


def housing_in_flange(tool: Pose | None) -> tuple[Vector, Vector, float] | None:
    """The 2FG7 housing's capsule in the flange frame: its ends and radius (None: no room).

    It runs along the flange's z axis from the flange, :data:`HOUSING_LENGTH_MM` long or
    up to :data:`HOUSING_TCP_CLEARANCE_MM` short of the TCP if that is nearer, and is
    :data:`HOUSING_WIDTH_MM` wide; a tool too short for that width has none.

    Args:
        tool: The TCP in the flange frame (None: the flange).

    Returns:
        (a, b, radius), mm, or None.
    """
    reach = 0.0 if tool is None else tool.z
    length = min(HOUSING_LENGTH_MM, reach - HOUSING_TCP_CLEARANCE_MM)
    radius = HOUSING_WIDTH_MM / 2
    return None if length < 2 * radius else ((0, 0, radius), (0, 0, length - radius), radius)


@functools.lru_cache(maxsize=64)
def arm_body(name: str, tool: Pose | None) -> ArmBody | None:
    """The capsules of the arm ``name`` with the 2FG7 housing the ``tool`` leaves room for.

    Args:
        name: The arm model's name (:attr:`RobotModel.name`).
        tool: The TCP in the flange frame (None: the flange).

    Returns:
        The body, or None for an arm without a capsule model.
    """
    specs = ARM_CAPSULES.get(name)
    if specs is None:
        return None
    if (housing := housing_in_flange(tool)) is not None:
        specs = (*specs, (HOUSING_LINK, "2FG7 housing", *housing))
    names = tuple(f"link {s[0]} {s[1]}" if s[0] < HOUSING_LINK else f"the {s[1]}" for s in specs)
    # Each capsule's bounding sphere: its segment's middle, half its length + its radius.
    centres = tuple(_mid(a, b) for _, _, a, b, _ in specs)
    radii = tuple(math.dist(a, b) / 2 + r for _, _, a, b, r in specs)
    pairs = tuple(
        (i, j, radii[i] + radii[j])
        for i in range(len(specs))
        for j in range(i + 1, len(specs))
        if specs[i][0] != specs[j][0]
        and (min(specs[i][0], specs[j][0]), max(specs[i][0], specs[j][0])) not in ALLOWED_PAIRS
    )
    return ArmBody(specs, names, pairs, centres, radii)


def _apply(t: Sequence[Sequence[float]], p: Vector) -> Vector:
    x, y, z = p
    return (
        t[0][0] * x + t[0][1] * y + t[0][2] * z + t[0][3],
        t[1][0] * x + t[1][1] * y + t[1][2] * z + t[1][3],
        t[2][0] * x + t[2][1] * y + t[2][2] * z + t[2][3],
    )


def contacts(
    model: RobotModel,
    joints_deg: Sequence[float],
    tool: Pose | None = None,
    *,
    mount: bool = True,
    frames: Sequence[kin.Frame] | None = None,
) -> list[Contact]:
    """The arm's parts that meet at ``joints_deg``, and those below the mounting plane.

    Args:
        model: The arm model (an arm without a capsule model has none).
        joints_deg: The joints, deg.
        tool: The TCP in the flange frame (the 2FG7 housing's room).
        mount: Also the parts (link 2 on, the housing) closer than
            :data:`MOUNT_MARGIN_MM` to the mounting plane z = 0.
        frames: ``Chain.link_frames`` at ``joints_deg``, if the caller has them.

    Returns:
        The contacts, deepest first.
    """
    body = arm_body(model.name, tool)
    if body is None:
        return []
    if frames is None:
        frames = joint_chain(model).link_frames([math.radians(q) for q in joints_deg])
    frames = [*frames, frames[-1]]  # each link's (0 the base), 7 the housing's: the flange
    specs = body.specs
    centres = [_apply(frames[s[0]], c) for s, c in zip(specs, body.centres, strict=True)]
    ends: dict[int, tuple[Vector, Vector]] = {}

    def ends_of(k: int) -> tuple[Vector, Vector]:
        """Capsule ``k``'s segment ends in the base frame, placed once."""
        if k not in ends:
            frame = frames[specs[k][0]]
            ends[k] = (_apply(frame, specs[k][2]), _apply(frame, specs[k][3]))
        return ends[k]

    found = []
    for i, j, reach in body.pairs:
        if math.dist(centres[i], centres[j]) > reach:
            continue  # bounding spheres apart
        gap = segment_distance(*ends_of(i), *ends_of(j)) - specs[i][4] - specs[j][4]
        if gap < -GRAZE_MM:
            found.append(Contact(body.names[i], body.names[j], gap))
    if mount:
        for k, spec in enumerate(specs):
            # The base and the shoulder stand on the mount; a part whose bounding sphere
            # keeps clear of the plane cannot reach it.
            if spec[0] < 2 or centres[k][2] - body.radii[k] >= MOUNT_MARGIN_MM:
                continue
            a, b = ends_of(k)
            gap = min(a[2], b[2]) - spec[4] - MOUNT_MARGIN_MM
            if gap < 0:
                found.append(Contact(body.names[k], "the mounting plane", gap))
    found.sort(key=lambda c: c.distance_mm)
    return found


@functools.lru_cache(maxsize=512)
def _contacts_at(
    model: RobotModel, joints: tuple[float, ...], tool: Pose | None, mount: bool
) -> tuple[Contact, ...]:
    return tuple(contacts(model, joints, tool, mount=mount))


#: A contact the move starts with is tolerated while it gets no deeper than this, mm.
START_CONTACT_SLACK_MM = 1.0


def check_body(
    model: RobotModel,
    samples: Sequence[Sequence[float]],
    *,
    tool: Pose | None,
    floor_z_mm: float | None,
    start: Sequence[float] | None = None,
) -> None:
    """Refuse joint samples where the arm meets itself or its mounting plane.

    Each sample is checked with :func:`contacts`; with a floor (``floor_z_mm`` not
    None) the parts must also keep :data:`MOUNT_MARGIN_MM` above the mounting plane and
    the 2FG7 housing must stay above the floor. A contact the arm already has at
    ``start`` (the model's shapes are approximate) is tolerated while it gets no deeper.

    Args:
        model: The arm model (an arm without a capsule model is not checked).
        samples: The joints to check (a target, or a path's samples, end last), deg.
        tool: The TCP in the flange frame.
        floor_z_mm: The workspace's table plane (None: no plane, no mounting plane).
        start: The joints the move starts from (None: not known), deg.

    Raises:
        ConfigError: naming the two parts (or the part and the plane) and the overlap.
    """
    if model.name not in ARM_CAPSULES:
        return
    mount = floor_z_mm is not None
    known: dict[tuple[str, str], float] = {}
    if start is not None:
        for c in _contacts_at(model, tuple(start), tool, mount):
            known[c.first, c.second] = c.distance_mm
    for joints in _thinned(samples, start):
        for c in _contacts_at(model, joints, tool, mount):
            before = known.get((c.first, c.second))
            if before is None or c.distance_mm < before - START_CONTACT_SLACK_MM:
                raise ConfigError(_contact_text(c, joints, samples))
        if floor_z_mm is not None:
            segment = housing_segment(model, joints, tool)  # None: no housing
            lowest = math.inf if segment is None else min(segment[0][2], segment[1][2]) - segment[2]
            if lowest <= floor_z_mm:
                raise ConfigError(
                    f"{_where(joints, samples)} put the 2FG7 housing at z = {lowest:.1f} mm,"
                    f" on or below the table plane (workspace floor_z_mm = {floor_z_mm:g} mm)"
                )


def _thinned(
    samples: Sequence[Sequence[float]], start: Sequence[float] | None
) -> list[tuple[float, ...]]:
    """The samples at least :data:`PTP_SAMPLE_DEG` of any joint apart, and the last."""
    kept: list[tuple[float, ...]] = []
    last = None if start is None else tuple(start)
    for k, q in enumerate(samples):
        joints = tuple(q)
        if (
            k + 1 < len(samples)
            and last is not None
            and max(abs(a - b) for a, b in zip(joints, last, strict=True)) < PTP_SAMPLE_DEG
        ):
            continue
        kept.append(joints)
        last = joints
    return kept


def _where(joints: tuple[float, ...], samples: Sequence[Sequence[float]]) -> str:
    text = "(" + ", ".join(f"{q:.1f}" for q in joints) + ") deg"
    return f"joints {text}" if len(samples) == 1 else f"the path passes joints {text}, which"


def _contact_text(c: Contact, joints: tuple[float, ...], samples: Sequence[Sequence[float]]) -> str:
    where = _where(joints, samples)
    if c.second == "the mounting plane":
        return (
            f"{where} put {c.first} {-c.distance_mm:.1f} mm too low: closer than"
            f" {MOUNT_MARGIN_MM:g} mm to the robot's mounting plane (z = 0)"
        )
    return (
        f"self-collision: {where} put {c.first} into {c.second}"
        f" ({-c.distance_mm:.1f} mm overlap of the capsules fitted to Techman's collision"
        " meshes)"
    )


def housing_segment(
    model: RobotModel,
    joints_deg: Sequence[float],
    tool: Pose | None,
    *,
    flange: Sequence[Sequence[float]] | None = None,
) -> tuple[Vector, Vector, float] | None:
    """The 2FG7 housing's capsule at ``joints_deg``: its ends and radius (None: none).

    Args:
        model: The arm model.
        joints_deg: The joints, deg.
        tool: The TCP in the flange frame.
        flange: The flange's frame at ``joints_deg``, if the caller has it.

    Returns:
        (a, b, radius), mm, or None.
    """
    housing = housing_in_flange(tool)
    if housing is None:
        return None
    a, b, r = housing
    if flange is None:
        flange = joint_chain(model).flange([math.radians(q) for q in joints_deg])
    return _apply(flange, a), _apply(flange, b), r


def same_joints(a: Sequence[float], b: Sequence[float]) -> bool:
    """Whether two joint sets are the same within 0.001 deg each.

    Args:
        a: Joints, deg.
        b: Joints, deg.

    Returns:
        True when every joint is within 0.001 deg of the other's.
    """
    return all(abs(x - y) <= 1e-3 for x, y in zip(a, b, strict=True))


def ptp_samples(start: Sequence[float] | None, end: Sequence[float]) -> list[tuple[float, ...]]:
    """Joint samples along a PTP from ``start`` to ``end`` (joint interpolation), end last.

    Args:
        start: The joints the move starts from (None: not known), deg.
        end: The target's joints, deg.

    Returns:
        One sample per :data:`PTP_SAMPLE_DEG` of the largest joint's travel (at least
        the end), ``start`` itself left out; the end alone without a start.
    """
    if start is None:
        return [tuple(end)]
    travel = max((abs(b - a) for a, b in zip(start, end, strict=True)), default=0.0)
    steps = max(1, math.ceil(travel / PTP_SAMPLE_DEG))
    return [
        tuple(a + (b - a) * k / steps for a, b in zip(start, end, strict=True))
        for k in range(1, steps + 1)
    ]


def _mid(a: Vector, b: Vector) -> Vector:
    return ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2)


def segment_distance(p1: Vector, q1: Vector, p2: Vector, q2: Vector) -> float:
    """The shortest distance between the segments p1-q1 and p2-q2, mm.

    Ericson, *Real-Time Collision Detection*, 5.1.9 (closest points of two segments).

    Args:
        p1: The first segment's start.
        q1: Its end.
        p2: The second segment's start.
        q2: Its end.

    Returns:
        The distance.
    """
    d1 = (q1[0] - p1[0], q1[1] - p1[1], q1[2] - p1[2])
    d2 = (q2[0] - p2[0], q2[1] - p2[1], q2[2] - p2[2])
    r = (p1[0] - p2[0], p1[1] - p2[1], p1[2] - p2[2])
    a = d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2]
    e = d2[0] * d2[0] + d2[1] * d2[1] + d2[2] * d2[2]
    f = d2[0] * r[0] + d2[1] * r[1] + d2[2] * r[2]
    if a <= 1e-12 and e <= 1e-12:
        return math.dist(p1, p2)
    if a <= 1e-12:
        s, t = 0.0, min(max(f / e, 0.0), 1.0)
    else:
        c = d1[0] * r[0] + d1[1] * r[1] + d1[2] * r[2]
        if e <= 1e-12:
            s, t = min(max(-c / a, 0.0), 1.0), 0.0
        else:
            b = d1[0] * d2[0] + d1[1] * d2[1] + d1[2] * d2[2]
            denom = a * e - b * b
            s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > 1e-12 else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                s, t = min(max(-c / a, 0.0), 1.0), 0.0
            elif t > 1.0:
                s, t = min(max((b - c) / a, 0.0), 1.0), 1.0
    c1 = (p1[0] + d1[0] * s, p1[1] + d1[1] * s, p1[2] + d1[2] * s)
    c2 = (p2[0] + d2[0] * t, p2[1] + d2[1] * t, p2[2] + d2[2] * t)
    return math.dist(c1, c2)
