"""The pick & place command line is resolved once: nothing after ``_resolve`` sees argparse.

``run`` hands the parsed namespace to ``_resolve``, which turns it into one frozen
invocation (the validated configuration, what to run, the output options); the plan
check, the robot, the runner, the simulator and the report read that object. These tests
seal the namespace once ``_resolve`` returns: any later read of it is recorded.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from sim_speeds import QUICK
from tmmaster.pickplace import __main__ as cli
from tmmaster.sim import Simulator

#: Quick runs: short polls and settle times.
FAST = """
[gripper]
settle_s = 0.05
[run]
poll_interval_s = 0.02
[timeouts]
ack_s = 0.5
motion_margin_s = 0.5
"""


class _SealedArgs(argparse.Namespace):
    """Arguments that record every option read once they are sealed."""

    def __init__(self, args: argparse.Namespace, late: list[str]) -> None:
        super().__init__(**vars(args))
        object.__setattr__(self, "_late", late)
        object.__setattr__(self, "_sealed", False)

    def __getattribute__(self, name: str) -> Any:
        if not name.startswith("_") and object.__getattribute__(self, "_sealed"):
            object.__getattribute__(self, "_late").append(name)
        return object.__getattribute__(self, name)


@pytest.fixture
def late_reads(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The options read after ``_resolve`` returned (sealed from then on)."""
    late: list[str] = []
    resolve = cli._resolve

    def sealing(args: argparse.Namespace, outcome: Any) -> Any:
        invocation = resolve(args, outcome)
        object.__setattr__(args, "_sealed", True)
        return invocation

    monkeypatch.setattr(cli, "_resolve", sealing)
    return late


def _run(argv: list[str], late: list[str]) -> int:
    args = _SealedArgs(cli.build_parser().parse_args(argv), late)
    return cli.run(args, output=cli._Output(quiet=True))


@pytest.mark.parametrize("mode", ["dry-run", "robot", "sim", "bad-option"])
def test_nothing_after_resolve_reads_the_command_line(
    mode: str,
    late_reads: list[str],
    tmp_path: Path,
    memory_simulator_factory: Callable[..., Simulator],
) -> None:
    config = tmp_path / "cell.toml"
    config.write_text(FAST)
    report = tmp_path / "run.json"
    argv = ["--config", str(config), "--report", str(report), "--profile", "article", "-v"]
    expected = cli.EXIT_OK
    if mode == "dry-run":
        argv += ["--dry-run"]
    elif mode == "robot":
        sim = memory_simulator_factory("article", **QUICK)
        argv += ["--host", sim.url, "--poll-interval", "0.03"]
    elif mode == "sim":
        argv += ["--sim", "--sim-time-scale", "40", "--poll-interval", "0.03"]
    else:
        argv += ["--port", "70000"]
        expected = cli.EXIT_CONFIG

    assert _run(argv, late_reads) == expected

    assert late_reads == []
    # The report (an output option, resolved with the rest) is still written, and says
    # how the run ended, a refused option included.
    assert json.loads(report.read_text())["exit_code"] == expected


def test_the_resolved_invocation_is_frozen(tmp_path: Path) -> None:
    args = cli.build_parser().parse_args(["--dry-run", "--report", str(tmp_path / "r.json")])
    invocation = cli._resolve(args, cli._Outcome())
    assert isinstance(invocation.command, cli._Command)
    assert invocation.output.report == str(tmp_path / "r.json")
    with pytest.raises(dataclasses.FrozenInstanceError):
        invocation.output = invocation.output  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        invocation.command.config = invocation.command.config  # type: ignore[misc]
