"""The runner: executes any :class:`TaskSequence` with the same shared policies.

What lives here, once, for every sequence: waiting until the robot is ready, stop
requests (checked between states; running waits are interrupted through
``robot.interrupt()`` and the arm is then stopped), retries by the steps' rules,
cycles, one log event per state change with its duration, timing per state and per
cycle, recording which state failed and why, and the reaction to a failure ("stay",
or "retreat" to a safe pose at low speed, never after an e-stop or a robot error).
Polling and timeouts are the robot API's (``Robot(poll_interval_s=, timeouts=)``).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any, Literal

from .._exceptions import (
    EmergencyStopError,
    GraspFailedError,
    RobotError,
    RobotFaultError,
    StopRequestedError,
    TMMasterError,
)
from .._gripper import GripperStatus
from .._logging import get_logger
from .._pose import MotionType, Pose
from .._robot import Robot
from ._machine import DONE, ERROR, IDLE, SequenceMachine
from ._steps import PlannedMove, TaskSequence

_log = get_logger("tmmaster.pickplace")

Reaction = Literal["stay", "retreat"]


@dataclass(frozen=True)
class Failure:
    """Which state failed and why."""

    state: str
    cycle: int
    type: str
    message: str
    #: The robot's error code when the failure carries one (robot fault, e-stop).
    error_code: int | None
    exception: BaseException = field(repr=False, compare=False)

    @property
    def interrupted(self) -> bool:
        """True when the run was stopped on request rather than failing."""
        return isinstance(self.exception, StopRequestedError)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (without the exception object)."""
        return {
            "state": self.state,
            "cycle": self.cycle,
            "type": self.type,
            "message": self.message,
            "error_code": self.error_code,
        }


@dataclass(frozen=True)
class StateRecord:
    """One pass through a state."""

    state: str
    cycle: int
    #: Seconds since the run started.
    started_s: float
    duration_s: float
    #: "ok", "skipped", "retry" or "failed".
    outcome: str


@dataclass(frozen=True)
class ReactionRecord:
    """What was done after a failure."""

    reaction: Reaction
    performed: bool
    detail: str


@dataclass(frozen=True)
class StateEvent:
    """Sent to the ``on_state`` listener at every state change (for live progress)."""

    state: str
    previous: str
    cycle: int
    cycles: int
    #: Seconds since the current cycle started.
    cycle_elapsed_s: float


@dataclass
class RunResult:
    """The outcome of :meth:`Runner.run`."""

    sequence: str
    state: str
    cycles_requested: int
    cycles_completed: int = 0
    cycle_times_s: list[float] = field(default_factory=list)
    records: list[StateRecord] = field(default_factory=list)
    failure: Failure | None = None
    retries: int = 0
    reaction: ReactionRecord | None = None
    #: After a stop request, or a move the master gave up on while the arm ran: whether
    #: a stop was delivered to the robot (None: no stop was needed or possible).
    stop_delivered: bool | None = None
    started_at: str = ""
    duration_s: float = 0.0

    @property
    def ok(self) -> bool:
        """True when the machine ended in DONE."""
        return self.state == DONE

    @property
    def interrupted(self) -> bool:
        """True when the run ended because a stop was requested."""
        return self.failure is not None and self.failure.interrupted

    def state_timings(self) -> dict[str, dict[str, float]]:
        """Per state: passes, total, mean and max seconds (skipped passes excluded)."""
        timings: dict[str, dict[str, float]] = {}
        for record in self.records:
            if record.outcome == "skipped":
                continue
            entry = timings.setdefault(
                record.state, {"count": 0, "total_s": 0.0, "mean_s": 0.0, "max_s": 0.0}
            )
            entry["count"] += 1
            entry["total_s"] += record.duration_s
            entry["max_s"] = max(entry["max_s"], record.duration_s)
        for entry in timings.values():
            entry["mean_s"] = entry["total_s"] / entry["count"]
            for key in ("total_s", "mean_s", "max_s"):
                entry[key] = round(entry[key], 4)
        return timings


