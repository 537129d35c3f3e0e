"""The tmflow sequence numbers stay inside what TMflow's modbus_read_int16 reads (1..32767)."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from pymodbus.client import ModbusTcpClient

import tmmaster
from tmmaster import Pose
from tmmaster._profiles import profile_from_data
from tmmaster._registers import RobotProfile
from tmmaster.sim import RobotSetup, Simulator

SimFactory = Callable[..., Simulator]

A = Pose(300, -200, 200, 180, 0, 90)
B = Pose(300, -150, 200, 180, 0, 90)
C = Pose(250, -150, 200, 180, 0, 90)


def seq_writes(sim: Simulator) -> list[int]:
    """The seq word (9015) of every command block the simulator accepted, in order."""
    seq = sim.profile.field("seq")
    start = 9000
    return [
        r.values[seq.address - start]
        for r in sim.request_log
        if r.function_code == 16 and r.address == start and r.values and not r.refused
    ]


def test_master_walks_the_sequence_across_32767_to_1(tm_simulator_factory: SimFactory) -> None:
    sim = tm_simulator_factory("tmflow", robot=RobotSetup(initial_seq=32766))
    with tmmaster.connect("127.0.0.1", port=sim.port, profile="tmflow") as robot:
        robot.wait_until_ready(timeout_s=5)
        for target in (A, B, C):
            robot.move_to(target, speed=50)
            assert sim.tcp_pose().is_close(target, mm=0.01)
    assert seq_writes(sim) == [32767, 1, 2]
    assert (sim.field("ack_seq"), sim.field("done_seq")) == (2, 2)


def test_master_refuses_an_ack_seq_outside_the_int16_range(
    tm_simulator_factory: SimFactory,
) -> None:
    # A broken robot program writes 40000 into ack_seq; read as int16 it is -25536. (The
    # test plays that program through a profile that lets a client write ack_seq.)
    profile = profile_from_data({"extends": "tmflow", "fields": {"ack_seq": {"access": "rw"}}})
    assert isinstance(profile, RobotProfile)
    sim = tm_simulator_factory(profile)
    with ModbusTcpClient("127.0.0.1", port=sim.port) as program:
        assert not program.write_register(9100, 40000).isError()
    with tmmaster.connect("127.0.0.1", port=sim.port, profile=profile) as robot:
        robot.wait_until_ready(timeout_s=5)
        with pytest.raises(tmmaster.RobotError, match=r"outside 0\.\.32767"):
            robot.move_to(A, speed=50)
    assert seq_writes(sim) == []
