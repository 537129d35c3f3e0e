"""The article's handshake in the simulator: the controller clears the command it takes.

The simulated half of :class:`tmmaster._channels.ClearOnAcceptChannel`: a master writes
the target, the speed and then the command; on the next tick the controller starts the
motion, sets ``motion_status`` and only then writes the command back to 0 (the
acknowledgement). Errors go to ``error_code`` and ``robot_mode``; a robot in error, or
reset by the operator, discards a pending command instead of running it later. The
gripper output is level-triggered (``gripper_command``). The rules are documented in
``docs/simulator-model.md``.
"""

from __future__ import annotations

from typing import Literal

from .._pose import MotionType
from .._registers import RobotProfile
from ._controller import RobotController, SimErrorCode, _Active

#: Article error code of each reason a backend may give for refusing a motion.
_REJECT_CODES = {
    "reach": SimErrorCode.UNREACHABLE,
    "joint_limit": SimErrorCode.JOINT_LIMIT,
    "singularity": SimErrorCode.SINGULARITY,
}


class ClearOnAcceptController(RobotController):
    """The article's robot program: take a command, then clear its register."""

    _error_code_field = "error_code"
    #: The last gripper_command value acted upon.
    _gripper_seen = 0

    @property
    def project_running(self) -> bool:
        """The article robot has no project: it runs once initialised."""
        return self._initialised

    @staticmethod
    def _takes_initial_seq(profile: RobotProfile, seq: int) -> bool:
        return False

    def _reset_handshake_registers(self) -> None:
        self._bank.set("robot_mode", self._mode_now())
        self._bank.set("motion_status", 0)
        self._bank.set("error_code", 0)

    def _on_initialised(self) -> None:
        self._bank.set("robot_mode", self._mode_now())

    # -- the tick ----------------------------------------------------------------------

    def _run_handshake(self, dt: float, ready: bool) -> None:
        if self._active is not None:
            self._advance(dt, ready)
        elif self._error_code or self._bank.get("motion_status"):
            # In error, and after a reset that came while the arm still braked: moving
            # until it is at rest, then 0 (never "moving" for good with nothing to move).
            self._publish_braking()
        command_field = self._profile.field("command")
        raw = int(self._bank.get("command"))
        label = command_field.label(raw)
        if raw == 0:
            self._late_key = None
        elif label == "stop":
            # Stop is taken in any state, even while moving or in error.
            self._stop_motion()
            self._bank.set("command", 0)
            self._log.info("sim.command_accepted", device=self._name, command="stop")
            self._check_done(ready)
        elif self._initialised and not self._error_code and self._active is None:
            if label in ("ptp", "line"):
                self._take_motion(MotionType(label), ready)
            else:
                self._log.warning("sim.command_rejected", device=self._name, command=raw)
                self._enter_error(SimErrorCode.INVALID_COMMAND, f"unknown command {raw}")
                self._bank.set("command", 0)
        # Otherwise (initialising, in error, or moving) the command waits in its register.
        if self._profile.has("gripper_command"):
            self._run_gripper(ready)

    def _take_motion(self, motion: MotionType, ready: bool) -> None:
        block = (int(self._bank.get("command")), *self._targets_raw(), self._bank.get("speed"))
        if self._late_ack_pending(block, motion_command=True) or not ready:
            return
        target, speed = self._read_target()
        if target is None or speed is None:
            self._enter_error(SimErrorCode.INVALID_COMMAND, "invalid speed or target")
            self._bank.set("command", 0)
            return
        rejected = self._model_rejects(target)
        if rejected is not None:
            self._log.warning(
                "sim.command_rejected",
                device=self._name,
                reason=rejected.reason,
                target=str(target),
            )
            # Error first, then the acknowledgement: a master that sees command == 0
            # already sees the error.
            self._enter_error(
                _REJECT_CODES.get(rejected.reason, SimErrorCode.UNREACHABLE),
                f"target rejected: {rejected.reason}",
            )
            self._bank.set("command", 0)
            return
        self._log.info(
            "sim.command_accepted",
            device=self._name,
            command=motion.value,
            target=str(target),
            speed=speed,
        )
        if not self._start_motion(target, motion, speed, self._accel_time_s, seq=0):
            # Refused by the backend: the error is already set; acknowledge after it.
            self._bank.set("command", 0)
            return
        # The contract: moving first, then clear the command, in the same tick.
        self._bank.set("motion_status", 1)
        self._bank.set("command", 0)

    def _run_gripper(self, ready: bool) -> None:
        value = int(self._bank.get("gripper_command"))
        if (
            value != self._gripper_seen
            and ready
            and self._initialised
            and not self._error_code
            and self._profile.field("gripper_command").label(value) in ("open", "close")
        ):
            self._gripper_seen = value
            self._drive_gripper(
                close=self._profile.field("gripper_command").label(value) == "close"
            )
        if self._profile.has("grasp_status"):
            self._bank.set("grasp_status", int(self._grip_detected()))

    # -- outcomes ----------------------------------------------------------------------

    def _target_rejected(self, seq: int, reason: str) -> None:
        self._enter_error(_REJECT_CODES[reason], f"target rejected: {reason}")

    def _backend_failed(self, seq: int, kind: Literal["motion", "gripper"]) -> None:
        self._enter_error(SimErrorCode.BACKEND_FAILURE, "backend failed")

    def _gripper_started(self, number: int, seq: int, *, close: bool, miss: bool) -> None:
        # The gripper output is level-triggered: no command stays active while it moves.
        return

    def _command_done(self, active: _Active) -> None:
        self._bank.set("motion_status", 0)

    def _motion_failed(self, active: _Active) -> None:
        self._enter_error(SimErrorCode.MOTION_LOST, "motion lost when the physics was rebuilt")

    def _publish_braking(self) -> None:
        """In error: moving until the arm, stopped by the error, is at rest (a stop takes
        time, and a master must never read "not moving" while the arm still moves)."""
        self._bank.set("motion_status", 0 if self._backend.is_settled() else 1)

    def _publish_error(self, code: int, reason: str) -> None:
        self._bank.set("error_code", code)
        self._bank.set("robot_mode", self._profile.mode_error)
        self._publish_braking()
        # A robot in error discards a pending command instead of keeping it for later.
        self._discard_commands("error")

    def _publish_error_cleared(self) -> None:
        # A reset never arms anything: a command (or gripper command) written before or
        # during the error is discarded, not executed now that the robot can move again.
        self._discard_commands("reset")
        self._bank.set("error_code", 0)
        self._bank.set("robot_mode", self._mode_now())

    def _discard_commands(self, reason: str) -> None:
        pending = int(self._bank.get("command"))
        if pending and self._profile.field("command").label(pending) != "stop":
            self._log.warning(
                "sim.command_discarded", device=self._name, command=pending, reason=reason
            )
        self._bank.set("command", 0)
        if self._profile.has("gripper_command"):
            # The gripper register is level-triggered: adopt its value without acting on it.
            self._gripper_seen = int(self._bank.get("gripper_command"))

    def _mode_now(self) -> int:
        if self._error_code:
            return self._profile.mode_error
        if not self._initialised:
            return self._code("robot_mode", "initialising", 0)
        return self._profile.mode_auto
