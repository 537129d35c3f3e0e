"""Hunt 24: the master's Euler angles and relative moves against TMscript's worked examples.

[TS]: Programming Language TMscript 2.24, document version 1.00 (text copy:
kenshu528-oss/Modbus-testkit-for-TMflow, ``TM Doc/``), 6.27 ``trans()``, 6.28
``inversetrans()``, 6.29 ``applytrans()``, pp. 194-198: each gives the rotation matrix of
``{x, y, z, rx, ry, rz}`` (``Rz(rz) Ry(ry) Rx(rx)``) and a worked example with the robot's
own answers. The master's conversions, and ``move_by``'s two frames (``moved``), reproduce
those answers to the printed digits. Held: no defect found; kept as proof (a few ms).
"""

from __future__ import annotations

import pytest

from tmmaster import Pose
from tmmaster import _kinematics as kin
from tmmaster._planning import moved

P1 = Pose(100, -200, 300, 10, 20, 60)
P2 = Pose(-400, 200, 50, -20, 30, -45)
#: [TS] p. 195-198, the examples' printed results.
TRANS_RB = Pose(-500, 400, -250, -24.615868, -15.565178, -88.613686)
TRANS_I = Pose(176.10095, 588.32776, -308.80237, 3.7459252, 23.13792, -92.46916)
INV_I = Pose(218.38095, 142.13216, -268.52972, 12.483133, -18.590115, -60.283367)


def _t(pose: Pose) -> kin.Transform:
    return kin.pose_to_transform(pose)


def _same(a: Pose, b: Pose) -> bool:
    """Within 1e-3 (mm, deg), value by value (no ry near 90 here)."""
    return all(abs(x - y) < 1e-3 for x, y in zip(a.as_list(), b.as_list(), strict=True))


def test_inversetrans_relative_to_the_point() -> None:
    assert _same(kin.transform_to_pose(kin.invert(_t(P1))), INV_I)


def test_trans_relative_to_the_first_point() -> None:
    assert _same(kin.transform_to_pose(kin.multiply(kin.invert(_t(P1)), _t(P2))), TRANS_I)


def test_trans_in_the_robot_base_turns_about_the_base_axes() -> None:
    # R_trans = R2 * R1^-1, P_trans = P2 - P1.
    turn = kin.transform_to_pose(kin.multiply(_t(P2), kin.invert(_t(P1))))
    assert _same(Pose(P2.x - P1.x, P2.y - P1.y, P2.z - P1.z, turn.rx, turn.ry, turn.rz), TRANS_RB)


@pytest.mark.parametrize(("offset", "frame"), [(TRANS_RB, "base"), (TRANS_I, "tool")])
def test_move_by_is_applytrans(offset: Pose, frame: str) -> None:
    # applytrans(P1, trans_RB) and applytrans(P1, trans_i, true) both give P2 back
    # ([TS] p. 198: {-400, 200, 50, -20, 30, -44.999996}); move_by(frame="base"/"tool").
    assert _same(moved(P1, offset, frame), P2)


def test_a_split_at_gimbal_lock_moves_by_the_same_turn() -> None:
    # At ry = 90 only rx - rz counts: a robot may report (0, 90, -30) for (30, 90, 0).
    # A relative move resolved against either lands on the same orientation.
    commanded, reported = Pose(450, -100, 400, 30, 90, 0), Pose(450, -100, 400, 0, 90, -30)
    assert commanded.rotation_to(reported) < 1e-6
    for frame in ("base", "tool"):
        a = moved(commanded, Pose(0, 0, 0, 5, -10, 15), frame)
        b = moved(reported, Pose(0, 0, 0, 5, -10, 15), frame)
        assert a.is_close(b, mm=1e-6, deg=1e-6)
