"""What ``python -m tmmaster.pickplace`` says against what the simulated robot did.

The command runs in-process (``main(argv)``) against a tmflow simulator, so its request
log and motion log are at hand; the claims checked are the exit code, the one-line
reason and the JSON report (``--report``).

1. Exit 2 means "invalid configuration or options: nothing was sent to the robot"
   (docs/pickplace.md). The arm parked at the home position in another pose
   configuration (J5 < 0): the plan, checked before connecting from the home pose,
   passes; the approach from the real joints is refused (self-collision on its joint
   path). Once connected the run checks its moves again from the reported pose and
   joints (the runner's check, before its first command), so that refusal is exit 2
   with no command sent. A refusal after the run began commanding (here forced by
   skipping that check) is exit 1 (``failed``), never exit 2: it used to be exit 2
   after the gripper had opened.
2. A guard on the report's per-step claims under device faults (robot error, e-stop,
   stall) hitting the 2nd and 4th moves: every move step the timeline reports ``ok``
   is a motion the robot finished, the failing state is the one whose motion was
   running, and no motion started after ``main`` returned.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import tmmaster.pickplace._runner as pickplace_runner
from sim_speeds import QUICK
from tmmaster import Pose, Robot
from tmmaster._robot_models import robot_model
from tmmaster.pickplace import ARTICLE_PICK
from tmmaster.pickplace.__main__ import (
    EXIT_CONFIG,
    EXIT_FAILED,
    EXIT_ROBOT_FAULT,
    EXIT_TIMEOUT,
    main,
)
from tmmaster.sim import Cell, Simulator, TableObject

SimFactory = Callable[..., Simulator]
PICK = Pose.from_sequence(ARTICLE_PICK)
#: The built-in cell's part, waiting at the pick pose.
PART = TableObject(name="part-1", pose=PICK)
HOME = Pose(250, 0, 300, 180, 0, 90)  # the default home
FAST = """
[gripper]
settle_s = 0.05

[run]
poll_interval_s = 0.02

[timeouts]
ack_s = 0.5
motion_margin_s = 0.5
motion_s = 0.5  # a stalled move is given up within half a second
"""
#: The tmflow command register (a move's or the gripper's command code).
COMMAND_REGISTER = 9014
#: The moves of the pick & place cycle, in order.
MOVES = ["MOVE_TO_APPROACH", "MOVE_TO_PICK", "MOVE_TO_LIFT", "MOVE_TO_PLACE", "MOVE_TO_HOME"]


def run_cli(sim: Simulator, tmp_path: Path, *extra: str) -> tuple[int, dict[str, Any]]:
    config = tmp_path / "cell.toml"
    config.write_text(FAST)
    report = tmp_path / "run.json"
    argv = ["--host", "127.0.0.1", "--port", str(sim.port), "--config", str(config)]
    code = main([*argv, "--report", str(report), *extra])
    return code, json.loads(report.read_text())


def park_at_home_with_the_wrist_flipped(sim: Simulator) -> None:
    """Home, reached with the wrist the other way (J5 < 0): the plan, checked before
    connecting from the default configuration, passes; the approach from these joints
    does not (a self-collision on its joint path)."""
    flipped = robot_model("tm5-700").inverse(HOME, seed_deg=(29, -37, 126, 180, -90, -150))
    assert flipped[4] < 0
    with Robot("127.0.0.1", sim.port, profile="tmflow") as robot:
        robot.move_joints(flipped, speed=50)


def commands(sim: Simulator) -> list[object]:
    return [r for r in sim.request_log if r.is_write and r.address == COMMAND_REGISTER]


def test_a_first_move_the_arm_cannot_take_from_where_it_is_is_exit_2_before_any_command(
    tm_simulator_factory: SimFactory, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Once connected, the run checks its moves again from the pose and joints the robot
    # reports, before its IDLE state opens the gripper: exit 2, nothing commanded.
    sim = tm_simulator_factory("tmflow", cell=Cell(scene=[PART]), **QUICK)
    park_at_home_with_the_wrist_flipped(sim)
    motions = len(sim.motion_log())
    sim.clear_request_log()

    code, report = run_cli(sim, tmp_path)

    assert commands(sim) == [], "a command was sent before the plan was refused"
    assert len(sim.motion_log()) == motions
    assert code == EXIT_CONFIG
    assert (report["result"], report["exit_code"]) == ("config_error", EXIT_CONFIG)
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert "MOVE_TO_APPROACH" in line
    assert line.endswith(f"[exit {EXIT_CONFIG}]")


def test_a_move_refused_after_the_run_opened_the_gripper_is_not_exit_2(
    tm_simulator_factory: SimFactory,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A refusal the check from where the arm is cannot foresee (here: that check, the
    # runner's before its first command, skipped) comes after the gripper opened: exit 1,
    # never exit 2's "nothing sent".
    monkeypatch.setattr(pickplace_runner, "validate_plan", lambda *args, **kwargs: 0)
    sim = tm_simulator_factory("tmflow", cell=Cell(scene=[PART]), **QUICK)
    park_at_home_with_the_wrist_flipped(sim)
    motions = len(sim.motion_log())
    sim.clear_request_log()

    code, report = run_cli(sim, tmp_path)

    assert commands(sim), "the run opened the gripper before the approach was refused"
    assert len(sim.motion_log()) == motions, "the refused approach must not move"
    assert code != EXIT_CONFIG, "exit 2 says nothing was sent, but the gripper was opened"
    assert code == EXIT_FAILED
    assert (report["result"], report["exit_code"]) == ("failed", EXIT_FAILED)
    assert report["error"]["state"] == "MOVE_TO_APPROACH"
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert line.startswith("pickplace: failed in MOVE_TO_APPROACH (cycle 1): ConfigError")
    assert line.endswith(f"[exit {EXIT_FAILED}]")


@pytest.mark.parametrize("at_move", [2, 4])
@pytest.mark.parametrize("kind", ["robot_error", "estop", "stall"])
def test_the_report_claims_only_the_moves_the_robot_finished(
    tm_simulator_factory: SimFactory, tmp_path: Path, kind: str, at_move: int
) -> None:
    sim = tm_simulator_factory(
        "tmflow",
        cell=Cell(scene=[PART]),
        faults=[f"{kind}:at_move={at_move}"],
        **QUICK,
    )
    code, report = run_cli(sim, tmp_path, "--poll-interval", "0.02")
    ended = time.monotonic()

    motions = [m for m in sim.motion_log() if m.target is not None]
    assert all(m.wall_time <= ended for m in sim.motion_log()), "a motion started after exit"
    moves = [t for t in report["timeline"] if t["state"] in report["move_states"]]
    claimed = [t["state"] for t in moves if t["outcome"] == "ok"]
    assert claimed == MOVES[: at_move - 1]
    for state, motion in zip(claimed, motions, strict=False):
        assert motion.done_wall_time is not None, f"{state} reported ok, the robot did not finish"
    # The failing state is the one whose motion the robot was running, unfinished.
    assert report["error"]["state"] == MOVES[at_move - 1]
    assert len(motions) == at_move
    assert motions[-1].done_wall_time is None
    assert report["cycles"]["completed"] == 0
    assert report["result"] != "done"
    assert code == (EXIT_TIMEOUT if kind == "stall" else EXIT_ROBOT_FAULT)
