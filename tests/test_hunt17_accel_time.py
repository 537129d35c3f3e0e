"""A move's time to top speed, held against the range TMflow takes (helper H17's hunt).

[TMF]: TMflow Software Manual 2.24, Rev 1.00 (text copy: kenshu528-oss/Modbus-testkit-for-TMflow,
``TM Doc/``). 9 Motion Programming, "Speed of Line Motion", p. 171: "the available ABS Time to top
speed is from 150 to 9999 ms". [TS] 13.8 PTP, p. 331 and 13.10 Line, p. 337: the motion functions
take "the time interval to accelerate to top speed (ms)" and give it no other range.

Found by this hunt (fails without its fix): the master took any ``accel_time_ms`` of
0..10000 (the profile's register range) and the robot program ran it: a Line at 1100 mm/s
told to reach top speed in 1 ms, which TMflow's own motion settings never offer (a real
TM5 reaches top speed by its joints' torque, not in 1 ms: the master would plan, and time
out, a move the arm cannot make), and 10000 ms, one past TMflow's 9999. A move now takes 0
(the program's default, 200 ms) or 150..9999 ms, refused otherwise before any request;
the robot program answers a command block outside that range ``invalid_command``, so a
master that skips the check does not move the simulated arm either.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from test_sim_controller import DT, PART, finish_tmflow, send_tmflow, tmflow
from tmmaster import ConfigError, PollPolicy, Pose, Robot
from tmmaster._registers import Table
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]
START = Pose(300, -200, 200, 180, 0, 90)
TARGET = Pose(320, -180, 220, 180, 0, 90)
VIA = Pose(330, -190, 200, 180, 0, 90)
READY = [0, 0, 90, 0, 90, 0]
#: TMflow's range for a time to top speed, ms ([TMF] p. 171), and 0: the program's default.
OFF_RANGE_MS = [1, 50, 149, 10000]


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: Factory) -> Factory:
    return memory_simulator_factory


def _ready(factory: Factory) -> tuple[Simulator, Robot]:
    sim = factory("tmflow")
    robot = Robot(sim.url, profile="tmflow", polling=PollPolicy(interval_s=0.01))
    robot.connect()
    robot.wait_until_ready(timeout_s=5)
    robot.move_to(START, speed=100)
    return sim, robot


@pytest.mark.parametrize("accel_ms", OFF_RANGE_MS)
def test_a_ramp_outside_tmflows_range_is_refused_before_any_request(
    tm_simulator_factory: Factory, accel_ms: int
) -> None:
    sim, robot = _ready(tm_simulator_factory)
    calls: list[Callable[[], Any]] = [
        lambda: robot.move_to(TARGET, motion="line", speed_mm_s=1100, accel_time_ms=accel_ms),
        lambda: robot.move_to(TARGET, speed=100, accel_time_ms=accel_ms),
        lambda: robot.move_joints(READY, speed=100, accel_time_ms=accel_ms),
        lambda: robot.move_by(dz=10, accel_time_ms=accel_ms),
        lambda: robot.move_arc(VIA, TARGET, speed_mm_s=500, accel_time_ms=accel_ms),
        lambda: robot.start_move(TARGET, accel_time_ms=accel_ms),
    ]
    try:
        moves = len(sim.motion_log())
        for call in calls:
            sim.clear_request_log()
            with pytest.raises(ConfigError, match=r"accel_time_ms .*150\.\.9999 ms"):
                call()
            assert list(sim.request_log) == []
        assert len(sim.motion_log()) == moves
    finally:
        robot.close()


def test_the_edges_of_tmflows_range_and_the_default_run(tm_simulator_factory: Factory) -> None:
    sim, robot = _ready(tm_simulator_factory)
    try:
        robot.move_to(TARGET, motion="line", speed_mm_s=500, accel_time_ms=150)
        robot.move_to(START, accel_time_ms=0)
        robot.move_to(TARGET, speed=100, accel_time_ms=None)
        robot.move_joints(READY, speed=50, accel_time_ms=9999)
        assert [m.target for m in sim.motion_log()[-4:-1]] == [TARGET, START, TARGET]
        assert len(sim.motion_log()) == 5
    finally:
        robot.close()


@pytest.mark.parametrize("accel_ms", [1, 149, 10000])
def test_the_robot_program_answers_invalid_command_to_a_ramp_outside_the_range(
    accel_ms: int,
) -> None:
    # A master that skips the check (another program, an older tmmaster) writes the block
    # itself: the robot program answers invalid_command (result 2) and starts no move.
    ctl, bank, _, _ = tmflow()
    send_tmflow(bank, 1, target=PART)
    bank.write(Table.HOLDING, 9013, [accel_ms])  # raw: the master's check is skipped
    ctl.tick(DT)
    assert bank.get("ack_seq") == 1
    assert (bank.get("robot_state"), bank.get("result_code")) == (2, 2)
    assert ctl.moves_started == 0
    send_tmflow(bank, 2, target=PART, accel_ms=150)  # the program takes the next one
    finish_tmflow(ctl, bank, 2)
    assert bank.get("result_code") == 0
