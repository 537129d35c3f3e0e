"""The asyncio front of a Robot: its calls run on its own thread, awaited on your loop.

An :class:`AsyncRobot` owns one thread (``_Worker``) that runs the :class:`Robot`'s own
methods, one call at a time in the order they were made: every check, write, wait,
withdraw and stop is the sync Robot's, written once in ``_robot.py``. The robot's link
and the polls of its waits live on a :class:`~tmmaster.Fleet`'s event loop (by default
one fleet shared by every robot :func:`connect` opens), so a waiting robot costs its
thread nothing until the loop wakes it.

The caller's event loop only awaits a future per call (``_Job.outcome``). Cancelling
the awaiting coroutine asks the robot's thread to give the call up
(:meth:`Robot.interrupt`: the wait ends, its command is withdrawn or the arm stopped, by
``_MotionFollower.abandon``); the ``CancelledError`` is raised once that call has ended,
bounded by :attr:`AsyncRobot.settle_timeout_s`. A call cancelled before the thread
started it never runs; a wait or progress call that follows a sent move gives that move
up however early it is cancelled (queued, or before its first step: ``_Primed``). A
move handed back by a call whose caller was cancelled meanwhile (``start_move``) is
given up the same way, before the thread runs another call.
"""

from __future__ import annotations

import asyncio
import collections
import collections.abc
import contextlib
import functools
import inspect
import threading
from collections.abc import Callable, Coroutine, Generator, Sequence
from enum import Enum
from typing import Any, Concatenate, Generic, Literal, ParamSpec, Protocol, TypeVar

from .._address import is_in_process
from .._checks import require_positive
from .._exceptions import TMMasterError, TransportClosedError
from .._fleet import Fleet
from .._gripper import GripperStatus
from .._io import DEFAULT_MODULE
from .._logging import get_logger
from .._pose import MotionType, Pose
from .._project import PRESS_TIMEOUT_S
from .._robot import Motion, Robot
from .._status import MovePhase, MoveProgress, ProjectState, RobotStatus

_log = get_logger("tmmaster.aio")

P = ParamSpec("P")
T = TypeVar("T")

#: How long a cancelled call may take to give its command up before the CancelledError
#: is raised anyway, s: beyond a withdraw's answer (``ack_timeout_s``) and a stop's
#: retries on a link that is down (the default RetryPolicy: 10 s).
DEFAULT_SETTLE_TIMEOUT_S = 30.0


class _Runs(Protocol):
    """What the robot's thread runs: a call, from its start to its outcome."""

    def run(self) -> None:
        """Run the call in the robot's thread and hand its outcome to the awaiting loop."""
        ...


class _Worker:
    """The robot's own thread: it runs the robot's calls one at a time, in order.

    A daemon thread, started with the first call: a program that exits with the robot
    still open closes it from the Robot's exit hook, which waits for a clean-up this
    thread is doing.
    """

    def __init__(self, name: str) -> None:
        self._name = name
        self._jobs: collections.deque[_Runs] = collections.deque()
        self._ready = threading.Condition()
        self._thread: threading.Thread | None = None
        self._closed = False
        #: The job the thread runs now (None between jobs).
        self.running: _Runs | None = None

    def submit(self, job: _Runs, *, first: bool = False) -> bool:
        """Queue ``job`` (``first``: before every queued one); False once shut down."""
        with self._ready:
            if self._closed:
                return False
            if first:
                self._jobs.appendleft(job)
            else:
                self._jobs.append(job)
            if self._thread is None:
                self._thread = threading.Thread(target=self._run, name=self._name, daemon=True)
                self._thread.start()
            self._ready.notify()
        return True

    def _run(self) -> None:
        while True:
            with self._ready:
                while not self._jobs and not self._closed:
                    self._ready.wait()
                if not self._jobs:
                    return  # shut down, every queued call run
                job = self._jobs.popleft()
                self.running = job
            try:
                job.run()
            finally:
                self.running = None

    def shutdown(self, timeout_s: float) -> bool:
        """Take no new call, run the queued ones, end the thread; False if still running."""
        with self._ready:
            self._closed = True
            self._ready.notify()
            thread = self._thread
        if thread is None or thread is threading.current_thread():
            return True
        thread.join(timeout_s)
        return not thread.is_alive()


class _State(Enum):
    QUEUED = "queued"
    SKIPPED = "skipped"
    RUNNING = "running"
    ENDED = "ended"


