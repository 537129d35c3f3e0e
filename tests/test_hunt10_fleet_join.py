"""A Robot made on a Fleet while that Fleet closes (hunt 10: the master's own threads).

``Fleet.close()`` closes every robot's command gate, then closes each robot; a robot
made after it was called is refused (``ConfigError``, nothing connected). A worker
thread may be making its ``Robot(link=fleet)`` right then (a pool that connects its
robots lazily, the main thread's Ctrl-C closing the fleet): the robot checked that the
fleet was open, and joined it only after the close had listed the robots to close. Its
gate stayed open while the fleet's loop still ran (the close busy with another robot's
command write held in the network), so it connected and wrote a move that no close
gave up: the loop stopped under it, its Stop could not go out, the arm ran to the
target. The join is held at that point here (an Event around the fleet's registration
of the robot), released once the close has begun. The simulators judge: nothing starts
after ``Fleet.close()`` was called, on the late robot's arm.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import pytest

import tmmaster._robot as robot_module
from fault_proxy import FaultProxy, Rule
from tmmaster import ConfigError, Fleet, PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster.sim import Simulator

A = Pose(300, -200, 150, 180, 0, 90)
FAR = Pose(250, 0, 400, 180, 0, 90)


def test_a_robot_joining_a_closing_fleet_writes_no_command(monkeypatch: pytest.MonkeyPatch) -> None:
    joining, go = threading.Event(), threading.Event()
    join = robot_module.fleet_driver

    def held_join(*args: Any) -> Any:
        if threading.current_thread().name == "late":
            joining.set()
            go.wait(5)
        return join(*args)

    monkeypatch.setattr(robot_module, "fleet_driver", held_join)
    options: dict[str, Any] = dict(
        profile="tmflow",
        gripper=None,
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(request_s=3.0, ack_timeout_s=5.0, motion_margin_s=1.0),
    )
    release = threading.Event()
    outcome: list[str] = []
    with (
        Simulator("tmflow", time_scale=20.0) as sim_a,
        Simulator("tmflow", time_scale=2.0) as sim_b,
        FaultProxy(sim_a.port) as proxy,
    ):
        fleet = Fleet()
        robot_a = Robot("127.0.0.1", proxy.port, link=fleet, name="a", **options)
        try:
            robot_a.connect()
            robot_a.wait_until_ready(timeout_s=5)
            # a's command write held: the close waits for it (its gate's drain).
            proxy.add(Rule("hold", function_code=16, address=9000, release=release))
            mover = threading.Thread(target=lambda: _attempt(robot_a, A))
            mover.start()
            sim_a.wait_for(lambda: proxy.played("hold"), timeout=5)

            def late() -> None:
                try:
                    robot_b = Robot("127.0.0.1", sim_b.port, link=fleet, name="b", **options)
                except ConfigError:
                    outcome.append("refused")
                    return
                try:
                    robot_b.connect()
                    robot_b.wait_until_ready(timeout_s=5)
                finally:
                    outcome.append(_attempt(robot_b, FAR))
                robot_b.close()

            maker = threading.Thread(target=late, name="late")
            maker.start()
            assert joining.wait(5)
            closed_at = time.monotonic()
            closer = threading.Thread(target=fleet.close)
            closer.start()
            _wait_closed(fleet)
            go.set()  # b joins now: the close has listed its robots already
            sim_b.wait_for(lambda: bool(outcome) or bool(sim_b.motion_log()), timeout=10)
            release.set()
            for thread in (closer, maker, mover):
                thread.join(15)
                assert not thread.is_alive()
            proxy.wait_held()
            ticks = sim_b.ticks
            sim_b.wait_for(lambda: sim_b.ticks >= ticks + 10, timeout=5)
            late_moves = [m for m in sim_b.motion_log() if m.wall_time > closed_at]
            assert not late_moves, f"b moved after Fleet.close() was called: {outcome}"
            assert outcome == ["refused"]
        finally:
            release.set()
            go.set()
            fleet.close()
            robot_a.close()


def _attempt(robot: Robot, target: Pose) -> str:
    try:
        robot.move_to(target, speed=10)
    except Exception as exc:
        return f"{type(exc).__name__}: {exc}"
    return "done"


def _wait_closed(fleet: Fleet) -> None:
    """Until the close has begun: a closed fleet refuses start() (a state, not a time)."""
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:
        try:
            fleet.start()
        except ConfigError:
            return
        time.sleep(0.002)
    raise AssertionError("the fleet never began to close")


def test_a_fleet_closing_while_a_robot_is_being_made_closes_no_half_made_robot(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The same race one step later: the robot was listed by its fleet before it was
    # whole (its link and gate made, not its close() state): the close's thread failed
    # on it (AttributeError), the fleet named it unconfirmed though it sent nothing, and
    # the robot came out of Robot() open, on a closed fleet. It joins last now: a close
    # at that point never lists it, and Robot() raises ConfigError.
    building, go = threading.Event(), threading.Event()
    frames = robot_module.FrameGuard

    def held_frames(*args: Any) -> Any:
        if threading.current_thread().name == "late":
            building.set()
            go.wait(5)
        return frames(*args)

    monkeypatch.setattr(robot_module, "FrameGuard", held_frames)
    outcome: list[str] = []
    failures: list[BaseException] = []
    monkeypatch.setattr(threading, "excepthook", lambda args: failures.append(args.exc_value))
    with Simulator("tmflow", time_scale=20.0) as sim:
        fleet = Fleet()

        def late() -> None:
            try:
                Robot("127.0.0.1", sim.port, profile="tmflow", gripper=None, link=fleet).close()
                outcome.append("made")
            except ConfigError:
                outcome.append("refused")

        maker = threading.Thread(target=late, name="late")
        maker.start()
        try:
            assert building.wait(5)
            unconfirmed = fleet.close()
        finally:
            go.set()
            maker.join(10)
        assert not failures, failures
        assert unconfirmed == ()
        assert outcome == ["refused"]
