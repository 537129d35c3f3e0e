"""The robot API: connect, read typed status, move safely, drive the gripper.

Every move follows the same rules, whatever the profile:

1. validate the pose (codec range, workspace envelope, reach) and the speed: an
   invalid move raises before a single byte is sent;
2. check the robot can take it (no error, idle, nothing pending);
3. write target, speed and command in one request, exactly once;
4. wait for the acknowledgement (bounded by ``ack_timeout_s``), then for completion
   (bounded by a timeout derived from the move), polling on a monotonic clock;
5. a robot error, error mode or e-stop ends the wait at once with a typed error.

Completion is never inferred from an idle flag alone: the robot must have
acknowledged the command first, and the final pose must be at the target.

This module is the Robot's lifecycle and its public verbs. Its parts: the planner
(``_planning.py``: step 1's checks, the joints seed, expected times and timeouts, no
I/O) and the command path (``_command.py``: the gate, the one write, the waits, and
giving a command up safely).
"""

from __future__ import annotations

import atexit
import functools
import inspect
import threading
import time
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal, ParamSpec, TypeVar

from . import _commanded
from ._address import check_host, check_port, is_in_process
from ._channels import (
    REUSE_DONE_READ_S,
    Command,
    CommandChannel,
    CommandKind,
    channel_for,
    pose_from,
)
from ._checks import Bounds, require_in, require_positive, shown
from ._codec import allowed_range, encode
from ._command import SETTLE_S, _MotionFollower
from ._command import Motion as Motion  # tmmaster imports it from here
from ._exceptions import (
    ConfigError,
    ConnectError,
    IllegalAddressError,
    MotionTimeoutError,
    ProfileMismatchError,
    RobotError,
    StopRequestedError,
    TMMasterError,
    TransportClosedError,
)
from ._fleet import (
    Fleet,
    FleetMember,
    LoopTransport,
    fleet_driver,
    join_fleet,
    open_transport,
    wake_waits,
)
from ._following import STALL_FLOOR_S
from ._gripper import GRIPPER_DRIVERS, Gripper, GripperLink, NoGripper, auto_gripper
from ._heartbeat import Heartbeat
from ._io import RobotIO
from ._logging import get_logger
from ._options import ORIENTATION_BOUNDS, POSITION_BOUNDS, Checks, GripperDevice, speed_limit
from ._options import FrameCheck as FrameCheck  # tmmaster imports it from here
from ._planning import Planner, check_accel, joint_values, motion_type, moved, offset_pose
from ._planning import TimeoutPolicy as TimeoutPolicy  # tmmaster imports it from here
from ._planning import Workspace as Workspace  # tmmaster imports it from here
from ._poller import INTERVAL_BOUNDS, TICK_S, Poller, PollPolicy
from ._pose import MotionType, Pose
from ._profiles import (
    DEFAULT_PROFILE,
    builtin_profile_names,
    gripper_profile,
    load_profile,
    robot_profile,
)
from ._project import PRESS_TIMEOUT_S, ProjectControl
from ._registers import ROBOT_BASE_FLANGE_FIELDS, TCP_FIELDS, GripperProfile, RobotProfile, Role
from ._retry import RetryPolicy
from ._robot_models import RobotModel, robot_model
from ._sigint import deferred
from ._status import ProjectState, RobotStatus, project_hint
from ._tool import FrameGuard, Tool, tool_option
from ._transport import ConnectionState, Transport, TransportStats

_log = get_logger("tmmaster.robot")
#: The connected Robots not closed yet (by id: a subclass may have no hash), closed by the
#: exit hook. Held weakly: a Robot the program dropped unclosed is garbage (its heartbeat
#: stops, its link is given back), never one that beats its session beside the next's.
_OPEN: weakref.WeakValueDictionary[int, Robot] = weakref.WeakValueDictionary()

#: The speed (deg/s) under which :meth:`Robot.wait_until_at_rest` counts a joint still.
REST_SPEED_DEG_S = 0.05
_P = ParamSpec("_P")
_T = TypeVar("_T")
_F = TypeVar("_F", bound=Callable[..., object])
_PolicyT = TypeVar("_PolicyT")  # an option object's class


def _link(link: object) -> tuple[Transport | None, Fleet | None]:
    """The ``link`` option: a ready Transport, a Fleet whose loop runs the link, or None."""
    if link is None:
        return None, None
    if isinstance(link, Fleet):
        return None, link
    if isinstance(link, Transport):
        return link, None
    raise ConfigError(
        f"link must be a tmmaster.Transport or a tmmaster.Fleet, got {type(link).__name__}"
    )


def _policy(name: str, value: object, kind: type[_PolicyT], *, default: bool = True) -> _PolicyT:
    """``value`` when it is a ``kind`` (None: the default one, where ``default``); a
    ConfigError otherwise."""
    if value is None and default:
        return kind()
    if not isinstance(value, kind):
        raise ConfigError(f"{name} must be a tmmaster.{kind.__name__}, got {value!r}")
    return value


@dataclass(frozen=True)
class _Options:
    """A Robot's option objects, checked (docs/robot-api.md)."""

    polling: PollPolicy
    timeouts: TimeoutPolicy
    retry: RetryPolicy | None
    checks: Checks

    @classmethod
    def checked(
        cls, polling: object, timeouts: object, retry: RetryPolicy | None, checks: object
    ) -> _Options:
        """Each option object checked for its type (None: the default one)."""
        return cls(
            _policy("polling", polling, PollPolicy),
            _policy("timeouts", timeouts, TimeoutPolicy),
            retry,
            _policy("checks", checks, Checks),
        )

    def gripper(
        self,
        spec: str | Path | GripperProfile | GripperDevice | Gripper | None,
        profile: RobotProfile,
        links: _Links,
    ) -> Gripper:
        """The gripper for ``spec``: an instance as given, "auto" what the profile offers.

        A stand-alone gripper listens at the gripper's address of ``links`` (a
        GripperDevice's, else the robot's host), or speaks over its ready link.
        """
        if isinstance(spec, Gripper):
            return spec
        if spec is None or spec == "none":
            return NoGripper()
        if spec == "auto":
            return auto_gripper(profile, settle_s=self.timeouts.gripper_settle_s)
        link = GripperLink(
            host=links.gripper_host,
            port=links.gripper_port,
            retry=self.retry,
            request_timeout_s=self.timeouts.request_s,
            poll_interval_s=self.polling.interval_s,
            timeout_s=self.timeouts.gripper_timeout_s,
            ack_timeout_s=self.timeouts.ack_timeout_s,
            transport=links.gripper_transport,
        )
        device = gripper_profile(spec.profile if isinstance(spec, GripperDevice) else spec)
        return GRIPPER_DRIVERS[device.driver](device, link)  # on its own connection


@dataclass(frozen=True)
class _Links:
    """Where a Robot and its stand-alone gripper are, checked (or their ready links)."""

    host: str
    port: int
    #: The ``link`` option: a ready transport, or the Fleet whose loop runs the link.
    transport: Transport | None
    fleet: Fleet | None
    gripper_host: str
    gripper_port: int
    gripper_transport: Transport | None

    @classmethod
    def checked(cls, host: str, port: int, link: object, gripper: object) -> _Links:
        """The addresses checked (an in-process host, sim://name, has no port).

        A ready transport (``link``, a GripperDevice's) leaves its address unchecked. A
        stand-alone gripper is at a GripperDevice's host (which it checked itself), else
        at the robot's host, port 502.
        """
        transport, fleet = _link(link)
        if transport is None:
            host = check_host(host, field="host", port_field="port")
            if not is_in_process(host):
                port = check_port(port, field="port")
        gripper_host, gripper_port, gripper_transport = None, 502, None
        if isinstance(gripper, GripperDevice):
            gripper_host, gripper_port = gripper.host, gripper.port
            gripper_transport = gripper.transport
        if gripper_transport is None and not is_in_process(gripper_host or host):
            gripper_port = check_port(gripper_port, field="gripper.port")
        gripper_host = gripper_host or host
        return cls(host, port, transport, fleet, gripper_host, gripper_port, gripper_transport)

    def open(self, profile: RobotProfile, name: str, options: _Options) -> Transport:
        """The robot's link: the ready one, a Fleet's, or one opened to ``host:port``.

        An in-process ``host`` ("sim://name") opens through the plugin that registered it;
        any other is opened on the process's default driver.
        """
        link: dict[str, Any] = {
            "device_id": profile.device_id,
            "timeout": options.timeouts.request_s,
            "retry": options.retry,
            "name": name,
        }
        if self.fleet is not None:
            return join_fleet(self.fleet, self.host, self.port, **link)
        return self.transport or open_transport(self.host, self.port, **link)