class StepContext:
    """What a step's action may use: the robot, the cycle, and moves that obey the policies."""

    def __init__(self, runner: Runner, machine: SequenceMachine) -> None:
        self.runner = runner
        self.robot = runner.robot
        self._machine = machine
        #: Free space for a sequence's own state between steps (reset per run).
        self.data: dict[str, Any] = {}
        #: The gripper status of the last gripper action or check.
        self.last_gripper: GripperStatus | None = None

    @property
    def state(self) -> str:
        """The current state."""
        return self._machine.state

    @property
    def cycle(self) -> int:
        """The current cycle, from 1."""
        return self._machine.cycle

    @property
    def cycles(self) -> int:
        """How many cycles this run makes."""
        return self._machine.cycles

    @property
    def last_cycle(self) -> bool:
        """True during the last cycle."""
        return self._machine.cycle >= self._machine.cycles

    @property
    def attempt(self) -> int:
        """1 + the retries already used by the current step in this cycle."""
        return 1 + self._machine.retries_used.get(self._machine.state, 0)

    @property
    def stop_requested(self) -> bool:
        """True once a stop was requested (long actions should return early)."""
        return self.runner.stop_requested

    def move(
        self,
        pose: Pose,
        *,
        speed: int,
        motion: MotionType | Literal["ptp", "line"] = MotionType.PTP,
    ) -> None:
        """Move and wait until the robot acknowledged and finished (robot API timeouts)."""
        self.robot.move_to(pose, speed=speed, motion=motion)

    def move_planned(self, planned: PlannedMove) -> None:
        """Make a :class:`PlannedMove`."""
        self.move(planned.pose, speed=planned.speed, motion=planned.motion)

    def open_gripper(self) -> GripperStatus:
        """Open the fingers and wait until they stopped."""
        self.last_gripper = self.robot.gripper.open()
        return self.last_gripper

    def close_gripper(self) -> GripperStatus:
        """Close the fingers and wait until they stopped (no check of the object)."""
        self.last_gripper = self.robot.gripper.close()
        return self.last_gripper

    def check_holding(self, expected: bool = True) -> GripperStatus:
        """Read the gripper; raise :class:`GraspFailedError` unless holding == ``expected``."""
        status = self.robot.gripper.status()
        self.last_gripper = status
        if status.holding != expected:
            what = "no object detected" if expected else "an object is still detected"
            raise GraspFailedError(f"{self.state}: {what} (attempt {self.attempt})")
        return status

    def grip(self) -> GripperStatus:
        """Close and require an object (raises :class:`GraspFailedError`)."""
        self.close_gripper()
        return self.check_holding(True)

    def wait(self, seconds: float) -> None:
        """Dwell for ``seconds``; a stop request ends the dwell at once."""
        if self.runner._stop.wait(seconds):
            raise StopRequestedError("stop requested during a dwell")


