"""A command the master gave up on while the TMflow project was stopped never runs later.

The network holds a tmflow command write and its resend (a switch buffering, a link
that hangs); meanwhile the operator stops the project (the Stop button, or the e-stop).
The master gives the command up (its write is in doubt) and finds the project stopped:
the robot program cannot take the number now. But the frames are still in the network:
once the operator presses Play, the start-up rule finds nothing pending (the frames
have not landed yet), and when they land their number is the next one, of a master
that is still beating. Only a cancel record written at the give-up uses the number up
(the start-up rule consumes it). On a running project, a number another master's move
took is left alone: a cancel record there would stop that move. The simulator runs the
generated robot program; its motion log is the judge.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, attempt, check
from tmmaster import (
    PollPolicy,
    Pose,
    RetryPolicy,
    Robot,
    StopRequestedError,
    TimeoutPolicy,
)
from tmmaster.sim import Simulator, Timing

START = Pose(300, -200, 150, 180, 0, 90)
STALE = Pose(300, -200, 180, 180, 0, 90)
NEXT = Pose(250, 0, 160, 180, 0, 90)


def press_stop(sim: Simulator) -> None:
    """The operator's Stop button on the pendant (coil 7105)."""
    sim.call(lambda: sim._controller.bank.set("stop_project", True))


OPERATOR: dict[str, Callable[[Simulator], None]] = {
    "stop button": press_stop,
    "e-stop": lambda sim: sim.press_estop(),
}


@pytest.fixture
def sim() -> Iterator[Simulator]:
    with Simulator(profile="tmflow", time_scale=20.0, timing=Timing(tick_hz=50.0)) as simulator:
        yield simulator


@pytest.mark.parametrize("operator", sorted(OPERATOR))
def test_a_write_held_while_the_project_stopped_never_runs_after_play(
    sim: Simulator, operator: str
) -> None:
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy:
        robot = Robot(
            "127.0.0.1",
            proxy.port,
            profile="tmflow",
            gripper=None,
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(request_s=0.3, ack_timeout_s=0.5, motion_margin_s=1.0),
            retry=RetryPolicy(attempts=8, total_time_s=2.0, initial_backoff_s=0.02),
        )
        with robot:
            robot.wait_until_ready()
            assert attempt(robot, START, issued) == "done"
            landed = threading.Event()
            # The command write and its resend (same number), both stuck in the network.
            proxy.add(Rule("hold", function_code=16, address=9000, release=landed, times=2))

            def operator_acts() -> None:
                sim.wait_for(lambda: proxy.played("hold"), timeout=5.0)
                OPERATOR[operator](sim)  # while the first frame is held

            acting = threading.Thread(target=operator_acts)
            acting.start()
            assert attempt(robot, STALE, issued) == "CommandStateUnknownError"
            acting.join()
            assert not sim.field("project_running")
            # The operator fixes it: reset (e-stop), Play; then the frames land.
            sim.clear_error()
            sim.press_play()
            sim.wait_for(lambda: bool(sim.field("project_running")), timeout=2.0)
            landed.set()
            proxy.wait_held()
            start = sim.ticks
            sim.wait_for(lambda: sim.ticks >= start + 10, timeout=5.0)  # 4 simulated s
            check(issued, sim.motion_log())
            assert [r.target for r in sim.motion_log()] == [START]
            assert attempt(robot, NEXT, issued) == "done"  # the master still commands
    check(issued, sim.motion_log())


def test_a_give_up_never_cancels_the_move_another_master_runs_under_its_number(
    sim: Simulator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two masters read the same free number; the second's move takes it and runs. The
    first gives its command up before its first poll: the number is another master's,
    so it writes no cancel record, which the program's watchdog would take for the
    second master giving its own move up."""
    with (
        Robot("127.0.0.1", sim.port, gripper=None) as first,
        Robot("127.0.0.1", sim.port, gripper=None) as second,
    ):
        first.wait_until_ready()
        first.move_to(START, speed=80)  # the first master claims the robot
        real_send = first._channel.send
        moves: list[Any] = []

        def second_goes_first(ticket: Any) -> None:
            # Between the first master's read of ack_seq and its write, the second
            # claims the robot and its move takes the same number.
            monkeypatch.setattr(first._channel, "send", real_send)
            moves.append(second.start_move(NEXT, speed=5))
            sim.wait_for(lambda: sim.field("ack_seq") == ticket.seq, timeout=2.0)
            real_send(ticket)
            first.interrupt()  # given up before its first poll

        monkeypatch.setattr(first._channel, "send", second_goes_first)
        with pytest.raises(StopRequestedError):
            first.move_to(STALE, speed=80)
        moves[0].wait()  # the second master's move runs to its end
    assert [r.target for r in sim.motion_log()] == [START, NEXT]
