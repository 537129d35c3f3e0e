"""The asyncio front of a Robot: its calls run on its own thread, awaited on your loop.

An :class:`AsyncRobot` owns one thread (``_Worker``) that runs the :class:`Robot`'s own
methods, one call at a time in the order they were made: every check, write, wait,
withdraw and stop is the sync Robot's, written once in ``_robot.py``. The awaited methods
are made from the sync ones (``move_to = _awaited(Robot.move_to)``): the same signature
and docstring, typed once. The robot's link
and the polls of its waits live on a driver's event loop (the process's default one,
which every network Robot joins, or a :class:`~tmmaster.Fleet` of your own), so a
waiting robot costs its thread nothing until the loop wakes it.

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
import concurrent.futures
import contextlib
import functools
import inspect
import re
import textwrap
import threading
import weakref
from collections.abc import Callable, Coroutine, Generator
from typing import Any, Concatenate, Generic, ParamSpec, TypeVar, cast

from .._checks import require_positive
from .._exceptions import TMMasterError, TransportClosedError
from .._gripper import Gripper
from .._io import RobotIO
from .._logging import get_logger
from .._robot import Motion, Robot, _named_connect, _waited
from .._status import MovePhase, MoveProgress

_log = get_logger("tmmaster.aio")

P = ParamSpec("P")
T = TypeVar("T")
R = TypeVar("R")
F = TypeVar("F", bound=Callable[..., Any])

#: How long a cancelled call may take to give its command up before the CancelledError
#: is raised anyway, s: beyond a withdraw's answer (``ack_timeout_s``) and a stop's
#: retries on a link that is down (the default RetryPolicy: 10 s).
DEFAULT_SETTLE_TIMEOUT_S = 30.0


class _Worker:
    """The robot's own thread: it runs the robot's calls one at a time, in order.

    A daemon thread, started with the first call: a program that exits with the robot
    still open closes it from the Robot's exit hook, which waits for a clean-up this
    thread is doing. It holds no robot between calls, and ends once its AsyncRobot is
    garbage (dropped without ``close()``).
    """

    def __init__(self, name: str) -> None:
        self._jobs: collections.deque[_Job[Any]] = collections.deque()
        self._ready = threading.Condition()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._closed = False
        #: The job the thread runs now (None between jobs).
        self.running: _Job[Any] | None = None

    def submit(self, job: _Job[Any], *, first: bool = False) -> bool:
        """Queue ``job`` (``first``: before every queued one); False once shut down."""
        with self._ready:
            if self._closed:
                return False
            (self._jobs.appendleft if first else self._jobs.append)(job)
            if self._thread.ident is None:  # the first call
                self._thread.start()
            self._ready.notify()
        return True

    def _run(self) -> None:
        while True:
            with self._ready:
                self._ready.wait_for(lambda: self._jobs or self._closed)
                if not self._jobs:
                    return  # shut down, every queued call run
                job = self._jobs.popleft()
                self.running = job
            try:
                job.run()
            finally:
                self.running = None
                del job  # while it waits, it holds no robot: a dropped one is garbage

    def shutdown(self, timeout_s: float) -> bool:
        """Take no new call, run the queued ones, end the thread; False if still running."""
        with self._ready:  # no thread starts after this
            self._closed = True
            self._ready.notify()
        if self._thread.ident is None or self._thread is threading.current_thread():
            return True
        self._thread.join(timeout_s)
        return not self._thread.is_alive()


class _Job(Generic[T]):
    """One call of an AsyncRobot: run by the robot's thread, awaited on the caller's loop."""

    def __init__(
        self, owner: AsyncRobot, call: Callable[[], T], *, follows: Motion | None = None
    ) -> None:
        self._owner = owner
        self._call = call
        #: The motion the call follows (a motion's wait or progress), given up with it.
        self.follows = follows
        # Pending (queued), cancelled (skipped: never run) or running, then the call's
        # result or exception, set by the robot's thread once its clean-up is done.
        self._future: concurrent.futures.Future[T] = concurrent.futures.Future()
        #: The same, on the caller's loop (nothing is set there once that loop is closed).
        self.outcome = asyncio.wrap_future(self._future, loop=asyncio.get_running_loop())
        self.outcome.add_done_callback(_retrieve)
        self._lock = threading.Lock()
        self._ended = False
        self._interrupted = False

    def cancel(self) -> None:
        """From the caller's loop: never start the call, or make the running one give up.

        Never blocks: a stop request (:meth:`Robot.interrupt`) ends the call's wait at
        its next poll, or at once where a Fleet's loop polls it.
        """
        with self._lock:
            if self._future.cancel() or self._ended or self._interrupted:
                return  # skipped now, or over, or given up already
            self._interrupted = True
            self._owner.robot.interrupt()  # its wait gives up now

    def run(self) -> None:
        """In the robot's thread: the call, then (if cancelled meanwhile) its clean-up."""
        with self._lock:
            if not self._future.set_running_or_notify_cancel():
                return  # skipped
        value: T | None = None
        error: BaseException | None = None
        try:
            value = self._call()
        except BaseException as exc:  # handed to the awaiting coroutine as it is
            error = exc
        with self._lock:
            self._ended = True
            interrupted = self._interrupted
        if interrupted:
            # Nobody waits for what this call started: give it up before the next call.
            live = _live_motion(value, self.follows)
            if live is not None:
                self._owner._give_up_in_thread(live)
            self._owner._end_interrupt()
        if error is not None:
            self._future.set_exception(error)
        else:
            self._future.set_result(value)  # type: ignore[arg-type]  # T when no error

    def unsupervised(self) -> Motion | None:
        """After the call ended uninterrupted: the motion it leaves nobody waiting for."""
        outcome = self.outcome
        if self._interrupted or not outcome.done() or outcome.cancelled() or outcome.exception():
            return None
        return _live_motion(outcome.result(), self.follows)


