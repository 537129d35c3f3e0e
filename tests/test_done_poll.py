"""The poll that sees a move done also reads where the arm ended (tmflow: right after).

On a driver's loop that read is part of the poll (tests/test_hand_overs.py counts a
move's hand-overs). A failure of that last read leaves the finished move alone:
nothing is stopped.
"""

from __future__ import annotations

import time

import pytest

import tmmaster
from fault_proxy import Action, FaultProxy, Rule
from tmmaster import PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster.sim import Simulator

A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(300, -200, 180, 180, 0, 90)


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
            # 0.1 s once failed a connect's read on a loaded machine.
            timeouts=TimeoutPolicy(request_s=0.3),
            retry=tmmaster.RetryPolicy(attempts=2, total_time_s=1.0, initial_backoff_s=0.01),
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


@pytest.mark.parametrize("fault", ["delay", "drop_answer"])
def test_a_move_to_where_the_arm_is_is_done_only_once_it_ran(fault: Action) -> None:
    # The same target again: the pose read before the write matches the target already.
    # Its write held up, or its answer lost: done comes only from the program's done_seq
    # for this number, after the robot ran the move.
    with (
        Simulator("tmflow", time_scale=4.0) as sim,
        FaultProxy(sim.port) as proxy,
        Robot(
            "127.0.0.1",
            proxy.port,
            gripper=None,
            # A loaded machine's margins (beside CPU hogs): a connect's first read is not
            # retried, and 0.2 s went unanswered; the dropped answer blocks the link (and
            # the heartbeat) for request_s, and the program's watchdog then used up the
            # next number past the 2 s TTL. The dropped answer times out all the same.
            timeouts=TimeoutPolicy(request_s=0.5, heartbeat_ttl_s=10.0),
            polling=PollPolicy(interval_s=0.01),
        ) as robot,
    ):
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(A, speed=60)
        proxy.add(Rule(fault, function_code=16, address=9000, delay_s=0.1))
        robot.move_to(A, speed=60)
        returned = time.monotonic()
        log = sim.motion_log()
        assert [r.target for r in log] == [A, A]
        assert log[1].done_wall_time is not None
        assert log[1].done_wall_time <= returned
