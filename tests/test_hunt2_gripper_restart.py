"""The operator's Stop then Play in the middle of a tmflow gripper command.

On ``tmflow`` a gripper command goes through the robot program's sequence handshake
like a move. The operator stops the project while the program runs the command, then
starts it again: the master must not report the command done, and the program must not
run it a second time (the start-up rule). The judge is the simulator's motion log.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from pendant import press_play_pause
from tmmaster import PollPolicy, Robot, TMMasterError
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]


def closes(sim: Simulator) -> int:
    """How many gripper closes the robot program started."""
    return sum(1 for m in sim.motion_log() if m.kind == "gripper_close")


def test_stop_then_play_during_a_gripper_close_neither_reports_it_done_nor_runs_it_again(
    tm_simulator_factory: Factory,
) -> None:
    sim = tm_simulator_factory("tmflow", time_scale=0.5)
    outcome: list[object] = []
    with Robot("127.0.0.1", sim.port, polling=PollPolicy(interval_s=0.01)) as robot:
        robot.wait_until_ready(timeout_s=5)

        def close() -> None:
            try:
                outcome.append(robot.gripper.close(timeout_s=3.0))
            except TMMasterError as exc:
                outcome.append(exc)

        thread = threading.Thread(target=close)
        thread.start()
        try:
            sim.wait_for(lambda: closes(sim) == 1, timeout=3)
            sim.call(lambda: sim._controller.bank.set("stop_project", True))  # the pendant
            sim.wait_for(lambda: not sim.field("project_running"), timeout=2)
        finally:
            thread.join(5)  # the master gave the close up (a Stop of its own lands first)
        press_play_pause(sim)  # then the operator starts the project again
        sim.wait_for(lambda: bool(sim.field("project_running")), timeout=2)
        beat = sim.field("heartbeat")
        sim.wait_for(lambda: sim.field("heartbeat") != beat, timeout=2)
    assert len(outcome) == 1
    assert isinstance(outcome[0], TMMasterError), outcome  # never reported done
    assert closes(sim) == 1  # never started again
