"""The simulated robot controller: what both handshakes share, tick by tick.

The controller owns no socket, no thread and no clock (a :class:`~._device.SimDevice`).
The server (or a test) calls :meth:`RobotController.tick` with the simulated time that
passed; everything the controller does happens inside a tick, never when a register is
written, so a master sees exactly the race a real robot shows: right after it writes a
command, before the next tick, nothing has been acknowledged yet.

Per tick, in this order: advance the physics backend, check that it is ready (else
rebuild it), fire timed faults (the device prologue), run the profile's handshake
(advance the running command, then take a pending one), publish the TCP pose.

As the client has one channel per handshake (``_channels.py``), the simulator has one
controller per handshake, chosen by the :class:`~._simulator.Simulator` that builds it:
:class:`~._clear_on_accept.ClearOnAcceptController` (the article) and
:class:`~._sequence.SequenceController` (tmflow, run as the robot program interpreted by
:class:`~._script_project.ScriptProjectController`). This base holds what they share:
backend driving, device faults, the error and e-stop state, motion records, pose
publication under the encodable range rule and Techman's fixed table. The rules, error
codes and fault effects are documented in ``docs/simulator-model.md``; keep the two in
step.
"""

from __future__ import annotations

import math
import traceback
from abc import abstractmethod
from array import array
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace
from enum import IntEnum
from typing import ClassVar, Literal

from .. import _kinematics as kin
from .._codec import allowed_range, encode
from .._exceptions import ConfigError, UnreachablePoseError, ValueOutOfRangeError
from .._pose import MotionType, Pose
from .._registers import (
    FLANGE_FIELDS,
    JOINT_FIELDS,
    ROBOT_BASE_FLANGE_FIELDS,
    ROBOT_BASE_TCP_FIELDS,
    TARGET_FIELDS,
    TCP_FIELDS,
    RobotProfile,
)
from .._robot_models import RobotModel
from .._tm_errors import describe
from ._backend import MotionRejectedError, PathBackend, PhysicsBackend
from ._bank import RegisterBank, digital_io_areas
from ._device import Logger, SimDevice
from ._faults import (
    EstopFault,
    Fault,
    LateAckFault,
    RobotErrorFault,
    StallFault,
    is_network_fault,
)

#: Oldest motion records are dropped beyond this, as the request log's are beyond its
#: limit: a simulator serving a cell for days does not grow with every move.
MOTION_LOG_LIMIT = 100_000

#: Faults that fire during the N-th motion.
_MoveFault = RobotErrorFault | StallFault | EstopFault


class SimErrorCode(IntEnum):
    """Error codes the simulated controller reports (article error_code, tmflow last_error_code)."""

    #: Target out of the arm's reach: no joint solution (article; on tmflow a motion the
    #: physics refuses although the program's checks passed: an error stop).
    UNREACHABLE = 0x0101
    #: Unknown command value, speed outside 1..100 % or a target that is not a number.
    INVALID_COMMAND = 0x0102
    #: The arm came to rest at a TCP pose the profile's pose registers cannot encode.
    POSE_OUT_OF_RANGE = 0x0103
    #: The physics backend raised while starting a motion or driving the gripper.
    BACKEND_FAILURE = 0x0104
    #: The backend refused the target: a joint would leave its limits (article).
    JOINT_LIMIT = 0x0105
    #: The backend refused the target: it lies on a singularity (article).
    SINGULARITY = 0x0106
    #: The physics view was rebuilt mid-motion and the motion did not survive.
    MOTION_LOST = 0x0107
    #: The control tick raised (a fault of the simulator, of a backend of one's own, or
    #: memory exhausted): the robot stops in error instead of freezing its registers.
    TICK_FAILED = 0x0108
    #: Emergency stop pressed.
    EMERGENCY_STOP = 0x0200
    #: Techman's "Over Payload Limit" (0x0000000F, TMflow SW 2.24 Software Manual,
    #: Appendix J, pp. 349 and 407): the arm carries a part over its rated payload.
    OVER_PAYLOAD = 0x000F
    #: Techman's "Velocity or Angular Velocity Over Range" (0x00000021, Appendix J, pp.
    #: 349 and 409: "an exceeding TCP speed or Joint speed which is over the limit of the
    #: Safety Settings"; "check if the issued point is PTP"): a PTP's TCP ran faster than
    #: the robot's TCP speed limit.
    OVER_SPEED = 0x0021
    #: Techman's "Force or Torque Over Range" (0x00000022, Appendix J, pp. 349 and 409,
    #: whose first check is "if the robot collides with anything"): the arm, tool or
    #: fingers hit the table, a fixture or a part.
    COLLISION = 0x0022


#: The robot error of each kind of fault a physics backend stopped the arm for.
_FAULT_CODES = {
    "collision": SimErrorCode.COLLISION,
    "payload": SimErrorCode.OVER_PAYLOAD,
    "speed": SimErrorCode.OVER_SPEED,
}

