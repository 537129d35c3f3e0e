"""The simulator's options, grouped: the robot, the cell, the timing and where it listens.

Each group is a frozen dataclass checked once, when it is made: a bad value is a
ConfigError that names the field. :class:`~tmmaster.sim.Simulator` takes them whole, so
the options that only make sense together travel together (the physics engine with the
world it simulates; your own backend instead of both).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from .._checks import Bounds, is_finite_number, require_in, shown
from .._exceptions import ConfigError, UnknownNameError
from .._pose import Pose
from .._profiles import gripper_profile
from .._registers import GripperProfile
from .._robot_models import TCP_SPEED_MAX, RobotModel, robot_model
from ._scene import Scene, load_scene
from ._world import GRASP_MODES, GraspMode, GripperGeometry, TableObject, World

#: The project speeds TMflow offers, % (TMflow 2.24 Appendix C, p. 314: 5..100 by 5).
_PROJECT_SPEEDS = range(5, 101, 5)

#: The range of the robot's TCP speed limit (``RobotSetup.tcp_speed_limit_mm_s``): TMflow
#: 2.24 Appendix B, Performance Safety "TCP Speed", 0-4500 mm/s (0 itself refused here).
_TCP_SPEED_LIMIT_BOUNDS = Bounds(0.0, TCP_SPEED_MAX, "mm/s", open_low=True)

#: Physics backends a simulator can be built with by name (``Cell(physics=...)``).
PHYSICS_BACKENDS = ("kinematic", "mujoco")


def _port(field: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 65535:
        raise ConfigError(
            f"{field} must be an integer 0..65535 (0: a free port), got {shown(value)}"
        )


@dataclass(frozen=True, kw_only=True)
class Listen:
    """Where the simulator serves Modbus TCP: ``Simulator(listen=Listen(port=5020))``.

    Raises:
        ConfigError: A port that is not an integer 0..65535, a host that is not a string.
    """

    #: The address to listen on (Modbus has no authentication: loopback unless you mean
    #: it).
    host: str = "127.0.0.1"
    #: The robot's Modbus TCP port; 0 picks a free one (``sim.port`` once started).
    port: int = 0
    #: The separate gripper's port (``RobotSetup(gripper=...)``); 0 picks a free one.
    gripper_port: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.host, str) or not self.host:
            raise ConfigError(f"host must be an address, got {shown(self.host)}")
        _port("port", self.port)
        _port("gripper_port", self.gripper_port)


@dataclass(frozen=True, kw_only=True)
class Timing:
    """How the simulator's clock ticks, and how long the robot takes to start up.

    Raises:
        ConfigError: ``tick_hz`` outside (0, 1000], ``init_time_s`` below 0 or not finite,
            ``batch_s`` outside [0, 1].
    """

    #: Control ticks per wall second, in (0, 1000]; each advances simulated time by
    #: ``time_scale / tick_hz``.
    tick_hz: float = 50.0
    #: Simulated seconds before the robot reports ready (its start-up: tmflow starts the
    #: project then); a finite number >= 0.
    init_time_s: float = 0.2
    #: Wall seconds a due tick may wait while nothing observes the robot, in [0, 1]. A
    #: request or a call runs every tick due by then before it reads or writes anything,
    #: so what a master sees is the same as with each tick at its time; between
    #: requests the due ticks run back to back (each with its own due time, which the
    #: motion log records), for a fraction of the CPU. 0: every tick at its own time.
    batch_s: float = 0.1

    def __post_init__(self) -> None:
        hz = require_in("tick_hz", self.tick_hz, Bounds(0, 1000, "Hz", open_low=True))
        object.__setattr__(self, "tick_hz", hz)
        if not (is_finite_number(self.init_time_s) and self.init_time_s >= 0):
            raise ConfigError(
                f"init_time_s must be a finite number >= 0, got {shown(self.init_time_s)}"
            )
        batch = require_in("batch_s", self.batch_s, Bounds(0, 1, "s"))
        object.__setattr__(self, "batch_s", batch)


@dataclass(frozen=True, kw_only=True)
class RobotSetup:
    """The simulated robot: its arm model, separate gripper and (tmflow) its program.

    Raises:
        ConfigError: An unknown model (UnknownNameError) or gripper profile,
            ``initial_seq`` not an int, ``resume_after_error`` not a bool,
            ``tcp_speed_limit_mm_s`` not a number in (0, 4500] mm/s. (The program
            and the range of ``initial_seq`` depend on the profile: the Simulator checks
            them.)
    """

    #: The arm model: ``"tm5-700"``, ``"tm5-900"``, ``"tm12"`` or ``"tm14"``, or a
    #: RobotModel: an arm that differs from the one the master plans with (a calibrated
    #: variant, another inverse-kinematics choice).
    model: str | RobotModel = "tm5-700"
    #: A separate gripper device, served on its own port: None, ``"blog-2fg7"``,
    #: ``"onrobot-2fg7"``, a TOML file or a GripperProfile.
    gripper: str | Path | GripperProfile | None = None
    #: tmflow: the Script Project the robot runs; None or ``"generated"``: the program
    #: ``tmmaster robot-program`` writes for the profile and the cell's tool.
    program: str | Path | None = None
    #: tmflow: the sequence numbers at the start (e.g. 32766, to test their wrap).
    initial_seq: int = 0
    #: tmflow: an e-stop pauses the project (Play resumes the move) instead of stopping
    #: it.
    resume_after_error: bool = False
    #: tmflow: the project speed, % (Techman's 7101: 5..100 in steps of 5): every move
    #: runs at its own speed times this, as in TMflow.
    project_speed: int = 100
    #: The robot's TCP speed limit, mm/s (its Safety Settings' Performance Safety "TCP
    #: Speed", up to 4500): a PTP whose TCP runs faster stops in error 0x0021. None:
    #: the arm model's, TMflow's default 1500 mm/s.
    tcp_speed_limit_mm_s: float | None = None
    _gripper: GripperProfile | None = field(default=None, init=False, repr=False, compare=False)
    _arm: RobotModel | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if isinstance(self.model, RobotModel):
            arm = self.model
        elif isinstance(self.model, str):
            arm = robot_model(self.model)  # an unknown name: UnknownNameError, the models
        else:
            raise ConfigError(
                f"model must be a model name or a RobotModel, got {shown(self.model)}"
            )
        if self.tcp_speed_limit_mm_s is not None:
            limit = require_in(
                "tcp_speed_limit_mm_s", self.tcp_speed_limit_mm_s, _TCP_SPEED_LIMIT_BOUNDS
            )
            arm = arm.model_copy(update={"tcp_speed_limit_mm_s": limit})
        object.__setattr__(self, "_arm", arm)
        if self.gripper is not None:
            object.__setattr__(self, "_gripper", gripper_profile(self.gripper))
        if isinstance(self.initial_seq, bool) or not isinstance(self.initial_seq, int):
            raise ConfigError(f"initial_seq must be an int, got {shown(self.initial_seq)}")
        if not isinstance(self.resume_after_error, bool):
            raise ConfigError(
                f"resume_after_error must be True or False, got {shown(self.resume_after_error)}"
            )
        speed = self.project_speed
        if isinstance(speed, bool) or not isinstance(speed, int) or speed not in _PROJECT_SPEEDS:
            raise ConfigError(
                f"project_speed must be an integer 5..100 in steps of 5 (%), got {shown(speed)}"
            )

    @property
    def arm(self) -> RobotModel:
        """The arm model (loaded when this setup was made)."""
        assert self._arm is not None  # set by __post_init__
        return self._arm

    @property
    def gripper_profile(self) -> GripperProfile | None:
        """The separate gripper's profile (loaded when this setup was made), or None."""
        return self._gripper