class Runner:
    """Runs sequences on one connected robot with shared policies."""

    def __init__(
        self,
        robot: Robot,
        *,
        error_reaction: Reaction = "stay",
        ready_timeout_s: float = 10.0,
        on_state: Callable[[StateEvent], None] | None = None,
    ) -> None:
        self.robot = robot
        self.error_reaction: Reaction = error_reaction
        self.ready_timeout_s = ready_timeout_s
        self.on_state = on_state
        self._stop = threading.Event()
        self._log = _log.bind(robot=robot.name)

    @property
    def stop_requested(self) -> bool:
        """True once :meth:`request_stop` was called."""
        return self._stop.is_set()

    def request_stop(self) -> None:
        """Ask the run to stop: checked between states, and running waits give up now.

        Safe from a signal handler or another thread: it only sets two events.
        """
        self._stop.set()
        self.robot.interrupt()

    # -- the run -------------------------------------------------------------

    def run(self, sequence: TaskSequence, *, cycles: int | None = None) -> RunResult:
        """Run ``cycles`` cycles of ``sequence``; never raises for a robot failure."""
        count = cycles if cycles is not None else sequence.default_cycles
        ctx_holder: list[StepContext] = []
        machine = SequenceMachine(
            sequence, cycles=count, stop_event=self._stop, guard_context=lambda: ctx_holder[0]
        )
        ctx = StepContext(self, machine)
        ctx_holder.append(ctx)
        result = RunResult(
            sequence=sequence.name,
            state=IDLE,
            cycles_requested=count,
            started_at=datetime.now(UTC).isoformat(timespec="milliseconds"),
        )
        t0 = time.monotonic()
        self._run_start = t0
        self._cycle_start = t0
        if not self._stop.is_set():
            self.robot.clear_stop_request()
        self._log.info("pickplace.run_started", sequence=sequence.name, cycles=count)

        state_start = time.monotonic()
        try:
            self._check_stop()
            self.robot.wait_until_ready(self.ready_timeout_s)
            if sequence.prepare is not None:
                sequence.prepare(ctx)
        except Exception as exc:
            if self._stop.is_set() and not isinstance(exc, StopRequestedError):
                # The preparation failed because its wait was interrupted: that is the stop.
                exc = StopRequestedError("stop requested during the preparation")
            self._record(result, IDLE, 0, state_start, "failed")
            self._fail(machine, result, IDLE, exc)
        else:
            self._record(result, IDLE, 0, state_start, "ok")
            if not machine.start():
                self._fail(machine, result, IDLE, StopRequestedError("stop requested"))
            else:
                self._changed(machine, IDLE, state_start)
        while not machine.finished:
            self._step(machine, ctx, result)

        result.state = machine.state
        if result.failure is not None:
            if result.failure.interrupted:
                result.stop_delivered = self._stop_arm()
            else:
                motion = self.robot.last_motion
                if motion is not None and motion.abandoned:
                    result.stop_delivered = motion.stop_delivered
            result.reaction = self._react(sequence, result.failure)
        result.duration_s = round(time.monotonic() - t0, 4)
        self._log.info(
            "pickplace.run_done",
            sequence=sequence.name,
            state=result.state,
            cycles_completed=result.cycles_completed,
            duration_s=result.duration_s,
        )
        return result

    def _step(self, machine: SequenceMachine, ctx: StepContext, result: RunResult) -> None:
        step = machine.step()
        state, cycle = machine.state, machine.cycle
        started = time.monotonic()
        try:
            self._check_stop()
            if step.when is not None and not step.when(ctx):
                outcome = "skipped"
            else:
                step.action(ctx)
                outcome = "ok"
        except Exception as exc:
            if self._stop.is_set() and not isinstance(exc, StopRequestedError):
                # The action failed because its wait was interrupted: that is the stop.
                exc = StopRequestedError(f"stop requested during {state}")
            rule = step.retry
            if (
                rule is not None
                and isinstance(exc, rule.on)
                and not self._stop.is_set()
                and machine.retries_left()
            ):
                self._record(result, state, cycle, started, "retry")
                self._log.warning(
                    "pickplace.retry",
                    state=state,
                    cycle=cycle,
                    back_to=rule.back_to,
                    attempt=ctx.attempt + 1,
                    attempts=rule.attempts + 1,
                    error=str(exc),
                )
                try:
                    if rule.recover is not None:
                        rule.recover(ctx)
                except Exception as recover_exc:
                    self._fail(machine, result, state, recover_exc)
                    return
                result.retries += 1
                machine.retry()
                self._changed(machine, state, started)
                return
            self._record(result, state, cycle, started, "failed")
            self._fail(machine, result, state, exc)
            return
        self._record(result, state, cycle, started, outcome)
        last = machine.is_last_step()
        if not machine.advance():
            guard = step.guard_name or "guard"
            reason = (
                StopRequestedError("stop requested")
                if self._stop.is_set()
                else RobotError(f"{state}: guard {guard} does not hold; not moving on")
            )
            self._fail(machine, result, state, reason)
            return
        if last:
            elapsed = round(time.monotonic() - self._cycle_start, 4)
            result.cycle_times_s.append(elapsed)
            result.cycles_completed += 1
            self._log.info("pickplace.cycle_done", cycle=cycle, cycle_time_s=elapsed)
            self._cycle_start = time.monotonic()
        self._changed(machine, state, started)

    # -- helpers -----------------------------------------------------------------

    def _check_stop(self) -> None:
        if self._stop.is_set():
            raise StopRequestedError("stop requested")

    def _record(
        self, result: RunResult, state: str, cycle: int, started: float, outcome: str
    ) -> None:
        now = time.monotonic()
        result.records.append(
            StateRecord(
                state=state,
                cycle=cycle,
                started_s=round(started - self._run_start, 4),
                duration_s=round(now - started, 4),
                outcome=outcome,
            )
        )

    def _changed(self, machine: SequenceMachine, previous: str, started: float) -> None:
        now = time.monotonic()
        self._log.info(
            "pickplace.state",
            state=machine.state,
            previous=previous,
            previous_s=round(now - started, 4),
            cycle=machine.cycle,
            cycles=machine.cycles,
        )
        if self.on_state is not None:
            self.on_state(
                StateEvent(
                    state=machine.state,
                    previous=previous,
                    cycle=machine.cycle,
                    cycles=machine.cycles,
                    cycle_elapsed_s=now - self._cycle_start,
                )
            )

    def _fail(
        self, machine: SequenceMachine, result: RunResult, state: str, exc: BaseException
    ) -> None:
        code = getattr(exc, "error_code", None)
        failure = Failure(
            state=state,
            cycle=machine.cycle,
            type=type(exc).__name__,
            message=str(exc),
            error_code=code if isinstance(code, int) and code != 0 else None,
            exception=exc,
        )
        result.failure = failure
        if failure.interrupted:
            self._log.warning("pickplace.interrupted", state=state, cycle=machine.cycle)
        else:
            self._log.error("pickplace.failed", **failure.as_dict())
        started = time.monotonic()
        machine.fail()
        self._changed(machine, state, started)

    def _stop_arm(self) -> bool | None:
        """After a stop request: stop the arm; True if delivered, None if it cannot be stopped."""
        if not self.robot.can_stop:
            return None
        motion = self.robot.last_motion
        if motion is not None and motion.abandoned and motion.stop_delivered:
            return True  # the interrupted wait already stopped the arm
        try:
            self.robot.stop()
        except TMMasterError as exc:  # the link may be gone: report, never raise
            self._log.error("pickplace.stop_failed", error=str(exc))
            return False
        return True

    def _react(self, sequence: TaskSequence, failure: Failure) -> ReactionRecord:
        """Apply the error reaction; only ever moves a robot that is not in error."""
        reaction = self.error_reaction
        if reaction == "stay":
            return ReactionRecord("stay", False, "configured to stay where it stopped")
        if failure.interrupted:
            return ReactionRecord(reaction, False, "stop requested: not moving")
        if isinstance(failure.exception, EmergencyStopError | RobotFaultError):
            return ReactionRecord(reaction, False, "robot in error or e-stop: never move")
        if sequence.retreat is None:
            return ReactionRecord(reaction, False, "the sequence defines no retreat pose")
        target = sequence.retreat
        try:
            status = self.robot.status()
            if status.error or status.estop:
                return ReactionRecord(reaction, False, f"robot not movable: {status}")
            self.robot.wait_until_ready(self.ready_timeout_s)
            here = self.robot.pose()
            self._log.warning("pickplace.retreat", target=target.pose.as_list(), speed=target.speed)
            # Straight up first (Line), so the retreat never drags a part sideways.
            if here.z < target.pose.z - self.robot.position_tolerance_mm:
                up = Pose(here.x, here.y, target.pose.z, here.rx, here.ry, here.rz)
                self.robot.move_to(up, speed=target.speed, motion=MotionType.LINE)
            self.robot.move_to(target.pose, speed=target.speed, motion=target.motion)
        except Exception as exc:
            self._log.error("pickplace.retreat_failed", error=str(exc))
            return ReactionRecord(reaction, False, f"retreat failed: {exc}")
        return ReactionRecord(reaction, True, f"retreated to {target.pose}")


__all__ = [
    "ERROR",
    "Failure",
    "ReactionRecord",
    "RunResult",
    "Runner",
    "StateEvent",
    "StateRecord",
    "StepContext",
    "StopRequestedError",
]
