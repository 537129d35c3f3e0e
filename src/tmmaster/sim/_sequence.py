"""TMflow's handshake in the simulator: sequence-numbered commands to a running project.

The simulated half of :class:`tmmaster._channels.SequenceChannel`, as the TMflow program
of ``docs/tmflow-program.md`` runs it: a command is taken only when ``seq`` is the
number after ``ack_seq``; the controller acknowledges it (``ack_seq``), reports
``result_code`` and ``robot_state`` and, when it finished, ``done_seq``. Commands run only
while the project runs (Play / Stop coils, started once initialised); an error stops the
project and keeps its code in ``last_error_code``. The rules are documented in
``docs/simulator-model.md``.
"""

from __future__ import annotations

from typing import Any, Literal

from .._codec import allowed_range
from .._pose import MotionType, Pose
from .._registers import RobotProfile
from ._bank import RegisterBank
from ._controller import RobotController, SimErrorCode, _Active
from ._tm_table import tm_table_areas, tm_table_fields

#: tmflow result_code label of each reason (a profile without the label reports unreachable).
_REJECT_RESULTS = {
    "reach": "unreachable",
    "joint_limit": "joint_limit",
    "singularity": "singularity",
}


class SequenceController(RobotController):
    """The TMflow project: take the command whose seq follows ack_seq, report done_seq."""

    _error_code_field = "last_error_code"
    #: The TMflow project runs (started once initialised, by Play, stopped by an error).
    _running = False
    #: Paused (Pause button, or an e-stop with resumption on): Play resumes the move.
    _paused = False
    #: Simulated time when the project last started.
    _project_started_s = 0.0

    def __init__(self, *args: Any, resume_after_error: bool = False, **options: Any) -> None:
        #: TMflow's Motion Settings > Resumption Behavior, "continue project execution from
        #: the error position" (TMflow 2.24 manual, Table 5, pp. 53-54; p. 112): an e-stop
        #: pauses the project instead of stopping it, and Play resumes the interrupted move.
        self._resume_after_error = resume_after_error
        #: The move a pause or a resumable stop interrupted: (target, motion, speed,
        #: accel, seq), restarted by Play.
        self._interrupted: tuple[Pose, MotionType, float, float, int] | None = None
        self._motion_args: tuple[Pose, MotionType, float, float, int] | None = None
        self._pausing_on_error = False
        super().__init__(*args, **options)

    @property
    def project_paused(self) -> bool:
        """The project is paused: Play resumes it (and the move it interrupted)."""
        return self._paused

    @classmethod
    def bank_for(cls, profile: RobotProfile) -> RegisterBank:
        """A TM controller's memory: the profile, Techman's fixed table and its raw areas."""
        return RegisterBank(
            profile, extra_fields=tm_table_fields(profile), raw_areas=tm_table_areas()
        )

    @property
    def project_running(self) -> bool:
        """The TMflow project runs."""
        return self._running

    @staticmethod
    def _takes_initial_seq(profile: RobotProfile, seq: int) -> bool:
        return 0 <= seq <= profile.seq_max

    def _reset_handshake_registers(self) -> None:
        for name in ("error", "estop", "project_running", "paused"):
            if self._bank.has(name):
                self._bank.set(name, False)
        if self._profile.has("ma_mode"):
            self._bank.set("ma_mode", self._code("ma_mode", "auto", 1))
        if self._profile.has("project_speed"):
            self._bank.set("project_speed", 100)
        self._bank.set("robot_state", self._code("robot_state", "idle", 0))
        # As if command number initial_seq had been the last one, taken and finished.
        for name in ("seq", "ack_seq", "done_seq"):
            self._bank.set(name, self._initial_seq)

    def _on_initialised(self) -> None:
        if not self._error_code:
            self._start_project()

    def _running_timer_s(self) -> float:
        return self._time_s - self._project_started_s if self._running else 0.0

    # -- the tick ----------------------------------------------------------------------

    def _run_handshake(self, dt: float, ready: bool) -> None:
        self._handle_buttons()
        if not self._running or self._paused:
            return
        if self._profile.has("heartbeat"):
            wrap = int(allowed_range(self._profile.field("heartbeat"))[1]) + 1
            self._bank.set("heartbeat", (int(self._bank.get("heartbeat")) + 1) % wrap)
        if self._active is not None:
            self._advance(dt, ready)
        if self._active is None and self._running:
            self._take_command(ready)

    def _handle_buttons(self) -> None:
        # Coils are buttons: act on a press, then release them like a spring would.
        if self._profile.has("stop_project") and self._bank.get("stop_project"):
            self._bank.set("stop_project", False)
            if self._running:
                self._log.info("sim.button", device=self._name, button="stop")
                self._stop_project("stop button")
        if self._profile.has("play_pause") and self._bank.get("play_pause"):
            self._bank.set("play_pause", False)
            if self._running and not self._paused:
                self._log.info("sim.button", device=self._name, button="pause")
                self._pause("pause button")
            elif not self._initialised or self._error_code or self._estop:
                self._log.warning(
                    "sim.button_ignored",
                    device=self._name,
                    button="play_pause",
                    reason="robot in error" if self._initialised else "initialising",
                )
            elif self._paused:
                self._log.info("sim.button", device=self._name, button="play")
                self._resume()
            else:
                self._log.info("sim.button", device=self._name, button="play_pause")
                self._start_project()

    def _take_command(self, ready: bool) -> None:
        # As the TMflow program reads them: int16, signed (a uint16-style 32768 reads as
        # -32768), and taken only when seq is the number after ack_seq.
        seq = int(self._bank.get("seq"))
        if seq != self._profile.next_seq(int(self._bank.get("ack_seq"))):
            # Only the next number is a new command: a duplicate of the acknowledged seq,
            # or a seq a master put back to withdraw a command, is never executed.
            self._late_key = None
            return
        command_field = self._profile.field("command")
        raw = int(self._bank.get("command"))
        label = command_field.label(raw)
        if self._late_ack_pending(seq, motion_command=label in ("ptp", "line")) or not ready:
            return
        if label == "none":
            # A master's cancel: the number is used up, nothing runs.
            self._bank.set("ack_seq", seq)
            self._cancel_sequence(seq, "withdrawn by the master")
            return
        self._bank.set("ack_seq", seq)
        self._bank.set("result_code", self._code("result_code", "ok", 0))
        self._bank.set("robot_state", self._code("robot_state", "busy", 1))
        self._log.info("sim.command_accepted", device=self._name, seq=seq, command=label)
        if label in ("ptp", "line"):
            target, speed = self._read_target()
            # The guide's check M2: accel_time beyond its declared maximum is invalid too.
            accel_ok = (
                not self._profile.has("accel_time")
                or int(self._bank.get("accel_time"))
                <= allowed_range(self._profile.field("accel_time"))[1]
            )
            if target is None or speed is None or not accel_ok:
                self._fail_sequence(seq, "invalid_command", 2)
                return
            rejected = self._model_rejects(target)
            if rejected is not None:
                self._reject_sequence(seq, rejected.reason)
                return
            accel = self._accel_time_s
            if self._profile.has("accel_time"):
                ms = int(self._bank.get("accel_time"))
                # 0 means "the program's default", i.e. the controller's accel time.
                accel = ms / 1000.0 if ms > 0 else self._accel_time_s
            self._motion_args = (target, MotionType(label), speed, accel, seq)
            self._start_motion(target, MotionType(label), speed, accel, seq=seq)
        elif label in ("gripper_open", "gripper_close"):
            self._drive_gripper(close=label == "gripper_close", seq=seq)
        else:
            self._fail_sequence(seq, "invalid_command", 2)

    # -- outcomes ----------------------------------------------------------------------

    def _target_rejected(self, seq: int, reason: str) -> None:
        self._reject_sequence(seq, reason)

    def _backend_failed(self, seq: int, kind: Literal["motion", "gripper"]) -> None:
        if kind == "motion":
            self._fail_sequence(seq, "motion_failed", 3)
        else:
            self._fail_sequence(seq, "gripper_failed", 4)

    def _gripper_started(self, number: int, seq: int, *, close: bool, miss: bool) -> None:
        self._active = _Active(
            "gripper",
            number,
            seq=seq,
            closing=close,
            miss=miss,
            record=len(self._motion_log) - 1,
        )

    def _command_done(self, active: _Active) -> None:
        self._finish_sequence(active)

    def _motion_failed(self, active: _Active) -> None:
        self._active = None
        self._bank.set("result_code", self._code("result_code", "motion_failed", 3))
        self._bank.set("robot_state", self._code("robot_state", "error", 2))

    def _publish_estop(self) -> None:
        self._bank.set("estop", True)

    def _enter_error(self, code: int, reason: str) -> None:
        # Table 5 (TMflow 2.24, p. 53): with resumption on, a stop from a safety function
        # (the e-stop) pauses the project, other errors stop it.
        self._pausing_on_error = (
            self._resume_after_error and self._running and code == SimErrorCode.EMERGENCY_STOP
        )
        if self._pausing_on_error and not self._paused:
            self._interrupted = self._running_move()
        super()._enter_error(code, reason)

    def _publish_error(self, code: int, reason: str) -> None:
        self._bank.set("last_error_code", code)
        self._bank.set("error", True)
        self._publish_tm_state()
        if self._pausing_on_error:
            self._pausing_on_error = False
            self._set_paused(True, reason)
        elif self._running:
            self._stop_project(reason)

    def _publish_error_cleared(self) -> None:
        # last_error_code keeps the code: it is the *last* error, not the current one.
        self._bank.set("estop", False)
        self._bank.set("error", False)
        self._publish_tm_state()

    def _reject_sequence(self, seq: int, reason: str) -> None:
        """tmflow: a target the arm cannot take, with the reason's own result_code."""
        unreachable = self._code("result_code", "unreachable", 1)
        self._fail_sequence(seq, _REJECT_RESULTS.get(reason, "unreachable"), unreachable)

    def _fail_sequence(self, seq: int, result: str, default: int) -> None:
        self._log.warning("sim.command_rejected", device=self._name, seq=seq, reason=result)
        # result_code before robot_state: whoever sees "error" sees why.
        self._bank.set("result_code", self._code("result_code", result, default))
        self._bank.set("robot_state", self._code("robot_state", "error", 2))

    def _finish_sequence(self, active: _Active) -> None:
        if active.kind == "gripper" and active.closing and self._profile.has("grasp_status"):
            self._bank.set("grasp_status", int(self._grip_detected()))
        elif active.kind == "gripper" and self._profile.has("grasp_status"):
            self._bank.set("grasp_status", 0)
        self._bank.set("result_code", self._code("result_code", "ok", 0))
        self._bank.set("done_seq", active.seq)
        self._bank.set("robot_state", self._code("robot_state", "idle", 0))
        self._log.info("sim.command_done", device=self._name, seq=active.seq)

    def _cancel_sequence(self, seq: int, reason: str) -> None:
        self._log.warning("sim.command_cancelled", device=self._name, seq=seq, reason=reason)
        self._bank.set("result_code", self._code("result_code", "cancelled", 5))
        self._bank.set("robot_state", self._code("robot_state", "error", 2))

    def _start_project(self) -> None:
        self._running = True
        self._project_started_s = self._time_s
        # The start-up rule (docs/tmflow-program.md): a freshly started project never takes
        # a command written before it started. A pending sequence number is consumed as
        # cancelled (ack_seq := seq), so neither it nor a late copy of it can run. Any
        # other value in seq is not a command (the loop would never take it either).
        seq, ack = int(self._bank.get("seq")), int(self._bank.get("ack_seq"))
        if seq == self._profile.next_seq(ack):  # the same "next number" rule the loop applies
            self._bank.set("ack_seq", seq)
            self._cancel_sequence(seq, "written before the project started")
        else:
            self._bank.set("robot_state", self._code("robot_state", "idle", 0))
        self._bank.set("project_running", True)
        self._log.info("sim.project_started", device=self._name)

    def _stop_project(self, reason: str) -> None:
        self._running = False
        self._stop_motion()
        self._active = None
        self._interrupted = None
        self._set_paused(False, reason)
        self._bank.set("project_running", False)
        self._log.warning("sim.project_stopped", device=self._name, reason=reason)

    def _running_move(self) -> tuple[Pose, MotionType, float, float, int] | None:
        """The move being executed now (what a pause interrupts), if any."""
        active = self._active
        args = self._motion_args
        if active is None or active.kind != "motion" or args is None or args[4] != active.seq:
            return None
        return args

    def _set_paused(self, paused: bool, reason: str) -> None:
        self._paused = paused
        if self._profile.has("paused"):
            self._bank.set("paused", paused)
        if paused:
            self._log.warning("sim.project_paused", device=self._name, reason=reason)

    def _pause(self, reason: str) -> None:
        """Pause the project: the arm stops, and Play resumes the move it was making."""
        self._interrupted = self._running_move()
        self._stop_motion()
        self._active = None
        self._set_paused(True, reason)

    def _resume(self) -> None:
        """Play on a paused project: it goes on, and the interrupted move runs to its end."""
        self._set_paused(False, "play")
        interrupted, self._interrupted = self._interrupted, None
        self._log.info("sim.project_resumed", device=self._name)
        if interrupted is not None:
            target, motion, speed, accel, seq = interrupted
            self._start_motion(target, motion, speed, accel, seq=seq)
