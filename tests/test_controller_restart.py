"""A robot controller restarted under a connected master (a power cycle, the TMflow
project reloaded): the robot program's registers come back at 0, sequence numbers,
``ack_seq``, ``done_seq`` and the sessions alike, and the program starts afresh.

The simulator has no restart of its own; :func:`restart_controller` models one on the
simulated controller: the project stops, every register of the robot program (9000 and
up) reads 0, and the project starts again from the beginning. The judge is the
simulator's motion log.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, attempt, check, wait_braked
from tmmaster import Fleet, PollPolicy, Pose, RetryPolicy, Robot, TimeoutPolicy, TMMasterError
from tmmaster.sim import Simulator, Timing

START = Pose(300, -200, 150, 180, 0, 90)
STALE = Pose(300, -200, 180, 180, 0, 90)
NEXT = Pose(250, 0, 160, 180, 0, 90)
FAR = Pose(300, 200, 150, 180, 0, 90)


#: The robot program's registers that a restart leaves at 0 (the handshake's; the target
#: and speed words read 0 too, but no frame is taken on them alone).
RESET = (
    *("command", "seq", "ext_seq", "command_session", "command_boot"),
    *("master_heartbeat", "master_ttl_ms", "master_session"),
    *("ack_seq", "done_seq", "robot_state", "result_code", "heartbeat", "ack_session"),
    "boot_id",
)


def restart_controller(sim: Simulator) -> None:
    """The controller restarts: project stopped, program registers at 0, project started."""

    sim.call(lambda: sim._controller.bank.set("stop_project", True))
    sim.wait_for(lambda: not sim.field("project_running"), timeout=5.0)
    # A restart takes seconds; the arm has braked long before the project starts again.
    # Started while it still braked, the program's start-up ChangeTCP() failed ("the tool
    # cannot change while the arm moves"), seen under load.
    wait_braked(sim, ticks=3)

    def clear() -> None:
        for name in RESET:
            sim._controller.bank.set(name, 0)

    sim.call(clear)
    sim.press_play()
    sim.wait_for(lambda: bool(sim.field("project_running")), timeout=5.0)


@pytest.fixture
def sim() -> Iterator[Simulator]:
    with Simulator(profile="tmflow", time_scale=20.0, timing=Timing(tick_hz=50.0)) as simulator:
        yield simulator


#: How the master of these tests retries a request (about 2 s in all).
RETRY = RetryPolicy(attempts=8, total_time_s=2.0, initial_backoff_s=0.02)


def robot_through(
    proxy: FaultProxy, link: Fleet | None = None, retry: RetryPolicy = RETRY
) -> Robot:
    """A tmflow master behind ``proxy``: 0.3 s requests, a 0.5 s acknowledgement."""
    return Robot(
        "127.0.0.1",
        proxy.port,
        link=link,
        profile="tmflow",
        gripper=None,
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(request_s=0.3, ack_timeout_s=0.5, motion_margin_s=1.0),
        retry=retry,
    )


@pytest.mark.parametrize("lands", ["before the first beat", "after the first beat"])
def test_a_write_held_across_a_controller_restart_never_runs(sim: Simulator, lands: str) -> None:
    """The master's first command (number 1) and its resend are held in the network; the
    master gives it up (its cancel record uses number 1 up). The controller restarts:
    ``ack_seq`` is 0 again, so number 1 is free. The held frames land, of the master
    still beating, before its first beat after the restart or after it."""
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy, robot_through(proxy) as robot:
        robot.wait_until_ready()
        landed = threading.Event()
        proxy.add(Rule("hold", function_code=16, address=9000, release=landed, times=2))
        assert attempt(robot, STALE, issued) == "CommandStateUnknownError"
        assert sim.field("ack_seq") == 1  # the cancel record used the number up
        restart_controller(sim)
        if lands == "after the first beat":
            sim.wait_for(lambda: sim.field("master_session") != 0, timeout=2.0)
        landed.set()
        proxy.wait_held()
        start = sim.ticks
        sim.wait_for(lambda: sim.ticks >= start + 10, timeout=5.0)  # 4 simulated s
        check(issued, sim.motion_log())
        assert [r.target for r in sim.motion_log()] == []
        # The master still commands, once the program has its beat again (a command
        # written before that is refused as another master's: nothing moves).
        sim.wait_for(lambda: sim.field("master_session") != 0, timeout=2.0)
        assert attempt(robot, NEXT, issued) == "done"
    check(issued, sim.motion_log())


def test_a_resent_write_held_across_a_restart_never_runs_twice(sim: Simulator) -> None:
    """The first copy of the master's command 1 is held; its resend runs, and the move is
    done. The controller restarts (``ack_seq`` 0 frees number 1), the master beats
    again, and the held first copy lands: the same command would run a second time."""
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy, robot_through(proxy) as robot:
        robot.wait_until_ready()
        landed = threading.Event()
        proxy.add(Rule("hold", function_code=16, address=9000, release=landed, times=1))
        assert attempt(robot, STALE, issued) == "done"
        restart_controller(sim)
        sim.wait_for(lambda: sim.field("master_session") != 0, timeout=2.0)
        landed.set()
        proxy.wait_held()
        start = sim.ticks
        sim.wait_for(lambda: sim.ticks >= start + 10, timeout=5.0)  # 4 simulated s
        check(issued, sim.motion_log())


def cut_by_a_restart(sim: Simulator, issued: list[Issued]) -> Any:
    """A move to FAR whose project a restart stops while it runs; its motion, given up."""
    with FaultProxy(sim.port) as proxy, robot_through(proxy) as robot:
        robot.wait_until_ready()
        command = Issued(FAR, time.monotonic())
        issued.append(command)
        motion = robot.start_move(FAR, speed=20)
        sim.wait_for(lambda: sim.field("ack_seq") == 1, timeout=2.0)
        restart_controller(sim)  # the arm stops with the project
        with pytest.raises(TMMasterError) as failed:
            motion.wait()
        command.outcome, command.ended_at = type(failed.value).__name__, time.monotonic()
    return motion


def test_a_move_cut_by_a_restart_is_never_reported_done(sim: Simulator) -> None:
    """A restart mid-move leaves ``ack_seq`` and ``done_seq`` at 0, the master's number
    being 1, and the program draws a new ``boot_id``: the wait never reads the move done,
    it names the restart, and it presses no Stop on the project's new run."""
    issued: list[Issued] = []
    motion = cut_by_a_restart(sim, issued)
    assert issued[-1].outcome == "CommandRejectedError"
    assert sim.field("done_seq") == 0
    assert len(sim.motion_log()) == 1
    assert sim.field("project_running")
    assert not motion.done
    check(issued, sim.motion_log())


