"""The runner: executes any :class:`TaskSequence` with the same shared policies.

What lives here, once, for every sequence: waiting until the robot is ready, stop
requests (checked between states; running waits are interrupted through
``robot.interrupt()`` and the arm is then stopped), retries by the steps' rules,
cycles, one log event per state change with its duration, timing per state and per
cycle, recording which state failed and why, and the reaction to a failure ("stay",
or "retreat" to a safe pose at low speed, never after an e-stop or a robot error).
Polling and timeouts are the robot API's (``Robot(polling=, timeouts=)``).
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
    ProjectPausedError,
    RobotError,
    RobotFaultError,
    StopRequestedError,
    TMMasterError,
)
from .._gripper import GripperStatus, RegisterGripper
from .._logging import get_logger
from .._pose import MotionType, Pose
from .._robot import Motion, Robot
from .._sigint import deferred
from .._status import PROJECT_STOPPED, RobotStatus, project_failure
from ._config import PickPlaceConfig, check_held_input
from ._machine import DONE, ERROR, IDLE, SequenceMachine
from ._plan import validate_plan
from ._runlog import RunLog
from ._sequences import moves_no_arm
from ._steps import Action, PlannedMove, Step, TaskSequence, arm_at, refuse_held_part

_log = get_logger("tmmaster.pickplace")

Reaction = Literal["stay", "retreat"]


@dataclass(frozen=True)
class Failure:
    """Which state failed and why."""

    #: The state that failed.
    state: str
    #: The cycle, 1-based.
    cycle: int
    #: The error's class name (``MotionTimeoutError``...).
    type: str
    #: The error's message.
    message: str
    #: The robot's error code when the failure carries one (robot fault, e-stop).
    error_code: int | None
    #: The error itself.
    exception: BaseException = field(repr=False, compare=False)

    @property
    def interrupted(self) -> bool:
        """True when the run was stopped on request rather than failing."""
        return isinstance(self.exception, StopRequestedError)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (without the exception object).

        Returns:
            ``state``, ``cycle``, ``type``, ``message`` and ``error_code``.
        """
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

    #: The state.
    state: str
    #: The cycle, 1-based.
    cycle: int
    #: Seconds since the run started.
    started_s: float
    #: How long the pass took, s.
    duration_s: float
    #: "ok", "skipped", "retry" or "failed".
    outcome: str


@dataclass(frozen=True)
class ReactionRecord:
    """What was done after a failure."""

    #: ``"stay"`` or ``"retreat"``.
    reaction: Reaction
    #: Whether it was carried out (never a retreat after an e-stop or a robot error).
    performed: bool
    #: What happened, in words.
    detail: str


@dataclass(frozen=True)
class StateEvent:
    """Sent to the ``on_state`` listener at every state change (for live progress)."""

    #: The state entered.
    state: str
    #: The state left.
    previous: str
    #: The current cycle, 1-based.
    cycle: int
    #: How many cycles run.
    cycles: int
    #: Seconds since the current cycle started.
    cycle_elapsed_s: float


@dataclass
class RunResult:
    """The outcome of :meth:`Runner.run`."""

    #: The sequence's name.
    sequence: str
    #: The state the machine ended in: DONE or ERROR.
    state: str
    #: How many cycles were asked for.
    cycles_requested: int
    #: How many cycles finished.
    cycles_completed: int = 0
    #: Finished cycles' durations, s: every one up to 2,000; beyond, the first 1,000 and
    #: the latest 1,000 (``log.cycles`` has the statistics of all of them).
    cycle_times_s: list[float] = field(default_factory=list)
    #: The passes through a state, in order: every one of the first 10 cycles (and IDLE),
    #: the latest 10, and up to 100 others with a retry or a failure (``log`` counts all).
    records: list[StateRecord] = field(default_factory=list)
    #: Why the run failed (None when it did not).
    failure: Failure | None = None
    #: How many retries were used in all.
    retries: int = 0
    #: What was done after the failure (None without one).
    reaction: ReactionRecord | None = None
    #: After a stop request, or a move the master gave up on while the arm ran: whether
    #: a stop was delivered to the robot (None: no stop was needed or possible).
    stop_delivered: bool | None = None
    #: ISO 8601 UTC time the run started.
    started_at: str = ""
    #: How long the run took, s.
    duration_s: float = 0.0
    #: Every pass and cycle counted (per-state statistics), and what was kept of them.
    log: RunLog = field(default_factory=RunLog, repr=False, compare=False)

    @property
    def ok(self) -> bool:
        """True when the machine ended in DONE."""
        return self.state == DONE

    @property
    def interrupted(self) -> bool:
        """True when the run ended because a stop was requested."""
        return self.failure is not None and self.failure.interrupted

    def state_timings(self) -> dict[str, dict[str, Any]]:
        """Per state, over every pass (skipped ones excluded): passes, total, mean, min and
        max seconds, and the passes that were retried or failed.

        Returns:
            ``{state: {"count", "total_s", "mean_s", "min_s", "max_s", "retries",
            "failures"}}``.
        """
        log = self.log
        if not log.passes and self.records:  # a result made without a runner
            log = RunLog()
            for record in self.records:
                log.add(record)
        return log.state_timings()