def _retrieve(future: asyncio.Future[Any]) -> None:
    """Mark an outcome's exception as seen (a cancelled caller may never read it)."""
    if not future.cancelled():
        future.exception()


def _live_motion(value: object, follows: Motion | None) -> Motion | None:
    """The motion a call leaves running or pending: its result, or the one it follows."""
    motion = value if isinstance(value, Motion) else follows
    return None if motion is None or motion.done or motion.abandoned else motion


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

    def send(self, value: Any) -> Any:
        """Run the body on to its next ``await``."""
        return self._body.send(value)

    def throw(self, typ: Any, val: Any = None, tb: Any = None) -> Any:
        """Raise ``typ`` in the body at its current ``await`` (its first, if not started)."""
        if inspect.getcoroutinestate(self._body) == inspect.CORO_CREATED:
            with contextlib.suppress(StopIteration):
                self._body.send(None)  # what it yields is dropped: the throw comes first
        if val is None and tb is None:
            return self._body.throw(typ)
        return self._body.throw(typ, val, tb)  # pragma: no cover - the legacy form

    def close(self) -> None:
        """Close the body (its clean-up runs if it started)."""
        self._body.close()

    def __await__(self) -> Generator[Any, None, T]:
        # Awaited: the body steps on as any awaited coroutine (throws included).
        return self._body.__await__()


# -- the awaited methods, made from the sync ones -----------------------------------------

#: What a method made by :func:`_awaited` says after the sync method's summary.
_AWAITED = (
    "Awaited: :meth:`{}`, run on the robot's thread. Cancelled, it is given up as a sync"
    " call that ends with an exception is (a command the robot has not taken is withdrawn,"
    " a running move is stopped), then the ``CancelledError`` is raised."
)
#: The order of a derived docstring's sections (any other after them).
_ORDER = ("Args", "Returns", "Raises")


def _sections(doc: str) -> dict[str, str]:
    """A Google-style docstring's parts: ``{"": the text before its sections, "Args": ...}``."""
    parts = re.split(r"^(\w[\w ]*):\n", inspect.cleandoc(doc), flags=re.MULTILINE)
    titles, bodies = parts[1::2], parts[2::2]
    return {"": parts[0].strip(), **{t: b.rstrip() for t, b in zip(titles, bodies, strict=True)}}


def _derived_doc(method: Callable[..., Any], own: str) -> str:
    """``method``'s docstring with ``own``'s text after its summary, ``own``'s sections in
    place of its own (Returns), and no example (the sync method's is sync code)."""
    sync, mine = _sections(inspect.getdoc(method) or ""), _sections(own)
    summary, _, rest = sync.pop("").partition("\n\n")
    blocks = [summary, mine.pop(""), rest]
    sections = {t: body for t, body in {**sync, **mine}.items() if not t.startswith("Example")}
    for title in sorted(sections, key=lambda t: _ORDER.index(t) if t in _ORDER else len(_ORDER)):
        blocks.append(f"{title}:\n{sections[title]}")
    return "\n\n".join(block for block in blocks if block)


