"""A fault on one robot's link of a Fleet: its given-up command never runs, the other's runs once.

Two tmflow robots share one Fleet. Robot ``b``'s command write is held in the network
(FaultProxy, on FC16 to the command block) while robot ``a`` moves; ``b``'s write times
out, it resends the same sequence number and the arm takes that; ``b`` is interrupted,
then the held original lands. The simulators' motion logs judge: ``a`` ran each of its
moves exactly once, ``b`` ran its target once and nothing after it gave it up.
"""

from __future__ import annotations

import threading
import time

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, check
from tmmaster import Fleet, PollPolicy, Pose, Robot, StopRequestedError, TimeoutPolicy
from tmmaster.sim import Simulator, Timing

A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(300, -200, 180, 180, 0, 90)


def test_a_held_command_on_one_fleet_robot_runs_once_and_the_other_moves_once() -> None:
    timing = Timing(tick_hz=50.0)
    with (
        Simulator("tmflow", time_scale=20.0, timing=timing) as sim_a,
        Simulator("tmflow", time_scale=20.0, timing=timing) as sim_b,
        FaultProxy(sim_b.port) as proxy,
        Fleet() as fleet,
    ):
        options = dict(
            gripper=None,
            link=fleet,
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(request_s=0.15, ack_timeout_s=0.5, motion_margin_s=1.0),
        )
        robot_a = Robot("127.0.0.1", sim_a.port, profile="tmflow", **options)  # type: ignore[arg-type]
        robot_b = Robot("127.0.0.1", proxy.port, profile="tmflow", **options)  # type: ignore[arg-type]
        with robot_a, robot_b:
            for robot in (robot_a, robot_b):
                robot.wait_until_ready(timeout_s=5)
            robot_b.move_to(A, speed=80)
            issued_b = [Issued(A, 0.0, 0.0, "done"), Issued(B, time.monotonic())]
            release = threading.Event()
            proxy.add(Rule("hold", function_code=16, address=9000, release=release))
            errors: list[BaseException] = []

            def move_b() -> None:
                try:
                    robot_b.move_to(B, speed=80)
                except BaseException as exc:
                    errors.append(exc)

            thread = threading.Thread(target=move_b)
            thread.start()
            sim_b.wait_for(lambda: proxy.played("hold"), timeout=5.0)
            for target in (A, B, A):  # the healthy robot moves while b's frame is held
                robot_a.move_to(target, speed=80)
            # b's write timed out; it read back, found nothing, and resent the same number:
            # the arm takes the resend. Only then is b interrupted (stopped mid-move, or
            # already done), and only then does the original frame land.
            sim_b.wait_for(lambda: B in [r.target for r in sim_b.motion_log()], timeout=5.0)
            robot_b.interrupt()
            thread.join(10)
            assert not thread.is_alive()
            outcome = type(errors[0]).__name__ if errors else "done"
            issued_b[-1].ended_at, issued_b[-1].outcome = time.monotonic(), outcome
            assert all(isinstance(e, StopRequestedError) for e in errors), errors
            release.set()  # the held frame lands now, after b gave its move up
            proxy.wait_held()
            ticks = sim_b.ticks
            sim_b.wait_for(lambda: sim_b.ticks >= ticks + 10, timeout=5.0)
        check(issued_b, sim_b.motion_log())
        assert [r.target for r in sim_b.motion_log() if r.target is not None] == [A, B]
        assert [r.target for r in sim_a.motion_log() if r.target is not None] == [A, B, A]
