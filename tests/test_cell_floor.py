"""Pick & place knows the table its default plan is written for: a target into it is
refused before anything connects; the simulator catches only what the master was told
nothing of (a floor set lower than the table, a fixture)."""

from __future__ import annotations

from pathlib import Path

import pytest

import tmmaster
from tmmaster import ConfigError, Pose
from tmmaster.pickplace import (
    PickPlaceConfig,
    load_config,
    pick_and_place,
    robot_from_config,
    validate_plan,
)
from tmmaster.pickplace.__main__ import EXIT_CONFIG, EXIT_OK, main
from tmmaster.sim import Simulator, World

#: The TCP 30 mm below the default cell's table top (85 mm), 55 mm above the robot's base.
INTO_TABLE = "[300, -200, 55, 180, 0, 90]"


def _config(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "cell.toml"
    path.write_text(text)
    return path


def test_the_default_floor_is_the_simulated_tables_top() -> None:
    floor = PickPlaceConfig().workspace.floor_z_mm
    assert floor == World().table_top_z_mm == 85.0
    # The default plan grips the part on that table: every pose of it is above the plane.
    for name, pose in PickPlaceConfig().poses.resolved().items():
        assert pose.z >= floor, name


def test_a_pick_into_the_table_is_refused_before_anything_connects(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _config(tmp_path, f"[poses]\npick = {INTO_TABLE}\n")
    assert main(["--config", str(path), "--dry-run"]) == EXIT_CONFIG
    err = capsys.readouterr().err
    assert "below the table plane" in err
    assert "floor_z_mm = 85" in err
    # The library's check says the same thing, with no robot at all.
    config = load_config(path)
    robot = robot_from_config(config, host="127.0.0.1", port=1)
    with pytest.raises(ConfigError, match="floor_z_mm = 85"):
        validate_plan(robot, pick_and_place(config), 1, source=str(path))


def test_a_workspace_box_keeps_the_tables_floor(tmp_path: Path) -> None:
    # Setting only the box must not lower the table plane to the library's 0 mm.
    config = load_config(_config(tmp_path, "[workspace]\nx = [-800, 800]\n"))
    assert config.workspace.floor_z_mm == 85.0
    assert config.workspace.x == (-800.0, 800.0)


def test_a_cell_with_a_lower_table_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = f"[poses]\npick = {INTO_TABLE}\n\n[workspace]\nfloor_z_mm = 40\n"
    assert main(["--config", str(_config(tmp_path, text)), "--dry-run"]) == EXIT_OK


def test_what_the_master_was_not_told_the_simulator_stops(tmp_path: Path) -> None:
    # The file says the table is at 40 mm; the simulated one is at 85: the master lets the
    # pick at 55 mm through and the simulated arm stops on the table with TM's 0x22.
    config = load_config(
        _config(tmp_path, f"[poses]\npick = {INTO_TABLE}\n\n[workspace]\nfloor_z_mm = 40\n")
    )
    with Simulator("tmflow", time_scale=20, tick_hz=100, listen=False) as sim:
        robot = robot_from_config(config, host=sim.url)
        with robot:
            robot.wait_until_ready(timeout_s=5)
            pick = config.poses.resolved()["pick"]
            robot.move_to(pick.offset(dz=100), speed=50)
            with pytest.raises(tmmaster.RobotError) as caught:
                robot.move_to(pick, speed=50, motion="line")
            assert caught.value.error_code == 0x22
            assert sim.tcp_pose().z > pick.z + 20  # stopped where the pads met the table


def test_the_librarys_own_default_is_the_mounting_plane() -> None:
    # A library user with no cell described: only below the robot's base is refused.
    tmmaster.Workspace().check(Pose(300, -200, 55, 180, 0, 90))
    with pytest.raises(ConfigError, match="floor_z_mm = 0"):
        tmmaster.Workspace().check(Pose(300, -200, -1, 180, 0, 90))