def _documented(method: Callable[..., Any]) -> Callable[[F], F]:
    """A decorator: the function's docstring is ``method``'s with its own (:func:`_derived_doc`)."""

    def document(function: F) -> F:
        function.__doc__ = _derived_doc(method, function.__doc__ or "")
        return function

    return document


def _derive(
    method: Callable[Concatenate[Any, P], T], then: Callable[[Any, T], R] | None, own: str = ""
) -> Callable[Concatenate[_Front, P], Coroutine[Any, Any, R]]:
    """An ``async def`` that runs ``method`` (by name) on the robot's thread, then ``then``.

    Its name, signature and docstring are ``method``'s: the docstring with a note that it
    is awaited, and with ``own`` (a docstring's sections, such as a Returns that says
    what ``then`` makes: :func:`_derived_doc`); with ``then``, its return annotation is
    ``then``'s name.
    """
    name = method.__name__

    # Named after the method, which it wraps: its signature is the method's.
    @functools.wraps(method, assigned=("__name__",))
    async def awaited(self: _Front, /, *args: P.args, **kwargs: P.kwargs) -> R:
        value = await self._on_thread(name, *args, **kwargs)
        return cast(R, value if then is None else then(self, value))

    if then is not None:
        signature = inspect.signature(method).replace(return_annotation=then.__name__)
        awaited.__signature__ = signature  # type: ignore[attr-defined]
    note = textwrap.fill(_AWAITED.format(method.__qualname__), 88)
    awaited.__doc__ = _derived_doc(method, note + own)
    return awaited


def _awaited(
    method: Callable[Concatenate[Any, P], T],
) -> Callable[Concatenate[_Front, P], Coroutine[Any, Any, T]]:
    """``method`` of the Robot (of its gripper, its I/O), awaited: see :func:`_derive`."""
    return _derive(method, None)


class _Front:
    """An awaited front of the Robot, or of a part of it (``_part``: its gripper, its I/O).

    Its methods made by :func:`_awaited` run the method of the same name on the robot's
    thread (:meth:`_on_thread`); they are named after the class.
    """

    #: The Robot's attribute this front awaits (AsyncRobot awaits the Robot itself).
    _part = ""

    def __init__(self, robot: AsyncRobot) -> None:
        self._robot = robot

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        for name, member in vars(cls).items():
            if inspect.iscoroutinefunction(member) and hasattr(member, "__wrapped__"):
                member.__qualname__ = f"{cls.__qualname__}.{name}"

    def _on_thread(self, name: str, /, *args: Any, **kwargs: Any) -> Coroutine[Any, Any, Any]:
        """The method ``name`` of the part (of the Robot itself), called on the robot's thread."""
        part = getattr(self._robot.robot, self._part) if self._part else self._robot.robot
        return self._robot._run(getattr(part, name), *args, **kwargs)


