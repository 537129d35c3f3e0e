"""A second Ctrl-C inside ``Robot.interrupt()`` leaves no lock held.

A script's Ctrl-C handler calls ``robot.interrupt()``; a second Ctrl-C that lands while
``threading.Event.set()`` holds its condition's lock (CPython runs a signal handler
between two bytecodes: one that lands right after the lock's acquire, before the
``with`` statement's clean-up is in place, leaves it held) left the stop event locked,
and the next ``interrupt()``, the one ``close()`` makes, waited on it forever: hunt 29
saw ``examples/many_robots.py --processes`` children hang at exit in 3 runs of 30, the
stack in ``close()`` -> ``interrupt()`` -> ``Event.set()``. ``interrupt()`` now holds
Ctrl-C back while it sets the event (``deferred()``) and delivers it right after.

The Ctrl-C is raised from inside the event's critical section (``signal.raise_signal``,
the lock held), so it lands exactly there, every run.
"""

from __future__ import annotations

import signal
import threading

import pytest

from tmmaster import Robot


class CtrlCInsideSet(threading.Event):
    """An Event whose ``set()`` takes a Ctrl-C while it holds its lock, once."""

    def __init__(self) -> None:
        super().__init__()
        self.landed = False

    def set(self) -> None:
        self._cond.acquire()  # type: ignore[attr-defined]
        if not self.landed:
            self.landed = True
            # As the race does: the exception leaves before any release.
            signal.raise_signal(signal.SIGINT)
        self._flag = True
        self._cond.notify_all()  # type: ignore[attr-defined]
        self._cond.release()  # type: ignore[attr-defined]


#: The Ctrl-C tests need Python's own handler, in the main thread.
NEEDS_MAIN_THREAD_CTRL_C = pytest.mark.skipif(
    threading.current_thread() is not threading.main_thread()
    or signal.getsignal(signal.SIGINT) is not signal.default_int_handler,
    reason="needs Python's own Ctrl-C handler in the main thread",
)


@NEEDS_MAIN_THREAD_CTRL_C
def test_a_ctrl_c_inside_interrupt_is_delivered_after_it_and_close_still_ends() -> None:
    robot = Robot("127.0.0.1", 5020, profile="article", gripper=None)
    event = CtrlCInsideSet()
    robot._stop_event = event
    with pytest.raises(KeyboardInterrupt):
        robot.interrupt()
    assert event.landed
    assert event.is_set()
    closer = threading.Thread(target=robot.close, daemon=True)
    closer.start()
    closer.join(5.0)
    assert not closer.is_alive(), "close() waits forever on the stop event's lock"