class _RunContext:
    """The :class:`StepContext` of one run: the robot, the run's position, policy moves."""

    def __init__(self, run: _Run) -> None:
        self._run = run
        self.robot: Robot = run.runner.robot
        #: Free space for a sequence's own state between steps (reset per run).
        self.data: dict[str, Any] = {}
        #: The gripper status of the last gripper action or check.
        self.last_gripper: GripperStatus | None = None

    @property
    def state(self) -> str:
        """The current state."""
        return self._run.machine.state

    @property
    def cycle(self) -> int:
        """The current cycle, from 1."""
        return self._run.machine.cycle

    @property
    def cycles(self) -> int:
        """How many cycles this run makes."""
        return self._run.machine.cycles

    @property
    def last_cycle(self) -> bool:
        """True during the last cycle."""
        return self.cycle >= self.cycles

    @property
    def attempt(self) -> int:
        """1 + the retries already used by the current step in this cycle."""
        machine = self._run.machine
        return 1 + machine.retries_used.get(machine.state, 0)

    @property
    def stop_requested(self) -> bool:
        """True once a stop was requested (long actions should return early)."""
        return self._run.runner.stop_requested

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
        """Open the fingers and wait until they stopped.

        At the start (IDLE: the sequence's ``prepare``) a gripper that reports holding a
        part is not opened unless the runner releases held parts at the start: the run
        fails with :class:`ConfigError` instead (:func:`refuse_held_part`).
        """
        if self.state == IDLE:
            self._run.runner._open_at_start()
        self.last_gripper = self.robot.gripper.open()
        return self.last_gripper

    def close_gripper(self) -> GripperStatus:
        """Close the fingers and wait until they stopped (no check of the object)."""
        self.last_gripper = self.robot.gripper.close()
        return self.last_gripper

    def part_held(self, *, start: bool = False) -> bool | None:
        """Whether the gripper holds a part now (:meth:`Runner.part_held`)."""
        return self._run.runner.part_held(start=start)

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
        """Dwell for ``seconds``; a stop request ends the dwell at once.

        :meth:`Runner.request_stop` (which requests the robot's stop too) and a stop
        requested on the robot (``robot.interrupt()``) end it at once (:meth:`Robot.dwell`).
        """
        try:
            self._run.runner.robot.dwell(seconds)
        except StopRequestedError as exc:
            raise StopRequestedError(f"{exc} during a dwell") from exc


