"""examples/many_robots.py runs: on its own simulators, on given ports, and with one failure."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import pytest

from examples_support import load_example
from sim_speeds import QUICK, ticking_simulator
from tmmaster import RobotFaultError
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

#: The example's own simulators tick at Simulator's default 50 Hz, which allows 20x at
#: most; its test runs them at 50x with the tick raised to match (``fast_example``).
EXAMPLE_TIME_SCALE = 50.0
# The simulators a test starts for the example run at QUICK: the tests count moves and
# errors, not wall-clock times.


@pytest.fixture(scope="module")
def example() -> ModuleType:
    """The example script, imported as a module."""
    return load_example("many_robots")


@pytest.fixture
def fast_example(example: ModuleType, monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    """The example, its own simulators ticking fast enough for their time scale.

    Only the tick rate is added: the example still starts, drives and closes them itself.
    """
    monkeypatch.setattr(example, "Simulator", ticking_simulator)
    return example


@pytest.mark.parametrize("fleet", [True, False], ids=["fleet", "no-fleet"])
def test_every_robot_drives_its_tour(
    tm_simulator_factory: Factory, example: ModuleType, fleet: bool
) -> None:
    sims = [tm_simulator_factory(**QUICK) for _ in range(4)]
    reports = example.run([s.port for s in sims], moves=3, watch_hz=50, fleet=fleet)
    assert [r.error for r in reports] == [None] * 4
    assert [r.moves_done for r in reports] == [3] * 4
    # The fleet's watch (or one StatusMonitor) watched the robots while the threads drove
    # them: every robot's link worked, and it polled.
    assert all(r.watched is not None and r.watched.failures == 0 for r in reports)
    assert sum(r.watched.polls for r in reports if r.watched is not None) > 0
    for sim in sims:
        # The simulator's own record: exactly the three tour poses, in order, once each.
        targets = [m.target for m in sim.motion_log() if m.target is not None]
        assert len(targets) == 3
        for target, expected in zip(targets, example.TOUR, strict=True):
            assert target.is_close(expected)
        assert sim.tcp_pose().is_close(example.TOUR[2])


def test_one_failure_stays_with_its_robot(
    tm_simulator_factory: Factory, example: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    good = [tm_simulator_factory(**QUICK) for _ in range(2)]
    bad = tm_simulator_factory(faults=["robot_error:at_move=2"], **QUICK)
    reports = example.run([good[0].port, bad.port, good[1].port], moves=3)
    assert [r.moves_done for r in reports] == [3, 1, 3]
    assert reports[0].error is None
    assert reports[2].error is None
    assert isinstance(reports[1].error, RobotFaultError)
    # The failed robot started nothing after its error.
    assert len([m for m in bad.motion_log() if m.target is not None]) == 2
    assert example.print_reports(reports) == 1
    out = capsys.readouterr().out
    assert "robot1: FAILED after 1 move(s)" in out
    assert "2 of 3 robots done" in out


def test_main_on_its_own_simulators(
    fast_example: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["--sim", "3", "--moves", "2", "--time-scale", str(EXAMPLE_TIME_SCALE)]
    assert fast_example.main(argv) == 0
    assert "3 of 3 robots done" in capsys.readouterr().out


def test_main_on_its_own_simulators_from_two_processes(
    fast_example: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    # The simulators run in this process; two child processes drive them.
    argv = ["--sim", "3", "--moves", "2", "--time-scale", str(EXAMPLE_TIME_SCALE)]
    assert fast_example.main([*argv, "--processes", "2", "--no-fleet"]) == 0
    out = capsys.readouterr().out
    assert "3 of 3 robots done" in out
    assert [line.split(":")[0] for line in out.splitlines() if line.startswith("robot")] == [
        "robot0",
        "robot1",
        "robot2",
    ]


@pytest.mark.parametrize("fleet", [True, False], ids=["fleet", "no-fleet"])
def test_without_a_watch_nothing_is_watched(
    tm_simulator_factory: Factory, example: ModuleType, fleet: bool
) -> None:
    sim = tm_simulator_factory(**QUICK)
    (report,) = example.run([sim.port], moves=1, watch_hz=0, fleet=fleet)
    assert report.moves_done == 1
    assert report.watched is None


@pytest.mark.parametrize("processes", ["1", "2"])
def test_main_on_given_ports(
    tm_simulator_factory: Factory,
    example: ModuleType,
    processes: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    sims = [tm_simulator_factory(**QUICK) for _ in range(2)]
    ports = [str(s.port) for s in sims]
    assert example.main(["--ports", *ports, "--moves", "1", "--processes", processes]) == 0
    assert "2 of 2 robots done" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv",
    [
        ["--sim", "2", "--ports", "5020"],
        ["--moves", "0"],
        ["--sim", "0"],
        ["--watch-hz", "-1"],
        ["--processes", "0"],
    ],
)
def test_bad_arguments_exit_2(example: ModuleType, argv: list[str]) -> None:
    with pytest.raises(SystemExit) as info:
        example.main(argv)
    assert info.value.code == 2


def test_several_processes_share_the_robots(
    tm_simulator_factory: Factory, example: ModuleType
) -> None:
    sims = [tm_simulator_factory(**QUICK) for _ in range(4)]
    sims.append(tm_simulator_factory(faults=["robot_error:at_move=2"], **QUICK))
    reports = example.run_in_processes([s.port for s in sims], processes=2, moves=3, watch_hz=50)
    # Each child drove a contiguous share; the parent gathered them in order.
    assert [r.name for r in reports] == [f"robot{i}" for i in range(5)]
    assert [r.moves_done for r in reports] == [3, 3, 3, 3, 1]
    assert [r.error is None for r in reports] == [True] * 4 + [False]
    assert str(reports[4].error).startswith("RobotFaultError: ")
    assert all(r.watched is not None and r.watched.failures == 0 for r in reports)
    for sim in sims[:4]:
        targets = [m.target for m in sim.motion_log() if m.target is not None]
        assert len(targets) == 3  # each robot driven by exactly one child
    # The failed robot started nothing after its error.
    assert len([m for m in sims[4].motion_log() if m.target is not None]) == 2


def test_a_child_that_ends_without_reporting_fails_its_robots(
    example: ModuleType, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    script = tmp_path / "crash.py"
    script.write_text("import sys\nsys.exit(3)\n")
    monkeypatch.setattr(example, "__file__", str(script))
    reports = example.run_in_processes([1, 2, 3], processes=2)
    assert [r.name for r in reports] == ["robot0", "robot1", "robot2"]
    assert all("ended with code 3 before reporting" in str(r.error) for r in reports)


def test_a_report_survives_the_trip_from_a_child(example: ModuleType) -> None:
    report = example.RobotReport(
        "robot7", moves_done=2, move_times_s=[0.5, 0.25], error=RobotFaultError("robot in error")
    )
    back = example.report_from_json(json.loads(json.dumps(example.report_to_json(report))))
    assert (back.name, back.moves_done, back.move_times_s) == ("robot7", 2, [0.5, 0.25])
    assert str(back.error) == "RobotFaultError: robot in error"
    assert back.watched is None