#: Techman's table: the Running Timer and Up Time (days, hours, minutes, seconds).
_RUNNING_TIMER_FIELDS = ("running_days", "running_hours", "running_minutes", "running_seconds")
_UP_TIME_FIELDS = ("up_days", "up_hours", "up_minutes", "up_seconds")
#: Techman's Joint Speed J1..J6 (7949-7960) and TCP Speed (7859-7872), in that order.
_SPEED_FIELDS = (
    *(f"joint_speed_{j}" for j in range(1, 7)),
    *(f"tcp_speed_{a}" for a in ("x", "y", "z", "rx", "ry", "rz", "s3d")),
)
#: The speeds of an arm that did not move.
_NO_SPEEDS = (0.0,) * len(_SPEED_FIELDS)
_TM_TABLE_FIELDS = (
    *FLANGE_FIELDS,
    *ROBOT_BASE_FLANGE_FIELDS,
    *ROBOT_BASE_TCP_FIELDS,
    *JOINT_FIELDS,
    "robot_link",
    "operation_mode",
    "aut_p",
    "tm_robot_state",
    *_RUNNING_TIMER_FIELDS,
    *_UP_TIME_FIELDS,
    *_SPEED_FIELDS,
)


@dataclass(frozen=True)
class MotionRecord:
    """One motion or gripper action the controller started: the ground truth of what ran."""

    #: Motion number (1 = first motion started); gripper closes count grasps instead.
    number: int
    #: "ptp", "line", "ptp_joints", "circle", "gripper_open" or "gripper_close".
    kind: str
    #: Sequence number of the command (tmflow), 0 for the article profile.
    seq: int
    #: The motion's target (None for a gripper action).
    target: Pose | None
    #: The motion's speed, % (None for a gripper action).
    speed: float | None
    #: Simulated seconds since the controller started.
    sim_time_s: float
    #: ``time.monotonic()`` when the tick that started it was due (a Simulator runs a
    #: due tick before it serves a request or a call, see :class:`Timing`).
    wall_time: float
    #: ``time.monotonic()`` when the tick that reported it finished was due (the registers
    #: showing the end were set in that tick); None while it runs, and for one that
    #: failed, was stopped by an error or never reports its end.
    done_wall_time: float | None = None


