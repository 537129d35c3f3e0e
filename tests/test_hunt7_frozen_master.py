"""A master process frozen (not killed) for longer than master_ttl_ms, then resumed (tmflow).

A master's process can stop without dying: SIGSTOP, a debugger, a laptop lid, a VM
paused, a long garbage collection. Its heartbeat stops with it, so the robot program
sees it gone after ``master_ttl_ms`` and expires its command (docs/safety.md, "A command
expires with its master"): a running move is stopped (the watchdog ends the project), a
number not yet taken is used up. Then the process resumes, with every timer of its own
overdue and its requests' answers waiting in its sockets. Here the master is a real
child process, frozen with SIGSTOP and resumed with SIGCONT:

- frozen while its move runs: once resumed, its ``wait()`` must end in an error, never
  "done" (the move was cut short), and nothing moves afterwards;
- frozen while its command write is held in the network: the program uses the number
  up; the frame lands, then the master resumes and finds its write answered: its call
  must end in an error, and the command never runs.

The judge is the simulator: its motion log (tests/safety_invariant.py) and its arm.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, at_rest, check
from tmmaster import Pose
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

A = Pose(300, -200, 200, 180, 0, 90)
B = Pose(300, 200, 200, 180, 0, 90)  # a long turn of J1 at 5 %

MASTER = textwrap.dedent(
    """
    import sys
    from tmmaster import PollPolicy, Pose, Robot, TimeoutPolicy, TMMasterError

    timeouts = TimeoutPolicy(heartbeat_s=0.05, heartbeat_ttl_s=0.5, request_s=1.0)
    robot = Robot("127.0.0.1", int(sys.argv[1]), gripper=None, timeouts=timeouts,
                  polling=PollPolicy(interval_s=0.01))
    robot.connect()
    robot.wait_until_ready(timeout_s=5)
    robot.move_to(Pose(300, -200, 200, 180, 0, 90), speed=50)
    print("ready", flush=True)
    sys.stdin.readline()
    try:
        motion = robot.start_move(Pose(300, 200, 200, 180, 0, 90), speed=5)
        print("moving", flush=True)
        motion.wait()
    except TMMasterError as exc:
        print("error", type(exc).__name__, flush=True)
    else:
        print("done", flush=True)
    robot.close()
    """
)


class Master:
    """The master's child process: lines it printed, a go, freeze and resume."""

    def __init__(self, port: int) -> None:
        self.process = subprocess.Popen(
            [sys.executable, "-c", MASTER, str(port)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )

    def line(self, timeout: float = 20.0) -> str:
        """The next line it prints (fails after ``timeout``)."""
        assert self.process.stdout is not None
        ready, _, _ = select.select([self.process.stdout], [], [], timeout)
        assert ready, "the master printed nothing"
        return self.process.stdout.readline().strip()

    def go(self) -> None:
        assert self.process.stdin is not None
        self.process.stdin.write("go\n")
        self.process.stdin.flush()

    def freeze(self) -> None:
        os.kill(self.process.pid, signal.SIGSTOP)

    def resume(self) -> None:
        os.kill(self.process.pid, signal.SIGCONT)

    def close(self) -> None:
        if self.process.poll() is None:
            self.resume()
            self.process.kill()
        self.process.wait(timeout=5.0)
        for stream in (self.process.stdin, self.process.stdout, self.process.stderr):
            if stream is not None:
                stream.close()


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("tmflow", time_scale=5.0)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


@pytest.fixture
def master(proxy: FaultProxy) -> Iterator[Master]:
    child = Master(proxy.port)
    try:
        assert child.line() == "ready"
        yield child
    finally:
        child.close()


def settle(sim: Simulator) -> None:
    """20 ticks for a frame just landed to be acted on; then the arm at rest."""
    ticks = sim.ticks
    sim.wait_for(lambda: sim.ticks >= ticks + 20, timeout=5.0)
    sim.wait_for(at_rest(sim), timeout=5.0, interval=0.05)


def test_a_master_frozen_while_its_move_runs_never_reports_it_done(
    sim: Simulator, master: Master
) -> None:
    master.go()
    assert master.line() == "moving"
    sim.wait_for(lambda: len(sim.motion_log()) == 2, timeout=5.0)
    sim.wait_for(lambda: sim.tcp_pose().distance_to(A) > 20, timeout=5.0)
    master.freeze()
    frozen_at = time.monotonic()
    # The program sees the heartbeat stop: its watchdog ends the project, the arm stops.
    sim.wait_for(lambda: not sim.field("project_running"), timeout=5.0)
    settle(sim)
    held = sim.tcp_pose()
    master.resume()
    outcome = master.line()
    assert outcome.startswith("error"), outcome  # never "done": the move was cut short
    master.process.wait(timeout=10.0)
    settle(sim)
    issued = [Issued(A, 0.0, 0.0, "done"), Issued(B, 0.0, frozen_at, outcome.split()[-1])]
    check(issued, sim.motion_log())
    assert len(sim.motion_log()) == 2, sim.motion_log()
    assert sim.motion_log()[1].done_wall_time is None
    assert sim.tcp_pose().is_close(held, mm=1e-6, deg=1e-6), (held, sim.tcp_pose())


def test_a_master_frozen_while_its_write_is_held_never_runs_the_expired_number(
    sim: Simulator, proxy: FaultProxy, master: Master
) -> None:
    release = threading.Event()
    number = int(sim.field("ack_seq")) + 1
    proxy.add(Rule("hold", function_code=16, address=9000, release=release))
    master.go()
    try:
        sim.wait_for(lambda: proxy.played("hold"), timeout=5.0)
        master.freeze()  # its write waits for an answer; no beat goes out any more
        frozen_at = time.monotonic()
        # The program sees the master silent and uses its number up, unrun.
        sim.wait_for(lambda: int(sim.field("ack_seq")) == number, timeout=5.0)
    finally:
        release.set()  # the held frame lands now, on a number used up
    proxy.wait_held()
    settle(sim)
    master.resume()  # its write's answer is waiting: it finds the write answered
    lines = [master.line()]
    if lines[0] == "moving":
        lines.append(master.line())
    assert lines[-1].startswith("error"), lines
    master.process.wait(timeout=10.0)
    settle(sim)
    issued = [Issued(A, 0.0, 0.0, "done"), Issued(B, 0.0, frozen_at, lines[-1].split()[-1])]
    check(issued, sim.motion_log())
    assert len(sim.motion_log()) == 1, sim.motion_log()  # A's only
    assert sim.tcp_pose().is_close(A), sim.tcp_pose()
