"""Hostile files and numbers end in one clean line: scenes, configs, profiles, run reports.

Each hostile file is written here, in tmp_path: arrays nested 100,000 deep (Python's
parsers recurse), keys of thousands of dotted parts (Python's TOML parser is quadratic
in them), rich markup and ANSI escapes as names, millions of cycle times, integers
too large for a float.
"""

from __future__ import annotations

import gc
import io
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tmmaster import ConfigError, PollPolicy, Pose, RegisterMapError, Robot, load_profile
from tmmaster._toml import MAX_KEY_PARTS, MAX_TOML_BYTES
from tmmaster.pickplace import load_config, load_report
from tmmaster.pickplace.__main__ import EXIT_CONFIG
from tmmaster.pickplace.__main__ import main as pickplace_main
from tmmaster.pickplace._report import RunReport
from tmmaster.report.__main__ import main as report_main
from tmmaster.sim import load_scene
from tmmaster.sim.__main__ import main as sim_main

DEEP = 100_000
DEEP_ARRAY = "a = " + "[" * DEEP + "]" * DEEP + "\n"
DEEP_INLINE_TABLE = "a = " + "{b = " * DEEP + "1" + "}" * DEEP + "\n"
LONG_KEY = ".".join(["k"] * 5_000) + " = 1\n"


@pytest.fixture(autouse=True)
def no_collection_inside_a_parser() -> Iterator[None]:
    """No automatic collection runs during these tests: one that ran deep inside a
    parser's recursion would finalize what earlier tests of the worker left there, where
    the hook reporting a finalizer's exception hits the recursion limit and prints a
    traceback into the output these tests read (seen once in a full run). Collected after
    the test instead, at a shallow depth (no_leaks collects; Python's thresholds do)."""
    gc.disable()
    try:
        yield
    finally:
        gc.enable()


def _one_line_error(err: str, *needles: str) -> None:
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    for needle in needles:
        assert needle in err


# --- TOML: scenes, pick & place configs, profiles ---------------------------------


@pytest.mark.parametrize(
    ("text", "why"),
    [
        (DEEP_ARRAY, "nested too deeply"),
        (DEEP_INLINE_TABLE, "nested too deeply"),
        (LONG_KEY, f"more than {MAX_KEY_PARTS} dotted parts"),
        ("[" + ".".join(["k"] * 5_000) + "]\n", f"more than {MAX_KEY_PARTS} dotted parts"),
    ],
    ids=["deep-array", "deep-inline-table", "long-dotted-key", "long-table-header"],
)
def test_a_hostile_scene_is_a_config_error_naming_the_file(
    tmp_path: Path, text: str, why: str
) -> None:
    scene = tmp_path / "cell.toml"
    scene.write_text(text)
    with pytest.raises(ConfigError, match=why) as caught:
        load_scene(scene)
    assert str(scene) in str(caught.value)


def test_the_simulator_cli_refuses_a_deeply_nested_scene_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scene = tmp_path / "cell.toml"
    scene.write_text(DEEP_ARRAY)
    assert sim_main(["--scene", str(scene), "--port", "0"]) == 2
    _one_line_error(capsys.readouterr().err, str(scene), "nested too deeply")


def test_pickplace_refuses_a_deeply_nested_scene_and_config_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    hostile = tmp_path / "hostile.toml"
    hostile.write_text(DEEP_ARRAY)
    assert pickplace_main(["--sim", "--sim-scene", str(hostile)]) == EXIT_CONFIG
    _one_line_error(capsys.readouterr().err, str(hostile), "nested too deeply")
    assert pickplace_main(["--config", str(hostile)]) == EXIT_CONFIG
    _one_line_error(capsys.readouterr().err, str(hostile), "nested too deeply")


