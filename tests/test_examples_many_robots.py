"""examples/many_robots.py runs: on its own simulators, on given ports, and with one failure."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import pytest

from examples_support import load_example
from tmmaster import RobotFaultError
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

# The simulators a test starts for the example run at the suite's pace (40x, 100 Hz): the
# tests count moves and errors, not wall-clock times, and several tmflow simulators (each
# tick runs the robot program) cost about twice the CPU at QUICK's 250 Hz, for no gain.


@pytest.fixture(scope="module")
def example() -> ModuleType:
    """The example script, imported as a module."""
    return load_example("many_robots")


@pytest.mark.parametrize("fleet", [True, False], ids=["fleet", "no-fleet"])
def test_every_robot_drives_its_tour(
    tm_simulator_factory: Factory, example: ModuleType, fleet: bool
) -> None:
    sims = [tm_simulator_factory() for _ in range(4)]
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
    good = [tm_simulator_factory() for _ in range(2)]
    bad = tm_simulator_factory(faults=["robot_error:at_move=2"])
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


# main() on its own simulators, in one process and from two: the commands of the
# example's docstring (tests/test_examples_docstrings.py).


@pytest.mark.parametrize("fleet", [True, False], ids=["fleet", "no-fleet"])
def test_without_a_watch_nothing_is_watched(
    tm_simulator_factory: Factory, example: ModuleType, fleet: bool
) -> None:
    sim = tm_simulator_factory()
    (report,) = example.run([sim.port], moves=1, watch_hz=0, fleet=fleet)
    assert report.moves_done == 1
    assert report.watched is None


@pytest.mark.parametrize(
    "options", [["--processes", "1"], ["--processes", "2", "--no-fleet"]], ids=["1", "2"]
)
def test_main_on_given_ports(
    tm_simulator_factory: Factory,
    example: ModuleType,
    options: list[str],
    capsys: pytest.CaptureFixture[str],
) -> None:
    sims = [tm_simulator_factory() for _ in range(2)]
    ports = [str(s.port) for s in sims]
    assert example.main(["--ports", *ports, "--moves", "1", *options]) == 0
    out = capsys.readouterr().out
    assert "2 of 2 robots done" in out
    # Two children, one robot each, reported in order.
    assert [line.split(":")[0] for line in out.splitlines() if line.startswith("robot")] == [
        "robot0",
        "robot1",
    ]


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
    # On the article's map: the children are told the profile.
    sims = [tm_simulator_factory("article") for _ in range(4)]
    sims.append(tm_simulator_factory("article", faults=["robot_error:at_move=2"]))
    ports = [s.port for s in sims]
    reports = example.run_in_processes(ports, processes=2, moves=3, watch_hz=50, profile="article")
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
