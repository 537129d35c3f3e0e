"""A TMflow Script Project on the simulated robot: the robot program, interpreted.

The ``tmflow`` robot of the simulator runs the very program a user loads into TMflow
(``tmmaster robot-program``, or the user's own Script Project) through
:mod:`tmmaster.tmscript`, one slice of statements per control tick. The program reaches
the robot through :class:`SimHost`:

- ``modbus_read`` / ``modbus_write`` on the robot's own slave (127.0.0.1, port 502 as the
  program declares it) read and write this robot's register bank, as TMflow's own
  Modbus client would;
- motion functions queue moves that the physics backend runs one after the other, in the
  current TCP (``ChangeTCP``) and the robot base; ``QueueTag``/``WaitQueueTag`` wait for
  them; ``inversekin`` is the arm model's;
- the end module's digital output drives the gripper, its digital input reports grip.

TMflow's operational model stays the controller's (:class:`SequenceController`): the
project Running / Paused / Stopped / Error on the documented discrete inputs, the Play /
Pause and Stop coils, an e-stop pausing the project (Resumption Behavior on) or stopping
it; stopping runs ``closestop``, an error ``errorstop``; a start runs ``main`` from the
beginning.
"""

from __future__ import annotations

import contextlib
import functools
import gc
import random
import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

from .._exceptions import ConfigError, UnreachablePoseError
from .._io import END_MODULE_DO
from .._pose import MotionType, Pose
from .._registers import RobotProfile, Table
from .._robot_models import RobotModel
from .._robot_program import ToolSetting, robot_program
from ..tmscript import Execution, Program, parse
from ..tmscript._host import HostError, ModbusCommunicationError, ModbusDevice, MotionCall
from ._backend import PathBackend, PhysicsBackend
from ._bank import RegisterBank
from ._controller import MoveArgs, SimErrorCode, _Active
from ._kinematic import KinematicBackend
from ._mujoco import MuJoCoBackend
from ._sequence import SequenceController

#: Statements a program may run per control tick before it yields to the robot (a busy
#: loop must not freeze the simulator; TMflow time-slices a project the same way).
STATEMENTS_PER_TICK = 400
#: CPU seconds a program may run per control tick (``time.thread_time``, less the
#: garbage collections that fell in it: :class:`_ProgramClock`), whichever of
#: the two budgets ends first: slow statements yield too, so the Modbus server (on the
#: same thread) keeps answering between ticks. CPU time, not wall time, so that how far
#: a program gets in a tick does not depend on the machine's load. A statement running
#: then finishes first (a bounded one: strings and arrays are capped, see
#: ``docs/tmscript.md``).
TICK_SECONDS = 0.02


class _ProgramClock:
    """The budget clock of a tick: this thread's CPU seconds less its garbage collections.

    A collection the interpreter happens to trigger (tens to hundreds of milliseconds in
    a process with a large heap) is not the program's: counted, it spent a tick's whole
    budget, and a command written before that tick was taken a tick late. Installed in
    ``gc.callbacks`` once, when the first Script Project starts.
    """

    _local = threading.local()
    _installed = False

    def __call__(self) -> float:
        return time.thread_time() - getattr(self._local, "collecting_s", 0.0)

    @classmethod
    def install(cls) -> None:
        """Count the collections from now on (once per process)."""
        if not cls._installed:
            cls._installed = True
            gc.callbacks.append(cls._collection)

    @classmethod
    def _collection(cls, phase: str, info: dict[str, int]) -> None:
        local, now = cls._local, time.thread_time()
        if phase == "start":
            local.started_s = now
        elif hasattr(local, "started_s"):
            local.collecting_s = getattr(local, "collecting_s", 0.0) + now - local.started_s
            del local.started_s


#: The Modbus tables behind each function code, and whether it writes.
_FUNCTIONS: dict[int, tuple[Table, bool]] = {
    1: (Table.COIL, False),
    2: (Table.DISCRETE_INPUT, False),
    3: (Table.HOLDING, False),
    4: (Table.INPUT, False),
    5: (Table.COIL, True),
    6: (Table.HOLDING, True),
    15: (Table.COIL, True),
    16: (Table.HOLDING, True),
}

