"""pause() and play() right after the master's own stop(), before the robot took the Stop.

stop() returns once the Stop is written; the robot takes it at its next cycle. A
pause() made in between read the project still running and pressed the Play/Pause
toggle, which the robot then took after the Stop: on a stopped project the toggle is
Play, and the project started again from the beginning (seen in a full run as
tests/test_doc_samples.py's robot-api.md sample, stop(), project_state(), play(),
pause(), failing now and then: "Pause was pressed (the project was running) and the
project is running 5 s later"); a play() in between skipped ("the project runs
already") and returned while the project stopped. Now a press decision waits until the
project shows this master's Stop. Here the simulated robot's buttons are held until
the master has read the project still running after its Stop.
"""

from __future__ import annotations

import threading
from typing import Any

import pytest

from pendant import hold_buttons
from tmmaster import ProjectState, Robot
from tmmaster.sim import Simulator

#: Techman's Play/Pause coil (TMflow 2.24 appendix C, p. 313) and the flags' first input.
PLAY_PAUSE, FLAGS = 7104, 7201


@pytest.mark.parametrize("call", ["pause", "play"])
def test_a_press_right_after_the_own_stop_is_decided_on_the_stopped_project(
    tm_simulator_factory: Any, call: str
) -> None:
    sim: Simulator = tm_simulator_factory("tmflow")
    held = hold_buttons(sim)
    with Robot("127.0.0.1", sim.port, gripper=None) as robot:
        robot.wait_until_ready(timeout_s=5)
        assert robot.project_state() is ProjectState.RUNNING
        reads = len(sim.request_log)

        def release_once_read() -> None:
            # The master has read the flags (the project still running) after its Stop.
            sim.wait_for(
                lambda: any(r.address == FLAGS and not r.is_write for r in sim.request_log[reads:]),
                timeout=5.0,
            )
            held.clear()  # the Stop is taken at the next tick

        releaser = threading.Thread(target=release_once_read)
        robot.stop()  # written; the robot has not taken it yet
        releaser.start()
        try:
            if call == "pause":
                # Stopped by this master's Stop: a pause leaves it so, pressing nothing.
                assert robot.pause(timeout_s=1.0) is ProjectState.STOPPED
                assert robot.project_state() is ProjectState.STOPPED
            else:
                # Play starts the project again once it shows the Stop: never skipped.
                assert robot.play(timeout_s=1.0) is ProjectState.RUNNING
                assert robot.project_state() is ProjectState.RUNNING
        finally:
            held.clear()
            releaser.join(5.0)
        presses = [r for r in sim.request_log[reads:] if r.is_write and r.address == PLAY_PAUSE]
        assert len(presses) == (call == "play")
