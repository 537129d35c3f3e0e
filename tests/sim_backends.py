"""Test-only physics backends, and what the tests of both built-in backends share.

:data:`BACKENDS` parametrizes a test over the kinematic and the MuJoCo backend (MuJoCo
skipped without its extra); :func:`until_fault` steps a backend until a condition or a
fault.

:class:`SlowSettlingBackend` stands in for an Isaac Sim scene: the arm keeps
oscillating for a while after a motion, and the physics view is invalidated (as on a
simulation stop/restart) until the controller calls ``reinitialize()``. Controller
tests use it to prove that commands arriving meanwhile are queued and retried.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Callable

import pytest

from tmmaster._pose import MotionType, Pose
from tmmaster._robot_models import RobotModel
from tmmaster.sim._backend import BackendFault, PhysicsBackend
from tmmaster.sim._kinematic import DEFAULT_HOME, KinematicBackend
from tmmaster.sim._world import World

HAS_MUJOCO = importlib.util.find_spec("mujoco") is not None
NEEDS_MUJOCO = pytest.mark.skipif(not HAS_MUJOCO, reason="the MuJoCo backend needs the extra")
#: Both built-in physics backends, by name.
BACKENDS = ["kinematic", pytest.param("mujoco", marks=NEEDS_MUJOCO)]
#: The simulated step the tests advance a backend by, s (a 50 Hz tick).
STEP_S = 0.02


def until_fault(
    backend: PhysicsBackend, done: Callable[[], bool], limit_s: float = 5.0
) -> BackendFault | None:
    """Step ``backend`` until ``done()``: None, or the fault that stopped the arm first.

    Raises:
        AssertionError: Neither within ``limit_s`` simulated seconds.
    """
    for _ in range(round(limit_s / STEP_S)):
        backend.step(STEP_S)
        fault: BackendFault | None = backend.take_fault()  # type: ignore[attr-defined]
        if fault is not None:
            return fault
        if done():
            return None
    raise AssertionError(f"not done in {limit_s} simulated seconds")


class BackendNotReadyError(RuntimeError):
    """A command reached the backend while its physics view was invalid."""


class SlowSettlingBackend(KinematicBackend):
    """Kinematic backend that settles slowly and loses its physics view every N motions."""

    def __init__(
        self,
        model: RobotModel,
        *,
        home: Pose = DEFAULT_HOME,
        world: World | None = None,
        settle_time_s: float = 1.5,
        invalidate_after_motions: int | None = 1,
        motion_survives_reinit: bool = True,
    ) -> None:
        if invalidate_after_motions is not None and invalidate_after_motions < 1:
            raise ValueError("invalidate_after_motions must be >= 1 or None")
        super().__init__(model, home=home, world=world, settle_time_s=settle_time_s)
        self.invalidate_after_motions = invalidate_after_motions
        #: False: a motion running when the view is rebuilt is lost (the arm stops).
        self.motion_survives_reinit = motion_survives_reinit
        self.reinitialize_count = 0
        self.motions_completed = 0
        #: Commands refused because the view was invalid (the controller should send none).
        self.rejected_commands = 0
        self._ready = True
        self._motions_since_reinit = 0

    def invalidate(self) -> None:
        """Invalidate the physics view now, as a simulation stop/restart would."""
        self._ready = False

    def is_ready(self) -> bool:
        """False from the N-th completed motion until ``reinitialize()``."""
        return self._ready

    def reinitialize(self) -> bool:
        """Rebuild the physics view; the arm keeps its last pose. True: the motion survived."""
        self.reinitialize_count += 1
        self._ready = True
        self._motions_since_reinit = 0
        if self.motion_running and not self.motion_survives_reinit:
            self.stop_motion()
            return False
        return True

    def step(self, dt: float) -> None:
        """Advance the physics; an invalid view does not step at all."""
        if not self._ready:
            return
        was_running = self.motion_running
        super().step(dt)
        if was_running and not self.motion_running:
            self.motions_completed += 1
            self._motions_since_reinit += 1
            limit = self.invalidate_after_motions
            if limit is not None and self._motions_since_reinit >= limit:
                self._ready = False

    def start_motion(
        self, target: Pose, *, motion: MotionType, speed_percent: float, accel_time_s: float
    ) -> float:
        """Start a motion, or raise :class:`BackendNotReadyError` while the view is invalid."""
        self._check_ready("start_motion")
        return super().start_motion(
            target, motion=motion, speed_percent=speed_percent, accel_time_s=accel_time_s
        )

    def drive_gripper(self, width_mm: float, *, speed_mm_s: float, force_n: float) -> None:
        """Drive the fingers, or raise :class:`BackendNotReadyError` while the view is invalid."""
        self._check_ready("drive_gripper")
        super().drive_gripper(width_mm, speed_mm_s=speed_mm_s, force_n=force_n)

    def _check_ready(self, command: str) -> None:
        if not self._ready:
            self.rejected_commands += 1
            raise BackendNotReadyError(f"{command} while the physics view is invalid")