def test_a_hostile_config_or_profile_file_is_a_config_error(tmp_path: Path) -> None:
    config = tmp_path / "config.toml"
    config.write_text(DEEP_INLINE_TABLE)
    with pytest.raises(ConfigError, match="nested too deeply"):
        load_config(config)
    profile = tmp_path / "robot.toml"
    profile.write_text(LONG_KEY)
    with pytest.raises(RegisterMapError, match="dotted parts") as caught:
        load_profile(profile)
    assert str(profile) in str(caught.value)
    # What real files hold still reads: a dotted string, a dotted key of a few parts.
    config.write_text('[robot]\nhost = "192.168.10.2"\n')
    assert load_config(config).robot.host == "192.168.10.2"


def test_a_toml_file_over_the_limit_is_refused_before_parsing(tmp_path: Path) -> None:
    scene = tmp_path / "huge.toml"
    # Valid TOML (one long comment): only its size is wrong.
    scene.write_text("#" + "x" * MAX_TOML_BYTES + "\n")
    with pytest.raises(ConfigError, match="larger than 1 MiB"):
        load_scene(scene)


# --- run reports: tmmaster report show ---------------------------------------------


def _report(tmp_path: Path, **fields: Any) -> Path:
    data = {"tmmaster_version": "1.0", "result": "done", "exit_code": 0, **fields}
    path = tmp_path / "run.json"
    path.write_text(json.dumps(data))
    return path


def _show(path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = report_main(["show", str(path)])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("where", ["top", "inside-a-key"])
def test_report_show_refuses_deep_nesting_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], where: str
) -> None:
    deep = "[" * DEEP + "]" * DEEP
    path = tmp_path / "run.json"
    path.write_text(deep if where == "top" else '{"result": "done", "x": ' + deep + "}")
    code, out, err = _show(path, capsys)
    assert code == 2
    assert out == ""
    _one_line_error(err, str(path), "nested too deeply")