class _Run:
    """Everything one :meth:`Runner.run` call owns: machine, context, result, clocks."""

    def __init__(self, runner: Runner, sequence: TaskSequence, cycles: int, source: str) -> None:
        self.runner = runner
        self.sequence = sequence
        #: Where the sequence comes from, for the messages of the plan's check.
        self.source = source
        # The runner's stop as its checks see it: a Ctrl-C's noted flag, or the request.
        self.machine = SequenceMachine(
            sequence, cycles=cycles, stopped=lambda: runner.stop_requested
        )
        self.ctx = _RunContext(self)
        self.result = RunResult(
            sequence=sequence.name,
            state=IDLE,
            cycles_requested=cycles,
            started_at=datetime.now(UTC).isoformat(timespec="milliseconds"),
        )
        self.started = runner.run_started = time.monotonic()
        self.cycle_started = self.started

    def record(self, state: str, cycle: int, started: float, outcome: str) -> None:
        """Append the record of one pass through ``state``."""
        now = time.monotonic()
        self.result.log.add(
            StateRecord(
                state=state,
                cycle=cycle,
                started_s=round(started - self.started, 4),
                duration_s=round(now - started, 4),
                outcome=outcome,
            )
        )

    def cycle_done(self, cycle: int) -> None:
        """Count a finished cycle and start the clock of the next."""
        elapsed = round(time.monotonic() - self.cycle_started, 4)
        self.result.log.cycle_time(elapsed)
        self.result.cycles_completed += 1
        self.runner._log.info("pickplace.cycle_done", cycle=cycle, cycle_time_s=elapsed)
        self.cycle_started = time.monotonic()


