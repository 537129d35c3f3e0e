"""The public surface: a complete, sorted __all__, and generated docs that match the code."""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable
from pathlib import Path

import pytest

import tmmaster
import tmmaster.aio
import tmmaster.pickplace
import tmmaster.report
import tmmaster.sim
from tmmaster import PollPolicy
from tmmaster._cli import main

ROOT = Path(__file__).resolve().parents[1]


def _isort_key(name: str) -> tuple[int, str]:
    # ruff's RUF022 order: CONSTANTS, then Classes, then everything else.
    if name.isupper():
        return (0, name)
    if name[0].isupper():
        return (1, name)
    return (2, name)


@pytest.mark.parametrize(
    "module", [tmmaster, tmmaster.aio, tmmaster.sim, tmmaster.pickplace, tmmaster.report]
)
def test_all_is_sorted_and_complete(module: object) -> None:
    exported = list(module.__all__)  # type: ignore[attr-defined]
    assert exported == sorted(exported, key=_isort_key), "keep __all__ sorted (ruff RUF022)"
    public = {
        name
        for name, value in vars(module).items()
        if not name.startswith("_") and not inspect.ismodule(value) and name != "annotations"
    }
    assert public - set(exported) == set(), "public names missing from __all__"
    for name in exported:
        assert hasattr(module, name), name


@pytest.mark.parametrize(
    "module", [tmmaster, tmmaster.aio, tmmaster.sim, tmmaster.pickplace, tmmaster.report]
)
def test_every_public_function_and_class_has_a_docstring(module: object) -> None:
    for name in module.__all__:  # type: ignore[attr-defined]
        value = getattr(module, name)
        if inspect.isfunction(value) or inspect.isclass(value):
            assert inspect.getdoc(value), f"{name} has no docstring"


def test_exception_root_and_builtins() -> None:
    for name in tmmaster.__all__:
        value = getattr(tmmaster, name)
        if inspect.isclass(value) and issubclass(value, Exception):
            assert issubclass(value, tmmaster.TMMasterError), name
    assert issubclass(tmmaster.MotionTimeoutError, TimeoutError)
    assert issubclass(tmmaster.ResponseTimeoutError, TimeoutError)
    assert issubclass(tmmaster.ConnectError, ConnectionError)
    assert issubclass(tmmaster.ConfigError, ValueError)


@pytest.mark.parametrize("name", tmmaster.builtin_profile_names())
def test_profile_docs_are_generated_from_the_models(name: str) -> None:
    committed = (ROOT / "docs" / "profiles" / f"{name}.md").read_text(encoding="utf-8")
    assert committed == tmmaster.profile_markdown(tmmaster.load_profile(name)), (
        f"docs/profiles/{name}.md is stale: run `tmmaster profile show {name} -o "
        f"docs/profiles/{name}.md`"
    )


def test_profile_command_prints_markdown(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["profile", "show", "article"]) == 0
    out = capsys.readouterr().out
    assert "| `target_x` | command | holding | 512 (0x0200) | int16 | x100 |" in out
    assert main(["profile", "show", "missing"]) == 2


@pytest.mark.parametrize(
    "module",
    [
        "tmmaster._cli",
        "tmmaster.pickplace.__main__",
        "tmmaster.sim.__main__",
        "tmmaster.report.__main__",
    ],
)
def test_every_command_answers_version(module: str, capsys: pytest.CaptureFixture[str]) -> None:
    # Each command's main() (``python -m tmmaster`` runs tmmaster._cli's). As processes:
    # ``python -m tmmaster --version``, ``.report``, ``.tmscript`` and the console script
    # in test_sigint_exit.py (then two Ctrl-Cs in their exit hooks); pick & place and the
    # simulator in test_pickplace.py and test_sim_server.py (a process costs most of a
    # second of CPU importing pydantic, pymodbus and structlog).
    command_main = importlib.import_module(module).main
    with pytest.raises(SystemExit) as exited:
        command_main(["--version"])
    assert exited.value.code == 0
    assert capsys.readouterr().out.strip().endswith(tmmaster.__version__)