#: Techman's error codes for a move the arm cannot make (TMflow 2.24 Software Manual,
#: appendix J, p. 349): "Inverse Kinematics Failure, Working Range Issue" (a PTP or
#: Circle target out of reach), "... Interpolation Points Issue" (a reachable target on
#: a path the arm cannot follow), "Target of Line Motion is Out of reachable point of
#: Robot", "Target of PtP Motion is Out of Joint Boundary" (a joint target).
TM_IK_WORKING_RANGE = 0x0001
TM_IK_INTERPOLATION = 0x0012
TM_LINE_TARGET_UNREACHABLE = 0x001B
TM_PTP_JOINT_BOUNDARY = 0x001C

#: The mass of the simulated tool the generated program declares (an OnRobot 2FG7, 1.1 kg).
SIMULATED_TOOL_MASS_KG = 1.1

#: The most an absolute ("A", "D") Line or Circle speed may be, mm/s: "The available range
#: of ABS Speed is from 0 to 4500 mm/s" (TMflow 2.24, 9 Line, p. 171).
ABS_SPEED_MAX_MM_S = 4500.0

#: Error code the simulated controller reports when the program fails (a script error).
SCRIPT_ERROR = 0x0300


@dataclass
class _Queued:
    """A move in the robot's motion buffer."""

    target: Pose
    motion: MotionType
    speed: float
    accel_s: float
    tag: int = 0
    done: bool = False
    #: ``PTP("JPP", ...)``, or a "CPP" one's with reference joints: the joints to reach.
    joints: tuple[float, ...] | None = None
    #: The joints are a "CPP" PTP's: the motion log says ``ptp``.
    cartesian: bool = False
    #: ``Circle``: a point on the arc, and where the arc starts.
    via: Pose | None = None
    start: Pose | None = None
    #: A move the arm cannot make: the error code and reason the robot stops with.
    error: tuple[int, str] | None = None
    #: The joints the arm ends at, as planned when queued (the next move plans from them).
    end_joints: tuple[float, ...] | None = None


