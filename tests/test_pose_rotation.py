"""Orientations compare as rotations: equivalent Euler angles are the same orientation."""

from __future__ import annotations

import math
import random

import pytest

from tmmaster import Pose
from tmmaster import _kinematics as kin


def matrix_angle(a: Pose, b: Pose) -> float:
    """The angle between two orientations from their rotation matrices (the reference)."""
    ra, rb = kin.pose_to_transform(a), kin.pose_to_transform(b)
    trace = sum(ra[i][k] * rb[i][k] for i in range(3) for k in range(3))
    return math.degrees(math.acos(max(-1.0, min(1.0, (trace - 1) / 2))))


@pytest.mark.parametrize(
    ("a", "b"),
    [
        # The same orientation written two ways (a TCP pointing down).
        ((0, 180, -90), (180, 0, 90)),
        ((0, 180, -90), (180, -0.0, 90)),
        # rz across the wrap.
        ((180, 0, 180), (180, 0, -180)),
        ((-180, 0, 90), (180, 0, 90)),
        # Gimbal lock: at ry = +90 only rz - rx counts, at ry = -90 only rz + rx.
        ((10, 90, 20), (0, 90, 10)),
        ((10, -90, 20), (0, -90, 30)),
        ((0, 90, 0), (45, 90, 45)),
    ],
)
def test_equivalent_euler_angles_are_the_same_orientation(
    a: tuple[float, float, float], b: tuple[float, float, float]
) -> None:
    pa, pb = Pose(300, 0, 300, *a), Pose(300, 0, 300, *b)
    assert pa.rotation_to(pb) < 1e-9
    assert pa.is_close(pb, mm=0.01, deg=0.01)


@pytest.mark.parametrize(
    ("a", "b", "angle"),
    [
        ((180, 0, 90), (180, 0, 91), 1.0),
        ((180, 0, 179.5), (180, 0, -179.5), 1.0),
        ((0, 89.5, 0), (0, 90.5, 0), 1.0),
        ((0, 0, 0), (180, 0, 0), 180.0),
    ],
)
def test_the_angle_is_the_rotation_between_them(
    a: tuple[float, float, float], b: tuple[float, float, float], angle: float
) -> None:
    assert Pose(0, 0, 0, *a).rotation_to(Pose(0, 0, 0, *b)) == pytest.approx(angle, abs=1e-9)


def test_the_angle_agrees_with_the_rotation_matrices() -> None:
    rng = random.Random(7)
    for _ in range(500):
        a = Pose(0, 0, 0, *(rng.uniform(-180, 180) for _ in range(3)))
        b = Pose(0, 0, 0, *(rng.uniform(-180, 180) for _ in range(3)))
        assert a.rotation_to(b) == pytest.approx(matrix_angle(a, b), abs=1e-6)
        assert a.rotation_to(b) == pytest.approx(b.rotation_to(a), abs=1e-9)
