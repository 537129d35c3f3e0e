"""The TMflow project's state and its Play and Pause buttons, pressed only when asked.

TMflow runs the robot program as a project. Techman's table reports its state (7201
error, 7202 running, 7204 paused, 7208 e-stop: FC 02, TMflow 2.24 appendix C, pp.
305-306) and takes the Robot Stick's buttons as coils: 7104 Play/Pause, "triggered as
1 received (toggle)", and 7105 Stop (FC 05, p. 313). Only in Auto mode (a Modbus Play
"cannot be written to when the robot is in Manual Mode", 12.1, p. 219), with the Robot
Stick disabled (remote control) or a fieldbus active, and in Auto mode only while the
AUT.P input is high (appendix C, note, p. 314).

:class:`ProjectControl` reads the state, then presses the toggle only when it does what
was asked (Play on a stopped or paused project, Pause on a running one), through the
robot's command gate: a stop request or ``close()`` refuses the press. Nothing here
runs unless a caller asks: no method of the library presses Play on its own.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any

from ._channels import STOP_SHOWS_BY, CommandChannel, Ticket
from ._checks import require_positive
from ._exceptions import ConfigError, RobotError, TMMasterError
from ._gate import CommandGate
from ._io import SETTLED_FAILURES
from ._poller import Poller
from ._registers import RobotProfile
from ._sigint import deferred
from ._status import ProjectState, RobotStatus
from ._transport import Transport

#: How long ``play()`` and ``pause()`` wait for the project to show the new state, s.
PRESS_TIMEOUT_S = 5.0
#: How long a pause seen must hold, s: a Play/Pause press crossing ours (the pendant's)
#: acts a few robot ticks after its answer, and may resume what showed paused.
PAUSE_SETTLE_S = 0.1

#: A status read and the project's state in it.
_Read = tuple[RobotStatus, ProjectState]

#: What TMflow needs before it takes Play over Modbus (TMflow 2.24 manual).
REMOTE_PLAY_NEEDS = (
    "TMflow takes Play over Modbus only in Auto mode, with the Robot Stick disabled"
    " (remote control) and the AUT.P input high (TMflow 2.24 appendix C, p. 314)"
)


@dataclass(frozen=True)
class ProjectControl:
    """Reads a TMflow project's state and presses Play or Pause (coil 7104) when asked.

    Args:
        profile: The robot's register map (``play_pause`` and ``project_running``).
        transport: The robot's link.
        channel: Reads the status snapshots.
        gate: The robot's command gate: a stop request or close() refuses a press.
        stop_event: The robot's stop request (ends a wait for the new state).
        log: The robot's bound logger.
    """

    _profile: RobotProfile
    _transport: Transport
    _channel: CommandChannel
    _gate: CommandGate
    _stop_event: threading.Event
    _log: Any

    def _require(self, what: str) -> None:
        """ConfigError for a profile without a TMflow project (the article's)."""
        if not (self._profile.has("play_pause") and self._profile.has("project_running")):
            raise ConfigError(
                f"{what}: profile {self._profile.name!r} has no TMflow project (no Play/Pause"
                " coil, no project state): its robot takes commands once initialised;"
                " robot.stop() stops the arm"
            )

    def _status(self) -> _Read:
        status = self._channel.read_status()
        assert status.project is not None  # _require: the profile has project_running
        return status, status.project

    def state(self) -> ProjectState:
        """The project's state now (one status read).

        Returns:
            RUNNING, PAUSED, STOPPED or ERROR (robot error or e-stop).

        Raises:
            ConfigError: The profile has no TMflow project.
            TransportError: The read failed.
        """
        self._require("project_state()")
        return self._status()[1]

    def play(self, timeout_s: float, poll_interval_s: float, own: Ticket | None) -> ProjectState:
        """Press Play on a stopped or paused project; wait until it runs.

        A paused command other than ``own`` is never resumed: another master's (one that
        died within its heartbeat's time-to-live, or one numbered as ``own`` after a
        controller restart put the numbers back at 0), or one this master gave up.

        Args:
            timeout_s: How long to wait for the project to run after the press, s.
            poll_interval_s: Seconds between two status reads.
            own: The command this master still follows, if any.

        Returns:
            RUNNING (also when it was running already: nothing pressed).

        Raises:
            ConfigError: The profile has no project, or a bad ``timeout_s``.
            RobotFaultError: The robot is in error (EmergencyStopError: e-stop): reset it
                on the robot first; nothing pressed.
            RobotError: Manual mode, or a paused command not ``own`` (nothing pressed), or
                the project did not run within ``timeout_s`` of the press (the
                remote-control settings), or a Stop of this process's did not show within
                ``timeout_s`` (:meth:`_before_press`).
            StopRequestedError: A stop was requested or the robot is closing.
            TransportError: The link failed.
        """
        status, state = before = self._before_press("play()", timeout_s, poll_interval_s)
        if state is ProjectState.RUNNING:
            self._log.info("robot.play_skipped", reason="the project runs already")
            return state
        if state is ProjectState.PAUSED and (held := self._held(status, own)) is not None:
            raise RobotError(
                f"play(): paused command {held} is another master's, or given up: press Stop"
            )
        mode = status.raw.get("ma_mode")
        if mode is not None and self._profile.field("ma_mode").label(int(mode)) == "manual":
            raise RobotError(
                "play(): the robot is in Manual mode, where TMflow refuses Play over Modbus"
                " (TMflow 2.24, 12.1, p. 219): switch it to Auto mode on the robot",
                pose=status.pose,
            )
        return self._wait_for(ProjectState.RUNNING, before, timeout_s, poll_interval_s, "play")

    def pause(self, timeout_s: float, poll_interval_s: float) -> ProjectState:
        """Press Pause on a running project; wait until it shows paused.

        Args:
            timeout_s: How long to wait for the project to pause after the press, s.
            poll_interval_s: Seconds between two status reads.

        Returns:
            PAUSED, or STOPPED when it was stopped (nothing pressed: the Play/Pause
            toggle would start it) or stopped during the wait (held 0.1 s).

        Raises:
            ConfigError: The profile has no project, or a bad ``timeout_s``.
            RobotFaultError: The robot is in error (EmergencyStopError: e-stop).
            RobotError: The project did not pause within ``timeout_s`` of the press, or
                ran again after it paused or stopped, or as a new start (Stop pressed), or
                a Stop of this process's did not show within ``timeout_s``.
            StopRequestedError: A stop was requested or the robot is closing.
            TransportError: The link failed.
        """
        before = self._before_press("pause()", timeout_s, poll_interval_s)
        if (state := before[1]) is not ProjectState.RUNNING:
            self._log.info("robot.pause_skipped", reason=f"the project is {state.value}")
            return state
        return self._wait_for(ProjectState.PAUSED, before, timeout_s, poll_interval_s, "pause")

    def _held(self, status: RobotStatus, own: Ticket | None) -> int | None:
        """The number of the command the robot program holds taken (busy), or the one it
        takes at Play: written, not taken yet (``seq == ack_seq + 1``: a block that landed
        while the project was paused, perhaps a dead master's), if it says. A pending
        cancel record counts too: Stop, not Play, then ends it all. None for ``own``: its
        number, in the program's start (boot_id) it was written in."""
        if "ack_seq" not in status.raw:  # no robot program's handshake in this profile
            return None
        ack, p, boot = int(status.raw["ack_seq"]), self._profile, status.raw.get("boot_id", 0)
        seq = ack if status.moving else int(self._channel.read((p.field("seq"),))["seq"])
        mine = own is not None and (own.seq, own.extra.get("boot", 0)) == (seq, boot)
        return seq if (status.moving or seq == p.next_seq(ack)) and not mine else None

    def _before_press(self, what: str, timeout_s: float, interval: float) -> _Read:
        """The status a press starts from; refused without a project, for a bad
        ``timeout_s``, or while the robot is in error or e-stop (a running project never
        is: its state would be ERROR). Within ``STOP_SHOWS_S`` of a Stop this master wrote,
        a project not shown stopped is waited for (up to ``timeout_s``): a toggle decided
        on the running project would land after it, on the stopped one, where it is Play.
        So is one an earlier Robot of this process wrote (its ``close()``): kept per robot
        address. Not for a project started anew since a Stop this master pressed on giving
        up a press (``boot_id``): the Stop showed and was undone, the press that landed late
        starting the project over."""
        self._require(what)
        require_positive("timeout_s", timeout_s)
        status, state = self._status()
        if (failure := self._channel.status_failure(status)) is not None:
            why = f"{what}: {failure}: reset it on the robot first"
            raise type(failure)(why, error_code=failure.error_code, pose=failure.pose)
        by, boot = STOP_SHOWS_BY.get(self._transport.endpoint, (0.0, None))  # any Robot's
        by = by if boot in (None, status.raw.get("boot_id")) else 0.0  # a new start: shown
        if state is not ProjectState.STOPPED and time.monotonic() < by:
            state = self._wait_for(ProjectState.STOPPED, (status, state), timeout_s, interval)
        return status, state

    def _press(self, button: str, state: ProjectState) -> None:
        """Press the Play/Pause toggle once, through the gate (never written twice).

        Called inside :meth:`_wait_for`'s guard: a press whose answer never came, or
        whose caller gives up at any moment after it was sent (a Ctrl-C as it is logged),
        may still land, later, on a project paused meanwhile (by the operator, an e-stop
        with resumption on), where the toggle is Play: so before the error reaches the
        caller the Stop button is pressed (retried). The project ends; a press that lands
        after it starts it from the beginning, where the start-up rule runs nothing
        pending.
        """
        if button:  # empty: a wait with nothing to press
            field = self._profile.field("play_pause")

            def send() -> None:
                # Sent once: a repeated toggle would undo the press.
                self._transport.write_fields([(field, True)], retry=False, interruptible=False)

            STOP_SHOWS_BY.pop(self._transport.endpoint, None)  # seen: _before_press waited
            self._gate.write(None, send)  # a press registers no command
            self._log.warning("robot.project_button", button=button, project=state.value)

    def _stop_before_giving_up(self, why: str, press: str, exc: BaseException, boot: Any) -> None:
        """Press Stop (retried, best effort): a press that may still land later then never
        resumes a move; it starts the project from the beginning, running nothing pending.
        ``press``: the button pressed whose answer was never seen, logged
        ``robot.project_button_unanswered`` once the Stop went (docs/safety.md). ``boot``:
        the program's start the press was decided in; a new start since shows the Stop.
        Held back from a second Ctrl-C, as a withdraw or a stop is (``_sigint.deferred``):
        cut short, the press landing later would resume the move given up."""
        with deferred():
            try:
                self._channel.stop(boot)
            except TMMasterError as failed:
                self._log.error("robot.stop_failed", reason=why, error=str(failed))
            if press:
                self._log.error("robot.project_button_unanswered", button=press, error=str(exc))

    def _wait_for(
        self, wanted: ProjectState, was: _Read, timeout_s: float, dt: float, press: str = ""
    ) -> ProjectState:
        """Press ``press`` (if any), then wait for ``wanted``; on any failure after the
        press may be on its way, press Stop first."""
        settled: float | None = None  # when a pause seen is trusted
        boot = was[0].raw.get("boot_id")  # the program's start the press is decided in
        try:  # until its answer came, ``press`` names the button pressed
            self._press(press, was[1])
            press = ""  # answered: a failure from here on is the wait's
            poller = Poller(dt, self._stop_event, deadline=time.monotonic() + timeout_s)
            while True:
                poller.check()
                status, state = self._status()
                if state is ProjectState.ERROR:
                    failure = self._channel.status_failure(status)
                    assert failure is not None
                    raise failure
                if wanted is not ProjectState.PAUSED:
                    if state is wanted:
                        return state
                elif (settled := _pause_held((status, state), settled, was)) is not None:
                    poller.deadline = max(poller.deadline or 0.0, settled)
                    if time.monotonic() >= settled:
                        return state  # paused, or stopped meanwhile (the pendant's Stop)
                if time.monotonic() >= (poller.deadline or 0.0):
                    button = {ProjectState.RUNNING: "Play", ProjectState.PAUSED: "Pause"}
                    raise RobotError(
                        f"{button.get(wanted, 'Stop')} was pressed (the project was"
                        f" {was[1].value}) and the project is {state.value} {timeout_s:g} s"
                        f" later{': ' + REMOTE_PLAY_NEEDS if wanted in button else ''}",
                        pose=status.pose,
                    )
                poller.sleep()
        except BaseException as exc:
            if press and isinstance(exc, SETTLED_FAILURES):
                raise  # never sent, or answered: nothing can land later
            # A Play answered but not seen taking effect may land later (a gateway that
            # answers a write before delivering it): it must never resume a move then. A
            # Pause not seen holding leaves the arm running, which pause() must not.
            self._stop_before_giving_up(f"{wanted.value} unconfirmed", press, exc, boot)
            raise


def _pause_held(now: _Read, settled: float | None, was: _Read) -> float | None:
    """When a pause seen may be trusted (or a stop: the arm halts all the same, and the
    master's own Stop on a move the pause interrupted often shows before the pause is
    read); None before one is seen.

    Raises:
        RobotError: The project showed paused or stopped and runs again, or runs as a new
            start (``boot_id``): the toggle landed on a project stopped meanwhile (a Stop
            crossing this press), where it is Play.
    """
    status, running, boot = now[0], now[1] is ProjectState.RUNNING, was[0].raw.get("boot_id")
    if running and (settled is not None or status.raw.get("boot_id") != boot):
        raise RobotError(
            "the project ran again after a stop or pause (a press crossed this one): Stop pressed",
            pose=status.pose,
        )
    return settled or (None if running else time.monotonic() + PAUSE_SETTLE_S)
