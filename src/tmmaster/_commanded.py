"""Which robots this process commands: so a second link to one of them is refused.

A TM robot's Modbus slave may serve one client only (a controller configured so, a
gateway in front of it): a status monitor opening its own link to a robot that a
:class:`~tmmaster.Robot` of this process commands would lock the Robot out, or take the
connection a stop needs. Every Robot is registered here (weakly: a Robot nobody holds
is forgotten), and :meth:`StatusMonitor.add <tmmaster.StatusMonitor.add>` asks
:func:`commanding` before it adds a link of its own (the monitor cannot import
``_robot.py``, which depends on it through the Fleet).
"""

from __future__ import annotations

import threading
import weakref
from typing import Any

from ._transport import ConnectionState

_LOCK = threading.Lock()
_ROBOTS: weakref.WeakSet[Any] = weakref.WeakSet()


def register(robot: Any) -> None:
    """Remember ``robot`` (a :class:`~tmmaster.Robot`) as commanding its host and port.

    Args:
        robot: The robot; kept by a weak reference.
    """
    with _LOCK:
        _ROBOTS.add(robot)


def commanding(host: str, port: int) -> Any | None:
    """A robot of this process, not closed, whose link goes to ``host``:``port``.

    Args:
        host: The address, as the robot was given it (after :func:`check_host`).
        port: The Modbus TCP port.

    Returns:
        The robot, or None when no open robot of this process commands that address.
    """
    with _LOCK:
        robots = list(_ROBOTS)
    for robot in robots:
        transport = getattr(robot, "_transport", None)
        if transport is None or getattr(transport, "host", None) != host:
            continue
        if getattr(transport, "port", None) != port:
            continue
        if getattr(transport, "state", None) is not ConnectionState.CLOSED:
            return robot
    return None
