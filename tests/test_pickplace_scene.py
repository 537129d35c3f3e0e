"""pickplace --sim --sim-scene: the run in a cell of the user's (table, fixtures, parts)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tmmaster.pickplace.__main__ import (
    EXIT_CONFIG,
    EXIT_OK,
    EXIT_ROBOT_FAULT,
    main,
)

EXAMPLE = Path(__file__).parent.parent / "examples" / "scene.toml"
FAST = ["--sim", "--sim-time-scale", "40", "--poll-interval", "0.02"]


def _run(tmp_path: Path, *argv: str) -> tuple[int, dict[str, object]]:
    report = tmp_path / "r.json"
    code = main([*FAST, *argv, "--report", str(report)])
    return code, json.loads(report.read_text()) if report.exists() else {}


def test_the_example_scene_runs_and_only_the_runs_parts_count(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Two parts wait at the pick pose, one lies on the shelf: one cycle places the first.
    code, report = _run(tmp_path, "--sim-scene", str(EXAMPLE))
    assert code == EXIT_OK
    sim = report["sim"]
    assert isinstance(sim, dict)
    by_name = {o["name"]: o for o in sim["objects"]}
    assert by_name["part-1"]["run_part"]
    assert by_name["part-1"]["on_place"]
    assert not by_name["part-2"]["run_part"]  # still waiting: the second cycle's
    assert by_name["on-shelf"]["resting_on"] == "shelf"
    assert sim["on_place"] is True
    out = capsys.readouterr().out
    assert "part-1 is on the place position" in out
    assert "part-2" not in out  # not the run's: said with -v only


def test_a_scene_without_parts_at_the_pick_gets_one_per_cycle(tmp_path: Path) -> None:
    scene = tmp_path / "cell.toml"
    scene.write_text("[table]\ntop_z_mm = 85\n")
    code, report = _run(tmp_path, "--sim-scene", str(scene), "--cycles", "2")
    assert code == EXIT_OK
    sim = report["sim"]
    assert isinstance(sim, dict)
    assert [(o["name"], o["on_place"]) for o in sim["objects"]] == [
        ("part-1", True),
        ("part-2", True),
    ]


def test_a_fixture_the_master_knows_nothing_of_stops_the_arm(tmp_path: Path) -> None:
    # A block 245 mm high where the part is set down (at 200 mm): the master's checks pass
    # (it knows the table, not the block); the simulated arm meets the block and stops
    # with TM's collision code.
    scene = tmp_path / "cell.toml"
    scene.write_text(
        '[[fixtures]]\nname = "block"\npose = [300, 200, 165, 0, 0, 0]\nsize_mm = [80, 80, 160]\n'
    )
    code, report = _run(tmp_path, "--sim-scene", str(scene))
    assert code == EXIT_ROBOT_FAULT
    error = report["error"]
    assert isinstance(error, dict)
    assert error["error_code"] == 0x22  # Force or Torque Over Range
    assert error["state"] == "MOVE_TO_PLACE"


def test_the_scene_is_checked_before_anything_starts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = tmp_path / "cell.toml"
    scene.write_text("[table]\ntop_z_m = 85\n")  # a typo
    assert main([*FAST, "--sim-scene", str(scene)]) == EXIT_CONFIG
    err = capsys.readouterr().err
    assert "top_z_m" in err
    assert str(scene) in err
    assert main(["--host", "127.0.0.1", "--sim-scene", str(EXAMPLE)]) == EXIT_CONFIG
    assert "--sim-scene needs --sim" in capsys.readouterr().err


def test_a_scene_table_the_configuration_does_not_know_is_said(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = tmp_path / "cell.toml"
    scene.write_text("[table]\ntop_z_mm = 60\n")
    code, _ = _run(tmp_path, "--sim-scene", str(scene))
    assert code == EXIT_OK  # the plan stays above both
    err = capsys.readouterr().err
    assert "pickplace.scene_table_differs" in err
    assert "scene_table_top_z_mm=60" in err
    assert "workspace_floor_z_mm=85" in err
