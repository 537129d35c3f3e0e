"""Review of hunt 34: a move from before a controller restart is never read as done.

Hunt 34 (1ea1b37) reads a command of another program start as never done while the
command at ``ack_seq`` is another master's (``ack_session``). After a controller restart
(the registers back at 0), another master's command numbered as this one's ran to its
end (``done_seq`` = the number), and its next number was then used up unrun (a cancel
record: ``ack_session`` 0, ``ack_seq`` one on): the command at ``ack_seq`` was then
no master's, and the ``done_seq`` the other master's command left was read as this
master's done: its move, stopped by the restart, reported finished. Now a command of
another program start is done only while ``ack_seq`` is still its number.
"""

from __future__ import annotations

import pytest

from test_controller_restart import restart_controller
from test_hunt32_same_robot import open_robot
from test_hunt34_seq_wrap import FAR, A, SimFactory
from tmmaster import TMMasterError


def test_a_move_from_before_a_restart_is_not_done_by_another_masters_number(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("tmflow", time_scale=5.0)
    with open_robot(sim, gripper=None) as first:
        mine = first.start_move(A, speed=50)
        sim.wait_for(lambda: len(sim.motion_log()) == 1, timeout=5.0)
        mine.progress()
        assert mine.ticket.acknowledged  # A saw its move taken
        # A beats no more while B moves: a beat of A's during B's move is another master's,
        # and the program gives B's command up (one master at a time), which would end B's
        # run before it is done (seen in about one run in three beside another worker).
        first._heartbeat.stop()
        restart_controller(sim)  # its move stopped short: registers at 0
        with open_robot(sim, gripper=None) as second:
            second.move_to(FAR, speed=100)  # number 1 too, run to its end
            assert second.last_motion is not None
            assert second.last_motion.ticket.seq == mine.ticket.seq == 1
            # B's next number, 2, used up unrun: its cancel record, one request.
            channel = second._channel
            command = channel._command_field
            cancel = [(command, command.code_of("none")), (sim.profile.field("seq"), 2)]
            channel.transport.write_fields(cancel, retry=False, interruptible=False)
            sim.wait_for(lambda: sim.field("ack_seq") == 2, timeout=5.0)
        assert (sim.field("ack_session"), sim.field("done_seq")) == (0, 1)
        with pytest.raises(TMMasterError, match="started again under command 1"):
            mine.wait()
    assert [m.target for m in sim.motion_log()] == [A, FAR]
