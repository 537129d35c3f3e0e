"""The command-safety invariant under random faults, e-stops, resets, stops and reconnects.

A hypothesis state machine drives a real :class:`tmmaster.Robot` through the fault proxy
against the in-process simulator (both handshakes), with random rules: moves to unique
targets, network faults on the next command write (held and delivered late, delayed
answer, dropped request or answer, connection closed after the write, a short outage),
an operator's e-stop, reset and Play, a stop request in the middle of a move, and closing
and reopening the robot, closing it from another thread while it commands, and a
second Ctrl-C in the middle of a withdraw or stop. After every rule, and after letting
simulated time run on at the end (so a stale armed command would have had its chance),
the invariant of docs/safety.md is checked on the simulator's own motion log.

CI runs ``STATEFUL_EXAMPLES`` (5) examples of up to 8 steps per profile; set the
environment variable ``TMMASTER_STATEFUL_EXAMPLES`` for a longer hunt.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, check
from tmmaster import Fleet, PollPolicy, Pose, RetryPolicy, Robot, TimeoutPolicy, TMMasterError
from tmmaster.sim import Simulator

STATEFUL_EXAMPLES = int(os.environ.get("TMMASTER_STATEFUL_EXAMPLES", "5"))

#: Where the command block starts, per profile (the FC16 the faults aim at).
COMMAND_BLOCK = {"article": 0x0200, "tmflow": 9000}

#: Reachable targets near the default pick & place poses; each command adds its own z step.
BASES = (
    Pose(300, -200, 150, 180, 0, 90),
    Pose(300, 200, 180, 180, 0, 90),
    Pose(250, 0, 160, 180, 0, 90),
)

#: Request timeout and in-flight window of the master under test (seconds).
REQUEST_TIMEOUT_S = 0.15
IN_FLIGHT_S = 0.4


class CommandSafety(RuleBasedStateMachine):
    """Moves, faults and operator actions; the robot's own log must keep the invariant."""

    profile = "article"
    #: True: the robot is a Fleet's (its waits polled on the fleet's event loop).
    in_fleet = False
    #: The longest a held command frame may take. Article cannot tell a late frame from a
    #: lost one: one that lands after the in-flight window runs after the master gave up
    #: (docs/safety.md, "what it cannot guarantee"), so the hunt stays inside the window.
    max_hold_s = REQUEST_TIMEOUT_S + IN_FLIGHT_S * 0.6

    def __init__(self) -> None:
        super().__init__()
        self.sim = Simulator(self.profile, time_scale=20).start()
        self.proxy = FaultProxy(self.sim.port)
        self.issued: list[Issued] = []
        self.robot: Robot | None = None
        # Watched too: its reads interleave with the commands, the polls and the faults.
        self.fleet = Fleet(watch_hz=50) if self.in_fleet else None
        self.count = 0
        self._open()

    # -- helpers ---------------------------------------------------------------------

    def _open(self) -> None:
        robot = Robot(
            "127.0.0.1",
            self.proxy.port,
            profile=self.profile,
            gripper=None,
            timeouts=TimeoutPolicy(
                request_s=REQUEST_TIMEOUT_S,
                ack_timeout_s=0.4,
                in_flight_s=IN_FLIGHT_S,
                motion_factor=1.3,
                motion_margin_s=0.8,
            ),
            retry=RetryPolicy(
                attempts=6, total_time_s=1.0, initial_backoff_s=0.02, max_backoff_s=0.2
            ),
            polling=PollPolicy(interval_s=0.01),
            link=self.fleet,
        )
        try:
            robot.connect()
        except TMMasterError:
            robot.close()
            return
        self.robot = robot

    def _target(self) -> Pose:
        self.count += 1
        base = BASES[self.count % len(BASES)]
        return base.offset(dz=0.5 * self.count)

    def _move(self, speed: int, motion: str) -> None:
        assert self.robot is not None
        command = Issued(self._target(), time.monotonic())
        self.issued.append(command)
        try:
            self.robot.move_to(command.target, speed=speed, motion=motion)  # type: ignore[arg-type]
        except TMMasterError as exc:
            command.outcome = type(exc).__name__
        else:
            command.outcome = "done"
        finally:
            command.ended_at = time.monotonic()

    # -- rules -----------------------------------------------------------------------

    @precondition(lambda self: self.robot is not None)
    @rule(speed=st.integers(40, 100), motion=st.sampled_from(["ptp", "line"]))
    def move(self, speed: int, motion: str) -> None:
        self._move(speed, motion)

    def _move_through(self, rule: Rule | None, speed: int) -> None:
        if rule is not None:
            self.proxy.add(rule)
        try:
            self._move(speed, "ptp")
        finally:
            self.proxy.clear()

    def _aim(self, action: str, delay_s: float = 0.0) -> Rule:
        """A rule for the next write of the command block."""
        address = COMMAND_BLOCK[self.profile]
        return Rule(action, function_code=16, address=address, delay_s=delay_s)  # type: ignore[arg-type]

    # One rule per fault, so each is drawn as often as a plain move.

    @precondition(lambda self: self.robot is not None)
    @rule(fraction=st.sampled_from([0.45, 0.7, 0.95]), speed=st.integers(40, 100))
    def move_whose_write_arrives_late(self, fraction: float, speed: int) -> None:
        # Held past the request timeout, then delivered on the link the master dropped.
        self._move_through(self._aim("hold", fraction * self.max_hold_s), speed)

    @precondition(lambda self: self.robot is not None)
    @rule(speed=st.integers(40, 100))
    def move_whose_write_is_lost(self, speed: int) -> None:
        self._move_through(self._aim("drop_request"), speed)

    @precondition(lambda self: self.robot is not None)
    @rule(speed=st.integers(40, 100))
    def move_whose_answer_is_lost(self, speed: int) -> None:
        self._move_through(self._aim("drop_answer"), speed)

    @precondition(lambda self: self.robot is not None)
    @rule(speed=st.integers(40, 100))
    def move_whose_link_closes_after_the_write(self, speed: int) -> None:
        self._move_through(self._aim("close_after"), speed)

    @precondition(lambda self: self.robot is not None)
    @rule(outage_s=st.floats(0.05, 0.6), speed=st.integers(40, 100))
    def move_into_an_outage(self, outage_s: float, speed: int) -> None:
        self.proxy.outage(outage_s)
        self._move_through(None, speed)

    @precondition(lambda self: self.robot is not None)
    @rule(after_s=st.floats(0.0, 0.06), speed=st.integers(40, 100))
    def stop_request_during_a_move(self, after_s: float, speed: int) -> None:
        robot = self.robot
        assert robot is not None
        timer = threading.Timer(after_s, robot.interrupt)
        timer.start()
        try:
            self._move(speed, "ptp")
        finally:
            timer.join()
            robot.clear_stop_request()

    @precondition(lambda self: self.robot is not None)
    @rule(after_s=st.floats(0.0, 0.05), speed=st.integers(40, 100))
    def estop_during_a_move(self, after_s: float, speed: int) -> None:
        timer = threading.Timer(after_s, self.sim.press_estop)
        timer.start()
        try:
            self._move(speed, "ptp")
        finally:
            timer.join()

    @rule()
    def operator_resets_and_presses_play(self) -> None:
        self.sim.clear_error()
        self.sim.press_play()
        time.sleep(0.01)

    @precondition(lambda self: self.robot is not None)
    @rule(after_s=st.floats(0.0, 0.08), speed=st.integers(40, 100))
    def close_from_another_thread_while_moving(self, after_s: float, speed: int) -> None:
        # The robot's thread keeps commanding; close() comes from another thread at any
        # moment (between commands, mid-write, mid-wait). Then a fresh robot.
        robot = self.robot
        assert robot is not None
        closer = threading.Timer(after_s, robot.close)
        closer.start()
        try:
            for _ in range(3):
                self._move(speed, "ptp")
        finally:
            closer.join()
            self.robot = None
        self._open()

    @precondition(lambda self: self.robot is not None)
    @rule(
        after_s=st.floats(0.0, 0.06),
        speed=st.integers(40, 100),
        cut=st.sampled_from(["withdraw", "stop"]),
    )
    def second_interrupt_during_the_clean_up(self, after_s: float, speed: int, cut: str) -> None:
        # A stop request ends the move; a second Ctrl-C lands in the withdraw or the stop
        # (the main thread only receives SIGINT: elsewhere, a KeyboardInterrupt raised
        # there, which is what a handler raising it does). Then close, as the CLI does.
        robot = self.robot
        assert robot is not None
        channel = robot._channel
        real = getattr(channel, cut)
        main = threading.current_thread() is threading.main_thread()

        def second_ctrl_c(*args: object, **kwargs: object) -> object:
            setattr(channel, cut, real)  # once
            if main:
                signal.raise_signal(signal.SIGINT)
            else:
                raise KeyboardInterrupt
            return real(*args, **kwargs)

        setattr(channel, cut, second_ctrl_c)
        timer = threading.Timer(after_s, robot.interrupt)
        timer.start()
        command = Issued(self._target(), time.monotonic())
        self.issued.append(command)
        try:
            robot.move_to(command.target, speed=speed)
        except (TMMasterError, KeyboardInterrupt) as exc:
            command.outcome = type(exc).__name__
        else:
            command.outcome = "done"
        finally:
            command.ended_at = time.monotonic()
            timer.join()
            setattr(channel, cut, real)
            # (A held-back Ctrl-C of a clean-up that close() did itself is raised here.)
            with contextlib.suppress(KeyboardInterrupt):
                robot.close()
            self.robot = None
        self._open()

    @rule()
    def close_and_reopen(self) -> None:
        if self.robot is not None:
            self.robot.close()
            self.robot = None
        self._open()

    # -- the invariant ---------------------------------------------------------------

    @invariant()
    def the_robot_did_only_what_was_commanded(self) -> None:
        check(self.issued, self.sim.motion_log())

    def teardown(self) -> None:
        try:
            if self.robot is not None:
                self.robot.close()
            # Let every held frame land and the operator bring the robot back: whatever
            # is still armed now would run. Then nothing may have run that should not.
            self.proxy.wait_held()
            self.sim.clear_error()
            self.sim.press_play()
            # 3 simulated seconds, 7 ticks (due ticks run before the check reads the log):
            # a project starts in the tick after Play, and a command written to a running
            # one starts in the tick after the write.
            time.sleep(0.15)
            check(self.issued, self.sim.motion_log())
        finally:
            if self.fleet is not None:
                self.fleet.close()
            self.proxy.close()
            self.sim.close()


class TmflowCommandSafety(CommandSafety):
    """The same hunt on the sequence-numbered handshake."""

    profile = "tmflow"
    #: Sequence numbers make any delay safe: a late frame carries a used-up number.
    max_hold_s = 1.5


class FleetCommandSafety(CommandSafety):
    """The article hunt with the robot in a Fleet: its waits polled on the fleet's loop."""

    in_fleet = True


class FleetTmflowCommandSafety(TmflowCommandSafety):
    """The tmflow hunt with the robot in a Fleet."""

    in_fleet = True


_SETTINGS = settings(
    max_examples=STATEFUL_EXAMPLES,
    stateful_step_count=8,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)

TestArticleCommandSafety = CommandSafety.TestCase
TestArticleCommandSafety.settings = _SETTINGS
TestTmflowCommandSafety = TmflowCommandSafety.TestCase
TestTmflowCommandSafety.settings = _SETTINGS
TestFleetArticleCommandSafety = FleetCommandSafety.TestCase
TestFleetArticleCommandSafety.settings = _SETTINGS
TestFleetTmflowCommandSafety = FleetTmflowCommandSafety.TestCase
TestFleetTmflowCommandSafety.settings = _SETTINGS
