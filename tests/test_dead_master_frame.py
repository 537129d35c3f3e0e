"""A command frame of a master that died lands late: the next master never runs it.

A master process killed (or its machine cut off) while its command write was on the
wire leaves that frame to the network: its TCP stack, a gateway or a proxy may deliver
it long after the master is gone, when another master is connected and beating. The
frame carries the number the dead master read as next (``ack_seq + 1``); unless that
number is used up, the program would take it as the new master's heartbeat keeps it
alive. The simulator runs the generated robot program, and its motion record is the
judge.
"""

from __future__ import annotations

import socket
import struct
import time
from collections.abc import Iterator
from typing import Any

import pytest

from pendant import press_play_pause, runs_again_without_moving
from tmmaster import Pose, ProjectPausedError, Robot, RobotError, TimeoutPolicy
from tmmaster._channels import Command, CommandKind
from tmmaster.sim import Simulator

LEFT = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 200, 200, 180, 0, 90)
#: A short time-to-live: the program sees the silence within a second of wall time.
FAST = TimeoutPolicy(heartbeat_s=0.05, heartbeat_ttl_s=0.5)


@pytest.fixture
def sim() -> Iterator[Simulator]:
    with Simulator(time_scale=5) as simulator:
        yield simulator


def deliver(port: int, address: int, words: list[int]) -> None:
    """One FC16 request on a connection of its own, as a frame held in the network lands."""
    pdu = struct.pack(f">BHHB{len(words)}H", 16, address, len(words), 2 * len(words), *words)
    frame = struct.pack(">HHHB", 7, 0, len(pdu) + 1, 1) + pdu
    with socket.create_connection(("127.0.0.1", port), timeout=2.0) as link:
        link.sendall(frame)
        assert link.recv(260)[7] == 16  # written (not an exception answer)


def age_project(sim: Simulator, days: float) -> None:
    """Let the running project have run for ``days`` already (its GetNowStamp clock)."""

    def shift() -> None:
        controller: Any = sim._controller
        run = controller._execution._rt
        run.started_s -= days * 86400 * controller.stamp_scale  # simulated s per wall s

    sim.call(shift)


def frame_of_a_master_that_died(sim: Simulator) -> tuple[int, int, list[int]]:
    """A master that moved to LEFT, then died writing its next command (to FAR): that
    frame, still in the network (its number, its block's address, its words)."""
    with Robot("127.0.0.1", sim.port, gripper=None, timeouts=FAST) as first:
        first.wait_until_ready()
        first.move_to(LEFT, speed=50)
        ticket = first._channel.prepare(Command(CommandKind.PTP, FAR, speed=5))
        ((block, words),) = ticket.plan
        first._heartbeat.stop()  # the master is gone: nothing beats any more
    return ticket.seq, block.address, words


# 25 days: past GetNowStamp()'s int range (2147483647 ms, 24.8 days: then -1, [TS] 4.39,
# p. 128), where the program's heartbeat clock must go on counting.
@pytest.mark.parametrize("days", [0, 25])
def test_a_dead_masters_late_frame_never_runs_for_the_next_master(
    sim: Simulator, days: float
) -> None:
    age_project(sim, days)
    _, address, words = frame_of_a_master_that_died(sim)
    # The silence on the simulator's own clock (GetNowStamp: 20 ms a tick here), so a
    # simulator slowed by load is not looked at too early: 0.8 s, past the TTL (0.5 s)
    # and the program's next look (every 0.1 s).
    gone = sim.ticks
    sim.wait_for(lambda: sim.ticks > gone + 40, timeout=5.0)
    with Robot("127.0.0.1", sim.port, gripper=None, timeouts=FAST) as second:
        second.wait_until_ready()
        deliver(sim.port, address, words)  # the dead master's frame lands now
        landed = sim.ticks
        sim.wait_for(lambda: sim.ticks > landed + 5, timeout=3.0)
        assert [record.target for record in sim.motion_log()] == [LEFT]
        assert second.move_to(LEFT, speed=50).done  # the next master still commands