class Runner:
    """Runs sequences on one connected robot with shared policies.

    Readiness, stop requests, retries, cycles, timing, logging and the reaction to a
    failure are the runner's; what each state does is the sequence's.

    Example:
        The article's cycle against the simulator (``python -m tmmaster.sim --port
        5020``):

        ```python
        from tmmaster import connect
        from tmmaster.pickplace import Runner, load_config, pick_and_place

        config = load_config()  # the defaults: the built-in cell
        with connect("127.0.0.1", 5020) as robot:
            result = Runner.from_config(robot, config).run(pick_and_place(config))
        print(result.state, result.cycles_completed)  # DONE 1
        ```

    Args:
        robot: The robot, connected before :meth:`run`.
        error_reaction: After a failure: ``"stay"`` where it stopped, or
            ``"retreat"`` to the sequence's retreat pose (never after an e-stop or a
            robot error).
        ready_timeout_s: The robot must be ready within this time at the start, s.
        on_state: Called with a StateEvent at every state change.
        release_held_part_at_start: When the sequence's ``prepare`` opens the gripper
            and the gripper reports holding a part: True releases it where the arm is
            (logged as ``pickplace.held_part_released``); False (the default) fails the
            run in IDLE with :class:`ConfigError`, nothing moved or opened.
        held_input: The robot's digital input that is high while the gripper holds a
            part (:meth:`part_held`); None: the gripper's own report.
        held_input_module: The module of ``held_input`` (``"end_module"`` by default).

    Raises:
        ConfigError: ``held_input`` is not a DI of that module in the robot's profile.
    """

    def __init__(
        self,
        robot: Robot,
        *,
        error_reaction: Reaction = "stay",
        ready_timeout_s: float = 10.0,
        on_state: Callable[[StateEvent], None] | None = None,
        release_held_part_at_start: bool = False,
        held_input: int | None = None,
        held_input_module: str = "end_module",
    ) -> None:
        if held_input is not None:
            check_held_input(robot.profile, held_input_module, held_input, "held_input")
        #: The robot it runs on.
        self.robot = robot
        #: ``"stay"`` or ``"retreat"`` after a failure.
        self.error_reaction: Reaction = error_reaction
        #: The robot must be ready within this time at the start, s.
        self.ready_timeout_s = ready_timeout_s
        #: Called with a StateEvent at every state change.
        self.on_state = on_state
        #: Release a part the gripper holds when ``prepare`` opens it (else refuse).
        self.release_held_part_at_start = release_held_part_at_start
        #: The DI that tells whether a part is held; None: the gripper's own report.
        self.held_input = held_input
        #: The module of ``held_input``: ``"end_module"`` or ``"control_box"``.
        self.held_input_module = held_input_module
        #: ``time.monotonic()`` when the current or last :meth:`run` started (None before
        #: the first): time 0 of its records, for whatever else is timed beside the run.
        self.run_started: float | None = None
        self._stop = threading.Event()
        self._stop_noted = False  # note_stop(): a Ctrl-C's, before its thread sets _stop
        self._log = _log.bind(robot=robot.name)

    @classmethod
    def from_config(
        cls,
        robot: Robot,
        config: PickPlaceConfig,
        *,
        on_state: Callable[[StateEvent], None] | None = None,
    ) -> Runner:
        """A runner with the configuration's error reaction, readiness timeout,
        ``gripper.release_held_part_at_start`` and ``gripper.held_input``.

        Args:
            robot: The robot (``robot_from_config(config)``).
            config: The configuration.
            on_state: Called with a StateEvent at every state change.

        Returns:
            The runner.
        """
        return cls(
            robot,
            error_reaction=config.on_error.reaction,
            ready_timeout_s=config.timeouts.ready_s,
            on_state=on_state,
            release_held_part_at_start=config.gripper.release_held_part_at_start,
            held_input=config.gripper.held_input,
            held_input_module=config.gripper.held_input_module,
        )

    def part_held(self, *, start: bool = False) -> bool | None:
        """Whether the gripper holds a part now.

        With ``held_input`` the robot's digital input says it, read directly (FC 02): what
        the wire shows now, whatever the gripper's grasp flag last recorded (a part
        slipped out since the close, a flag left at 0 by a stop in the middle of a close,
        registers cleared by a restart). Else the gripper's report
        (:func:`gripper_holds_a_part`).

        Args:
            start: Asked before the start opens the gripper (or starts a pick): then a
                part is held when the input or the gripper's report says so, so that an
                input named wrongly (never high) cannot have a held part dropped.

        Returns:
            Whether a part is held; None when the gripper cannot tell.

        Raises:
            TMMasterError: A read failed.
        """
        if self.held_input is None:
            return gripper_holds_a_part(self.robot)
        held = self.robot.io.di(self.held_input, module=self.held_input_module)
        return held or (start and bool(gripper_holds_a_part(self.robot)))

    @property
    def stop_requested(self) -> bool:
        """True once :meth:`request_stop` or :meth:`note_stop` was called."""
        return self._stop_noted or self._stop.is_set()

    def note_stop(self) -> None:
        """Ask the run to start no further state, at once; :meth:`request_stop` follows.

        Safe in a signal handler, even one that interrupted the main thread inside an
        event's lock: it sets a flag and takes no lock. The state the run is in goes on
        until :meth:`request_stop` interrupts its waits.
        """
        self._stop_noted = True

    def request_stop(self) -> None:
        """Ask the run to stop: checked between states, and running waits give up now.

        Safe from a signal handler or another thread: it only sets two events (a Ctrl-C
        that comes meanwhile is delivered after both are set, never inside an event's lock).
        """
        self._stop_noted = True
        with deferred():
            self._stop.set()
            self.robot.interrupt()

    # -- the run -------------------------------------------------------------

    def run(
        self, sequence: TaskSequence, *, cycles: int | None = None, source: str | None = None
    ) -> RunResult:
        """Run ``cycles`` cycles of ``sequence``; never raises for a robot failure.

        Before its first command the run checks the plan of every cycle it is about to
        run (:func:`validate_plan`, from the pose and joints the robot reports once it is
        ready): a move of a later step, slot or cycle that cannot be sent or taken fails
        the run in IDLE with :class:`ConfigError` (``failure.state == "IDLE"``), nothing
        moved or opened, only reads sent. A ``prepare`` of the user's code (not the
        library's gripper open or held-part check) runs first, as it may move the arm:
        the plan is then checked from where it left the arm. A move known only while the
        run goes (made in a step's code, from ``ctx.data``) is checked when it is sent, as
        every move is. :meth:`request_stop` ends the check (seconds for a long pallet)
        at its next move: the run ends interrupted in IDLE.

        A :class:`~tmmaster.TMMasterError` from a step fails (or retries) it and ends the
        run with a failure; any other exception from a step's code is a bug and is raised.

        A stop requested on the robot (``robot.interrupt()``, from another thread, a
        signal handler or a cancelled awaited call) stands: the run ends interrupted
        without moving until ``robot.clear_stop_request()`` takes it back.

        Args:
            sequence: What to run.
            cycles: How many cycles; None: the sequence's default.
            source: Where the sequence comes from (a file name), for the messages of the
                plan's check; None: ``sequence <name>``.

        Returns:
            The outcome: ``ok`` in DONE, else ``failure`` says where and why.
        """
        count = cycles if cycles is not None else sequence.default_cycles
        earlier = self.robot.last_motion  # an earlier run's: none of this run's business
        run = _Run(self, sequence, count, source or f"sequence {sequence.name}")
        self._log.info("pickplace.run_started", sequence=sequence.name, cycles=count)
        self._start(run)
        while not run.machine.finished:
            self._step(run)
        result = run.result
        result.state = run.machine.state
        if result.failure is not None:
            if result.failure.interrupted:
                result.stop_delivered = self._stop_arm(earlier)
            else:
                motion = self.robot.last_motion
                if motion is not None and motion is not earlier and motion.abandoned:
                    result.stop_delivered = motion.stop_delivered
            before = self.robot.last_motion
            result.reaction = self._react(sequence, result.failure)
            self._note_retreat_stop(result, before)
        result.duration_s = round(time.monotonic() - run.started, 4)
        result.records = result.log.records()
        result.cycle_times_s = result.log.cycle_times()[0]
        self._log.info(
            "pickplace.run_done",
            sequence=sequence.name,
            state=result.state,
            cycles_completed=result.cycles_completed,
            duration_s=result.duration_s,
        )
        return result

    def _start(self, run: _Run) -> None:
        """IDLE: wait until the robot is ready, check the plan, prepare, then enter the
        first step (a ``prepare`` of the user's code first: it may move the arm)."""
        started = time.monotonic()
        try:
            self._check_stop()
            # A stopped or paused TMflow project never gets ready by itself: said at once,
            # with the fix, instead of a wait that ends in "not ready".
            if (failure := project_failure(self.robot.status())) is not None:
                raise failure
            ready, prepare = self.robot.wait_until_ready(self.ready_timeout_s), run.sequence.prepare
            if first := moves_no_arm(prepare):  # checked before it opens the gripper
                self._check_plan(run, ready)
            if prepare is not None:
                self._settled(prepare, run.ctx)
            if not first:  # a prepare of the user's may move the arm: checked from there
                self._check_plan(run, self.robot.wait_until_ready(self.ready_timeout_s))
        except TMMasterError as exc:
            run.record(IDLE, 0, started, "failed")
            self._fail(run, IDLE, self._as_stop(exc, "the preparation"))
            return
        run.record(IDLE, 0, started, "ok")
        if not run.machine.start(run.ctx):
            self._fail(run, IDLE, StopRequestedError("stop requested"))
        else:
            self._changed(run, IDLE, started)

    def _check_plan(self, run: _Run, ready: RobotStatus) -> None:
        """Check every known move of the run from where the ready arm is, before anything
        is commanded: a later step, slot or cycle the arm cannot take is refused here, not
        after the first moves carried a part (ConfigError, reads only sent). A stop
        request ends it at the next move (StopRequestedError)."""
        where = None if ready.joints is None else (ready.pose, ready.joints)
        cycles, source = run.machine.cycles, run.source
        validate_plan(self.robot, run.sequence, cycles, source=source, start=where, stop=self._stop)

    def _step(self, run: _Run) -> None:
        """Run the current state's action, then retry, fail or move on."""
        machine = run.machine
        step = machine.step()
        state, cycle = machine.state, machine.cycle
        started = time.monotonic()
        try:
            outcome = self._act(run, step)
        except TMMasterError as exc:
            self._failed_step(run, step, cycle, started, self._as_stop(exc, state))
            return
        except Exception as exc:
            if step.retry is None or not isinstance(exc, step.retry.on):
                # A bug in the step's code, not a robot failure: let it surface as itself.
                self._log.error("pickplace.step_raised", state=state, error=repr(exc))
                raise
            self._failed_step(run, step, cycle, started, self._as_stop(exc, state))
            return
        run.record(state, cycle, started, outcome)
        self._advance(run, step, state, cycle, started)

    def _act(self, run: _Run, step: Step) -> str:
        """The step's action, unless its skip condition says no; returns the outcome.

        Run through :meth:`_settled`, as ``prepare`` and a retry's ``recover`` are."""
        self._check_stop()
        if step.when is not None and not step.when(run.ctx):
            return "skipped"
        self._settled(step.action, run.ctx)
        return "ok"

    def _settled(self, action: Action, ctx: _RunContext) -> None:
        """Run ``action``; a command it sent and left running is waited for, so it ends
        with its move done, never with the arm still moving into the next step, a gripper
        action, or DONE (``ctx.robot.start_move`` without its wait). An action that raises
        instead gives that command up first (withdrawn, or the arm stopped), as an
        exception escaping a wait does: a failed step's move never runs on."""
        before = self.robot.last_motion
        try:
            action(ctx)
        except BaseException:
            if (motion := _left_running(self.robot, before)) is not None:
                motion.cancel()
            raise
        if (motion := _left_running(self.robot, before)) is not None:
            motion.wait()

    def _failed_step(
        self, run: _Run, step: Step, cycle: int, started: float, exc: BaseException
    ) -> None:
        """Go back by the step's retry rule when it allows, else fail the run."""
        state = step.name
        rule = step.retry
        if (
            rule is None
            or not isinstance(exc, rule.on)
            or self.stop_requested
            or not run.machine.retries_left()
        ):
            run.record(state, cycle, started, "failed")
            self._fail(run, state, exc)
            return
        self._log.warning(
            "pickplace.retry",
            state=state,
            cycle=cycle,
            back_to=rule.back_to,
            attempt=run.ctx.attempt + 1,
            attempts=rule.attempts + 1,
            error=str(exc),
        )
        try:
            if rule.recover is not None:
                self._settled(rule.recover, run.ctx)
        except TMMasterError as recover_exc:  # never tried again: this pass failed the run
            run.record(state, cycle, started, "failed")
            self._fail(run, state, self._as_stop(recover_exc, state))
            return
        run.record(state, cycle, started, "retry")
        run.result.retries += 1
        run.machine.retry(run.ctx)
        self._changed(run, state, started)

    def _advance(self, run: _Run, step: Step, state: str, cycle: int, started: float) -> None:
        """Leave a finished state forward (its guard must hold)."""
        last = run.machine.is_last_step()
        if not run.machine.advance(run.ctx):
            guard = step.guard_name or "guard"
            reason = (
                StopRequestedError("stop requested")
                if self.stop_requested
                else RobotError(f"{state}: guard {guard} does not hold; not moving on")
            )
            self._fail(run, state, reason)
            return
        if last:
            run.cycle_done(cycle)
        self._changed(run, state, started)

    # -- helpers -----------------------------------------------------------------

    def _check_stop(self) -> None:
        if self.stop_requested:
            raise StopRequestedError("stop requested")

    def _open_at_start(self) -> None:
        """Before ``prepare`` opens the gripper: refuse (or, if allowed, announce) the
        release of a part it holds; a gripper that cannot tell is opened as before."""
        held = self.part_held(start=True)
        if held is None:
            self._log.warning(
                "pickplace.held_part_unknown",
                gripper=self.robot.gripper.kind,
                detail="the gripper cannot say whether it holds a part; opening it at the"
                " start as configured",
            )
        elif held and not self.release_held_part_at_start:
            raise refuse_held_part(self.robot, opening=True)
        elif held:
            self._log.warning("pickplace.held_part_released", at=arm_at(self.robot))

    def _as_stop(self, exc: BaseException, during: str) -> BaseException:
        """A failure caused by an interrupted wait is the stop request itself. A fault the
        robot reports is never the stop's doing (a Stop sets no e-stop and no error code:
        article reports its e-stop as code 0x0200): it is reported as it is."""
        faulted = isinstance(exc, EmergencyStopError) or (
            isinstance(exc, RobotFaultError) and bool(exc.error_code)
        )
        if self.stop_requested and not faulted and not isinstance(exc, StopRequestedError):
            return StopRequestedError(f"stop requested during {during}")
        return exc

    def _changed(self, run: _Run, previous: str, started: float) -> None:
        machine = run.machine
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
                    cycle_elapsed_s=now - run.cycle_started,
                )
            )

    def _fail(self, run: _Run, state: str, exc: BaseException) -> None:
        code = getattr(exc, "error_code", None)
        failure = Failure(
            state=state,
            cycle=run.machine.cycle,
            type=type(exc).__name__,
            message=str(exc),
            error_code=code if isinstance(code, int) and code != 0 else None,
            exception=exc,
        )
        run.result.failure = failure
        if failure.interrupted:
            self._log.warning("pickplace.interrupted", state=state, cycle=run.machine.cycle)
        else:
            self._log.error("pickplace.failed", **failure.as_dict())
        started = time.monotonic()
        run.machine.fail(run.ctx)
        self._changed(run, state, started)

    def _stop_arm(self, earlier: Motion | None) -> bool | None:
        """After a stop request: stop the arm; True if delivered, None if it cannot be stopped.

        ``earlier`` is the robot's last motion before the run (not the run's own)."""
        if not self.robot.can_stop:
            return None
        motion = self.robot.last_motion
        if (
            motion is not earlier
            and motion is not None
            and motion.abandoned
            and motion.stop_delivered
        ):
            return True  # the interrupted wait already stopped the arm
        try:
            self.robot.stop()
        except TMMasterError as exc:  # the link may be gone: report, never raise
            self._log.error("pickplace.stop_failed", error=str(exc))
            return False
        return True

    def _note_retreat_stop(self, result: RunResult, before: Motion | None) -> None:
        """After the reaction: a stop requested during it stops the arm, as an interrupted
        run's does; a retreat move the run gave up is the run's own. Either says whether
        the stop was delivered (an undelivered one wins over an earlier delivered stop)."""
        motion = self.robot.last_motion
        if self.stop_requested and result.failure is not None and not result.interrupted:
            delivered = self._stop_arm(before)
        elif motion is not None and motion is not before and motion.abandoned:
            delivered = motion.stop_delivered
        else:
            return
        if result.stop_delivered is None or delivered is False:
            result.stop_delivered = delivered

    def _react(self, sequence: TaskSequence, failure: Failure) -> ReactionRecord:
        """Apply the error reaction; only ever moves a robot that is not in error."""
        reaction = self.error_reaction
        if reaction == "stay":
            return ReactionRecord("stay", False, "configured to stay where it stopped")
        if failure.interrupted or self.stop_requested:
            return ReactionRecord(reaction, False, "stop requested: not moving")
        if failure.state == IDLE:  # the arm is where the run found it, with what it holds
            return ReactionRecord(reaction, False, "the run had not started: not moving")
        if isinstance(failure.exception, EmergencyStopError | RobotFaultError):
            return ReactionRecord(reaction, False, f"{_not_movable(failure.exception)}: never move")
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
        except TMMasterError as exc:
            self._log.error("pickplace.retreat_failed", error=str(exc))
            return ReactionRecord(reaction, False, f"retreat failed: {exc}")
        return ReactionRecord(reaction, True, f"retreated to {target.pose}")


