"""The poll that sees a move done also reads where the arm ended (tmflow: right after).

On a driver's loop that read is part of the poll, so a move wakes the robot's thread no
more than the article's: one read before the command, the write, the wait. A failure
of that last read leaves the finished move alone: nothing is stopped.
"""

from __future__ import annotations

import collections
from collections.abc import Callable
from typing import Any

import pytest

import tmmaster
import tmmaster._fleet as fleet_module
from fault_proxy import FaultProxy, Rule
from tmmaster import PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster.sim import Simulator

A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(300, -200, 180, 180, 0, 90)


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_move_hands_the_loop_one_read_one_write_and_its_wait(
    tm_simulator_factory: Callable[..., Simulator],
    monkeypatch: pytest.MonkeyPatch,
    profile: str,
) -> None:
    handed: collections.Counter[str] = collections.Counter()
    hand_over = fleet_module.LoopTransport._hand_over
    follow = fleet_module.FleetMember.follow

    def counted_hand_over(link: Any, what: str, *args: Any) -> Any:
        handed[what.split()[0]] += 1  # "read ..." / "write ..."
        return hand_over(link, what, *args)

    def counted_follow(member: Any, state: Any) -> Any:
        handed["wait"] += 1
        return follow(member, state)

    monkeypatch.setattr(fleet_module.LoopTransport, "_hand_over", counted_hand_over)
    monkeypatch.setattr(fleet_module.FleetMember, "follow", counted_follow)
    sim = tm_simulator_factory(profile, time_scale=4)
    with Robot(
        "127.0.0.1", sim.port, profile=profile, gripper=None, polling=PollPolicy(interval_s=0.01)
    ) as robot:
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(A, speed=60)  # the first move reads what later ones reuse
        for target in (B, A, B):
            handed.clear()
            motion = robot.move_to(target, speed=60)
            assert motion.done
            assert motion.last_pose is not None
            assert motion.last_pose.is_close(target, mm=0.5)
            assert dict(handed) == {"read": 1, "write": 1, "wait": 1}


def test_a_failed_read_after_the_done_stops_nothing() -> None:
    # The poll saw the move done; the read of the final pose that follows it fails for
    # good. The move has ended: pressing Stop would end the operator's project for nothing.
    with (
        Simulator("tmflow", time_scale=4.0) as sim,
        FaultProxy(sim.port) as proxy,
        Robot(
            "127.0.0.1",
            proxy.port,
            gripper=None,
            timeouts=TimeoutPolicy(request_s=0.1),
            retry=tmmaster.RetryPolicy(attempts=2, total_time_s=0.5, initial_backoff_s=0.01),
            polling=PollPolicy(interval_s=0.01),
        ) as robot,
    ):
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(A, speed=60)
        plan_read = robot._channel.plan_fields[0].address  # the pose and joints after a done
        motion = robot.start_move(B, speed=60)
        proxy.add(Rule("drop_answer", function_code=4, address=plan_read, times=100))
        with pytest.raises(tmmaster.TransportError):
            motion.wait()
        proxy.clear()
        assert len(sim.motion_log()) == 2
        assert sim.tcp_pose().is_close(B, mm=0.5)
        assert not [s for s in proxy.seen if s.function_code == 5]  # no Stop written
        assert sim.field("project_running")