def test_a_dead_masters_late_frame_never_runs_once_another_master_claimed(
    sim: Simulator,
) -> None:
    """The next master claims the robot at once (its first command, refused here because
    the project is paused) and beats from then on: no silence ever. The dead master's
    frame, which carries the number still free, lands later and must not run."""
    seq, address, words = frame_of_a_master_that_died(sim)
    with Robot("127.0.0.1", sim.port, gripper=None, timeouts=FAST) as second:
        second.wait_until_ready()
        press_play_pause(sim)  # the operator pauses the idle project
        sim.wait_for(lambda: bool(sim.field("paused")), timeout=2.0)
        with pytest.raises(ProjectPausedError):
            second.move_to(LEFT, speed=50)  # claimed, then refused: nothing written
        press_play_pause(sim)
        sim.wait_for(lambda: not sim.field("paused"), timeout=2.0)
        # Long past the dead master's time-to-live; the second beats all along.
        beats = second._heartbeat.writes
        sim.wait_for(lambda: second._heartbeat.writes > beats + 15, timeout=5.0)
        deliver(sim.port, address, words)  # the dead master's frame lands now
        sim.wait_for(lambda: sim.field("ack_seq") == seq, timeout=3.0)
        assert sim.field("result_code") == 6  # another_master: consumed, never run
        assert [record.target for record in sim.motion_log()] == [LEFT]
        assert second.move_to(FAR, speed=50).done  # the next master still commands


def test_a_paused_move_of_a_dead_master_is_stopped_when_the_next_master_claims(
    sim: Simulator,
) -> None:
    """The next master connects within the time-to-live and commands: the dead master's
    paused move is stopped at once, so Play on the pendant never resumes it."""
    with Robot("127.0.0.1", sim.port, gripper=None, timeouts=FAST) as first:
        first.wait_until_ready()
        first.move_to(LEFT, speed=50)
        first.start_move(FAR, speed=5)
        sim.wait_for(lambda: sim.tcp_pose().distance_to(LEFT) > 20, timeout=5.0)
        press_play_pause(sim)  # the operator pauses the project mid-move
        sim.wait_for(lambda: bool(sim.field("paused")), timeout=2.0)
        first._heartbeat.stop()  # the master dies: the next starts before the TTL
        first._transport.close()  # type: ignore[attr-defined]
        with Robot("127.0.0.1", sim.port, gripper=None, timeouts=FAST) as second:
            with pytest.raises(RobotError):
                second.move_to(LEFT, speed=50)  # claims the robot, then refused
            sim.wait_for(lambda: not sim.field("project_running"), timeout=3.0)
            held = sim.tcp_pose()
            press_play_pause(sim)  # the operator presses Play
            runs_again_without_moving(sim, held, moves=2)
            assert any("another master" in line for line in sim.displayed())


def test_a_robot_that_only_reads_disturbs_no_moving_master(sim: Simulator) -> None:
    with Robot("127.0.0.1", sim.port, gripper=None, timeouts=FAST) as master:
        master.wait_until_ready()
        master.move_to(LEFT, speed=50)
        motion = master.start_move(FAR, speed=5)  # several times the time-to-live
        with Robot("127.0.0.1", sim.port, gripper=None, timeouts=FAST) as observer:
            deadline = time.monotonic() + 10.0
            while not sim.tcp_pose().is_close(FAR, mm=1.0, deg=1.0):
                assert observer.status().mode == "running"
                assert time.monotonic() < deadline
                time.sleep(0.05)
        motion.wait()
        assert master.move_to(LEFT, speed=50).done


@pytest.mark.xfail(
    strict=True,
    reason="known limit (docs/safety.md, tmflow): within master_ttl_ms of its last beat, a"
    " dead master's frame is as alive as the master could be, until another master claims"
    " the robot with its first command (a robot that only reads claims nothing)",
)
def test_a_master_restarted_within_the_ttl_never_runs_the_dead_ones_late_frame(
    sim: Simulator,
) -> None:
    _, address, words = frame_of_a_master_that_died(sim)
    with Robot("127.0.0.1", sim.port, gripper=None, timeouts=FAST) as second:
        second.wait_until_ready()  # at once: no silence for the program to see
        deliver(sim.port, address, words)
        landed = sim.ticks
        sim.wait_for(lambda: sim.ticks > landed + 5, timeout=3.0)
        assert [record.target for record in sim.motion_log()] == [LEFT]
