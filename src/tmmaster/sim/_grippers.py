"""Simulated standalone grippers: the blog-2fg7 map and OnRobot's real 2FG7 map.

Each device works on its own :class:`RegisterBank` and drives the fingers of a shared
:class:`PhysicsBackend`; like the robot controller it is a :class:`~._device.SimDevice`
(the same tick prologue) and acts only inside :meth:`tick`, never when a register is
written. A grip is detected only when the
backend reports finger contact, i.e. the fingers closed on a real object; the
``grasp_miss`` fault hides that contact for one close. The rules are documented in
``docs/simulator-model.md``.

When a robot controller and a gripper device share one backend, exactly one of them
may step it: pass ``step_backend=False`` to the gripper.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from .._registers import GripperDriverName, GripperProfile
from ._backend import PhysicsBackend
from ._bank import RegisterBank
from ._device import Logger, SimDevice
from ._faults import Fault

#: blog-2fg7 control value that executes a move (rCTR).
BLOG_EXECUTE = 16
#: OnRobot product codes (register 1536): 2FG7 and 2FG14.
ONROBOT_2FG7_PRODUCT_CODE = 0xC0
ONROBOT_2FG14_PRODUCT_CODE = 0xC1


def _identity(reg_1031: int, version: int, build: int, git_hash: tuple[int, ...]) -> dict[str, int]:
    words = {f"firmware_hash_{i}": word for i, word in enumerate(git_hash)}
    return {
        "reg_1028": 14,
        "reg_1031": reg_1031,
        "firmware_version": version,
        "firmware_build": build,
        **words,
    }


#: Identity registers, seeded per product as the test fixture of OnRobot's official ROS 2
#: driver seeds them (OnRobot/onrobot-ros2, commit f0dcd6cd54b57505e4dc4f36662192be4bb2bbe7,
#: onrobot_gripper_hardware/tests/support/modbus_tcp_test_server.hpp). Their meaning is
#: not publicly documented; the simulator serves them so clients that read them work.
_FIXTURE_IDENTITY: dict[int, dict[str, int]] = {
    ONROBOT_2FG7_PRODUCT_CODE: _identity(
        95,
        0x0100,
        33,
        (0xB422, 0x2B25, 0x1054, 0xDEC1, 0x1291, 0x3425, 0xA623, 0x86D2, 0x8939, 0xC375),
    ),
    ONROBOT_2FG14_PRODUCT_CODE: _identity(
        196,
        0x0101,
        21,
        (0x0E03, 0x7259, 0x7CC6, 0x6EF5, 0xF5EC, 0x4174, 0xA143, 0x73E2, 0x3215, 0xD071),
    ),
}


class _GripperDevice(SimDevice[GripperProfile]):
    """A standalone gripper: after the device prologue, finish a move, take commands, publish."""

    #: A move was taken and the fingers have not stopped yet.
    _busy = False
    #: The last move taken closes the fingers.
    _closing = False
    #: A grasp_miss fault hides the contact of the last close.
    _miss = False

    @property
    def busy(self) -> bool:
        """True while a taken move has not finished."""
        return self._busy

    def _run(self, dt: float, ready: bool) -> None:
        if ready and self._busy and not self._backend.gripper_state().moving:
            self._busy = False
            self._log.info("sim.gripper_done", device=self._name, detected=self._detected())
        if ready and self._initialised:
            self._handle_commands()
        self._publish(ready)

    @abstractmethod
    def _handle_commands(self) -> None:
        """Act on the command registers (the device is ready and initialised)."""

    @abstractmethod
    def _publish(self, ready: bool) -> None:
        """Publish the gripper's status registers."""

    def _move(self, width_mm: float, *, speed_mm_s: float, force_n: float) -> bool:
        """Drive the fingers; True when the backend took the move."""
        current = self._backend.gripper_state().width_mm
        closing = width_mm < current
        try:
            self._backend.drive_gripper(width_mm, speed_mm_s=speed_mm_s, force_n=force_n)
        except Exception as exc:  # a backend failure must not kill the server: log, no move
            self._log.warning("sim.backend_failed", device=self._name, error=repr(exc))
            return False
        self._closing = closing
        self._miss = False
        if closing:
            number, self._miss = self._count_grasp()
            if self._miss:
                self._log_grasp_miss(number)
        self._busy = True
        self._log.info(
            "sim.command_accepted",
            device=self._name,
            width_mm=width_mm,
            speed_mm_s=speed_mm_s,
            force_n=force_n,
            closing=closing,
        )
        return True

    def _stop(self) -> None:
        # The backend has no finger stop: driving to the current width holds the fingers.
        width = self._backend.gripper_state().width_mm
        try:
            self._backend.drive_gripper(width, speed_mm_s=1.0, force_n=0.0)
        except Exception as exc:  # a backend failure must not kill the server: log only
            self._log.warning("sim.backend_failed", device=self._name, error=repr(exc))
        self._busy = False
        self._log.info("sim.gripper_stopped", device=self._name, width_mm=width)

    def _detected(self) -> bool:
        """Grip detected: fingers stopped on an object, unless grasp_miss hides it."""
        state = self._backend.gripper_state()
        return state.contact and not state.moving and not self._miss


