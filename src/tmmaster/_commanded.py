"""Which robots this process commands: so a second link to one of them is refused.

A TM robot's Modbus slave may serve one client only (a controller configured so, a
gateway in front of it): a status monitor opening its own link to a robot that a
:class:`~tmmaster.Robot` of this process commands would lock the Robot out, or take the
connection a stop needs. Every Robot registers its link here (weakly: a link nobody
holds is forgotten), and :meth:`StatusMonitor.add <tmmaster.StatusMonitor.add>` asks
:func:`commanding` before it adds a link of its own.
"""

from __future__ import annotations

import threading
import weakref

from ._transport import ConnectionState, Transport

_LOCK = threading.Lock()
#: Each Robot's link, and the Robot's name, for as long as the link lives.
_LINKS: weakref.WeakKeyDictionary[Transport, str] = weakref.WeakKeyDictionary()


def register(name: str, transport: Transport) -> None:
    """Remember that the robot ``name`` commands the address of ``transport``.

    Args:
        name: The :class:`~tmmaster.Robot`'s name, for messages.
        transport: Its link; kept by a weak reference.
    """
    with _LOCK:
        _LINKS[transport] = name


def commanding(host: str, port: int) -> str | None:
    """The name of a robot of this process, not closed, whose link goes to ``host``:``port``.

    Args:
        host: The address, as the robot was given it (after :func:`check_host`).
        port: The Modbus TCP port.

    Returns:
        The robot's name, or None when no open robot of this process commands that address.
    """
    with _LOCK:
        links = list(_LINKS.items())
    for transport, name in links:
        same = (transport.host, transport.port) == (host, port)
        if same and transport.state is not ConnectionState.CLOSED:
            return name
    return None
