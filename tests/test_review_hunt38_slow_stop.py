"""pause() and play() after the master's own Stop that takes longer than STOP_SHOWS_S to show.

fd7bc65 bounded the wait for a Stop of this process to show by STOP_SHOWS_S (1 s, a
judgement, not measured on a TM5) and decided the press on the project as it was then.
On a robot slower than that, pause() read the project still running and pressed the
Play/Pause toggle, which the robot took after its Stop, on the stopped project, where
it is Play: pause() started the project over (then raised and pressed Stop); play()
returned RUNNING, pressing nothing, on a project that then stopped. The wait lasts up
to ``timeout_s`` again; what skips it is a project started anew since a Stop that
play() or pause() pressed on giving up (``boot_id``: their press landed late, the Stop
showed and was undone, tests/test_hunt38_aio_cancel_points.py).

Here the simulated robot's buttons are held until the master has read the project
still running after STOP_SHOWS_S has passed since its Stop, or has pressed
the toggle: the Stop then shows, late.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import pytest

from pendant import hold_buttons
from tmmaster import ProjectState, Robot, _channels
from tmmaster.sim import Simulator

#: Techman's Play/Pause coil (TMflow 2.24 appendix C, p. 313) and the flags' first input.
PLAY_PAUSE, FLAGS = 7104, 7201
#: STOP_SHOWS_S for these tests, s (the press comes well within it; the Stop shows later).
SHOWS_S = 1.0


def _ticks_pass(sim: Simulator, ticks: int) -> None:
    start = sim.ticks
    sim.wait_for(lambda: sim.ticks >= start + ticks, timeout=5.0)


@pytest.mark.parametrize("call", ["pause", "play"])
def test_a_press_after_a_stop_slower_than_stop_shows_s_is_decided_on_the_stopped_project(
    tm_simulator_factory: Any, monkeypatch: pytest.MonkeyPatch, call: str
) -> None:
    monkeypatch.setattr(_channels, "STOP_SHOWS_S", SHOWS_S)
    sim: Simulator = tm_simulator_factory("tmflow")
    held = hold_buttons(sim)
    with Robot("127.0.0.1", sim.port, gripper=None) as robot:
        robot.wait_until_ready(timeout_s=5)
        assert robot.project_state() is ProjectState.RUNNING
        start = len(sim.request_log)

        def release_late() -> None:
            # Past STOP_SHOWS_S since the Stop: the next flags read, or a press, lets it show.
            time.sleep(SHOWS_S + 0.2)
            late = len(sim.request_log)
            sim.wait_for(
                lambda: (
                    not held.is_set()
                    or any(
                        (r.address == FLAGS and not r.is_write) or r.address == PLAY_PAUSE
                        for r in sim.request_log[late:]
                    )
                ),
                timeout=5.0,
            )
            held.clear()

        releaser = threading.Thread(target=release_late)
        robot.stop()  # written; the robot takes it late
        releaser.start()
        try:
            if call == "pause":
                # Stopped by this master's Stop: a pause leaves it so, pressing nothing.
                assert robot.pause(timeout_s=5.0) is ProjectState.STOPPED
            else:
                # Play starts the project again once it shows the Stop: never skipped.
                assert robot.play(timeout_s=5.0) is ProjectState.RUNNING
        finally:
            held.clear()  # the Stop shows now if it has not yet
            releaser.join(5.0)
        _ticks_pass(sim, 3)
        wanted = ProjectState.STOPPED if call == "pause" else ProjectState.RUNNING
        assert robot.project_state() is wanted
        presses = [r for r in sim.request_log[start:] if r.is_write and r.address == PLAY_PAUSE]
        assert len(presses) == (call == "play")