class _Job(Generic[T]):
    """One call of an AsyncRobot: run by the robot's thread, awaited on the caller's loop."""

    def __init__(
        self,
        owner: AsyncRobot,
        call: Callable[[], T],
        *,
        follows: Motion | None = None,
    ) -> None:
        self._owner = owner
        self._call = call
        #: The motion the call follows (a motion's wait or progress), given up with it.
        self.follows = follows
        self._loop = asyncio.get_running_loop()
        #: The call's result or exception, set on the caller's loop.
        self.outcome: asyncio.Future[T] = self._loop.create_future()
        self.outcome.add_done_callback(_retrieve)
        self._lock = threading.Lock()
        self._state = _State.QUEUED
        self._interrupted = False

    @property
    def skipped(self) -> bool:
        """True when the call was cancelled before the robot's thread started it."""
        return self._state is _State.SKIPPED

    @property
    def interrupted(self) -> bool:
        """True when the call was cancelled while the robot's thread ran it."""
        return self._interrupted

    def cancel(self) -> None:
        """From the caller's loop: never start the call, or make the running one give up.

        Never blocks: a stop request (:meth:`Robot.interrupt`) ends the call's wait at
        its next poll, or at once where a Fleet's loop polls it.
        """
        with self._lock:
            if self._state is _State.QUEUED:
                self._state = _State.SKIPPED
            elif self._state is _State.RUNNING and not self._interrupted:
                self._interrupted = True
                self._owner._interrupt_for_cancel()

    def run(self) -> None:
        """In the robot's thread: the call, then (if cancelled meanwhile) its clean-up."""
        with self._lock:
            if self._state is _State.SKIPPED:
                return
            self._state = _State.RUNNING
        value: T | None = None
        error: BaseException | None = None
        try:
            value = self._call()
        except BaseException as exc:  # handed to the awaiting coroutine as it is
            error = exc
        with self._lock:
            self._state = _State.ENDED
            interrupted = self._interrupted
        if interrupted:
            # Nobody waits for what this call started: give it up before the next call.
            live = _live_motion(value, self.follows)
            if live is not None:
                self._owner._give_up_in_thread(live)
            self._owner._end_interrupt()
        self._deliver(value, error)

    def unsupervised(self) -> Motion | None:
        """After the call ended uninterrupted: the motion it leaves nobody waiting for."""
        if self._interrupted or not self.outcome.done() or self.outcome.cancelled():
            return None
        if self.outcome.exception() is not None:
            return None
        return _live_motion(self.outcome.result(), self.follows)

    def _deliver(self, value: T | None, error: BaseException | None) -> None:
        try:
            self._loop.call_soon_threadsafe(self._settle, value, error)
        except RuntimeError:  # the caller's loop is closed: nobody awaits this any more
            return

    def _settle(self, value: T | None, error: BaseException | None) -> None:
        if self.outcome.done():
            return
        if error is not None:
            self.outcome.set_exception(error)
        else:
            self.outcome.set_result(value)  # type: ignore[arg-type]  # T when no error


def _retrieve(future: asyncio.Future[Any]) -> None:
    """Mark an outcome's exception as seen (a cancelled caller may never read it)."""
    if not future.cancelled():
        future.exception()


def _live_motion(value: object, follows: Motion | None) -> Motion | None:
    """The motion a call leaves running or pending: its result, or the one it follows."""
    motion = value if isinstance(value, Motion) else follows
    if motion is None or motion.done or motion.abandoned:
        return None
    return motion


class _Primed(collections.abc.Coroutine[Any, Any, T]):
    """A coroutine that reaches its first ``await`` even when cancelled before its first step.

    asyncio cancels a task that never ran by throwing ``CancelledError`` into a coroutine
    that has not started, which runs none of its code (``asyncio.wait_for(coro, 0)``).
    A wait that follows a sent move must still give the move up: thrown into before it
    started, this coroutine first runs its body up to its first ``await`` (the call is
    queued), then throws there, where the body's clean-up handles it.
    """

    def __init__(self, body: Coroutine[Any, Any, T]) -> None:
        self._body = body
        self._started = False

    def send(self, value: Any) -> Any:
        """Run the body on to its next ``await``."""
        self._started = True
        return self._body.send(value)

    def throw(self, typ: Any, val: Any = None, tb: Any = None) -> Any:
        """Raise ``typ`` in the body at its current ``await`` (its first, if not started)."""
        if not self._started:
            self._started = True
            with contextlib.suppress(StopIteration):
                self._body.send(None)  # what it yields is dropped: the throw comes first
        if val is None and tb is None:
            return self._body.throw(typ)
        return self._body.throw(typ, val, tb)  # pragma: no cover - the legacy form

    def close(self) -> None:
        """Close the body (its clean-up runs if it started)."""
        self._body.close()

    def __await__(self) -> Generator[Any, None, T]:
        return self._steps()

    def _steps(self) -> Generator[Any, None, T]:
        # Awaited: the body steps on as any awaited coroutine's (throws included).
        return (yield from self._body.__await__())