class AsyncMotion(_Primed[Motion]):
    """A move sent by :meth:`AsyncRobot.start_move`: await it, or ask its progress.

    ``await motion`` waits for the end and returns the finished :class:`~tmmaster.Motion`
    (the same as :meth:`wait`, then :attr:`motion`). It is a coroutine, so that a task
    made of it (``asyncio.wait_for(motion, 5)``, ``asyncio.ensure_future(motion)``,
    ``asyncio.gather(motion)``) runs a wait of its own, and gives the move up when it is
    cancelled, even before its first step, as a cancelled :meth:`wait` does.
    """

    def __init__(self, robot: AsyncRobot, motion: Motion) -> None:
        self._robot = robot
        #: The move itself: its target, phase, last pose, ``withdrawn``,
        #: ``stop_delivered``... (never call its blocking ``wait`` from a coroutine).
        self.motion = motion
        # The run of each task made of the handle (each its own wait, as each ``await``).
        self._runs = weakref.WeakKeyDictionary[object, Coroutine[Any, Any, Motion]]()

    @property
    @_documented(Motion.done)
    def done(self) -> bool:
        return self.motion.done

    @property
    def phase(self) -> MovePhase:
        """Where the move stands."""
        return self.motion.phase

    @_documented(Motion.wait)
    def wait(self, timeout_s: float | None = None) -> Coroutine[Any, Any, None]:
        """Awaited: :meth:`Motion.wait`, run on the robot's thread. Cancelled, the move is
        withdrawn or stopped before the ``CancelledError`` is raised: while the wait is
        queued behind another call of the robot, while it runs, and also when it is
        cancelled before it ever ran (``asyncio.wait_for(motion.wait(), 0)``).

        Returns:
            The wait, a coroutine (await it, or make it a task).
        """
        return self._robot._follow(self.motion, functools.partial(self.motion.wait, timeout_s))

    @_documented(Motion.progress)
    def progress(self) -> Coroutine[Any, Any, MoveProgress]:
        """Awaited: :meth:`Motion.progress`, run on the robot's thread. Cancelled, the move
        is given up as a cancelled :meth:`wait` gives it up.

        Returns:
            The report (a :class:`~tmmaster.MoveProgress`), a coroutine.
        """
        return self._robot._follow(self.motion, self.motion.progress)

    @_documented(Motion.cancel)
    def cancel(self) -> Coroutine[Any, Any, bool]:
        """Awaited: :meth:`Motion.cancel`, run on the robot's thread before any call
        queued there. A wait on the motion running there (another task's ``await
        motion``) gives up now, as a cancelled one does (StopRequestedError), and one
        queued raises it when its turn comes: the move is not left to run to its end
        first.

        Returns:
            Whether the command can no longer run, a coroutine.
        """
        return self._robot._follow(self.motion, self.motion.cancel, first=True)

    @property  # never assigned here: _Primed.__init__ (which sets it) is not called
    def _body(self) -> Coroutine[Any, Any, Motion]:  # type: ignore[override]
        """The run of the task stepping the handle, made at its first step (primed)."""
        task = asyncio.current_task()
        if task not in self._runs:
            self._runs[task] = self._until_done()._body
        return self._runs[task]

    def _until_done(self) -> _Primed[Motion]:
        """:meth:`wait`, then the move: what ``await motion`` and a task made of it run."""
        return self._robot._follow(self.motion, functools.partial(_waited, self.motion))

    def __await__(self) -> Generator[Any, None, Motion]:
        return self._until_done().__await__()


