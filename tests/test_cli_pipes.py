"""A reader of stdout that goes away (``| head``): every command ends quietly with 141.

141 is 128 + SIGPIPE, what a shell reports for a writer whose pipe was closed. A
``pickplace`` run still goes to its end and still writes ``--report``. The closed pipe is
made here by closing a pipe's read end before the command writes (what ``head`` does
after its lines); subprocess tests check the whole process, its exit included.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from tmmaster import _cli
from tmmaster._cliparse import EXIT_BROKEN_PIPE
from tmmaster.pickplace.__main__ import main as pickplace_main
from tmmaster.report.__main__ import main as report_main

#: The quick --sim run (simulated time 40x faster, 20 ms polling).
SIM = ["--sim", "--sim-time-scale", "40", "--poll-interval", "0.02"]


def test_the_status_is_the_shells_for_a_closed_pipe() -> None:
    assert EXIT_BROKEN_PIPE == 141


@contextmanager
def _closed_stdout(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """``sys.stdout`` is a pipe whose reader already left."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    with open(write_end, "w", encoding="utf-8") as pipe:
        monkeypatch.setattr("sys.stdout", pipe)
        yield
        monkeypatch.undo()


def test_a_pickplace_run_into_a_closed_pipe_still_writes_its_report(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    report = tmp_path / "run.json"
    with _closed_stdout(monkeypatch):
        code = pickplace_main([*SIM, "--cycles", "1", "--report", str(report)])
    assert code == EXIT_BROKEN_PIPE
    assert capsys.readouterr().err == ""  # quiet: the reader left on purpose
    written = json.loads(report.read_text(encoding="utf-8"))
    assert written["result"] == "done"  # the report says how the run ended
    assert written["exit_code"] == 0
    assert written["cycles"]["completed"] == 1


def test_a_failed_run_keeps_its_own_status_with_a_closed_stdout(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    report = tmp_path / "run.json"
    with _closed_stdout(monkeypatch):
        code = pickplace_main(["--dry-run", "--profile", "tmfow", "--report", str(report)])
    assert code == 2  # the run's own failure says more than the closed pipe
    assert "tmfow" in capsys.readouterr().err
    assert json.loads(report.read_text(encoding="utf-8"))["result"] == "config_error"


def test_report_show_into_a_closed_pipe_ends_quietly(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    report = tmp_path / "run.json"
    assert pickplace_main(["--dry-run", "--quiet", "--report", str(report)]) == 0
    capsys.readouterr()
    with _closed_stdout(monkeypatch):
        assert report_main(["show", str(report)]) == EXIT_BROKEN_PIPE
    with _closed_stdout(monkeypatch):
        assert _cli.main(["profile", "list"]) == EXIT_BROKEN_PIPE
    assert capsys.readouterr().err == ""


def _run_into_a_closed_pipe(argv: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    """``python argv...`` whose stdout's reader is gone before it writes."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        return subprocess.run(
            [sys.executable, *argv],
            stdout=write_end,
            stderr=subprocess.PIPE,
            text=True,
            cwd=cwd,
            timeout=60,
            check=False,
        )
    finally:
        os.close(write_end)


def test_pickplace_process_into_a_closed_pipe_is_141_without_a_traceback(tmp_path: Path) -> None:
    done = _run_into_a_closed_pipe(
        ["-m", "tmmaster.pickplace", "--dry-run", "--cycles", "2", "--report", "run.json"],
        tmp_path,
    )
    assert (done.returncode, done.stderr) == (EXIT_BROKEN_PIPE, "")
    assert json.loads((tmp_path / "run.json").read_text(encoding="utf-8"))["result"] == "done"


def test_the_simulator_process_into_a_closed_pipe_ends_quietly(tmp_path: Path) -> None:
    # Its banner is its first write: the reader is gone, the simulator stops, quietly.
    done = _run_into_a_closed_pipe(
        ["-m", "tmmaster.sim", "--port", "0", "--gripper-port", "0", "--log-level", "error"],
        tmp_path,
    )
    assert (done.returncode, done.stderr) == (EXIT_BROKEN_PIPE, "")