@dataclass(frozen=True, kw_only=True)
class Cell:
    """The cell the robot works in, simulated by a built-in physics backend.

    ``Simulator(cell=...)`` takes this or your own :class:`PhysicsBackend`, which then
    models the world, the tool, the grasp and the arm's speed itself.

    Raises:
        ConfigError: An unknown ``physics`` (UnknownNameError) or ``grasp``, a scene
            file that cannot be read or is invalid (naming the key), parts that are not
            TableObjects, ``tool`` not a Pose, ``dynamics=True`` with the kinematic
            backend, ``speed_factor`` outside 0.1..10.
    """

    #: What is on the table: a :class:`Scene`, a TOML scene file (table height,
    #: fixtures, parts, gripper geometry; read when the Cell is made: this is then its
    #: Scene), or the parts alone (TableObjects on the default table; ``[]``: an empty
    #: table). None: one part at ``DEFAULT_PART_POSE``.
    scene: Scene | str | Path | Iterable[TableObject] | None = None
    #: ``"kinematic"`` (analytic) or ``"mujoco"`` (the ``tmmaster[mujoco]`` extra).
    physics: str = "kinematic"
    #: The TCP in the flange frame (TCP = flange x tool); None: the flange.
    tool: Pose | None = None
    #: How the fingers hold a part: ``"friction"`` (a part too heavy for the grip force
    #: slips out) or ``"weld"`` (a part between the pads is carried whatever its mass).
    grasp: GraspMode = "friction"
    #: Arm dynamics, with ``physics="mujoco"``: the links carry Techman's masses and
    #: inertias and each joint is a servo limited to its effort, so the arm lags its
    #: trajectory (more with a heavy part) and a move is done once the joints settled;
    #: the reported pose is where the joints are. None (the default): on with the
    #: mujoco backend for the models whose link masses are known (TM5-700, TM5-900),
    #: off otherwise; False: the ideal servo; True: on, or ConfigError where it cannot
    #: be (another model).
    dynamics: bool | None = None
    #: The arm moves this many times faster than the model the master plans with
    #: (0.1..10; for testing a master against a robot it does not predict).
    speed_factor: float = 1.0

    def __post_init__(self) -> None:
        if self.physics not in PHYSICS_BACKENDS:
            raise UnknownNameError(
                f"unknown physics backend {self.physics!r} (known: {', '.join(PHYSICS_BACKENDS)})"
            )
        if self.grasp not in GRASP_MODES:
            raise ConfigError(f"grasp must be one of {', '.join(GRASP_MODES)}, got {self.grasp!r}")
        if self.dynamics not in (None, True, False):
            raise ConfigError(f"dynamics must be None, True or False, got {shown(self.dynamics)}")
        if self.dynamics and self.physics != "mujoco":
            raise ConfigError(
                "dynamics: only the mujoco physics backend models arm dynamics"
                " (physics='mujoco', --physics mujoco)"
            )
        if not (is_finite_number(self.speed_factor) and 0.1 <= self.speed_factor <= 10):
            raise ConfigError(
                f"speed_factor must be a number in 0.1..10, got {shown(self.speed_factor)}"
            )
        if self.tool is not None and not isinstance(self.tool, Pose):
            raise ConfigError(f"tool must be a Pose, got {shown(self.tool)}")
        object.__setattr__(self, "scene", _scene(self.scene))

    def world(self) -> tuple[World, GripperGeometry | None]:
        """A new world of this cell, and the gripper geometry its scene gives (or None).

        Returns:
            The world (its parts at rest) and the scene's gripper (None: an OnRobot 2FG7).

        Raises:
            ConfigError: Two parts or fixtures of one name.
        """
        scene = self.scene
        if isinstance(scene, Scene):
            return scene.world(), scene.gripper
        assert scene is None or isinstance(scene, tuple)  # __post_init__
        return World(scene), None


def _scene(scene: object) -> Scene | tuple[TableObject, ...] | None:
    """``Cell.scene`` checked: a Scene, a loaded scene file, a tuple of parts or None."""
    if scene is None or isinstance(scene, Scene):
        return scene
    if isinstance(scene, str | Path):
        return load_scene(scene)
    if isinstance(scene, Iterable):
        parts = tuple(scene)
        for part in parts:
            if not isinstance(part, TableObject):
                raise ConfigError(f"scene: a part must be a TableObject, got {shown(part)}")
        return parts
    raise ConfigError(f"scene must be a Scene, a scene file or TableObjects, got {shown(scene)}")