def test_report_show_refuses_an_integer_python_cannot_read(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "run.json"
    path.write_text('{"result": "done", "exit_code": ' + "9" * 5000 + "}")
    code, _, err = _show(path, capsys)
    assert code == 2
    _one_line_error(err, str(path), "more than 4300 digits")


def test_report_show_prints_markup_in_names_as_text(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    timing = {"count": 1, "total_s": 1.0, "mean_s": 1.0, "max_s": 1.0}
    path = _report(
        tmp_path, states={"[/]": timing, "[bold red]x": timing}, sequence="[link=x]seq[/link]"
    )
    code, out, err = _show(path, capsys)
    assert (code, err) == (0, "")
    assert "[/]" in out
    assert "[bold red]x" in out
    assert "[link=x]seq[/link]" in out


def test_report_show_escapes_control_characters_from_the_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    timing = {"count": 1, "total_s": 1.0, "mean_s": 1.0, "max_s": 1.0}
    path = _report(
        tmp_path,
        result="failed\x1b[2J",
        reason="\x1b[31mred\x1b[0m\x1b]0;title\x07 \u202eevil",
        sequence="\x1b[2J",
        states={"GRASP\x1b[1A": timing},
    )
    code, out, _ = _show(path, capsys)
    assert code == 0
    assert "\x1b" not in out
    assert "\x07" not in out
    assert "\u202e" not in out
    assert "\\x1b[31mred" in out  # shown, escaped
    assert "GRASP\\x1b[1A" in out


def test_a_validation_error_quotes_the_files_keys_escaped(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _report(tmp_path, states={"\x1b[2J": 5})
    code, _, err = _show(path, capsys)
    assert code == 2
    assert "\x1b" not in err
    _one_line_error(err, "\\x1b[2J")


def _report_of(fields: dict[str, Any]) -> RunReport:
    return RunReport.model_validate(
        {"tmmaster_version": "1.0", "result": "done", "exit_code": 0, **fields}
    )


def _rendered(report: RunReport) -> str:
    # rich loads here, as in the command (only a terminal's summary shows it): not in
    # every test process that collects this module.
    from rich.console import Console

    from tmmaster.pickplace._summary import summary_renderable

    buffer = io.StringIO()
    Console(file=buffer, width=100).print(summary_renderable(report))
    return buffer.getvalue()


def test_the_summary_of_many_cycles_lists_a_bounded_number_of_times() -> None:
    # 200,000 cycle times: the summary lists the first and the last, not every one, so
    # what is rendered does not grow with the run (rich wraps a long line in time
    # quadratic in its length: 2,000,000 times took 40 s).
    from tmmaster.pickplace._summary import MAX_LISTED_TIMES

    times = [float(i % 7) for i in range(200_000)]
    report = _report_of({"cycles": {"completed": len(times), "times_s": times}})
    text = _rendered(report)
    assert len(text) < 2_000
    assert f"{len(times) - MAX_LISTED_TIMES} more" in text
    assert "mean 3.00, max 6.00" in text
    # A few are all listed.
    few = _report_of({"cycles": {"completed": 3, "times_s": [4.75, 4.25, 4.35]}})
    assert "cycle times (s): 4.75, 4.25, 4.35  (mean 4.45, max 4.75)" in _rendered(few)


def test_the_summary_lists_a_bounded_number_of_states() -> None:
    from tmmaster.pickplace._summary import MAX_STATE_ROWS

    timing = {"count": 1, "total_s": 1.0, "mean_s": 1.0, "max_s": 1.0}
    report = RunReport.model_validate(
        {
            "tmmaster_version": "1.0",
            "result": "done",
            "exit_code": 0,
            "states": {f"S{i}": timing for i in range(5_000)},
        }
    )
    text = _rendered(report)
    assert f"S{MAX_STATE_ROWS - 1} " in text
    assert f"S{MAX_STATE_ROWS} " not in text
    assert f"{5_000 - MAX_STATE_ROWS} more states" in text


def test_a_long_reason_is_cut_short() -> None:
    report = RunReport.model_validate(
        {"tmmaster_version": "1.0", "result": "failed", "exit_code": 1, "reason": "x" * 100_000}
    )
    assert len(_rendered(report)) < 2_000


def test_load_report_refuses_deep_nesting(tmp_path: Path) -> None:
    path = tmp_path / "run.json"
    path.write_text("{" + '"a": {' * DEEP + "}" * DEEP + "}")
    with pytest.raises(ConfigError, match="nested too deeply"):
        load_report(path)


# --- numbers too large for a float ---------------------------------------------------

HUGE = 10**400
HUGER = 10**5000  # more digits than Python writes (its 4300-digit limit)


@pytest.mark.parametrize("value", [HUGE, -HUGE, HUGER], ids=["1e400", "-1e400", "1e5000"])
def test_numbers_too_large_for_a_float_are_config_errors_naming_the_field(value: int) -> None:
    with pytest.raises(ConfigError, match=r"polling\.interval_s"):
        Robot("127.0.0.1", port=5999, polling=PollPolicy(interval_s=value))
    with pytest.raises(ConfigError, match="x"):
        Pose(value, 0, 0, 180, 0, 90)
    robot = Robot("127.0.0.1", port=5999)
    try:
        with pytest.raises(ConfigError, match="J1"):
            robot.move_joints([value, 0, 90, 0, 90, 0])
        with pytest.raises(ConfigError, match="J6"):
            robot.move_joints([0, 0, 90, 0, 90, value])
        with pytest.raises(ConfigError, match="dz"):
            robot.move_by(dz=value)
        with pytest.raises(ConfigError, match="accel_time"):
            robot.move_joints([0, 0, 90, 0, 90, 0], accel_time_ms=abs(value))
        with pytest.raises(ConfigError, match="speed"):
            robot.move_joints([0, 0, 90, 0, 90, 0], speed=value)
        with pytest.raises(ConfigError, match="timeout_s"):
            robot.wait_until_ready(timeout_s=value)
    finally:
        robot.close()


def test_the_message_writes_a_huge_integer_short() -> None:
    robot = Robot("127.0.0.1", port=5999)
    try:
        with pytest.raises(ConfigError) as caught:
            robot.move_joints([HUGER, 0, 90, 0, 90, 0])
    finally:
        robot.close()
    assert "1.000e+5000" in str(caught.value)
    assert len(str(caught.value)) < 200
