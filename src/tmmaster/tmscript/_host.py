"""How a running script reaches the world: the :class:`Host` protocol, and :class:`NullHost`.

The interpreter calls a host for everything outside the script: the clock, the dashboard,
Modbus devices, the motion queue, kinematics. A host answers at once (it never blocks):
waiting (``Sleep``, ``WaitFor``, ``WaitQueueTag``) is done by the interpreter, which polls
the host on each :meth:`Execution.step`. A host reports a failure by raising
:class:`HostError`; the interpreter turns it into a ``TMScriptRuntimeError`` at the call.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, Protocol, runtime_checkable

__all__ = [
    "Host",
    "HostError",
    "ModbusCommunicationError",
    "ModbusDevice",
    "MotionCall",
    "NullHost",
    "NullHostError",
]


class HostError(Exception):
    """A host could not do what the script asked (a Modbus timeout, a rejected motion...)."""


class ModbusCommunicationError(HostError):
    """The device refused a request or did not answer it (an exception answer, a timeout).

    ``modbus_write`` returns false on it ("an error occurred in Modbus communication",
    TMscript 2.24 §16.11, p. 436); other functions fail with it.
    """


@dataclass(frozen=True, slots=True)
class ModbusDevice:
    """A Modbus TCP device as the script declared it (TMscript 2.24 §16.1)."""

    #: The variable's name (``ModbusTCP dev = ...`` is ``"dev"``).
    name: str
    #: The IP address or host name.
    host: str
    #: The TCP port.
    port: int = 502
    #: The slave ID of this request.
    unit: int = 0
    #: Read/write timeout, ms.
    timeout_ms: int = 10000


@dataclass(frozen=True, slots=True)
class MotionCall:
    """One motion for the robot's queue: ``PTP()``, ``Line()`` or ``Circle()``.

    TMscript 2.24 §13.8, §13.10, §13.12.
    """

    #: ``"PTP"``, ``"Line"`` or ``"Circle"``.
    kind: Literal["PTP", "Line", "Circle"]
    #: The data format string: ``"CPP"``, ``"JPP"`` for PTP; ``"CPP"``, ``"CAR"``... for
    #: Line; ``"CPP"``, ``"CAP"``, ``"CDP"`` for Circle (target, speed, blending letters).
    format: str
    #: Six values: X, Y, Z (mm), RX, RY, RZ (degrees) or six joint angles.
    target: tuple[float, ...]
    #: Percentage of speed, or mm/s for Line's and Circle's ``A``/``D`` speed formats.
    speed: int
    #: Time to reach top speed, ms.
    accel_time_ms: int
    #: Percentage, or radius in mm for Line's ``R`` blending format.
    blending: int
    #: The script's last bool argument, as the manual names it: True disables precise
    #: positioning (TMscript 2.24, 13.8, p. 331).
    disable_precise_positioning: bool
    #: PTP's pose configuration ``[Config1, Config2, Config3]``, when given.
    pose: tuple[int, ...] | None = None
    #: PTP's reference joint angles, when given.
    reference_joints: tuple[float, ...] | None = None
    #: Circle's point on the arc (X, Y, Z, RX, RY, RZ).
    via: tuple[float, ...] | None = None
    #: Circle's arc angle, deg (0: from here through ``via`` to ``target``).
    arc_angle: int = 0
    #: Circle's rotation (Syntax 2: 0 linear interpolation, 1 keep rotation), when given.
    rotation: int | None = None


@runtime_checkable
class Host(Protocol):
    """What a script needs from the robot (or the simulator). All methods return at once."""

    def now_s(self) -> float:
        """The host's clock in seconds (simulated time in the simulator).

        Returns:
            The time, s.
        """
        ...

    def display(self, text: str) -> None:
        """Show a ``Display()`` text on the dashboard (one call per ``Display()``).

        Args:
            text: The text.
        """
        ...

    def modbus_request(
        self,
        device: ModbusDevice,
        function: int,
        address: int,
        count: int,
        values: Sequence[int] | None,
    ) -> list[int]:
        """One Modbus request.

        Args:
            device: The device and slave ID.
            function: 1, 2, 3, 4 (read coils, discrete inputs, holding, input
                registers) or 5, 6, 15, 16 (write a coil, a register, coils, registers).
            address: The starting address.
            count: How many coils or registers.
            values: For writes, the words (0..65535) or bits (0/1); None for reads.

        Returns:
            The words or bits read (``count`` of them); an empty list for writes.

        Raises:
            HostError: The request failed.
        """
        ...

    def modbus_ready(self, device: ModbusDevice) -> bool:
        """False while ``device`` cannot answer a request yet: the script waits at the call.

        A request takes time on a real link; a host models that latency (or a slow link)
        by answering False until the request may go out. The script's statement waits
        there, as ``modbus_read`` on a robot waits for the answer.

        Args:
            device: The device the script is about to talk to.

        Returns:
            Whether a request may go out now.
        """
        ...

    def motion(self, call: MotionCall) -> bool:
        """Queue a motion (it runs later; the script goes on at once).

        Args:
            call: The motion.

        Returns:
            False when the robot rejects the command (the motion function then returns
            False, TMscript 2.24 §13.8, p. 331): nothing was queued.
        """
        ...

    def queue_tag(self, tag: int, wait: int) -> None:
        """Tag the motion queued last with ``tag`` (1..15) (TMscript 2.24 §13.1).

        Args:
            tag: The tag number, 1..15.
            wait: ``QueueTag``'s wait argument, as given.
        """
        ...

    def queue_tag_done(self, tag: int) -> bool | None:
        """Whether the motions up to ``tag`` are done; None when no such tag exists.

        Args:
            tag: The tag number.

        Returns:
            True once done, False before, None for an unknown tag.
        """
        ...

    def stop_and_clear_buffer(self) -> None:
        """Stop the robot and clear the motion queue (§13.4)."""
        ...

    def change_base(self, value: str | Sequence[float]) -> None:
        """The base of the following motions: a base name or X, Y, Z, RX, RY, RZ (§13.5).

        Args:
            value: A base name, or the base as six numbers (mm, degrees).
        """
        ...

    def change_tcp(
        self,
        value: str | Sequence[float],
        mass: float | None = None,
        inertia: Sequence[float] | None = None,
    ) -> None:
        """The tool of the following motions: a TCP name or X, Y, Z, RX, RY, RZ (§13.6).

        Args:
            value: A TCP name, or the TCP as six numbers (mm, degrees).
            mass: The tool's mass, kg, when given.
            inertia: The tool's inertia values, when given.
        """
        ...

    def inversekin(
        self, pose: Sequence[float], reference: Sequence[float] | None = None
    ) -> list[float]:
        """Joint angles of a Cartesian pose (§6.35).

        Args:
            pose: X, Y, Z (mm), RX, RY, RZ (degrees).
            reference: Three pose configuration numbers or six reference joint angles.

        Returns:
            Six joint angles, degrees; empty when the pose is unreachable.
        """
        ...

    def forwardkin(self, joints: Sequence[float]) -> list[float]:
        """The Cartesian pose of six joint angles (§6.36).

        Args:
            joints: Six joint angles, degrees.

        Returns:
            X, Y, Z (mm), RX, RY, RZ (degrees); empty when it cannot be computed.
        """
        ...

    def pause(self) -> None:
        """The script called ``Pause()``: pause the project and the robot's motion (§5.2)."""
        ...