def test_a_move_cut_by_a_restart_is_not_reported_withdrawn(sim: Simulator) -> None:
    """The restart erased the acknowledgement before the master's first poll: the master
    cannot read that the arm had started, so it never reports the command withdrawn."""
    motion = cut_by_a_restart(sim, [])
    assert len(sim.motion_log()) == 1  # the arm started
    assert not motion.withdrawn


def test_a_first_copy_held_across_a_restart_during_its_resend_never_runs(
    sim: Simulator, driver_or_fleet: Fleet | None
) -> None:
    """The first copy of command 1 is held; the master resends it and the move starts. No
    wait polls it (``start_move``), so the master beats on with the session of that
    command. The controller restarts mid-move (``ack_seq`` 0 frees number 1), the master
    beats again, and the held first copy lands: it carries the ``boot_id`` of the
    program's earlier start and is consumed unrun."""
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy, robot_through(proxy, driver_or_fleet) as robot:
        robot.wait_until_ready()
        landed = threading.Event()
        proxy.add(Rule("hold", function_code=16, address=9000, release=landed, times=1))
        command = Issued(FAR, time.monotonic())
        issued.append(command)
        motion = robot.start_move(FAR, speed=20)  # its resend, taken
        sim.wait_for(lambda: sim.field("ack_seq") == 1, timeout=2.0)
        restart_controller(sim)
        sim.wait_for(lambda: sim.field("master_session") != 0, timeout=2.0)
        landed.set()
        proxy.wait_held()
        start = sim.ticks
        sim.wait_for(lambda: sim.ticks >= start + 10, timeout=5.0)  # 4 simulated s
        assert [r.target for r in sim.motion_log()] == [FAR]  # the resend's, cut short
        with pytest.raises(TMMasterError) as failed:
            motion.wait()
        command.outcome, command.ended_at = type(failed.value).__name__, time.monotonic()
    check(issued, sim.motion_log())


def test_a_resent_command_done_leaves_a_new_session_and_the_project_running(
    sim: Simulator,
) -> None:
    """Once a command written twice is done, the master beats with a new session: the
    program's watchdog takes that for no other master (the project runs on), and the
    next command, of the new session, runs."""
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy, robot_through(proxy) as robot:
        robot.wait_until_ready()
        proxy.add(Rule("drop_request", function_code=16, address=9000, times=1))
        assert attempt(robot, STALE, issued) == "done"
        first = sim.field("command_session")
        sim.wait_for(lambda: sim.field("master_session") not in (0, first), timeout=2.0)
        assert sim.field("project_running")
        assert attempt(robot, NEXT, issued) == "done"
        assert sim.field("command_session") == sim.field("master_session") != first
    check(issued, sim.motion_log())
