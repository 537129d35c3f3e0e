"""The default cell: the table and the tool the master and the simulator both assume.

One place for the numbers, so that the master's default :class:`~tmmaster.Workspace`
and the simulator's default world are the same cell: a move the master validates with
its defaults does not run the default tool into the default table. The simulator
imports these (never the other way round: the core does not import the simulator).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from ._robot_models import RobotModel, joint_chain

#: Height of the default cell's table top in the robot base frame, mm: the article's
#: 30 mm part, gripped at its centre at z = 100 mm, rests on it.
DEFAULT_TABLE_TOP_Z_MM = 85.0

#: The default tool's extent around the TCP, in the TCP frame: (x lo, hi), (y lo, hi),
#: (z lo, hi), mm. It holds the simulator's tool with the TCP at the flange (its default):
#: the flange disc (32 mm radius), the palm (20 mm behind the TCP, 30 mm to each side)
#: and the two-finger gripper's pads wide open (27.5 mm to each side, 12 mm ahead of
#: the TCP and behind it).
DEFAULT_TOOL_EXTENT_MM: tuple[tuple[float, float], tuple[float, float], tuple[float, float]] = (
    (-32.0, 32.0),
    (-32.0, 32.0),
    (-24.0, 12.0),
)

#: The radius of the arm's links round the segments between its joints' origins, mm
#: (the simulator's arm): the wrist's ends this far short of the flange, so the arm's
#: shape ends at the flange plane.
DEFAULT_ARM_RADIUS_MM = 45.0


def arm_lowest_z_mm(
    model: RobotModel, joints_deg: Sequence[float], radius_mm: float
) -> tuple[int, float]:
    """The arm's lowest link from the elbow on at ``joints_deg`` and its lowest point.

    The links are capsules of ``radius_mm`` round the segments between consecutive
    joints' origins (the simulator's arm): 3 the forearm, 4 and 5 the wrist, whose
    segment stops ``radius_mm`` short of the flange. The shoulder (link 1) and the upper
    arm's shoulder end stay where the arm is mounted, whatever the joints: not measured
    (the elbow, the upper arm's other end, is the forearm's start).

    Args:
        model: The arm model.
        joints_deg: The joints, deg.
        radius_mm: The links' radius, mm.

    Returns:
        The link's number (3-5) and the lowest point's z, mm.
    """
    origins = joint_chain(model).joint_origins([math.radians(q) for q in joints_deg])
    last = len(origins) - 1
    lowest = (0, math.inf)
    for k in range(2, last):
        a, b = origins[k], origins[k + 1]
        if (length := math.dist(a, b)) <= 1e-6:
            continue
        keep = max(0.0, 1 - radius_mm / length) if k + 1 == last else 1.0
        z = min(a[2], a[2] + (b[2] - a[2]) * keep) - radius_mm
        if z < lowest[1]:
            lowest = (k + 1, z)
    return lowest
