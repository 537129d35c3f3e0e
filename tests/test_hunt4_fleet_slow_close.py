"""Fleet.close() while one robot's link is slow, or was just closed by the device.

Two robots of one Fleet are each on a long move. Robot ``b`` sits behind a FaultProxy:
either every request of its link is delayed (each answer comes late, well inside the
request timeout: a slow link, nothing lost), or its connection has just been closed by
the far end (a new one is taken at once). Then ``Fleet.close()`` runs. docs/safety.md:
the close stops every robot in parallel within its budget and returns the names of the
robots whose stop it could not confirm. The judge is what the simulators did: nothing
starts after the close, nothing runs twice, a robot the close did not name is stopped
short of its target and stays at rest, and on ``tmflow`` (the program expires the
command of a master gone silent) even a named one does not run on to its target.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, at_rest, check
from sim_speeds import SUITE_TICK_HZ
from tmmaster import Fleet, PollPolicy, Pose, RetryPolicy, Robot, TimeoutPolicy, TMMasterError
from tmmaster.sim import Simulator, Timing

A = Pose(300, -200, 150, 180, 0, 90)
FAR = Pose(300, 250, 200, 180, 0, 90)  # about 8 s away from A at SLOW (40 simulated s)
#: The simulators run SCALE times real time, and the long moves at SLOW %: as long in
#: wall time as at 5 % in real time (the fleet's close, the link's delays and the tmflow
#: program's master_ttl_ms are wall-clock windows); the setup move to A takes a fifth.
SCALE = 5.0
SLOW = 1
#: Each request of b's slow link waits this long in the proxy (its timeout: 1 s).
SLOW_S = 0.15
VERY_SLOW_S = 0.6


@dataclass
class Cell:
    sims: dict[str, Simulator]
    proxy: FaultProxy
    fleet: Fleet
    robots: dict[str, Robot]
    issued: dict[str, list[Issued]] = field(default_factory=dict)
    threads: list[threading.Thread] = field(default_factory=list)

    def move_far(self, name: str) -> None:
        robot, command = self.robots[name], Issued(FAR, time.monotonic())
        self.issued[name].append(command)

        def run() -> None:
            try:
                robot.move_to(FAR, speed=SLOW)
            except TMMasterError as exc:
                command.outcome = type(exc).__name__
            else:
                command.outcome = "done"
            command.ended_at = time.monotonic()

        thread = threading.Thread(target=run, name=f"move-{name}")
        thread.start()
        self.threads.append(thread)

    def wait_moving(self, *names: str) -> None:
        """Each named robot took its move to FAR and its arm left A."""
        for name in names:
            took_it, left_a = moving(self.sims[name])
            self.sims[name].wait_for(took_it, timeout=5)
            self.sims[name].wait_for(left_a, timeout=5)

    def check_stopped_short(
        self, names: list[str], goals: dict[str, Pose], why: str, closed_at: float
    ) -> None:
        """Each named robot is at rest short of its goal and stays there (30 ticks).

        The robots are watched together, and then none has started a motion since
        ``closed_at``.
        """
        rests: dict[str, tuple[Pose, int]] = {}
        # Watched together: each look compares every named arm with its previous look,
        # 0.05 s (5 ticks) apart; all of them still at once is at rest.
        still = [at_rest(self.sims[name]) for name in names]
        self.sims["a"].wait_for(lambda: all([s() for s in still]), timeout=10, interval=0.05)
        for name in names:
            sim = self.sims[name]
            rest = sim.tcp_pose()
            assert rest.distance_to(goals[name]) > 50, f"{name} ran on to {rest} ({why})"
            rests[name] = rest, sim.ticks
        for name, (rest, ticks) in rests.items():
            sim = self.sims[name]
            sim.wait_for(ticked(sim, ticks + 30), timeout=5)
            assert sim.tcp_pose().is_close(rest), f"{name} moved again after it stopped"
        for name, sim in self.sims.items():
            late = [m for m in sim.motion_log() if m.wall_time > closed_at]
            assert not late, f"{name}: motions started after Fleet.close(): {late}"


def moving(sim: Simulator) -> tuple[Callable[[], bool], Callable[[], bool]]:
    """For ``sim.wait_for``: the robot took its move to FAR; its arm left A."""
    return (lambda: len(sim.motion_log()) == 2), (lambda: sim.tcp_pose().distance_to(A) > 5)


def ticked(sim: Simulator, ticks: int) -> Callable[[], bool]:
    """For ``sim.wait_for``: the simulator has run ``ticks`` ticks."""
    return lambda: sim.ticks >= ticks


@contextmanager
def cell(profile: str) -> Iterator[Cell]:
    # The start-up (0.2 s by default) is not what these tests are about. 100 Hz, as at
    # real time: 0.05 simulated s a tick.
    timing = Timing(tick_hz=SUITE_TICK_HZ, init_time_s=0.02)
    with (
        Simulator(profile, time_scale=SCALE, timing=timing) as sim_a,
        Simulator(profile, time_scale=SCALE, timing=timing) as sim_b,
        FaultProxy(sim_b.port) as proxy,
    ):
        fleet = Fleet()
        options = dict(
            profile=profile,
            gripper=None,
            link=fleet,
            polling=PollPolicy(interval_s=0.02),
            retry=RetryPolicy(attempts=4, total_time_s=1.0, initial_backoff_s=0.05, jitter_s=0),
            timeouts=TimeoutPolicy(request_s=1.0),
        )
        robots = {
            "a": Robot("127.0.0.1", sim_a.port, name="a", **options),  # type: ignore[arg-type]
            "b": Robot("127.0.0.1", proxy.port, name="b", **options),  # type: ignore[arg-type]
        }
        here = Cell({"a": sim_a, "b": sim_b}, proxy, fleet, robots)
        try:
            for robot in robots.values():
                robot.connect()
                robot.wait_until_ready(timeout_s=5)
            # Both arms to A at once: then each on its long move.
            motions = {name: robot.start_move(A, speed=100) for name, robot in robots.items()}
            for name, motion in motions.items():
                motion.wait()
                here.issued[name] = [Issued(A, 0.0, 0.0, "done")]
            yield here
        finally:
            fleet.close()
            for robot in robots.values():
                robot.close()
            for thread in here.threads:
                thread.join(10)


def slow_link(c: Cell) -> None:
    c.proxy.add(Rule("delay", delay_s=SLOW_S, times=10**9))


def slower_than_the_budget(c: Cell) -> None:
    # Each request still answered within its 1 s timeout, but a Stop and its cancel
    # record (and the reads around them) take longer than the 0.5 s budget.
    c.proxy.add(Rule("delay", delay_s=VERY_SLOW_S, times=10**9))


def closed_by_the_far_end(c: Cell) -> None:
    c.proxy.outage(0.0)  # b's connection closed now; a new one is taken at once


@pytest.mark.parametrize("fault", [slow_link, slower_than_the_budget, closed_by_the_far_end])
@pytest.mark.parametrize("profile", ["tmflow", "article"])
@pytest.mark.parametrize("budget_s", [0.5, 2.0])
def test_fleet_close_with_a_slow_or_dropped_link_leaves_nothing_running(
    profile: str, fault: Callable[[Cell], None], budget_s: float
) -> None:
    with cell(profile) as c:
        c.move_far("a")
        c.move_far("b")
        c.wait_moving("a", "b")
        fault(c)
        closed_at = time.monotonic()
        unconfirmed = c.fleet.close(timeout_s=budget_s)
        for thread in c.threads:
            thread.join(15)
            assert not thread.is_alive()
        for name, sim in c.sims.items():
            outcome = c.issued[name][-1].outcome
            assert outcome != "done", f"{name}: the move given up returned done"
            late = [m for m in sim.motion_log() if m.wall_time > closed_at]
            assert not late, f"{name}: motions started after Fleet.close(): {late}"
            check(c.issued[name], sim.motion_log())
        # Confirmed (or tmflow: the program expires a silent master's move within
        # master_ttl_ms, 2 s): at rest short of FAR (8 s away), and it stays there. An
        # article robot whose Stop failed is reported, and may run on.
        names = [n for n in c.sims if n not in unconfirmed or profile != "article"]
        c.check_stopped_short(names, {"a": FAR, "b": FAR}, f"{unconfirmed=}", closed_at)
        assert "a" not in unconfirmed, unconfirmed


B_TARGET = Pose(300, 150, 200, 180, 0, 90)  # about 6 s from A at SLOW


@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_fleet_close_during_a_slow_command_write_stops_what_it_started(profile: str) -> None:
    # b's command write reaches the robot only 0.6 s after it was sent (its answer
    # within the 1 s request timeout): the fleet closes while it is on its way. The
    # close waits for it and gives it up: the robot may take it after close() was
    # called, but then stops it; nothing starts after close() returned.
    with cell(profile) as c:
        c.move_far("a")
        c.wait_moving("a")
        command_block = 9000 if profile == "tmflow" else 0x0200
        c.proxy.add(Rule("delay", function_code=16, address=command_block, delay_s=VERY_SLOW_S))
        command = Issued(B_TARGET, time.monotonic())
        c.issued["b"].append(command)

        def run() -> None:
            try:
                c.robots["b"].move_to(B_TARGET, speed=SLOW)
            except TMMasterError as exc:
                command.outcome = type(exc).__name__
            else:
                command.outcome = "done"
            command.ended_at = time.monotonic()

        thread = threading.Thread(target=run, name="move-b")
        thread.start()
        c.threads.append(thread)
        c.sims["b"].wait_for(lambda: c.proxy.played("delay"), timeout=5)
        unconfirmed = c.fleet.close(timeout_s=0.5)
        closed_at = time.monotonic()
        thread.join(15)
        assert not thread.is_alive()
        assert command.outcome != "done", command
        for name, sim in c.sims.items():
            late = [m for m in sim.motion_log() if m.wall_time > closed_at]
            assert not late, f"{name}: motions started after Fleet.close() returned: {late}"
        c.check_stopped_short(["a", "b"], {"a": FAR, "b": B_TARGET}, f"{unconfirmed=}", closed_at)
        assert unconfirmed == (), unconfirmed