class Blog2FG7Device(_GripperDevice):
    """The second article's gripper map: control 16 executes a move to width with force."""

    def __init__(
        self,
        profile: GripperProfile,
        bank: RegisterBank,
        backend: PhysicsBackend,
        *,
        faults: Sequence[Fault] = (),
        init_time_s: float = 0.2,
        speed_mm_s: float = 100.0,
        step_backend: bool = True,
        log: Logger | None = None,
    ) -> None:
        super().__init__(
            profile,
            bank,
            backend,
            faults=faults,
            init_time_s=init_time_s,
            step_backend=step_backend,
            log=log,
        )
        if speed_mm_s <= 0:
            raise ValueError(f"speed_mm_s must be > 0, got {speed_mm_s}")
        self._speed = speed_mm_s
        self._control_writes = bank.field_writes("control")
        self._publish(True)

    def _handle_commands(self) -> None:
        writes = self._bank.field_writes("control")
        written = writes != self._control_writes
        self._control_writes = writes
        control = int(self._bank.get("control"))
        if control == BLOG_EXECUTE:
            width = float(self._bank.get("width"))
            force = float(self._bank.get("force"))
            if self._move(width, speed_mm_s=self._speed, force_n=force):
                # Status first, then the acknowledgement (control back to 0), like the
                # article robot's clear-on-accept: whoever sees 0 sees the move running.
                self._set_status(object_status=0, motion_state=1)
                self._bank.set("control", 0)
                self._control_writes = self._bank.field_writes("control")
        elif control == 0 and written and self._busy:
            # Only a master's write of 0 stops: the device's own reset to 0 must not.
            self._stop()
        elif control != 0:
            self._log.warning("sim.command_rejected", device=self._name, control=control)
            self._bank.set("control", 0)

    def _set_status(self, *, object_status: int, motion_state: int) -> None:
        self._bank.set("object_status", object_status)
        self._bank.set("motion_state", motion_state)

    def _publish(self, ready: bool) -> None:
        self._bank.set("gripper_status", 3 if self._initialised else 1)
        if not self._initialised or not ready:
            self._set_status(object_status=0, motion_state=0)
            return
        if self._busy:
            self._set_status(object_status=0, motion_state=1)
        elif self._detected():
            self._set_status(object_status=2 if self._closing else 1, motion_state=0)
        else:
            self._set_status(object_status=3, motion_state=0)


@dataclass(frozen=True)
class OnRobotLimits:
    """An OnRobot 2FG7's stroke, speeds and forces (its presets and clamps)."""

    #: The smallest and largest external grip widths, mm.
    min_external_mm: float = 1.0
    max_external_mm: float = 39.0
    #: An internal grip's widths are the external ones plus this, mm.
    internal_offset_mm: float = 34.0
    #: The finger speeds at 1 % and at 100 %, mm/s.
    speed_range_mm_s: tuple[float, float] = (16.0, 450.0)
    #: The smallest force (a requested 0 gets it) and the power setting's ceiling, N.
    min_force_n: float = 20.0
    max_force_n: float = 100.0


