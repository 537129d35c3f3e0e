"""``tmmaster robot play`` never starts a command the robot program has not taken yet.

A paused TMflow project holds its robot program where it was; a command block written
just before the pause (or landing during it: a frame of a master that died, held in the
network) waits in the registers, ``seq == ack_seq + 1``, not taken, the program idle.
Play resumes the program, and its next turn takes that command. ``robot.play()`` and
``tmmaster robot play`` refuse a paused command that is not the pressing master's own
(docs/safety.md: "it presses Play only for the command this master still follows"), but
looked only at one taken (busy): a pending one of a master that died within its
heartbeat's time-to-live ran once the operator's ``tmmaster robot play`` resumed the
project, a move no live master asked for. The simulator runs the generated robot
program; its motion log is the judge.

Found by hunt 28 (fails without its fix): exit 0 "project  running", and the arm went
to FAR for the dead master.
"""

from __future__ import annotations

import socket
import struct
from collections.abc import Iterator

import pytest

from pendant import press_play_pause
from tmmaster import Pose, Robot, TimeoutPolicy
from tmmaster._channels import Command, CommandKind
from tmmaster._cli import main
from tmmaster.sim import Simulator

FAR = Pose(300, 200, 200, 180, 0, 90)
#: The longest time-to-live, in real time: the dead master is "alive" to the program for
#: the whole test (a second or two).
LONG = TimeoutPolicy(heartbeat_ttl_s=10.0)


@pytest.fixture
def sim() -> Iterator[Simulator]:
    with Simulator(time_scale=1) as simulator:
        yield simulator


def deliver(port: int, address: int, words: list[int]) -> None:
    """One FC16 request on a connection of its own, as a frame held in the network lands."""
    pdu = struct.pack(f">BHHB{len(words)}H", 16, address, len(words), 2 * len(words), *words)
    frame = struct.pack(">HHHB", 7, 0, len(pdu) + 1, 1) + pdu
    with socket.create_connection(("127.0.0.1", port), timeout=2.0) as link:
        link.sendall(frame)
        assert link.recv(260)[7] == 16  # written (not an exception answer)


def let_run(sim: Simulator, ticks: int) -> None:
    start = sim.ticks
    sim.wait_for(lambda: sim.ticks >= start + ticks, timeout=5.0)


def pending_command_of_a_dead_master(sim: Simulator) -> None:
    """The operator paused the idle project; a master's command (to FAR) landed in the
    paused project's registers, and the master died."""
    with Robot("127.0.0.1", sim.port, gripper=None, timeouts=LONG) as first:
        first.wait_until_ready()
        ticket = first._channel.prepare(Command(CommandKind.PTP, FAR, speed=50))
        ((block, words),) = ticket.plan
        press_play_pause(sim)  # the operator's Pause
        sim.wait_for(lambda: bool(sim.field("paused")), timeout=2.0)
        deliver(sim.port, block.address, words)
        first._heartbeat.stop()  # the master is gone: no close, no clean-up
    let_run(sim, 10)
    assert sim.field("seq") == ticket.seq != sim.field("ack_seq")  # pending, not taken


def test_robot_play_never_starts_a_dead_masters_pending_command(
    sim: Simulator, capsys: pytest.CaptureFixture[str]
) -> None:
    pending_command_of_a_dead_master(sim)
    home = sim.tcp_pose()
    code = main(["robot", "play", "--host", "127.0.0.1", "--port", str(sim.port)])
    let_run(sim, 50)
    assert sim.motion_log() == ()
    assert sim.tcp_pose().is_close(home, mm=0.01, deg=0.01)
    assert code == 4
    assert "press Stop" in capsys.readouterr().err


def test_robot_play_on_a_stopped_project_runs_no_command_left_from_before(
    sim: Simulator, capsys: pytest.CaptureFixture[str]
) -> None:
    """The same command left pending, then the project stopped (the pendant's Stop):
    Play starts the project from the beginning, whose start-up rule consumes the
    command unrun. ``robot play`` presses Play there, and the arm stays."""
    pending_command_of_a_dead_master(sim)
    home = sim.tcp_pose()
    sim.call(lambda: sim._controller.bank.set("stop_project", True))  # the Stop button
    sim.wait_for(lambda: not sim.field("project_running"), timeout=2.0)
    assert main(["robot", "play", "--host", "127.0.0.1", "--port", str(sim.port)]) == 0
    assert capsys.readouterr().out == "project  running\n"
    seq = sim.field("seq")
    sim.wait_for(lambda: sim.field("ack_seq") == seq, timeout=3.0)  # consumed
    let_run(sim, 50)
    assert sim.motion_log() == ()
    assert sim.tcp_pose().is_close(home, mm=0.01, deg=0.01)
