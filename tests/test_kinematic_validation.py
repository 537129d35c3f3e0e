"""The master refuses what a TM5 cannot execute, before the command is written."""

from __future__ import annotations

from collections.abc import Callable

import pytest

import tmmaster
from tmmaster import Pose, Robot, UnreachablePoseError
from tmmaster.pickplace import ARTICLE_HOME, pick_and_place, validate_config, validate_plan
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
ABOVE_NEAR_BASE = Pose(250, 0, 200, 180, 0, 90)
#: Straight below ABOVE_NEAR_BASE: J3 passes its 155 deg limit at z ~ 115 on the way.
NEAR_BASE = Pose(250, 0, 100, 180, 0, 90)


def requests_sent(sim: Simulator) -> list[object]:
    """Every request that reached the robot but the master's heartbeat (written on its own)."""
    return [r for r in sim.request_log if r.address != 9050]


def motion_writes(sim: Simulator) -> list[object]:
    """Every FC16 that reached the robot (the command block is one FC16)."""
    return [r for r in requests_sent(sim) if r.function_code == 16 and not r.refused]


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_the_articles_home_is_refused_and_nothing_is_sent(
    robots: Callable[..., Robot], memory_simulator_factory: SimFactory, profile: str
) -> None:
    sim = memory_simulator_factory(profile)
    robot = robots(sim)
    sim.clear_request_log()
    with pytest.raises(UnreachablePoseError, match="out of reach") as caught:
        robot.move_to(Pose.from_sequence(ARTICLE_HOME), speed=30)
    assert caught.value.reason == "reach"
    assert requests_sent(sim) == []


def test_a_line_through_a_joint_limit_is_refused_before_the_write(
    robots: Callable[..., Robot], memory_simulator_factory: SimFactory
) -> None:
    sim = memory_simulator_factory("article")
    robot = robots(sim)
    robot.move_to(ABOVE_NEAR_BASE, speed=100)
    sim.clear_request_log()
    with pytest.raises(UnreachablePoseError, match="J3") as caught:
        robot.move_to(NEAR_BASE, speed=30, motion="line")
    assert caught.value.reason == "joint_limit"
    assert motion_writes(sim) == []  # status reads happened; no command was written
    # The target itself has joint solutions, none in the arm's configuration (J3 would
    # pass its limit there too): the robot program solves a Cartesian target in the
    # current one (TMscript inversekin, p. 207), so the PTP is refused too, nothing sent.
    with pytest.raises(UnreachablePoseError, match="another pose configuration"):
        robot.check_move(NEAR_BASE, speed=100)
    assert motion_writes(sim) == []


def test_the_plan_validation_names_the_line_that_leaves_the_range() -> None:
    config = validate_config(
        {
            "poses": {"pick": NEAR_BASE.as_list()},
            "speeds": {"pick": 10},
        }
    )
    robot = Robot("127.0.0.1", 1, profile="article")  # never connected
    try:
        with pytest.raises(UnreachablePoseError, match=r"cell\.toml: poses\.pick.*J3"):
            validate_plan(robot, pick_and_place(config), 1, source="cell.toml")
    finally:
        robot.close()


def test_dry_run_prints_the_joints_of_every_move(capsys: pytest.CaptureFixture[str]) -> None:
    from tmmaster.pickplace.__main__ import main

    assert main(["--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "joints J1..J6 [deg]" in out
    model = tmmaster.robot_model("tm5-700")
    home = model.inverse(
        tmmaster.DEFAULT_HOME, seed_deg=model.inverse(Pose(300, 200, 200, 180, 0, 90))
    )
    assert "[" + ", ".join(f"{q:.1f}" for q in home) + "]" in out


def test_a_tool_offset_is_part_of_the_validation() -> None:
    # Tool pointing down 150 mm: the flange must be 150 mm higher than the TCP pose,
    # so a TCP pose near the top of the reach sphere becomes unreachable...
    tool = Pose(0, 0, 150, 0, 0, 0)
    high = Pose(300, 0, 550, 180, 0, 90)
    bare = Robot("127.0.0.1", 1, profile="tmflow")
    tooled = Robot("127.0.0.1", 1, profile="tmflow", tool=tool)
    try:
        bare.validate_move(high, 30)
        with pytest.raises(UnreachablePoseError):
            tooled.validate_move(high, 30)
        # ... and its joints are the bare arm's at the flange pose.
        low = Pose(300, 0, 100, 180, 0, 90)
        assert tooled.validate_move(low, 30) == pytest.approx(
            bare.validate_move(low.offset(dz=150), 30), abs=1e-3
        )
    finally:
        bare.close()
        tooled.close()


def test_a_tool_that_is_not_a_pose_is_a_config_error() -> None:
    with pytest.raises(tmmaster.ConfigError, match="tool"):
        Robot("127.0.0.1", 1, tool=[0, 0, 150, 0, 0, 0])  # type: ignore[arg-type]