@dataclass(frozen=True)
class MoveArgs:
    """A move as the controller starts it, and as Play resumes it after a pause."""

    #: The TCP target.
    target: Pose
    #: PTP or LINE (a circle runs as a path, like a Line).
    motion: MotionType
    #: Speed, % of the arm's top speed.
    speed: float
    #: Time to reach full speed, s.
    accel_s: float
    #: The command's sequence number (tmflow), 0 otherwise.
    seq: int = 0
    #: A joint target: the joints to reach exactly (the program's ``PTP("JPP", ...)``).
    joints: tuple[float, ...] | None = None
    #: A circle: a point on the arc, and where the arc started.
    via: Pose | None = None
    start: Pose | None = None
    #: The joints are a Cartesian PTP's, chosen by its reference joints (Syntax 3).
    cartesian: bool = False

    @property
    def kind(self) -> str:
        """The motion log's word for it: ptp, line, ptp_joints or circle."""
        if self.joints is not None and not self.cartesian:
            return "ptp_joints"
        return "circle" if self.via is not None else self.motion.value

    def resumed(self, here: Pose) -> MoveArgs:
        """The rest of this move from ``here``: an arc goes on along its own circle."""
        if self.via is None or self.start is None:
            return self
        arc = kin.Arc.through(self.start, self.via, self.target)
        n = 100
        points = [kin.transform_to_pose(arc.at(k / n)) for k in range(n + 1)]
        reached = min(range(n + 1), key=lambda k: points[k].distance_to(here))
        if reached >= n - 2 or here.distance_to(self.target) < 2 * kin.ARC_MIN_SPACING_MM:
            return replace(self, motion=MotionType.LINE, via=None, start=None)
        return replace(self, via=points[(reached + n) // 2], start=here)


@dataclass(frozen=True)
class GripperMoves:
    """The widths, speed and force of the robot's own gripper open and close commands."""

    #: The width an open command drives the fingers to, mm.
    open_width_mm: float = 39.0
    #: The width a close command drives the fingers to (a part stops them), mm.
    close_width_mm: float = 0.0
    #: The fingers' speed, mm/s.
    speed_mm_s: float = 100.0
    #: The grip force, N.
    force_n: float = 40.0


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
    #: Its record's index in the motion log (-1: none).
    record: int = -1


class RobotController(SimDevice[RobotProfile]):
    """Simulated TM robot behind one robot profile; a subclass per handshake runs it."""

    #: The register holding the robot error code (the article's current error,
    #: tmflow's last one).
    _error_code_field: ClassVar[str]

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
        gripper_moves: GripperMoves = GripperMoves(),
        initial_seq: int = 0,
        speed_factor: float = 1.0,
    ) -> None:
        if accel_time_s is not None and accel_time_s < 0:
            raise ConfigError(f"accel_time_s must be >= 0, got {accel_time_s}")
        self._check_initial_seq(profile, initial_seq)
        # Ready before the base adds the given faults (through _add_fault).
        self._move_faults: list[_MoveFault] = []
        self._timed_estops: list[EstopFault] = []
        self._late_acks: list[LateAckFault] = []
        super().__init__(
            profile,
            bank,
            backend,
            faults=faults,
            init_time_s=init_time_s,
            step_backend=step_backend,
            log=log,
        )
        self._model = model
        self._accel_time_s = model.accel_time_s if accel_time_s is None else accel_time_s
        self._gripper_moves = gripper_moves
        self._initial_seq = initial_seq
        #: The arm is this many times faster than the model (its backend moves by a
        #: model with the speeds scaled): acceleration times shrink by as much.
        self._speed_factor = speed_factor

        self._active: _Active | None = None
        self._error_code = 0
        self._estop = False
        self._moves_started = 0
        self._late_key: object = None
        self._late_since = 0.0
        self._gripper_closing = False
        self._gripper_miss = False
        self._motion_log: deque[MotionRecord] = deque(maxlen=MOTION_LOG_LIMIT)
        self._records_made = 0  # every record appended: an _Active's record counts them
        self._saturating = False  # the published pose is saturated (encodable range rule)
        self._rest_error_raised = False  # POSE_OUT_OF_RANGE raised for the current rest
        self._tick_failed = False  # TICK_FAILED reported, not yet reset by the operator
        self._init_publication(profile, bank)
        self._reset_handshake_registers()
        self._publish_pose()

    @classmethod
    def _check_initial_seq(cls, profile: RobotProfile, initial_seq: int) -> None:
        """Refuse a first sequence number the profile's handshake cannot count from."""
        if initial_seq and not cls._takes_initial_seq(profile, initial_seq):
            if not cls._takes_initial_seq(profile, 1):  # no sequence numbers at all
                raise ConfigError(
                    f"initial_seq must be 0: profile {profile.name} has no sequence numbers,"
                    f" got {initial_seq}"
                )
            raise ConfigError(
                f"initial_seq must be 0..{profile.seq_max} with profile {profile.name},"
                f" got {initial_seq}"
            )

    def _init_publication(self, profile: RobotProfile, bank: RegisterBank) -> None:
        """What publishing the pose at every tick keeps between ticks."""
        # The pose fields and their ranges are looked up once, and a pose equal to the
        # last one that encoded is not encoded again to check it.
        self._tcp_fields = tuple(profile.field(n) for n in TCP_FIELDS)
        self._tcp_ranges = tuple(allowed_range(f) for f in self._tcp_fields)
        self._encodable_pose: list[float] | None = None
        # What the pose and Techman's table stored last, and the change counts of their
        # Modbus tables then (see _publish_pose).
        self._published_tables = tuple(
            {bank.field(n).table for n in (*TCP_FIELDS, *_TM_TABLE_FIELDS) if bank.has(n)}
        )
        self._published_mark: int | None = None
        self._published_tcp: bytes | None = None
        # The pose (as bytes) published last when it was encodable and inside every
        # register's range: the same pose again is published as it is, unchecked.
        self._in_range_pose: bytes | None = None
        self._published_values: list[float] = []
        self._tm_table_pose: tuple[bytes, int | None, tuple[float, ...]] | None = None
        # The bytes of the last pose objects seen (a Pose is immutable, a tuple too): an
        # idle arm's backend hands the same objects out at every tick.
        self._pose_seen: tuple[Pose | None, bytes] = (None, b"")
        self._tm_seen: tuple[Pose | None, Pose | None, tuple[float, ...] | None, bytes] = (
            None,
            None,
            None,
            b"",
        )
        # The bank's fields never change: whether it has Techman's table, looked up once.
        self._has_tm_table = bank.has("flange_x")
        self._has_tm_state = bank.has("tm_robot_state")
        self._tm_table_clock: tuple[int, int] | None = None
        # The joints and TCP published last, when, and the speeds published then.
        self._tm_motion: tuple[bytes, Pose | None, Sequence[float], float] = (b"", None, (), 0.0)
        self._tm_speeds: tuple[float, ...] = _NO_SPEEDS

    @classmethod
    def bank_for(cls, profile: RobotProfile) -> RegisterBank:
        """The register memory such a controller serves: ``profile``'s fields and its
        digital I/O (plain memory where no field is)."""
        return RegisterBank(profile, raw_areas=digital_io_areas(profile))

    # -- read-only state for the server and tests --------------------------------------

    @property
    def profile(self) -> RobotProfile:
        """The robot profile whose handshake the controller runs."""
        return self._profile

    @property
    def moves_started(self) -> int:
        """Motion commands taken that started a motion (rejected ones do not count)."""
        return self._moves_started

    @property
    def motion_log(self) -> tuple[MotionRecord, ...]:
        """Every motion and gripper action started so far, in order (the latest
        ``MOTION_LOG_LIMIT``)."""
        return tuple(self._motion_log)

    @property
    def error_code(self) -> int:
        """Current robot error code, 0 when there is no robot error."""
        return self._error_code

    @property
    def estop_pressed(self) -> bool:
        """True while the emergency stop is pressed (until :meth:`clear_error`)."""
        return self._estop

    @property
    @abstractmethod
    def project_running(self) -> bool:
        """tmflow: the TMflow project runs; article: the robot is initialised."""

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
        if not self.project_running:
            return "stopped"
        if self._active is None:
            return "idle"
        return "moving" if self._active.kind == "motion" else "gripping"

    # -- faults ------------------------------------------------------------------------

    def inject(self, fault: Fault) -> None:
        """Add a device fault at run time; its at_move / at_grasp / after_s count from now."""
        if is_network_fault(fault):
            raise ValueError(f"{fault.kind} is a network fault: the Modbus server plays it")
        super().inject(fault)

    def clear_faults(self) -> None:
        """Forget every device fault not yet fired (an effect already under way stays)."""
        super().clear_faults()
        self._move_faults.clear()
        self._timed_estops.clear()
        self._late_acks.clear()
        self._late_key = None
        if self._active is not None:
            self._active.fault = None
        self._log.info("sim.faults_cleared", device=self._name)

    def _from_now(self, fault: Fault) -> Fault | None:
        at_move = getattr(fault, "at_move", None)
        if at_move is not None:
            return fault.model_copy(update={"at_move": at_move + self._moves_started})
        if isinstance(fault, EstopFault) and fault.after_s is not None:
            return fault.model_copy(update={"after_s": fault.after_s + self._time_s})
        return super()._from_now(fault) or fault

    def _add_fault(self, fault: Fault) -> None:
        # Only device faults concern the controller; network faults are the server's.
        super()._add_fault(fault)
        if isinstance(fault, RobotErrorFault):
            # Refuse a code the error register cannot hold when it is given, not mid-run.
            encode(self._profile.field(self._error_code_field), fault.code)
        if isinstance(fault, EstopFault) and fault.after_s is not None:
            self._timed_estops.append(fault)
        elif isinstance(fault, RobotErrorFault | StallFault | EstopFault):
            self._move_faults.append(fault)
        elif isinstance(fault, LateAckFault):
            self._late_acks.append(fault)

    def _fire_timed_faults(self) -> None:
        for fault in list(self._timed_estops):
            if fault.after_s is not None and self._time_s + 1e-9 >= fault.after_s:
                self._timed_estops.remove(fault)
                self._log.warning("sim.fault_fired", device=self._name, fault="estop")
                self.press_estop()

    # -- operator actions --------------------------------------------------------------

    def clear_error(self) -> None:
        """Operator resets the error (and releases the e-stop) on the pendant."""
        if not self._error_code and not self._estop:
            return
        code = self._error_code
        self._error_code = 0
        self._estop = False
        self._tick_failed = False
        self._publish_error_cleared()
        self._log.info("sim.error_cleared", device=self._name, code=code)

    def press_play(self) -> None:
        """Press Play on the pendant: acted on at the next tick, like the Play/Pause coil."""
        if self._profile.has("play_pause"):
            self._bank.set("play_pause", True)

    def press_estop(self) -> None:
        """Press the emergency stop now (the estop fault does the same at its trigger)."""
        if self._estop:
            return
        self._estop = True
        self._log.warning("sim.estop", device=self._name, time_s=self._time_s)
        self._publish_estop()
        self._enter_error(SimErrorCode.EMERGENCY_STOP, "emergency stop")

    # -- what each handshake does its own way ------------------------------------------

    @staticmethod
    @abstractmethod
    def _takes_initial_seq(profile: RobotProfile, seq: int) -> bool:
        """True when the handshake can start as if command ``seq`` had run (seq != 0)."""

    @abstractmethod
    def _reset_handshake_registers(self) -> None:
        """Put the handshake's registers in their power-on state."""

    @abstractmethod
    def _run_handshake(self, dt: float, ready: bool) -> None:
        """Advance the running command, then take a pending one."""

    @abstractmethod
    def _publish_error(self, code: int, reason: str) -> None:
        """Report the robot error just entered (the motion is already stopped)."""

    @abstractmethod
    def _publish_error_cleared(self) -> None:
        """Report that the operator reset the error."""

    def _publish_estop(self) -> None:
        """Show the pressed e-stop before the error it causes (nothing by default)."""

    @abstractmethod
    def _target_rejected(self, seq: int, reason: str) -> None:
        """The arm cannot take the target of command ``seq``, for ``reason``."""

    @abstractmethod
    def _backend_failed(self, seq: int, kind: Literal["motion", "gripper"]) -> None:
        """The backend raised while starting command ``seq``."""

    @abstractmethod
    def _gripper_started(self, number: int, seq: int, *, close: bool, miss: bool) -> None:
        """The gripper of command ``seq`` started to move."""

    @abstractmethod
    def _command_done(self, active: _Active) -> None:
        """The running command finished: the arm settled or the fingers stopped."""

    @abstractmethod
    def _motion_failed(self, active: _Active) -> None:
        """The running motion was lost with the rebuilt physics (already stopped)."""

    def _running_timer_s(self) -> float:
        """Techman's Running Timer: seconds the project has run (0 by default)."""
        return 0.0

    def _up_time_s(self) -> float:
        """Techman's Up Time: seconds since the controller started (simulated time)."""
        return self._time_s

    # -- the tick ----------------------------------------------------------------------

    def tick(self, dt: float) -> None:
        """Advance by ``dt`` s; an exception inside the tick stops the robot in error.

        The robot stops with :attr:`SimErrorCode.TICK_FAILED` (tmflow: the project stops,
        its program abandoned without errorstop), logged ``sim.tick_failed`` once until
        the operator's reset; the next ticks publish the registers as usual.

        Raises:
            ValueError: ``dt`` is not a finite number >= 0.
        """
        if not math.isfinite(dt) or dt < 0:
            raise ValueError(f"dt must be a finite number >= 0, got {dt}")
        try:
            super().tick(dt)
        except Exception as exc:
            if not self._tick_failed:
                self._tick_failed = True
                _log_tick_failure(self._log, self._name, exc)
                self._abandon_program()
                self._enter_error(SimErrorCode.TICK_FAILED, f"tick failed ({type(exc).__name__})")

    def _abandon_program(self) -> None:
        """The tick failed: drop whatever program runs, without its error handling."""

    def _run(self, dt: float, ready: bool) -> None:
        self._take_backend_fault()
        self._run_handshake(dt, ready)
        if ready:
            self._publish_pose()

    def _take_backend_fault(self) -> None:
        """A collision, an overload or an over-speed the physics stopped the arm for becomes a
        robot error."""
        take = getattr(self._backend, "take_fault", None)  # optional in a backend
        fault = None if take is None else take()
        if fault is None:
            return
        code = _FAULT_CODES.get(fault.kind, SimErrorCode.OVER_PAYLOAD)
        self._log.warning(
            "sim.backend_fault", device=self._name, fault=fault.kind, detail=fault.message
        )
        self._enter_error(code, fault.message)

    def _on_rebuilt(self, survived: bool) -> None:
        active = self._active
        if survived is not True and active is not None and active.kind == "motion":
            # The rebuilt physics lost the running motion: it fails, never reported done.
            self._log.warning("sim.motion_lost", device=self._name, move=active.number)
            self._backend.stop_motion()
            self._motion_failed(active)

    # -- shared machinery --------------------------------------------------------------

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

    def _start_motion(
        self, target: Pose, motion: MotionType, speed: float, accel: float, *, seq: int
    ) -> bool:
        """Start the backend motion; False (error reported, nothing started) if it failed."""
        return self._start_move(MoveArgs(target, motion, speed, accel, seq))

    def _backend_start(self, move: MoveArgs) -> float:
        """Start ``move`` on the backend; return its expected duration, s."""
        backend = self._backend
        accel_time_s = move.accel_s / self._speed_factor
        if move.joints is None and move.via is None:
            return backend.start_motion(
                move.target,
                motion=move.motion,
                speed_percent=move.speed,
                accel_time_s=accel_time_s,
            )
        if not isinstance(backend, PathBackend):
            raise TypeError(f"{type(backend).__name__} cannot follow a {move.kind}")
        if move.joints is not None:
            return backend.start_joint_motion(
                move.joints, speed_percent=move.speed, accel_time_s=accel_time_s
            )
        assert move.via is not None
        return backend.start_arc_motion(
            move.via, move.target, speed_percent=move.speed, accel_time_s=accel_time_s
        )

    def _start_move(self, move: MoveArgs) -> bool:
        """Start ``move`` on the backend; False (error reported, nothing started) if it failed."""
        target, speed, seq = move.target, move.speed, move.seq
        number = self._moves_started + 1
        try:
            expected = self._backend_start(move)
        except MotionRejectedError as exc:  # the backend's own reach / limit check
            self._log.warning(
                "sim.command_rejected",
                device=self._name,
                reason=exc.reason,
                target=str(target),
            )
            self._target_rejected(seq, exc.reason)
            return False
        except Exception as exc:  # a backend failure is a robot error, not a crash
            self._log.warning("sim.backend_failed", device=self._name, error=repr(exc))
            self._backend_failed(seq, "motion")
            return False
        self._moves_started = number
        self._record(number, move.kind, seq, target, speed)
        fault = next((f for f in self._move_faults if f.at_move == number), None)
        self._active = _Active(
            "motion",
            number,
            seq=seq,
            target=target,
            expected_s=expected,
            fault=fault,
            record=self._records_made - 1,
        )
        self._log.info(
            "sim.motion_started",
            device=self._name,
            move=number,
            motion=move.kind,
            target=str(target),
            speed=speed,
            expected_s=round(expected, 4),
        )
        return True

    def _drive_gripper(self, *, close: bool, seq: int = 0) -> None:
        number, miss = self._count_grasp() if close else (0, False)
        moves = self._gripper_moves
        try:
            self._backend.drive_gripper(
                moves.close_width_mm if close else moves.open_width_mm,
                speed_mm_s=moves.speed_mm_s,
                force_n=moves.force_n,
            )
        except Exception as exc:  # a backend failure is a robot error, not a crash
            self._log.warning("sim.backend_failed", device=self._name, error=repr(exc))
            self._backend_failed(seq, "gripper")
            return
        self._gripper_closing = close
        self._gripper_miss = miss
        self._record(number, "gripper_close" if close else "gripper_open", seq, None, None)
        if miss:
            self._log_grasp_miss(number)
        self._log.info("sim.gripper", device=self._name, close=close, grasp=number)
        self._gripper_started(number, seq, close=close, miss=miss)

    def _record(
        self, number: int, kind: str, seq: int, target: Pose | None, speed: float | None
    ) -> None:
        self._motion_log.append(
            MotionRecord(number, kind, seq, target, speed, self._time_s, self.clock())
        )
        self._records_made += 1

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
            self._log.info("sim.motion_done", device=self._name, move=active.number)
            self._command_done(active)
            self._record_done(active)
        elif not self._backend.gripper_state().moving:
            self._active = None
            self._command_done(active)
            self._record_done(active)

    def _record_done(self, active: _Active) -> None:
        """Note in its record when ``active`` was reported finished (this tick)."""
        # Its place among the records kept (the oldest are dropped beyond the limit).
        index = active.record - (self._records_made - len(self._motion_log))
        if active.record >= 0 and 0 <= index < len(self._motion_log):
            record = self._motion_log[index]
            self._motion_log[index] = replace(record, done_wall_time=self.clock())

    def _fire(self, fault: _MoveFault, active: _Active) -> None:
        self._log.warning(
            "sim.fault_fired", device=self._name, fault=fault.kind, move=active.number
        )
        if isinstance(fault, StallFault):
            # The arm stops where it is (stuck: no braking, where a backend can say so)
            # but the motion never reports completion.
            getattr(self._backend, "halt_motion", self._backend.stop_motion)()
            active.stalled = True
        elif isinstance(fault, EstopFault):
            self.press_estop()
        else:
            self._enter_error(fault.code, "injected robot error")

    def _stop_motion(self) -> None:
        # Whatever the arm still does brakes, also after a done the backend reported early
        # (a robot's Stop halts the arm, not the controller's idea of it).
        self._backend.stop_motion()
        active = self._active
        if active is not None and active.kind == "motion":
            # A stopped motion is over once the arm settles, stalled or not.
            active.stalled = False
            active.fault = None

    def _enter_error(self, code: int, reason: str) -> None:
        self._error_code = int(code)
        self._log.warning(
            "sim.robot_error",
            device=self._name,
            code=int(code),
            meaning=describe(int(code), hint=True),
            reason=reason,
        )
        self._stop_motion()
        self._active = None
        self._publish_error(int(code), reason)

    def _late_ack_delay(self, *, motion_command: bool) -> float:
        """How late the late_ack faults take the next command (0: not late)."""
        number = self._moves_started + 1
        return max(
            (
                f.delay_s
                for f in self._late_acks
                if f.at_move is None or (motion_command and f.at_move == number)
            ),
            default=0.0,
        )

    def _late_ack_pending(self, key: object, *, motion_command: bool) -> bool:
        """True while a late_ack fault still holds back the command identified by ``key``."""
        delay = self._late_ack_delay(motion_command=motion_command)
        if delay <= 0:
            return False
        if key != self._late_key:
            # A changed command restarts the delay: it is a different command.
            self._late_key = key
            self._late_since = self._time_s
            self._log.warning("sim.fault_fired", device=self._name, fault="late_ack", delay_s=delay)
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
        seen, tcp = self._pose_seen
        if pose is not seen or pose.__class__ is not Pose:
            tcp = array("d", pose.as_list()).tobytes()
            self._pose_seen = (pose, tcp)
        # An idle arm: the very pose (bytes, so a zero's sign too) that was published last
        # inside every range. Nothing is clipped, it encodes, and the saturation check would
        # change nothing (it left both flags False for an unclipped pose).
        if tcp != self._in_range_pose and not self._check_pose(pose, pose.as_list(), tcp):
            return
        bank = self._bank
        # Published at every tick and mostly unchanged (an idle arm, the same second): a
        # part is stored again only when its values differ from those it stored last, or
        # when any word of its Modbus tables changed since the last publication. Floats
        # are compared as their bytes: a zero's sign is stored too.
        unchanged = self._published_mark == self._published_changes()
        if not unchanged or tcp != self._published_tcp:
            published = self._published_values
            for name, value in zip(TCP_FIELDS, published, strict=True):
                bank.set(name, value)
            self._published_tcp = tcp
        if self._has_tm_table:
            self._publish_tm_table(pose, unchanged=unchanged)
        self._published_mark = self._published_changes()

    def _check_pose(self, pose: Pose, values: list[float], tcp: bytes) -> bool:
        """Saturate, encode-check and saturation-log a pose that is not the last in range.

        Sets ``_published_values`` (what the registers get). Returns False when the pose
        cannot be published at all (a robot error was raised).
        """
        self._in_range_pose = None
        fields = self._tcp_fields
        published = [
            min(max(v, low), high) for v, (low, high) in zip(values, self._tcp_ranges, strict=True)
        ]
        # Whether a value encodes does not depend on the sign of a zero: an unchanged pose
        # (an idle arm) is not checked again.
        if values != self._encodable_pose:
            try:
                # Encode all six before storing any: a pose is published whole or not at all
                # (the bank keeps the words for the set() that follows).
                check = self._bank.check
                for name, value in zip(TCP_FIELDS, published, strict=True):
                    check(name, value)
            except ValueOutOfRangeError as exc:  # not even the saturated value fits
                self._encodable_pose = None
                if self._error_code != SimErrorCode.POSE_OUT_OF_RANGE:
                    self._log.warning(
                        "sim.pose_out_of_range",
                        device=self._name,
                        pose=str(pose),
                        error=str(exc),
                    )
                    self._enter_error(SimErrorCode.POSE_OUT_OF_RANGE, "pose cannot be encoded")
                return False
            self._encodable_pose = values
        clipped = [f.name for f, a, b in zip(fields, values, published, strict=True) if a != b]
        self._check_saturation(pose, published, clipped)
        self._published_values = published
        if not clipped:
            # Unclipped values are the pose's own float objects: the same bytes.
            self._in_range_pose = tcp
        return True

    def _published_changes(self) -> int:
        """The change count of the Modbus tables the pose and Techman's table are in."""
        return self._bank.changes_in(self._published_tables)

    def _check_saturation(self, pose: Pose, published: list[float], clipped: list[str]) -> None:
        """Log a saturated excursion once; an arm at rest outside the range is an error."""
        at_rest = self._backend.is_settled()
        if clipped and not self._saturating:
            self._saturating = True
            self._log.warning(
                "sim.pose_saturated",
                device=self._name,
                pose=str(pose),
                published=str(Pose(*published)),
                fields=clipped,
            )
        elif not clipped and self._saturating:
            self._saturating = False
            self._log.info("sim.pose_in_range", device=self._name, pose=str(pose))
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
                device=self._name,
                pose=str(pose),
                fields=clipped,
            )
            self._enter_error(
                SimErrorCode.POSE_OUT_OF_RANGE, "arm at rest at a pose the registers cannot hold"
            )

    def _publish_tm_table(self, tcp: Pose, *, unchanged: bool) -> None:
        """Techman's fixed table beside a tmflow profile (docs/simulator-model.md).

        ``unchanged``: no word of its Modbus tables changed since it was last published
        (only the parts whose values changed are stored again).
        """
        flange = self._backend.flange_pose()
        joints = self._backend.joint_positions_deg() or (0.0,) * 6
        # Without a joint model the simulated tool is the identity: flange = TCP.
        flange = tcp if flange is None else flange
        # Running Timer (0 while the project is stopped) and Up Time.
        clock = (int(self._running_timer_s()), int(self._up_time_s()))
        values = self._tm_table_bytes(flange, tcp, joints)
        speeds = self._tm_speeds_now(values, tcp, joints)
        pose = (values, self._tm_robot_state(), speeds)
        bank_set = self._bank.set
        if not unchanged or pose != self._tm_table_pose:
            flange_values = flange.as_list()
            tcp_values = tcp.as_list()
            # The simulated current base is the robot base (Current Base 8300-8311 reads 0).
            for names, group in (
                (FLANGE_FIELDS, flange_values),
                (ROBOT_BASE_FLANGE_FIELDS, flange_values),
                (ROBOT_BASE_TCP_FIELDS, tcp_values),
            ):
                for name, value in zip(names, group, strict=True):
                    bank_set(name, value)
            for i, angle in enumerate(joints, start=1):
                bank_set(f"joint_{i}", angle)
            for name, speed in zip(_SPEED_FIELDS, speeds, strict=True):
                bank_set(name, speed)
            bank_set("robot_link", True)
            bank_set("operation_mode", 1)  # auto, as ma_mode
            bank_set("aut_p", True)  # AUT.P high: able to play in auto mode
            self._publish_tm_state()
            self._tm_table_pose = pose
        if not unchanged or clock != self._tm_table_clock:
            # Unchanged tables hold what was stored last: only the parts that differ from
            # it (mostly the seconds) are stored again.
            before_clock = self._tm_table_clock
            last = _clock_parts(before_clock) if unchanged and before_clock else _NO_CLOCK
            for name, part, before in zip(_CLOCK_FIELDS, _clock_parts(clock), last, strict=True):
                if part != before:
                    bank_set(name, part)
            self._tm_table_clock = clock

    def _tm_table_bytes(self, flange: Pose, tcp: Pose, joints: Sequence[float]) -> bytes:
        """The flange, the TCP and the joints as the bytes of their doubles (the same
        objects as at the last call: the same bytes, not built again)."""
        seen_flange, seen_tcp, seen_joints, values = self._tm_seen
        if (
            flange is seen_flange
            and tcp is seen_tcp
            and joints is seen_joints
            and flange.__class__ is Pose
            and tcp.__class__ is Pose
            and joints.__class__ is tuple
        ):
            return values
        values = array("d", [*flange.as_list(), *tcp.as_list(), *joints]).tobytes()
        held = joints if joints.__class__ is tuple else None
        self._tm_seen = (flange, tcp, held, values)
        return values

    def _tm_speeds_now(
        self, values: bytes, tcp: Pose, joints: Sequence[float]
    ) -> tuple[float, ...]:
        """Joint Speed and TCP Speed: how far the joints and the TCP moved since the last
        publication, per simulated second (all 0 once the arm held still a whole tick)."""
        last_values, last_tcp, last_joints, last_s = self._tm_motion
        now_s = self._time_s
        # A backend's own list may change under it: its values are kept, as a tuple.
        self._tm_motion = (values, tcp, joints if joints.__class__ is tuple else (*joints,), now_s)
        if values == last_values or last_tcp is None:
            self._tm_speeds = _NO_SPEEDS
        elif now_s > last_s:  # else (no time passed) the speeds published last stand
            self._tm_speeds = motion_speeds(last_tcp, tcp, last_joints, joints, now_s - last_s)
        return self._tm_speeds

    def _tm_robot_state(self) -> int | None:
        """Robot State (7215): STO, error or normal; None when the profile has no such field."""
        if not self._has_tm_state:
            return None
        return 4 if self._estop else 2 if self._error_code else 0

    def _publish_tm_state(self) -> None:
        """Robot State (7215) in the same step as the error and e-stop bits."""
        state = self._tm_robot_state()
        if state is not None:
            self._bank.set("tm_robot_state", state)

    def _code(self, field: str, label: str, default: int) -> int:
        try:
            return self._profile.field(field).code_of(label)
        except KeyError:
            return default