class AsyncRobot:
    """A :class:`~tmmaster.Robot` driven from asyncio: each call awaited, never blocking.

    Every method is the Robot method of the same name, run on this robot's own thread
    (one call at a time, in the order the calls were made, as a Robot used from one
    thread): the same checks, the one write, the same waits, withdraws and stops. With
    a Fleet (what :func:`connect` gives a robot), the polls of its waits run on the
    fleet's event loop and the robot's thread is woken only when a poll needs it.

    Cancelling an awaited call (``task.cancel()``, ``asyncio.timeout``, Ctrl-C in
    ``asyncio.run``) gives its command up as a wait ended by an exception does: a
    command the robot has not taken is withdrawn, a running move is stopped, and the
    ``CancelledError`` is raised once that is done (at most :attr:`settle_timeout_s`
    later). A call cancelled before the robot's thread started it is never run.

    Example:
        Two robots at once, against two simulators (``python -m tmmaster.sim --port
        5020`` and ``--port 5021``):

        ```python
        import asyncio

        from tmmaster import Pose, aio

        async def cycle(port: int) -> None:
            async with aio.connect("127.0.0.1", port, name=f"r{port}") as robot:
                await robot.move_to(Pose(300, -200, 200, 180, 0, 90), speed=50)
                await robot.gripper.close()
                print(robot.name, (await robot.status()).ready)

        async def main() -> None:
            await asyncio.gather(cycle(5020), cycle(5021))

        asyncio.run(main())
        ```

    Args:
        robot: The Robot to drive (not connected yet, or connected); made with
            ``fleet=`` for its waits to be polled on that fleet's loop. The AsyncRobot
            closes it in :meth:`close`.
        settle_timeout_s: How long a cancelled call may take to give its command up
            before the ``CancelledError`` is raised anyway (the clean-up then goes on in
            the robot's thread, and an error is logged), s.

    Raises:
        ConfigError: ``settle_timeout_s`` is not a finite number > 0.
    """

    def __init__(self, robot: Robot, *, settle_timeout_s: float = DEFAULT_SETTLE_TIMEOUT_S) -> None:
        require_positive("settle_timeout_s", settle_timeout_s)
        #: The Robot underneath: its settings and attributes (``name``, ``profile``,
        #: ``stats``, ``timeouts`` ...). Call its blocking methods only through :meth:`call`.
        self.robot = robot
        #: How long a cancelled call may take to give its command up, s.
        self.settle_timeout_s = settle_timeout_s
        #: The robot's gripper, awaited.
        self.gripper = AsyncGripper(self)
        #: The robot's digital I/O, awaited.
        self.io = AsyncRobotIO(self)
        self._worker = _Worker(f"tmmaster-aio-{robot.name}")
        self._log = _log.bind(robot=robot.name)
        # True while a stop request of the user's own (interrupt()) stands: a cancelled
        # call's stop request is withdrawn when the call ends, never the user's.
        self._user_stop = False
        # interrupt() and a cancelled call's end take turns: the call's end reads
        # _user_stop and clears the stop request as one step, so an interrupt() of the
        # user's in between is never cleared with it.
        self._stop_lock = threading.Lock()
        self._release: Callable[[], None] | None = None
        self._release_lock = threading.Lock()

    # -- attributes (no I/O) -----------------------------------------------------------

    @property
    def name(self) -> str:
        """The robot's name in messages and logs."""
        return self.robot.name

    @property
    def last_motion(self) -> Motion | None:
        """The last command sent (move or gripper action), with its outcome.

        A cancelled call's command is here too: ``withdrawn`` and ``stop_delivered``
        say how it was given up.
        """
        return self.robot.last_motion

    # -- the calls, on the robot's thread ----------------------------------------------

    async def call(
        self, fn: Callable[Concatenate[Robot, P], T], /, *args: P.args, **kwargs: P.kwargs
    ) -> T:
        """Run ``fn(robot, *args, **kwargs)`` on the robot's thread, as the other calls.

        For a Robot method this class has no async method for, or a few sync steps that
        belong together (``await robot.call(Robot.move_to, target, speed=30)`` is
        :meth:`move_to`). Cancelled, it is given up like the other calls; a
        :class:`~tmmaster.Motion` it returns to a cancelled caller is withdrawn or
        stopped.

        Args:
            fn: A function of the Robot (a Robot method, unbound).
            *args: Its positional arguments after the robot.
            **kwargs: Its keyword arguments.

        Returns:
            What ``fn`` returns.

        Raises:
            TransportClosedError: This robot is closed (nothing is run).
        """
        return await self._run(fn, self.robot, *args, **kwargs)

    async def connect(self) -> AsyncRobot:
        """Open the connections (:meth:`Robot.connect`); a no-op when open.

        A connect that fails, or is cancelled, closes this robot.

        Returns:
            This robot, connected.

        Raises:
            ConnectError: The robot cannot be reached, or was closed.
            ConfigError: The frame check failed (see :meth:`Robot.connect`).
        """
        try:
            await self._run(self.robot.connect)
        except BaseException:
            await self.close()
            raise
        return self

    async def status(self) -> RobotStatus:
        """One status snapshot (:meth:`Robot.status`).

        Returns:
            The robot's mode, motion, error, e-stop, grasp and TCP pose.

        Raises:
            TransportError: The read failed.
        """
        return await self._run(self.robot.status)

    async def pose(self) -> Pose:
        """The current TCP pose (:meth:`Robot.pose`).

        Returns:
            The TCP pose the robot reports, mm / deg.

        Raises:
            TransportError: The read failed.
        """
        return await self._run(self.robot.pose)

    async def check_fault(self) -> None:
        """Raise the typed error if the robot is in e-stop or error (:meth:`Robot.check_fault`).

        Raises:
            RobotFaultError: The robot is in error (EmergencyStopError for an e-stop).
        """
        await self._run(self.robot.check_fault)

    async def wait_until_ready(self, timeout_s: float = 10.0) -> RobotStatus:
        """Wait until the robot can take a motion command (:meth:`Robot.wait_until_ready`).

        Args:
            timeout_s: How long to wait, s.

        Returns:
            The first status that is ready.

        Raises:
            MotionTimeoutError: Not ready in time.
            RobotFaultError: The robot is in error (EmergencyStopError for an e-stop).
            StopRequestedError: A stop was requested.
        """
        return await self._run(self.robot.wait_until_ready, timeout_s)

    async def check_move(
        self,
        target: Pose,
        speed: int,
        motion: MotionType | Literal["ptp", "line"] = MotionType.PTP,
        *,
        start: Pose | None = None,
        seed_deg: Sequence[float] | None = None,
    ) -> tuple[float, ...]:
        """Check a move fully without sending it (:meth:`Robot.check_move`).

        Args:
            target: The TCP target.
            speed: Speed, an integer percent.
            motion: ``"ptp"`` or ``"line"``.
            start: Where a Line starts (None: its path is not checked).
            seed_deg: The joints at ``start``.

        Returns:
            The target's joints, deg.

        Raises:
            ConfigError: What is wrong (UnreachablePoseError, ValueOutOfRangeError).
        """
        return await self._run(
            self.robot.check_move, target, speed, motion, start=start, seed_deg=seed_deg
        )

    async def move_to(
        self,
        target: Pose,
        *,
        speed: int | None = None,
        motion: MotionType | Literal["ptp", "line"] = MotionType.PTP,
        timeout: float | None = None,
        accel_time_ms: int | None = None,
        speed_mm_s: int | None = None,
    ) -> Motion:
        """Move to ``target``; return when the robot acknowledged and finished the move.

        :meth:`Robot.move_to`, awaited. Cancelled before the robot took the command, the
        command is withdrawn; while the arm moves, the arm is stopped; then the
        ``CancelledError`` is raised. :attr:`last_motion` says which.

        Args:
            target: The TCP target (mm, deg, robot base frame).
            speed: Speed, an integer percent (1 .. ``max_speed_percent``); None: 30 %
                (or ``speed_mm_s``).
            motion: ``"ptp"`` (joint interpolation) or ``"line"`` (a straight TCP path).
            timeout: How long the move may take, s; None: from the expected time.
            accel_time_ms: Time to reach full speed, ms, where the profile has the
                field; None: the robot's default.
            speed_mm_s: A Line's TCP speed in mm/s instead of ``speed`` (``tmflow``).

        Returns:
            The finished move (its attributes; it has nothing left to wait for).

        Raises:
            ConfigError: The move is not allowed; nothing is sent.
            AcknowledgeTimeoutError: The robot did not take the command (withdrawn).
            MotionTimeoutError: The move did not finish in time (the arm is stopped).
            RobotFaultError: The robot reported an error (EmergencyStopError: e-stop).
            StopRequestedError: A stop was requested, or the robot was closed.
            TransportError: The link failed and did not come back in time.
        """
        return await self._run(
            self.robot.move_to,
            target,
            speed=speed,
            motion=motion,
            timeout=timeout,
            accel_time_ms=accel_time_ms,
            speed_mm_s=speed_mm_s,
        )

    async def start_move(
        self,
        target: Pose,
        *,
        speed: int | None = None,
        motion: MotionType | Literal["ptp", "line"] = MotionType.PTP,
        timeout: float | None = None,
        accel_time_ms: int | None = None,
        speed_mm_s: int | None = None,
    ) -> AsyncMotion:
        """Validate and send a move; return once it is sent (:meth:`Robot.start_move`).

        ``await`` the handle (or its :meth:`AsyncMotion.wait`) for the end. Cancelled
        before the handle is returned, the move is withdrawn or stopped.

        Args:
            target: The TCP target (mm, deg, robot base frame).
            speed: Speed, an integer percent (1 .. ``max_speed_percent``); None: 30 %
                (or ``speed_mm_s``).
            motion: ``"ptp"`` or ``"line"``.
            timeout: How long the move may take, s; None: from the expected time.
            accel_time_ms: Time to reach full speed, ms; None: the robot's default.
            speed_mm_s: A Line's TCP speed in mm/s instead of ``speed`` (``tmflow``).

        Returns:
            The move's handle.

        Raises:
            ConfigError: The move is not allowed (nothing is sent).
            RobotFaultError: The robot is in error or e-stop (nothing is sent).
            StopRequestedError: A stop was requested (nothing is sent).
        """
        sent = await self._run(
            self.robot.start_move,
            target,
            speed=speed,
            motion=motion,
            timeout=timeout,
            accel_time_ms=accel_time_ms,
            speed_mm_s=speed_mm_s,
        )
        return AsyncMotion(self, sent)

    async def move_joints(
        self,
        joints: Sequence[float],
        *,
        speed: int = 30,
        timeout: float | None = None,
        accel_time_ms: int | None = None,
    ) -> Motion:
        """Move to joint angles J1..J6 (a PTP in joint space); return when it is done.

        :meth:`Robot.move_joints`, awaited: the same checks before any request, and the
        joints and the TCP checked at the end. Cancelled before the robot took the
        command, the command is withdrawn; while the arm moves, the arm is stopped; then
        the ``CancelledError`` is raised.

        Args:
            joints: J1..J6, deg.
            speed: Speed, an integer percent of the joints' top speeds (1 ..
                ``max_speed_percent``).
            timeout: How long the move may take, s; None: from the expected time.
            accel_time_ms: Time to reach full speed, ms; None: the robot's default.

        Returns:
            The finished move (``motion.target``: the TCP pose the joints give).

        Raises:
            ConfigError: The move is not allowed, or the profile has no joint move
                (``article``); UnreachablePoseError for joints past a range, at a
                singularity or out of reach. Nothing is sent.
            AcknowledgeTimeoutError: The robot did not take the command (withdrawn).
            MotionTimeoutError: The move did not finish in time (the arm is stopped).
            RobotFaultError: The robot reported an error (EmergencyStopError: e-stop).
            StopRequestedError: A stop was requested, or the robot was closed.
            TransportError: The link failed and did not come back in time.
        """
        return await self._run(
            self.robot.move_joints,
            joints,
            speed=speed,
            timeout=timeout,
            accel_time_ms=accel_time_ms,
        )

    async def move_by(
        self,
        dx: float = 0.0,
        dy: float = 0.0,
        dz: float = 0.0,
        drx: float = 0.0,
        dry: float = 0.0,
        drz: float = 0.0,
        *,
        frame: Literal["base", "tool"] = "base",
        speed: int | None = None,
        motion: MotionType | Literal["ptp", "line"] = MotionType.PTP,
        timeout: float | None = None,
        accel_time_ms: int | None = None,
        speed_mm_s: int | None = None,
    ) -> Motion:
        """Move relative to where the robot reports the TCP; return when it is done.

        :meth:`Robot.move_by`, awaited: the offset is resolved against the TCP pose the
        robot reports into one absolute target, sent like :meth:`move_to`'s. Cancelled
        before the robot took the command, the command is withdrawn; while the arm
        moves, the arm is stopped; then the ``CancelledError`` is raised.

        Args:
            dx: Offset along x, mm.
            dy: Offset along y, mm.
            dz: Offset along z, mm.
            drx: Rotation about x, deg.
            dry: Rotation about y, deg.
            drz: Rotation about z, deg.
            frame: ``"base"`` (the robot base's axes) or ``"tool"`` (the TCP's own frame).
            speed: Speed, an integer percent; None: 30 % (or ``speed_mm_s``).
            motion: ``"ptp"`` or ``"line"``.
            timeout: How long the move may take, s; None: from the expected time.
            accel_time_ms: Time to reach full speed, ms; None: the robot's default.
            speed_mm_s: A Line's TCP speed in mm/s instead of ``speed`` (``tmflow``).

        Returns:
            The finished move (``motion.start``: the pose it was resolved against).

        Raises:
            ConfigError: A bad offset, frame or speed (nothing is read or sent), or a
                target the move may not take (nothing is sent).
            RobotError: The arm moved between the read and the write (nothing is sent).
            AcknowledgeTimeoutError: The robot did not take the command (withdrawn).
            MotionTimeoutError: The move did not finish in time (the arm is stopped).
            RobotFaultError: The robot reported an error (EmergencyStopError: e-stop).
            StopRequestedError: A stop was requested, or the robot was closed.
            TransportError: The link failed and did not come back in time.
        """
        return await self._run(
            self.robot.move_by,
            dx,
            dy,
            dz,
            drx,
            dry,
            drz,
            frame=frame,
            speed=speed,
            motion=motion,
            timeout=timeout,
            accel_time_ms=accel_time_ms,
            speed_mm_s=speed_mm_s,
        )

    async def move_arc(
        self,
        via: Pose,
        to: Pose,
        *,
        speed: int | None = None,
        timeout: float | None = None,
        accel_time_ms: int | None = None,
        speed_mm_s: int | None = None,
    ) -> Motion:
        """Move the TCP along a circular arc through ``via`` to ``to``; return when done.

        :meth:`Robot.move_arc`, awaited: the arc is resolved against the TCP pose the
        robot reports and checked before the write like a Line. Cancelled before the
        robot took the command, the command is withdrawn; while the arm moves, the arm
        is stopped; then the ``CancelledError`` is raised.

        Args:
            via: A pose whose position the arc passes through (mm).
            to: The TCP target at the arc's end (mm, deg).
            speed: Speed, an integer percent of the arm's top TCP speed; None: 30 % (or
                ``speed_mm_s``).
            timeout: How long the move may take, s; None: from the expected time.
            accel_time_ms: Time to reach full speed, ms; None: the robot's default.
            speed_mm_s: The TCP speed in mm/s instead of ``speed`` (``tmflow``).

        Returns:
            The finished move.

        Raises:
            ConfigError: No arc passes through the points, the arc may not be taken, or
                the profile has no circle command (``article``); UnreachablePoseError
                for an arc the arm cannot follow. Nothing is sent.
            RobotError: The arm moved between the read and the write (nothing is sent).
            AcknowledgeTimeoutError: The robot did not take the command (withdrawn).
            MotionTimeoutError: The move did not finish in time (the arm is stopped).
            RobotFaultError: The robot reported an error (EmergencyStopError: e-stop).
            StopRequestedError: A stop was requested, or the robot was closed.
            TransportError: The link failed and did not come back in time.
        """
        return await self._run(
            self.robot.move_arc,
            via,
            to,
            speed=speed,
            timeout=timeout,
            accel_time_ms=accel_time_ms,
            speed_mm_s=speed_mm_s,
        )

    async def stop(self) -> None:
        """Stop the arm (:meth:`Robot.stop`), as the robot's next call.

        To stop a move another task awaits, cancel that task (or :meth:`interrupt`):
        its wait gives the move up and stops the arm.

        Raises:
            ConfigError: The profile defines no stop.
            TransportError: The stop could not be written.
        """
        await self._run(self.robot.stop)

    async def project_state(self) -> ProjectState:
        """The TMflow project's state (:meth:`Robot.project_state`).

        Returns:
            RUNNING, PAUSED, STOPPED or ERROR.

        Raises:
            ConfigError: The profile has no TMflow project (article).
            TransportError: The read failed.
        """
        return await self._run(self.robot.project_state)

    async def play(self, timeout_s: float = PRESS_TIMEOUT_S) -> ProjectState:
        """Press Play on a stopped or paused project; wait until it runs (:meth:`Robot.play`).

        Args:
            timeout_s: How long to wait for the project to run after the press, s.

        Returns:
            ProjectState.RUNNING.

        Raises:
            ConfigError: The profile has no TMflow project (article).
            RobotFaultError: The robot is in error; nothing was pressed.
            RobotError: Manual mode, or the project did not run within ``timeout_s``.
            StopRequestedError: A stop was requested or the robot is closing.
        """
        return await self._run(self.robot.play, timeout_s)

    async def pause(self, timeout_s: float = PRESS_TIMEOUT_S) -> ProjectState:
        """Press Pause on a running project; wait until it pauses (:meth:`Robot.pause`).

        Args:
            timeout_s: How long to wait for the project to pause after the press, s.

        Returns:
            ProjectState.PAUSED, or STOPPED for a stopped project (nothing pressed).

        Raises:
            ConfigError: The profile has no TMflow project (article).
            RobotFaultError: The robot is in error.
            RobotError: The project did not pause within ``timeout_s``.
            StopRequestedError: A stop was requested or the robot is closing.
        """
        return await self._run(self.robot.pause, timeout_s)

    def interrupt(self) -> None:
        """Make running waits give up now, and refuse new commands until cleared.

        :meth:`Robot.interrupt`: the call waiting ends with StopRequestedError, its
        command withdrawn or the arm stopped; later moves raise StopRequestedError
        unsent until :meth:`clear_stop_request`. Never blocks.
        """
        with self._stop_lock:
            self._user_stop = True
            self.robot.interrupt()

    def clear_stop_request(self) -> None:
        """Allow commands again after :meth:`interrupt` (not after :meth:`close`)."""
        with self._stop_lock:
            self._user_stop = False
            self.robot.clear_stop_request()

    async def close(self, *, timeout_s: float | None = None) -> bool:
        """Withdraw or stop what is outstanding, close the connections, end the thread.

        :meth:`Robot.close` (from another thread: it does not queue behind a running
        call): a move running is stopped, and the call awaiting it raises
        StopRequestedError. Calls made after it raise TransportClosedError. Safe to
        call more than once. Cancelled, it still finishes first (bounded by
        :attr:`settle_timeout_s`).

        Args:
            timeout_s: A bound on the clean-up, s; None: the retry policy's own bounds.

        Returns:
            True when nothing this robot sent can still run; False when a withdraw or
            stop could not be confirmed (logged).

        Raises:
            ConfigError: ``timeout_s`` is not a finite number > 0.
        """
        if timeout_s is not None:
            require_positive("timeout_s", timeout_s)
        loop = asyncio.get_running_loop()
        closed: asyncio.Future[bool] = loop.create_future()
        closed.add_done_callback(_retrieve)

        def close_here() -> None:
            try:
                safely = self._close_in_thread(timeout_s)
            except BaseException as exc:
                _hand_over(loop, closed, None, exc)
            else:
                _hand_over(loop, closed, safely, None)

        threading.Thread(
            target=close_here, name=f"tmmaster-aio-close-{self.name}", daemon=True
        ).start()
        try:
            return await asyncio.shield(closed)
        except asyncio.CancelledError:
            await self._settle(closed, loop.time() + self.settle_timeout_s, "close")
            raise

    def _close_in_thread(self, timeout_s: float | None) -> bool:
        safely = self.robot.close(timeout_s=timeout_s)
        # Calls still queued run now and fail at once: the robot is closed.
        if not self._worker.shutdown(self.settle_timeout_s):
            self._log.error("aio.thread_still_running", timeout_s=self.settle_timeout_s)
        with self._release_lock:
            release, self._release = self._release, None
        if release is not None:
            release()
        return safely

    async def __aenter__(self) -> AsyncRobot:
        return await self.connect()

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    def __await__(self) -> Generator[Any, None, AsyncRobot]:
        return self.connect().__await__()

    # -- internals -----------------------------------------------------------------------

    async def _run(self, fn: Callable[P, T], /, *args: P.args, **kwargs: P.kwargs) -> T:
        return await self._await(_Job(self, functools.partial(fn, *args, **kwargs)))

    def _follow(self, motion: Motion, call: Callable[[], T]) -> _Primed[T]:
        """A call that follows ``motion`` (its wait, its progress): cancelled, it gives it up.

        Cancelled before its first step too (:class:`_Primed`).
        """
        return _Primed(self._await(_Job(self, call, follows=motion)))

    async def _await(self, job: _Job[T]) -> T:
        if not self._worker.submit(job):
            raise TransportClosedError(f"{self.name}: this robot is closed")
        try:
            return await asyncio.shield(job.outcome)
        except asyncio.CancelledError:
            await self._give_up(job)
            raise

    async def _give_up(self, job: _Job[Any]) -> None:
        """The caller was cancelled: the call gives up, then whatever it left running."""
        job.cancel()
        deadline = asyncio.get_running_loop().time() + self.settle_timeout_s
        if job.skipped:
            # Never started, so the call itself sent nothing; but a wait queued behind
            # another call follows a move that was sent, and that move is given up.
            live = _live_motion(None, job.follows)
            if live is not None:
                self._interrupt_followers(live)
        elif not await self._settle(job.outcome, deadline, "call"):
            return
        else:
            # The call had ended (a move sent) when the caller was cancelled: nobody
            # will wait for that move.
            live = job.unsupervised()
        if live is None:
            return
        # Given up before any other call runs.
        give_up = _Job(self, functools.partial(self._give_up_in_thread, live))
        if self._worker.submit(give_up, first=True):
            await self._settle(give_up.outcome, deadline, "give_up")

    async def _settle(self, future: asyncio.Future[Any], deadline: float, what: str) -> bool:
        """Wait for ``future`` until ``deadline`` (loop time), whatever cancels the caller."""
        loop = asyncio.get_running_loop()
        while not future.done():
            left = deadline - loop.time()
            if left <= 0:
                self._log.error(
                    "aio.cancel_unsettled", what=what, settle_timeout_s=self.settle_timeout_s
                )
                return False
            try:
                await asyncio.wait((future,), timeout=left)
            except asyncio.CancelledError:
                continue  # cancelled again (a second Ctrl-C): the clean-up still comes first
        return True

    def _interrupt_followers(self, motion: Motion) -> None:
        """Another caller's running wait on ``motion`` gives up too (the move is given up)."""
        running = self._worker.running
        if isinstance(running, _Job) and running.follows is motion:
            running.cancel()

    def _interrupt_for_cancel(self) -> None:
        """From the caller's loop (a call cancelled): its wait gives up now."""
        self.robot.interrupt()

    def _end_interrupt(self) -> None:
        """In the robot's thread, a cancelled call over: take back its stop request."""
        with self._stop_lock:
            if not self._user_stop:
                self.robot.clear_stop_request()

    def _give_up_in_thread(self, motion: Motion) -> None:
        """In the robot's thread: withdraw ``motion`` or stop it (its wait, given up at once)."""
        if _live_motion(None, motion) is None:
            return  # over, or given up already (by the wait it followed)
        self.robot.interrupt()
        try:
            motion.wait()  # ends at once with StopRequestedError, after the clean-up
        except TMMasterError:
            pass
        finally:
            self._end_interrupt()
        self._log.warning(
            "aio.motion_given_up",
            command=motion.command.kind.value,
            withdrawn=motion.withdrawn,
            stop_delivered=motion.stop_delivered,
        )


