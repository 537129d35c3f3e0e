"""Where a robot is: a host and a port, checked before any I/O.

A host is an IPv4 address (``192.168.1.100``), an IPv6 address (``::1``, or ``[::1]``
as in a URL, taken without its brackets), a host name (``robot-3.local``), or
``scheme://name``, an in-process endpoint, for a scheme a plugin registered with
:func:`register_scheme` (the simulator registers ``sim`` when ``tmmaster.sim`` is
imported; the core imports no plugin). Everything else is refused with a
:class:`ConfigError` naming the field and the value as written: a port in the host
(``192.168.1.100:502``), a URL (``http://...``, ``modbus://...``), spaces, characters no
host name has, an IPv4 address with a part missing (``192.168.1`` would silently be
``192.168.0.1``) or out of range (``192.168.1.300`` would go to a name server).
"""

from __future__ import annotations

import ipaddress
import operator
import string
import threading
from collections.abc import Callable
from typing import Any
from urllib.parse import urlsplit

from ._error_root import ConfigError

#: Opens a transport to an in-process endpoint: ``opener(url, role=..., device_id=...,
#: timeout=..., retry=..., name=...)`` returns a :class:`~tmmaster.Transport` (or raises
#: :class:`ConnectError` when nothing of that name runs).
SchemeOpener = Callable[..., Any]

#: ``scheme`` -> the opener of its ``scheme://name`` addresses (filled by plugins).
_SCHEMES: dict[str, SchemeOpener] = {}
_SCHEMES_LOCK = threading.Lock()

#: What starts an endpoint of a scheme the package ships, for the message when its
#: plugin was not imported (the message only: the core imports no plugin).
_SHIPPED_SCHEMES = {
    "sim": "no in-process simulator named {name!r}: start one with"
    " tmmaster.sim.Simulator(listen=False, name={name!r}) (sim:// is served once"
    " tmmaster.sim is imported)",
}

_NAME_PUNCTUATION = frozenset("-._")
_DIGITS_AND_DOTS = frozenset(string.digits + ".")


def register_scheme(scheme: str, opener: SchemeOpener) -> None:
    """Serve ``scheme://name`` hosts in this process through ``opener`` (for plugins).

    :func:`check_host` then takes such a host as it is, and ``Robot(host)`` opens its
    links with ``opener(url, role=..., device_id=..., timeout=..., retry=...,
    name=...)``; ``opener`` resolves the name (and raises :class:`ConnectError` when
    nothing of that name runs). ``tmmaster.sim`` registers ``sim`` when imported.

    Args:
        scheme: the URL scheme, without ``://`` (``"sim"``).
        opener: opens a transport to ``url``.

    Raises:
        ConfigError: ``scheme`` is not a plain name, or another opener serves it
            already (two plugins for one scheme).
    """
    if not scheme.isidentifier():
        raise ConfigError(f"scheme {scheme!r}: not a plain name (letters, digits, _)")
    with _SCHEMES_LOCK:
        current = _SCHEMES.get(scheme)
        if current is not None and current is not opener:
            raise ConfigError(f"{scheme}:// is served already by {current!r}")
        _SCHEMES[scheme] = opener


def scheme_opener(host: str) -> SchemeOpener | None:
    """The opener of ``host`` when it is an in-process ``scheme://name`` (None: a network host).

    Args:
        host: a host as :func:`check_host` returned it.

    Returns:
        The opener its plugin registered, or None for a host on the network.
    """
    scheme, sep, _ = host.partition("://")
    if not sep:
        return None
    with _SCHEMES_LOCK:
        return _SCHEMES.get(scheme)


def is_in_process(host: object) -> bool:
    """Whether ``host`` is an in-process ``scheme://name`` of a registered scheme (no port).

    Args:
        host: what the user gave (anything).

    Returns:
        True for a string whose scheme a plugin registered.
    """
    return isinstance(host, str) and scheme_opener(host) is not None