def _not_movable(exc: BaseException) -> str:
    """Why a robot fault forbids the retreat, in words: what the robot is in."""
    if isinstance(exc, EmergencyStopError):
        return "robot in e-stop"
    if isinstance(exc, ProjectPausedError):
        return "the robot's project is paused"
    if str(exc).startswith(PROJECT_STOPPED):
        return "the robot's project is stopped"
    return "robot in error"


def _left_running(robot: Robot, before: Motion | None) -> Motion | None:
    """The command sent since ``before`` that is neither done nor given up, if any."""
    motion = robot.last_motion
    if motion is None or motion is before or motion.done or motion.abandoned:
        return None
    return motion


def gripper_holds_a_part(robot: Robot) -> bool | None:
    """Whether ``robot``'s gripper reports holding a part now (one status read).

    Args:
        robot: The connected robot.

    Returns:
        The gripper's ``holding``; None when it cannot tell: a register gripper on a
        profile without a ``grasp_status`` field.

    Raises:
        TMMasterError: The read failed (ConfigError for a robot without a gripper).
    """
    if isinstance(robot.gripper, RegisterGripper) and not robot.profile.has("grasp_status"):
        return None
    return robot.gripper.status().holding


__all__ = [
    "ERROR",
    "Failure",
    "ReactionRecord",
    "RunResult",
    "Runner",
    "StateEvent",
    "StateRecord",
    "StopRequestedError",
]