def _hand_over(
    loop: asyncio.AbstractEventLoop,
    future: asyncio.Future[T],
    value: T | None,
    error: BaseException | None,
) -> None:
    """From a thread: settle ``future`` on ``loop`` (nothing if the loop has closed)."""

    def settle() -> None:
        if future.done():
            return
        if error is not None:
            future.set_exception(error)
        else:
            future.set_result(value)  # type: ignore[arg-type]  # T when no error

    try:
        loop.call_soon_threadsafe(settle)
    except RuntimeError:
        return


class AsyncMotion:
    """A move sent by :meth:`AsyncRobot.start_move`: await it, or ask its progress.

    ``await motion`` waits for the end and returns the finished :class:`~tmmaster.Motion`
    (the same as :meth:`wait`, then :attr:`motion`).
    """

    def __init__(self, robot: AsyncRobot, motion: Motion) -> None:
        self._robot = robot
        #: The move itself: its target, phase, last pose, ``withdrawn``,
        #: ``stop_delivered``... (never call its blocking ``wait`` from a coroutine).
        self.motion = motion

    @property
    def done(self) -> bool:
        """True once the robot acknowledged and then finished the move."""
        return self.motion.done

    @property
    def phase(self) -> MovePhase:
        """Where the move stands."""
        return self.motion.phase

    def wait(self, timeout_s: float | None = None) -> Coroutine[Any, Any, None]:
        """Wait until the move is done (:meth:`Motion.wait`).

        Cancelled, the move is withdrawn or stopped before the ``CancelledError`` is
        raised: while the wait is queued behind another call of the robot, while it
        runs, and also when it is cancelled before it ever ran
        (``asyncio.wait_for(motion.wait(), 0)``).

        Args:
            timeout_s: How long to wait, s; None: the move's own ``timeout_s``.

        Returns:
            The wait, a coroutine (await it, or make it a task).

        Raises:
            AcknowledgeTimeoutError: The robot did not take the command in time.
            MotionTimeoutError: The move did not finish in time.
            RobotFaultError: The robot reported an error (EmergencyStopError: e-stop).
            StopRequestedError: A stop was requested, or the robot was closed.
            ConnectionLostError: The link broke and did not come back in time.
        """
        motion = self.motion
        return self._robot._follow(motion, functools.partial(motion.wait, timeout_s))

    def progress(self) -> Coroutine[Any, Any, MoveProgress]:
        """Poll the robot once and report where the move stands (:meth:`Motion.progress`).

        Cancelled, the move is given up as a cancelled :meth:`wait` gives it up.

        Returns:
            A coroutine of the phase, the last pose, the time elapsed and expected, and
            the fraction of the distance covered.

        Raises:
            RobotFaultError: The robot reported an error (EmergencyStopError: e-stop).
        """
        motion = self.motion
        return self._robot._follow(motion, motion.progress)

    def __await__(self) -> Generator[Any, None, Motion]:
        return self._finished().__await__()

    async def _finished(self) -> Motion:
        await self.wait()
        return self.motion


