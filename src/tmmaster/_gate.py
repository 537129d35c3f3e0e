"""Where a command write and a shutdown meet: one lock, one check.

A robot's thread writes a command through its :class:`CommandGate`; ``close()``, a
``Fleet`` closing, or a stop request closes or blocks the gate. The check and the
write happen under the same lock, so every command is either never written, or
written before the gate closed and then visible to whoever closes it: ``close()``
waits for a write in flight (:meth:`CommandGate.drain`) and then withdraws or stops
the command it finds. Without this, a close from another thread could read the
previous (finished) command, find nothing to withdraw, and close the link while the
robot's thread wrote its next command, which then ran to its end.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from ._exceptions import StopRequestedError


class CommandGate:
    """Admits a command write only while its robot is open and no stop is requested."""

    __slots__ = ("_closed", "_lock", "_stop_event")

    def __init__(self, stop_event: threading.Event) -> None:
        """Make an open gate.

        Args:
            stop_event: the robot's stop request; while it is set, no command is written.
        """
        self._lock = threading.Lock()
        self._stop_event = stop_event
        self._closed = False

    @property
    def closed(self) -> bool:
        """True once :meth:`close` was called: no command will ever be written again."""
        return self._closed

    def write(self, register: Callable[[], None] | None, send: Callable[[], None]) -> None:
        """Run ``register`` then ``send`` under the lock, if the gate admits a command.

        Args:
            register: records the command as outstanding (it must be visible to a
                closer before any byte of it can reach the robot), or that a copy of a
                registered one is resent; None: nothing to record (an output, a button,
                a gripper's own command).
            send: writes the command (one request).

        Raises:
            StopRequestedError: the gate is closed or a stop was requested; nothing was
                written and ``register`` was not called.
        """
        with self._lock:
            if self._closed:
                raise StopRequestedError("the robot connection is closing: command not sent")
            if self._stop_event.is_set():
                raise StopRequestedError("a stop was requested: command not sent")
            if register is not None:
                register()
            send()

    def close(self) -> None:
        """Refuse every later write and request a stop (running waits give up)."""
        self._closed = True
        self._stop_event.set()

    def drain(self) -> None:
        """Wait until no write is in flight (one request, bounded by the link's timeout):
        a write in flight may land and run, so whoever closes waits for it and gives it up.
        """
        with self._lock:
            pass
