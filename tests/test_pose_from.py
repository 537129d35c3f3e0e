"""pose_from: the pose of six decoded register values, the same as Pose(...) builds."""

from __future__ import annotations

import copy
import dataclasses
import math
import pickle

import pytest

from tmmaster import ConfigError, Pose
from tmmaster._channels import TCP_FIELDS, pose_from


def _values(*coordinates: float) -> dict[str, float | int]:
    return dict(zip(TCP_FIELDS, coordinates, strict=True))


@pytest.mark.parametrize(
    "coordinates",
    [(300.0, -200.0, 200.0, 180.0, 0.0, 90.0), (1, -2, 3, 4, -5, 6), (0.0, -0.0, 1e9, 0, 0, 0)],
)
def test_the_pose_is_the_one_pose_builds(coordinates: tuple[float, ...]) -> None:
    pose = pose_from(_values(*coordinates), TCP_FIELDS)
    built = Pose(*(float(c) for c in coordinates))
    assert type(pose) is Pose
    assert pose == built
    assert hash(pose) == hash(built)
    assert repr(pose) == repr(built)
    assert all(type(c) is float for c in pose.as_list())
    assert pickle.loads(pickle.dumps(pose)) == built
    assert copy.deepcopy(pose) == built
    assert dataclasses.replace(pose, z=7.0) == dataclasses.replace(built, z=7.0)
    assert pose.offset(dz=1) == built.offset(dz=1)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_coordinate_that_is_not_finite_is_refused_as_pose_refuses_it(bad: float) -> None:
    with pytest.raises(ConfigError, match="invalid pose: rx"):
        pose_from(_values(1, 2, 3, bad, 5, 6), TCP_FIELDS)
