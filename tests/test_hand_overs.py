"""What a robot's thread hands to the driver's loop: one hand-over per read, one per wait.

Each hand-over wakes two threads (the loop, then the caller), the largest share of a
request's CPU on the driver (docs/performance.md, the hot path).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

import tmmaster._fleet as fleet_module
from scripted_slave import SlaveThread, answer_with, registers
from tmmaster import ModbusTransport, PollPolicy, Pose, Robot, RobotStatus
from tmmaster._fleet import LoopTransport
from tmmaster._registers import RegisterField, Role, Table
from tmmaster._retry import RetryPolicy
from tmmaster.sim import Simulator

A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(300, -200, 180, 180, 0, 90)


def refuse_per_request_hand_over(*_args: object) -> list[int]:
    raise AssertionError("a request was handed to the loop on its own")


def test_a_read_of_one_block_is_handed_over_as_a_whole_read() -> None:
    # The same path as a read of several blocks: no per-request hand-over, counted once.
    field = RegisterField(
        name="only", role=Role.STATUS, table=Table.HOLDING, address=4, type="uint16"
    )
    policy = RetryPolicy(attempts=1, total_time_s=5, initial_backoff_s=0.01, max_backoff_s=0.01)
    with (
        SlaveThread([answer_with(registers(9))]) as slave,
        ModbusTransport("127.0.0.1", slave.port, timeout=2.0, retry=policy, name="s") as link,
        pytest.MonkeyPatch.context() as patch,
    ):
        patch.setattr(LoopTransport, "_exchange", refuse_per_request_hand_over)
        assert link.read_fields([field]) == {"only": 9}
        assert link.stats.requests == 1
        assert [pdu[:3] for pdu in slave.server.requests] == [bytes([3, 0, 4])]


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_move_hands_its_wait_to_the_loop_once(
    tm_simulator_factory: Callable[..., Simulator],
    monkeypatch: pytest.MonkeyPatch,
    profile: str,
) -> None:
    # The loop notes the acknowledgement itself and polls on to the end: the robot's
    # thread is woken once per move, by the poll that saw it done.
    woken: list[str] = []
    follow = fleet_module.FleetMember.follow

    def counted(member: fleet_module.FleetMember, state: Any) -> Any:
        observation = follow(member, state)
        woken.append("handed back" if observation is None else "observation")
        return observation

    monkeypatch.setattr(fleet_module.FleetMember, "follow", counted)
    sim = tm_simulator_factory(profile, time_scale=2)  # the acknowledgement ticks before the end
    with Robot(
        "127.0.0.1", sim.port, profile=profile, gripper=None, polling=PollPolicy(interval_s=0.01)
    ) as robot:
        robot.wait_until_ready(timeout_s=5)
        for target in (A, B):
            woken.clear()
            motion = robot.move_to(target, speed=60)
            assert motion.done
            assert woken == ["observation"]
        assert isinstance(robot.status(), RobotStatus)
