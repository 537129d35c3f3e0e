"""A TMflow project on the simulated robot: its states and buttons, whatever it runs.

The robot a :class:`tmmaster._channels.SequenceChannel` talks to is a TM controller
running a project; what the project does (the sequence handshake) is the robot program,
interpreted (:mod:`._script_project`). This base is the project's life around it, as
TMflow models it: Running (7202), Paused (7204), Stopped; the Play/Pause and Stop
coils; the project started once the robot is initialised; a robot error (the code kept
in ``last_error_code``) stopping it, or an e-stop pausing it with Resumption Behavior
on; Play resuming a paused project and the move it interrupted. The rules are
documented in ``docs/simulator-model.md``.
"""

from __future__ import annotations

import dataclasses
from abc import abstractmethod
from typing import Any

from .._registers import RobotProfile
from ._bank import RegisterBank, digital_io_areas
from ._controller import MoveArgs, RobotController, SimErrorCode, _Active
from ._tm_table import tm_table_areas, tm_table_fields

#: How long the running move takes to follow a change of the project speed from 0 to 100 %
#: (s): the arm model's acceleration time (an assumption: the manual gives none), so that
#: a physics backend's servos see no jump in the reference's speed.
_SPEED_CHANGE_S = 0.2


class SequenceController(RobotController):
    """A TMflow project's states and buttons (the project itself: a subclass)."""

    _error_code_field = "last_error_code"
    #: The TMflow project runs (started once initialised, by Play, stopped by an error).
    _running = False
    #: Paused (Pause button, or an e-stop with resumption on): Play resumes the move.
    _paused = False
    #: Simulated time when the project last started.
    _project_started_s = 0.0

    def __init__(
        self,
        *args: Any,
        resume_after_error: bool = False,
        project_speed: int = 100,
        **options: Any,
    ) -> None:
        #: The project speed the project starts with, % (Techman's 7101): every move runs
        #: at its speed times the project speed the register holds, as it is now.
        self._project_speed = project_speed
        #: The project speed the running move started at, and the one it runs at now, %.
        self._move_percent = self._percent_now = 100.0
        #: TMflow's Motion Settings > Resumption Behavior, "continue project execution from
        #: the error position" (TMflow 2.24 manual, Table 5, pp. 53-54; p. 112): an e-stop
        #: pauses the project instead of stopping it, and Play resumes the interrupted move.
        self._resume_after_error = resume_after_error
        #: The move a pause or a resumable stop interrupted, restarted by Play.
        self._interrupted: MoveArgs | None = None
        self._motion_args: MoveArgs | None = None
        self._pausing_on_error = False
        super().__init__(*args, **options)
        #: The tables of the Stop and Play/Pause coils, and their change counts when the
        #: buttons were last released, summed (see :meth:`_handle_buttons`).
        self._button_tables = tuple(
            {
                self._bank.field(n).table
                for n in ("stop_project", "play_pause")
                if self._profile.has(n)
            }
        )
        self._buttons_released: int | None = None
        #: The bank's network writes when the buttons were last released: a coil written
        #: since has that write's number (RegisterBank.last_write) as its press's order.
        self._released_writes = 0
        #: The order of a Play pressed on the pendant (press_play()) since the buttons were
        #: released: after the writes received before it, before any received later.
        self._pendant_play_at: float | None = None
        #: A Play pressed on the stopped project while its arm still brakes (a Stop's):
        #: the project starts once the arm is at rest (see :meth:`_press_play_pause`).
        self._start_at_rest = False

    def tick(self, dt: float) -> None:
        """One tick, the running move at the project speed as it is now: TMflow applies a
        change the operator makes while the arm moves (the Robot Stick's + and -: TMflow
        2.24, 4.5 table 4, p. 53; "while the robot is running", 5.5.4.3 G) to the move,
        its time running at the new speed over the one it started at (a backend without
        ``scale_time`` keeps each move at the speed it started with)."""
        scale_time = getattr(self._backend, "scale_time", None)  # optional in a backend
        if scale_time is not None and self._profile.has("project_speed"):
            change = float(self._bank.get("project_speed")) - self._percent_now
            most = dt * 100.0 / _SPEED_CHANGE_S
            self._percent_now += max(-most, min(most, change))
            scale_time(max(self._percent_now, 1.0) / max(self._move_percent, 1.0))
        super().tick(dt)

    def _backend_start(self, move: MoveArgs) -> float:
        """TMflow runs a move at its speed times the project speed (7101), as it is now."""
        percent = self._bank.get("project_speed") if self._profile.has("project_speed") else 100
        self._move_percent = self._percent_now = float(percent)
        if percent != 100:
            move = dataclasses.replace(move, speed=move.speed * float(percent) / 100.0)
        return super()._backend_start(move)

    @property
    def project_paused(self) -> bool:
        """The project is paused: Play resumes it (and the move it interrupted)."""
        return self._paused

    @classmethod
    def bank_for(cls, profile: RobotProfile) -> RegisterBank:
        """A TM controller's memory: the profile, Techman's fixed table and its raw areas
        (and the profile's digital I/O, where the table does not serve it)."""
        return RegisterBank(
            profile,
            extra_fields=tm_table_fields(profile),
            raw_areas=(*tm_table_areas(), *digital_io_areas(profile)),
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
            self._bank.set("project_speed", self._project_speed)
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

    def _handle_buttons(self) -> None:
        # A button is pressed by a write: while no word of the buttons' tables changed
        # since they were released (both read 0 then), none is pressed.
        if self._start_at_rest and self._backend.is_settled():
            self._start_at_rest = False
            self._start_project()
        if self._buttons_released == self._buttons_mark():
            return
        self._press_buttons()
        self._buttons_released = self._buttons_mark()

    def _buttons_mark(self) -> int:
        return self._bank.changes_in(self._button_tables)

    def press_play(self) -> None:
        """Press Play on the pendant: acted on at the next tick, after any press written
        before it that waits there (a Stop pressed during an error, acted on first), and
        before one written after it."""
        super().press_play()
        if self._profile.has("play_pause") and self._pendant_play_at is None:
            self._pendant_play_at = self._bank.network_writes + 0.5

    def _pressed_at(self, name: str) -> float:
        """When button ``name`` was pressed, as an order: its network write since the
        buttons were released, else the pendant's Play (press_play()), else a press set on
        the robot's side (a test's pendant): after every write."""
        written = self._bank.last_write(name)
        if written > self._released_writes:
            return written
        if name == "play_pause" and self._pendant_play_at is not None:
            return self._pendant_play_at
        return float("inf")

    def _press_buttons(self) -> None:
        # Coils are buttons: act on each press in the order written, as TMflow takes each
        # as received (a Pause, then a Stop within one tick: paused, then stopped; a Stop,
        # then a Play/Pause landing late: the project starts over), then release them like
        # a spring would. The pendant's Play (press_play()) comes after the presses
        # written before it.
        pressed = [
            name
            for name in ("stop_project", "play_pause")
            if self._profile.has(name) and self._bank.get(name)
        ]
        order = sorted(pressed, key=self._pressed_at)
        self._released_writes = self._bank.network_writes
        self._pendant_play_at = None
        for name in order:
            self._bank.set(name, False)
            if name == "stop_project":
                self._press_stop()
            else:
                self._press_play_pause()

    def _press_stop(self) -> None:
        self._start_at_rest = False  # a Play waiting for the arm to rest is taken back
        if self._running:
            self._log.info("sim.button", device=self._name, button="stop")
            self._stop_project("stop button")

    def _press_play_pause(self) -> None:
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
        elif self._backend.is_settled():
            self._log.info("sim.button", device=self._name, button="play_pause")
            self._start_project()
        else:
            # Assumed, not measured on a TM5: TMflow starts a project only once the arm a
            # Stop brakes is at rest. Started at once, the program's start-up ChangeTCP()
            # would fail on the moving arm and leave the robot in error.
            self._log.info("sim.button", device=self._name, button="play_pause", at_rest=False)
            self._start_at_rest = True

    def _gripper_started(self, number: int, seq: int, *, close: bool, miss: bool) -> None:
        self._active = _Active(
            "gripper",
            number,
            seq=seq,
            closing=close,
            miss=miss,
            record=self._records_made - 1,
        )

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
        self._start_at_rest = False  # an error takes a waiting Play back, as it takes Play
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

    @abstractmethod
    def _start_project(self) -> None:
        """Start the project from the beginning (Play on a stopped project, initialised)."""

    def _stop_project(self, reason: str) -> None:
        self._running = False
        self._stop_motion()
        self._active = None
        self._interrupted = None
        self._set_paused(False, reason)
        self._bank.set("project_running", False)
        self._log.warning("sim.project_stopped", device=self._name, reason=reason)

    def _running_move(self) -> MoveArgs | None:
        """The move being executed now (what a pause interrupts), if any."""
        active = self._active
        args = self._motion_args
        if active is None or active.kind != "motion" or args is None or args.seq != active.seq:
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
            self._start_move(interrupted.resumed(self._backend.tcp_pose()))