class OnRobot2FG7Device(_GripperDevice):
    """OnRobot 2FG7 on a Compute Box: grip external/internal/stop, status bits, live widths."""

    def __init__(
        self,
        profile: GripperProfile,
        bank: RegisterBank,
        backend: PhysicsBackend,
        *,
        faults: Sequence[Fault] = (),
        init_time_s: float = 0.2,
        limits: OnRobotLimits = OnRobotLimits(),
        product_code: int = ONROBOT_2FG7_PRODUCT_CODE,
        step_backend: bool = True,
        log: Logger | None = None,
    ) -> None:
        if product_code not in _FIXTURE_IDENTITY:
            raise ValueError(
                f"product_code must be 0xC0 (2FG7) or 0xC1 (2FG14), got {product_code}"
            )
        if not 0 < limits.min_force_n <= limits.max_force_n:
            raise ValueError("need 0 < min_force_n <= max_force_n")
        super().__init__(
            profile,
            bank,
            backend,
            faults=faults,
            init_time_s=init_time_s,
            step_backend=step_backend,
            log=log,
        )
        self._min_ext = limits.min_external_mm
        self._max_ext = limits.max_external_mm
        self._offset = limits.internal_offset_mm
        self._speeds = limits.speed_range_mm_s
        self._min_force = limits.min_force_n
        self._force = 0.0
        self._internal_grip = False
        # Presets a master reads at run time instead of hard-coding the stroke.
        bank.set("min_external_width", limits.min_external_mm)
        bank.set("max_external_width", limits.max_external_mm)
        bank.set("min_internal_width", limits.min_external_mm + limits.internal_offset_mm)
        bank.set("max_internal_width", limits.max_external_mm + limits.internal_offset_mm)
        bank.set("product_code", product_code)
        # The force ceiling of the power setting (the box's default power, fixture value).
        bank.set("max_force", limits.max_force_n)
        for name, value in _FIXTURE_IDENTITY[product_code].items():
            if self._profile.has(name):
                bank.set(name, value)
        self._publish(True)

    def speed_mm_s(self, percent: float) -> float:
        """Finger speed for a target speed in % (1..100 mapped linearly, clamped)."""
        low, high = self._speeds
        pct = min(max(percent, 1.0), 100.0)
        return low + (pct - 1.0) / 99.0 * (high - low)

    def force_n(self, requested: float) -> float:
        """The force the device applies: 0 = its minimum; else clamped to min..max_force."""
        ceiling = float(self._bank.get("max_force"))
        if requested == 0:
            return self._min_force
        return min(max(requested, self._min_force), ceiling)

    def _handle_commands(self) -> None:
        command = int(self._bank.get("command"))
        if command == 0:
            return
        label = self._profile.field("command").label(command)
        if label == "stop":
            self._stop()
        elif label in ("grip_external", "grip_internal"):
            width = float(self._bank.get("target_width"))
            external = width if label == "grip_external" else width - self._offset
            clamped = min(max(external, self._min_ext), self._max_ext)
            if clamped != external:
                self._log.warning(
                    "sim.width_clamped",
                    device=self._name,
                    requested_mm=width,
                    grip=label,
                )
            requested_force = float(self._bank.get("target_force"))
            force = self.force_n(requested_force)
            percent = float(self._bank.get("target_speed"))
            if (requested_force not in (0.0, force)) or not 1.0 <= percent <= 100.0:
                # Raw network writes can hold anything; the real box limits, we log it.
                self._log.warning(
                    "sim.value_clamped",
                    device=self._name,
                    force_n=requested_force,
                    speed_percent=percent,
                )
            speed = self.speed_mm_s(percent)
            if self._move(clamped, speed_mm_s=speed, force_n=force):
                self._force = force
                self._internal_grip = label == "grip_internal"
                self._publish(True)
        else:
            self._log.warning("sim.command_rejected", device=self._name, command=command)
        # The command register is reset once taken (status already shows busy).
        self._bank.set("command", 0)

    def _publish(self, ready: bool) -> None:
        if not ready:
            return
        state = self._backend.gripper_state()
        field = self._profile.field("status")
        detected = self._detected()
        busy = self._busy or not self._initialised
        raw = (int(busy) << field.bits["busy"]) | (int(detected) << field.bits["grip_detected"])
        self._bank.set("status", raw)
        self._bank.set("external_width", round(state.width_mm, 1))
        self._bank.set("internal_width", round(state.width_mm + self._offset, 1))
        # Signed: negative while closing on an object (an external grip), as OnRobot's
        # fixture shows (-40); positive for an internal grip (an assumption).
        sign = 1 if self._internal_grip else -1
        self._bank.set("force", sign * round(self._force) if detected else 0)


#: The simulated device of each gripper protocol (the drivers' registry is
#: ``tmmaster._gripper.GRIPPER_DRIVERS``; both are keyed by ``GripperDriverName``).
GRIPPER_DEVICES: Mapping[GripperDriverName, type[Blog2FG7Device | OnRobot2FG7Device]] = {
    "blog-2fg7": Blog2FG7Device,
    "onrobot-2fg7": OnRobot2FG7Device,
}