@dataclass(frozen=True)
class _Mount:
    """What a Robot hands its gripper driver (:class:`~tmmaster._gripper.GripperMount`)."""

    name: str
    profile: RobotProfile
    link: Transport
    require_connection: Callable[[], None]
    stop_event: threading.Event
    poll_interval_s: float
    gripper_timeout_s: float
    ack_timeout_s: float
    check_fault: Callable[[], None]
    checked_status: Callable[[], RobotStatus]
    run_command: Callable[[CommandKind, float | None], None]
    #: A gripper command write through the robot's command gate (refused unsent once
    #: close() began or while a stop is requested).
    gated: Callable[[Callable[[], None]], None]

    @property
    def transport(self) -> Transport:
        """The robot's link; TransportClosedError before :meth:`Robot.connect`."""
        self.require_connection()
        return self.link


class Robot:
    """A connection to one robot (and its gripper) speaking one profile.

    Every move is validated before a byte is sent (speed, workspace, the arm's reach,
    the profile's encodable range), written once, acknowledged, waited for on a
    monotonic clock and checked at its end (docs/robot-api.md). Nothing connects before
    :meth:`connect` (or ``with``); :func:`~tmmaster.connect` does both. Before that, a
    command or a read raises :class:`TransportClosedError` naming the fix (nothing is
    sent; the checks of a move and of its arguments come first). One Robot is used by
    one thread; :meth:`interrupt` is the call meant for other threads.

    Example:
        Against the simulator (``python -m tmmaster.sim --port 5020``):

        ```python
        from tmmaster import Pose, Robot

        robot = Robot("127.0.0.1", 5020, name="cell-1")
        with robot:  # connects; closes (withdrawing anything outstanding) at the end
            robot.wait_until_ready()
            robot.move_to(Pose(300, -200, 200, 180, 0, 90), speed=50)
            robot.move_to(Pose(300, -200, 150, 180, 0, 90), speed=10, motion="line")
            print(robot.pose(), robot.status().ready)
        ```

    Args:
        host: The robot's address: an IP address or a host name, or ``"sim://NAME"``
            for an in-process simulator (``Simulator(listen=False)``).
        port: The robot's Modbus TCP port.
        profile: The register map the robot speaks: ``"tmflow"`` (the default, the
            robot program's sequence handshake), ``"article"``, a TOML file or a
            RobotProfile.
        model: The arm: ``"tm5-700"``, ``"tm5-900"``, ``"tm12"``, ``"tm14"`` or a
            RobotModel; inverse kinematics of every target, and expected motion times.
        gripper: ``"auto"`` (what the profile offers), None, ``"blog-2fg7"``,
            ``"onrobot-2fg7"``, a gripper TOML file or a GripperProfile (a stand-alone
            gripper at the robot's host, port 502), a :class:`GripperDevice` (one at
            an address or on a ready link of its own), or a Gripper.
        tool: The TCP in the flange frame (mm, deg): poses are TCP poses, TCP = flange
            x tool; a :class:`Tool` carries its mass as well (checked at connect against
            the robot's, Techman's 7366); None: the TCP is the flange.
        name: The robot's name in messages and logs.
        polling: How waits poll: the nominal interval (``interval_s``, 0.001 to 5 s)
            and the dense windows around the acknowledgement and the expected end;
            None: ``PollPolicy()`` (50 ms).
        timeouts: The bound of one Modbus request (``request_s``), the
            acknowledgement, motion and gripper timeouts, a register gripper's settle
            time; None: ``TimeoutPolicy()``.
        retry: How transient failures are retried (never a command write); None:
            ``RetryPolicy()``, up to 12 attempts within 10 s.
        checks: What is checked before a move is sent and at its end (workspace, speed
            cap, tolerances, units) and at connect (the frame check); None:
            ``Checks()``.
        link: A ready Transport for the robot's link instead of one opened to
            ``host:port``, or a Fleet: the robot's link and the polls of its waits on
            the fleet's event loop (not with a ``sim://`` host).

    Raises:
        ConfigError: An invalid argument, named in the message with its range where it
            has one (an unknown profile or model: RegisterMapError). The setters of
            the options check what the option objects check.
    """

    def __init__(
        self,
        host: str,
        port: int = 502,
        *,
        profile: str | Path | RobotProfile = DEFAULT_PROFILE,
        model: str | RobotModel = "tm5-700",
        gripper: str | Path | GripperProfile | GripperDevice | Gripper | None = "auto",
        tool: Pose | Tool | None = None,
        name: str = "robot",
        polling: PollPolicy | None = None,
        timeouts: TimeoutPolicy | None = None,
        retry: RetryPolicy | None = None,
        checks: Checks | None = None,
        link: Transport | Fleet | None = None,
    ) -> None:
        # The addresses first, then every option, before anything is opened.
        links = _Links.checked(host, port, link, gripper)
        #: The robot's register map.
        self.profile = robot_profile(profile)
        arm = model if isinstance(model, RobotModel) else robot_model(model)
        options = _Options.checked(polling, timeouts, retry, checks)
        #: The robot's name in messages and logs.
        self.name = name
        tool_pose, tool_spec = tool_option(tool, options.checks.units, arm)
        #: The check of the robot's TCP against ``tool`` at :meth:`connect`.
        self.frame_check = options.checks.frame
        self._transport = links.open(self.profile, name, options)
        self._log = _log.bind(robot=name)
        self._open_command_path(options)
        # The frame check, at connect and before every move (_tool.py).
        self._frames = FrameGuard(self._channel, self.frame_check, tool_spec, self._log)
        # Checks and plans every move from where the arm is believed to be (no I/O).
        self._planner = Planner(
            arm,
            workspace=options.checks.workspace,
            tool=tool_pose,
            check_units=options.checks.units,
            max_speed_percent=options.checks.max_speed_percent,
            settings=self._follower,
            log=self._log,
        )
        self._planner.tcp_speed_limit_mm_s = options.checks.tcp_speed_limit_mm_s
        # A move at its deadline asks again (None, no read, where the profile has none).
        self._follower.project_speed = self._read_project_speed
        self._connected = False
        # What the last close() found: True when nothing it sent can still run.
        self._closed_safely: bool | None = None
        #: The last command sent; while it is not settled, close() withdraws or stops it.
        self._last_motion: Motion | None = None
        #: The robot's gripper (a NoGripper when there is none).
        self.gripper = options.gripper(gripper, self.profile, links)
        self.gripper.attach(self._mount())
        # Whole, it joins its driver (a Fleet closing from now on closes it; one closing
        # since links.open() refuses it), and a StatusMonitor.add() of its link is refused.
        self._shared = self._join(links.fleet)
        _commanded.register(self.name, self._transport)

    def _open_command_path(self, options: _Options) -> None:
        """The channel over the link, the stop event, the follower and its gate; the I/O
        and the TMflow project's Play and Pause, whose writes pass the same gate."""
        self._channel: CommandChannel = channel_for(self.profile, self._transport)
        self._stop_event = threading.Event()
        # Retry sleeps of reads end at once on a stop request, like every poll.
        self._transport.interrupt = self._stop_event
        # Sends once, polls, waits for and gives up safely every command (each Motion
        # has it); every command write passes its gate, never after close() or a stop
        # request began. It holds the polling, timeout and tolerance settings.
        self._follower = _MotionFollower(
            self._channel,
            self._stop_event,
            self._log,
            polling=options.polling,
            timeouts=options.timeouts,
            position_tolerance_mm=options.checks.position_tolerance_mm,
            orientation_tolerance_deg=options.checks.orientation_tolerance_deg,
        )
        self._gate = self._follower.gate
        self._io = RobotIO(
            self.profile, self._transport, self._gate, self._log, self._require_connection
        )
        # Pressed only when asked.
        self._project = ProjectControl(
            self.profile, self._transport, self._channel, self._gate, self._stop_event, self._log
        )
        # The master's heartbeat (tmflow), from the first command to close (_heartbeat.py).
        self._heartbeat = Heartbeat(
            self.profile,
            self._transport,
            period_s=options.timeouts.heartbeat_s,
            ttl_s=options.timeouts.heartbeat_ttl_s,
            log=self._log,
        )
        self._follower.silence = self._heartbeat.stop  # while a give-up is owed
        self._follower.renew = self._heartbeat.renew

    def _join(self, fleet: Fleet | None) -> FleetMember | None:
        """A robot whose link is on a driver (its Fleet's, or the process's default one):
        the polls of its waits run on that driver's loop."""
        transport = self._transport
        if not isinstance(transport, LoopTransport):
            return None  # in process (sim://): the robot's thread polls
        member = fleet_driver(fleet or transport.fleet, self, self._channel, transport, self._gate)
        self._follower.shared_driver = member.follow
        return member

    def _mount(self) -> _Mount:
        """What the gripper driver gets of this robot: never the Robot itself."""
        return _Mount(
            name=self.name,
            profile=self.profile,
            link=self._transport,
            require_connection=self._require_connection,
            stop_event=self._stop_event,
            poll_interval_s=self.poll_interval_s,
            gripper_timeout_s=self.timeouts.gripper_timeout_s,
            ack_timeout_s=self.timeouts.ack_timeout_s,
            check_fault=self.check_fault,
            checked_status=self._checked_status,
            run_command=self._run_command,
            gated=functools.partial(self._gate.write, None),
        )

    # -- settings (the follower's: every wait reads them when it starts) ---

    @property
    def poll_interval_s(self) -> float:
        """Seconds between two polls of a wait (its nominal pace)."""
        return self._follower.polling.interval_s

    @poll_interval_s.setter
    def poll_interval_s(self, value: float) -> None:
        interval = require_in("poll_interval_s", value, INTERVAL_BOUNDS)
        self._follower.polling = self._follower.polling.model_copy(update={"interval_s": interval})

    @property
    def polling(self) -> PollPolicy:
        """How waits poll: the nominal interval and when a move is polled densely."""
        return self._follower.polling

    @polling.setter
    def polling(self, value: PollPolicy) -> None:
        self._follower.polling = _policy("polling", value, PollPolicy, default=False)

    @property
    def timeouts(self) -> TimeoutPolicy:
        """How long waits may take (acknowledgement, motion, gripper, in-flight write).

        A new policy applies to the next wait; its ``request_s``,
        ``gripper_settle_s``, ``heartbeat_s`` and ``heartbeat_ttl_s`` are read when the
        robot is made (they bound its link, its gripper and its heartbeat), and are those
        a robot keeps.
        """
        return self._follower.timeouts

    @timeouts.setter
    def timeouts(self, value: TimeoutPolicy) -> None:
        self._follower.timeouts = _policy("timeouts", value, TimeoutPolicy, default=False)

    @property
    def position_tolerance_mm(self) -> float:
        """How far (mm) the final TCP may be from the target of a finished move."""
        return self._follower.position_tolerance_mm

    @position_tolerance_mm.setter
    def position_tolerance_mm(self, value: float) -> None:
        self._follower.position_tolerance_mm = require_in(
            "position_tolerance_mm", value, POSITION_BOUNDS
        )

    @property
    def orientation_tolerance_deg(self) -> float:
        """How far (deg) the final TCP orientation may be from the target's."""
        return self._follower.orientation_tolerance_deg

    @orientation_tolerance_deg.setter
    def orientation_tolerance_deg(self, value: float) -> None:
        self._follower.orientation_tolerance_deg = require_in(
            "orientation_tolerance_deg", value, ORIENTATION_BOUNDS
        )

    @property
    def max_speed_percent(self) -> int:
        """Faster moves are refused, % (an integer in [1, 100])."""
        return self._planner.max_speed_percent

    @max_speed_percent.setter
    def max_speed_percent(self, value: int) -> None:
        self._planner.max_speed_percent = speed_limit(value)

    @property
    def checks(self) -> Checks:
        """What is checked now: the workspace, speed cap, tolerances, units, frame check.

        Made from the properties below (each has a setter); read-only itself.
        """
        return Checks.model_construct(
            workspace=self.workspace,
            max_speed_percent=self.max_speed_percent,
            position_tolerance_mm=self.position_tolerance_mm,
            orientation_tolerance_deg=self.orientation_tolerance_deg,
            units=self.check_units,
            frame=self.frame_check,
            tcp_speed_limit_mm_s=self._planner.tcp_speed_limit_mm_s,
        )

    # -- what a move is planned with (the planner's) ---------------------------

    @property
    def model(self) -> RobotModel:
        """The arm model: inverse kinematics of every target, expected motion times.

        Set, it must be a built-in model's name (``"tm12"``, as ``Robot(model=)`` takes
        it) or a :class:`RobotModel`, whose rated payload carries the ``tool``'s mass and,
        when connected, which the arm's reported joints fit (one read, as :meth:`connect`
        checks them): anything else is a ConfigError naming ``model`` (an unknown name:
        UnknownNameError, listing the models) or ``tool.mass_kg``, the model not taken.
        That read is connect's, frame check included: a failed read (TransportError) or a
        robot TCP that is no longer the ``tool`` (ToolMismatchError) also leaves the model
        as it was. ``article`` publishes neither joints nor frames: nothing is read there.
        """
        return self._planner.model

    @model.setter
    def model(self, value: str | RobotModel) -> None:
        value = robot_model(value) if isinstance(value, str) else value  # as Robot(model=)
        model = _policy("model", value, RobotModel, default=False)
        tool_option(self._frames.tool, False, model)  # a Tool's mass within its rated payload
        old, self._planner.model = self._planner.model, model
        try:  # connected: the arm's joints must fit it, as connect() checks them
            if self._connected:
                self._read_arm_at_connect()
        except BaseException:
            self._planner.model = old
            raise

    @property
    def workspace(self) -> Workspace:
        """Where the tool may go: the table plane (on by default) and the TCP's box.

        Set, it must be a :class:`Workspace`: anything else is a ConfigError naming
        ``workspace``, the workspace not taken.
        """
        return self._planner.workspace

    @workspace.setter
    def workspace(self, value: Workspace) -> None:
        self._planner.workspace = _policy("workspace", value, Workspace, default=False)

    @property
    def tool(self) -> Pose | None:
        """The TCP in the flange frame (mm, deg); poses are TCP poses: TCP = flange x tool.

        Set, it is checked as ``Robot(tool=)`` checks it (ConfigError, the tool not taken):
        a Pose, not in metres or radians (``check_units``), and on a profile that cannot
        verify a tool (``article``) only with the frame check off. A :class:`Tool` gives
        its pose and its mass, which must be within the model's rated payload and is
        checked against the robot's at :meth:`connect` (a Pose has none to check).
        """
        return self._planner.tool

    @tool.setter
    def tool(self, value: Pose | None) -> None:
        # Robot(tool=)'s checks: what connect() refuses (article), the units, the type.
        self._frames.refuse_unverifiable(value)
        self._planner.tool, self._frames.tool = tool_option(value, self.check_units, self.model)

    @property
    def check_units(self) -> bool:
        """Whether a target or ``tool`` that looks like metres or radians is refused.

        Refused with :class:`~tmmaster.UnitsError` (docs/robot-api.md, "Units"). Set, it
        must be True or False: anything else is a ConfigError naming ``check_units``; set to
        True, a ``tool`` already set that looks like metres is refused, the setting not taken.
        """
        return self._planner.check_units

    @check_units.setter
    def check_units(self, value: bool) -> None:
        if not isinstance(value, bool):
            raise ConfigError(f"check_units must be True or False, got {shown(value)}")
        tool_option(self.tool, value, self.model)  # a tool set before, now in the units checked
        self._planner.check_units = value

    # -- connection -------------------------------------------------------

    @property
    def state(self) -> ConnectionState:
        """Connection state of the robot link."""
        return self._transport.state

    @property
    def stats(self) -> TransportStats:
        """Request, retry, reconnect and byte counters of the robot link."""
        return self._transport.stats

    def connect(self) -> Robot:
        """Open the connections (robot, then gripper if it has its own); a no-op when open.

        Where the profile publishes them (``tmflow``: Techman's 7001-7036, one request,
        and the TCP in the robot base, 7049-7060), it then reads the robot's flange, joints
        and TCP: the :class:`FrameCheck` compares the TCP with flange x ``tool``, and the
        joints seed the first plan. A connect that fails closes the robot.

        Returns:
            This robot, connected.

        Raises:
            ConnectError: the robot was closed, or cannot be reached.
            ConfigError: the frame check found the robot's TCP is not its flange x
                ``tool`` (naming the tool offset the robot appears to have), or not in
                the robot base.
            IllegalAddressError: the device does not serve the profile's registers
                (:class:`ProfileMismatchError` when it answers another built-in
                profile's).
        """
        if self._transport.state is ConnectionState.CLOSED:
            raise ConnectError(
                f"{self.name}: this Robot was closed; create a new Robot to connect again"
            )
        if self._connected:
            return self
        try:
            self._transport.connect()
            self.gripper.connect()
            self._read_arm_at_connect()
            self._read_project_speed()
        except BaseException:
            # ``with Robot(...)`` never reaches __exit__ when connecting fails: close
            # here so a half-open robot link is not left behind.
            self.close()
            raise
        self._connected = True
        _OPEN[id(self)] = self
        atexit.unregister(_close_at_exit)  # registered last: it runs before earlier hooks
        atexit.register(_close_at_exit)
        self._log.info(
            "robot.connected",
            host=self._transport.host,
            port=self._transport.port,
            profile=self.profile.name,
        )
        return self

    def _require_connection(self) -> None:
        """Refuse I/O before :meth:`connect`: nothing connects on its own.

        Connected, a give-up still owed goes first (``_MotionFollower.settle_owed``): the
        withdraw and stop of a command given up while the link was down.

        Raises:
            TransportClosedError: never connected (a closed robot's link says so itself).
            CommandStateUnknownError: a give-up still owed could not be delivered.
        """
        if self._connected or self._transport.state is ConnectionState.CLOSED:
            self._follower.settle_owed()
            return
        raise TransportClosedError(
            f"{self.name}: not connected, nothing was sent: call robot.connect() first, or"
            " open it with `with tmmaster.connect(...) as robot:` (or `with robot:`)"
        )

    def _read_arm_at_connect(self) -> None:
        """At connect: the frame check (:class:`~tmmaster._tool.FrameGuard`: the frames,
        the TCP value and mass) and the robot's joints, in one read where contiguous.

        Raises:
            ConfigError: a tool the profile cannot verify, with the frame check on.
            ToolMismatchError: the robot's TCP, base, TCP value or mass are not the
                master's tool (or its base not the robot base), with the frame check on.
        """
        channel, frames = self._channel, self._frames
        frames.check = self.frame_check
        frames.refuse_unverifiable(self.tool)
        check, fields = frames.enabled, channel.plan_fields
        if check and not channel.frames_in_plan:
            fields = (*channel.flange_fields, *fields, *channel.robot_base_tcp_fields)
        if not check and not channel.joint_fields:
            return  # nothing to check, nothing to seed from
        values = self._read_naming_profile(functools.partial(channel.read, fields))
        if check:
            frames.at_connect(values, self.tool)
        if (joints := channel.joints_from(values)) is not None:
            if channel.frames_in_plan:  # the flange in the robot base: whatever tool and base
                self._planner.check_model(pose_from(values, ROBOT_BASE_FLANGE_FIELDS), joints)
            self._planner.take_robot_joints(pose_from(values, TCP_FIELDS), joints)

    def _read_naming_profile(self, read: Callable[[], _T]) -> _T:
        """``read()``; refused (IllegalAddressError), the ProfileMismatchError naming the
        built-in profile the device answers instead, where one does."""
        try:
            return read()
        except IllegalAddressError as exc:
            if (mismatch := _profile_mismatch(self._transport, self.profile, exc)) is None:
                raise
            raise mismatch from exc

    def _read_project_speed(self) -> float | None:
        """The robot's project speed (``tmflow``: 7101, one request), for the next plans:
        TMflow runs every move at its speed times the project speed."""
        fields = self.profile.published(("project_speed",))  # none: None
        return self._planner.take_project_speed(self._channel.read(fields))

    def close(self, *, timeout_s: float | None = None) -> bool:
        """Withdraw (or stop) a command still outstanding, then close every connection.

        Safe to call more than once, and from any thread. From the moment it is called,
        no command is written any more; a command write already in flight on another
        thread finishes first and is then withdrawn or stopped like any other, whichever
        thread wrote it. Waits in progress end with :class:`StopRequestedError`. In the
        main thread, Ctrl-C is held back until the clean-up is done.

        Args:
            timeout_s: a bound on the clean-up (the retries of the withdraw or stop, the
                wait for a withdraw's answer, a stand-alone gripper's stop included);
                None: the retry policy's own bounds. Each step still gets its first
                attempt (one request each); a command write in flight, which may still
                land and run, is waited out (one request) and given up the same way.

        Returns:
            True when nothing this robot sent can still run; False when a withdraw or
            stop (the gripper's too) could not be confirmed (logged as
            ``robot.close_unconfirmed``).

        Raises:
            ConfigError: ``timeout_s`` is not a finite number > 0.
        """
        if timeout_s is not None:
            require_positive("timeout_s", timeout_s)
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        with deferred():
            self._gate.close()
            for link in (self._transport, self.gripper.transport):  # before any clean-up
                if deadline is not None and link is not None:
                    link.bound_retries(deadline)
            self.interrupt()  # waits in progress end now, a fleet's included
            # Another thread's wait for a withdraw's answer ends now: it stops the command
            # instead, and this close finishes at once (its own withdraw is not ended so).
            self._follower.closing.set()
            if self._closed_safely is None or self._transport.state is not ConnectionState.CLOSED:
                # No beat from now on: the robot program expires what is left, and the
                # give-up's requests do not wait behind beats on a slow link.
                self._heartbeat.stop()
                self._closed_safely = self._give_up_outstanding(deadline)
                self._closed_safely = self.gripper.disconnect() and self._closed_safely
                self._transport.close()
            # Only now: until the clean-up is over, the exit hook may still have it to do.
            _OPEN.pop(id(self), None)
            safely = self._closed_safely
        if not safely:
            self._log.error("robot.close_unconfirmed")
        return safely

    def _give_up_outstanding(self, deadline: float | None) -> bool:
        """For :meth:`close`: withdraw or stop the last command written, if not settled
        (one poll first: a move that finished unwatched is left as it is)."""
        if self._transport.state is ConnectionState.CLOSED:
            return True  # closed by someone else: nothing can be written any more
        self._gate.drain()  # past the deadline too: a write in flight may land and run
        # After drain(): the last command that can ever be written.
        if (motion := self._last_motion) is None:
            return True
        reason = StopRequestedError("the robot connection is closing")
        return self._follower.abandon(motion, reason, deadline=deadline, closer=True)

    @property
    def io(self) -> RobotIO:
        """The robot's digital I/O: control-box and end-module DOs and DIs (RobotIO)."""
        return self._io

    @property
    def last_motion(self) -> Motion | None:
        """The last command sent (move or gripper action), with its outcome."""
        return self._last_motion

    @property
    def can_stop(self) -> bool:
        """True when the profile defines a way to stop the arm (:meth:`stop`)."""
        return self._channel.can_stop

    def check_fault(self) -> None:
        """Read the fewest registers that tell; raise the typed error if in e-stop or error.

        Raises:
            RobotFaultError: The robot is in error (EmergencyStopError: in e-stop).
            TransportError: The read failed (TransportClosedError: never connected).
            CommandStateUnknownError: A command given up earlier still owes its withdraw or
                stop (the link was down): nothing is sent until that is delivered
                (docs/safety.md).
        """
        self._require_connection()
        if (failure := self._channel.read_failure()) is not None:
            raise failure

    def __enter__(self) -> Robot:
        return self.connect()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- status -----------------------------------------------------------

    def status(self) -> RobotStatus:
        """One immutable snapshot: each status block read in one request.

        Returns:
            The robot's mode, motion, error, e-stop, grasp, TCP pose and joints (where
            the profile publishes them: tmflow reads them with the pose, one request).

        Raises:
            TransportError: The read failed (ProfileMismatchError when the device answers
                another built-in profile's registers).
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        self._require_connection()
        status = self._read_naming_profile(self._channel.read_status)
        self._planner.take_project_speed(status.raw)  # tmflow: 7101, read with the status
        return status

    def pose(self) -> Pose:
        """The current TCP pose.

        Returns:
            The TCP pose the robot reports, mm / deg.

        Raises:
            TransportError: The read failed (TransportClosedError: never connected).
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        self._require_connection()
        return self._channel.read_pose()

    def wait_until_ready(self, timeout_s: float = 10.0) -> RobotStatus:
        """Poll until the robot can take a motion command (auto / running, idle, no error).

        Args:
            timeout_s: How long to wait, s.

        Returns:
            The first status that is ready.

        Raises:
            MotionTimeoutError: Not ready in time.
            RobotFaultError: The robot is in error (EmergencyStopError for an e-stop).
            StopRequestedError: A stop was requested.
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        require_positive("timeout_s", timeout_s)
        deadline = time.monotonic() + timeout_s
        poller = Poller(self.poll_interval_s, self._stop_event, deadline=deadline)
        while True:
            poller.check()
            status = self._checked_status()  # a ready robot is in neither e-stop nor error
            if status.ready:
                return status
            if time.monotonic() >= deadline:
                raise MotionTimeoutError(
                    f"robot not ready after {timeout_s:g} s ({status}){project_hint(status)}",
                    pose=status.pose,
                )
            poller.sleep()

    def wait_until_at_rest(self, timeout_s: float = PRESS_TIMEOUT_S) -> RobotStatus:
        """Poll until the arm is at rest: after :meth:`stop`, an e-stop, a move given up.

        On ``tmflow``, ``status().moving`` is the robot program's state and reads False
        while a stopped arm still brakes; this reads the arm. At rest: two reads at
        least ``STALL_FLOOR_S`` (0.5 s) apart, and every read between them, show the arm
        not moving, with the TCP within 0.5 mm and 0.5 deg of the first, and, where the
        profile publishes Techman's Joint Speed (tmflow: 7949-7960, one request more per
        read, never read by a move's polls, read before the status), every joint slower
        than ``REST_SPEED_DEG_S`` (0.05 deg/s). Joint speeds that lag the arm, or pose
        registers that stand still for a few cycles while it moves, only delay the
        answer; on a real TM they are not verified (docs/safety.md).

        Args:
            timeout_s: How long to wait, s (5 by default). A read begun before it ends
                that finds the arm still is followed by the read ``STALL_FLOOR_S`` later
                that confirms the rest, however short ``timeout_s`` is or slow the link
                (at most that floor and a read more).

        Returns:
            The status read that found the arm at rest (read after the joint speeds:
            its pose is where the arm rests).

        Raises:
            MotionTimeoutError: The arm still moves after ``timeout_s``.
            StopRequestedError: A stop was requested (:meth:`interrupt`).
            TransportError: A read failed.
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        require_positive("timeout_s", timeout_s)
        poller, deadline = Poller(STALL_FLOOR_S, self._stop_event), time.monotonic() + timeout_s
        first: RobotStatus | None = None
        while True:
            poller.check()
            # late: this read begins past the deadline. One begun before it that finds the
            # arm still is confirmed by the next (the sleep is not cut), however slow the link.
            late = time.monotonic() >= deadline
            # Joints first: a pose read after the joints were found still is where the arm
            # rests, even from a gateway that serves one sample twice.
            if self._joints_turning() | (now := self.status()).moving:
                first = None
            elif first is None or not now.pose.is_close(first.pose):
                first = now
            elif now.timestamp - first.timestamp >= STALL_FLOOR_S:
                return now
            if time.monotonic() >= deadline and (first is not now or late):
                raise MotionTimeoutError(f"arm still moving after {timeout_s:g} s", pose=now.pose)
            poller.sleep_until(now.timestamp + STALL_FLOOR_S)

    def _joints_turning(self) -> bool:
        """Whether a joint turns faster than ``REST_SPEED_DEG_S``, by Techman's Joint Speed
        J1..J6 (deg/s, TMflow 2.24 appendix C p. 317; one read): on ``tmflow`` the
        status's ``moving`` is the robot program's, idle while a stopped arm still brakes.
        False where the profile publishes no joint speeds."""
        speeds = self.profile.published([f"joint_speed_{j}" for j in range(1, 7)])
        return any(abs(float(v)) > REST_SPEED_DEG_S for v in self._channel.read(speeds).values())

    # -- moves ------------------------------------------------------------

    def validate_move(
        self, pose: Pose, speed: int, *, seed_deg: Sequence[float] | None = None
    ) -> tuple[float, ...]:
        """Check a move (speed, workspace, inverse kinematics); return the target's joints.

        Raises :class:`ConfigError` (:class:`UnreachablePoseError` for a pose the arm
        cannot take) when the move is not allowed; sends nothing. The joints are searched
        from ``seed_deg``, else from where the arm is believed to be: the joints the robot
        reported (at :meth:`connect` and before each move, where the profile publishes
        them) moved on to each commanded target's; without published joints, the last
        commanded target's (the model's ready posture before the first move).

        Args:
            pose: The TCP target.
            speed: Speed, an integer percent (1 .. ``max_speed_percent``).
            seed_deg: Joints to search from; None: where the arm is believed to be.

        Returns:
            The target's joints, deg.

        Raises:
            ConfigError: The move is not allowed (UnitsError for a target that looks
                like metres or radians, UnreachablePoseError for a pose the arm cannot
                take).
        """
        return self._planner.validate(pose, speed, seed_deg)

    def expected_motion_time(
        self,
        start: Pose,
        target: Pose,
        speed: float,
        motion: MotionType,
        *,
        accel_time_ms: int | None = None,
    ) -> float:
        """Expected duration of a move from the arm model (joint-space PTP, checked Line), s.

        Args:
            start: The TCP pose at the start.
            target: The TCP target.
            speed: Speed, %.
            motion: PTP or LINE.
            accel_time_ms: Time to reach full speed, ms; None or 0: the robot program's
                default (200 ms, the model's ``accel_time_s``).

        Returns:
            The expected duration, s.

        Raises:
            UnreachablePoseError: The target, or a Line's straight path, cannot be
                taken.
        """
        return self._planner.expected_time(start, target, speed, motion, accel_time_ms)

    def check_move(
        self,
        target: Pose,
        speed: int,
        motion: MotionType | Literal["ptp", "line"] = MotionType.PTP,
        *,
        start: Pose | None = None,
        seed_deg: Sequence[float] | None = None,
    ) -> tuple[float, ...]:
        """Check a move fully without sending it; return the target's joints.

        Everything :meth:`validate_move` checks, the command block encoded in this
        profile (e.g. the article's +/-327.67 mm range), and for a Line from ``start``
        (with the joints ``seed_deg`` there) that the straight path stays in the arm's
        range.

        Args:
            target: The TCP target.
            speed: Speed, an integer percent.
            motion: ``"ptp"`` (joint interpolation) or ``"line"`` (a straight TCP path).
            start: Where a Line starts (None: its path is not checked).
            seed_deg: The joints at ``start``.

        Returns:
            The target's joints, deg.

        Raises:
            ConfigError: What is wrong (UnreachablePoseError for a pose or a path the
                arm cannot take, ValueOutOfRangeError for one the profile cannot encode).
        """
        motion = motion_type(motion)
        joints = self._planner.check_move(target, speed, motion, start, seed_deg)
        self._planner.check_tcp_speed(command := Command(CommandKind.of(motion), target, speed))
        self._channel.check_command(command)
        return joints

    def start_move(
        self,
        target: Pose,
        *,
        speed: int | None = None,
        motion: MotionType | Literal["ptp", "line"] = MotionType.PTP,
        timeout: float | None = None,
        accel_time_ms: int | None = None,
        speed_mm_s: int | None = None,
    ) -> Motion:
        """Validate and send a move, returning at once with a :class:`Motion` handle.

        Everything :meth:`validate_move` checks is checked before the first request, and
        for a Line the straight path from where the arm is believed to be (the pose the
        robot reported, or the last target it reached), when that is known; after a move
        given up (it may have stopped short), from where the robot reports the arm, read
        first. A Line's or an arc's TCP speed is held to ``checks.tcp_speed_limit_mm_s``
        as a PTP's is. Where
        the profile publishes the robot's joints, they are read with the start pose before
        the write (no extra request: Techman's 7013-7036 is one read, or the final check of
        the previous move read them) and the target's joints and the expected time are
        planned from them, on the branch the arm is actually on.

        Args:
            target: The TCP target (mm, deg, robot base frame).
            speed: Speed, an integer percent (1 .. ``max_speed_percent``); None: 30 %
                (or ``speed_mm_s``).
            motion: ``"ptp"`` (joint interpolation) or ``"line"`` (a straight TCP path).
            timeout: How long the move may take, s; None: from the expected time
                (``TimeoutPolicy.for_motion``).
            accel_time_ms: Time to reach full speed, ms, where the profile has the
                field (ConfigError on one without it: ``article``); None: the default.
            speed_mm_s: A Line's TCP speed in mm/s instead of ``speed`` (at most
                ``max_speed_percent`` of the arm's top TCP speed), where the profile
                has the field (``tmflow``).

        Returns:
            The move's handle: :meth:`Motion.wait` for it, or :meth:`Motion.progress`.

        Raises:
            ConfigError: The move is not allowed (nothing is sent).
            RobotFaultError: The robot is in error or e-stop (nothing is sent).
            CommandRejectedError: The robot refused the command.
            StopRequestedError: A stop was requested (nothing is sent).
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        motion = motion_type(motion)
        percent = self._move_arguments(speed, speed_mm_s, motion, accel_time_ms, timeout)
        self._planner.check_path(target, percent, motion)
        # prepare() encodes the block (a field the profile lacks, a range) before any I/O.
        cmd = Command(CommandKind.of(motion), target, percent, accel_time_ms, speed_mm_s=speed_mm_s)
        return self._start_command(cmd, timeout=timeout)

    def _move_arguments(
        self,
        speed: int | None,
        speed_mm_s: int | None,
        motion: MotionType | None,
        accel_ms: int | None,
        timeout: float | None,
        read: bool = True,
    ) -> int:
        """The speed register's percent for ``speed`` or ``speed_mm_s``, then the move's
        ``accel_time_ms`` (``accel_ms``, in the profile's range) and ``timeout`` checked
        too, before any I/O: nothing is read for a bad one. Then, after a move given up
        (a cancel, a timeout, a stop: it may have stopped short, in another pose
        configuration than its target), where the robot reports the arm is read, so that
        the move's checks (``start_move``'s, ``move_joints``', ``move_arc``'s end) run
        from there, not from the given-up move's target; ``read`` False: the caller reads
        it anyway (``move_by``).

        ``motion`` None: a Circle (which takes mm/s too).
        """
        percent = self._planner.speed_percent(speed, speed_mm_s, motion)
        for value, missing, what in (
            (speed_mm_s, not self._channel.extension_fields, "TCP speed in mm/s (speed_mm_s)"),
            (accel_ms, not self.profile.has("accel_time"), "acceleration time (accel_time_ms)"),
        ):
            if value is not None and missing:  # the robot would never get it
                raise ConfigError(f"profile {self.profile.name!r} has no {what}: give speed in %")
        check_accel(accel_ms)
        if accel_ms is not None:  # the profile's range (tmflow: 0..9999 ms)
            encode(self.profile.field("accel_time"), accel_ms)
        if timeout is not None:
            require_positive("timeout", timeout)
        if read and (last := self._last_motion) is not None and last.abandoned:
            self._read_start()
        return percent

    def move_joints(
        self,
        joints: Sequence[float],
        *,
        speed: int = 30,
        timeout: float | None = None,
        accel_time_ms: int | None = None,
    ) -> Motion:
        """Move to joint angles J1..J6 (a PTP in joint space) and return when it is done.

        The robot program runs ``PTP("JPP", ...)``: every joint turns on the same
        profile to its angle. Checked before any request: six finite numbers, each inside
        its range and the whole away from the arm model's singularities
        (:meth:`RobotModel.check_joints`), the TCP they put the arm at (forward
        kinematics with ``tool``) inside the ``workspace`` and above its table plane, and
        the arm's body and TCP speed along the PTP from where the arm is believed to be
        (after a move given up, from where the robot reports it, read first). The
        expected time is the model's joint-space time from the joints the robot reports;
        at the end, the joints the robot reports must be the target's (their TCP is the
        robot's own: a calibrated arm's differs from the model's by a mm or two).

        Example:
            Against the simulator (``python -m tmmaster.sim --port 5020``):

            ```python
            from tmmaster import connect

            with connect("127.0.0.1", 5020) as robot:
                robot.move_joints([0, 0, 90, 0, 90, 0], speed=20)
                print(robot.status().joints)
            ```

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
            StopRequestedError: A stop was requested (the move is withdrawn or stopped).
            TransportError: The link failed and did not come back in time.
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        self._require(CommandKind.PTP_JOINTS, "a joint move (move_joints)")
        values = joint_values(joints)
        self._move_arguments(speed, None, MotionType.PTP, accel_time_ms, timeout)
        checked, tcp = self._planner.joint_target(values, speed)
        command = Command(CommandKind.PTP_JOINTS, tcp, speed, accel_time_ms, joints=checked)
        return _waited(self._start_command(command, timeout=timeout))

    def move_by(
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
        """Move relative to where the robot reports the TCP, and return when it is done.

        The offset is resolved against the TCP pose the robot reports (read first;
        away from the last move's target, read until two reads a robot tick apart agree)
        into one absolute target, validated and sent like :meth:`move_to`'s; before the
        write the arm must still be at that pose. ``frame="base"``: the TCP moves ``dx, dy,
        dz`` along the robot base's axes and turns by ``Rz(drz) Ry(dry) Rx(drx)`` about
        the base's axes, in place. ``frame="tool"``: the offset is a pose in the TCP's
        own frame (target = TCP x offset), as TMscript's ``Move_PTP("TPP", ...)``.

        Example:
            Against the simulator (``python -m tmmaster.sim --port 5020``):

            ```python
            from tmmaster import connect

            with connect("127.0.0.1", 5020) as robot:
                robot.move_by(dz=-50, motion="line", speed_mm_s=100)  # 50 mm down
                robot.move_by(drz=30, frame="tool")                   # turn the tool
            ```

        Args:
            dx: Offset along x, mm.
            dy: Offset along y, mm.
            dz: Offset along z, mm.
            drx: Rotation about x, deg.
            dry: Rotation about y, deg.
            drz: Rotation about z, deg.
            frame: ``"base"`` or ``"tool"``.
            speed: Speed, an integer percent; None: 30 % (or ``speed_mm_s``).
            motion: ``"ptp"`` or ``"line"``.
            timeout: How long the move may take, s; None: from the expected time.
            accel_time_ms: Time to reach full speed, ms, where the profile has the
                field (ConfigError on one without it: ``article``); None: the default.
            speed_mm_s: A Line's TCP speed in mm/s instead of ``speed``.

        Returns:
            The finished move (``motion.start``: the pose it was resolved against).

        Raises:
            ConfigError: A bad offset, frame, speed, acceleration time or timeout
                (nothing is read or sent), or a target the move may not take (nothing is
                sent).
            RobotError: The arm moved between the read and the write, or its pose reads at a
                pose register's end (the article map's ±327.67 mm: the arm may be past it,
                where ``move_to`` brings it back). Nothing is sent.
            AcknowledgeTimeoutError: The robot did not take the command (withdrawn).
            MotionTimeoutError: The move did not finish in time (the arm is stopped).
            RobotFaultError: The robot reported an error (EmergencyStopError: e-stop).
            StopRequestedError: A stop was requested (the move is withdrawn or stopped).
            TransportError: The link failed and did not come back in time.
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        offset = offset_pose(dx, dy, dz, drx, dry, drz)
        if frame not in ("base", "tool"):
            raise ConfigError(f"frame must be 'base' or 'tool', got {frame!r}")
        kind = motion_type(motion)
        percent = self._move_arguments(speed, speed_mm_s, kind, accel_time_ms, timeout, read=False)
        start = self._read_start()  # a register saturates at its end: the arm may be past it
        ends = [allowed_range(self.profile.field(name)) for name in TCP_FIELDS]
        if any(not low < value < high for value, (low, high) in zip(start, ends, strict=True)):
            raise RobotError(f"the TCP reads {start}, a pose register's end: the arm may be past")
        target = moved(start, offset, frame)
        self._planner.check_path(target, percent, kind)  # move_to's: a Line's path too
        cmd = Command(CommandKind.of(kind), target, percent, accel_time_ms, speed_mm_s=speed_mm_s)
        self._channel.check_command(cmd)
        return _waited(self._start_command(cmd, timeout=timeout, resolved_at=start))

    def move_arc(
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

        The robot program runs TMscript's ``Circle`` with arc angle 0: the TCP follows
        the circle through where it is, ``via``'s position and ``to``, from the start
        through ``via`` to ``to``, and its orientation turns uniformly from the start's
        to ``to``'s (``via``'s orientation is not used: the master writes the one the
        TCP has there). Its end is checked from where the arm is believed to be (after a
        move given up, from where the robot reports it, read first). The arc is resolved
        against the TCP pose the robot reports (read first) and checked before the write
        like a Line: every point by inverse kinematics on the arm's branch, and inside the
        ``workspace``, the tool above its table plane.

        Example:
            Against the simulator (``python -m tmmaster.sim --port 5020``):

            ```python
            from tmmaster import Pose, connect

            with connect("127.0.0.1", 5020) as robot:
                robot.move_to(Pose(300, -200, 200, 180, 0, 90), speed=30)
                robot.move_arc(Pose(350, -150, 200, 180, 0, 90),
                               Pose(400, -200, 200, 180, 0, 90), speed_mm_s=100)
            ```

        Args:
            via: A pose whose position the arc passes through (mm).
            to: The TCP target at the arc's end (mm, deg).
            speed: Speed, an integer percent of the arm's top TCP speed; None: 30 % (or
                ``speed_mm_s``).
            timeout: How long the move may take, s; None: from the expected time.
            accel_time_ms: Time to reach full speed, ms; None: the robot's default.
            speed_mm_s: The TCP speed in mm/s instead of ``speed``.

        Returns:
            The finished move.

        Raises:
            ConfigError: No arc passes through the points, the arc may not be taken, or
                the profile has no circle command (``article``); UnreachablePoseError
                for an arc the arm cannot follow. Nothing is sent (nothing is read either
                for a bad speed, acceleration time or timeout).
            RobotError: The arm moved between the read and the write (nothing is sent).
            AcknowledgeTimeoutError: The robot did not take the command (withdrawn).
            MotionTimeoutError: The move did not finish in time (the arm is stopped).
            RobotFaultError: The robot reported an error (EmergencyStopError: e-stop).
            StopRequestedError: A stop was requested (the move is withdrawn or stopped).
            TransportError: The link failed and did not come back in time.
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        self._require(CommandKind.CIRCLE, "an arc (move_arc)")
        if not isinstance(via, Pose):
            raise ConfigError(f"via must be a tmmaster.Pose, got {type(via).__name__}")
        percent = self._move_arguments(speed, speed_mm_s, None, accel_time_ms, timeout)
        # Its end and via (after a give-up, from the arm's read); the arc from a read too.
        self._planner.check_arc_move(via, to, percent)
        command = Command(
            CommandKind.CIRCLE, to, percent, accel_time_ms, via=via, speed_mm_s=speed_mm_s
        )
        self._channel.check_command(command)
        start = self._read_start()
        # The robot's arc passes via's position with the orientation the TCP has there.
        command = replace(command, via=self._planner.via_on_arc(start, via, to))
        self._channel.check_command(command)
        return _waited(self._start_command(command, timeout=timeout, resolved_at=start))

    def _require(self, kind: CommandKind, what: str) -> None:
        """Refuse a command the profile has no code for (ConfigError naming it), no I/O."""
        if not self._channel.supports(kind):
            raise ConfigError(
                f"profile {self.profile.name!r} has no {kind.value!r} command: {what} needs"
                " the tmflow profile (its robot program)"
            )

    def _read_start(self) -> Pose:
        """The TCP pose the robot reports (with its joints, where published), for a plan.

        Away from the last move's target (a stopped move's brake, the first move), the
        pose registers may still trail an arm that just came to rest: they are read again
        each robot tick until two reads in a row are within 0.5 mm and 0.5 deg of each
        other, for ``SETTLE_S`` at most (a stop request ends the wait).
        """
        self._require_connection()
        start, joints, _ = self._channel.read_plan()
        poller = Poller(TICK_S, self._stop_event, deadline=(end := time.monotonic() + SETTLE_S))
        before = self._planner.origin(start)  # the last move's target where the arm reads so
        while (before is start or not start.is_close(before)) and time.monotonic() < end:
            poller.sleep()
            before, (start, joints, _) = start, self._channel.read_plan()
        self._planner.take_robot_joints(start, joints)
        return start

    def _run_command(self, kind: CommandKind, timeout_s: float | None) -> None:
        """A gripper command through the robot program's handshake, waited for."""
        self._start_command(Command(kind), timeout=timeout_s).wait()

    def _checked_status(self) -> RobotStatus:
        """One status read; raises the typed error when it shows e-stop or error."""
        status = self.status()
        if (failure := self._channel.status_failure(status)) is not None:
            raise failure
        return status

    def _start_command(
        self, command: Command, *, timeout: float | None = None, resolved_at: Pose | None = None
    ) -> Motion:
        """Check, send and follow any command of the profile: a move or a gripper action.

        ``resolved_at``: the pose a relative move or an arc was resolved against; the arm
        must still be there before the write.
        """
        if timeout is not None:
            require_positive("timeout", timeout)
        self._planner.check_tcp_speed(command)  # a Line's or an arc's, before any request
        if not self._connected:
            # What prepare() refuses before its first read (a value out of the profile's
            # range) is said first, as on a connected robot; then the missing connect.
            self._channel.check_command(command)
        self._require_connection()  # and a give-up still owed goes first
        if self._heartbeat.claim_due:
            # The first command claims the robot (this master beats from then on) once
            # its values fit the profile; the checks that read the arm come after (the
            # ticket carries the session), so a move they refuse has claimed it. After a
            # silence (the link was down), a beat goes first: the program may see us gone.
            self._channel.check_command(command)
            self._channel.session = self._heartbeat.claim(self._shared)
        # prepare() encodes (refusing out-of-range values) before its first read.
        ticket = self._channel.prepare(command, reuse_s=REUSE_DONE_READ_S)
        start: Pose | None = None
        joints: tuple[float, ...] | None = None
        if command.target is not None:
            # Where the move starts, the robot's TCP and base checked against the tool.
            start, joints = self._frames.arm_before(ticket, self.tool)
        plan = self._planner.plan(command, start, joints, timeout=timeout, resolved_at=resolved_at)
        motion = self._follower.start(ticket, plan, self._outstanding)
        self._planner.sent(plan)
        return motion

    def _outstanding(self, motion: Motion) -> None:
        """Record the command being sent (under the gate's lock, before its write)."""
        self._last_motion = motion

    def move_to(
        self,
        target: Pose,
        *,
        speed: int | None = None,
        motion: MotionType | Literal["ptp", "line"] = MotionType.PTP,
        timeout: float | None = None,
        accel_time_ms: int | None = None,
        speed_mm_s: int | None = None,
    ) -> Motion:
        """Move to ``target`` and return when the robot acknowledged and finished the move.

        :meth:`start_move`, then :meth:`Motion.wait`: the move is validated before the
        first byte, written once, and its final pose checked against the target.

        Example:
            Against the simulator (``python -m tmmaster.sim --port 5020``):

            ```python
            from tmmaster import MotionTimeoutError, Pose, connect

            with connect("127.0.0.1", 5020) as robot:
                above = Pose(300, -200, 200, 180, 0, 90)
                robot.move_to(above, speed=50)  # PTP
                try:
                    robot.move_to(above.offset(dz=-50), speed=10, motion="line")
                except MotionTimeoutError as exc:
                    print("gave up, the arm was stopped:", exc.pose)
            ```

        Args:
            target: The TCP target (mm, deg, robot base frame).
            speed: Speed, an integer percent (1 .. ``max_speed_percent``); None: 30 %
                (or ``speed_mm_s``).
            motion: ``"ptp"`` (joint interpolation) or ``"line"`` (a straight TCP path).
            timeout: How long the move may take, s; None: from the expected time
                (``TimeoutPolicy.for_motion``).
            accel_time_ms: Time to reach full speed, ms, where the profile has the
                field (ConfigError on one without it: ``article``); None: the default.
            speed_mm_s: A Line's TCP speed in mm/s instead of ``speed`` (``tmflow``).

        Returns:
            The finished move.

        Raises:
            ConfigError: The move is not allowed (UnreachablePoseError: the arm cannot
                take it); nothing is sent.
            AcknowledgeTimeoutError: The robot did not take the command (withdrawn).
            MotionTimeoutError: The move did not finish in time (the arm is stopped).
            RobotFaultError: The robot reported an error (EmergencyStopError: e-stop).
            StopRequestedError: A stop was requested (the move is withdrawn or stopped).
            TransportError: The link failed and did not come back in time.
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        handle = self.start_move(
            target,
            speed=speed,
            motion=motion,
            timeout=timeout,
            accel_time_ms=accel_time_ms,
            speed_mm_s=speed_mm_s,
        )
        return _waited(handle)

    def project_state(self) -> ProjectState:
        """The TMflow project's state, from Techman's table (7201, 7202, 7204, 7208).

        Returns:
            RUNNING, PAUSED, STOPPED or ERROR (a robot error or the e-stop).

        Raises:
            ConfigError: The profile has no TMflow project (article).
            TransportError: The read failed.
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        self._require_connection()
        return self._project.state()

    def play(self, timeout_s: float = PRESS_TIMEOUT_S) -> ProjectState:
        """Press Play (coil 7104) on a stopped or paused project and wait until it runs.

        Never implicit: nothing in tmmaster presses Play unless you call this (or press
        it on the robot). A stopped project starts ``main`` from the beginning; a paused
        one goes on, with the move it interrupted, if any, only when that move is one this
        robot still follows (not done, not given up): never another master's. A running
        project is left as
        it is (the coil is a toggle: pressing it would pause it). The press passes the
        command gate: refused after :meth:`interrupt` or :meth:`close`. TMflow takes it
        only in Auto mode with the Robot Stick disabled and AUT.P high
        (docs/tmflow-program.md, settings checklist).

        Args:
            timeout_s: How long to wait for the project to run after the press, s.

        Returns:
            ProjectState.RUNNING.

        Raises:
            ConfigError: The profile has no TMflow project (article), or a bad
                ``timeout_s``.
            RobotFaultError: The robot is in error (EmergencyStopError: e-stop); reset it
                on the robot first. Nothing was pressed.
            RobotError: Manual mode, or a paused move this robot does not follow (nothing
                pressed: press Stop), or the project did not run within ``timeout_s``, or
                this process's Stop of the last second did not show within it (Stop pressed).
            StopRequestedError: A stop was requested or the robot is closing.
            TransportError: The link failed (a press left unanswered: Stop was pressed,
                so that it cannot resume a paused move when it lands).
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        self._require_connection()
        # Only a command this master still follows may resume.
        own = m.ticket if (m := self._last_motion) and not (m.done or m.abandoned) else None
        return self._project.play(timeout_s, self.poll_interval_s, own)

    def pause(self, timeout_s: float = PRESS_TIMEOUT_S) -> ProjectState:
        """Press Pause (coil 7104) on a running project and wait until it is paused.

        A stopped project is left stopped (the toggle would start it). A move in progress
        ends with :class:`ProjectPausedError` and the master presses Stop on it, so Play
        can never resume it. The press passes the command gate, like :meth:`play`.

        Args:
            timeout_s: How long to wait for the project to pause after the press, s.

        Returns:
            ProjectState.PAUSED, or STOPPED for a stopped project (nothing pressed) or one
            stopped during the wait (that stayed stopped 0.1 s: Stop pressed elsewhere).

        Raises:
            ConfigError: The profile has no TMflow project (article), or a bad
                ``timeout_s``.
            RobotFaultError: The robot is in error (EmergencyStopError: e-stop).
            RobotError: The project did not pause within ``timeout_s`` (nor this process's
                Stop of the last second show within it), or showed paused
                (or stopped) and ran on within 0.1 s (a press from the pendant crossed
                this one), or ran as a new start (the press landed on a project a Stop
                had just ended, where the toggle is Play): Stop was pressed, so the arm
                does not run on.
            StopRequestedError: A stop was requested or the robot is closing (Stop was
                pressed).
            TransportError: The link failed (a press left unanswered: Stop was pressed,
                so that it cannot resume a paused move when it lands).
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        self._require_connection()
        return self._project.pause(timeout_s, self.poll_interval_s)

    def stop(self) -> None:
        """Stop the arm now (article: command = stop; tmflow: the TM Stop button).

        Returns once the stop is written; the arm then brakes to rest, which takes
        a Category 2 stop's deceleration time (300 ms by default on a TM5S, TMflow 2.24
        p. 112). On ``article`` :meth:`status` reports ``moving`` until the arm is at
        rest; on ``tmflow`` ``moving`` is the robot program's state, False as soon as the
        project stops, while the arm still brakes. :meth:`wait_until_at_rest` waits for
        the arm itself.

        Raises:
            TransportClosedError: The robot was never connected (nothing was sent) or is
                closed.
            TransportError: The stop could not be written.
            CommandStateUnknownError: A command given up earlier still owes its withdraw or stop
                (the link was down): nothing is sent until that is delivered (docs/safety.md).
        """
        self._require_connection()
        # A stop is idempotent: the channel retries it, even after a stop request.
        self._follower.stop()

    def clear_stop_request(self) -> None:
        """Allow waits and commands again after :meth:`interrupt` (not after :meth:`close`)."""
        if not self._gate.closed:
            self._stop_event.clear()
            if self._gate.closed:  # a close() on another thread since: its request stands
                self._stop_event.set()

    def interrupt(self) -> None:
        """Make running waits give up at their next poll (for Ctrl-C handlers, other threads).

        Until :meth:`clear_stop_request`, no new command is written either: a move or
        gripper command started meanwhile raises :class:`StopRequestedError` unsent.
        """
        with deferred():  # a second Ctrl-C inside set() would leave the event's lock held
            self._stop_event.set()
        if self._shared is not None:
            wake_waits(self._shared)  # a wait polled by the fleet ends now

    def dwell(self, seconds: float) -> None:
        """Wait ``seconds`` without a request; a stop request ends the wait at once.

        A pause between steps (a camera's exposure, a part settling) that ends as every
        wait of the robot does: at once on :meth:`interrupt` (a Ctrl-C handler, another
        thread), and at once while a stop request stands (until
        :meth:`clear_stop_request`).

        Args:
            seconds: How long, s (a number from 0 to 1e9).

        Raises:
            ConfigError: ``seconds`` is not a number from 0 to 1e9.
            StopRequestedError: A stop was requested before or during the wait.
        """
        deadline = time.monotonic() + require_in("seconds", seconds, _DWELL)
        Poller(self.poll_interval_s, self._stop_event, deadline=deadline).sleep_until(deadline)


