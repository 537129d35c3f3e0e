"""The in-process simulator: register banks, controller, physics and Modbus servers.

Everything that changes simulator state runs on ONE asyncio event loop in ONE
background thread: the Modbus servers and the control tick. So the register banks
need no locks; calls from other threads (tests, the CLI) are handed to the loop with
``run_coroutine_threadsafe`` and wait for the answer.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any, TypeVar

from .._checks import require_positive, shown
from .._exceptions import ConfigError, ConnectError, UnknownNameError
from .._io import io_address, io_value
from .._pose import DEFAULT_HOME, Pose
from .._profiles import DEFAULT_PROFILE, robot_profile
from .._registers import GripperProfile, Handshake, RobotProfile, Table
from .._retry import RetryPolicy
from .._robot_models import RobotModel
from .._transport import Transport
from ._backend import ObjectState, PhysicsBackend
from ._bank import RegisterBank
from ._clear_on_accept import ClearOnAcceptController
from ._controller import MotionRecord, RobotController
from ._faults import Fault, NetworkFault, is_network_fault, parse_fault
from ._kinematic import KinematicBackend
from ._memory import register_endpoint, unregister_endpoint
from ._options import PHYSICS_BACKENDS, Cell, Listen, RobotSetup, Timing
from ._server import DeviceServer, RequestLog, RequestRecord
from ._world import GraspMode, GripperGeometry, World

if TYPE_CHECKING:
    from ._grippers import Blog2FG7Device, OnRobot2FG7Device

T = TypeVar("T")

#: How long a call from another thread waits for the loop before giving up.
_CALL_TIMEOUT_S = 10.0

#: Numbers the ``sim://sim-N`` names of simulators made without a name.
_SIM_NUMBERS = itertools.count(1)


def _as_fault(fault: Fault | str) -> Fault:
    return parse_fault(fault) if isinstance(fault, str) else fault


def _split_faults(faults: Iterable[Fault | str]) -> tuple[list[NetworkFault], list[Fault]]:
    """The faults to play: the network faults (the servers play them), then the others."""
    parsed = [_as_fault(f) for f in faults]
    network: list[NetworkFault] = [f for f in parsed if is_network_fault(f)]  # type: ignore[misc]
    return network, [f for f in parsed if not is_network_fault(f)]


def _backend_of(
    cell: Cell | PhysicsBackend | None, model: RobotModel
) -> tuple[PhysicsBackend, Cell | None]:
    """The physics backend, and the Cell it simulates (None: your own backend)."""
    if cell is None or isinstance(cell, Cell):
        cell = Cell() if cell is None else cell
        return _built_in_backend(cell, model), cell
    if isinstance(cell, PhysicsBackend):
        return cell, None
    raise ConfigError(f"cell must be a Cell or a PhysicsBackend, got {shown(cell)}")


def _group(option: str, value: object, kind: type[T], expected: str = "") -> T:
    """``value`` when it is a ``kind`` (None: the default one); else a ConfigError."""
    if value is None:
        return kind()
    if not isinstance(value, kind):
        expected = expected or f"a {kind.__name__}"
        raise ConfigError(f"{option} must be {expected}, got {shown(value)}")
    return value


class _Ticker:
    """Runs the control ticks on the event loop, each due ``period`` after the one before.

    A due tick runs before anything observes the simulator (:meth:`catch_up`: each
    request's data, each call) and at most ``batch`` wall seconds after it was due: while
    nothing observes the simulator, the due ticks run back to back, each with its own due
    time, for what waking the thread once a tick cost (10-30 times the tick's own CPU).
    While ``eager()`` is true (the start-up) each tick runs at its time. A schedule more
    than ten periods behind its batches (a stalled machine) restarts instead of
    bursting. Ticks slower than their period (a busy machine, a slow program or physics)
    run from the timer, a period's worth of wall time each loop turn, with the requests
    answered in between and not made to wait for more ticks. An exception from ``tick``
    stops the ticking and goes to ``failed``.
    """

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        period: float,
        tick: Callable[[float], None],
        failed: Callable[[BaseException], None],
        *,
        batch: float = 0.0,
        eager: Callable[[], bool] = lambda: False,
    ) -> None:
        self._loop = loop
        self._period = period
        self._tick = tick
        self._failed = failed
        self._batch = max(batch, 0.0)
        self._eager = eager
        self._due = time.monotonic()  # when the next tick is due
        self._ticking = False  # a tick runs now (a call it makes must not tick again)
        self._behind = False  # slow ticks left due ticks to the timer's next turns
        self._stopped = False
        self._handle: asyncio.Handle | None = loop.call_soon(self._on_timer)

    def catch_up(self) -> None:
        """Run every tick due by now, in order, before something observes the simulator.

        Nothing inside a tick, once stopped, or while slow ticks are behind: the timer
        runs those between requests, as one wake-up a tick would (an observer waits for
        the tick running, never for more).
        """
        if not (self._ticking or self._stopped or self._behind):
            self._run_due()
            if self._behind and self._handle is not None:  # the rest: from the next turn
                self._handle.cancel()
                self._handle = self._loop.call_soon(self._on_timer)

    def _run_due(self) -> None:
        now = time.monotonic()
        if now - self._due > self._batch + 10 * self._period:
            self._due = now  # a stalled machine: restart the schedule
        self._ticking = True
        try:
            while self._due <= now:
                self._tick(self._due)
                self._due += self._period
                if time.monotonic() - now > self._period:
                    self._behind = True  # slow ticks: answer what waits first
                    break
        except Exception as exc:
            self.cancel()
            self._failed(exc)
        finally:
            self._ticking = False

    def _on_timer(self) -> None:
        self._handle = None
        self._behind = False
        self._run_due()
        if self._stopped:
            return
        now = time.monotonic()
        if self._behind:  # the rest on the next loop turn, requests answered in between
            self._handle = self._loop.call_soon(self._on_timer)
        else:
            wait = max(self._due - now, 0.0) + (0.0 if self._eager() else self._batch)
            self._handle = self._loop.call_later(wait, self._on_timer)

    def cancel(self) -> None:
        """No tick after this one."""
        self._stopped = True
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None


class Simulator:
    """A simulated TM robot (and optional gripper) served over Modbus TCP on loopback.

    Nothing starts before :meth:`start` (or ``with``). ``python -m tmmaster.sim`` runs
    one from the command line.

    Example:
        A simulator on a free loopback port, a robot connected to it, one move:

        ```python
        from tmmaster import Pose, connect
        from tmmaster.sim import Simulator

        with Simulator(time_scale=10) as sim:  # the tmflow profile, 10x real time
            with connect(sim.host, sim.port) as robot:
                robot.move_to(Pose(300, -200, 200, 180, 0, 90), speed=50)
            print(sim.tcp_pose(), sim.motion_log()[-1].kind)  # ... ptp
        ```

        ``Simulator(listen=False)`` opens no socket: ``connect(sim.url)`` reaches it
        in-process. The other options come in groups, each checked when it is made
        (``listen=Listen(host=..., port=..., gripper_port=...)`` for fixed ports):

        ```python
        from tmmaster.sim import DEFAULT_PART_POSE, Cell, RobotSetup, Simulator, TableObject
        from tmmaster.sim import Timing

        part = TableObject(name="part", pose=DEFAULT_PART_POSE, mass_kg=0.5)
        sim = Simulator(
            "tmflow",
            time_scale=10,
            robot=RobotSetup(model="tm5-900", gripper="onrobot-2fg7"),
            cell=Cell(scene=[part], grasp="weld"),  # or your own PhysicsBackend
            timing=Timing(tick_hz=100),
        )
        print(sim.url, sim.tool)  # sim://sim-N None: not started yet
        ```

    Args:
        profile: The robot's register map: ``"tmflow"`` (default), ``"article"``, a
            TOML file or a RobotProfile.
        time_scale: Simulated seconds per wall second (10: a 2 s move takes 0.2 s).
        listen: True (the default): Modbus TCP on a free loopback port (``sim.port``);
            a :class:`Listen`: on that host and those ports; False: no TCP listener at
            all, reach it in-process at ``sim.url``.
        name: The in-process name (``sim.url`` is ``"sim://NAME"``); default
            ``sim-1``, ``sim-2``...; unique among running simulators.
        robot: The arm model, the separate gripper, the program (:class:`RobotSetup`);
            None: a TM5-700 without a separate gripper, running the generated program
            on tmflow.
        cell: The table and its parts, the tool, the grasp and the physics engine
            (:class:`Cell`; None: ``Cell()``, one part on the table, kinematic), or
            your own :class:`PhysicsBackend`, which models all of that itself.
        timing: The control tick rate and the robot's start-up time (:class:`Timing`).
        faults: Faults to play from the start: Fault models or ``"kind:key=value,..."``
            texts (:func:`parse_fault`).
        request_listener: Called with each RequestRecord, on the simulator's thread.
        wait_ready: True (the default): :meth:`start` (and ``with``) returns, and
            ``sim.url`` opens, only once the robot (and gripper) finished its start-up
            (``Timing.init_time_s``): tmflow's project runs and its program took its
            first steps, so a command written right after takes effect. False: at once,
            while it still initialises (to test a master against a robot that boots).

    Raises:
        ConfigError: a bad argument, named in the message: ``time_scale`` not a finite
            number above 0, a group of the wrong type, ``initial_seq`` outside the
            profile's sequence range, a program on a profile without the sequence
            handshake, ``resume_after_error`` on such a profile, two objects of one
            name, an unknown profile, ``dynamics=True`` for a model whose link masses
            are not known. (Each group checks its own fields when it is made.)
    """

    def __init__(
        self,
        profile: str | Path | RobotProfile = DEFAULT_PROFILE,
        *,
        time_scale: float = 1.0,
        listen: bool | Listen = True,
        name: str | None = None,
        robot: RobotSetup | None = None,
        cell: Cell | PhysicsBackend | None = None,
        timing: Timing | None = None,
        faults: Iterable[Fault | str] = (),
        request_listener: Callable[[RequestRecord], None] | None = None,
        wait_ready: bool = True,
    ) -> None:
        self._time_scale = require_positive("time_scale", time_scale)
        setup = _group("robot", robot, RobotSetup)
        timing = _group("timing", timing, Timing)
        bound = None if isinstance(listen, bool) else listen
        where = _group("listen", bound, Listen, "True, False or a Listen")
        self._profile = robot_profile(profile)
        self._model = setup.arm
        self._tick_hz = timing.tick_hz
        self._batch_s = timing.batch_s
        self._host = where.host
        #: False: no TCP listener; reach it in-process through :attr:`url`.
        self.listen = listen is not False
        self._url = f"sim://{name or f'sim-{next(_SIM_NUMBERS)}'}"
        self._backend, self._cell = _backend_of(cell, self._model)
        network, device = _split_faults(faults)
        self._log = RequestLog(listener=request_listener)
        controller, handshake_options = _controller_class(self._profile, setup, self.tool)
        self._bank = controller.bank_for(self._profile)
        self._controller = controller(
            self._profile,
            self._bank,
            self._backend,
            self._model,
            faults=device,
            init_time_s=timing.init_time_s,
            initial_seq=setup.initial_seq,
            speed_factor=1.0 if self._cell is None else float(self._cell.speed_factor),
            **handshake_options,
        )
        self._controller.clock = self._wall_clock
        if hasattr(self._controller, "stamp_scale"):  # a Script Project: GetNowStamp
            self._controller.stamp_scale = self._time_scale
        self._robot_server = DeviceServer(
            "robot",
            self._bank,
            host=where.host,
            port=where.port,
            log=self._log,
            device_id=None,  # the TM controller ignores the unit id
            tcp=self.listen,
        )
        self._servers = [self._robot_server]
        self._add_gripper(setup.gripper_profile, where, device, timing.init_time_s)
        for server in self._servers:
            server.set_faults(network)
        self._init_lifecycle(timing.init_time_s, wait_ready)

    def _init_lifecycle(self, init_time_s: float, wait_ready: bool) -> None:
        """The state of the loop thread and the start-up: nothing runs yet."""
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ticker: _Ticker | None = None
        self._tick_due: float | None = None  # the due time of the tick running now
        self._tick_error: BaseException | None = None
        #: Control ticks run so far (a plain int: reading it from another thread is safe).
        self.ticks = 0
        self._closed = False
        self._init_time_s = init_time_s
        self._wait_ready = wait_ready
        #: Set once every device finished its start-up (at once with wait_ready=False),
        #: or the tick failed: start() returns and ``sim.url`` opens then.
        self._ready = threading.Event()

    def _add_gripper(
        self,
        profile: GripperProfile | None,
        where: Listen,
        faults: Sequence[Fault],
        init_time_s: float,
    ) -> None:
        """The separate gripper device and its server (none without a gripper profile)."""
        self._gripper_profile = profile
        self._gripper_bank: RegisterBank | None = None
        self._gripper: Blog2FG7Device | OnRobot2FG7Device | None = None
        self._gripper_server: DeviceServer | None = None
        if profile is None:
            return
        # Imported here: the gripper devices are only needed with a separate gripper.
        from ._grippers import GRIPPER_DEVICES

        self._gripper_bank = RegisterBank(profile)
        self._gripper = GRIPPER_DEVICES[profile.driver](
            profile,
            self._gripper_bank,
            self._backend,
            faults=faults,
            init_time_s=init_time_s,
            # One backend, stepped once per tick: the robot controller steps it.
            step_backend=False,
        )
        self._gripper_server = DeviceServer(
            "gripper",
            self._gripper_bank,
            host=where.host,
            port=where.gripper_port,
            log=self._log,
            # The Compute Box answers its own unit id only; the article's Isaac Sim
            # server (blog-2fg7) answers any.
            device_id=profile.device_id if profile.own_unit_id_only else None,
            max_connections=profile.max_connections,
            tcp=self.listen,
        )
        self._servers.append(self._gripper_server)

    # -- properties ---------------------------------------------------------------------

    @property
    def host(self) -> str:
        """Address the servers listen on."""
        return self._host

    @property
    def url(self) -> str:
        """The in-process address (``sim://name``): ``Robot(sim.url)`` needs no socket."""
        return self._url

    @property
    def port(self) -> int:
        """The robot's Modbus TCP port (the real one after start with port 0)."""
        return self._robot_server.port

    @property
    def gripper_port(self) -> int | None:
        """The separate gripper's Modbus TCP port, or None without such a gripper."""
        return None if self._gripper_server is None else self._gripper_server.port

    @property
    def profile(self) -> RobotProfile:
        """The robot profile being served."""
        return self._profile

    @property
    def gripper_profile(self) -> GripperProfile | None:
        """The separate gripper's profile, or None."""
        return self._gripper_profile

    @property
    def backend(self) -> PhysicsBackend:
        """The physics backend (call its methods through :meth:`call` while running)."""
        return self._backend

    @property
    def tool(self) -> Pose | None:
        """The TCP in the flange frame (TCP = flange x tool): the :class:`Cell`'s.

        Returns:
            The tool, or None: the TCP is the flange (or your own backend's tool).
        """
        return None if self._cell is None else self._cell.tool

    @property
    def physics(self) -> str | None:
        """The built-in physics backend's name (``"kinematic"``, ``"mujoco"``).

        Returns:
            The name, or None with your own backend.
        """
        return None if self._cell is None else self._cell.physics

    @property
    def dynamics(self) -> bool:
        """Whether the physics backend models the arm's dynamics (see ``dynamics``).

        Returns:
            True with the mujoco backend's torque-limited joint servos (the default for
            the TM5-700 and TM5-900), False with an ideal servo (the kinematic backend,
            ``dynamics=False``, a model without link masses, or your own backend unless
            it has a true ``dynamics`` attribute).
        """
        return getattr(self._backend, "dynamics", False) is True

    @property
    def time_scale(self) -> float:
        """Simulated seconds per wall second."""
        return self._time_scale

    @property
    def running(self) -> bool:
        """True between start() and close()."""
        return self._thread is not None and not self._closed

    # -- lifecycle ----------------------------------------------------------------------

    def start(self) -> Simulator:
        """Start the event loop thread, the servers and the control tick; return self.

        Returns:
            This simulator, running.

        Raises:
            ConfigError: another running simulator of this process has the same
                :attr:`url` (its name); nothing was started.
            RuntimeError: the simulator was closed (make a new one).
            OSError: a listening port could not be bound.
        """
        if self._closed:
            raise RuntimeError("a closed Simulator cannot be restarted; make a new one")
        if self._thread is not None:
            return self
        # First: a name another running simulator holds is refused before anything starts.
        register_endpoint(self._url, self._open_memory_transport)
        loop = asyncio.new_event_loop()
        self._loop = loop
        self._thread = threading.Thread(target=self._run_loop, name="tmmaster-sim", daemon=True)
        self._thread.start()
        try:
            asyncio.run_coroutine_threadsafe(self._start_async(), loop).result(_CALL_TIMEOUT_S)
            self._wait_started_up()
        except BaseException:
            self.close()
            raise
        return self

    def _wait_started_up(self) -> None:
        """Wait until every device finished its start-up (the tick sets the event)."""
        if not self._wait_ready:
            self._ready.set()
            return
        # init_time_s in wall seconds, and room for a machine that is slow to tick.
        budget = self._init_time_s / self._time_scale + _CALL_TIMEOUT_S
        if not self._ready.wait(budget):
            raise RuntimeError(
                f"the simulated robot did not finish starting up within {budget:g} s"
            )
        if self._tick_error is not None:
            raise RuntimeError("the simulator's control tick failed") from self._tick_error

    def _started_up(self) -> bool:
        """Every device finished initialising (tmflow: its project started in that tick)."""
        gripper = self._gripper
        return self._controller.initialised and (gripper is None or gripper.initialised)

    def close(self) -> None:
        """Stop servers, tick and thread; safe to call more than once.

        Its :attr:`url` is free again afterwards: a new simulator may take the name.
        """
        if self._closed:
            return
        self._closed = True
        self._ready.set()  # a connect waiting for the start-up goes on (and finds it closed)
        # Only our own registration: a simulator refused for a taken name frees nothing.
        unregister_endpoint(self._url, self._open_memory_transport)
        loop, thread = self._loop, self._thread
        if loop is None or thread is None:
            return
        if loop.is_running():
            with contextlib.suppress(Exception):
                asyncio.run_coroutine_threadsafe(self._stop_async(), loop).result(_CALL_TIMEOUT_S)
            loop.call_soon_threadsafe(loop.stop)
        thread.join(_CALL_TIMEOUT_S)

    def __enter__(self) -> Simulator:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def _run_loop(self) -> None:
        loop = self._loop
        assert loop is not None
        asyncio.set_event_loop(loop)
        try:
            loop.run_forever()
        finally:
            # Like asyncio.run(): cancel what is left (pymodbus request tasks) and close.
            pending = [t for t in asyncio.all_tasks(loop) if not t.done()]
            for task in pending:
                task.cancel()
            if pending:
                loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
            # Closing transports finish on a later loop turn (their sockets close in a
            # call_soon callback): give them those turns before the loop goes away.
            for _ in range(3):
                loop.run_until_complete(asyncio.sleep(0))
            loop.run_until_complete(loop.shutdown_asyncgens())
            loop.close()

    async def _start_async(self) -> None:
        for server in self._servers:
            await server.start()
        self._ticker = ticker = _Ticker(
            asyncio.get_running_loop(),
            1.0 / self._tick_hz,
            self._tick_once,
            self._tick_failed,
            batch=self._batch_s,
            eager=lambda: not self._ready.is_set(),
        )
        for server in self._servers:
            server.before_data = ticker.catch_up

    async def _stop_async(self) -> None:
        if self._ticker is not None:
            self._ticker.cancel()
        for server in self._servers:
            await server.stop()

    def _tick_once(self, due: float) -> None:
        """One control tick: ``1 / tick_hz`` wall seconds, times ``time_scale`` simulated.

        ``due``: the ``time.monotonic()`` it is due, which the motion log records.
        """
        dt_sim = (1.0 / self._tick_hz) * self._time_scale
        self._tick_due = due
        try:
            self._controller.tick(dt_sim)
            if self._gripper is not None:
                self._gripper.tick(dt_sim)
        finally:
            self._tick_due = None
        self.ticks += 1
        if not self._ready.is_set() and self._started_up():
            self._ready.set()

    def _wall_clock(self) -> float:
        """``time.monotonic()``, or in a tick the time that tick was due."""
        return time.monotonic() if self._tick_due is None else self._tick_due

    def _catch_up(self) -> None:
        """Run the ticks due by now (on the loop thread): something observes the robot."""
        if self._ticker is not None:
            self._ticker.catch_up()

    def _tick_failed(self, exc: BaseException) -> None:
        # Ticking stops; wait_for() and start() report it: a hidden bug would otherwise
        # look like a robot that never moves.
        self._tick_error = exc
        self._ready.set()  # start() reports it

    # -- calls from any thread ----------------------------------------------------------

    def _call(self, fn: Callable[[], T]) -> T:
        """Run ``fn`` on the loop thread (directly when not running) and return its result."""
        loop = self._loop
        if loop is None or self._closed or not loop.is_running():
            return fn()
        if threading.current_thread() is self._thread:
            self._catch_up()
            return fn()

        async def wrapper() -> T:
            self._catch_up()
            return fn()

        return asyncio.run_coroutine_threadsafe(wrapper(), loop).result(_CALL_TIMEOUT_S)

    def call(self, fn: Callable[[], T]) -> T:
        """Run ``fn`` on the simulator's loop thread and return its result.

        Args:
            fn: What to run (between two control ticks).

        Returns:
            What ``fn`` returned.
        """
        return self._call(fn)

    def call_later(self, delay_s: float, fn: Callable[[], object]) -> None:
        """Run ``fn`` on the loop thread after ``delay_s`` wall seconds (dropped when closed).

        Args:
            delay_s: Wall seconds to wait.
            fn: What to run.
        """
        loop = self._loop
        if loop is not None and not self._closed and loop.is_running():
            loop.call_soon_threadsafe(loop.call_later, max(delay_s, 0.0), self._call, fn)

    def device_server(self, device: str = "robot") -> DeviceServer:
        """The request path (gate, log, network faults) of ``"robot"`` or ``"gripper"``."""
        if device == "robot":
            return self._robot_server
        if device == "gripper" and self._gripper_server is not None:
            return self._gripper_server
        raise ConfigError(f"this simulator has no {device!r} device (known: robot, gripper)")

    def _open_memory_transport(
        self,
        *,
        role: str,
        device_id: int,
        timeout: float,
        retry: RetryPolicy | None,
        name: str,
    ) -> Transport:
        from ._memory import MemoryTransport

        # The name resolves once the robot started up (start() returns then, too): a
        # master on another thread that connects meanwhile waits for it.
        if not self._ready.wait(max(timeout, self._init_time_s / self._time_scale)):
            raise ConnectError(f"{self._url} is still starting up: not ready within {timeout:g} s")
        return MemoryTransport(
            self, role, device_id=device_id, timeout=timeout, retry=retry, name=name
        )

    @property
    def request_log(self) -> list[RequestRecord]:
        """A copy of every Modbus request received so far (robot and gripper)."""
        return self._log.records()

    def clear_request_log(self) -> None:
        """Forget the recorded requests."""
        self._log.clear()

    def objects(self) -> list[ObjectState]:
        """Every object in the scene with its pose and whether it is held.

        Returns:
            One state per object.
        """
        return self._call(self._backend.objects)

    def tcp_pose(self) -> Pose:
        """The arm's current TCP pose.

        Returns:
            The TCP pose, mm / deg.
        """
        return self._call(self._backend.tcp_pose)

    def displayed(self) -> list[str]:
        """Every ``Display()`` text the robot's Script Project showed, in order (tmflow).

        Returns:
            The texts; empty for a profile without a program (``article``).
        """
        texts = getattr(self._controller, "displayed", None)
        return [] if texts is None else self._call(lambda: list(texts))

    def field(self, name: str, *, device: str = "robot") -> Any:
        """Engineering value of a field of the robot's (or ``device="gripper"``) register map.

        Args:
            name: A field of the device's profile.
            device: ``"robot"`` or ``"gripper"``.

        Returns:
            The field's engineering value now.

        Raises:
            ConfigError: The simulator has no such device.
        """
        bank = self._bank if device == "robot" else self._gripper_bank
        if bank is None:
            raise ConfigError(f"no {device} register bank in this simulator")
        return self._call(lambda: bank.get(name))

    def set_di(self, channel: int, value: bool, *, module: str = "control_box") -> None:
        """Drive digital input ``channel`` of ``module``, as the wiring of a real cell would.

        The input reads ``value`` for every master from then on (FC 02 at the address
        the profile gives, e.g. control box DI 3 at discrete input 3). On the ``tmflow``
        profile the end-module DI the robot program reads as its gripper's grip signal
        (DI 0 by default) is driven by the simulated gripper at every tick.

        Args:
            channel: The DI number, from 0 (control box 0-15, end module 0-3 on tmflow).
            value: True: high; False: low.
            module: ``"control_box"`` or ``"end_module"`` (the profile's modules).

        Raises:
            ConfigError: A profile without digital I/O, an unknown module, a channel out
                of range or not an int, a value that is not a bool.
        """
        address = io_address(self._profile, module, "di", channel)
        bit = int(io_value(value, f"{module} DI {channel}"))
        bank = self._bank
        self._call(lambda: bank.write(Table.DISCRETE_INPUT, address, [bit], device=True))

    def do(self, channel: int, *, module: str = "control_box") -> bool:
        """What digital output ``channel`` of ``module`` is now (as a master last set it).

        Args:
            channel: The DO number, from 0 (control box 0-15, end module 0-3 on tmflow).
            module: ``"control_box"`` or ``"end_module"`` (the profile's modules).

        Returns:
            True when the output is high.

        Raises:
            ConfigError: A profile without digital I/O, an unknown module, a channel out
                of range or not an int.
        """
        address = io_address(self._profile, module, "do", channel)
        bank = self._bank
        return bool(self._call(lambda: bank.read(Table.COIL, address, 1))[0])

    def inject(self, fault: Fault | str) -> None:
        """Add a fault at run time (a Fault model or a ``"kind:k=v,..."`` spec).

        Args:
            fault: The fault; request counts start now.

        Raises:
            ConfigError: A text that is not a valid fault.
        """
        parsed = _as_fault(fault)

        def apply() -> None:
            if is_network_fault(parsed):
                for server in self._servers:
                    server.add_fault(parsed)  # type: ignore[arg-type]
            else:
                self._controller.inject(parsed)
                if self._gripper is not None:
                    self._gripper.inject(parsed)

        self._call(apply)

    def clear_faults(self) -> None:
        """Remove every injected fault (network and device)."""

        def apply() -> None:
            for server in self._servers:
                server.set_faults(())
            self._controller.clear_faults()
            if self._gripper is not None:
                self._gripper.clear_faults()

        self._call(apply)

    def clear_error(self) -> None:
        """Clear the robot's error state, as an operator would on the pendant."""
        self._call(self._controller.clear_error)

    def press_estop(self) -> None:
        """Press the emergency stop now, as an operator would."""
        self._call(self._controller.press_estop)

    def press_play(self) -> None:
        """Press Play on the pendant (tmflow: starts the project if the robot can run)."""
        self._call(self._controller.press_play)

    def motion_log(self) -> tuple[MotionRecord, ...]:
        """Every motion and gripper action the robot started, in order (the ground truth).

        Returns:
            One record per motion or gripper action.
        """
        return self._call(lambda: self._controller.motion_log)

    def drop_connections(self) -> None:
        """Close every client connection now (robot and gripper listeners keep listening)."""

        def apply() -> None:
            for server in self._servers:
                server.drop_connections()

        self._call(apply)

    def wait_for(
        self, predicate: Callable[[], bool], timeout: float = 5.0, *, interval: float = 0.005
    ) -> None:
        """Poll ``predicate`` until true; raise TimeoutError after ``timeout`` wall seconds.

        Args:
            predicate: The condition, called from this thread.
            timeout: Wall seconds to wait at most.
            interval: Wall seconds between two calls of ``predicate``.

        Raises:
            TimeoutError: The condition was not met in time.
            RuntimeError: The simulator's control tick failed.
        """
        deadline = time.monotonic() + timeout
        while True:
            if self._tick_error is not None:
                raise RuntimeError("the simulator's control tick failed") from self._tick_error
            if predicate():
                return
            if time.monotonic() >= deadline:
                raise TimeoutError(f"condition not met within {timeout} s")
            time.sleep(interval)


def _controller_class(
    profile: RobotProfile, setup: RobotSetup, tool: Pose | None
) -> tuple[type[RobotController], dict[str, Any]]:
    """The controller class of ``profile``'s handshake, and its options from ``setup``.

    One controller class per handshake (as the client has one channel per handshake):
    the article's clears on accept; the sequence handshake is a TMflow project, the
    robot program interpreted (ScriptProjectController).
    """
    program = setup.program
    if program is None and profile.handshake is Handshake.SEQUENCE:
        program = "generated"  # the robot program tmmaster ships, interpreted
    controller: type[RobotController] = ClearOnAcceptController
    options: dict[str, Any] = {}
    if program is not None:
        controller, options = _script_project(profile, program, tool)
    if setup.resume_after_error:
        if profile.handshake is not Handshake.SEQUENCE:
            raise ConfigError(
                "resume_after_error is a TMflow project setting: it needs a"
                f" sequence-handshake profile, not {profile.name!r}"
            )
        options["resume_after_error"] = True
    if setup.project_speed != 100:
        if profile.handshake is not Handshake.SEQUENCE:
            raise ConfigError(
                "project_speed is a TMflow project setting: it needs a sequence-handshake"
                f" profile, not {profile.name!r}"
            )
        options["project_speed"] = setup.project_speed
    return controller, options


def _built_in_backend(cell: Cell, model: RobotModel) -> PhysicsBackend:
    """The built-in physics backend ``cell`` names, simulating its world for ``model``."""
    world, gripper = cell.world()
    return physics_backend(
        cell.physics,
        _faster(model, cell.speed_factor),
        world=world,
        tool=cell.tool,
        gripper=gripper,
        grasp=cell.grasp,
        dynamics=cell.dynamics,
    )


def _script_project(
    profile: RobotProfile, program: str | Path, tool: Pose | None
) -> tuple[type[RobotController], dict[str, Any]]:
    """The controller that runs a Script Project, and its options (ConfigError if it can't).

    ``program``: "generated" (``tmmaster robot-program`` for the profile and ``tool``) or
    a Script Project file.
    """
    if profile.handshake is not Handshake.SEQUENCE:
        raise ConfigError(
            f"program: a Script Project runs on a sequence-handshake profile (tmflow),"
            f" not {profile.name!r}"
        )
    # Imported here: the interpreter is loaded only by a simulator that runs a program.
    from .._robot_program import robot_program
    from ._script_project import ScriptProjectController, simulated_tool

    if program == "generated":
        text = robot_program(profile, tool=simulated_tool(tool))
    else:
        path = Path(program)
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise ConfigError(f"program {path}: cannot read it ({exc})") from exc
    return ScriptProjectController, {"program": text}


def _faster(model: RobotModel, factor: float) -> RobotModel:
    """The arm ``factor`` times faster than ``model``: every move takes 1/factor the time."""
    if factor == 1:
        return model
    joints = tuple(
        j.model_copy(update={"speed_deg_s": j.speed_deg_s * factor}) for j in model.joints
    )
    return model.model_copy(
        update={
            "joints": joints,
            "tcp_speed_mm_s": model.tcp_speed_mm_s * factor,
            "accel_time_s": model.accel_time_s / factor,
        }
    )


def physics_backend(
    name: str,
    model: RobotModel,
    *,
    world: World,
    tool: Pose | None = None,
    gripper: GripperGeometry | None = None,
    grasp: GraspMode = "friction",
    dynamics: bool | None = None,
) -> PhysicsBackend:
    """A built-in physics backend by name: "kinematic" (analytic) or "mujoco" (optional extra).

    Args:
        name: ``"kinematic"`` or ``"mujoco"``.
        model: The arm.
        world: The table, fixtures and parts.
        tool: The TCP in the flange frame (None: the TCP is the flange).
        gripper: The fingers' stroke, pads and friction (None: an OnRobot 2FG7).
        grasp: ``"friction"`` or ``"weld"``.
        dynamics: Arm dynamics: the links carry Techman's masses and inertias and each
            joint is a servo limited to its effort (docs/physics-backends.md). None: on
            for ``"mujoco"`` and a model whose link masses are known (TM5-700, TM5-900),
            off otherwise; False: the ideal servo (the kinematic backend has nothing
            else); True: on, where it can be.

    Returns:
        The backend.

    Raises:
        UnknownNameError: Another name.
        PhysicsUnavailableError: The MuJoCo extra is missing.
        ConfigError: ``dynamics=True`` with the kinematic backend, or for an arm model
            whose link masses are not known.
    """
    if name == "kinematic":
        if dynamics:
            raise ConfigError("dynamics: the kinematic backend has none (physics='mujoco')")
        return KinematicBackend(model, world=world, tool=tool, gripper=gripper, grasp=grasp)
    if name == "mujoco":
        from ._mujoco import MuJoCoBackend, has_dynamics_data  # imports mujoco: when asked

        if dynamics and not has_dynamics_data(model.name):
            raise ConfigError(f"dynamics: no link masses for the {model.name} model")
        return MuJoCoBackend(
            model,
            world=world,
            home=DEFAULT_HOME,
            tool=tool,
            gripper=gripper,
            grasp=grasp,
            dynamics=dynamics,
        )
    raise UnknownNameError(
        f"unknown physics backend {name!r} (known: {', '.join(PHYSICS_BACKENDS)})"
    )


def simulator_summary(sim: Simulator) -> Sequence[str]:
    """Human-readable lines saying where the simulator listens."""
    lines = [
        f"robot   modbus tcp {sim.host}:{sim.port}  profile={sim.profile.name}"
        f" handshake={sim.profile.handshake.value} unit id: any",
    ]
    gp = sim.gripper_profile
    if gp is not None:
        unit = gp.device_id if gp.own_unit_id_only else "any"
        limit = f" max connections={gp.max_connections}" if gp.max_connections else ""
        lines.append(
            f"gripper modbus tcp {sim.host}:{sim.gripper_port}  profile={gp.name}"
            f" unit id: {unit}{limit}"
        )
    elif sim.profile.has("gripper_command"):
        lines.append("gripper in the robot's register map (gripper_command)")
    if sim.tool is not None:
        lines.append(f"tool    TCP = flange x {sim.tool}")
    if sim.physics is not None:
        servo = (
            "on (torque-limited joint servos: the arm lags, done once settled)"
            if sim.dynamics
            else "off (ideal servo: the joints are where the trajectory says)"
        )
        lines.append(f"physics {sim.physics}, arm dynamics {servo}")
    return lines
