"""A master (tmflow) reads from the program's feedback whether its command ran: hostile
interleavings of the program's writes and the master's reads.

The program takes a number at most once and names whose command it took
(``ack_session``, 9106); a master that gives a command up reads that answer. These
cases put the program's steps between two reads of the master, deterministically: the
program's link to its slave is held (its next request waits) and released at a named
point. The simulator runs the generated robot program; its motion record is the judge.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import pytest

from tmmaster import Pose, Robot, RobotError, TimeoutPolicy
from tmmaster._channels import Command, CommandKind
from tmmaster.sim import Simulator

LEFT = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 200, 200, 180, 0, 90)
ACK_SEQ = 9100
ACK_SESSION = 9106


@pytest.fixture
def sim() -> Iterator[Simulator]:
    with Simulator(time_scale=5) as simulator:
        yield simulator


def hold_program_link(sim: Simulator, held: bool) -> None:
    """Hold the program's link to its slave (each next Modbus request waits), or let go."""

    def apply() -> None:
        controller: Any = sim._controller
        controller.link_free_at = 1e12 if held else -1.0

    sim.call(apply)


def hold_after_write(
    sim: Simulator, monkeypatch: pytest.MonkeyPatch, address: int, wanted: Callable[[int], bool]
) -> None:
    """Once the program writes a ``wanted`` value at ``address``, hold its link there."""
    controller: Any = sim._controller
    real_after_write = controller.after_write

    def after_write(table: Any, start: int, values: Any) -> None:
        real_after_write(table, start, values)
        if start == address and len(values) == 1 and wanted(int(values[0])):
            controller.link_free_at = 1e12

    monkeypatch.setattr(controller, "after_write", after_write)