class SimHost:
    """The robot as a running program sees it (the :class:`tmmaster.tmscript` host)."""

    def __init__(self, controller: ScriptProjectController) -> None:
        self._c = controller

    def now_s(self) -> float:
        """The simulated clock, seconds."""
        return self._c._time_s  # not the property: the program reads it in every wait

    @property
    def stamp_scale(self) -> float:
        """Simulated seconds per wall second: ``GetNowStamp`` counts wall milliseconds."""
        return self._c.stamp_scale

    @property
    def random(self) -> random.Random:
        """The controller's random numbers (``random()``), across the project's starts."""
        return self._c.random

    def display(self, text: str) -> None:
        """A ``Display()`` line, logged."""
        self._c.displayed.append(text)
        self._c.log_display(text)

    def modbus_request(
        self,
        device: ModbusDevice,
        function: int,
        address: int,
        count: int,
        values: Sequence[int] | None,
    ) -> list[int]:
        """A request on the robot's own slave: this robot's register bank."""
        if device.host not in ("127.0.0.1", "localhost") or device.port != 502:
            raise HostError(
                f"device {device.name} is {device.host}:{device.port}: the simulated robot's"
                " program reaches only its own slave (127.0.0.1, port 502)"
            )
        table, write = _FUNCTIONS.get(function, (None, False))
        if table is None:
            raise HostError(f"Modbus function {function} is not supported")
        c = self._c
        if not write:
            try:
                words = c._bank.read(table, address, count)
            except Exception as exc:  # an illegal address: the device's exception answer
                raise HostError(f"{device.name}: {exc}") from exc
            if c._late_acks:  # after_read() acts with a late_ack fault only
                c.after_read(table, address, words)
            return words
        refused = c.refused_writes
        if refused and any((table, a) in refused for a in range(address, address + count)):
            # The slave's answer to a client without write permission (its IP filter):
            # a communication error, on which modbus_write returns false.
            raise ModbusCommunicationError(
                f"{device.name}: write to {table.value} {address} refused"
            )
        written = list(values or ())
        try:
            c._bank.write(table, address, written, device=True)
            c.after_write(table, address, written)
        except Exception as exc:  # an illegal address: the device's exception answer
            raise HostError(f"{device.name}: {exc}") from exc
        return []

    def modbus_ready(self, device: ModbusDevice) -> bool:
        """False while a late_ack fault holds the program's link (its next request waits)."""
        c = self._c
        return c._time_s >= c.link_free_at  # the field: the program asks before every request

    def motion(self, call: MotionCall) -> bool:
        """Put a PTP, Line or Circle into the motion buffer ("CPP", "JPP", "CAP"...).

        False (nothing queued) for a target or a path the arm cannot take.
        """
        return self._c.queue_motion(call)

    def queue_tag(self, tag: int, wait: int) -> None:
        """Tag the move queued last (done at once when the buffer is empty)."""
        self._c.tag_last(tag)

    def queue_tag_done(self, tag: int) -> bool | None:
        """Whether the moves up to ``tag`` ran; None when no move carries it."""
        return self._c.tag_done(tag)

    def stop_and_clear_buffer(self) -> None:
        """Stop the arm and forget the queued moves."""
        self._c.clear_buffer()

    def change_base(self, value: str | Sequence[float]) -> None:
        """Only the robot base is modelled (a base name other than RobotBase is refused)."""
        if isinstance(value, str):
            if value != "RobotBase":
                raise HostError(f"base {value!r}: the simulator models only RobotBase")
            return
        if any(abs(v) > 1e-9 for v in value):
            raise HostError("the simulator models only the robot base (all zeros)")

    def change_tcp(
        self,
        value: str | Sequence[float],
        mass: float | None = None,
        inertia: Sequence[float] | None = None,
    ) -> None:
        """The TCP of the following moves: the flange, or X, Y, Z, RX, RY, RZ, with the
        tool's mass and inertia (TMscript 2.24 §13.6, pp. 327-328), published at 7354-7385
        (TMflow 2.24 appendix C, "TCP Value", p. 313)."""
        if isinstance(value, str):
            if value != "RobotEndFlange":
                raise HostError(
                    f"TCP {value!r}: the simulator has no tool by name but RobotEndFlange:"
                    " for the simulator, make the program with robot-program"
                    " --tool X,Y,Z,RX,RY,RZ --tool-mass KG and give the simulator that --tool"
                )
            tool: Pose | None = None
        else:
            tool = None if all(abs(v) < 1e-9 for v in value) else Pose(*value)
        if inertia is not None and len(inertia) != 9:
            raise HostError(f"ChangeTCP: the inertia needs 9 values, got {len(inertia)}")
        self._c.change_tool(tool)
        self._c.publish_tcp_value(
            [0.0] * 6 if isinstance(value, str) else list(value),
            0.0 if mass is None else float(mass),
            [0.0] * 9 if inertia is None else list(inertia),
        )

    def inversekin(
        self, pose: Sequence[float], reference: Sequence[float] | None = None
    ) -> list[float]:
        """The arm model's joints for a TCP pose in the current tool; empty when unreachable.

        Without ``reference``, "by the current pose configuration" (TMscript 2.24 §6.35,
        p. 207): a pose the arm reaches only in another configuration than the one it is
        in is unreachable, as on the robot. With it, the solution nearest the reference.
        """
        model, here, target = self._c.model, self._c.arm_joints, Pose(*pose)
        seed = list(reference) if reference is not None and len(reference) == 6 else here
        try:
            joints = model.inverse(target, seed_deg=seed, tool=self._c.tool)
        except UnreachablePoseError as exc:
            self._c.log_rejected("inversekin", exc.reason, target)
            return []
        keep = None if reference is not None or here is None else model.configuration(here)
        if keep is None or model.configuration(joints) == keep:
            return list(joints)
        # The kinematic solver keeps the configuration, whatever a controller's PTP would
        # choose (a model of another controller may choose otherwise): from here only.
        with contextlib.suppress(UnreachablePoseError):
            joints = model.inverse(target, seed_deg=here, tool=self._c.tool, same_branch=True)
        if model.configuration(joints) == keep:
            return list(joints)
        self._c.log_rejected("inversekin", "configuration", target)
        return []

    def forwardkin(self, joints: Sequence[float]) -> list[float]:
        """The TCP pose of six joint angles in the current tool."""
        return self._c.model.forward(joints, self._c.tool).as_list()

    def pause(self) -> None:
        """``Pause()``: the project pauses, as with the Pause button."""
        self._c.pause_from_program()

    def resume(self) -> None:
        """``Resume()`` (a non-pause thread's, while paused): the project resumes, as with Play."""
        self._c.resume_from_program()


