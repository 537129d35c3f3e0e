"""Closing a Fleet while one robot's command is stuck in the network and another moves.

Two tmflow robots share one Fleet. Robot ``b``'s command write (FC16 to the command
block) is held in the network by a FaultProxy -- or never arrives and the proxy closes
``b``'s link -- while robot ``a`` is in the middle of a long move, and the fleet is
closed. Afterwards the held frame lands and the simulators run on. The simulators'
motion logs judge: ``b``'s given-up command never runs after the close, ``a``'s move is
stopped and never resumes, and nothing runs twice.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, check
from tmmaster import Fleet, PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster.sim import Simulator, Timing

A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(300, -200, 180, 180, 0, 90)
FAR = Pose(250, 0, 400, 180, 0, 90)  # seconds away from A at FAR_SPEED (a's time_scale)
#: a's simulator runs A_SCALE times real time and its long move at FAR_SPEED %: the whole
#: move about 1.7 s of wall time (1.46 s at 10 % and twice real time, as before); the
#: setup move to A takes a quarter of that.
A_SCALE = 8.0
FAR_SPEED = 2
#: The masters' heartbeat: the program expires a command once it has been silent for
#: TTL_S (master_ttl_ms). 1 s, not the default 2 s, so that the held writes' timeouts,
#: set against it, are waited out in half the time; not less: a loaded machine once kept
#: a beat from running for that long (tests/test_heartbeat.py).
HEARTBEAT = {"heartbeat_s": 0.25, "heartbeat_ttl_s": 1.0}
TTL_S = HEARTBEAT["heartbeat_ttl_s"]


@dataclass
class Cell:
    """Two robots of one fleet; ``b`` behind a FaultProxy; what each was told to do."""

    sim_a: Simulator
    sim_b: Simulator
    proxy: FaultProxy
    fleet: Fleet
    robot_a: Robot
    robot_b: Robot
    release: threading.Event = field(default_factory=threading.Event)
    issued_a: list[Issued] = field(default_factory=list)
    issued_b: list[Issued] = field(default_factory=list)
    threads: list[threading.Thread] = field(default_factory=list)
    closed_at: float = 0.0

    def move_in_thread(self, robot: Robot, target: Pose, issued: list[Issued]) -> None:
        """``robot.move_to(target)`` on its own thread, its outcome recorded in ``issued``."""
        command = Issued(target, time.monotonic())
        issued.append(command)

        def run() -> None:
            try:
                robot.move_to(target, speed=FAR_SPEED if target == FAR else 80)
            except BaseException as exc:
                command.outcome = type(exc).__name__
            else:
                command.outcome = "done"
            command.ended_at = time.monotonic()

        thread = threading.Thread(target=run)
        thread.start()
        self.threads.append(thread)

    def a_moves_and_b_writes(self) -> None:
        """``a`` on its long move, then ``b``'s write of B meets the proxy's fault."""
        self.move_in_thread(self.robot_a, FAR, self.issued_a)
        self.sim_a.wait_for(lambda: FAR in targets(self.sim_a), timeout=5.0)
        self.move_in_thread(self.robot_b, B, self.issued_b)
        self.sim_b.wait_for(lambda: any(s.action != "pass" for s in self.proxy.seen), timeout=5)

    def close_fleet(self, **options: float) -> tuple[str, ...]:
        assert self.threads[-1].is_alive()  # b still waits on its write
        self.closed_at = time.monotonic()
        unconfirmed = self.fleet.close(**options)
        for thread in self.threads:
            thread.join(15)
            assert not thread.is_alive()
        return unconfirmed

    def judge(self) -> None:
        """What the robots did after the close: nothing new, nothing twice, ``a`` at rest."""
        settle(self.sim_a, self.sim_b)
        resting = self.sim_a.tcp_pose()
        settle(self.sim_a)
        assert [c.outcome for c in (self.issued_a[-1], self.issued_b[-1])].count("done") == 0
        check(self.issued_a, self.sim_a.motion_log())
        check(self.issued_b, self.sim_b.motion_log())
        for sim in (self.sim_a, self.sim_b):
            late = [m for m in sim.motion_log() if m.wall_time > self.closed_at]
            assert not late, f"motions started after Fleet.close(): {late}"
        assert targets(self.sim_a) == [A, FAR]
        assert targets(self.sim_b) == [A]
        assert not resting.is_close(FAR)  # a stopped short of its far target
        assert self.sim_a.tcp_pose().is_close(resting)  # and at rest: it never resumed


def targets(sim: Simulator) -> list[Pose]:
    return [m.target for m in sim.motion_log() if m.target is not None]


def settle(*sims: Simulator) -> None:
    """Let each simulator run 10 more ticks (together)."""
    ticks = [sim.ticks for sim in sims]
    sims[0].wait_for(
        lambda: all(sim.ticks >= t + 10 for sim, t in zip(sims, ticks, strict=True)), timeout=5.0
    )


@contextmanager
def cell(request_s: float = 1.5 * TTL_S, heartbeat: dict[str, float] = HEARTBEAT) -> Iterator[Cell]:
    """The two robots, ready, each having moved to A once (b through the proxy).

    ``request_s``: how long b's held write waits on its answer (1.5 TTL_S: far longer
    than the fleet takes to close, and than the program's ``master_ttl_ms``; 0.5 TTL_S:
    less than ``master_ttl_ms``). The ratios of 3 s and 1 s to the default 2 s TTL.
    ``heartbeat``: the masters' TimeoutPolicy heartbeat settings ({}: the defaults).
    """
    timing = Timing(tick_hz=50.0)
    with (
        Simulator("tmflow", time_scale=A_SCALE, timing=timing) as sim_a,
        Simulator("tmflow", time_scale=20.0, timing=timing) as sim_b,
        FaultProxy(sim_b.port) as proxy,
    ):
        fleet = Fleet()
        options = dict(
            gripper=None,
            link=fleet,
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(
                request_s=request_s, ack_timeout_s=5.0, motion_margin_s=1.0, **heartbeat
            ),
        )
        robot_a = Robot("127.0.0.1", sim_a.port, profile="tmflow", name="a", **options)  # type: ignore[arg-type]
        robot_b = Robot("127.0.0.1", proxy.port, profile="tmflow", name="b", **options)  # type: ignore[arg-type]
        here = Cell(sim_a, sim_b, proxy, fleet, robot_a, robot_b)
        try:
            for robot, issued in ((robot_a, here.issued_a), (robot_b, here.issued_b)):
                robot.connect()
                robot.wait_until_ready(timeout_s=5)
                robot.move_to(A, speed=80)
                issued.append(Issued(A, 0.0, 0.0, "done"))
            yield here
        finally:
            here.release.set()
            here.fleet.close()
            for robot in (robot_a, robot_b):
                robot.close()


def test_a_held_command_that_lands_after_the_robot_saw_the_master_gone_never_runs() -> None:
    with cell() as c:
        c.proxy.add(Rule("hold", function_code=16, address=9000, release=c.release))
        c.a_moves_and_b_writes()
        c.close_fleet()
        # The program sees b's master silent for master_ttl_ms and uses up number 2
        # (cancelled); only then does the held frame carrying number 2 land.
        c.sim_b.wait_for(lambda: c.sim_b.field("ack_seq") == 2, timeout=10.0)
        c.release.set()
        c.proxy.wait_held()
        c.judge()


@pytest.mark.parametrize("request_s", [1.5 * TTL_S, 0.5 * TTL_S])
def test_a_held_command_that_lands_right_after_fleet_close_never_runs(request_s: float) -> None:
    # close(timeout_s=0.5) runs out while b's write is held: close waits the write out
    # and still delivers its give-up. With request_s=0.5 TTL_S, close returns before the
    # program could see b's master silent (TTL_S): only that give-up keeps B from running.
    with cell(request_s) as c:
        c.proxy.add(Rule("hold", function_code=16, address=9000, release=c.release))
        c.a_moves_and_b_writes()
        c.close_fleet(timeout_s=0.5)
        c.release.set()  # the held frame lands now, after the fleet gave b up
        c.proxy.wait_held()
        c.judge()


def test_closing_the_fleet_while_the_proxy_has_cut_b_off_runs_nothing_late() -> None:
    # The default heartbeat (2 s TTL) and a 3 s request timeout: the 1 s outage stays
    # well inside the TTL, so b's link being cut does not by itself expire its command.
    with cell(3.0, heartbeat={}) as c:
        # b's write never reaches the arm; while b waits on its answer the proxy closes
        # b's link and refuses it for a while: Fleet.close() runs during that outage.
        c.proxy.add(Rule("drop_request", function_code=16, address=9000))
        c.a_moves_and_b_writes()
        c.proxy.outage(1.0)
        c.close_fleet()
        # Number 2 is used up (the withdraw, or the program seeing b's master silent),
        # or, when the withdraw could not be answered through the outage (a loaded
        # machine), b's master stopped the project: either way nothing is left to run.
        c.sim_b.wait_for(
            lambda: c.sim_b.field("ack_seq") == 2 or not c.sim_b.field("project_running"),
            timeout=10.0,
        )
        c.judge()
