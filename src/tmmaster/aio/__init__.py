"""Drive a robot from asyncio: ``await robot.move_to(...)``, the same Robot underneath.

:func:`connect` opens an :class:`AsyncRobot`: every call is the :class:`~tmmaster.Robot`
method of the same name, run on the robot's own thread, while the polls of its waits
run on the event loop of a :class:`~tmmaster.Fleet` (docs/robot-api.md, "asyncio").
Your event loop only awaits: it is never blocked by a request, a wait or a clean-up.

Cancelling an awaited call gives its command up as any wait that ends early does: a
command the robot has not taken is withdrawn, a running move is stopped, and the
``CancelledError`` reaches your code once that is settled.
"""

from ._robot import AsyncGripper, AsyncMotion, AsyncRobot, AsyncRobotIO, connect

__all__ = ["AsyncGripper", "AsyncMotion", "AsyncRobot", "AsyncRobotIO", "connect"]

# Shown as tmmaster.aio.Name where they are used (tracebacks, reprs, the docs), not as
# the private module that defines them (each is a class or function of ._robot).
for _name in __all__:
    globals()[_name].__module__ = __name__
del _name
