"""examples/many_robots.py says when a robot's give-up could not be confirmed, not only
after Ctrl-C: a robot whose withdraw or stop did not get through may still be moving.
And with ``--processes``, a Ctrl-C sent to the parent alone stops the children too.

Robot 1's second command write is held in the network and its link goes down right
behind it (every reconnect refused): the master cannot know whether the robot took the
command, and cannot deliver its withdraw or stop. ``Robot.close()`` then returns False.

Found by hunt 29 ("the code users copy"); the test fails without the fix: the example
kept close()'s answer only for its Ctrl-C message, so the run's report said "FAILED
after 1 move(s): <the link error>" and nothing about an arm that may still be moving
toward a target the master had given up.

The second test fails without its fix when the SIGINT goes to the parent alone, or the
terminal hangs up: the parent waited for its children, which never got it and drove all
30 moves of their tours after it (5 s), and then said "interrupted: each robot still
open gives its command up at exit". Passing the parent's Ctrl-C on to children that
got the terminal's too hung 3 runs in 30 (the second landing inside a child's own
clean-up): the children now run in process groups of their own and get it once.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType

import pytest

from examples_support import load_example
from fault_proxy import FaultProxy, Rule
from safety_invariant import wait_braked
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "many_robots.py"
#: tmflow's command block (the move's FC16 write).
COMMAND = 9000


@pytest.fixture(scope="module")
def example() -> ModuleType:
    return load_example("many_robots")


@pytest.fixture
def proxy(tm_simulator_factory: Factory) -> Iterator[FaultProxy]:
    sim = tm_simulator_factory()
    with FaultProxy(sim.port) as p:
        yield p


def link_down_behind_the_second_move(proxy: FaultProxy) -> threading.Thread:
    proxy.add(Rule("hold", function_code=16, address=COMMAND, nth=2))

    def cut() -> None:
        deadline = time.monotonic() + 30.0
        while not proxy.played("hold") and time.monotonic() < deadline:
            time.sleep(0.005)
        proxy.outage(600.0)  # every connection closed, every reconnect refused

    thread = threading.Thread(target=cut)
    thread.start()
    return thread


def test_an_unconfirmed_give_up_is_reported_and_fails_the_run(
    tm_simulator_factory: Factory,
    proxy: FaultProxy,
    example: ModuleType,
    capsys: pytest.CaptureFixture[str],
) -> None:
    healthy = tm_simulator_factory()
    cutter = link_down_behind_the_second_move(proxy)
    try:
        reports = example.run([healthy.port, proxy.port], moves=3, watch_hz=0, retry_s=0.3)
    finally:
        cutter.join(10.0)
    assert [r.moves_done for r in reports] == [3, 1]
    assert [r.unconfirmed for r in reports] == [False, True]
    assert example.print_reports(reports) == 1
    out = capsys.readouterr().out
    assert "robot1: could NOT confirm that it gave its command up: check the arm" in out
    assert "robot0: could NOT" not in out
    # The same from a child process (--processes): the parent learns it too.
    back = example.report_from_json(json.loads(json.dumps(example.report_to_json(reports[1]))))
    assert back.unconfirmed


@pytest.mark.parametrize(
    ("to", "signum"),
    [
        ("parent", signal.SIGINT),  # a supervisor's, an IDE's stop button: the PID only
        ("group", signal.SIGINT),  # a terminal's Ctrl-C: the whole process group
        ("parent", signal.SIGHUP),  # the terminal closed
    ],
    ids=["ctrl-c-to-parent", "ctrl-c-in-terminal", "hang-up"],
)
def test_ctrl_c_to_the_parent_stops_the_children(
    tm_simulator_factory: Factory, to: str, signum: signal.Signals
) -> None:
    # --processes 2: each child drives one robot of a 30-move tour.
    sims = [tm_simulator_factory(time_scale=5.0) for _ in range(2)]
    ports = [str(sim.port) for sim in sims]
    command = [sys.executable, str(EXAMPLE), "--ports", *ports, "--processes", "2"]
    command += ["--moves", "30", "--watch-hz", "0"]
    parent = subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, process_group=0
    )
    try:
        for sim in sims:
            moving(sim)
        if to == "group":
            os.killpg(parent.pid, signum)
        else:
            parent.send_signal(signum)
        _, err = parent.communicate(timeout=60)
    finally:
        if parent.poll() is None:
            parent.kill()
            parent.communicate()
    assert parent.returncode == 130, err
    assert err.count("interrupted: every robot gave its command up") == 2, err  # each child
    for sim in sims:
        log = sim.motion_log()
        wait_braked(sim)
        assert sim.motion_log() == log  # nothing started after the parent ended
        assert len(log) < 30, f"the child drove {len(log)} of its 30 moves after the signal"


def moving(sim: Simulator) -> None:
    sim.wait_for(lambda: len(sim.motion_log()) >= 1, timeout=30.0)
