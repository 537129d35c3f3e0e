"""A withdraw (tmflow) decides from the program's feedback whether its command ran:
hostile interleavings of the program's writes and the master's reads.

The program takes a number at most once and names whose command it took
(``ack_session``, 9106); a master that gives a command up reads that answer. These
cases put the program's steps between two reads of the master, deterministically: the
program's link to its slave is held (its next request waits) and released at a named
point. The simulator runs the generated robot program; its motion record is the judge.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from tmmaster import Pose, Robot
from tmmaster._channels import Command, CommandKind
from tmmaster.sim import Simulator

LEFT = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 200, 200, 180, 0, 90)


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