#: The Running Timer's and the Up Time's days, hours, minutes and seconds, in that order.
_CLOCK_FIELDS = (*_RUNNING_TIMER_FIELDS, *_UP_TIME_FIELDS)
#: Parts no clock has: each part of a clock differs from them.
_NO_CLOCK: tuple[None, ...] = (None,) * len(_CLOCK_FIELDS)


def motion_speeds(
    tcp_from: Pose,
    tcp_to: Pose,
    joints_from: Sequence[float],
    joints_to: Sequence[float],
    dt: float,
) -> tuple[float, ...]:
    """Joint Speed J1..J6 (deg/s), then TCP Speed x, y, z (mm/s), rx, ry, rz (deg/s, each
    angle's change the short way round) and s3d (mm/s), moving from one sample to the
    next in ``dt`` s (> 0)."""
    joints = [(b - a) / dt for a, b in zip(joints_from, joints_to, strict=True)]
    a, b = tcp_from.as_list(), tcp_to.as_list()
    linear = [(b[i] - a[i]) / dt for i in range(3)]
    angular = [((b[i] - a[i] + 180.0) % 360.0 - 180.0) / dt for i in range(3, 6)]
    return (*joints, *linear, *angular, math.hypot(*linear))


def _clock_parts(clock: tuple[int, int]) -> tuple[int, ...]:
    """The values of :data:`_CLOCK_FIELDS` for (Running Timer, Up Time) in whole seconds."""
    run, up = clock
    return (
        *(run // 86400, run // 3600 % 24, run // 60 % 60, run % 60),
        *(up // 86400, up // 3600 % 24, up // 60 % 60, up % 60),
    )


def _log_tick_failure(log: Logger, device: str, exc: Exception) -> None:
    """One error-level line: the exception that ended a tick, and where it was raised."""
    frames = traceback.extract_tb(exc.__traceback__)[-1:]
    where = f"{frames[0].filename}:{frames[0].lineno} in {frames[0].name}" if frames else "?"
    log_error = getattr(log, "error", log.warning)  # a Logger may have no error()
    log_error(
        "sim.tick_failed",
        device=device,
        error=f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__,
        where=where,
    )
