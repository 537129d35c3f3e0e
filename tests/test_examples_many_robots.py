"""examples/many_robots.py runs: on its own simulators, on given ports, and with one failure."""

from __future__ import annotations

import json
import select
import socket
import threading
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from examples_support import load_example
from tmmaster import RobotFaultError, TransportError
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


def test_main_on_given_ports(
    tm_simulator_factory: Factory, example: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    # In this process (--processes 2: test_several_processes_share_the_robots).
    sims = [tm_simulator_factory() for _ in range(2)]
    ports = [str(s.port) for s in sims]
    assert example.main(["--ports", *ports, "--moves", "1", "--processes", "1"]) == 0
    out = capsys.readouterr().out
    assert "2 of 2 robots done" in out
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
    tm_simulator_factory: Factory,
    example: ModuleType,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    # main() on given ports with --processes 2 (two child processes: each starts a fresh
    # interpreter, so one run serves every check). On the article's map: the children are
    # told the profile; --no-fleet reaches them too.
    sims = [tm_simulator_factory("article") for _ in range(4)]
    sims.append(tm_simulator_factory("article", faults=["robot_error:at_move=2"]))
    ports = [str(s.port) for s in sims]
    calls: list[tuple[dict[str, object], list[Any]]] = []
    real = example.run_in_processes

    def recorded(*args: Any, **options: Any) -> list[Any]:
        reports: list[Any] = real(*args, **options)
        calls.append((options, reports))
        return reports

    monkeypatch.setattr(example, "run_in_processes", recorded)
    argv = ["--ports", *ports, "--moves", "3", "--processes", "2", "--no-fleet"]
    assert example.main([*argv, "--profile", "article", "--watch-hz", "50"]) == 1  # one failed
    ((options, reports),) = calls
    assert (options["processes"], options["fleet"]) == (2, False)
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
    # main() printed them in order, the failure included.
    out = capsys.readouterr().out
    assert "4 of 5 robots done" in out
    named = [line.split(":")[0] for line in out.splitlines() if line.startswith("robot")]
    assert named == [f"robot{i}" for i in range(5)]


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


class SilentSlaves:
    """Loopback ports that accept connections and never answer, until ``gate`` are open.

    Once ``gate`` connections are open at the same time it records that, closes them
    all and stops listening (further connects are refused): robots connecting one after
    another never get there (each gives up alone, its link closed, before the next
    tries); robots connecting in parallel do, at once. An event, not a time.
    """

    def __init__(self, ports: int, gate: int) -> None:
        self._listeners = []
        for _ in range(ports):
            listener = socket.socket()
            listener.bind(("127.0.0.1", 0))
            listener.listen(16)
            self._listeners.append(listener)
        self.ports = [int(s.getsockname()[1]) for s in self._listeners]
        self._gate = gate
        self._open: list[socket.socket] = []
        #: The most connections open at the same time.
        self.most_at_once = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="silent-slaves", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._stop.is_set() and self._listeners:
            ready, _, _ = select.select([*self._listeners, *self._open], [], [], 0.02)
            for sock in ready:
                if sock in self._listeners:
                    self._open.append(sock.accept()[0])
                elif not sock.recv(4096):  # the robot gave up and closed: gone
                    self._open.remove(sock)
                    sock.close()
                # (a request's bytes are read and never answered)
            self.most_at_once = max(self.most_at_once, len(self._open))
            if len(self._open) >= self._gate:
                self._close_all()

    def _close_all(self) -> None:
        for sock in [*self._open, *self._listeners]:
            sock.close()
        self._open, self._listeners = [], []

    def close(self) -> None:
        """Stop serving and close every socket."""
        self._stop.set()
        self._thread.join(5)
        self._close_all()


@pytest.mark.parametrize("fleet", [True, False], ids=["fleet", "no-fleet"])
def test_robots_connect_in_parallel_and_the_dead_ones_hold_up_nobody(
    tm_simulator_factory: Factory, example: ModuleType, fleet: bool
) -> None:
    live = [tm_simulator_factory() for _ in range(2)]
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        refused = int(s.getsockname()[1])  # nobody listens there once released
    silent = SilentSlaves(4, gate=4)
    try:
        ports = [live[0].port, *silent.ports[:2], refused, *silent.ports[2:], live[1].port]
        reports = example.run(ports, moves=1, watch_hz=0, fleet=fleet, retry_s=0.3)
    finally:
        silent.close()
    # The four silent robots were connecting at the same time: in parallel.
    assert silent.most_at_once == 4
    assert [r.moves_done for r in reports] == [1, 0, 0, 0, 0, 0, 1]
    assert [isinstance(r.error, TransportError) for r in reports] == [False] + [True] * 5 + [False]
    for sim in live:
        assert len([m for m in sim.motion_log() if m.target is not None]) == 1