def check_host(host: object, *, field: str = "host", port_field: str = "port") -> str:
    """``host`` checked and normalised (``[::1]`` -> ``::1``), before any I/O.

    Args:
        host: what the user gave.
        field: its name, which starts each message (``host``, ``gripper_host``,
            ``--host``); empty: no name (a pydantic validator's, whose error names it).
        port_field: where a port belongs instead, named in messages.

    Returns:
        The host to connect to: as given, or an IPv6 address without its brackets.

    Raises:
        ConfigError: not an address, a host name or an in-process ``scheme://name`` of a
            registered scheme (:func:`register_scheme`); the message is
            ``"<field>: <what is wrong>"``, quoting the value as given and saying what
            to write instead.
    """
    prefix = f"{field}: " if field else ""
    if not isinstance(host, str):
        raise ConfigError(f"{prefix}not a string (an IP address or host name): {host!r}")
    if not host.strip():
        raise ConfigError(f"{prefix}empty; give the robot's IP address or host name")
    if "://" in host:
        if scheme_opener(host) is not None:
            return host  # an in-process endpoint, resolved where the link is opened
        raise ConfigError(_url_message(host, prefix, port_field))
    if any(c.isspace() for c in host):
        raise ConfigError(f"{prefix}{host!r} contains a space: give the address alone")
    if host.startswith("["):
        return _bracketed_ipv6(host, prefix, port_field)
    if is_ip_address(host):
        return host
    colons = host.count(":")
    if colons == 1 and host.partition(":")[2].isdigit():
        raise ConfigError(_port_message(host, prefix, port_field))
    if colons > 1:
        raise ConfigError(f"{prefix}{host!r} is not a valid IPv6 address")
    return _host_name(host, prefix)


def _bracketed_ipv6(host: str, prefix: str, port_field: str) -> str:
    """``[::1]`` -> ``::1``; a ConfigError for a port after it or anything else."""
    inner, bracket, rest = host[1:].partition("]")
    if bracket and ":" in inner and is_ip_address(inner):  # IPv6 (IPv4 has no colon)
        if not rest:
            return inner
        if rest[0] == ":" and rest[1:].isdigit():
            raise ConfigError(_port_message(host, prefix, port_field))
    raise ConfigError(f"{prefix}{host!r} is not an IPv6 address in brackets ([::1])")


def _host_name(host: str, prefix: str) -> str:
    """``host`` when it is a valid host name (not an IP address); else a ConfigError."""
    if set(host) <= _DIGITS_AND_DOTS:
        raise ConfigError(
            f"{prefix}{host!r} is not a valid IPv4 address (four numbers 0-255, as in"
            " 192.168.1.100)"
        )
    for char in host:
        if not (char.isalnum() or char in _NAME_PUNCTUATION):
            raise ConfigError(
                f"{prefix}{host!r} is not an IP address or host name ({char!r} is not"
                " allowed in one)"
            )
    labels = host.removesuffix(".").split(".")
    if any(not label for label in labels):
        raise ConfigError(f"{prefix}{host!r} is not a valid host name (an empty part)")
    if len(host) > 253 or any(len(label) > 63 for label in labels):
        raise ConfigError(
            f"{prefix}{host!r} is not a valid host name (at most 63 characters between"
            " dots, 253 in all)"
        )
    return host


def check_port(port: object, *, field: str = "port") -> int:
    """``port`` checked: an integer 1..65535 (a TCP port), before any I/O.

    Args:
        port: what the user gave.
        field: its name, which starts each message (``port``, ``gripper_port``).

    Returns:
        The port, as an ``int``.

    Raises:
        ConfigError: not an integer, or outside 1..65535 (naming ``field``).
    """
    prefix = f"{field}: " if field else ""
    try:
        if isinstance(port, bool):  # an int to Python, never a port
            raise TypeError
        number = operator.index(port)  # type: ignore[arg-type]
    except TypeError:
        raise ConfigError(f"{prefix}not an integer 1..65535: {port!r}") from None
    if not 1 <= number <= 65535:
        raise ConfigError(f"{prefix}{number} is not a TCP port (1..65535)")
    return number


def is_ip_address(host: str) -> bool:
    """Whether ``host`` is an IPv4 or IPv6 address as written (no brackets), not a name.

    Args:
        host: a host string.

    Returns:
        True for an IP address.
    """
    try:
        ipaddress.ip_address(host)
    except ValueError:
        return False
    return True


def _port_message(host: str, prefix: str, port_field: str) -> str:
    return f"{prefix}{host!r} includes a port; put the port in {port_field}"


def _url_message(host: str, prefix: str, port_field: str) -> str:
    """What to write instead of a URL: the address alone, and its port where it belongs.

    A scheme the package ships whose plugin was not imported (``sim://x`` before
    ``tmmaster.sim``) is said as what starts such an endpoint.
    """
    scheme, _, rest = host.partition("://")
    shipped = _SHIPPED_SCHEMES.get(scheme)
    if shipped is not None:
        return prefix + shipped.format(name=rest)
    try:
        parts = urlsplit(host)
        name, port = parts.hostname, parts.port
    except ValueError:
        name, port = None, None
    message = f"{prefix}{host!r} is a URL; give the address alone"
    if name:
        message += f" ({name!r})"
    if port is not None:
        message += f" and the port in {port_field} ({port})"
    return message
