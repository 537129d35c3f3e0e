"""The command-safety invariant through the asyncio front, under random cancellations.

A hypothesis state machine drives an :class:`tmmaster.aio.AsyncRobot` against the
simulator: moves sent and awaited, waits queued behind another call, cancelled at each
of their await points (before the first step, queued, while the command waits for its
acknowledgement, while the arm moves), the user's ``interrupt()``, and ``close()`` from
another task. After every step the invariant of docs/safety.md is checked on the
simulator's motion log, and so is one more: a move whose awaited call was cancelled or
interrupted is no longer running once that call has ended (withdrawn, or stopped).

CI runs ``STATEFUL_EXAMPLES`` examples per profile (``TMMASTER_STATEFUL_EXAMPLES`` for a
longer hunt).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import threading
import time
from collections.abc import Coroutine
from typing import Any

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from safety_invariant import Issued, check
from tmmaster import PollPolicy, Pose, TimeoutPolicy, TMMasterError, aio
from tmmaster.sim import Simulator, Timing

STATEFUL_EXAMPLES = int(os.environ.get("TMMASTER_STATEFUL_EXAMPLES", "3"))

BASES = (
    Pose(300, -200, 150, 180, 0, 90),
    Pose(300, 200, 180, 180, 0, 90),
    Pose(250, 0, 160, 180, 0, 90),
)

#: How much later than the call's end a given-up move may still report its end: a stop
#: is taken at the robot's next control tick (10 ms here), and a move that ends in that
#: very tick reports its end. A move left running goes on for its remaining distance.
TICK_SLACK_S = 0.15

#: Where a cancellation lands: before the wait's first step, while it is queued behind
#: another call, soon after it started (the acknowledgement), later (the arm moving).
CANCEL_POINTS = ("unstarted", "queued", "early", "moving")


class AsyncCommandSafety(RuleBasedStateMachine):
    """Awaited moves cancelled anywhere; the robot's own log must keep the invariant."""

    profile = "article"

    def __init__(self) -> None:
        super().__init__()
        self.sim = Simulator(self.profile, time_scale=5, timing=Timing(tick_hz=100)).start()
        self.loop = asyncio.new_event_loop()
        self.issued: list[Issued] = []
        self.given_up: list[tuple[Issued, float]] = []
        self.count = 0
        self.robot: aio.AsyncRobot | None = None
        self._open()

    # -- helpers ---------------------------------------------------------------------

    def _run(self, coro: Coroutine[Any, Any, Any]) -> Any:
        return self.loop.run_until_complete(asyncio.wait_for(coro, 20))

    def _open(self) -> None:
        robot = aio.connect(
            "127.0.0.1",
            self.sim.port,
            profile=self.profile,
            gripper=None,
            timeouts=TimeoutPolicy(ack_timeout_s=2.0),
            polling=PollPolicy(interval_s=0.01),
        )
        try:
            self._run(robot.connect())
        except TMMasterError:
            self._run(robot.close())
            return
        self.robot = robot

    def _target(self) -> Pose:
        self.count += 1
        return BASES[self.count % len(BASES)].offset(dz=0.5 * self.count)

    def _ready_project(self) -> None:
        # The operator brings the robot back (a stop on tmflow stops the project). Play
        # is the Play/Pause toggle: pressed on a running project it would pause it.
        self.sim.clear_error()
        if self.profile == "tmflow" and not (
            self.sim.field("project_running") and not self.sim.field("paused")
        ):
            self.sim.press_play()

    def _ready(self) -> None:
        self._ready_project()
        assert self.robot is not None
        self.robot.clear_stop_request()
        # Ready within a few ms when it will be at all (a tmflow project whose Stop lands
        # after the check above stays stopped: then the next command meets it so).
        with contextlib.suppress(TMMasterError):
            self._run(self.robot.wait_until_ready(timeout_s=1))

    async def _cancelled_wait(self, command: Issued, speed: int, point: str) -> None:
        robot = self.robot
        assert robot is not None
        try:
            handle = await robot.start_move(command.target, speed=speed)
        except TMMasterError as exc:
            command.outcome, command.ended_at = type(exc).__name__, time.monotonic()
            return
        release = threading.Event()
        blocker = None
        if point == "queued":
            blocker = asyncio.ensure_future(robot.call(lambda _robot: release.wait(2)))
        waiting = asyncio.ensure_future(handle.wait())
        if point == "early":
            await asyncio.sleep(0)
        elif point == "moving":
            await asyncio.sleep(0.05)
        elif point == "queued":
            await asyncio.sleep(0.02)
            self.loop.call_later(0.05, release.set)
        waiting.cancel()
        outcome = "CancelledError"
        try:
            await waiting
            outcome = "done"
        except asyncio.CancelledError:
            pass
        except TMMasterError as exc:
            outcome = type(exc).__name__
        command.outcome, command.ended_at = outcome, time.monotonic()
        if outcome != "done":
            self.given_up.append((command, command.ended_at))
        release.set()
        if blocker is not None:
            await blocker

    # -- rules -----------------------------------------------------------------------

    @precondition(lambda self: self.robot is not None)
    @rule(speed=st.integers(30, 100))
    def awaited_move(self, speed: int) -> None:
        self._run(self._awaited_move(self._issue(), speed))

    @precondition(lambda self: self.robot is not None)
    @rule(speed=st.integers(10, 60), point=st.sampled_from(CANCEL_POINTS))
    def cancelled_wait(self, speed: int, point: str) -> None:
        self._run(self._cancelled_wait(self._issue(), speed, point))

    async def _awaited_move(self, command: Issued, speed: int) -> None:
        """``move_to`` awaited, its outcome recorded (and noted as given up if it failed)."""
        robot = self.robot
        assert robot is not None
        try:
            await robot.move_to(command.target, speed=speed)
            command.outcome = "done"
        except TMMasterError as exc:
            command.outcome = type(exc).__name__
        command.ended_at = time.monotonic()
        if command.gave_up:
            self.given_up.append((command, command.ended_at))

    def _issue(self) -> Issued:
        self._ready()
        command = Issued(self._target(), time.monotonic())
        self.issued.append(command)
        return command

    @precondition(lambda self: self.robot is not None)
    @rule(speed=st.integers(10, 60), after_s=st.floats(0.0, 0.08))
    def interrupted_move(self, speed: int, after_s: float) -> None:
        robot = self.robot
        assert robot is not None
        command = self._issue()

        async def scenario() -> None:
            self.loop.call_later(after_s, robot.interrupt)
            await self._awaited_move(command, speed)
            await asyncio.sleep(after_s)  # the interrupt has landed

        self._run(scenario())

    @precondition(lambda self: self.robot is not None)
    @rule(speed=st.integers(10, 60), after_s=st.floats(0.0, 0.08))
    def closed_while_moving(self, speed: int, after_s: float) -> None:
        robot = self.robot
        assert robot is not None
        command = self._issue()

        async def scenario() -> None:
            closing = self.loop.call_later(after_s, lambda: asyncio.ensure_future(robot.close()))
            await self._awaited_move(command, speed)
            closing.cancel()
            await robot.close()

        self._run(scenario())
        self.robot = None
        self._open()

    # -- the invariants --------------------------------------------------------------

    @invariant()
    def the_robot_did_only_what_was_commanded(self) -> None:
        check(self.issued, self.sim.motion_log())

    @invariant()
    def a_move_given_up_is_not_running_after(self) -> None:
        # Its motion record never reports an end later than the call that gave it up,
        # beyond the tick that takes the stop (stopped moves report none).
        for command, ended_at in self.given_up:
            for motion in self.sim.motion_log():
                if motion.target is None or command.target.distance_to(motion.target) > 0.05:
                    continue
                done = motion.done_wall_time
                assert done is None or done <= ended_at + TICK_SLACK_S, (
                    f"{command.target} ({command.outcome}) finished {done - ended_at:.3f} s"
                    " after its call gave it up"
                )

    def teardown(self) -> None:
        try:
            if self.robot is not None:
                self._run(self.robot.close())
            self._ready_project()
            time.sleep(0.3)  # 1.5 simulated s: whatever is still armed would run now
            check(self.issued, self.sim.motion_log())
            self.a_move_given_up_is_not_running_after()
        finally:
            self.loop.close()
            self.sim.close()


class TmflowAsyncCommandSafety(AsyncCommandSafety):
    """The same hunt on the sequence-numbered handshake."""

    profile = "tmflow"


_SETTINGS = settings(
    max_examples=STATEFUL_EXAMPLES,
    stateful_step_count=6,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)

TestArticleAsyncCommandSafety = AsyncCommandSafety.TestCase
TestArticleAsyncCommandSafety.settings = _SETTINGS
TestTmflowAsyncCommandSafety = TmflowAsyncCommandSafety.TestCase
TestTmflowAsyncCommandSafety.settings = _SETTINGS
