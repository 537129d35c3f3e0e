"""Drive a robot from asyncio: ``await robot.move_to(...)``, the same Robot underneath.

:func:`connect` opens an :class:`AsyncRobot`: every call is the :class:`~tmmaster.Robot`
method of the same name, run on the robot's own thread, while the polls of its waits
run on the event loop of a :class:`~tmmaster.Fleet` (docs/robot-api.md, "asyncio").
Your event loop only awaits: it is never blocked by a request, a wait or a clean-up.

Cancelling an awaited call gives its command up as any wait that ends early does: a
command the robot has not taken is withdrawn, a running move is stopped, and the
``CancelledError`` reaches your code once that is settled.
"""

from __future__ import annotations

from typing import TYPE_CHECKING as _TYPE_CHECKING

from .._lazy import lazy_attributes as _lazy_attributes

if _TYPE_CHECKING:
    from ._robot import AsyncGripper, AsyncMotion, AsyncRobot, AsyncRobotIO, connect

_EXPORTS = {
    "AsyncGripper": "._robot",
    "AsyncMotion": "._robot",
    "AsyncRobot": "._robot",
    "AsyncRobotIO": "._robot",
    "connect": "._robot",
}

__getattr__, __dir__ = _lazy_attributes(__name__, globals(), _EXPORTS)

__all__ = ["AsyncGripper", "AsyncMotion", "AsyncRobot", "AsyncRobotIO", "connect"]
