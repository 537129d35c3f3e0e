"""The simulated robot controller: handshakes, error codes and device faults, tick by tick.

The controller owns no socket, no thread and no clock. The server (or a test) calls
:meth:`RobotController.tick` with the simulated time that passed; everything the
controller does happens inside a tick, never when a register is written, so a master
sees exactly the race a real robot shows: right after it writes a command, before the
next tick, nothing has been acknowledged yet.

Per tick, in this order: advance the physics backend, check that it is ready (else
rebuild it), fire timed faults, run the profile's handshake (advance the running
command, then take a pending one), publish the TCP pose. The rules, error codes and
fault effects are documented in ``docs/simulator-model.md``; keep the two in step.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import Any, Literal, Protocol

from .._codec import allowed_range, encode
from .._exceptions import UnreachablePoseError, ValueOutOfRangeError
from .._logging import get_logger
from .._pose import MotionType, Pose
from .._registers import TARGET_FIELDS, TCP_FIELDS, Handshake, RegisterField, RobotProfile
from .._robot_models import RobotModel
from ._backend import MotionRejectedError, PhysicsBackend
from ._bank import RegisterBank
from ._faults import (
    EstopFault,
    Fault,
    GraspMissFault,
    LateAckFault,
    RobotErrorFault,
    StallFault,
    is_network_fault,
)

#: Faults that fire during the N-th motion.
_MoveFault = RobotErrorFault | StallFault | EstopFault

#: While the backend stays not ready, ``reinitialize()`` is retried this often (simulated s).
REINITIALIZE_RETRY_S = 1.0


class SimErrorCode(IntEnum):
    """Error codes the simulated controller reports (article error_code, tmflow last_error_code)."""

    #: Target out of the arm's reach: no joint solution (article only; tmflow reports
    #: result_code unreachable).
    UNREACHABLE = 0x0101
    #: Unknown command value, speed outside 1..100 % or a target that is not a number.
    INVALID_COMMAND = 0x0102
    #: The arm came to rest at a TCP pose the profile's pose registers cannot encode.
    POSE_OUT_OF_RANGE = 0x0103
    #: The physics backend raised while starting a motion or driving the gripper.
    BACKEND_FAILURE = 0x0104
    #: The backend refused the target: a joint would leave its limits (article only).
    JOINT_LIMIT = 0x0105
    #: The backend refused the target: it lies on a singularity (article only).
    SINGULARITY = 0x0106
    #: The physics view was rebuilt mid-motion and the motion did not survive.
    MOTION_LOST = 0x0107
    #: Emergency stop pressed.
    EMERGENCY_STOP = 0x0200


#: Article error code of each reason a backend may give for refusing a motion.
_REJECT_CODES = {
    "reach": SimErrorCode.UNREACHABLE,
    "joint_limit": SimErrorCode.JOINT_LIMIT,
    "singularity": SimErrorCode.SINGULARITY,
}

#: tmflow result_code label of each reason (a profile without the label reports unreachable).
_REJECT_RESULTS = {
    "reach": "unreachable",
    "joint_limit": "joint_limit",
    "singularity": "singularity",
}


def _saturate(field: RegisterField, value: float) -> float:
    """``value`` clamped into what ``field`` can encode."""
    low, high = allowed_range(field)
    return min(max(value, low), high)


class Logger(Protocol):
    """The part of a structlog logger the simulator uses."""

    def info(self, event: str, **kw: Any) -> Any:
        """Log an ordinary state change."""

    def warning(self, event: str, **kw: Any) -> Any:
        """Log a fault or a refused command."""


@dataclass(frozen=True)
class MotionRecord:
    """One motion or gripper action the controller started: the ground truth of what ran."""

    #: Motion number (1 = first motion started); gripper closes count grasps instead.
    number: int
    #: "ptp", "line", "gripper_open" or "gripper_close".
    kind: str
    #: Sequence number of the command (tmflow), 0 for the article profile.
    seq: int
    target: Pose | None
    speed: float | None
    #: Simulated seconds since the controller started.
    sim_time_s: float
    #: ``time.monotonic()`` when the tick that started it ran.
    wall_time: float


@dataclass
class _Active:
    """The command the controller is executing."""

    kind: Literal["motion", "gripper"]
    #: Motion number (1 = first motion started) or grasp number for a gripper close.
    number: int
    seq: int = 0
    target: Pose | None = None
    expected_s: float = 0.0
    elapsed_s: float = 0.0
    fault: _MoveFault | None = None
    stalled: bool = False
    closing: bool = False
    miss: bool = False


class RobotController:
    """Simulated TM robot behind one robot profile: runs its handshake on every tick."""

    def __init__(
        self,
        profile: RobotProfile,
        bank: RegisterBank,
        backend: PhysicsBackend,
        model: RobotModel,
        *,
        faults: Sequence[Fault] = (),
        init_time_s: float = 0.2,
        accel_time_s: float | None = None,
        log: Logger | None = None,
        step_backend: bool = True,
        gripper_open_width_mm: float = 39.0,
        gripper_close_width_mm: float = 0.0,
        gripper_speed_mm_s: float = 100.0,
        gripper_force_n: float = 40.0,
        initial_seq: int = 0,
    ) -> None:
        if bank.register_map is not profile and bank.register_map != profile:
            raise ValueError("the register bank must serve the controller's profile")
        if init_time_s < 0 or (accel_time_s is not None and accel_time_s < 0):
            raise ValueError("init_time_s and accel_time_s must be >= 0")
        self._profile = profile
        self._bank = bank
        self._backend = backend
        self._model = model
        self._init_time_s = init_time_s
        self._accel_time_s = model.accel_time_s if accel_time_s is None else accel_time_s
        self._log: Logger = get_logger("tmmaster.sim") if log is None else log
        self._step_backend = step_backend
        self._gripper_open = gripper_open_width_mm
        self._gripper_close = gripper_close_width_mm
        self._gripper_speed = gripper_speed_mm_s
        self._gripper_force = gripper_force_n
        self._article = profile.handshake is Handshake.CLEAR_ON_ACCEPT
        if initial_seq and (self._article or not 0 <= initial_seq <= profile.seq_max):
            raise ValueError(
                f"initial_seq must be 0..{profile.seq_max} with a sequence profile,"
                f" got {initial_seq}"
            )
        self._initial_seq = initial_seq

        self._move_faults: list[_MoveFault] = []
        self._timed_estops: list[EstopFault] = []
        self._grasp_misses: set[int] = set()
        self._late_acks: list[LateAckFault] = []
        for fault in faults:
            self._add_fault(fault)

        self._time_s = 0.0
        self._initialised = False
        self._active: _Active | None = None
        self._error_code = 0
        self._estop = False
        self._moves_started = 0
        self._grasps = 0
        self._running = False  # tmflow: the TMflow project runs
        self._project_started_s = 0.0  # tmflow: when the project last started
        self._late_key: object = None
        self._late_since = 0.0
        self._reinit_at: float | None = None
        self._gripper_seen = 0  # article: last gripper_command value acted upon
        self._gripper_closing = False
        self._gripper_miss = False
        self._motion_log: list[MotionRecord] = []
        self._saturating = False  # the published pose is saturated (encodable range rule)
        self._rest_error_raised = False  # POSE_OUT_OF_RANGE raised for the current rest
        self._reset_registers()

    # -- read-only state for the server and tests --------------------------------------

    @property
    def profile(self) -> RobotProfile:
        """The robot profile whose handshake the controller runs."""
        return self._profile

    @property
    def bank(self) -> RegisterBank:
        """The register memory the controller works on."""
        return self._bank

    @property
    def time_s(self) -> float:
        """Simulated seconds since the controller started."""
        return self._time_s

    @property
    def moves_started(self) -> int:
        """Motion commands taken that started a motion (rejected ones do not count)."""
        return self._moves_started

    @property
    def motion_log(self) -> tuple[MotionRecord, ...]:
        """Every motion and gripper action started so far, in order."""
        return tuple(self._motion_log)

    @property
    def grasps(self) -> int:
        """Gripper close commands executed."""
        return self._grasps

    @property
    def error_code(self) -> int:
        """Current robot error code, 0 when there is no robot error."""
        return self._error_code

    @property
    def estop_pressed(self) -> bool:
        """True while the emergency stop is pressed (until :meth:`clear_error`)."""
        return self._estop

    @property
    def project_running(self) -> bool:
        """tmflow: the TMflow project runs; article: the robot is initialised."""
        return self._running if not self._article else self._initialised

    @property
    def active_target(self) -> Pose | None:
        """Target of the motion being executed, or None."""
        active = self._active
        return active.target if active is not None and active.kind == "motion" else None

    @property
    def state(self) -> str:
        """One word: initialising, error, stopped (tmflow project), moving, gripping or idle."""
        if self._error_code:
            return "error"
        if not self._initialised:
            return "initialising"
        if not self._article and not self._running:
            return "stopped"
        if self._active is None:
            return "idle"
        return "moving" if self._active.kind == "motion" else "gripping"

    # -- faults ------------------------------------------------------------------------

    def inject(self, fault: Fault) -> None:
        """Add a device fault at run time; its at_move / at_grasp / after_s count from now."""
        if is_network_fault(fault):
            raise ValueError(f"{fault.kind} is a network fault: the Modbus server plays it")
        at_move = getattr(fault, "at_move", None)
        if at_move is not None:
            fault = fault.model_copy(update={"at_move": at_move + self._moves_started})
        elif isinstance(fault, EstopFault) and fault.after_s is not None:
            fault = fault.model_copy(update={"after_s": fault.after_s + self._time_s})
        elif isinstance(fault, GraspMissFault):
            fault = fault.model_copy(update={"at_grasp": fault.at_grasp + self._grasps})
        self._add_fault(fault)
        self._log.info("sim.fault_injected", device=self._profile.name, fault=fault.kind)

    def clear_faults(self) -> None:
        """Forget every device fault not yet fired (an effect already under way stays)."""
        self._move_faults.clear()
        self._timed_estops.clear()
        self._grasp_misses.clear()
        self._late_acks.clear()
        self._late_key = None
        if self._active is not None:
            self._active.fault = None
        self._log.info("sim.faults_cleared", device=self._profile.name)

    def _add_fault(self, fault: Fault) -> None:
        # Only device faults concern the controller; network faults are the server's.
        if isinstance(fault, RobotErrorFault):
            # Refuse a code the error register cannot hold when it is given, not mid-run.
            encode(self._profile.field(self._error_code_field), fault.code)
        if isinstance(fault, EstopFault) and fault.after_s is not None:
            self._timed_estops.append(fault)
        elif isinstance(fault, RobotErrorFault | StallFault | EstopFault):
            self._move_faults.append(fault)
        elif isinstance(fault, GraspMissFault):
            self._grasp_misses.add(fault.at_grasp)
        elif isinstance(fault, LateAckFault):
            self._late_acks.append(fault)

    # -- operator actions --------------------------------------------------------------

    def clear_error(self) -> None:
        """Operator resets the error (and releases the e-stop) on the pendant."""
        if not self._error_code and not self._estop:
            return
        code = self._error_code
        self._error_code = 0
        self._estop = False
        if self._article:
            # A reset never arms anything: a command (or gripper command) written before or
            # during the error is discarded, not executed now that the robot can move again.
            self._discard_article_commands("reset")
            self._bank.set("error_code", 0)
            self._bank.set("robot_mode", self._mode_now())
        else:
            # last_error_code keeps the code: it is the *last* error, not the current one.
            self._bank.set("estop", False)
            self._bank.set("error", False)
            self._publish_tm_state()
        self._log.info("sim.error_cleared", device=self._profile.name, code=code)

    def press_play(self) -> None:
        """Press Play on the pendant: acted on at the next tick, like the Play/Pause coil."""
        if self._profile.has("play_pause"):
            self._bank.set("play_pause", True)

    def press_estop(self) -> None:
        """Press the emergency stop now (the estop fault does the same at its trigger)."""
        if self._estop:
            return
        self._estop = True
        self._log.warning("sim.estop", device=self._profile.name, time_s=self._time_s)
        if not self._article:
            self._bank.set("estop", True)
        self._enter_error(SimErrorCode.EMERGENCY_STOP, "emergency stop")

    # -- the tick ----------------------------------------------------------------------

    def tick(self, dt: float) -> None:
        """Advance the controller (and, unless told otherwise, the backend) by ``dt`` seconds."""
        if not math.isfinite(dt) or dt < 0:
            raise ValueError(f"dt must be a finite number >= 0, got {dt}")
        self._time_s += dt
        if self._step_backend:
            self._backend.step(dt)
        ready = self._check_ready()
        for fault in list(self._timed_estops):
            if fault.after_s is not None and self._time_s + 1e-9 >= fault.after_s:
                self._timed_estops.remove(fault)
                self._log.warning("sim.fault_fired", device=self._profile.name, fault="estop")
                self.press_estop()
        if not self._initialised and self._time_s + 1e-9 >= self._init_time_s:
            self._initialised = True
            self._log.info("sim.initialised", device=self._profile.name)
            if self._article:
                self._bank.set("robot_mode", self._mode_now())
            elif not self._error_code:
                self._start_project()
        if self._article:
            self._tick_article(dt, ready)
        else:
            self._tick_sequence(dt, ready)
        if ready:
            self._publish_pose()

    # -- clear-on-accept (article) -----------------------------------------------------

    def _tick_article(self, dt: float, ready: bool) -> None:
        if self._active is not None:
            self._advance(dt, ready)
        command_field = self._profile.field("command")
        raw = int(self._bank.get("command"))
        label = command_field.label(raw)
        if raw == 0:
            self._late_key = None
        elif label == "stop":
            # Stop is taken in any state, even while moving or in error.
            self._stop_motion()
            self._bank.set("command", 0)
            self._log.info("sim.command_accepted", device=self._profile.name, command="stop")
            self._check_done(ready)
        elif self._initialised and not self._error_code and self._active is None:
            if label in ("ptp", "line"):
                self._take_article_motion(MotionType(label), ready)
            else:
                self._log.warning("sim.command_rejected", device=self._profile.name, command=raw)
                self._enter_error(SimErrorCode.INVALID_COMMAND, f"unknown command {raw}")
                self._bank.set("command", 0)
        # Otherwise (initialising, in error, or moving) the command waits in its register.
        if self._profile.has("gripper_command"):
            self._tick_article_gripper(ready)

    def _take_article_motion(self, motion: MotionType, ready: bool) -> None:
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
                device=self._profile.name,
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
            device=self._profile.name,
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

    def _tick_article_gripper(self, ready: bool) -> None:
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

    # -- sequence (tmflow) -------------------------------------------------------------

    def _tick_sequence(self, dt: float, ready: bool) -> None:
        self._handle_buttons()
        if not self._running:
            return
        if self._profile.has("heartbeat"):
            wrap = int(allowed_range(self._profile.field("heartbeat"))[1]) + 1
            self._bank.set("heartbeat", (int(self._bank.get("heartbeat")) + 1) % wrap)
        if self._active is not None:
            self._advance(dt, ready)
        if self._active is None and self._running:
            self._take_sequence_command(ready)

    def _handle_buttons(self) -> None:
        # Coils are buttons: act on a press, then release them like a spring would.
        if self._profile.has("stop_project") and self._bank.get("stop_project"):
            self._bank.set("stop_project", False)
            if self._running:
                self._log.info("sim.button", device=self._profile.name, button="stop")
                self._stop_project("stop button")
        if self._profile.has("play_pause") and self._bank.get("play_pause"):
            self._bank.set("play_pause", False)
            if self._running:
                # Pausing a running project is not modelled; the press is ignored.
                self._log.info(
                    "sim.button_ignored",
                    device=self._profile.name,
                    button="play_pause",
                    reason="project already running",
                )
            elif not self._initialised or self._error_code or self._estop:
                self._log.warning(
                    "sim.button_ignored",
                    device=self._profile.name,
                    button="play_pause",
                    reason="robot in error" if self._initialised else "initialising",
                )
            else:
                self._log.info("sim.button", device=self._profile.name, button="play_pause")
                self._start_project()

    def _take_sequence_command(self, ready: bool) -> None:
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
        self._log.info("sim.command_accepted", device=self._profile.name, seq=seq, command=label)
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
            self._start_motion(target, MotionType(label), speed, accel, seq=seq)
        elif label in ("gripper_open", "gripper_close"):
            self._drive_gripper(close=label == "gripper_close", seq=seq)
        else:
            self._fail_sequence(seq, "invalid_command", 2)

    def _model_rejects(self, target: Pose) -> UnreachablePoseError | None:
        """Why the arm model refuses ``target``, for a backend without joints of its own.

        A backend with a joint model (``joint_positions_deg()`` not None) knows its joints
        and tool and refuses a target itself (:class:`MotionRejectedError`); checking here
        without them could disagree with it.
        """
        if self._backend.joint_positions_deg() is not None:
            return None
        try:
            self._model.inverse(target)
        except UnreachablePoseError as exc:
            return exc
        return None

    def _reject_sequence(self, seq: int, reason: str) -> None:
        """tmflow: a target the arm cannot take, with the reason's own result_code."""
        unreachable = self._code("result_code", "unreachable", 1)
        self._fail_sequence(seq, _REJECT_RESULTS.get(reason, "unreachable"), unreachable)

    def _fail_sequence(self, seq: int, result: str, default: int) -> None:
        self._log.warning("sim.command_rejected", device=self._profile.name, seq=seq, reason=result)
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
        self._log.info("sim.command_done", device=self._profile.name, seq=active.seq)

    def _cancel_sequence(self, seq: int, reason: str) -> None:
        self._log.warning(
            "sim.command_cancelled", device=self._profile.name, seq=seq, reason=reason
        )
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
        self._log.info("sim.project_started", device=self._profile.name)

    def _stop_project(self, reason: str) -> None:
        self._running = False
        self._stop_motion()
        self._active = None
        self._bank.set("project_running", False)
        self._log.warning("sim.project_stopped", device=self._profile.name, reason=reason)

    # -- shared machinery --------------------------------------------------------------

    def _start_motion(
        self, target: Pose, motion: MotionType, speed: float, accel: float, *, seq: int
    ) -> bool:
        """Start the backend motion; False (error reported, nothing started) if it failed."""
        number = self._moves_started + 1
        try:
            expected = self._backend.start_motion(
                target, motion=motion, speed_percent=speed, accel_time_s=accel
            )
        except MotionRejectedError as exc:  # the backend's own reach / limit check
            self._log.warning(
                "sim.command_rejected",
                device=self._profile.name,
                reason=exc.reason,
                target=str(target),
            )
            if self._article:
                self._enter_error(_REJECT_CODES[exc.reason], f"target rejected: {exc.reason}")
            else:
                self._reject_sequence(seq, exc.reason)
            return False
        except Exception as exc:  # a backend failure is a robot error, not a crash
            self._log.warning("sim.backend_failed", device=self._profile.name, error=repr(exc))
            if self._article:
                self._enter_error(SimErrorCode.BACKEND_FAILURE, "backend failed")
            else:
                self._fail_sequence(seq, "motion_failed", 3)
            return False
        self._moves_started = number
        self._record(number, motion.value, seq, target, speed)
        fault = next((f for f in self._move_faults if f.at_move == number), None)
        self._active = _Active(
            "motion", number, seq=seq, target=target, expected_s=expected, fault=fault
        )
        self._log.info(
            "sim.motion_started",
            device=self._profile.name,
            move=number,
            motion=motion.value,
            target=str(target),
            speed=speed,
            expected_s=round(expected, 4),
        )
        return True

    def _drive_gripper(self, *, close: bool, seq: int = 0) -> None:
        number = 0
        miss = False
        if close:
            self._grasps += 1
            number = self._grasps
            miss = number in self._grasp_misses
        try:
            self._backend.drive_gripper(
                self._gripper_close if close else self._gripper_open,
                speed_mm_s=self._gripper_speed,
                force_n=self._gripper_force,
            )
        except Exception as exc:  # a backend failure is a robot error, not a crash
            self._log.warning("sim.backend_failed", device=self._profile.name, error=repr(exc))
            if self._article:
                self._enter_error(SimErrorCode.BACKEND_FAILURE, "backend failed")
            else:
                self._fail_sequence(seq, "gripper_failed", 4)
            return
        self._gripper_closing = close
        self._gripper_miss = miss
        self._record(number, "gripper_close" if close else "gripper_open", seq, None, None)
        if miss:
            self._log.warning(
                "sim.fault_fired", device=self._profile.name, fault="grasp_miss", grasp=number
            )
        self._log.info("sim.gripper", device=self._profile.name, close=close, grasp=number)
        if not self._article:
            self._active = _Active("gripper", number, seq=seq, closing=close, miss=miss)

    def _record(
        self, number: int, kind: str, seq: int, target: Pose | None, speed: float | None
    ) -> None:
        self._motion_log.append(
            MotionRecord(number, kind, seq, target, speed, self._time_s, time.monotonic())
        )

    def _grip_detected(self) -> bool:
        return (
            self._gripper_closing
            and not self._gripper_miss
            and self._backend.gripper_state().contact
        )

    def _advance(self, dt: float, ready: bool) -> None:
        active = self._active
        assert active is not None
        active.elapsed_s += dt
        fault = active.fault
        # Move faults fire halfway through the motion, at least one tick after its start.
        if fault is not None and active.elapsed_s + 1e-9 >= active.expected_s / 2:
            active.fault = None
            self._fire(fault, active)
            if self._active is not active:
                return
        self._check_done(ready)

    def _check_done(self, ready: bool) -> None:
        active = self._active
        if active is None or active.stalled or not ready:
            return
        if active.kind == "motion":
            if not self._backend.is_settled():
                return
            self._active = None
            self._log.info("sim.motion_done", device=self._profile.name, move=active.number)
            if self._article:
                self._bank.set("motion_status", 0)
            else:
                self._finish_sequence(active)
        elif not self._backend.gripper_state().moving:
            self._active = None
            self._finish_sequence(active)

    def _fire(self, fault: _MoveFault, active: _Active) -> None:
        self._log.warning(
            "sim.fault_fired", device=self._profile.name, fault=fault.kind, move=active.number
        )
        if isinstance(fault, StallFault):
            # The arm stops where it is but the motion never reports completion.
            self._backend.stop_motion()
            active.stalled = True
        elif isinstance(fault, EstopFault):
            self.press_estop()
        else:
            self._enter_error(fault.code, "injected robot error")

    def _stop_motion(self) -> None:
        active = self._active
        if active is not None and active.kind == "motion":
            self._backend.stop_motion()
            # A stopped motion is over once the arm settles, stalled or not.
            active.stalled = False
            active.fault = None

    def _enter_error(self, code: int, reason: str) -> None:
        self._error_code = int(code)
        self._log.warning(
            "sim.robot_error", device=self._profile.name, code=int(code), reason=reason
        )
        self._stop_motion()
        self._active = None
        if self._article:
            self._bank.set("error_code", int(code))
            self._bank.set("robot_mode", self._profile.mode_error)
            self._bank.set("motion_status", 0)
            # A robot in error discards a pending command instead of keeping it for later.
            self._discard_article_commands("error")
        else:
            self._bank.set("last_error_code", int(code))
            self._bank.set("error", True)
            self._publish_tm_state()
            if self._running:
                self._stop_project(reason)

    def _check_ready(self) -> bool:
        if self._backend.is_ready():
            if self._reinit_at is not None:
                self._log.info("sim.backend_ready", device=self._profile.name)
            self._reinit_at = None
            return True
        if self._reinit_at is None or self._time_s - self._reinit_at >= REINITIALIZE_RETRY_S:
            self._log.warning("sim.backend_reinitialize", device=self._profile.name)
            self._reinit_at = self._time_s
            survived = self._backend.reinitialize()
            active = self._active
            if survived is not True and active is not None and active.kind == "motion":
                self._motion_lost(active)
        return self._backend.is_ready()

    def _motion_lost(self, active: _Active) -> None:
        """The rebuilt physics lost the running motion: it fails, it is never reported done."""
        self._log.warning("sim.motion_lost", device=self._profile.name, move=active.number)
        self._backend.stop_motion()
        if self._article:
            self._enter_error(SimErrorCode.MOTION_LOST, "motion lost when the physics was rebuilt")
        else:
            self._active = None
            self._bank.set("result_code", self._code("result_code", "motion_failed", 3))
            self._bank.set("robot_state", self._code("robot_state", "error", 2))

    def _late_ack_pending(self, key: object, *, motion_command: bool) -> bool:
        """True while a late_ack fault still holds back the command identified by ``key``."""
        number = self._moves_started + 1
        delay = max(
            (
                f.delay_s
                for f in self._late_acks
                if f.at_move is None or (motion_command and f.at_move == number)
            ),
            default=0.0,
        )
        if delay <= 0:
            return False
        if key != self._late_key:
            # A changed command restarts the delay: it is a different command.
            self._late_key = key
            self._late_since = self._time_s
            self._log.warning(
                "sim.fault_fired", device=self._profile.name, fault="late_ack", delay_s=delay
            )
        if self._time_s - self._late_since + 1e-9 >= delay:
            self._late_key = None
            return False
        return True

    def _read_target(self) -> tuple[Pose | None, float | None]:
        speed = float(self._bank.get("speed"))
        try:
            target = Pose(*(float(self._bank.get(n)) for n in TARGET_FIELDS))
        except ValueError:  # NaN or infinity in a float32 target
            return None, None
        if not 0 < speed <= 100:
            return target, None
        return target, speed

    def _targets_raw(self) -> tuple[float, ...]:
        return tuple(float(self._bank.get(n)) for n in TARGET_FIELDS)

    def _publish_pose(self) -> None:
        """Publish the TCP pose under the encodable range rule (docs/simulator-model.md).

        A coordinate the pose registers cannot hold is published saturated at the end of
        the register's range (the backend keeps the true pose). While the arm moves that
        is all (logged once per excursion); an arm that comes to rest there is a robot
        error, once per rest, since the registers cannot say where it is.
        """
        pose = self._backend.tcp_pose()
        fields = [self._profile.field(n) for n in TCP_FIELDS]
        values = pose.as_list()
        published = [_saturate(f, v) for f, v in zip(fields, values, strict=True)]
        try:
            # Encode all six before storing any: a pose is published whole or not at all.
            for field, value in zip(fields, published, strict=True):
                encode(field, value)
        except ValueOutOfRangeError as exc:  # not even the saturated value fits
            if self._error_code != SimErrorCode.POSE_OUT_OF_RANGE:
                self._log.warning(
                    "sim.pose_out_of_range",
                    device=self._profile.name,
                    pose=str(pose),
                    error=str(exc),
                )
                self._enter_error(SimErrorCode.POSE_OUT_OF_RANGE, "pose cannot be encoded")
            return
        clipped = [f.name for f, a, b in zip(fields, values, published, strict=True) if a != b]
        self._check_saturation(pose, published, clipped)
        for name, value in zip(TCP_FIELDS, published, strict=True):
            self._bank.set(name, value)
        if self._bank.has("flange_x"):
            self._publish_tm_table(pose)

    def _check_saturation(self, pose: Pose, published: list[float], clipped: list[str]) -> None:
        """Log a saturated excursion once; an arm at rest outside the range is an error."""
        at_rest = self._backend.is_settled()
        if clipped and not self._saturating:
            self._saturating = True
            self._log.warning(
                "sim.pose_saturated",
                device=self._profile.name,
                pose=str(pose),
                published=str(Pose(*published)),
                fields=clipped,
            )
        elif not clipped and self._saturating:
            self._saturating = False
            self._log.info("sim.pose_in_range", device=self._profile.name, pose=str(pose))
        if not at_rest or not clipped:
            self._rest_error_raised = False
        elif not self._rest_error_raised:
            # Once per rest: after the operator's reset the arm may be moved back. An arm
            # stopped by another error (an e-stop, a robot error) keeps that error's code.
            self._rest_error_raised = True
            if self._error_code:
                return
            self._log.warning(
                "sim.pose_out_of_range",
                device=self._profile.name,
                pose=str(pose),
                fields=clipped,
            )
            self._enter_error(
                SimErrorCode.POSE_OUT_OF_RANGE, "arm at rest at a pose the registers cannot hold"
            )

    def _publish_tm_table(self, tcp: Pose) -> None:
        """Techman's fixed table beside a tmflow profile (docs/simulator-model.md)."""
        flange = self._backend.flange_pose()
        joints = self._backend.joint_positions_deg()
        # Without a joint model the simulated tool is the identity: flange = TCP.
        flange = tcp if flange is None else flange
        # The simulated current base is the robot base (Current Base 8300-8311 reads 0).
        for prefix, p in (
            ("flange", flange),
            ("robot_base_flange", flange),
            ("robot_base_tcp", tcp),
        ):
            for axis, value in zip(("x", "y", "z", "rx", "ry", "rz"), p.as_list(), strict=True):
                self._bank.set(f"{prefix}_{axis}", value)
        for i, angle in enumerate(joints or (0.0,) * 6, start=1):
            self._bank.set(f"joint_{i}", angle)
        self._bank.set("robot_link", True)
        self._bank.set("operation_mode", 1)  # auto, as ma_mode
        self._bank.set("aut_p", True)  # AUT.P high: able to play in auto mode
        self._publish_tm_state()
        # Running Timer (0 while the project is stopped) and Up Time, in simulated time.
        running = self._time_s - self._project_started_s if self._running else 0.0
        for prefix, seconds in (("running", running), ("up", self._time_s)):
            whole = int(seconds)
            self._bank.set(f"{prefix}_days", whole // 86400)
            self._bank.set(f"{prefix}_hours", whole // 3600 % 24)
            self._bank.set(f"{prefix}_minutes", whole // 60 % 60)
            self._bank.set(f"{prefix}_seconds", whole % 60)

    def _publish_tm_state(self) -> None:
        """Robot State (7215) in the same step as the error and e-stop bits."""
        if self._bank.has("tm_robot_state"):
            state = 4 if self._estop else 2 if self._error_code else 0  # STO / error / normal
            self._bank.set("tm_robot_state", state)

    def _discard_article_commands(self, reason: str) -> None:
        pending = int(self._bank.get("command"))
        if pending and self._profile.field("command").label(pending) != "stop":
            self._log.warning(
                "sim.command_discarded", device=self._profile.name, command=pending, reason=reason
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

    def _code(self, field: str, label: str, default: int) -> int:
        try:
            return self._profile.field(field).code_of(label)
        except KeyError:
            return default

    @property
    def _error_code_field(self) -> str:
        return "error_code" if self._article else "last_error_code"

    def _reset_registers(self) -> None:
        if self._article:
            self._bank.set("robot_mode", self._mode_now())
            self._bank.set("motion_status", 0)
            self._bank.set("error_code", 0)
        else:
            for name in ("error", "estop", "project_running"):
                self._bank.set(name, False)
            if self._profile.has("ma_mode"):
                self._bank.set("ma_mode", self._code("ma_mode", "auto", 1))
            if self._profile.has("project_speed"):
                self._bank.set("project_speed", 100)
            self._bank.set("robot_state", self._code("robot_state", "idle", 0))
            # As if command number initial_seq had been the last one, taken and finished.
            for name in ("seq", "ack_seq", "done_seq"):
                self._bank.set(name, self._initial_seq)
        self._publish_pose()