def test_tmmaster_alone_prints_help(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 2  # a command is missing: a usage error
    assert "usage: tmmaster" in capsys.readouterr().err


@pytest.mark.parametrize("module", [tmmaster, tmmaster.aio, tmmaster.sim, tmmaster.pickplace])
def test_public_names_live_in_the_public_package(module: object) -> None:
    # Tracebacks and reprs show tmmaster.Robot, not tmmaster._robot.Robot.
    for name in module.__all__:  # type: ignore[attr-defined]
        value = getattr(module, name)
        if inspect.isclass(value) or inspect.isfunction(value):
            home = value.__module__
            assert not home.rsplit(".", 1)[-1].startswith("_"), f"{name}: {home}"


def _bad_calls() -> list[tuple[str, Callable[[], object]]]:
    article = tmmaster.robot_profile("article")
    return [
        ("unknown model", lambda: tmmaster.Robot("127.0.0.1", model="tm7")),
        ("unknown model name", lambda: tmmaster.robot_model("tm7")),
        ("unknown profile", lambda: tmmaster.Robot("127.0.0.1", profile="no-such")),
        ("unknown field", lambda: article.field("x")),
        ("unknown label", lambda: article.field("command").code_of("jump")),
        ("nan pose", lambda: tmmaster.Pose(float("nan"), 0, 0, 0, 0, 0)),
        ("text pose", lambda: tmmaster.Pose("here", 0, 0, 0, 0, 0)),  # type: ignore[arg-type]
        ("five values", lambda: tmmaster.Pose(300, -200, 200, 180, 0)),  # type: ignore[call-arg]
        ("motion lin", lambda: tmmaster.Robot("127.0.0.1", profile="article").start_move(
            tmmaster.Pose(300, -200, 200, 180, 0, 90), motion="lin"  # type: ignore[arg-type]
        )),
        ("bad poll interval", lambda: PollPolicy(interval_s=0)),
        ("bad speed cap", lambda: tmmaster.Checks(max_speed_percent=0)),
        ("bad gripper port", lambda: tmmaster.GripperDevice("onrobot-2fg7", "127.0.0.1", 0)),
        ("bad link", lambda: tmmaster.Robot("127.0.0.1", link="x")),  # type: ignore[arg-type]
        ("bad monitor rate", lambda: tmmaster.StatusMonitor(rate_hz=0)),
        ("unknown monitored robot", lambda: tmmaster.StatusMonitor().latest("r1")),
        ("value out of range", lambda: tmmaster.encode(article.field("target_x"), 400)),
    ]  # fmt: skip


@pytest.mark.parametrize(("what", "call"), _bad_calls(), ids=[w for w, _ in _bad_calls()])
def test_the_error_promise_holds(what: str, call: Callable[[], object]) -> None:
    with pytest.raises(tmmaster.TMMasterError) as caught:
        call()
    assert str(caught.value), what


def test_unknown_names_list_the_choices() -> None:
    with pytest.raises(KeyError, match="tm5-700"):  # still a KeyError/ValueError for old code
        tmmaster.robot_model("tm7")
    with pytest.raises(ValueError, match="'ptp', 'line'"):
        tmmaster.Robot("127.0.0.1", profile="article").start_move(
            tmmaster.Pose(300, -200, 200, 180, 0, 90),
            motion="lin",  # type: ignore[arg-type]
        )


def test_connect_after_close_is_a_clear_error() -> None:
    sim = tmmaster.sim.Simulator("article", listen=False).start()
    try:
        robot = tmmaster.Robot(sim.url, profile="article")
        robot.connect()
        robot.close()
        robot.close()
        with pytest.raises(tmmaster.ConnectError, match="was closed"):
            robot.connect()
    finally:
        sim.close()


def test_a_profile_mismatch_names_the_profile_the_device_speaks() -> None:
    sim = tmmaster.sim.Simulator("tmflow", listen=False).start()
    try:
        with (
            tmmaster.Robot(sim.url, profile="article", gripper=None) as robot,
            pytest.raises(tmmaster.IllegalAddressError, match="'tmflow' profile"),
        ):
            robot.status()
    finally:
        sim.close()


def test_the_shipped_config_schema_matches_the_model() -> None:
    from tmmaster._cli import config_schema

    shipped = ROOT / "src" / "tmmaster" / "schemas" / "pickplace-config.schema.json"
    assert shipped.read_text(encoding="utf-8") == config_schema(), (
        "stale: run `tmmaster schema -o src/tmmaster/schemas/pickplace-config.schema.json`"
    )


def test_the_shipped_report_schema_matches_the_model() -> None:
    from tmmaster.pickplace import report_schema

    shipped = ROOT / "src" / "tmmaster" / "schemas" / "run-report.schema.json"
    assert shipped.read_text(encoding="utf-8") == report_schema(), (
        "stale: run `tmmaster schema --report -o src/tmmaster/schemas/run-report.schema.json`"
    )


def test_schema_report_prints_the_report_schema(capsys: pytest.CaptureFixture[str]) -> None:
    import json

    assert main(["schema", "--report"]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert schema["title"] == "tmmaster pick & place run report (JSON)"
    assert {"result", "timeline", "sim", "move_states"} <= set(schema["properties"])
