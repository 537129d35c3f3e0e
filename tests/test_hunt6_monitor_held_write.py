"""A StatusMonitor reading over a Robot's own link while the robot's command write is held.

``StatusMonitor.add_robot`` reads the status between the robot's requests, on the same
connection, whenever the link is free. Here a tmflow robot's move write (FC16 to the
command block, 9000) is held by a FaultProxy while the monitor polls at 100 Hz: the write
times out, the link is dropped and taken up again, and either the robot resends the same
number (the move runs once) or a stop request gives the move up while its frame is held
(it never runs). The held frame lands only once the master's call has ended. The
simulator's motion log judges (tests/safety_invariant.py), and the monitor kept reading
throughout without ever reopening the robot's link itself.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, at_rest, check
from tmmaster import PollPolicy, Pose, Robot, StatusMonitor, TimeoutPolicy, TMMasterError
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]
A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(300, -200, 180, 180, 0, 90)


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("tmflow", time_scale=20.0)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


@pytest.mark.parametrize("give_up", [False, True], ids=["resent", "stop_requested"])
def test_a_held_command_write_under_a_shared_monitor_runs_at_most_once(
    sim: Simulator, proxy: FaultProxy, give_up: bool
) -> None:
    release, ended = threading.Event(), threading.Event()
    issued = [Issued(A, 0.0, 0.0, "done")]
    monitor = StatusMonitor(rate_hz=100)
    with Robot(
        "127.0.0.1",
        proxy.port,
        gripper=None,
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(request_s=0.3, ack_timeout_s=3.0, motion_margin_s=1.0),
    ) as robot:
        robot.wait_until_ready(timeout_s=5)
        monitor.add_robot(robot, name="arm")
        with monitor:
            robot.move_to(A, speed=80)
            proxy.add(Rule("hold", function_code=16, address=9000, release=release))
            command = Issued(B, time.monotonic())
            issued.append(command)

            def held_then() -> None:  # a stop request, or the frame let go once resent
                while not proxy.played("hold"):
                    if ended.wait(0.005):
                        return
                if give_up:
                    robot.interrupt()

            helper = threading.Thread(target=held_then)
            helper.start()
            try:
                robot.move_to(B, speed=80)
            except TMMasterError as exc:
                command.outcome = type(exc).__name__
            else:
                command.outcome = "done"
            finally:
                command.ended_at = time.monotonic()
                ended.set()
                helper.join(5)
            release.set()  # the held frame lands now, after the call ended
            proxy.wait_held()
            ticks = sim.ticks
            sim.wait_for(lambda: sim.ticks >= ticks + 20, timeout=5.0)
            sim.wait_for(at_rest(sim), timeout=5.0, interval=0.05)
            seen = monitor.latest("arm")
        robot.clear_stop_request()
        after = robot.status()
    check(issued, sim.motion_log())
    ran = [m.target for m in sim.motion_log() if m.target is not None]
    if give_up:
        assert command.outcome == "StopRequestedError"
        assert ran == [A]
    else:
        assert command.outcome == "done"
        assert ran == [A, B]
    assert seen.polls >= 2
    assert seen.status is not None
    assert not after.moving
