"""The master's session (tmflow) against a hostile network: a frame of a master the robot
already saw replaced never hands the robot back to it.

A master that dies (killed, its machine cut off) leaves its last frames to the network:
its TCP stack resends them, in order, when the link comes back, long after the next
master claimed the robot. Its heartbeat goes out on the same link as its commands, so a
late command frame usually lands right behind a late beat of the same master. The
simulator runs the generated robot program; its motion record is the judge.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from typing import Any

import pytest

from fault_proxy import FaultProxy, Rule
from pendant import press_play_pause
from test_dead_master_frame import FAR, LEFT, deliver
from tmmaster import ProjectPausedError, Robot, RobotError, TimeoutPolicy
from tmmaster._channels import Command, CommandKind
from tmmaster.sim import Simulator

#: A time-to-live of 10 s: a beat held in the network for a moment never makes a master
#: gone; beats 0.1 s apart, so that the test sees one held soon.
SLOW = TimeoutPolicy(heartbeat_s=0.1, heartbeat_ttl_s=10.0)
BEAT = 9050


@pytest.fixture
def sim() -> Iterator[Simulator]:
    with Simulator(time_scale=5) as simulator:
        yield simulator


def let_run(sim: Simulator, ticks: int) -> None:
    start = sim.ticks
    sim.wait_for(lambda: sim.ticks >= start + ticks, timeout=5.0)


def dead_master(sim: Simulator) -> tuple[list[int], int, list[int], int]:
    """A master that moved once and died: its last beat and its next command, both still
    in the network (the beat's words, the command's address, words and number)."""
    with Robot("127.0.0.1", sim.port, gripper=None, timeouts=SLOW) as first:
        first.wait_until_ready()
        first.move_to(LEFT, speed=50)
        ticket = first._channel.prepare(Command(CommandKind.PTP, FAR, speed=5))
        ((block, words),) = ticket.plan
        first._heartbeat.stop()
        beat = first._heartbeat.next_words()  # the beat it sent with the command
    return beat, block.address, words, ticket.seq


def hold_beats(sim: Simulator, proxy: FaultProxy, release: threading.Event) -> None:
    """From now on the live master's beats are held in the network (until ``release``)."""
    proxy.add(Rule("hold", function_code=16, address=BEAT, times=1000, release=release))
    sim.wait_for(
        lambda: any(s.address == BEAT and s.action == "hold" for s in proxy.seen), timeout=3.0
    )


def test_a_dead_masters_late_beat_and_frame_never_run_once_another_claimed(
    sim: Simulator,
) -> None:
    """The next master claimed the robot (its first command, refused while paused).
    The dead master's beat, then its command, land late: the command must not run."""
    beat, address, words, seq = dead_master(sim)
    release = threading.Event()
    with (
        FaultProxy(sim.port) as proxy,
        Robot("127.0.0.1", proxy.port, gripper=None, timeouts=SLOW) as second,
    ):
        second.wait_until_ready()
        press_play_pause(sim)
        sim.wait_for(lambda: bool(sim.field("paused")), timeout=2.0)
        with pytest.raises(ProjectPausedError):
            second.move_to(LEFT, speed=50)  # claimed, then refused: nothing written
        press_play_pause(sim)
        sim.wait_for(lambda: not sim.field("paused"), timeout=2.0)
        hold_beats(sim, proxy, release)  # so that only the dead master's frames land
        deliver(sim.port, BEAT, beat)
        deliver(sim.port, address, words)
        sim.wait_for(lambda: sim.field("ack_seq") == seq, timeout=3.0)
        release.set()
        proxy.clear()
        assert sim.field("result_code") == 6  # another_master: consumed, never run
        assert [record.target for record in sim.motion_log()] == [LEFT]
        assert second.move_to(LEFT, speed=50).done  # the next master still commands


def test_a_dead_masters_late_beat_never_stops_the_next_masters_move(sim: Simulator) -> None:
    beat, _address, _words, _seq = dead_master(sim)
    release = threading.Event()
    with (
        FaultProxy(sim.port) as proxy,
        Robot("127.0.0.1", proxy.port, gripper=None, timeouts=SLOW) as second,
    ):
        second.wait_until_ready()
        motion = second.start_move(FAR, speed=10)  # claims the robot; a long move
        sim.wait_for(lambda: sim.tcp_pose().distance_to(LEFT) > 20, timeout=5.0)
        hold_beats(sim, proxy, release)
        deliver(sim.port, BEAT, beat)
        let_run(sim, 10)  # 200 ms on the program's clock: its watchdog looked twice
        assert sim.tcp_pose().distance_to(FAR) > 20  # still under way meanwhile
        release.set()
        proxy.clear()
        motion.wait()
        assert sim.tcp_pose().is_close(FAR, mm=1.0, deg=1.0)


def test_the_first_command_after_a_link_outage_runs(sim: Simulator) -> None:
    """The link was down longer than the time-to-live, so the program saw the master
    gone (and used up a number). The master's next command goes out as soon as the link
    is back: it must beat first, not leave the command to a program that still sees it
    gone."""
    # The shortest time-to-live (the outage is ended only once the program saw it pass).
    policy = TimeoutPolicy(heartbeat_s=0.16, heartbeat_ttl_s=0.5)
    with (
        FaultProxy(sim.port) as proxy,
        Robot("127.0.0.1", proxy.port, gripper=None, timeouts=policy) as robot,
    ):
        robot.wait_until_ready()
        robot.move_to(LEFT, speed=50)
        ack = sim.field("ack_seq")
        proxy.outage(60.0)  # every connection closed, new ones refused
        # The program's idle rule: the master gone, its next number used up.
        sim.wait_for(lambda: sim.field("ack_seq") != ack, timeout=5.0)
        assert sim.field("result_code") == 5
        proxy._refusing_until = 0.0  # the link comes back
        assert robot.move_to(LEFT.offset(dz=-20), speed=50).done


def test_a_master_never_takes_another_masters_done_for_its_own_command(
    sim: Simulator, monkeypatch: pytest.MonkeyPatch
) -> None:
    with (
        Robot("127.0.0.1", sim.port) as first,
        Robot("127.0.0.1", sim.port) as second,
    ):
        first.wait_until_ready()
        first.gripper.open()  # the first master claims the robot
        real_send = first._channel.send

        def second_goes_first(ticket: Any) -> None:
            # Between the first master's read of ack_seq and its write, the second
            # master claims the robot and has its own command (the same number) done.
            monkeypatch.setattr(first._channel, "send", real_send)
            second.gripper.open()
            real_send(ticket)

        monkeypatch.setattr(first._channel, "send", second_goes_first)
        with pytest.raises(RobotError, match="another master"):  # never "done"
            first.gripper.close()
