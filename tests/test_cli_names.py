"""Names chosen from a set are said with the closest one; numbers out of range in our words.

Every command's parser (``tmmaster``, ``python -m tmmaster.pickplace``, ``.sim``...) says an
unknown option, sub-command or choice with a did-you-mean, and so do the names checked
after parsing (profiles, grippers, fault kinds). Nothing here connects to anything.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tmmaster import _cli
from tmmaster._cliparse import did_you_mean
from tmmaster.pickplace.__main__ import main as pickplace_main
from tmmaster.sim.__main__ import main as sim_main


def _err(capsys: pytest.CaptureFixture[str]) -> str:
    return " ".join(capsys.readouterr().err.split())


def test_did_you_mean_names_the_closest_choice_or_nothing() -> None:
    assert did_you_mean("tmfow", ["article", "tmflow"]) == "; did you mean tmflow?"
    assert did_you_mean("DEBUG", ["debug", "info"]) == "; did you mean debug?"
    assert did_you_mean("zzz", ["article", "tmflow"]) == ""


def test_the_usage_line_names_every_command() -> None:
    usage = _cli.build_parser().format_usage()
    for command in ("sim", "pickplace", "report", "tmscript", "profile", "schema"):
        assert command in usage


def test_tmmaster_alone_prints_its_usage_and_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert _cli.main([]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.startswith("usage: tmmaster")
    assert err.splitlines()[-1] == "tmmaster: give a command [exit 2]"


@pytest.mark.parametrize(
    "argv",
    [
        ["--log-level", "debug", "profile", "list"],
        ["--log-level", "DEBUG", "profile", "list"],
        ["profile", "list", "--log-level", "Warning"],
    ],
    ids=" ".join,
)
def test_log_level_before_the_command_and_in_any_case(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert _cli.main(argv) == 0
    assert "tmflow" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "line"),
    [
        (["--port", "70000", "--host", "127.0.0.1"], "--port 70000: must be 1..65535"),
        (["--cycles", "0", "--sim"], "--cycles 0: must be 1..1000000"),
        (["--cycles", "1000001", "--dry-run"], "--cycles 1000001: must be 1..1000000"),
        (["--poll-interval", "nan", "--dry-run"], "--poll-interval nan: must be 0.005..5"),
    ],
)
def test_numbers_out_of_range_are_said_as_the_option(
    argv: list[str], line: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert pickplace_main(argv) == 2
    assert _err(capsys) == f"pickplace: {line} [exit 2]"


@pytest.mark.parametrize(
    ("argv", "hint"),
    [
        (
            ["pickplace", "--cycle", "2", "--dry-run"],
            "unrecognized arguments: --cycle 2; did you mean --cycles?",
        ),
        (["pickplce", "--dry-run"], "did you mean pickplace?"),
        (["profile", "show", "tmfow"], "no such profile"),
        (["profile", "show", "tmfow"], "did you mean tmflow?"),
        (["profile", "sho", "tmflow"], "did you mean show?"),
        (["pickplace", "--sim", "--sim-physics", "mujco"], "did you mean mujoco?"),
        (["pickplace", "--profile", "tmfow", "--dry-run"], "did you mean tmflow?"),
        (["sim", "--physics", "kinematc"], "did you mean kinematic?"),
        (["sim", "--gripper", "onrobot"], "the gripper profiles are blog-2fg7, onrobot-2fg7"),
        (["sim", "--gripper", "onrobot"], "did you mean onrobot-2fg7?"),
        (["sim", "--profile", "tmflo"], "did you mean tmflow?"),
        (["sim", "--fault", "robot_eror"], "did you mean robot_error?"),
        (["sim", "--gripper-prot", "0"], "did you mean --gripper-port?"),
        (
            ["robot-program", "--version"],
            "--version is tmmaster's own: give it before the sub-command",
        ),
        (["profile", "list", "--version"], "--version is tmmaster's own"),
    ],
    ids=lambda v: " ".join(v) if isinstance(v, list) else "",
)
def test_a_name_from_a_set_is_said_with_the_closest(
    argv: list[str], hint: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _cli.main(argv) == 2
    err = _err(capsys)
    assert hint in err
    assert err.endswith("[exit 2]")
    assert "Traceback" not in err


def test_the_same_hint_from_the_module_entry(capsys: pytest.CaptureFixture[str]) -> None:
    assert pickplace_main(["--cycle", "2", "--dry-run"]) == 2
    assert "did you mean --cycles?" in _err(capsys)


def test_a_bad_program_file_is_named_with_line_and_column(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    program = tmp_path / "bad.tms"
    program.write_text("x = = 1\n", encoding="utf-8")
    assert sim_main(["--port", "0", "--program", str(program)]) == 2
    assert _err(capsys) == f"sim: {program}:1:1: unexpected 'x' [exit 2]"
