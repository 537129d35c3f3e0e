"""Every example runs against the simulator (loopback, time_scale 100: ``QUICK``).

Examples are loaded from ``examples/`` and their ``main(argv)`` is called in-process
with ``--host 127.0.0.1 --port <sim port>``; one also runs as a script (``runpy``).
"""

from __future__ import annotations

import logging
import runpy
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from examples_support import EXAMPLES, load_example
from sim_speeds import QUICK
from tmmaster import DEFAULT_HOME, Pose
from tmmaster.pickplace.__main__ import main as pickplace_main
from tmmaster.sim import Cell, Simulator, TableObject

PICK = Pose(300, -200, 100, 180, 0, 90)
PLACE = Pose(300, 200, 200, 180, 0, 90)
HOME = DEFAULT_HOME
#: A part released at PLACE (200 mm up) falls onto the table: it rests at PLACE's x-y
#: with its centre 100 mm up, where the parts start (issue 9: released parts fall).
PLACED = Pose(PLACE.x, PLACE.y, PICK.z, PLACE.rx, PLACE.ry, PLACE.rz)

# The examples' runs are checked for their outcome (exit code, where the parts end up),
# not for a wall-clock delay: their simulators run at sim_speeds.QUICK (the examples
# poll every 50 ms). The commands of their docstrings run them on the default tmflow
# profile (test_examples_docstrings.py); most of these run them on the article's map.

SimFactory = Callable[..., Simulator]


def target(sim: Simulator) -> list[str]:
    """The --host/--port/--profile arguments of ``sim``."""
    return ["--host", "127.0.0.1", "--port", str(sim.port), "--profile", sim.profile.name]


@pytest.fixture
def fast_config(tmp_path: Path) -> Path:
    """Keep the article's poses and speeds; poll and settle fast for a fast simulator."""
    path = tmp_path / "fast.toml"
    path.write_text("[gripper]\nsettle_s = 0.05\n[run]\npoll_interval_s = 0.02\n")
    return path


def test_pick_and_place_example(tm_simulator_factory: SimFactory, fast_config: Path) -> None:
    sim = tm_simulator_factory(
        "article",
        cell=Cell(scene=[TableObject(name=f"p{i}", pose=PICK) for i in range(2)]),
        **QUICK,
    )
    argv = [*target(sim), "--cycles", "2", "--config", str(fast_config)]
    assert load_example("pick_and_place").main(argv) == 0
    # The second part fell onto the first at the place x-y (issue 9: released parts fall).
    stack = sorted(sim.objects(), key=lambda o: o.pose.z)
    assert [o.pose.is_close(PLACED.offset(dz=30 * k), mm=1.0) for k, o in enumerate(stack)] == [
        True,
        True,
    ]


def test_custom_sequence_example(tm_simulator_factory: SimFactory) -> None:
    # A missed grasp exercises the retry.
    sim = tm_simulator_factory("article", faults=["grasp_miss:at_grasp=1"], **QUICK)
    assert load_example("custom_sequence").main([*target(sim), "--settle", "0.05"]) == 0
    (part,) = sim.objects()
    assert part.pose.is_close(PICK, mm=1.0)  # put back where it was
    assert not part.held


def test_palletizing_example(tm_simulator_factory: SimFactory) -> None:
    sim = tm_simulator_factory(
        "article",
        cell=Cell(scene=[TableObject(name=f"p{i}", pose=PICK) for i in range(4)]),
        **QUICK,
    )
    argv = [*target(sim), "--rows", "2", "--cols", "2", "--settle", "0.05"]
    assert load_example("palletizing").main(argv) == 0
    example = load_example("palletizing")
    xs = sorted({round(o.pose.x) for o in sim.objects()})
    ys = sorted({round(o.pose.y) for o in sim.objects()})
    assert xs == [round(example.PALLET_ORIGIN.x + k * 40) for k in range(2)]
    assert ys == [round(example.PALLET_ORIGIN.y + k * 40) for k in range(2)]


def test_toml_sequence_example_runs_through_the_command(
    tm_simulator_factory: SimFactory, fast_config: Path
) -> None:
    sim = tm_simulator_factory(**QUICK)
    argv = [
        *target(sim),
        "--config",
        str(fast_config),
        "--sequence",
        str(EXAMPLES / "inspect_sequence.toml"),
    ]
    assert pickplace_main(argv) == 0
    assert sim.objects()[0].pose.is_close(PICK, mm=1.0)
    assert sim.tcp_pose().is_close(HOME, mm=1.0)


def test_an_example_runs_as_a_script(
    tm_simulator_factory: SimFactory,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    # As ``python examples/palletizing.py ...`` runs it: __name__ == "__main__", sys.argv
    # and sys.path[0] set to the script's, its exit status from sys.exit() (in-process: a
    # new interpreter would cost most of a second of CPU importing the dependencies).
    sim = tm_simulator_factory(
        "article", cell=Cell(scene=[TableObject(name="p", pose=PICK)]), **QUICK
    )
    script = EXAMPLES / "palletizing.py"
    argv = [*target(sim), "--rows", "1", "--cols", "1", "--settle", "0.05"]
    monkeypatch.setattr(sys, "argv", [str(script), *argv])
    monkeypatch.syspath_prepend(str(EXAMPLES))
    # The script configures tmmaster's logging for a process of its own: undone after.
    root, pymodbus = logging.getLogger("tmmaster"), logging.getLogger("pymodbus")
    saved = ([*root.handlers], root.level, root.propagate, pymodbus.level)
    try:
        with pytest.raises(SystemExit) as exited:
            runpy.run_path(str(script), run_name="__main__")
    finally:
        root.handlers[:] = saved[0]
        root.setLevel(saved[1])
        root.propagate = saved[2]
        pymodbus.setLevel(saved[3])
    out, err = capsys.readouterr()
    assert exited.value.code == 0, err
    assert "1/1 slots filled" in out
