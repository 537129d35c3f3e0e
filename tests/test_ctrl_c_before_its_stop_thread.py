"""A Ctrl-C during a pick & place run starts no further state, even before its stop's
thread has run.

The first Ctrl-C's stop request (``Runner.request_stop``) sets events, so it runs in a
thread the signal handler starts (the handler may have interrupted the main thread inside
an event's lock); on a loaded machine that thread may run late, and the next state's
move was sent meanwhile, to be stopped only once the thread ran. The handler itself now
marks the run stopping (``Runner.note_stop``: a flag, no lock), and the run checks it
before each state. Here the stop's thread is held until ``main()`` has returned: the run
still ends in the state it was entering, its move never sent.
"""

from __future__ import annotations

import _thread
import json
import logging
import threading
from collections.abc import Callable
from pathlib import Path

import pytest

from sim_speeds import QUICK
from test_hunt30_cli_faults import CONFIG, PICK, OnState
from tmmaster.pickplace import Runner
from tmmaster.pickplace.__main__ import EXIT_INTERRUPTED, main
from tmmaster.sim import Cell, Simulator, TableObject


def test_a_ctrl_c_whose_stop_thread_has_not_run_sends_no_next_move(
    tm_simulator_factory: Callable[..., Simulator],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    sim = tm_simulator_factory(
        "tmflow", cell=Cell(scene=[TableObject(name="p", pose=PICK)]), **QUICK
    )
    config, report = tmp_path / "cell.toml", tmp_path / "report.json"
    config.write_text(CONFIG)
    release, finished = threading.Event(), threading.Event()
    request_stop = Runner.request_stop

    def late_request_stop(runner: Runner) -> None:  # the stop's thread, held
        release.wait(10.0)
        request_stop(runner)
        finished.set()

    monkeypatch.setattr(Runner, "request_stop", late_request_stop)
    handler = OnState("MOVE_TO_PICK", _thread.interrupt_main)
    logger = logging.getLogger("tmmaster.pickplace")
    logger.addHandler(handler)
    try:
        argv = ["--host", "127.0.0.1", "--port", str(sim.port), "--config", str(config)]
        code = main([*argv, "--report", str(report), "--log-level", "info"])
    finally:
        logger.removeHandler(handler)
        release.set()
    assert finished.wait(5.0)
    assert handler.fired
    err = capsys.readouterr().err
    assert code == EXIT_INTERRUPTED, err[-2000:]
    data = json.loads(report.read_text())
    assert data["error"]["state"] == "MOVE_TO_PICK"
    assert [m.kind for m in sim.motion_log()] == ["ptp"]  # the approach only