def _close_at_exit() -> None:
    # The interpreter is exiting with robots still open: nothing may stay armed. Their
    # references copied in one step: a robot closing on another thread meanwhile is fine.
    for ref in _OPEN.valuerefs():
        if (robot := ref()) is not None:
            robot.close()


#: A dwell's range: none included, up to 31 years (a thread's wait takes at most
#: ``threading.TIMEOUT_MAX``, 9.2e9 s: beyond it, the wait raised OverflowError).
_DWELL = Bounds(0.0, 1e9, "s")


def _waited(motion: Motion) -> Motion:
    """``motion``, once it is done (:meth:`Motion.wait`: raises when it failed)."""
    motion.wait()
    return motion


def _profile_mismatch(
    transport: Transport, profile: RobotProfile, refused: IllegalAddressError
) -> ProfileMismatchError | None:
    """After a refused read: the built-in profile the device seems to speak, as an error."""
    for name in builtin_profile_names():
        other = None if name == profile.name else load_profile(name)
        if not isinstance(other, RobotProfile):
            continue
        try:
            transport.read_fields(other.role(Role.STATUS)[:1], retry=False, interruptible=False)
        except TMMasterError:
            continue
        return ProfileMismatchError(
            f"{refused}; the device answers the {name!r} profile's status registers:"
            f" is it running that profile? (this Robot speaks {profile.name!r})",
            profile=profile.name,
            device_profile=name,
        )
    return None