class AsyncGripper:
    """An :class:`AsyncRobot`'s gripper: the Robot's :class:`~tmmaster.Gripper`, awaited.

    Each call runs on the robot's thread like the robot's own calls; cancelled, its
    command is withdrawn or stopped like a move's.
    """

    def __init__(self, robot: AsyncRobot) -> None:
        self._robot = robot

    @property
    def kind(self) -> str:
        """The driver's name (a gripper profile's name for the stand-alone grippers)."""
        return self._robot.robot.gripper.kind

    async def status(self) -> GripperStatus:
        """Read the gripper's status once.

        Returns:
            The gripper's status now.

        Raises:
            TransportError: The read failed.
        """
        return await self._robot._run(self._robot.robot.gripper.status)

    async def open(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Open the fingers fully; return when they have stopped.

        Args:
            timeout_s: How long the fingers may take, s; None: the driver's default.

        Returns:
            The status once the fingers stopped.

        Raises:
            GripperTimeoutError: The fingers did not stop in time.
            StopRequestedError: A stop was requested meanwhile.
            RobotFaultError: The robot went into e-stop or error (a subclass of it).
        """
        return await self._robot._run(self._robot.robot.gripper.open, timeout_s=timeout_s)

    async def close(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Close the fingers; return when they stopped (on an object or fully closed).

        Args:
            timeout_s: How long the fingers may take, s; None: the driver's default.

        Returns:
            The status once the fingers stopped; ``holding`` says whether they hold
            an object.

        Raises:
            GripperTimeoutError: The fingers did not stop in time.
            StopRequestedError: A stop was requested meanwhile.
            RobotFaultError: The robot went into e-stop or error (a subclass of it).
        """
        return await self._robot._run(self._robot.robot.gripper.close, timeout_s=timeout_s)

    async def grip(self, *, timeout_s: float | None = None) -> GripperStatus:
        """Close and require an object.

        Args:
            timeout_s: How long the fingers may take, s; None: the driver's default.

        Returns:
            The status, holding an object.

        Raises:
            GraspFailedError: The fingers closed on nothing.
            GripperTimeoutError: The fingers did not stop in time.
        """
        return await self._robot._run(self._robot.robot.gripper.grip, timeout_s=timeout_s)

    async def holding(self) -> bool:
        """Whether the gripper detects an object now (one status read).

        Returns:
            True when an object is between the fingers.

        Raises:
            TransportError: The read failed.
        """
        return (await self.status()).holding


class AsyncRobotIO:
    """An :class:`AsyncRobot`'s digital I/O: the Robot's :class:`~tmmaster.RobotIO`, awaited.

    Each call runs on the robot's thread like the robot's own calls. An output write
    passes the robot's command gate: refused unsent once ``close()`` began or while a
    stop is requested.
    """

    def __init__(self, robot: AsyncRobot) -> None:
        self._robot = robot

    @property
    def modules(self) -> tuple[str, ...]:
        """The names of the robot's digital I/O modules (empty when the profile has none)."""
        return self._robot.robot.io.modules

    async def set_do(self, channel: int, value: bool, *, module: str = DEFAULT_MODULE) -> None:
        """Set digital output ``channel`` of ``module`` high (True) or low (False).

        Args:
            channel: The DO number, from 0 (control box 0-15, end module 0-3 on a TM).
            value: True: high; False: low.
            module: ``"control_box"`` or ``"end_module"`` (the profile's modules).

        Raises:
            ConfigError: An unknown module, a channel out of range or not an int, a
                value that is not a bool, or the gripper's output.
            StopRequestedError: The robot is closing or a stop is requested: not written.
            TransportError: The write failed after its retries.
        """
        await self._robot._run(self._robot.robot.io.set_do, channel, value, module=module)

    async def do(self, channel: int, *, module: str = DEFAULT_MODULE) -> bool:
        """Read digital output ``channel`` of ``module`` back (one request).

        Args:
            channel: The DO number, from 0.
            module: ``"control_box"`` or ``"end_module"``.

        Returns:
            True when the output is high.

        Raises:
            ConfigError: An unknown module or a channel out of range or not an int.
            TransportError: The read failed.
        """
        return await self._robot._run(self._robot.robot.io.do, channel, module=module)

    async def di(self, channel: int, *, module: str = DEFAULT_MODULE) -> bool:
        """Read digital input ``channel`` of ``module`` (one request).

        Args:
            channel: The DI number, from 0.
            module: ``"control_box"`` or ``"end_module"``.

        Returns:
            True when the input is high.

        Raises:
            ConfigError: An unknown module or a channel out of range or not an int.
            TransportError: The read failed.
        """
        return await self._robot._run(self._robot.robot.io.di, channel, module=module)

    async def dos(self, *, module: str = DEFAULT_MODULE) -> tuple[bool, ...]:
        """Read every digital output of ``module`` in one request.

        Args:
            module: ``"control_box"`` or ``"end_module"``.

        Returns:
            One bool per DO, DO 0 first.

        Raises:
            ConfigError: An unknown module, or one without DOs.
            TransportError: The read failed.
        """
        return await self._robot._run(self._robot.robot.io.dos, module=module)

    async def dis(self, *, module: str = DEFAULT_MODULE) -> tuple[bool, ...]:
        """Read every digital input of ``module`` in one request.

        Args:
            module: ``"control_box"`` or ``"end_module"``.

        Returns:
            One bool per DI, DI 0 first.

        Raises:
            ConfigError: An unknown module, or one without DIs.
            TransportError: The read failed.
        """
        return await self._robot._run(self._robot.robot.io.dis, module=module)


class _SharedFleet:
    """The Fleet of the robots :func:`connect` opens: made with the first, closed with the last."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._fleet: Fleet | None = None
        self._users = 0

    def acquire(self) -> Fleet:
        with self._lock:
            if self._fleet is None:
                self._fleet = Fleet()
                self._users = 0
            self._users += 1
            return self._fleet

    def release(self, fleet: Fleet) -> None:
        with self._lock:
            if fleet is not self._fleet:
                return
            self._users -= 1
            if self._users > 0:
                return
            self._fleet = None
        fleet.close()  # its robots are closed: this stops its loop


_SHARED_FLEET = _SharedFleet()


def _async_connected(make: Callable[P, Robot]) -> Callable[P, AsyncRobot]:
    """An AsyncRobot from ``make``'s arguments, with ``make``'s exact signature."""
    signature = inspect.signature(make)

    def connect(*args: P.args, **kwargs: P.kwargs) -> AsyncRobot:
        """Open an :class:`AsyncRobot`: ``await`` it, or use it in ``async with``.

        Every argument is :class:`~tmmaster.Robot`'s, with the same defaults, but for
        ``fleet``: None (the default) puts the robot in one Fleet shared by the robots
        this function opens, started with the first and closed with the last, so that the
        polls of their waits run on one event loop (docs/robot-api.md, "asyncio"). A
        ``sim://`` host (an in-process simulator) or a ``transport=`` of your own has no
        fleet: the robot's thread polls its waits itself.

        Making the robot does no I/O; ``await aio.connect(...)`` or ``async with
        aio.connect(...) as robot`` connects it, and ``async with`` closes it (a move
        still running is stopped).

        Example:
            Against the simulator (``python -m tmmaster.sim --port 5020``):

            ```python
            import asyncio

            from tmmaster import Pose, aio

            async def main() -> None:
                async with aio.connect("127.0.0.1", 5020) as robot:
                    await robot.wait_until_ready()
                    await robot.move_to(Pose(300, -200, 200, 180, 0, 90), speed=50)
                    try:
                        async with asyncio.timeout(0.05):  # far too short
                            await robot.move_to(Pose(300, -200, 120, 180, 0, 90), speed=5)
                    except TimeoutError:  # withdrawn or stopped, whichever it needed
                        print("gave up:", robot.last_motion)
                    print(await robot.status())

            asyncio.run(main())
            ```

        Returns:
            The robot, not connected yet.

        Raises:
            ConfigError: An invalid argument.
        """
        bound = signature.bind(*args, **kwargs)
        options = bound.arguments
        fleet: Fleet | None = None
        host = options.get("host")
        if (
            options.get("fleet") is None
            and options.get("transport") is None
            and not is_in_process(host)
        ):
            fleet = _SHARED_FLEET.acquire()
            options["fleet"] = fleet
        try:
            robot = Robot(*bound.args, **bound.kwargs)
        except BaseException:
            if fleet is not None:
                _SHARED_FLEET.release(fleet)
            raise
        opened = AsyncRobot(robot)
        if fleet is not None:
            opened._release = functools.partial(_SHARED_FLEET.release, fleet)
        return opened

    connect.__qualname__ = "connect"
    # help() and the API docs show Robot's parameters, not *args/**kwargs, and what this
    # function returns (an AsyncRobot; Robot's constructor returns None).
    connect.__signature__ = signature.replace(  # type: ignore[attr-defined]
        return_annotation=inspect.signature(connect).return_annotation
    )
    return connect


connect = _async_connected(Robot)