class AsyncRobot(_Front):
    """A :class:`~tmmaster.Robot` driven from asyncio: each call awaited, never blocking.

    Every method is the Robot method of the same name, run on this robot's own thread
    (one call at a time, in the order the calls were made, as a Robot used from one
    thread): the same checks, the one write, the same waits, withdraws and stops. The
    polls of its waits run on the driver's event loop (the process's default one, or
    the robot's Fleet) and the robot's thread is woken only when a poll needs it.

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
        robot: The Robot to drive (not connected yet, or connected); its waits are
            polled on its driver's loop (its Fleet's, or the process's default one).
            The AsyncRobot closes it in :meth:`close`.
        settle_timeout_s: How long a cancelled call may take to give its command up
            before the ``CancelledError`` is raised anyway (the clean-up then goes on in
            the robot's thread, and an error is logged), s.

    Raises:
        ConfigError: ``settle_timeout_s`` is not a finite number > 0.
    """

    def __init__(self, robot: Robot, *, settle_timeout_s: float = DEFAULT_SETTLE_TIMEOUT_S) -> None:
        require_positive("settle_timeout_s", settle_timeout_s)
        super().__init__(self)  # the front of the Robot itself
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
        weakref.finalize(self, self._worker.shutdown, 0.0)  # dropped unclosed: it ends
        self._log = _log.bind(robot=robot.name)
        # True while a stop request of the user's own (interrupt()) stands: a cancelled
        # call's stop request is withdrawn when the call ends, never the user's.
        self._user_stop = False
        # interrupt() and a cancelled call's end take turns: the call's end reads
        # _user_stop and clears the stop request as one step, so an interrupt() of the
        # user's in between is never cleared with it.
        self._stop_lock = threading.Lock()

    # -- attributes (no I/O) -----------------------------------------------------------

    @property
    def name(self) -> str:
        """The robot's name in messages and logs."""
        return self.robot.name

    @property
    @_documented(Robot.last_motion)
    def last_motion(self) -> Motion | None:
        """A cancelled call's command is here too: ``withdrawn`` and ``stop_delivered``
        say how it was given up."""
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

    @_documented(Robot.connect)
    async def connect(self) -> AsyncRobot:
        """Awaited: :meth:`Robot.connect`. A connect that fails, or is cancelled, closes
        this robot."""
        try:
            await self._run(self.robot.connect)
        except BaseException:
            await self.close()
            raise
        return self

    status = _awaited(Robot.status)
    pose = _awaited(Robot.pose)
    check_fault = _awaited(Robot.check_fault)
    wait_until_ready = _awaited(Robot.wait_until_ready)
    wait_until_at_rest = _awaited(Robot.wait_until_at_rest)
    check_move = _awaited(Robot.check_move)
    move_to = _awaited(Robot.move_to)
    start_move = _derive(
        Robot.start_move,
        AsyncMotion,
        "\n\nReturns:\n    The move's handle, an :class:`AsyncMotion`: await it (or its\n"
        "        :meth:`AsyncMotion.wait`), or ask its :meth:`AsyncMotion.progress`.",
    )
    move_joints = _awaited(Robot.move_joints)
    move_by = _awaited(Robot.move_by)
    move_arc = _awaited(Robot.move_arc)
    stop = _awaited(Robot.stop)
    project_state = _awaited(Robot.project_state)
    play = _awaited(Robot.play)
    pause = _awaited(Robot.pause)

    @_documented(Robot.interrupt)
    def interrupt(self) -> None:
        """Never blocks. The stop request stands after a cancelled call (which takes back
        only its own)."""
        with self._stop_lock:
            self._user_stop = True
            self.robot.interrupt()

    @_documented(Robot.clear_stop_request)
    def clear_stop_request(self) -> None:
        """A cancelled call giving its command up keeps its own stop request until it is
        over (its wait may not have seen it yet)."""
        with self._stop_lock:
            self._user_stop = False
            running = self._worker.running
            if running is None or not running._interrupted:
                self.robot.clear_stop_request()

    @_documented(Robot.close)
    async def close(self, *, timeout_s: float | None = None) -> bool:
        """Awaited, on a thread of its own: it does not queue behind a running call, whose
        wait it ends (StopRequestedError); then this robot's thread ends, and calls made
        after it raise TransportClosedError. Cancelled, it still finishes first (bounded
        by :attr:`settle_timeout_s`).
        """
        if timeout_s is not None:
            require_positive("timeout_s", timeout_s)
        # Not queued behind a running call: a thread of its own runs it, as a call.
        closing = _Job(self, functools.partial(self._close_in_thread, timeout_s))
        name = f"tmmaster-aio-close-{self.name}"
        threading.Thread(target=closing.run, name=name, daemon=True).start()
        try:
            return await asyncio.shield(closing.outcome)
        except asyncio.CancelledError:
            deadline = asyncio.get_running_loop().time() + self.settle_timeout_s
            await self._settle(closing.outcome, deadline, "close")
            raise

    def _close_in_thread(self, timeout_s: float | None) -> bool:
        safely = self.robot.close(timeout_s=timeout_s)
        # Calls still queued run now and fail at once: the robot is closed.
        if not self._worker.shutdown(self.settle_timeout_s):
            self._log.error("aio.thread_still_running", timeout_s=self.settle_timeout_s)
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

    def _follow(self, motion: Motion, call: Callable[[], T], *, first: bool = False) -> _Primed[T]:
        """A call that follows ``motion`` (its wait, its progress): cancelled, it gives it up.

        Cancelled before its first step too (:class:`_Primed`). ``first`` (a cancel):
        run before the calls queued, a call following ``motion`` that runs giving up now.
        """
        return _Primed(self._await(_Job(self, call, follows=motion), first=first))

    async def _await(self, job: _Job[T], *, first: bool = False) -> T:
        if not self._worker.submit(job, first=first):
            raise TransportClosedError(f"{self.name}: this robot is closed")
        running = self._worker.running  # queued first: what runs now, not this job
        if first and running is not None and running is not job and running.follows is job.follows:
            running.cancel()  # never blocks: the robot's stop request ends that wait
        try:
            return await asyncio.shield(job.outcome)
        except asyncio.CancelledError:
            await self._give_up(job)
            raise

    async def _give_up(self, job: _Job[Any]) -> None:
        """The caller was cancelled: the call gives up, then whatever it left running."""
        job.cancel()
        deadline = asyncio.get_running_loop().time() + self.settle_timeout_s
        if job._future.cancelled():
            # Never started, so the call itself sent nothing; but a wait queued behind
            # another call follows a move that was sent, and that move is given up: a
            # running wait on it (another caller's) gives up too.
            live = _live_motion(None, job.follows)
            running = self._worker.running
            if live is not None and running is not None and running.follows is live:
                running.cancel()
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
        give_up._interrupted = True  # a stop request of its own (clear_stop_request keeps it)
        if self._worker.submit(give_up, first=True):
            await self._settle(give_up.outcome, deadline, "give_up")

    async def _settle(self, future: asyncio.Future[Any], deadline: float, what: str) -> bool:
        """Wait for ``future`` until ``deadline`` (loop time), whatever cancels the caller."""
        loop = asyncio.get_running_loop()
        while not future.done() and loop.time() < deadline:
            # Cancelled again (a second Ctrl-C): the clean-up still comes first.
            with contextlib.suppress(asyncio.CancelledError):
                await asyncio.wait((future,), timeout=deadline - loop.time())
        if not future.done():
            self._log.error(
                "aio.cancel_unsettled", what=what, settle_timeout_s=self.settle_timeout_s
            )
        return future.done()

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
            with contextlib.suppress(TMMasterError):  # StopRequestedError, after the clean-up
                motion.wait()  # ends at once
        finally:
            self._end_interrupt()
        self._log.warning(
            "aio.motion_given_up",
            command=motion.command.kind.value,
            withdrawn=motion.withdrawn,
            stop_delivered=motion.stop_delivered,
        )


