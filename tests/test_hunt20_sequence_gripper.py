"""A TOML sequence's gripper steps: refused unsent on a robot without a gripper, and a
release that finds the part gone is not a part placed.

Found by hunt 20 (each fails without its fix):

- A sequence whose fifth step grips, run with ``[gripper] kind = "none"``: ``--dry-run``
  said the plan was fine (exit 0) and the run made the first four steps' moves, then
  failed in the grip (``ConfigError: no gripper is configured``, exit 1). The plan check
  now refuses a gripper step (and an ``open_at_start``) on a robot without a gripper,
  naming ``steps.N``: exit 2, ``--dry-run`` too, and the robot sees no request at all.
- A part that slips out on the way (a grip too weak to carry it, reported held at the
  close) and a TOML ``release`` at the place: the run ended DONE, exit 0, while the part
  lay where it was picked. The built-in pick & place and palletizing read the gripper
  before their release (c65d211); a TOML release now does the same after a grip or a
  check that saw the part: exit 5, ``grasp_failed``, the fingers left closed. A release
  with no part seen (an open before the pick) still just opens.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pytest

from sim_speeds import QUICK
from tmmaster import Pose
from tmmaster.pickplace import ARTICLE_PICK
from tmmaster.pickplace.__main__ import EXIT_CONFIG, EXIT_GRASP, main
from tmmaster.sim import Cell, Simulator, TableObject

Factory = Callable[..., Simulator]
PICK = Pose.from_sequence(ARTICLE_PICK)

SEQUENCE = """\
name = "pick-carry-release"
open_at_start = false
[poses]
part = [300, -200, 100, 180, 0, 90]
place = [300, 200, 200, 180, 0, 90]
[[steps]]
do = "move"
pose = "part"
z_offset = 100
speed = 30
[[steps]]
do = "move"
pose = "part"
speed = 10
motion = "line"
[[steps]]
do = "wait"
seconds = 0.01
[[steps]]
do = "wait"
seconds = 0.01
[[steps]]
state = "GRIP"
do = "grip"
[[steps]]
do = "move"
pose = "part"
z_offset = 150
speed = 10
motion = "line"
[[steps]]
do = "move"
pose = "place"
speed = 30
[[steps]]
state = "RELEASE"
do = "release"
"""


def _files(tmp_path: Path, config: str) -> list[str]:
    (tmp_path / "seq.toml").write_text(SEQUENCE)
    (tmp_path / "cell.toml").write_text(config)
    return ["--config", str(tmp_path / "cell.toml"), "--sequence", str(tmp_path / "seq.toml")]


def test_a_grip_step_on_a_robot_without_gripper_is_refused_before_anything_moves(
    tm_simulator_factory: Factory, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    files = _files(tmp_path, '[gripper]\nkind = "none"\n')
    assert main(["--dry-run", *files]) == EXIT_CONFIG
    assert "steps.4 (GRIP) uses the gripper" in capsys.readouterr().err

    sim = tm_simulator_factory(**QUICK)
    code = main(["--host", "127.0.0.1", "--port", str(sim.port), *files, "--quiet"])
    assert code == EXIT_CONFIG
    assert "steps.4 (GRIP) uses the gripper, and this robot has none" in capsys.readouterr().err
    assert sim.motion_log() == ()
    assert sim.request_log == []


def test_a_part_lost_before_a_toml_release_fails_the_run_instead_of_done(
    tm_simulator_factory: Factory, tmp_path: Path
) -> None:
    # Squeezed at the close (reported held), too heavy for the grip: it slips out lifting.
    heavy = TableObject(name="part-1", pose=PICK, mass_kg=5.0)
    sim = tm_simulator_factory("article", cell=Cell(scene=[heavy]), **QUICK)
    files = _files(tmp_path, "[gripper]\nsettle_s = 0.05\n[run]\npoll_interval_s = 0.01\n")
    report = tmp_path / "run.json"
    argv = ["--host", "127.0.0.1", "--port", str(sim.port), "--profile", "article", *files]
    code = main([*argv, "--report", str(report), "--quiet"])

    (part,) = sim.objects()
    assert not part.held, part  # it slipped out, and lies where it was picked
    assert part.pose.is_close(PICK, mm=2.0), part
    data = json.loads(report.read_text())
    assert (code, data["result"], data["cycles"]["completed"]) == (EXIT_GRASP, "grasp_failed", 0)
    assert data["error"]["state"] == "RELEASE"
    assert "no longer holds" in data["error"]["message"]