class NullHostError(HostError):
    """A script that moves the robot or talks Modbus ran without a robot."""


class NullHost:
    """A host for scripts that move nothing: a real clock, ``Display()`` to a callback.

    Any motion, kinematics or Modbus call fails naming the function.

    Args:
        on_display: Called with each ``Display()`` text; None: print it.
        clock: The clock, s.
    """

    def __init__(
        self,
        on_display: Callable[[str], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._on_display = on_display if on_display is not None else print
        self._clock = clock

    def now_s(self) -> float:
        """The clock's reading in seconds.

        Returns:
            The time, s.
        """
        return self._clock()

    def display(self, text: str) -> None:
        """Pass the text to the callback.

        Args:
            text: The ``Display()`` text.
        """
        self._on_display(text)

    @staticmethod
    def _refuse(what: str) -> NullHostError:
        return NullHostError(
            f"{what}: this script moves the robot or talks Modbus: "
            "run it on a robot or in the simulator"
        )

    def modbus_ready(self, device: ModbusDevice) -> bool:
        """Always ready (and any request is refused).

        Args:
            device: Ignored.

        Returns:
            True.
        """
        return True

    def modbus_request(
        self,
        device: ModbusDevice,
        function: int,
        address: int,
        count: int,
        values: Sequence[int] | None,
    ) -> list[int]:
        """Refuse: this host moves nothing and talks to no device.

        Args:
            device: Ignored.
            function: Ignored.
            address: Ignored.
            count: Ignored.
            values: Ignored.

        Returns:
            Never.

        Raises:
            NullHostError: Always (naming the function).
        """
        raise self._refuse("Modbus")

    def motion(self, call: MotionCall) -> bool:
        """Refuse: this host moves nothing and talks to no device.

        Args:
            call: The motion (named in the message).

        Returns:
            Never.

        Raises:
            NullHostError: Always (naming the function).
        """
        raise self._refuse(call.kind)

    def queue_tag(self, tag: int, wait: int) -> None:
        """Refuse: this host moves nothing and talks to no device.

        Args:
            tag: Ignored.
            wait: Ignored.

        Raises:
            NullHostError: Always (naming the function).
        """
        raise self._refuse("QueueTag")

    def queue_tag_done(self, tag: int) -> bool | None:
        """Refuse: this host moves nothing and talks to no device.

        Args:
            tag: Ignored.

        Returns:
            Never.

        Raises:
            NullHostError: Always (naming the function).
        """
        raise self._refuse("WaitQueueTag")

    def stop_and_clear_buffer(self) -> None:
        """Refuse: this host moves nothing and talks to no device.

        Raises:
            NullHostError: Always (naming the function).
        """
        raise self._refuse("StopAndClearBuffer")

    def change_base(self, value: str | Sequence[float]) -> None:
        """Refuse: this host moves nothing and talks to no device.

        Args:
            value: Ignored.

        Raises:
            NullHostError: Always (naming the function).
        """
        raise self._refuse("ChangeBase")

    def change_tcp(
        self,
        value: str | Sequence[float],
        mass: float | None = None,
        inertia: Sequence[float] | None = None,
    ) -> None:
        """Refuse: this host moves nothing and talks to no device.

        Args:
            value: Ignored.
            mass: Ignored.
            inertia: Ignored.

        Raises:
            NullHostError: Always (naming the function).
        """
        raise self._refuse("ChangeTCP")

    def inversekin(
        self, pose: Sequence[float], reference: Sequence[float] | None = None
    ) -> list[float]:
        """Refuse: this host moves nothing and talks to no device.

        Args:
            pose: Ignored.
            reference: Ignored.

        Returns:
            Never.

        Raises:
            NullHostError: Always (naming the function).
        """
        raise self._refuse("inversekin")

    def forwardkin(self, joints: Sequence[float]) -> list[float]:
        """Refuse: this host moves nothing and talks to no device.

        Args:
            joints: Ignored.

        Returns:
            Never.

        Raises:
            NullHostError: Always (naming the function).
        """
        raise self._refuse("forwardkin")

    def pause(self) -> None:
        """Nothing to pause: the execution reports paused until resumed."""
