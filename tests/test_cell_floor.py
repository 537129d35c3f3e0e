"""The master's default workspace is the simulator's default cell: a target into the
table (the TCP, the tool round it, the arm's links) is refused before any byte is sent,
by the library and by pick & place; the simulator catches only what the master was told
nothing of (a floor set lower than the table, a fixture)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

import tmmaster
from tmmaster import ConfigError, Pose, Workspace
from tmmaster._cell import (
    DEFAULT_ARM_RADIUS_MM,
    DEFAULT_TABLE_TOP_Z_MM,
    DEFAULT_TOOL_EXTENT_MM,
    arm_lowest_z_mm,
)
from tmmaster._robot_models import joint_chain, robot_model
from tmmaster.pickplace import (
    PickPlaceConfig,
    load_config,
    pick_and_place,
    robot_from_config,
    validate_plan,
)
from tmmaster.pickplace.__main__ import EXIT_CONFIG, EXIT_OK, main
from tmmaster.sim import DEFAULT_PART_POSE, Simulator, Timing, World
from tmmaster.sim._collide import (
    ARM_RADIUS_MM,
    FLANGE_RADIUS_MM,
    PALM_CENTRE_MM,
    PALM_HALF_MM,
    arm_links,
)
from tmmaster.sim._server import RequestRecord
from tmmaster.sim._world import DEFAULT_GRIPPER, TABLE_CENTRE_XY_MM, TABLE_HALF_SIZE_XY_MM

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
    # Setting only the box must not lower the table plane.
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
    with Simulator("tmflow", time_scale=20, timing=Timing(tick_hz=100), listen=False) as sim:
        robot = robot_from_config(config, host=sim.url)
        with robot:
            robot.wait_until_ready(timeout_s=5)
            pick = config.poses.resolved()["pick"]
            robot.move_to(pick.offset(dz=100), speed=50)
            with pytest.raises(tmmaster.RobotError) as caught:
                robot.move_to(pick, speed=50, motion="line")
            assert caught.value.error_code == 0x22
            assert sim.tcp_pose().z > pick.z + 20  # stopped where the pads met the table


def test_the_librarys_default_is_the_default_cells_table() -> None:
    # One number: the master's default plane is the simulator's default table top.
    assert Workspace().floor_z_mm == World().table_top_z_mm == DEFAULT_TABLE_TOP_Z_MM == 85.0
    assert PickPlaceConfig().workspace.floor_z_mm == Workspace().floor_z_mm
    # Another cell states its own: 0 is the plane the robot stands on.
    Workspace(floor_z_mm=0).check(Pose(300, -200, 55, 180, 0, 90))
    with pytest.raises(ConfigError, match="floor_z_mm = 0"):
        Workspace(floor_z_mm=0).check(Pose(300, -200, -1, 180, 0, 90))


def test_the_default_tool_extent_holds_the_simulated_tool() -> None:
    # Every point of the simulator's tool (TCP at the flange, its default): the flange
    # disc, the palm's corners and the pads wide open, inside DEFAULT_TOOL_EXTENT_MM.
    (xl, xh), (yl, yh), (zl, zh) = DEFAULT_TOOL_EXTENT_MM
    g = DEFAULT_GRIPPER
    outer = g.max_width_mm / 2 + g.pad_thickness_mm
    points = [(FLANGE_RADIUS_MM, 0.0, 0.0), (0.0, FLANGE_RADIUS_MM, 0.0)]
    points += [
        (PALM_CENTRE_MM[0] + sx * PALM_HALF_MM[0], sy * PALM_HALF_MM[1], PALM_CENTRE_MM[2] + h)
        for sx in (-1, 1)
        for sy in (-1, 1)
        for h in (-PALM_HALF_MM[2], PALM_HALF_MM[2])
    ]
    points += [
        (sx * g.pad_depth_mm / 2, sy * outer, sz * g.pad_height_mm / 2)
        for sx in (-1, 1)
        for sy in (-1, 1)
        for sz in (-1, 1)
    ]
    for x, y, z in points:
        assert xl <= x <= xh, (x, y, z)
        assert yl <= y <= yh, (x, y, z)
        assert zl <= z <= zh, (x, y, z)
    assert DEFAULT_ARM_RADIUS_MM == ARM_RADIUS_MM


@pytest.mark.parametrize(
    "joints",
    [
        (0, 0, 90, 0, 90, 0),
        (29.4, 36.8, 89.7, 53.5, 29.4, 180),
        (-41.1, 59.9, 103.8, -163.7, 41.1, 0),
    ],
)
def test_the_arm_check_measures_the_simulators_links(joints: tuple[float, ...]) -> None:
    # The master's lowest link point is the lowest of the simulator's capsules from the
    # elbow on (the upper arm's shoulder end does not move).
    model = robot_model("tm5-700")
    chain = joint_chain(model)
    origins = chain.joint_origins([math.radians(q) for q in joints])
    lowest = math.inf
    for link, k, keep in arm_links(chain):
        if link < 3:
            continue
        a, b = origins[k], origins[k + 1]
        lowest = min(lowest, a[2] - ARM_RADIUS_MM, a[2] + (b[2] - a[2]) * keep - ARM_RADIUS_MM)
    assert arm_lowest_z_mm(model, joints, DEFAULT_ARM_RADIUS_MM)[1] == pytest.approx(lowest)


def _sim(records: list[RequestRecord] | None = None) -> Simulator:
    return Simulator(
        time_scale=50,
        timing=Timing(tick_hz=100),
        listen=False,
        request_listener=None if records is None else records.append,
    )


@pytest.mark.parametrize(
    ("target", "what"),
    [
        (Pose(450, 200, 60, 180, 0, 90), "puts the TCP below the table plane"),
        # The TCP above the table, the pads (12 mm ahead of it) in it.
        (Pose(450, 200, 90, 180, 0, 90), "tool's lowest point at z = 78.0 mm"),
        # The tool sideways: the wrist (45 mm round its axis) in the table.
        (Pose(450, 0, 117.5, 90, 0, 0), "link 5 of the arm at z = 72.5 mm"),
    ],
)
def test_with_every_default_a_target_into_the_table_is_refused_before_any_byte(
    target: Pose, what: str
) -> None:
    records: list[RequestRecord] = []
    with _sim(records) as sim, tmmaster.Robot(sim.url) as robot:
        robot.wait_until_ready(timeout_s=5)
        home, sent = sim.tcp_pose(), len(records)
        with pytest.raises(ConfigError, match=what):
            robot.move_to(target, speed=50)
        assert records[sent:] == []
        assert sim.tcp_pose() == home  # still where it was


@pytest.mark.parametrize(
    "target",
    [
        # Just above the clearance the default tool needs over the default table.
        Pose(450, 200, DEFAULT_TABLE_TOP_Z_MM + 12.5, 180, 0, 90),
        Pose(300, -350, DEFAULT_TABLE_TOP_Z_MM + 12.5, 180, 0, 0),
        # Tilted: the extent's corner, not the pads' front, is the lowest point.
        Pose(500, 100, 112.5, 150, 0, 90),
        # The default part's pick pose.
        DEFAULT_PART_POSE,
    ],
)
def test_with_every_default_a_validated_target_does_not_collide(target: Pose) -> None:
    # What the master lets through, the simulator's default cell lets the arm reach:
    # from above (PTP), then straight down (Line), no 0x22 on the way.
    cx, cy = TABLE_CENTRE_XY_MM
    sx, sy = TABLE_HALF_SIZE_XY_MM
    assert abs(target.x - cx) <= sx  # over the table
    assert abs(target.y - cy) <= sy
    with _sim() as sim, tmmaster.Robot(sim.url) as robot:
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(target.offset(dz=100), speed=100)
        robot.move_to(target, speed=100, motion="line")
        assert sim.tcp_pose().z == pytest.approx(target.z, abs=0.01)
        assert not robot.status().error