def test_a_command_taken_and_stopped_between_the_withdraws_two_reads_counts_as_taken(
    sim: Simulator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The master gives up a command the program has not acknowledged. Just before the
    withdraw reads the project's flags, the program takes it, the arm moves and the
    project stops (the e-stop). The arm moved: the withdraw must not report the command
    never taken (it did when it read the feedback before the flags)."""
    with Robot("127.0.0.1", sim.port, gripper=None) as robot:
        robot.wait_until_ready()
        robot.move_to(LEFT, speed=50)  # claims the robot: beating
        channel = robot._channel
        hold_program_link(sim, True)  # the program is slow to read the next command
        ticket = channel.prepare(Command(CommandKind.PTP, FAR, speed=5))
        channel.send(ticket)
        real_read = channel._read_regardless

        def meanwhile(fields: Any) -> Any:
            if fields is channel.flag_fields:
                monkeypatch.setattr(channel, "_read_regardless", real_read)
                hold_program_link(sim, False)
                sim.wait_for(lambda: sim.field("ack_seq") == ticket.seq, timeout=3.0)
                sim.wait_for(lambda: sim.tcp_pose().distance_to(LEFT) > 5, timeout=3.0)
                sim.press_estop()
                sim.wait_for(lambda: not sim.field("project_running"), timeout=3.0)
            return real_read(fields)

        monkeypatch.setattr(channel, "_read_regardless", meanwhile)
        taken = channel.withdraw_outcome(ticket)
        assert [record.target for record in sim.motion_log()] == [LEFT, FAR]  # it moved
        assert sim.field("ack_session") == channel.session
        assert taken is True


@pytest.mark.parametrize("where", ["session", "ack"])
def test_a_move_done_is_done_though_another_masters_next_command_took_the_robot(
    sim: Simulator, monkeypatch: pytest.MonkeyPatch, where: str
) -> None:
    """The first master's move was acknowledged (its own session) and is done; before
    its next poll, a second master claims the robot and the program takes that master's
    command, the next number: its poll lands after the program wrote the second master's
    session (ack_seq still the first master's number), or after the next ack_seq too.
    The first master's move ran and is done, never "from another master"."""
    near = LEFT.offset(dz=-20)
    with (
        Robot("127.0.0.1", sim.port, gripper=None) as first,
        Robot("127.0.0.1", sim.port, gripper=None) as second,
    ):
        first.wait_until_ready()
        first.move_to(LEFT, speed=50)
        motion = first.start_move(near, speed=50)
        sim.wait_for(lambda: sim.field("ack_seq") == motion.ticket.seq, timeout=3.0)
        motion.progress()  # the first master sees its move acknowledged
        sim.wait_for(lambda: sim.field("done_seq") == motion.ticket.seq, timeout=3.0)
        if where == "session":  # the second master's session (not ours, not 0)
            mine = first._channel.session
            hold_after_write(sim, monkeypatch, ACK_SESSION, lambda v: v not in (0, mine))
        else:
            hold_after_write(sim, monkeypatch, ACK_SEQ, lambda v: v == motion.ticket.seq + 1)
        # The second master claims and has the next number taken (a move where the arm
        # is: the first master's pose check still holds); the program holds there.
        later = second.start_move(near, speed=5)
        sim.wait_for(lambda: sim.field("ack_session") == second._channel.session, timeout=3.0)
        assert sim.field("done_seq") == motion.ticket.seq
        motion.wait()  # the first master's move: done
        hold_program_link(sim, False)
        assert motion.done
        later.wait()
        assert [record.target for record in sim.motion_log()] == [LEFT, near, near]


def test_a_command_that_ran_while_its_master_was_cut_off_counts_as_taken(
    sim: Simulator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The program took and finished the master's command while the master saw nothing
    of it (cut off), then saw the master gone and used up the next number (0 written to
    ack_session before that number's ack_seq). The master's withdraw reads in between:
    its own number, session 0, done: the command ran, never "not taken"."""
    policy = TimeoutPolicy(heartbeat_s=0.05, heartbeat_ttl_s=0.5)
    with Robot("127.0.0.1", sim.port, gripper=None, timeouts=policy) as robot:
        robot.wait_until_ready()
        robot.move_to(LEFT, speed=50)
        channel = robot._channel
        ticket = channel.prepare(Command(CommandKind.PTP, LEFT.offset(dz=-20), speed=50))
        channel.send(ticket)
        sim.wait_for(lambda: sim.field("done_seq") == ticket.seq, timeout=3.0)
        hold_after_write(sim, monkeypatch, ACK_SESSION, lambda v: v == 0)
        robot._heartbeat.stop()  # the master is silent: the program sees it gone
        sim.wait_for(lambda: sim.field("ack_session") == 0, timeout=3.0)
        assert sim.field("ack_seq") == ticket.seq  # the next number not acknowledged yet
        taken = channel.withdraw_outcome(ticket)
        hold_program_link(sim, False)
        assert [record.target for record in sim.motion_log()] == [LEFT, LEFT.offset(dz=-20)]
        assert taken is True


def test_a_move_stopped_and_the_project_started_again_before_the_next_poll_fails_at_once(
    sim: Simulator,
) -> None:
    """The operator stops the project during the master's move and starts it again before
    the master polls (a wait called later). The move never finishes: the master's next
    poll must say so, not wait for its deadline and then press Stop on the new run."""
    with Robot("127.0.0.1", sim.port, gripper=None) as robot:
        robot.wait_until_ready()
        robot.move_to(LEFT, speed=50)
        motion = robot.start_move(FAR, speed=5)
        sim.wait_for(lambda: sim.tcp_pose().distance_to(LEFT) > 5, timeout=3.0)
        sim.call(lambda: sim._controller.bank.set("stop_project", True))  # the Stop button
        sim.wait_for(lambda: not sim.field("project_running"), timeout=3.0)
        sim.press_play()
        sim.wait_for(lambda: bool(sim.field("project_running")), timeout=3.0)
        let_run = sim.ticks
        sim.wait_for(lambda: sim.ticks > let_run + 5, timeout=3.0)  # the start-up rule ran
        with pytest.raises(RobotError, match="motion_failed"):
            motion.wait(timeout_s=0.5)
        assert sim.field("project_running")  # not stopped again by the master