@functools.lru_cache(maxsize=8)
def _parsed(text: str) -> Program:
    """``parse(text)``, once per text: a Program runs any number of times, and the
    simulators of one process mostly run the same generated program (a parse takes a
    few tenths of a second, which a process starting many simulators paid for each)."""
    return parse(text)


class ScriptProjectController(SequenceController):
    """The tmflow robot running a Script Project through the TMscript interpreter."""

    def __init__(
        self,
        profile: RobotProfile,
        bank: RegisterBank,
        backend: PhysicsBackend,
        model: RobotModel,
        *,
        program: str | Program | None = None,
        gripper_output: int = 0,
        gripper_input: int = 0,
        **options: Any,
    ) -> None:
        if program is None:
            # The program tmmaster ships, for this profile and the backend's tool.
            program = robot_program(profile, tool=simulated_tool(_backend_tool(backend)))
        #: The mass of the tool the program set (``ChangeTCP``), kg; None before it did.
        self.tool_mass_kg: float | None = None
        #: The program's source, when given as text (the generated one is).
        self.program_text: str | None = program if isinstance(program, str) else None
        self._program = program if isinstance(program, Program) else _parsed(program)
        self._execution: Execution | None = None
        self._queue: deque[_Queued] = deque()
        self._tags: dict[int, _Queued | None] = {}
        #: A non-pause thread called Resume() while the project was paused.
        self._resume_asked = False
        #: Simulated time from which the program's next Modbus request may go (late_ack).
        self.link_free_at = -1.0
        self._gripper_output = gripper_output
        grip_input = f"em_di_{gripper_input}"
        #: The end module's DI field of the grip input (None: the profile has none).
        self._grip_input_field: str | None = grip_input if bank.has(grip_input) else None
        self._gripper_output_high = False
        #: Addresses the robot's slave refuses the program's writes to, as ``(table,
        #: address)``: a slave whose IP filter gives 127.0.0.1 no write permission (a test
        #: hook; empty by default).
        self.refused_writes: set[tuple[Table, int]] = set()
        #: Every ``Display()`` text, in order (for tests and the CLI's trace).
        self.displayed: list[str] = []
        #: Simulated seconds per wall second (the Simulator's ``time_scale``):
        #: ``GetNowStamp``, the Running Timer and the Up Time count wall time, the clock
        #: of the master's heartbeat (``master_ttl_ms``), so a simulator faster than real
        #: time expires no command of a live master.
        self.stamp_scale = 1.0
        #: The program's ``random()``: the same draws in every run of a test (a real
        #: controller's are its own), a new one at each start of the project.
        self.random = random.Random(0)
        super().__init__(profile, bank, backend, model, **options)
        # The robot's active tool before the project sets its own (TMflow's TCP value,
        # 7354-7385): the cell's, with the simulated gripper's mass.
        tool = _backend_tool(backend) or Pose(0, 0, 0, 0, 0, 0)
        names = [f"tcp_value_{n}" for n in ("x", "y", "z", "rx", "ry", "rz", "mass")]
        for name, value in zip(names, [*tool.as_list(), SIMULATED_TOOL_MASS_KG], strict=True):
            if bank.has(name):
                bank.set(name, value)

    # -- what the host reaches ----------------------------------------------------------

    @property
    def time_s(self) -> float:
        """Simulated seconds since the controller started."""
        return self._time_s

    @property
    def bank(self) -> RegisterBank:
        """The robot's register bank."""
        return self._bank

    @property
    def model(self) -> RobotModel:
        """The arm model."""
        return self._model

    @property
    def tool(self) -> Pose | None:
        """The TCP the program set (``ChangeTCP``)."""
        return _backend_tool(self._backend)

    @property
    def arm_joints(self) -> tuple[float, ...] | None:
        """The arm's joints now, deg (None: a backend without a joint model)."""
        return self._backend.joint_positions_deg()

    def log_display(self, text: str) -> None:
        """Log a program's ``Display()``."""
        self._log.info("sim.display", device=self._name, text=text)

    def change_tool(self, tool: Pose | None) -> None:
        """``ChangeTCP``: the backend's tool for the following moves."""
        backend = self._backend
        if isinstance(backend, KinematicBackend):
            if self._active is not None and self._active.kind == "motion":
                raise HostError("ChangeTCP while the arm moves")
            backend.set_tool(tool)
            return
        own = _backend_tool(backend)
        same = (tool is None and own is None) or (
            tool is not None and own is not None and tool.is_close(own, mm=1e-6, deg=1e-6)
        )
        if not same:
            raise HostError(
                f"this physics backend keeps its tool ({own}): ChangeTCP to {tool} is refused;"
                " start the simulator with that tool"
            )

    def publish_tcp_value(self, tcp: list[float], mass: float, inertia: list[float]) -> None:
        """The TCP the program set, its mass and inertia, where TMflow publishes them."""
        self.tool_mass_kg = mass
        names = [f"tcp_value_{n}" for n in ("x", "y", "z", "rx", "ry", "rz", "mass")]
        names += [f"tcp_value_{n}" for n in ("ixx", "iyy", "izz")]
        names += [f"tcp_value_cm_{n}" for n in ("x", "y", "z", "rx", "ry", "rz")]
        for name, value in zip(names, [*tcp, mass, *inertia], strict=True):
            if self._bank.has(name):
                self._bank.set(name, value)

    def after_read(self, table: Table, address: int, words: list[int]) -> None:
        """A late_ack fault: the program read a new command and takes ``delay_s`` to ack it.

        Its next Modbus request waits ``delay_s`` (a slow link between the program and its
        slave): the block was read before the delay, so a cancel written meanwhile is seen
        only when the program reads the command again before and after its ack.
        """
        if table is not Table.HOLDING or not self._late_acks:
            return
        # The read the program acts on: the whole block, targets and seq together.
        first = self._profile.field("target_x").address
        seq_field = self._profile.field("seq")
        if not (address <= first and seq_field.address < address + len(words)):
            return
        seq = int(self._bank.get("seq"))
        if seq != self._profile.next_seq(int(self._bank.get("ack_seq"))):
            return
        label = self._profile.field("command").label(int(self._bank.get("command")))
        delay = self._late_ack_delay(
            motion_command=label in ("ptp", "line", "ptp_joints", "circle")
        )
        if delay > 0 and self.link_free_at < self._time_s:
            self.link_free_at = self._time_s + delay
            self._log.warning("sim.fault_fired", device=self._name, fault="late_ack", delay_s=delay)

    def log_rejected(self, what: str, reason: str, target: Pose) -> None:
        """Log a target or path the arm model refused."""
        self._log.warning(
            "sim.command_rejected", device=self._name, by=what, reason=reason, target=str(target)
        )

    def queue_motion(self, call: MotionCall) -> bool:
        """Put a move into the buffer; False only for a command the robot would reject.

        PTP "CPP" / "JPP" (joints reached exactly), Line "C" + speed in % ("P") or mm/s
        ("A", "D") + any blending letter, Circle "CPP" / "CAP" / "CDP" with arc angle 0
        (blending is not modelled: each move ends at rest). Formats and arguments not
        modelled are a host error; a speed out of range, or a joint target or an arc on
        a backend that cannot follow one, is refused (False). A target or a path the arm
        cannot take is queued as it is on a robot, where PTP, Line and Circle return
        false for a malformed command only (TMscript 2.24 pp. 331, 337, 343): when the
        buffer reaches it, the robot stops in error with Techman's code for it.
        """
        fmt = _modelled_format(call)
        speed = self._percent(call, fmt)
        if not 0 < speed <= 100:
            self.log_rejected(call.kind, f"speed {call.speed} ({fmt})", Pose(*call.target[:6]))
            return False
        accel_s = (call.accel_time_ms if call.accel_time_ms > 0 else 200) / 1000.0
        # From where the arm will be, joints included: the end of the last queued move,
        # or here (a path checked from another posture refuses Lines the arm can follow).
        if self._queue:
            start, start_joints = self._queue[-1].target, self._queue[-1].end_joints
        else:
            start, start_joints = self._backend.tcp_pose(), self._backend.joint_positions_deg()
        try:
            target, joints, via, end = self._planned(call, fmt, start, start_joints)
        except (UnreachablePoseError, ConfigError) as exc:  # ConfigError: no arc
            reason = exc.reason if isinstance(exc, UnreachablePoseError) else str(exc)
            self.log_rejected(call.kind, reason, Pose(*call.target[:6]))
            stop = (self._rejection_code(call, fmt), f"{call.kind} {fmt}: {reason}")
            self._queue.append(
                _Queued(Pose(*call.target[:6]), MotionType.PTP, speed, accel_s, error=stop)
            )
            return True
        if (joints is not None or via is not None) and not isinstance(self._backend, PathBackend):
            self.log_rejected(call.kind, f"{type(self._backend).__name__} cannot follow it", target)
            return False
        motion = MotionType.PTP if call.kind == "PTP" else MotionType.LINE
        self._queue.append(
            _Queued(
                target,
                motion,
                speed,
                accel_s,
                joints=joints,
                cartesian=fmt != "JPP",
                via=via,
                start=start,
                end_joints=end,
            )
        )
        return True

    def _percent(self, call: MotionCall, fmt: str) -> float:
        """The move's speed in percent: "P" as given; an absolute speed ("A", "D"), mm/s,
        as the percent of the arm's top TCP speed it is, at most 100 (the modelled arm goes
        no faster), for the robot's whole range of 0..4500 mm/s ("The available range of
        ABS Speed is from 0 to 4500 mm/s", TMflow 2.24, 9 Line, p. 171); beyond it, -1."""
        speed = float(call.speed)
        if call.kind == "PTP" or fmt[1] not in "AD":
            return speed
        if speed > ABS_SPEED_MAX_MM_S:
            return -1.0
        return min(100.0, speed * 100.0 / self._model.tcp_speed_mm_s)

    def _rejection_code(self, call: MotionCall, fmt: str) -> int:
        """Techman's error code for a move the arm cannot make (TMflow 2.24, appendix J,
        p. 349): its target is out of reach, or only its path is."""
        if fmt == "JPP":
            return TM_PTP_JOINT_BOUNDARY
        try:
            self._model.inverse(Pose(*call.target[:6]), tool=self.tool)
        except UnreachablePoseError:
            return TM_LINE_TARGET_UNREACHABLE if call.kind == "Line" else TM_IK_WORKING_RANGE
        return TM_IK_INTERPOLATION

    def _planned(
        self, call: MotionCall, fmt: str, start: Pose, start_joints: Sequence[float] | None
    ) -> tuple[Pose, tuple[float, ...] | None, Pose | None, tuple[float, ...]]:
        """The move's target, joint target, arc point and end joints, its path checked
        from ``start`` with the arm at ``start_joints`` (None: the model's ready posture).

        Raises:
            UnreachablePoseError: The target or the path is out of reach.
            ConfigError: No arc passes through the points.
        """
        joints: tuple[float, ...] | None = None
        via: Pose | None = None
        if fmt == "JPP":
            joints = self._model.check_joints(call.target, tool=self.tool)
            target = self._model.forward(joints, self.tool)
        elif call.reference_joints is not None:
            # PTP Syntax 3: "attempt to reach the closest assigned joint target" (TMscript
            # 2.24 §13.8, p. 335): the solution nearest the reference joints, not here.
            target = Pose(*call.target)
            nearest = self._model.inverse(target, seed_deg=call.reference_joints, tool=self.tool)
            joints = self._own_choice(target, start_joints, nearest)
        else:
            target = Pose(*call.target)
        seed = None if start_joints is None else tuple(start_joints)
        model, tool = self._model, self.tool
        end: Sequence[float]
        if call.kind == "Circle":
            assert call.via is not None
            via = Pose(*call.via)
            end = model.arc_joints(start, via, target, start_joints_deg=seed, tool=tool)[-1]
        elif call.kind == "Line":
            end = model.line_joints(start, target, start_joints_deg=seed, tool=tool)[-1]
        elif joints is None:
            end = model.inverse(target, seed_deg=seed, tool=tool)
        else:
            end = joints
        return target, joints, via, tuple(end)

    def _own_choice(
        self, target: Pose, start_joints: Sequence[float] | None, nearest: Sequence[float]
    ) -> tuple[float, ...] | None:
        """A Cartesian PTP's joints nearest its reference: None where they are the backend's
        own choice from ``start_joints``, within 0.001° (its Cartesian PTP then ends on the
        target itself), or where the backend reports no joints (it takes its own)."""
        joints = self._model.check_joints(nearest, tool=self.tool)
        if start_joints is None:
            return None
        with contextlib.suppress(UnreachablePoseError):
            own = self._model.inverse(target, seed_deg=start_joints, tool=self.tool)
            if max(abs(a - b) for a, b in zip(own, joints, strict=True)) < 1e-3:
                return None
        return joints

    def tag_last(self, tag: int) -> None:
        """QueueTag: the last queued move carries ``tag`` (None: nothing queued, done).

        Only the final four tags are kept: an older one "returns not existed" (TMscript
        2.24 §13.2, p. 321; §13.3, p. 322).
        """
        self._tags.pop(tag, None)
        self._tags[tag] = self._queue[-1] if self._queue else None
        while len(self._tags) > 4:
            del self._tags[next(iter(self._tags))]
        if self._queue:
            self._queue[-1].tag = tag

    def tag_done(self, tag: int) -> bool | None:
        """True once the move tagged ``tag`` (and every one before it) ran."""
        if tag not in self._tags:
            return None
        move = self._tags[tag]
        return move is None or move.done

    def clear_buffer(self) -> None:
        """StopAndClearBuffer: stop the arm, forget the queue (tags count as done)."""
        self._stop_motion()
        self._active = None
        for move in self._queue:
            move.done = True
        self._queue.clear()

    def pause_from_program(self) -> None:
        """The program called ``Pause()``."""
        self._pause("Pause() in the program")

    def resume_from_program(self) -> None:
        """The program called ``Resume()``: a paused project resumes once its threads' step
        ends (TMscript 2.24 §5.2, p. 156; §5.3, p. 157), unless the robot is in error."""
        self._resume_asked = self._paused

    def _resume(self) -> None:
        # Play resumes the program too, where it called Pause() (TMscript 2.24 §5.2).
        super()._resume()
        if self._execution is not None:
            self._execution.resume()

    def after_write(self, table: Table, address: int, values: Sequence[int]) -> None:
        """The end module's gripper output (a coil): high closes the gripper, low opens it."""
        output = END_MODULE_DO + self._gripper_output
        if table is not Table.COIL or not address <= output < address + len(values):
            return
        close = bool(values[output - address])
        if close != self._gripper_output_high:
            self._gripper_output_high = close
            self._drive_gripper(close=close, seq=int(self._bank.get("ack_seq")))

    def _publish_grip(self) -> None:
        """The end module's grip input: a part is held between closed fingers."""
        name = self._grip_input_field
        if name is not None:
            self._bank.set(name, self._grip_detected())

    # -- the project -------------------------------------------------------------------

    def _start_project(self) -> None:
        self._running = True
        self._project_started_s = self._time_s
        self._queue.clear()
        self._tags.clear()
        self._resume_asked = False
        self.link_free_at = -1.0
        self._set_paused(False, "start")
        self._bank.set("project_running", True)
        # main from the beginning; define's variables fresh ([TS] 3.1-3.2, p. 29).
        _ProgramClock.install()
        self._execution = Execution(self._program, SimHost(self), budget_clock=_ProgramClock())
        self._log.info("sim.project_started", device=self._name)

    def _stop_project(self, reason: str) -> None:
        execution, self._execution = self._execution, None
        super()._stop_project(reason)
        self._queue.clear()
        if execution is not None:
            if self._error_code:
                execution.fail(reason, max_seconds=TICK_SECONDS)  # errorstop ([TS] 3.4, p. 31)
            else:
                execution.stop(max_seconds=TICK_SECONDS)  # closestop ([TS] 3.3, p. 30)

    def _running_timer_s(self) -> float:
        # In wall seconds, as GetNowStamp counts the run time (stamp_scale).
        return super()._running_timer_s() / self.stamp_scale

    def _up_time_s(self) -> float:
        # In wall seconds too: the program measures the master's silence by it as well as
        # by GetNowStamp, against master_ttl_ms, wall time (docs/tmflow-program.md).
        return self._time_s / self.stamp_scale

    def _abandon_program(self) -> None:
        # The tick failed: the program is dropped as it is, without errorstop (which would
        # run on a state the failure may have left half-updated).
        self._execution = None
        self._queue.clear()

    def _run_handshake(self, dt: float, ready: bool) -> None:
        self._handle_buttons()
        self._publish_grip()
        if not self._running:
            return
        if self._paused:
            if self._execution is not None:
                self._step_paused(self._execution)
            return
        if self._active is not None:
            self._advance(dt, ready)
        execution = self._execution
        if execution is not None:
            self._step(execution)
        # A move the program queued in this tick starts in this tick, as TMflow's motion
        # buffer takes it at once.
        if self._active is None and self._queue and ready and self._running:
            self._start_queued()

    def _step_paused(self, execution: Execution) -> None:
        """A paused project: its non-pause threads run ([TS] 3.12.1, p. 47).

        One that stops the project (``Exit()``, an error) ends the pause: the interrupted
        move is dropped, never resumed, and the stop section runs from the next tick.
        """
        execution.step_threads(STATEMENTS_PER_TICK, TICK_SECONDS)
        if self._execution is execution and execution.phase != "main":
            self._interrupted = None
            self._queue.clear()
            self._set_paused(False, "the program stopped the project from a thread")
        asked, self._resume_asked = self._resume_asked, False
        in_error = self._error_code or self._estop  # Play is refused there too
        if asked and self._paused and self._execution is execution and not in_error:
            self._log.info("sim.project_resumed_by_program", device=self._name)
            self._resume()

    def _step(self, execution: Execution) -> None:
        status = execution.step(STATEMENTS_PER_TICK, TICK_SECONDS)
        if self._execution is not execution:
            return  # the program stopped the project (Exit()) or failed: handled below
        if execution.phase != "main" and not execution.exit_waits and self._queue:
            # Exit(false, ...): the project stops without waiting for the motion ([TS]
            # 5.1, p. 154): the arm stops, the buffer is dropped.
            self.clear_buffer()
        if status.state == "ended":
            self._log.info("sim.program_ended", device=self._name)
            self._execution = None
            self._running = False
            self._bank.set("project_running", False)
        elif status.state == "error":
            self._log.warning("sim.program_error", device=self._name, error=str(status.error))
            self._execution = None
            self._enter_error(SCRIPT_ERROR, f"program error: {status.error}")

    def _start_queued(self) -> None:
        move = self._queue[0]
        if move.error is not None:
            # The motion controller reaches a move it cannot make: an error stop.
            code, reason = move.error
            self._queue.clear()
            self._enter_error(code, f"motion target rejected ({reason})")
            return
        args = MoveArgs(
            move.target,
            move.motion,
            move.speed,
            move.accel_s,
            int(self._bank.get("ack_seq")),
            joints=move.joints,
            via=move.via,
            start=move.start if move.via is not None else None,
            cartesian=move.cartesian,
        )
        self._motion_args = args
        self._start_move(args)

    def _command_done(self, active: _Active) -> None:
        # A move of the buffer ran; the fingers stopped (the program reports the gripper
        # command itself, after its settle time and the grip input).
        if active.kind == "motion" and self._queue:
            self._queue.popleft().done = True

    def _motion_failed(self, active: _Active) -> None:
        self._active = None
        self._enter_error(SimErrorCode.MOTION_LOST, "motion lost")

    def _target_rejected(self, seq: int, reason: str) -> None:
        # A motion function given a target the arm cannot take: an error stop.
        self._queue.clear()
        self._enter_error(SimErrorCode.UNREACHABLE, f"motion target rejected ({reason})")

    def _backend_failed(self, seq: int, kind: Literal["motion", "gripper"]) -> None:
        self._queue.clear()
        self._enter_error(SimErrorCode.BACKEND_FAILURE, f"{kind} backend failed")


def simulated_tool(tool: Pose | None) -> ToolSetting:
    """The tool the generated program sets on the simulated robot: ``tool`` (None: the
    flange's own frame) with the simulated gripper's mass, an OnRobot 2FG7's 1.1 kg."""
    return ToolSetting(tcp=tool or Pose(0, 0, 0, 0, 0, 0), mass_kg=SIMULATED_TOOL_MASS_KG)


def _backend_tool(backend: PhysicsBackend) -> Pose | None:
    """The TCP a built-in backend moves (None: the flange, or a backend of one's own)."""
    if isinstance(backend, KinematicBackend | MuJoCoBackend):
        return backend.tool
    return None


def _modelled_format(call: MotionCall) -> str:
    """The motion's format in capitals; a host error for what the simulator does not model."""
    fmt = call.format.upper()
    if call.kind == "PTP" and fmt not in ("CPP", "JPP"):
        raise HostError(f"motion format {call.format!r} is not modelled (CPP, JPP)")
    if call.kind == "Circle" and (call.arc_angle != 0 or call.rotation not in (None, 0)):
        raise HostError(
            "Circle is modelled with arc angle 0 and linear interpolation of the pose only"
        )
    return fmt
