"""Shared by the tests of a paused or stopped tmflow project: the operator's Play/Pause
button, and what a Play after the master gave up must show (the arm stays put)."""

from __future__ import annotations

import threading
from typing import Any

from tmmaster import Pose
from tmmaster.sim import Simulator


def press_play_pause(sim: Simulator) -> None:
    """The operator's Play/Pause button on the pendant (coil 7104)."""
    sim.call(lambda: sim._controller.bank.set("play_pause", True))


def hold_buttons(sim: Simulator) -> threading.Event:
    """The controller takes no button (Play/Pause, Stop) until the returned event is
    cleared: a robot slow to act on a press, as long as the test says."""
    controller: Any = sim._controller
    take_buttons = controller._handle_buttons
    held = threading.Event()
    held.set()

    def buttons() -> None:
        if not held.is_set():
            take_buttons()

    sim.call(lambda: setattr(controller, "_handle_buttons", buttons))
    return held


def runs_again_without_moving(sim: Simulator, held: Pose, moves: int) -> None:
    """After Play on a stopped project: the program runs again (its loop beats), reports
    the move that never finished (robot_state 2, the start-up rule), and the arm stays
    at ``held`` with ``moves`` moves started in all."""
    sim.wait_for(lambda: bool(sim.field("project_running")), timeout=2.0)
    beat = sim.field("heartbeat")
    sim.wait_for(lambda: sim.field("heartbeat") != beat, timeout=2.0)
    assert sim.field("robot_state") == 2
    assert sim.tcp_pose().is_close(held, mm=1e-6, deg=1e-6)  # not a micron
    assert len(sim.motion_log()) == moves  # never started again
