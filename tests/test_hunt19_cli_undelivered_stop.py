"""``python -m tmmaster.pickplace`` says so when the link lost mid-move never carried the stop.

The link goes down (the slave refuses connections: a proxy outage) exactly when the
robot starts the move to the place pose, and stays down past the retry policy. The
master gives the move up and owes the robot its stop (docs/safety.md); on ``article``
the arm runs its move to the end. The run ends with exit 3 and one line. That line said
only "connection error in MOVE_TO_PLACE (cycle 1): ConnectRefusedError: ..." while the
arm went on moving to the place pose after the command had returned: an operator reads
a stopped cell. An interrupted run says "the stop could NOT be delivered"; a failed one
said nothing, its report's ``stop_delivered`` false.

Found by this hunt (fails without its fix): a failed run whose stop was not delivered
says so in its line, "the stop could NOT be delivered: the arm may still move"; a
stop ``close()`` delivered after all (the link back) counts as delivered. The judge is
the simulator: the place move ended after ``main`` had returned.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from fault_proxy import FaultProxy
from tmmaster import Pose
from tmmaster.pickplace import ARTICLE_PICK, ARTICLE_PLACE
from tmmaster.pickplace.__main__ import EXIT_CONNECTION, main
from tmmaster.sim import Cell, MotionRecord, Simulator, TableObject

Factory = Callable[..., Simulator]
PICK, PLACE = Pose.from_sequence(ARTICLE_PICK), Pose.from_sequence(ARTICLE_PLACE)
#: Quick moves, but a slow move to the place pose (about 19 s simulated, 1 s at 20x).
CELL = """
[speeds]
approach = 100
pick = 50
lift = 50
place = 2

[gripper]
settle_s = 0.05

[run]
poll_interval_s = 0.01

[timeouts]
ack_s = 0.5
request_s = 0.2

[retry]
attempts = 2
total_time_s = 0.2
"""


def to_place(sim: Simulator) -> list[MotionRecord]:
    """The robot's motions to the place pose."""
    return [
        m for m in sim.motion_log() if m.target is not None and m.target.distance_to(PLACE) < 0.1
    ]


def test_a_failed_run_whose_stop_the_link_never_carried_says_so(
    tm_simulator_factory: Factory, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = tm_simulator_factory(
        "article", cell=Cell(scene=[TableObject(name="part-1", pose=PICK)]), time_scale=20.0
    )
    config, report = tmp_path / "cell.toml", tmp_path / "run.json"
    config.write_text(CELL)
    ended = threading.Event()
    with FaultProxy(sim.port) as proxy:

        def outage_when_the_place_move_starts() -> None:
            while not ended.wait(0.002):
                if any(
                    m.target is not None and m.target.distance_to(PLACE) < 0.1
                    for m in sim.motion_log()
                ):
                    proxy.outage(30.0)
                    return

        watcher = threading.Thread(target=outage_when_the_place_move_starts)
        watcher.start()
        try:
            argv = ["--host", "127.0.0.1", "--port", str(proxy.port), "--profile", "article"]
            code = main([*argv, "--config", str(config), "--report", str(report), "--quiet"])
        finally:
            ended.set()
            watcher.join(5)
        returned = time.monotonic()
        assert len(to_place(sim)) == 1
        sim.wait_for(lambda: sim.motion_log()[-1].done_wall_time is not None, timeout=5.0)

    (moved,) = to_place(sim)
    assert moved.done_wall_time is not None
    assert moved.done_wall_time > returned, "the scenario: the arm moved on after the return"
    data = json.loads(report.read_text())
    assert (code, data["result"], data["stop_delivered"]) == (
        EXIT_CONNECTION,
        "connection_error",
        False,
    )
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert line.startswith("pickplace: connection error in MOVE_TO_PLACE"), line
    assert "the stop could NOT be delivered" in line, line
