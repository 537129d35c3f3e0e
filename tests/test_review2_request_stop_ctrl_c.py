"""A second Ctrl-C inside ``Runner.request_stop()`` leaves no lock held.

``Runner.request_stop()`` is documented safe from a signal handler (docs/pickplace.md):
a script's Ctrl-C handler calls it. It sets the runner's own stop event before the
robot's; a second Ctrl-C that lands while ``threading.Event.set()`` holds that event's
lock (the race ``Robot.interrupt()`` was fixed for in e9a75b4) left it held, the event
unset and the robot not interrupted: the next ``request_stop()`` (another thread's, or
the handler's again) waited on the lock forever, and the run's waits went on.
``request_stop()`` now holds Ctrl-C back while it sets both, and delivers it after.

The Ctrl-C is raised from inside the event's critical section (``signal.raise_signal``,
the lock held), so it lands exactly there, every run.
"""

from __future__ import annotations

import threading

import pytest

from test_interrupt_ctrl_c_race import NEEDS_MAIN_THREAD_CTRL_C, CtrlCInsideSet
from tmmaster import Robot
from tmmaster.pickplace import Runner


@NEEDS_MAIN_THREAD_CTRL_C
def test_a_ctrl_c_inside_request_stop_is_delivered_after_it_and_a_later_stop_ends() -> None:
    robot = Robot("127.0.0.1", 5020, profile="article", gripper=None)
    runner = Runner(robot)
    event = CtrlCInsideSet()
    runner._stop = event
    try:
        with pytest.raises(KeyboardInterrupt):
            runner.request_stop()
        assert event.landed
        assert event.is_set()
        assert runner.stop_requested
        # The robot's waits end too: the Ctrl-C came after both events were set.
        assert robot._stop_event.is_set()
        again = threading.Thread(target=runner.request_stop, daemon=True)
        again.start()
        again.join(5.0)
        assert not again.is_alive(), "request_stop() waits forever on the event's lock"
    finally:
        robot.close()
