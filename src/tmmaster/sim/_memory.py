"""A transport to an in-process simulator: the TCP server's request path without sockets.

:class:`MemoryTransport` is a :class:`~tmmaster.Transport` like the
Modbus TCP transport: the same counters, retry rules and error types. Each request is
handed to the simulator's event loop thread and served by the same
:class:`~tmmaster.sim._server.DeviceServer` gate as a TCP request: the device-id
check, the request log and the network faults. A dropped connection raises
:class:`ConnectionLostError` (after the write was applied when the fault loses the
answer), a ``slow_responses`` delay longer than the timeout raises
:class:`ResponseTimeoutError` while the device still applies the write later, and
``stop_listening`` refuses connections for its duration.

The ``sim://name`` addresses of this process resolve here: a started simulator
registers its name (:func:`register_endpoint`) and ``tmmaster.sim`` serves the ``sim``
scheme of the core's in-process registry with :func:`open_endpoint`.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Protocol, TypeVar

from .._exceptions import (
    ConfigError,
    ConnectError,
    ConnectionLostError,
    ResponseTimeoutError,
)
from .._retry import RetryPolicy
from .._transport import Transport, refused_error
from ._server import DeviceServer, MemoryAnswer

T = TypeVar("T")

#: ``sim://name`` -> opener of a transport to that running simulator, for one device
#: role ("robot", "gripper").
EndpointOpener = Callable[..., Transport]
_ENDPOINTS: dict[str, EndpointOpener] = {}
_ENDPOINTS_LOCK = threading.Lock()


def register_endpoint(url: str, opener: EndpointOpener) -> None:
    """Make ``url`` (e.g. ``sim://sim-1``) open transports through ``opener``.

    Args:
        url: the simulator's address, ``sim://<name>``.
        opener: opens a transport to it (keyword arguments ``role``, ``device_id``,
            ``timeout``, ``retry``, ``name``).

    Raises:
        ConfigError: ``url`` already belongs to another running simulator of this
            process (two of one name): replacing it would silently send the first
            one's robots to the second.
    """
    with _ENDPOINTS_LOCK:
        current = _ENDPOINTS.get(url)
        if current is not None and current != opener:
            raise ConfigError(
                f"{url} is already taken by a running simulator in this process:"
                " give each simulator its own name, or close the first one"
            )
        _ENDPOINTS[url] = opener


def unregister_endpoint(url: str, opener: EndpointOpener | None = None) -> None:
    """Forget ``url`` (safe when unknown).

    Args:
        url: the simulator's address to forget.
        opener: when given, forget ``url`` only while it still opens through this
            opener (a simulator refused for a taken name must not free the other's).
    """
    with _ENDPOINTS_LOCK:
        if opener is None or _ENDPOINTS.get(url) == opener:
            _ENDPOINTS.pop(url, None)


def open_endpoint(
    url: str,
    *,
    role: str = "robot",
    device_id: int = 1,
    timeout: float = 1.0,
    retry: RetryPolicy | None = None,
    name: str = "device",
) -> Transport:
    """A transport to the running simulator at ``url`` (the core's opener of ``sim://``).

    Args:
        url: ``sim://<name>``.
        role: the device, ``"robot"`` or ``"gripper"``.
        device_id: the Modbus unit id of the requests.
        timeout: bound of one request, s.
        retry: how failed requests are retried; None: the default policy.
        name: the link's name in messages and logs.

    Returns:
        An in-memory transport to that simulator's device.

    Raises:
        ConnectError: no simulator of that name runs in this process.
    """
    with _ENDPOINTS_LOCK:
        opener = _ENDPOINTS.get(url)
        running = ", ".join(sorted(_ENDPOINTS)) or "none"
    if opener is None:
        wanted = url.partition("://")[2]
        raise ConnectError(
            f"no in-process endpoint {url!r}: no simulator named {wanted!r} runs in this"
            f" process (start one with Simulator(listen=False, name={wanted!r});"
            f" running: {running})"
        )
    return opener(role=role, device_id=device_id, timeout=timeout, retry=retry, name=name)


class SimulatorLoop(Protocol):
    """What a MemoryTransport needs of its simulator (a :class:`Simulator` is one)."""

    @property
    def url(self) -> str:
        """The simulator's ``sim://`` address."""

    @property
    def running(self) -> bool:
        """True while the simulator's loop runs."""

    def call(self, fn: Callable[[], T]) -> T:
        """Run ``fn`` on the simulator's loop thread and return its result."""

    def call_later(self, delay_s: float, fn: Callable[[], object]) -> None:
        """Run ``fn`` on the loop thread after ``delay_s`` seconds."""

    def device_server(self, device: str = "robot") -> DeviceServer:
        """The server of ``device`` ("robot" or "gripper")."""


def frame_bytes(function_code: int, count: int, *, request: bool, refused: bool) -> int:
    """Size of the Modbus TCP frame (7-byte MBAP header + PDU) a request or answer takes."""
    header = 7
    bits = (count + 7) // 8
    if request:
        pdu = {5: 5, 15: 6 + bits, 16: 6 + 2 * count}.get(function_code, 5)
    elif refused:
        pdu = 2
    elif function_code in (1, 2):
        pdu = 2 + bits
    elif function_code in (3, 4):
        pdu = 2 + 2 * count
    else:
        pdu = 5
    return header + pdu


class MemoryTransport(Transport):
    """Talks to one device (``"robot"`` or ``"gripper"``) of an in-process Simulator.

    A :class:`~tmmaster.Transport` without a socket: each request goes through the
    simulator's request path (device id, request log, network faults) as a TCP request
    would. ``Robot(sim.url)`` picks one for a ``Simulator(listen=False)``.

    Example:
        ```python
        from tmmaster import Robot
        from tmmaster.sim import MemoryTransport, Simulator

        with Simulator(listen=False) as sim:
            robot = Robot(sim.url, link=MemoryTransport(sim))
            with robot:
                print(robot.status().mode)
        ```

    Args:
        sim: The simulator (started or not).
        device: ``"robot"`` or ``"gripper"``.
        device_id: The Modbus unit id of the requests.
        timeout: Bound of one request, s.
        retry: How failed requests are retried; None: the default policy.
        name: Its name in messages and logs; None: ``device``.
    """

    def __init__(
        self,
        sim: SimulatorLoop,
        device: str = "robot",
        *,
        device_id: int = 1,
        timeout: float = 1.0,
        retry: RetryPolicy | None = None,
        name: str | None = None,
    ) -> None:
        server = sim.device_server(device)
        super().__init__(
            sim.url,
            server.port,
            device_id=device_id,
            timeout=timeout,
            retry=retry,
            name=name or device,
        )
        self._sim = sim
        self._server: DeviceServer = server
        self._link: int | None = None

    @property
    def endpoint(self) -> tuple[str, int, int]:
        """The simulated device by its URL, port and unit id: nothing to resolve (a URL
        given to the host name resolver could wait on a DNS server for seconds)."""
        return self.host, self.port, self.device_id

    def _link_open(self) -> bool:
        return self._link is not None

    def _open_link(self) -> None:
        if not self._sim.running:
            raise ConnectError(f"cannot connect to {self.name} at {self.host}: not running")
        self._link = self._sim.call(self._server.memory_connect)

    def _close_link(self) -> None:
        link, self._link = self._link, None
        if link is not None and self._sim.running:
            self._sim.call(lambda: self._server.memory_disconnect(link))

    def _exchange(
        self, what: str, function_code: int, address: int, count: int, values: list[int] | None
    ) -> list[int]:
        link = self._link
        if link is None or not self._sim.running:
            raise ConnectionLostError(f"{self.name}: connection lost during {what}")
        self.stats.bytes_sent += frame_bytes(function_code, count, request=True, refused=False)
        device_id = self.device_id
        answer: MemoryAnswer = self._sim.call(
            lambda: self._server.memory_request(
                link, device_id, function_code, address, count, values
            )
        )
        if answer.lost != "none":
            raise ConnectionLostError(f"{self.name}: connection lost during {what}")
        if answer.delay_s > 0:
            if answer.delay_s >= self.timeout:
                time.sleep(self.timeout)
                if answer.pending:
                    # The device still executes it once its delay is over, as over TCP.
                    self._sim.call_later(
                        answer.delay_s - self.timeout,
                        lambda: self._server.memory_apply(function_code, address, count, values),
                    )
                raise ResponseTimeoutError(
                    f"{self.name}: no answer to {what} within {self.timeout:g} s"
                )
            time.sleep(answer.delay_s)
            if answer.pending:
                answer = self._sim.call(
                    lambda: self._server.memory_apply(function_code, address, count, values)
                )
                if answer.lost != "none":
                    raise ConnectionLostError(f"{self.name}: connection lost during {what}")
        refused = bool(answer.refused)
        self.stats.bytes_received += frame_bytes(
            function_code, count, request=False, refused=refused
        )
        if refused:
            raise refused_error(answer.refused, name=self.name, what=what)
        return answer.words
