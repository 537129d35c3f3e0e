"""Units guarded: a pose has six numbers, and metres or radians are refused.

The rules (``suspect_units``, docs/robot-api.md "Units"): a position within 2 mm of the
base origin on every axis looks like metres; three angles within 2 pi, one of them
within 0.005 of a multiple of pi/4, look like radians; three angles within 2 pi that,
read as radians, point the tool within 45 degrees of straight down look like radians.
The library refuses such a target or tool (``UnitsError``, a ConfigError, before
anything is sent) unless ``Robot(checks=Checks(units=False))``; the pick & place files refuse
(exit 2) unless they say ``check_units = false``; every message quotes the values as
the user wrote them, on one line.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

import tmmaster
from sim_speeds import QUICK
from tmmaster import Checks, ConfigError, Pose, Robot, UnitsError, Workspace
from tmmaster._pose import suspect_units, written
from tmmaster.pickplace import (
    load_config,
    load_sequence,
    pick_and_place,
    robot_from_config,
    validate_plan,
)
from tmmaster.pickplace.__main__ import EXIT_CONFIG, main
from tmmaster.sim import Simulator

# -- all six values ---------------------------------------------------------------------


def test_a_pose_without_rz_is_refused_naming_it() -> None:
    with pytest.raises(ConfigError) as info:
        Pose(300, -200, 200, 180, 0)  # type: ignore[call-arg]
    assert str(info.value) == (
        "invalid pose: rz missing in Pose(300, -200, 200, 180, 0); a pose needs all 6:"
        " x, y, z (mm), rx, ry, rz (degrees)"
    )
    with pytest.raises(ConfigError, match=r"rx, ry, rz missing in Pose\(300, 0, 100\)"):
        Pose(300, 0, 100)  # type: ignore[call-arg]
    with pytest.raises(ConfigError, match=r"7 values in Pose\(1, 2, 3, 4, 5, 6, 7\)"):
        Pose(1, 2, 3, 4, 5, 6, 7)  # type: ignore[call-arg]


def test_from_sequence_names_the_values_missing() -> None:
    with pytest.raises(ConfigError) as info:
        Pose.from_sequence([300, -200, 200, 180, 0])
    assert str(info.value) == (
        "[300, -200, 200, 180, 0] has 5 values; a pose needs all 6: x, y, z (mm),"
        " rx, ry, rz (degrees) (rz missing)"
    )
    assert isinstance(info.value, ValueError)  # as before


# -- the rules ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "values",
    [
        (300, -200, 100, 180, 0, 90),
        (300, -200, 100, 0, 0, 0),  # tool up
        (300, -200, 100, 1.5, 0, 0),  # 1.5 degrees
        (300, -200, 100, 0.5, -1.2, 0.3),
        (300, -200, 100, 0.8, 0, 0),
        (300, -200, 100, 0, 0, 3.1),  # rz alone: up either way
        (300, -200, 100, 2.3, 0, 0),  # as radians 132 deg from up: not within 45 of down
        (300, -200, 100, 3.1, 0, 7),  # rz beyond 2 pi: degrees
        (300, -200, 100, -179, 1, 90),
        (0, 0, 0, 0, 0, 0),  # a tool with no offset
        (0, 0, 150, 0, 0, 0),
        (2, 0, 0, 0, 0, 0),
    ],
)
def test_degrees_and_millimetres_are_not_suspected(values: tuple[float, ...]) -> None:
    assert suspect_units(values) is None


@pytest.mark.parametrize(
    ("values", "says"),
    [
        ((0.3, -0.2, 0.1, 180, 0, 90), "x, y, z = 0.3, -0.2, 0.1 look like metres"),
        ((0, 0, 0.15, 0, 0, 0), "(0.15 m is 150 mm)"),
        ((300, -200, 100, 3.14159, 0, 1.5708), "rx, ry, rz = 3.14159, 0, 1.5708 look like radians"),
        ((300, -200, 100, 3.14, 0, 0), "(3.14 rad is 180 deg)"),
        ((300, -200, 100, 0, 0, -1.5708), "(-1.5708 rad is -90 deg)"),
        ((300, -200, 100, 0, 0.785, 0), "look like radians"),
        ((300, -200, 100, 6.2832, 0, 0), "look like radians"),
    ],
)
def test_metres_and_radians_are_suspected(values: tuple[float, ...], says: str) -> None:
    problem = suspect_units(values)
    assert problem is not None
    assert says in problem


@pytest.mark.parametrize(
    ("values", "down", "up"),
    [
        ((300, -200, 100, 3.1, 0, 1.6), 2, 3),  # radians, rounded: no quarter turn
        ((300, -200, 100, -3.1, 0.05, -1.6), 4, 3),
        ((300, -200, 100, 2.4, 0, 0), 42, 2),  # just within 45 deg of straight down
        ((300, -200, 100, 2.5, 0.3, 1.2), 40, 3),
        ((300, -200, 100, 0, 3, 0), 8, 3),
        ((300, -200, 100, 3, 0, 6), 8, 3),  # or 3 and 6 degrees: the tool 3 deg from up
    ],
)
def test_a_tool_down_pose_in_radians_is_suspected(
    values: tuple[float, ...], down: int, up: int
) -> None:
    rx, ry, rz = (written(v) for v in values[3:])
    assert suspect_units(values) == (
        f"rx, ry, rz = {rx}, {ry}, {rz} look like radians: orientations are in degrees"
        f" (read as radians the tool points {down} deg from straight down, read as degrees"
        f" {up} deg from straight up)"
    )


# -- the library refuses ----------------------------------------------------------------------

RADIANS = Pose(300, -200, 200, 3.14159, 0, 1.5708)
ROUNDED_RADIANS = Pose(300, -200, 200, 3.1, 0, 1.6)


@pytest.fixture
def as_a_program_runs() -> Iterator[None]:
    """Python's default warning filters, not the suite's "error": a warning stops nothing."""
    with warnings.catch_warnings():
        warnings.simplefilter("default")
        yield


@pytest.mark.usefixtures("as_a_program_runs")
def test_a_target_in_radians_is_refused_naming_the_values_and_the_rule() -> None:
    robot = Robot("127.0.0.1", profile="article", gripper=None)
    try:
        with pytest.raises(UnitsError) as info:  # refused, not warned
            robot.check_move(RADIANS, 30)
        assert str(info.value) == (
            "target [300, -200, 200, 3.14159, 0, 1.5708]: rx, ry, rz = 3.14159, 0, 1.5708"
            " look like radians: orientations are in degrees (3.14159 rad is 180 deg); if"
            " these really are mm and degrees, make the robot with"
            " Robot(checks=Checks(units=False))"
        )
        assert isinstance(info.value, ConfigError)
        with pytest.raises(UnitsError, match=r"^target \[300, -200, 200, 3\.1, 0, 1\.6\]: "):
            robot.validate_move(ROUNDED_RADIANS, 30)
    finally:
        robot.close()


@pytest.mark.usefixtures("as_a_program_runs")
def test_a_target_in_metres_is_refused_as_metres() -> None:
    robot = Robot("127.0.0.1", profile="article", gripper=None)
    try:
        with pytest.raises(UnitsError) as info:
            robot.check_move(Pose(0.3, -0.2, 0.1, 180, 0, 90), 30)
        assert str(info.value).startswith(
            "target [0.3, -0.2, 0.1, 180, 0, 90]: x, y, z = 0.3, -0.2, 0.1 look like metres"
        )
        assert "table" not in str(info.value)  # the units, before the workspace
    finally:
        robot.close()


@pytest.mark.usefixtures("as_a_program_runs")
@pytest.mark.parametrize("target", [RADIANS, ROUNDED_RADIANS], ids=["exact", "rounded"])
def test_a_move_in_radians_sends_nothing(
    memory_simulator_factory: Callable[..., Simulator], target: Pose
) -> None:
    sim = memory_simulator_factory("tmflow", **QUICK)
    # No table plane in the master's workspace: only the units stand between the target
    # and the robot (taken as degrees, the wrist would go into the simulated table).
    free = Workspace(floor_z_mm=None)
    with Robot(sim.url, profile="tmflow", gripper=None, checks=Checks(workspace=free)) as robot:
        sim.clear_request_log()
        with pytest.raises(UnitsError, match="look like radians"):
            robot.move_to(target, speed=30)
        assert [r for r in sim.request_log if r.is_write] == []
        assert robot.status().error_code == 0  # the arm did not hit the table


@pytest.mark.usefixtures("as_a_program_runs")
def test_check_units_false_takes_the_values_as_given() -> None:
    # Taken as degrees, (3.1, 0, 1.6) points the tool 3 deg from straight up: a pose the
    # arm can take where no table is in the way (high enough for the wrist to clear the
    # arm's own links).
    upward = Pose(300, 200, 500, 3.1, 0, 1.6)
    free = Workspace(floor_z_mm=None)
    robot = Robot("127.0.0.1", profile="tmflow", gripper=None, checks=Checks(workspace=free))
    lax = Robot(
        "127.0.0.1",
        profile="tmflow",
        gripper=None,
        checks=Checks(workspace=free, units=False),
    )
    try:
        with pytest.raises(UnitsError):
            robot.check_move(ROUNDED_RADIANS, 30)
        lax.check_move(upward, 30)
        with pytest.raises(ConfigError) as info:  # out of reach taken as mm: said as such
            lax.check_move(Pose(0.3, -0.2, 0.1, 180, 0, 90), 30)
        assert not isinstance(info.value, UnitsError)
        assert "metres" not in str(info.value)
    finally:
        robot.close()
        lax.close()


@pytest.mark.usefixtures("as_a_program_runs")
def test_a_tool_in_metres_is_refused_when_the_robot_is_made() -> None:
    with pytest.raises(UnitsError, match=r"^tool \[0, 0, 0.15, 0, 0, 0\]: .* look like metres"):
        Robot("127.0.0.1", profile="article", gripper=None, tool=Pose(0, 0, 0.15, 0, 0, 0))
    robot = Robot(
        "127.0.0.1",
        profile="article",
        gripper=None,
        tool=Pose(0, 0, 0.15, 0, 0, 0),
        checks=Checks(units=False),
    )
    robot.close()


def test_usual_targets_are_taken() -> None:
    robot = Robot("127.0.0.1", profile="article", gripper=None, tool=Pose(0, 0, 150, 0, 0, 0))
    try:
        robot.check_move(Pose(300, -200, 200, 180, 0, 90), 30)
    finally:
        robot.close()


def test_the_error_class_is_public_and_no_warning() -> None:
    assert issubclass(tmmaster.UnitsError, ConfigError)
    assert not issubclass(tmmaster.UnitsError, Warning)
    assert "UnitsError" in tmmaster.__all__
    assert not hasattr(tmmaster, "UnitsWarning")


# -- a coordinate is a number ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("values", "says"),
    [
        (("300", -200, 200, 180, 0, 90), "invalid pose: x must be an int or float, got '300'"),
        ((300, -200, 200, 180, True, 90), "invalid pose: ry must be an int or float, got True"),
        ((300, -200, 200, 180, 0, None), "invalid pose: rz must be an int or float, got None"),
    ],
)
def test_a_coordinate_that_is_not_a_number_is_refused_naming_it(
    values: tuple[object, ...], says: str
) -> None:
    with pytest.raises(ConfigError) as info:
        Pose(*values)  # type: ignore[arg-type]
    assert str(info.value) == says
    with pytest.raises(ConfigError, match="x must be an int or float, got '300'"):
        Pose.from_sequence(["300", -200, 200, 180, 0, 90])  # type: ignore[list-item]


def test_a_pose_from_text_or_a_file_is_still_numbers(tmp_path: Path) -> None:
    assert Pose.parse("300,-200,200,180,0,90") == Pose(300.0, -200.0, 200.0, 180.0, 0.0, 90.0)
    pose = Pose(300, -200, 200, 180, 0, 90)  # ints are numbers
    assert pose.as_list() == [300.0, -200.0, 200.0, 180.0, 0.0, 90.0]
    assert all(type(value) is float for value in pose)
    config = load_config(_config(tmp_path, "[poses]\npick = [300, -200, 100, 180, 0, 90]\n"))
    assert config.poses.resolved()["pick"] == Pose(300, -200, 100, 180, 0, 90)


# -- the pick & place files refuse ------------------------------------------------------------


def _config(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "cell.toml"
    path.write_text(text)
    return path


def test_a_pose_in_metres_is_refused_quoting_the_key_and_values(tmp_path: Path) -> None:
    path = _config(tmp_path, "[poses]\npick = [0.3, -0.2, 0.1, 180, 0, 90]\n")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(info.value) == (
        f"{path}: poses.pick: [0.3, -0.2, 0.1, 180, 0, 90]: x, y, z = 0.3, -0.2, 0.1 look"
        " like metres: positions are in mm (0.3 m is 300 mm); if these really are mm and"
        " degrees, set [poses] check_units = false"
    )


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("[poses]\npick = [300, -200, 100, 3.14159, 0, 1.5708]\n", "poses.pick"),
        ("[poses]\nhome = [250, 0, 300, 3.1416, 0, 1.5708]\n", "poses.home"),
        ("[robot]\ntool = [0, 0, 0.15, 0, 0, 0]\n", "robot.tool"),
        ('[on_error]\nreaction = "retreat"\npose = [0.25, 0, 0.3, 180, 0, 90]\n', "on_error.pose"),
    ],
)
def test_every_pose_of_the_config_is_checked(tmp_path: Path, text: str, key: str) -> None:
    with pytest.raises(ConfigError, match=rf": {key}: \["):
        load_config(_config(tmp_path, text))


def test_check_units_false_accepts_them_and_the_robot_does_not_refuse(tmp_path: Path) -> None:
    path = _config(
        tmp_path, "[poses]\ncheck_units = false\npick = [300, -200, 100, 3.14159, 0, 1.5708]\n"
    )
    config = load_config(path)
    robot = robot_from_config(config, "127.0.0.1")
    try:
        # Taken as degrees: the wrist into the table, refused as such, not for its units.
        with pytest.raises(ConfigError) as info:
            robot.check_move(config.poses.resolved()["pick"], 10)
        assert not isinstance(info.value, UnitsError)
    finally:
        robot.close()


def test_five_values_are_refused_naming_the_one_missing(tmp_path: Path) -> None:
    path = _config(tmp_path, "[poses]\nplace = [300, 200, 200, 180, 0]\n")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(info.value) == (
        f"{path}: poses.place: [300, 200, 200, 180, 0] has 5 values; a pose needs all 6:"
        " x, y, z (mm), rx, ry, rz (degrees) (rz missing)"
    )


def test_the_command_refuses_rounded_radians_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _config(tmp_path, "[poses]\npick = [300, -200, 100, 3.1, 0, 1.6]\n")
    assert main(["--config", str(path), "--dry-run"]) == EXIT_CONFIG
    err = capsys.readouterr().err
    assert err == (
        f"pickplace: config error: {path}: poses.pick: [300, -200, 100, 3.1, 0, 1.6]: rx, ry,"
        " rz = 3.1, 0, 1.6 look like radians: orientations are in degrees (read as radians the"
        " tool points 2 deg from straight down, read as degrees 3 deg from straight up); if"
        " these really are mm and degrees, set [poses] check_units = false [exit 2]\n"
    )


def test_the_command_refuses_metres_quoting_what_was_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _config(tmp_path, "[poses]\npick = [0.3, -0.2, 0.1, 180, 0, 90]\n")
    assert main(["--config", str(path), "--dry-run"]) == EXIT_CONFIG
    err = capsys.readouterr().err
    assert "poses.pick: [0.3, -0.2, 0.1, 180, 0, 90]: x, y, z" in err
    assert "poses.approach" not in err  # a pose derived from it, never written


def test_the_command_runs_radian_like_values_when_told_to(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _config(
        tmp_path,
        # Taken as degrees the tool points up, the wrist below it: no table in this cell.
        "[poses]\ncheck_units = false\npick = [300, -200, 100, 3.14159, 0, 1.5708]\n"
        "[workspace]\nfloor_z_mm = -2000\n",
    )
    # Not refused for its units: the plan takes the pose as given, as degrees, and the
    # arm model judges it (a tool pointing up in a pick and place puts the wrist into
    # the arm's own links: refused for that, naming the pose).
    assert main(["--config", str(path), "--dry-run"]) == EXIT_CONFIG
    err = capsys.readouterr().err
    assert "radians" not in err
    assert "self-collision" in err
    assert "poses.pick" in err


SEQUENCE = """name = "s"
{extra}
[poses]
p = {pose}
[[steps]]
do = "move"
pose = "p"
speed = 30
[[steps]]
do = "move"
pose = {inline}
speed = 30
"""


def test_a_sequence_files_poses_are_checked(tmp_path: Path) -> None:
    path = tmp_path / "s.toml"
    good, metres = "[300, -200, 100, 180, 0, 90]", "[0.3, -0.2, 0.1, 180, 0, 90]"
    path.write_text(SEQUENCE.format(extra="", pose=metres, inline=good))
    with pytest.raises(ConfigError, match=r"s\.toml: poses\.p: \[0\.3, -0\.2, 0\.1, 180, 0, 90\]"):
        load_sequence(path)
    path.write_text(SEQUENCE.format(extra="", pose=good, inline="[300, 0, 100, 3.1416, 0, 0]"))
    with pytest.raises(ConfigError, match=r"steps\.1\.pose: .* look like radians"):
        load_sequence(path)
    path.write_text(SEQUENCE.format(extra="", pose=good, inline="[300, 0, 100, 3.1, 0, 1.6]"))
    with pytest.raises(ConfigError, match=r"steps\.1\.pose: .* 2 deg from straight down") as info:
        load_sequence(path)
    assert "\n" not in str(info.value)
    path.write_text(
        SEQUENCE.format(
            extra="check_units = false", pose=good, inline="[300, 0, 100, 3.1416, 0, 0]"
        )
    )
    assert load_sequence(path).name == "s"


def test_a_derived_pose_is_named_by_what_was_written(tmp_path: Path) -> None:
    # Taken as mm on request: the approach derived from it is out of reach, and the
    # error names the keys the user wrote, not a poses.approach they never did.
    path = _config(tmp_path, "[poses]\ncheck_units = false\npick = [0.3, -0.2, 0.1, 180, 0, 90]\n")
    config = load_config(path)
    robot = robot_from_config(config, "127.0.0.1")
    try:
        with pytest.raises(
            ConfigError, match=r"^x: poses\.pick \+ approach_z_offset \(MOVE_TO_APP"
        ):
            validate_plan(robot, pick_and_place(config), 1, source="x")
    finally:
        robot.close()
