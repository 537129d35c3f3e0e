"""What every simulated device does on a tick before its own rules: the shared device base.

A device (the robot controller, a standalone gripper) owns no socket, no thread and no
clock: the server (or a test) calls :meth:`SimDevice.tick` with the simulated time that
passed. The prologue is the same for all of them, in this order: account the time,
advance the physics backend (unless another device steps it), check that the backend is
ready (else rebuild it, at most once per :data:`REINITIALIZE_RETRY_S`), fire timed
faults, finish initialising once ``init_time_s`` has passed. Then the device runs its
own rules (:meth:`SimDevice._run`). Grasp-miss faults and the grasp count are shared too:
both the robot's gripper output and a standalone gripper close fingers.
"""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from typing import Any, Generic, Protocol, TypeVar

from .._checks import is_finite_number, shown
from .._error_root import ConfigError
from .._logging import get_logger
from .._registers import RegisterMap
from ._backend import PhysicsBackend
from ._bank import RegisterBank
from ._faults import Fault, GraspMissFault

#: While the backend stays not ready, ``reinitialize()`` is retried this often (simulated s).
REINITIALIZE_RETRY_S = 1.0

#: The register map a device serves (a robot or a gripper profile).
ProfileT = TypeVar("ProfileT", bound=RegisterMap)


class Logger(Protocol):
    """The part of a structlog logger the simulator uses."""

    def info(self, event: str, **kw: Any) -> Any:
        """Log an ordinary state change."""

    def warning(self, event: str, **kw: Any) -> Any:
        """Log a fault or a refused command."""


class SimDevice(ABC, Generic[ProfileT]):
    """A simulated Modbus device: one register bank, a shared backend, a tick."""

    def __init__(
        self,
        profile: ProfileT,
        bank: RegisterBank,
        backend: PhysicsBackend,
        *,
        faults: Sequence[Fault],
        init_time_s: float,
        step_backend: bool,
        log: Logger | None,
    ) -> None:
        if bank.register_map is not profile and bank.register_map != profile:
            raise ValueError("the register bank must serve the device's profile")
        if not (is_finite_number(init_time_s) and init_time_s >= 0):
            raise ConfigError(f"init_time_s must be a finite number >= 0, got {shown(init_time_s)}")
        self._profile = profile
        self._bank = bank
        self._backend = backend
        self._init_time_s = init_time_s
        self._step_backend = step_backend
        self._log: Logger = get_logger("tmmaster.sim") if log is None else log
        self._time_s = 0.0
        #: The wall clock of the device's records (its motion log): ``time.monotonic``;
        #: a Simulator gives the time its running tick was due.
        self.clock: Callable[[], float] = time.monotonic
        self._initialised = False
        self._reinit_at: float | None = None
        self._grasps = 0
        self._grasp_misses: set[int] = set()
        for fault in faults:
            self._add_fault(fault)

    @property
    def bank(self) -> RegisterBank:
        """The register memory the device works on."""
        return self._bank

    @property
    def time_s(self) -> float:
        """Simulated seconds since the device started."""
        return self._time_s

    @property
    def initialised(self) -> bool:
        """True once ``init_time_s`` has passed (the start-up done, whatever its outcome)."""
        return self._initialised

    @property
    def grasps(self) -> int:
        """Gripper close commands executed so far."""
        return self._grasps

    @property
    def _name(self) -> str:
        """The device name logged with every event (its profile's name)."""
        return self._profile.name

    # -- faults ------------------------------------------------------------------------

    def inject(self, fault: Fault) -> None:
        """Add a device fault at run time; its at_move / at_grasp / after_s count from now."""
        shifted = self._from_now(fault)
        if shifted is None:
            return
        self._add_fault(shifted)
        self._log.info("sim.fault_injected", device=self._name, fault=shifted.kind)

    def clear_faults(self) -> None:
        """Forget every device fault not yet fired (an effect already under way stays)."""
        self._grasp_misses.clear()

    def _from_now(self, fault: Fault) -> Fault | None:
        """``fault`` with its trigger counted from now; None for a fault the device ignores."""
        if isinstance(fault, GraspMissFault):
            return fault.model_copy(update={"at_grasp": fault.at_grasp + self._grasps})
        return None

    def _add_fault(self, fault: Fault) -> None:
        if isinstance(fault, GraspMissFault):
            self._grasp_misses.add(fault.at_grasp)

    def _count_grasp(self) -> tuple[int, bool]:
        """Count one more close: its number, and whether a grasp_miss fault hides it."""
        self._grasps += 1
        return self._grasps, self._grasps in self._grasp_misses

    def _log_grasp_miss(self, number: int) -> None:
        self._log.warning("sim.fault_fired", device=self._name, fault="grasp_miss", grasp=number)

    # -- the tick ----------------------------------------------------------------------

    def tick(self, dt: float) -> None:
        """Advance the device (and, unless told otherwise, the backend) by ``dt`` seconds."""
        if not math.isfinite(dt) or dt < 0:
            raise ValueError(f"dt must be a finite number >= 0, got {dt}")
        self._time_s += dt
        if self._step_backend:
            self._backend.step(dt)
        ready = self._check_ready()
        self._fire_timed_faults()
        if not self._initialised and self._time_s + 1e-9 >= self._init_time_s:
            self._initialised = True
            self._log.info("sim.initialised", device=self._name)
            self._on_initialised()
        self._run(dt, ready)

    @abstractmethod
    def _run(self, dt: float, ready: bool) -> None:
        """The device's own rules for this tick, after the shared prologue."""

    def _fire_timed_faults(self) -> None:
        """Fire the faults due at this simulated time (none by default)."""

    def _on_initialised(self) -> None:
        """The device just finished initialising (nothing more by default)."""

    def _on_rebuilt(self, survived: bool) -> None:
        """The backend was rebuilt; ``survived`` is what ``reinitialize()`` returned."""

    def _check_ready(self) -> bool:
        if self._backend.is_ready():
            if self._reinit_at is not None:
                self._log.info("sim.backend_ready", device=self._name)
            self._reinit_at = None
            return True
        if self._reinit_at is None or self._time_s - self._reinit_at >= REINITIALIZE_RETRY_S:
            self._log.warning("sim.backend_reinitialize", device=self._name)
            self._reinit_at = self._time_s
            self._on_rebuilt(self._backend.reinitialize())
        return self._backend.is_ready()
