"""Units guarded: a pose has all six values, and metres or radians are caught.

The rule (``suspect_units``): a position within 2 mm of the base origin on every axis
looks like metres; three angles within 2 pi, one of them within 0.005 of a multiple of
pi/4, look like radians. The library warns (``UnitsWarning``), the pick & place files
refuse (exit 2) unless they say ``check_units = false``; every message quotes the key
and the values as the user wrote them.
"""

from __future__ import annotations

import contextlib
import warnings
from pathlib import Path

import pytest

import tmmaster
from tmmaster import ConfigError, Pose, Robot, UnitsWarning
from tmmaster._pose import suspect_units
from tmmaster.pickplace import (
    load_config,
    load_sequence,
    pick_and_place,
    robot_from_config,
    validate_plan,
)
from tmmaster.pickplace.__main__ import EXIT_CONFIG, EXIT_OK, main

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


# -- the rule -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "values",
    [
        (300, -200, 100, 180, 0, 90),
        (300, -200, 100, 0, 0, 0),  # tool up
        (300, -200, 100, 1.5, 0, 0),  # 1.5 degrees
        (300, -200, 100, 0.5, -1.2, 0.3),
        (300, -200, 100, 3, 0, 6),  # whole small degrees
        (300, -200, 100, 0.8, 0, 0),
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


# -- the library warns ----------------------------------------------------------------------


def test_a_target_in_radians_warns_at_the_callers_line() -> None:
    robot = Robot("127.0.0.1", profile="article", gripper=None)
    try:
        with pytest.warns(UnitsWarning) as caught, contextlib.suppress(ConfigError):
            robot.check_move(Pose(300, -200, 200, 3.14159, 0, 1.5708), 30)
        assert len(caught) == 1
        assert str(caught[0].message) == (
            "target [300, -200, 200, 3.14159, 0, 1.5708]: rx, ry, rz = 3.14159, 0, 1.5708"
            " look like radians: orientations are in degrees (3.14159 rad is 180 deg)"
        )
        assert caught[0].filename == __file__  # this test's line, not tmmaster's
    finally:
        robot.close()


def test_a_target_in_metres_warns_and_its_refusal_says_why() -> None:
    robot = Robot("127.0.0.1", profile="article", gripper=None)
    try:
        with pytest.warns(UnitsWarning), pytest.raises(ConfigError) as info:
            robot.check_move(Pose(0.3, -0.2, 0.1, 180, 0, 90), 30)
        assert "x, y, z = 0.3, -0.2, 0.1 look like metres" in str(info.value)
    finally:
        robot.close()


def test_check_units_false_takes_the_values_as_given() -> None:
    robot = Robot("127.0.0.1", profile="article", gripper=None, check_units=False)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            # Taken as degrees: the tool points up, the wrist into the table (or out of
            # reach): refused, and without a word about units.
            with contextlib.suppress(ConfigError):
                robot.check_move(Pose(300, -200, 200, 3.14159, 0, 1.5708), 30)
            with pytest.raises(ConfigError) as info:
                robot.check_move(Pose(0.3, -0.2, 0.1, 180, 0, 90), 30)
        assert "metres" not in str(info.value)
    finally:
        robot.close()


def test_a_tool_in_metres_warns_when_the_robot_is_made() -> None:
    with pytest.warns(UnitsWarning, match=r"^tool \[0, 0, 0.15, 0, 0, 0\]: .* look like metres"):
        robot = Robot("127.0.0.1", profile="article", gripper=None, tool=Pose(0, 0, 0.15, 0, 0, 0))
    robot.close()


def test_usual_targets_do_not_warn() -> None:
    robot = Robot("127.0.0.1", profile="article", gripper=None, tool=Pose(0, 0, 150, 0, 0, 0))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            robot.check_move(Pose(300, -200, 200, 180, 0, 90), 30)
    finally:
        robot.close()


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


def test_check_units_false_accepts_them_and_the_robot_does_not_warn(tmp_path: Path) -> None:
    path = _config(
        tmp_path, "[poses]\ncheck_units = false\npick = [300, -200, 100, 3.14159, 0, 1.5708]\n"
    )
    config = load_config(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        robot = robot_from_config(config, "127.0.0.1")
        with contextlib.suppress(ConfigError):
            robot.check_move(config.poses.resolved()["pick"], 10)
        robot.close()


def test_five_values_are_refused_naming_the_one_missing(tmp_path: Path) -> None:
    path = _config(tmp_path, "[poses]\nplace = [300, 200, 200, 180, 0]\n")
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert str(info.value) == (
        f"{path}: poses.place: [300, 200, 200, 180, 0] has 5 values; a pose needs all 6:"
        " x, y, z (mm), rx, ry, rz (degrees) (rz missing)"
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
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nor does the robot warn: the file said so
        assert main(["--config", str(path), "--dry-run"]) == EXIT_OK
    assert "3.14159" in capsys.readouterr().out  # the plan shows the pose as given


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
    path.write_text(
        SEQUENCE.format(
            extra="check_units = false", pose=good, inline="[300, 0, 100, 3.1416, 0, 0]"
        )
    )
    assert load_sequence(path).name == "s"


def test_the_warning_class_is_public() -> None:
    assert issubclass(tmmaster.UnitsWarning, UserWarning)


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