def _connected(make: Callable[_P, Robot]) -> Callable[_P, Robot]:
    """``make`` then ``connect()``, with ``make``'s exact signature (typos caught by mypy)."""

    def connect(*args: _P.args, **kwargs: _P.kwargs) -> Robot:
        """Open a :class:`Robot` (same arguments as :class:`Robot`); use it in a ``with`` block.

        ``Robot(...)`` then :meth:`Robot.connect`; a connect that fails closes the robot.
        Every argument is :class:`Robot`'s, with the same defaults.

        Example:
            Against the simulator (``python -m tmmaster.sim --port 5020``):

            ```python
            from tmmaster import Pose, connect

            with connect("127.0.0.1", 5020) as robot:  # the tmflow profile, a TM5-700
                robot.move_to(Pose(300, -200, 200, 180, 0, 90), speed=50)
                print(robot.status())
            ```

        Returns:
            The robot, connected.

        Raises:
            ConfigError: An invalid argument.
            ConnectError: The robot cannot be reached (ConnectRefusedError,
                HostNotFoundError say why).
        """
        robot = make(*args, **kwargs)
        try:
            return robot.connect()
        except BaseException:
            robot.close()
            raise

    return _named_connect(make, connect)


def _named_connect(make: Callable[..., object], connect: _F) -> _F:
    """``connect``, named so, with ``make``'s parameters and its own return annotation.

    help() and the API docs then show Robot's parameters, not *args/**kwargs, and what
    ``connect`` returns (a Robot, an AsyncRobot; the constructor's own returns None).
    """
    connect.__qualname__ = "connect"
    connect.__signature__ = inspect.signature(make).replace(  # type: ignore[attr-defined]
        return_annotation=inspect.signature(connect).return_annotation
    )
    return connect


connect = _connected(Robot)