class AsyncGripper(_Front):
    """An :class:`AsyncRobot`'s gripper: the Robot's :class:`~tmmaster.Gripper`, awaited.

    Each call runs on the robot's thread like the robot's own calls; cancelled, its
    command is withdrawn or stopped like a move's.
    """

    _part = "gripper"

    @property
    def kind(self) -> str:
        """The driver's name (a gripper profile's name for the stand-alone grippers)."""
        return self._robot.robot.gripper.kind

    status = _awaited(Gripper.status)
    open = _awaited(Gripper.open)
    close = _awaited(Gripper.close)
    grip = _awaited(Gripper.grip)

    async def holding(self) -> bool:
        """Whether the gripper detects an object now (one status read).

        Returns:
            True when an object is between the fingers.

        Raises:
            TransportError: The read failed.
        """
        return (await self.status()).holding


class AsyncRobotIO(_Front):
    """An :class:`AsyncRobot`'s digital I/O: the Robot's :class:`~tmmaster.RobotIO`, awaited.

    Each call runs on the robot's thread like the robot's own calls. An output write
    passes the robot's command gate: refused unsent once ``close()`` began or while a
    stop is requested.
    """

    _part = "io"

    @property
    @_documented(RobotIO.modules)
    def modules(self) -> tuple[str, ...]:
        return self._robot.robot.io.modules

    set_do = _awaited(RobotIO.set_do)
    do = _awaited(RobotIO.do)
    di = _awaited(RobotIO.di)
    dos = _awaited(RobotIO.dos)
    dis = _awaited(RobotIO.dis)


def _async_connected(make: Callable[P, Robot]) -> Callable[P, AsyncRobot]:
    """An AsyncRobot from ``make``'s arguments, with ``make``'s exact signature."""

    def connect(*args: P.args, **kwargs: P.kwargs) -> AsyncRobot:
        """Open an :class:`AsyncRobot`: ``await`` it, or use it in ``async with``.

        Every argument is :class:`~tmmaster.Robot`'s, with the same defaults: without
        a ``link=`` the robot's link and the polls of its waits run on the process's
        default driver, one event loop shared by every robot (docs/robot-api.md,
        "asyncio"). A ``sim://`` host (an in-process simulator) or a Transport of your
        own as ``link`` keeps its link: the robot's thread polls its waits itself.

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
        return AsyncRobot(make(*args, **kwargs))

    return _named_connect(make, connect)


connect = _async_connected(Robot)
