"""A MuJoCo physics backend: the TM arm, a two-finger gripper, a table and falling parts.

Optional: needs the ``mujoco`` extra (``pip install 'tmmaster[mujoco]'``, the headless
``mujoco-core`` wheel); ``mujoco`` is imported when a :class:`MuJoCoBackend` is made,
never when :mod:`tmmaster.sim` is imported.

The scene is generated as MJCF from the same data as everything else: the arm's joint
chain is :attr:`RobotModel.joints` (capsules between the joint origins, no meshes), the
parts are the :class:`~tmmaster.sim.World`'s boxes with their size and mass, the table
top is the world's. What is simulated, and what is not:

- **Arm**: servoed ideally along the joint-space trajectory the kinematics module plans
  (PTP: a synchronised joint trapezoid; Line: the straight TCP path sampled by
  :meth:`RobotModel.line_joints`), with the durations of :meth:`RobotModel.motion_time`,
  so the arm keeps the analytic backend's timing and the master's derived timeouts hold.
  With arm dynamics (the default for the models whose link masses are known, the TM5-700
  and TM5-900) the links carry the masses and inertias of Techman's URDF and the
  trajectory is the reference of torque-limited joint servos (computed torque: the
  planned acceleration through the arm's mass matrix, its gravity and Coriolis torques
  fed forward): the arm follows it, lagging with a part it does not know of, and a move
  is done once the joints settled at its target. Without (``dynamics=False``, or another
  model) the arm joints are driven directly (qpos / qvel set every physics step, heavy
  armature): an ideal servo, no lag.
- **Gripper**: two fingers on slide joints along the tool's y axis, position actuators
  whose force is limited to the commanded grip force, their target ramped at the
  commanded speed. Only the finger pads collide, and only with parts.
- **Grasp**: once both pads touch the same part, a weld constraint locks it to the tool
  (friction-only grasps slip in MuJoCo while the arm turns); ``grasp_lock=False`` keeps
  friction only. Opening the fingers releases the lock and the part falls under gravity.
- **Feeder**: parts that start inside one another (several parts "waiting" at the pick
  position) cannot coexist in a physics scene: the later ones are parked out of the scene
  and appear at their start pose once it is free.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, TypeVar, cast
from xml.sax.saxutils import quoteattr

from .. import _body as body
from .. import _kinematics as kin
from .._checks import Bounds, require_in, require_positive
from .._exceptions import ConfigError, UnreachablePoseError
from .._pose import MotionType, Pose
from .._robot_models import Joints, RobotModel, trapezoid_progress
from ._backend import (
    BackendFault,
    GripperState,
    MotionRejectedError,
    ObjectState,
    PhysicsBackend,
    PhysicsUnavailableError,
    RejectReason,
)
from ._collide import ARM_RADIUS_MM
from ._payload import over_payload
from ._stopping import (
    Braking,
    over_speed_at,
    path_gradient,
    plan_braking,
    speed_fault,
    trapezoid_rate,
)
from ._world import (
    DEFAULT_GRIPPER,
    GRASP_MODES,
    GRAVITY_M_S2,
    TABLE,
    TABLE_CENTRE_XY_MM,
    TABLE_HALF_SIZE_XY_MM,
    Fixture,
    GraspMode,
    GripperGeometry,
    TableObject,
    World,
    gripper_geometry,
    pad_overlaps,
)

if TYPE_CHECKING:
    from pathlib import Path

_T = TypeVar("_T")


class _RunningSimulator(Protocol):
    """What :func:`save_snapshot` needs of a simulator (a :class:`Simulator` is one)."""

    @property
    def backend(self) -> PhysicsBackend:
        """The simulator's physics backend."""

    def call(self, fn: Callable[[], _T]) -> _T:
        """Run ``fn`` on the simulator's loop thread and return its result."""


#: Physics step, s.
DEFAULT_TIMESTEP_S = 0.002

# Absorbs float drift when counting physics steps in a tick.
_EPS = 1e-9

#: Radians per degree.
_RAD = math.pi / 180

#: A part moving slower than this (m/s, rad/s) and touching a support is at rest.
_REST_LINEAR = 0.005
_REST_ANGULAR = 0.05

#: The fingers count as stopped below this speed (m/s per finger) ...
_FINGER_STOPPED = 0.002
#: ... for this long (s) after their target ramp ended.
_FINGER_STOP_TIME_S = 0.05

# Collision bits (MuJoCo: two geoms collide when one's contype meets the other's
# conaffinity): the table carries parts; parts touch the table, each other and the pads;
# the pads grip parts and hit the table; the arm, flange and palm hit the table only.
_TABLE_BITS = (1, 0)
_PART_BITS = (4, 1 | 2 | 4)
_PAD_BITS = (2, 1)
_ARM_BITS = (8, 1)
_ARM_CONTACT = f'contype="{_ARM_BITS[0]}" conaffinity="{_ARM_BITS[1]}"'

#: Radius of the arm's capsules, m (the kinematic backend checks the same ones).
_ARM_RADIUS_M = ARM_RADIUS_MM / 1000

#: A finger's mass and its pad's, kg (the rest of the gripper's mass is its palm's).
_FINGER_KG = 0.025
_PAD_KG = 0.02
#: Finger servo while travelling: stiffness (N/m) and the joint's damping (N s/m).
_FINGER_KP = 2000.0
_FINGER_DAMPING = 20.0
#: A pad pressing on a part harder than this while the arm moves is a collision, N:
#: TMflow's default TCP force limit (TMflow SW 2.24 Software Manual, Appendix B, p. 285).
DEFAULT_COLLISION_FORCE_N = 150.0
#: The table and fixtures are rigid: their contacts (with the parts too, priority) are as
#: stiff as the pads'. With MuJoCo's default (0.02 s) a part pressed by an arm driven
#: through its joint servos sank millimetres into the table and squirted out from under
#: a pad landing on it, instead of the pad's force rising to a collision.
_RIGID = ' priority="1" solref="0.004 1" solimp="0.95 0.99 0.001"'
#: The arm deeper in the table than when its motion started by more than this is a
#: collision, m.
_COLLISION_DEPTH_M = 0.0002

#: A closing finger this far behind its ramped target (m) is blocked on something: it
#: then presses with the whole commanded force.
_FINGER_BLOCKED_M = 0.0005


#: The arm's links from Techman's URDF (TechmanRobotInc/tmr_ros2, commit 684faab3c808,
#: tm_description/urdf/<model>-nominal.urdf, links link_1 .. link_6 ``<inertial>``): mass
#: (kg) and the diagonal of the inertia tensor (kg m^2) about the link frame's origin,
#: which is the frame of the joint that turns the link (the URDF's inertial origins are
#: all zero); and each joint's ``<limit effort>``, N m.
_URDF_LINKS: dict[str, tuple[tuple[float, tuple[float, float, float]], ...]] = {
    "tm5-700": (
        (4.032, (0.008800119, 0.011548982, 0.011970081)),
        (8.567, (0.023552072, 0.19825197, 0.20459254)),
        (2.273, (0.003380181, 0.033829144, 0.034328203)),
        (1.576, (0.002058405, 0.002563079, 0.00264321)),
        (1.576, (0.002058405, 0.002563079, 0.00264321)),
        (0.65, (0.000774544, 0.001383811, 0.001559496)),
    ),
    "tm5-900": (
        (4.032, (0.008800119, 0.011548982, 0.011970081)),
        (8.897, (0.024459295, 0.205888616, 0.2124734246)),
        (2.443, (0.003632988, 0.03635926, 0.036895644)),
        (1.576, (0.002058405, 0.002563079, 0.00264321)),
        (1.576, (0.002058405, 0.002563079, 0.00264321)),
        (0.65, (0.000774544, 0.001383811, 0.001559496)),
    ),
}
_URDF_EFFORT_NM: dict[str, tuple[float, ...]] = {
    "tm5-700": (157.0, 157.0, 157.0, 43.0, 43.0, 43.0),
    "tm5-900": (157.0, 157.0, 157.0, 43.0, 43.0, 43.0),
}

#: Rotor inertia reflected through the gearbox on each arm joint with ``dynamics=True``,
#: kg m^2 (not in Techman's URDF: a typical harmonic-drive figure, ours).
_DYN_ARMATURE = (0.4, 0.4, 0.2, 0.05, 0.05, 0.05)
#: The joint servo's bandwidth with ``dynamics=True``: natural frequency (Hz) and
#: damping ratio of each joint's PD loop, its gains scaled by the joint's inertia in the
#: ready posture without payload; an integral term (time constant ``_SERVO_TI_S``) holds
#: a payload the servo does not know of.
_SERVO_HZ = 8.0
_SERVO_ZETA = 1.0
_SERVO_TI_S = 0.1
#: A reference acceleration below this on every joint is none (rad/s^2): the inertial
#: torque is then below a micronewton-metre, and a cruise (most physics steps of a
#: move) skips the mass matrix product. Rounding in the sampled reference is ~1e-10.
_FF_MIN_ACCEL = 1e-6
#: A dynamic move is done once every joint is within this of its target (deg) ...
SETTLE_TOLERANCE_DEG = 0.01
#: ... and turns slower than this (deg/s).
SETTLE_SPEED_DEG_S = 0.5


def has_dynamics_data(model_name: str) -> bool:
    """Whether the MuJoCo backend can model the arm dynamics of ``model_name``.

    Args:
        model_name: A robot model's name (``"tm5-700"``).

    Returns:
        True when its link masses and joint torques are known (the TM5-700 and TM5-900):
        the MuJoCo backend then models its dynamics unless told ``dynamics=False``.
    """
    return model_name in _URDF_LINKS


def _import_mujoco() -> Any:
    try:
        import mujoco
    except ImportError as exc:
        raise PhysicsUnavailableError(
            "the MuJoCo backend needs the mujoco extra: pip install 'tmmaster[mujoco]'"
        ) from exc
    return mujoco


def require_mujoco() -> None:
    """Raise :class:`PhysicsUnavailableError` (naming the extra) unless mujoco imports."""
    _import_mujoco()


@dataclass
class _Trajectory:
    """Joint samples (deg) swept by a trapezoidal path parameter over ``duration_s``."""

    samples: list[tuple[float, ...]]
    duration_s: float
    accel_time_s: float
    elapsed_s: float = 0.0
    #: The reference velocity (deg/s) of the last physics step: the next step's velocity
    #: less this gives the reference acceleration (every trajectory starts at rest).
    velocity: tuple[float, ...] | list[float] = ()

    #: The last sample asked for (elapsed, joints): each physics step asks for the joints
    #: where the previous one ended.
    _last: tuple[float, tuple[float, ...]] = (-1.0, ())
    #: Stopped: how it brakes along its path (:mod:`._stopping`), from ``braking_from_s``.
    braking: Braking | None = None
    braking_from_s: float = 0.0
    #: A PTP whose TCP runs faster than the robot's TCP speed limit: when it first does
    #: (s after the start) and its top speed (mm/s); None: it never does.
    over_speed: tuple[float, float] | None = None

    def joints_at(self, elapsed_s: float) -> tuple[float, ...]:
        if elapsed_s == self._last[0]:
            return self._last[1]
        joints = self._joints_at(elapsed_s)
        self._last = (elapsed_s, joints)
        return joints

    def brake(self, top_speeds_deg_s: Sequence[float]) -> None:
        """Brake to rest along the path from now (unless its own end comes first)."""
        if self.braking is not None:
            return
        t = self.elapsed_s
        progress = trapezoid_progress(t, self.duration_s, self.accel_time_s)
        rate = trapezoid_rate(t, self.duration_s, self.accel_time_s)
        gradient = path_gradient(self.samples, progress)
        braking = plan_braking(progress, rate, gradient, top_speeds_deg_s)
        if braking is not None:
            self.braking, self.braking_from_s = braking, t
            self.duration_s = t + braking.duration_s
            self._last = (-1.0, ())

    def _joints_at(self, elapsed_s: float) -> tuple[float, ...]:
        braking = self.braking
        if braking is None and elapsed_s + _EPS >= self.duration_s:
            return self.samples[-1]
        if braking is not None and elapsed_s >= self.braking_from_s:
            s = braking.progress(elapsed_s - self.braking_from_s)
        else:
            s = trapezoid_progress(elapsed_s, self.duration_s, self.accel_time_s)
        position = s * (len(self.samples) - 1)
        k = min(int(position), len(self.samples) - 2)
        frac = position - k
        a, b = self.samples[k], self.samples[k + 1]
        return tuple(x + (y - x) * frac for x, y in zip(a, b, strict=True))


def _quat(t: kin.Transform) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) of a transform's rotation."""
    r = t
    trace = r[0][0] + r[1][1] + r[2][2]
    if trace > 0:
        s = math.sqrt(trace + 1.0) * 2
        w, x = 0.25 * s, (r[2][1] - r[1][2]) / s
        y, z = (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s
    elif r[0][0] > r[1][1] and r[0][0] > r[2][2]:
        s = math.sqrt(1.0 + r[0][0] - r[1][1] - r[2][2]) * 2
        w, x = (r[2][1] - r[1][2]) / s, 0.25 * s
        y, z = (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s
    elif r[1][1] > r[2][2]:
        s = math.sqrt(1.0 + r[1][1] - r[0][0] - r[2][2]) * 2
        w, x = (r[0][2] - r[2][0]) / s, (r[0][1] + r[1][0]) / s
        y, z = 0.25 * s, (r[1][2] + r[2][1]) / s
    else:
        s = math.sqrt(1.0 + r[2][2] - r[0][0] - r[1][1]) * 2
        w, x = (r[1][0] - r[0][1]) / s, (r[0][2] + r[2][0]) / s
        y, z = (r[1][2] + r[2][1]) / s, 0.25 * s
    return (w, x, y, z)


def _fmt(values: Sequence[float]) -> str:
    return " ".join(f"{v:.9g}" for v in values)


def _frame_attrs(t: kin.Transform) -> str:
    """MJCF pos / quat attributes of a transform given in mm."""
    pos = (t[0][3] / 1000, t[1][3] / 1000, t[2][3] / 1000)
    return f'pos="{_fmt(pos)}" quat="{_fmt(_quat(t))}"'


def build_mjcf(
    model: RobotModel,
    objects: Sequence[TableObject],
    *,
    table_top_z_mm: float,
    tool: Pose | None = None,
    gripper: GripperGeometry = DEFAULT_GRIPPER,
    timestep_s: float = DEFAULT_TIMESTEP_S,
    fixtures: Sequence[Fixture] = (),
    dynamics: bool = False,
) -> str:
    """The MJCF scene: the arm from ``model.joints``, gripper at ``tool``, table, parts.

    Args:
        model: The arm.
        objects: The parts, free boxes with their size and mass.
        table_top_z_mm: Height of the table top, mm.
        tool: The TCP in the flange frame (None: the flange).
        gripper: The fingers' stroke, pads and friction.
        timestep_s: The physics step, s.
        fixtures: Static boxes (in the world body, as the table: the arm hitting one is
            a collision; parts rest on them).
        dynamics: The links get Techman's masses and inertias, feel gravity and are
            driven by torque motors limited to the joints' efforts (False: weightless
            links whose joints the backend sets).

    Returns:
        The MJCF document.

    Raises:
        ValueError: ``dynamics`` for a model whose link masses are not known.
    """
    if dynamics and model.name not in _URDF_LINKS:
        raise ValueError(
            f"dynamics: no link masses for {model.name!r} (known: {', '.join(_URDF_LINKS)})"
        )
    # Arm links: weightless and gravity-compensated when the backend sets the joints.
    comp = "" if dynamics else ' gravcomp="1"'
    lines = _mjcf_head(model, timestep_s)
    lines += _mjcf_table(table_top_z_mm, fixtures)
    indent = "    " + "  " * len(model.joints)
    lines += _mjcf_arm(model, dynamics, comp)
    lines += _mjcf_gripper(indent, tool, gripper, comp)
    for _ in model.joints:
        indent = indent[:-2]
        lines.append(f"{indent}</body>")
    lines += _mjcf_parts(objects)
    lines.append("  </worldbody>")
    lines += _mjcf_equality(len(objects), timestep_s)
    lines += _mjcf_actuators(model, dynamics)
    lines += _mjcf_sensors()
    lines.append("</mujoco>")
    return "\n".join(lines) + "\n"


def _mjcf_head(model: RobotModel, timestep_s: float) -> list[str]:
    """The document's opening: compiler, options, assets, light and floor."""
    return [
        f"<mujoco model={quoteattr('tmmaster ' + model.name)}>",
        '  <compiler angle="radian" autolimits="true"/>',
        f'  <option timestep="{timestep_s:g}" gravity="0 0 -9.81" integrator="implicitfast"'
        ' cone="elliptic" impratio="10"/>',
        '  <visual><global offwidth="800" offheight="600"/></visual>',
        "  <asset>",
        '    <texture name="grid" type="2d" builtin="checker" width="256" height="256"'
        ' rgb1=".3 .3 .35" rgb2=".25 .25 .3"/>',
        '    <material name="grid" texture="grid" texrepeat="8 8"/>',
        "  </asset>",
        "  <worldbody>",
        '    <light pos="0.3 0 2" dir="0 0 -1" diffuse=".8 .8 .8"/>',
        '    <geom name="floor" type="plane" size="2 2 0.05" material="grid"'
        ' contype="0" conaffinity="0"/>',
    ]


def _mjcf_table(table_top_z_mm: float, fixtures: Sequence[Fixture]) -> list[str]:
    """The table, the fixtures (static boxes) and the arm's base."""
    top = table_top_z_mm / 1000
    (cx, cy), (sx, sy) = TABLE_CENTRE_XY_MM, TABLE_HALF_SIZE_XY_MM
    lines = [
        f'    <geom name="table" type="box" pos="{cx / 1000:g} {cy / 1000:g} {top - 0.02:.6g}"'
        f' size="{sx / 1000:g} {sy / 1000:g} 0.02" rgba=".55 .45 .35 1"'
        f' friction="0.8 0.005 0.0001"{_RIGID}'
        f' contype="{_TABLE_BITS[0]}" conaffinity="{_TABLE_BITS[1]}"/>'
    ]
    for k, fixture in enumerate(fixtures):
        lines.append(
            f'    <geom name="fixture{k}" type="box"'
            f" {_frame_attrs(kin.pose_to_transform(fixture.pose))}"
            f' size="{_fmt([s / 2000 for s in fixture.size_mm])}" rgba=".4 .45 .55 1"'
            f' friction="0.8 0.005 0.0001"{_RIGID}'
            f' contype="{_TABLE_BITS[0]}" conaffinity="{_TABLE_BITS[1]}"/>'
        )
    lines.append(
        '    <geom name="base" type="cylinder" pos="0 0 0.04" size="0.075 0.04"'
        ' rgba=".85 .85 .85 1" contype="0" conaffinity="0"/>'
    )
    return lines


def _mjcf_arm(model: RobotModel, dynamics: bool, comp: str) -> list[str]:
    """The arm's bodies, opened and left open (the gripper goes in the last one).

    One body per joint, each holding a capsule to the next joint's origin. The capsules
    collide with the table (an arm collision); the last one stops short of the flange by
    its radius, so the wrist's collision shape ends at the flange plane.
    """
    lines: list[str] = []
    indent = "    "
    for i, spec in enumerate(model.joints):
        origin = kin.rpy_transform(
            spec.origin_xyz_mm, [math.radians(a) for a in spec.origin_rpy_deg]
        )
        lo, hi = (math.radians(v) for v in spec.limits_deg)
        lines.append(f'{indent}<body name="link{i + 1}" {_frame_attrs(origin)}{comp}>')
        indent += "  "
        if dynamics:
            mass, inertia = _URDF_LINKS[model.name][i]
            lines.append(
                f'{indent}<inertial pos="0 0 0" mass="{mass:g}" diaginertia="{_fmt(inertia)}"/>'
            )
            armature = f"{_DYN_ARMATURE[i]:g}"
        else:
            armature = "1000"
        lines.append(
            f'{indent}<joint name="j{i + 1}" type="hinge" axis="0 0 1" range="{lo:.9g} {hi:.9g}"'
            f' armature="{armature}" damping="0"/>'
        )
        lines += _mjcf_link_geom(model, i, indent)
    return lines


def _mjcf_link_geom(model: RobotModel, i: int, indent: str) -> list[str]:
    """Link ``i``'s collision shape: a capsule to the next joint (a sphere if none)."""
    nxt = model.joints[i + 1].origin_xyz_mm if i + 1 < len(model.joints) else (0.0, 0.0, 0.0)
    length = math.hypot(*nxt)
    if length > 1e-6:
        end = [v / 1000 for v in nxt]
        if i + 2 == len(model.joints):  # the wrist ends at the flange
            keep = max(0.0, 1 - _ARM_RADIUS_M / (length / 1000))
            end = [v * keep for v in end]
        return [
            f'{indent}<geom name="arm{i + 1}" type="capsule"'
            f' fromto="0 0 0 {_fmt(end)}" size="{_ARM_RADIUS_M:g}"'
            f' rgba=".9 .9 .92 1" {_ARM_CONTACT} mass="2"/>'
        ]
    if i + 1 < len(model.joints):
        return [
            f'{indent}<geom name="arm{i + 1}" type="sphere" size="{_ARM_RADIUS_M + 0.005:g}"'
            f' rgba=".9 .9 .92 1" {_ARM_CONTACT} mass="2"/>'
        ]
    return []


def _mjcf_gripper(indent: str, tool: Pose | None, gripper: GripperGeometry, comp: str) -> list[str]:
    """Flange (frame of J6) -> TCP: the gripper, fingers closing along the tool's y."""
    tcp = kin.IDENTITY if tool is None else kin.pose_to_transform(tool)
    arm = _ARM_CONTACT
    lines = [
        f'{indent}<geom name="flange" type="cylinder" pos="0 0 -0.005" size="0.032 0.005"'
        f' rgba=".2 .2 .2 1" {arm} mass="0.1"/>',
    ]
    housing = body.housing_in_flange(tool)
    if housing is not None:  # the 2FG7's housing, between the flange and the fingers
        a, b, r = housing
        lines.append(
            f'{indent}<geom name="housing" type="capsule" fromto="{_fmt([v / 1000 for v in a])}'
            f' {_fmt([v / 1000 for v in b])}" size="{r / 1000:g}" rgba=".3 .3 .35 1" {arm}'
            ' mass="0.001"/>'
        )
    lines.append(f'{indent}<body name="tcp" {_frame_attrs(tcp)}{comp}>')
    g = indent + "  "
    stroke = (gripper.min_width_mm / 2000, gripper.max_width_mm / 2000)
    # The gripper weighs what the real one does: its body in the palm, less the fingers.
    palm_kg = max(gripper.mass_kg - 2 * _FINGER_KG, 0.001)
    lines.append(
        f'{g}<geom name="palm" type="box" pos="0 0 -0.02" size="0.012 0.03 0.004"'
        f' rgba=".25 .25 .28 1" {arm} mass="{palm_kg:g}"/>'
    )
    hx, hy, hz = (
        gripper.pad_depth_mm / 2000,
        gripper.pad_thickness_mm / 2000,
        gripper.pad_height_mm / 2000,
    )
    for side, sign in (("l", 1), ("r", -1)):
        lines.append(f'{g}<body name="finger_{side}" gravcomp="1">')
        lines.append(
            f'{g}  <joint name="finger_{side}" type="slide" axis="0 {sign} 0"'
            f' range="{stroke[0]:.6g} {stroke[1]:.6g}" damping="{_FINGER_DAMPING:g}"'
            ' armature="0.01"/>'
        )
        # priority: the pad's friction, not the part's, rules a pad-part contact.
        lines.append(
            f'{g}  <geom name="pad_{side}" type="box" pos="0 {sign * hy:.6g} 0"'
            f' size="{hx:g} {hy:g} {hz:g}" rgba=".1 .1 .1 1"'
            f' friction="{gripper.friction:g} 0.005 0.0001" priority="1" condim="4"'
            ' solref="0.004 1" solimp="0.95 0.99 0.001"'
            f' mass="{_PAD_KG:g}" contype="{_PAD_BITS[0]}" conaffinity="{_PAD_BITS[1]}"/>'
        )
        lines.append(
            f'{g}  <geom type="box" pos="0 {sign * hy:.6g} {-hz - 0.003:.6g}"'
            f' size="{hx:g} {hy:g} 0.003" rgba=".3 .3 .3 1" contype="0" conaffinity="0"'
            f' mass="{_FINGER_KG - _PAD_KG:g}"/>'
        )
        lines.append(f"{g}</body>")
    lines.append(f"{indent}</body>")
    return lines


def _mjcf_parts(objects: Sequence[TableObject]) -> list[str]:
    """Parts: free boxes with their size and mass."""
    lines: list[str] = []
    for k, obj in enumerate(objects):
        t = kin.pose_to_transform(obj.pose)
        half = _fmt([s / 2000 for s in obj.size_mm])
        lines.append(f'    <body name="part{k}" {_frame_attrs(t)}>')
        lines.append(f'      <freejoint name="part{k}"/>')
        lines.append(
            f'      <geom name="part{k}" type="box" size="{half}" mass="{obj.mass_kg:.6g}"'
            f' rgba=".9 .5 .1 1" friction="0.8 0.005 0.0001" condim="4"'
            f' contype="{_PART_BITS[0]}" conaffinity="{_PART_BITS[1]}"/>'
        )
        lines.append("    </body>")
    return lines


def _mjcf_equality(parts: int, timestep_s: float) -> list[str]:
    """The fingers' coupling and a weld per part (active while a weld grasp holds it).

    The fingers move together, symmetrically about the TCP (one drive, as on the 2FG7;
    Menagerie's 2F-85 couples its fingers the same way): a part squeezed between them
    cannot shift them sideways when the arm accelerates.
    """
    lines = [
        "  <equality>",
        '    <joint name="fingers" joint1="finger_r" joint2="finger_l" polycoef="0 1 0 0 0"'
        ' solref="0.004 1" solimp="0.95 0.99 0.001"/>',
    ]
    for k in range(parts):
        lines.append(
            f'    <weld name="grip{k}" body1="tcp" body2="part{k}" active="false"'
            f' solref="{2 * timestep_s:g} 1" solimp="0.99 0.999 0.001"/>'
        )
    lines.append("  </equality>")
    return lines


def _mjcf_actuators(model: RobotModel, dynamics: bool) -> list[str]:
    """The fingers' force motors and, with dynamics, the joints' torque motors.

    The fingers are force motors: the backend computes each finger's force (a
    speed-ramped position servo while it travels, the commanded force once it is
    blocked on a part), always within the commanded force.
    """
    lines = ["  <actuator>"]
    for side in ("l", "r"):
        lines.append(f'    <motor name="finger_{side}" joint="finger_{side}" gear="1"/>')
    if dynamics:
        # The joint servos (computed by the backend) drive these torque motors, each
        # limited to its joint's effort.
        for i, effort in enumerate(_URDF_EFFORT_NM[model.name]):
            lines.append(
                f'    <motor name="a{i + 1}" joint="j{i + 1}" gear="1"'
                f' ctrlrange="{-effort:g} {effort:g}"/>'
            )
    lines.append("  </actuator>")
    return lines


def _mjcf_sensors() -> list[str]:
    """Contact sensors (cheaper to read than MuJoCo's contact list every step).

    The arm, tool or pads in the table (the deepest contact), and the net force on each
    pad from everything and from the table alone.
    """
    lines = [
        "  <sensor>",
        '    <contact name="arm_table" subtree1="link1" body2="world" num="1"'
        ' reduce="mindist" data="found dist"/>',
    ]
    for side in ("l", "r"):
        lines.append(
            f'    <contact name="pad_{side}_touch" geom1="pad_{side}" num="1"'
            ' reduce="netforce" data="found force"/>'
        )
        lines.append(
            f'    <contact name="pad_{side}_table" geom1="pad_{side}" body2="world" num="1"'
            ' reduce="netforce" data="found force"/>'
        )
    lines.append("  </sensor>")
    return lines


class _FingersAndParts:
    """The gripper's fingers and the parts of a MuJoCo scene (the base of MuJoCoBackend).

    The model, the data and the ids below are the backend's, found again at each rebuild.
    """

    _mj: Any
    _m: Any
    _d: Any
    _ready: bool
    _qpos: Any
    _ctrl: Any
    _finger_qpos: list[int]
    _finger_dof: list[int]
    _part_qpos: list[int]
    _part_dof: list[int]
    _part_body: list[int]
    _part_geom: dict[int, int]
    _pads: list[int]
    _welds: list[int]
    _sense_pads: list[int]
    _tcp_body: int
    _table: int
    _fixture_geom: dict[int, str]
    _force6: Any
    _objects: list[TableObject]
    _sensordata: Any

    def _init_parts(self, world: World, grasp: GraspMode, gripper: GripperGeometry) -> None:
        """The parts, the fixtures and the gripper's command state, before the model."""
        self._gripper = gripper
        self._grasp_mode: GraspMode = grasp
        self._gripper_min = gripper.min_width_mm
        self._gripper_max = gripper.max_width_mm
        self._objects = list(world.objects)
        self._fixtures = world.fixtures
        self._table_top_mm = world.table_top_z_mm
        # Feeder: a part that starts inside an earlier one waits out of the scene.
        self._queued = _queued_parts(self._objects)
        # Gripper command state: targets are per finger (half the width), m.
        self._finger_target = self._gripper_max / 2000
        self._finger_ctrl = self._finger_target
        self._finger_speed = 0.05
        self._finger_force = 40.0
        self._closing = False
        self._gripper_moving = False
        self._stopped_for = 0.0
        self._held: int | None = None
        self._lost_ticks = 0
        # Friction grasp: the part body the grip's safety margin loads (see _load_margin).
        self._margin_body: int | None = None
        # The TCP's height at the last collision check, mm (a pad's descent since), and
        # the parts' poses when the running motion started.
        self._last_tcp_z = -math.inf
        self._start_parts: list[Pose] = [obj.pose for obj in self._objects]

    def _body_pose(self, body: int) -> Pose:
        d = self._d
        p = d.xpos[body] * 1000.0
        r = d.xmat[body]
        t: kin.Transform = (
            (float(r[0]), float(r[1]), float(r[2]), float(p[0])),
            (float(r[3]), float(r[4]), float(r[5]), float(p[1])),
            (float(r[6]), float(r[7]), float(r[8]), float(p[2])),
            kin.IDENTITY[3],
        )
        return kin.transform_to_pose(t)

    # -- gripper ------------------------------------------------------------------------

    def _drive_fingers(self, h: float) -> None:
        """Each finger's force for this step: servo on the ramp, or the grip force if blocked."""
        # The target ramps at the commanded speed.
        step = self._finger_speed * h
        ref = self._finger_ctrl
        if ref < self._finger_target:
            ref = min(self._finger_target, ref + step)
            feed = _FINGER_DAMPING * self._finger_speed
        elif ref > self._finger_target:
            ref = max(self._finger_target, ref - step)
            feed = -_FINGER_DAMPING * self._finger_speed
        else:
            feed = 0.0
        self._finger_ctrl = ref
        force = self._finger_force
        qpos, ctrl = self._qpos, self._ctrl
        for i, adr in enumerate(self._finger_qpos):
            q = qpos[adr]
            if self._closing and q - ref > _FINGER_BLOCKED_M:
                f = -force  # blocked on a part: squeeze with the commanded force
            else:
                f = min(max(_FINGER_KP * (ref - q) + feed, -force), force)
            ctrl[i] = f

    def drive_gripper(self, width_mm: float, *, speed_mm_s: float, force_n: float) -> None:
        """Move the fingers towards ``width_mm`` at ``speed_mm_s``, squeezing with ``force_n``.

        Each finger is a force motor: while it travels it follows the target ramped at
        the commanded speed (never pushing harder than ``force_n``); once a part blocks
        it, it presses with ``force_n``.
        """
        if speed_mm_s <= 0 or not math.isfinite(speed_mm_s):
            raise ValueError(f"speed_mm_s must be > 0, got {speed_mm_s}")
        if force_n < 0 or not math.isfinite(force_n):
            raise ValueError(f"force_n must be >= 0, got {force_n}")
        if not self._ready:
            raise RuntimeError("drive_gripper while the MuJoCo model is being rebuilt")
        target = min(max(width_mm, self._gripper_min), self._gripper_max)
        # Each finger moves half the width; below 1 N the fingers could not move at all.
        self._finger_force = max(force_n, 1.0)
        self._finger_speed = speed_mm_s / 2000
        self._finger_target = target / 2000
        width = self._width_mm()
        self._closing = target < width
        if self._held is not None:
            if target <= width:
                # Squeezing a held part harder: it blocks the fingers.
                self._gripper_moving = False
                return
            self._release()
        # The new move starts where the fingers are (the old target may lie beyond a part).
        self._finger_ctrl = width / 2000
        self._stopped_for = 0.0
        self._gripper_moving = abs(target - width) > 0.05

    def _width_mm(self) -> float:
        return float(sum(self._d.qpos[a] for a in self._finger_qpos) * 1000.0)

    def _pad_contacts(self) -> tuple[set[int], set[int]]:
        """Parts touched by the left and by the right pad."""
        left: set[int] = set()
        right: set[int] = set()
        d = self._d
        data = d.sensordata
        if not (data[self._sense_pads[0]] > 0 or data[self._sense_pads[1]] > 0):
            return left, right  # neither pad touches anything: no contact to read
        for i in range(d.ncon):
            c = d.contact[i]
            g1, g2 = int(c.geom1), int(c.geom2)
            for pad, other in ((g1, g2), (g2, g1)):
                part = self._part_geom.get(other)
                if part is None:
                    continue
                if pad == self._pads[0]:
                    left.add(part)
                elif pad == self._pads[1]:
                    right.add(part)
        return left, right

    def _update_held(self) -> None:
        """Friction grasp: the part both pads touch is held; it is lost once it slipped out.

        Read once per tick. A part is let go of after two ticks without both pads on it (a
        contact that flickers for a physics step does not drop it).
        """
        left, right = self._pad_contacts()
        both = left & right
        if self._held is None:
            if both:
                self._held = min(both)
                self._lost_ticks = 0
        elif self._held in both:
            self._lost_ticks = 0
        else:
            self._lost_ticks += 1
            if self._lost_ticks >= 2:
                self._held = None  # it slipped out of the fingers

    def _update_gripper(self, h: float) -> None:
        closing = self._finger_target < self._finger_ctrl + 1e-9 and self._finger_target < (
            self._width_mm() / 2000 - 1e-6
        )
        if closing and self._held is None:
            data = self._d.sensordata
            if data[self._sense_pads[0]] > 0 and data[self._sense_pads[1]] > 0:
                left, right = self._pad_contacts()
                both = sorted(left & right)
                if both:
                    self._grasp(both[0])
                    self._gripper_moving = False
                    return
        speed = max(abs(self._d.qvel[a]) for a in self._finger_dof)
        ramp_done = self._finger_ctrl == self._finger_target
        if ramp_done and abs(self._width_mm() - self._finger_target * 2000) < 0.1:
            self._gripper_moving = False
        elif ramp_done and speed < _FINGER_STOPPED:
            self._stopped_for += h
            if self._stopped_for >= _FINGER_STOP_TIME_S:
                self._gripper_moving = False  # blocked on something
        else:
            self._stopped_for = 0.0

    def _grasp(self, k: int) -> None:
        self._held = k
        if self._grasp_mode != "weld":
            return
        mj, m, d = self._mj, self._m, self._d
        eq = self._welds[k]
        # relpose: the part's pose in the tcp frame now, so locking it moves nothing.
        tcp_pos, tcp_quat = d.xpos[self._tcp_body], d.xquat[self._tcp_body]
        part_pos, part_quat = d.xpos[self._part_body[k]], d.xquat[self._part_body[k]]
        import numpy as np

        inv_q = np.zeros(4)
        mj.mju_negQuat(inv_q, tcp_quat)
        rel_pos = np.zeros(3)
        mj.mju_rotVecQuat(rel_pos, part_pos - tcp_pos, inv_q)
        rel_quat = np.zeros(4)
        mj.mju_mulQuat(rel_quat, inv_q, part_quat)
        m.eq_data[eq, 0:3] = 0.0
        m.eq_data[eq, 3:6] = rel_pos
        m.eq_data[eq, 6:10] = rel_quat
        m.eq_data[eq, 10] = 1.0
        d.eq_active[eq] = 1

    def _load_margin(self) -> None:
        """Friction grasp: the part held weighs ``safety_factor`` times its weight on the pads.

        The kinematic backend's rule (:meth:`GripperGeometry.holds`): a grip carries a part
        when 2 x friction x force >= safety_factor x mass x g. The pads' friction alone
        would carry up to safety_factor times that (twice the 2FG7's rated force-fit
        payload); an extra downward force of (safety_factor - 1) x mass x g on the part
        held, while the fingers hold it, makes MuJoCo's contacts keep the same margin. A
        part resting on a support between the pads only presses harder on it.
        """
        xfrc = self._d.xfrc_applied
        if self._margin_body is not None:
            xfrc[self._margin_body, 2] = 0.0
            self._margin_body = None
        k = self._held
        if k is None or self._grasp_mode != "friction" or self._gripper.safety_factor <= 1:
            return
        extra = (self._gripper.safety_factor - 1) * self._objects[k].mass_kg * GRAVITY_M_S2
        self._margin_body = self._part_body[k]
        xfrc[self._margin_body, 2] = -extra

    def _release(self) -> None:
        k = self._held
        self._held = None
        if k is None:
            return
        self._d.eq_active[self._welds[k]] = 0

    def gripper_state(self) -> GripperState:
        """Current finger width, motion and contact (a part held between the pads)."""
        return GripperState(
            width_mm=self._width_mm(),
            moving=self._gripper_moving,
            contact=self._held is not None,
        )

    # -- objects ------------------------------------------------------------------------

    def _park(self, k: int) -> None:
        d = self._d
        adr, dof = self._part_qpos[k], self._part_dof[k]
        d.qpos[adr : adr + 7] = (5.0 + 0.2 * k, 5.0, -5.0, 1.0, 0.0, 0.0, 0.0)
        d.qvel[dof : dof + 6] = 0.0

    def _feed(self) -> None:
        """Put the next waiting part at its start pose once nothing occupies it."""
        for k in list(self._queued):
            obj = self._objects[k]
            busy = any(
                _boxes_overlap(
                    obj, self._objects[j].model_copy(update={"pose": self._part_pose(j)})
                )
                for j in range(len(self._objects))
                if j != k and j not in self._queued
            )
            if busy:
                continue
            self._queued.remove(k)
            t = kin.pose_to_transform(obj.pose)
            adr = self._part_qpos[k]
            self._d.qpos[adr : adr + 3] = (t[0][3] / 1000, t[1][3] / 1000, t[2][3] / 1000)
            self._d.qpos[adr + 3 : adr + 7] = _quat(t)
            self._d.qvel[self._part_dof[k] : self._part_dof[k] + 6] = 0.0
            self._mj.mj_forward(self._m, self._d)

    def _part_pose(self, k: int) -> Pose:
        if k in self._queued:
            return self._objects[k].pose
        return self._body_pose(self._part_body[k])

    def _pad_landed(self) -> BackendFault | None:
        """A pad that came down on a part: the grasp rule's collision (:func:`pad_overlaps`).

        Decided by geometry when a pad touches a part, as the kinematic backend does: the
        pad overlaps the part across and in depth, and it was above the part a physics
        step ago (its vertical overlap is within the step's descent). MuJoCo's contacts
        would otherwise push a part whose edge a pad lands on aside, by up to a step's
        descent (0.4 mm at 20 %, 2 mm at 100 %): the backends disagreed for parts 4.5-6 mm
        off centre.
        """
        z = float(self._d.xpos[self._tcp_body][2]) * 1000.0
        descent, self._last_tcp_z = max(self._last_tcp_z - z, 0.0), z
        data = self._sensordata
        if not (data[self._sense_pads[0]] > 0 or data[self._sense_pads[1]] > 0):
            return None
        left, right = self._pad_contacts()
        tcp = self._body_pose(self._tcp_body)
        width = min(self._width_mm(), self._gripper_max)
        for k in sorted(left | right):
            obj = self._objects[k].model_copy(update={"pose": self._start_parts[k]})
            pads, vertical = pad_overlaps(obj, tcp, width_mm=width, gripper=self._gripper)
            for side, overlaps, touching in (("left", pads[0], left), ("right", pads[1], right)):
                if k in touching and min(overlaps) > 0 and overlaps[vertical] <= descent + 1e-6:
                    return BackendFault(
                        "collision", f"the {side} finger came down on {self._objects[k].name}"
                    )
        return None

    def _held_pressed(self, limit_n: float) -> BackendFault | None:
        """The part held pressed on the table or a fixture harder than ``limit_n``.

        The weld holds the part whatever the force: without this the arm pressed a held
        part into the table with hundreds of newtons and never reached its target. In a
        friction grasp the part slips in the pads first (at most 2 x friction x grip).
        """
        k = self._held
        assert k is not None
        mj, m, d = self._mj, self._m, self._d
        force = self._force6
        for i in range(d.ncon):
            contact = d.contact[i]
            g1, g2 = int(contact.geom1), int(contact.geom2)
            if self._part_geom.get(g1) == k:
                other = g2
            elif self._part_geom.get(g2) == k:
                other = g1
            else:
                continue
            if other != self._table and other not in self._fixture_geom:
                continue
            mj.mj_contactForce(m, d, i, force)
            if force[0] > limit_n:
                where = self._fixture_geom.get(other)
                what = "the table" if where is None else f"fixture {where}"
                name = self._objects[k].name
                return BackendFault(
                    "collision", f"the held part {name} pressed on {what} with {force[0]:.0f} N"
                )
        return None

    def _obstacle(self) -> str:
        """What the arm touches: "fixture NAME" when a fixture, else "the table"."""
        d = self._d
        for i in range(d.ncon):
            g1, g2 = int(d.contact[i].geom1), int(d.contact[i].geom2)
            for fixture, other in ((g1, g2), (g2, g1)):
                name = self._fixture_geom.get(fixture)
                if name is not None and other not in self._part_geom:  # a part resting on it
                    return f"fixture {name}"
        return "the table"

    def _resting_on(self, k: int) -> str | None:
        if k == self._held:
            return None
        if k in self._queued:
            return TABLE
        d = self._d
        dof = self._part_dof[k]
        v = d.qvel[dof : dof + 6]
        if math.hypot(*v[:3]) > _REST_LINEAR or math.hypot(*v[3:]) > _REST_ANGULAR:
            return None
        my_geom = next(g for g, j in self._part_geom.items() if j == k)
        z = d.xpos[self._part_body[k]][2]
        support: str | None = None
        for i in range(d.ncon):
            c = d.contact[i]
            g1, g2 = int(c.geom1), int(c.geom2)
            if my_geom not in (g1, g2):
                continue
            other = g2 if g1 == my_geom else g1
            if other == self._table:
                return TABLE
            if other in self._fixture_geom:
                return self._fixture_geom[other]
            j = self._part_geom.get(other)
            if j is not None and d.xpos[self._part_body[j]][2] < z:
                support = self._objects[j].name
        return support

    def objects(self) -> list[ObjectState]:
        """Every part with its pose (centre), size, mass, held flag and support."""
        return [
            ObjectState(
                name=obj.name,
                pose=self._part_pose(k),
                held=k == self._held,
                size_mm=obj.size_mm,
                mass_kg=obj.mass_kg,
                resting_on=self._resting_on(k),
            )
            for k, obj in enumerate(self._objects)
        ]


class MuJoCoBackend(_FingersAndParts):
    """MuJoCo :class:`~tmmaster.sim.PhysicsBackend`: joint-space arm, gripper, falling parts.

    Args:
        model: The arm (``tmmaster.robot_model("tm5-700")``).
        world: The parts and the table (None: one part at ``DEFAULT_PART_POSE``).
        home: The TCP pose at the start (None: the model's ready posture).
        tool: The TCP in the flange frame (None: the TCP is the flange).
        grasp: ``"friction"`` (the pads hold a part by friction alone: a part too heavy
            for the grip force slips out) or ``"weld"`` (once both pads touch a part it is
            locked to the tool, whatever its mass).
        gripper: The fingers' stroke, pads and friction (None: an OnRobot 2FG7).
        timestep_s: The physics step, s.
        gripper_min_width_mm: The fingers' smallest width (None: the gripper's), mm.
        gripper_max_width_mm: The fingers' largest width (None: the gripper's), mm.
        keep_motion_on_reinit: A rebuild keeps the running motion (False: loses it).
        collision_force_n: A pad pressing on a part it does not hold harder than this while
            the arm moves is a collision, N.
        dynamics: Arm dynamics: the links get the masses and inertias of Techman's URDF
            and feel gravity, and each joint is a servo (PD plus the arm's own gravity
            and the planned acceleration through its mass matrix, an integral term for
            a payload it does not know of) whose torque is limited to the joint's
            effort, following the planned trajectory as its reference: the joints and
            TCP reported are where the joints are (they lag the reference with a part
            the servo does not know of), and a move is done only once every
            joint has settled within ``SETTLE_TOLERANCE_DEG`` of its target. False: an
            ideal servo, the joints follow the trajectory exactly (no lag, no
            settling). None (the default): on for the models whose link masses are
            known (:func:`has_dynamics_data`: the TM5-700 and TM5-900), off for the
            others; :attr:`dynamics` says which.

    Raises:
        PhysicsUnavailableError: ``mujoco`` is not installed.
        ValueError: A bad time step, stroke or grasp mode, an unreachable ``home``, or
            ``dynamics`` for a model whose link masses are not known.
    """

    def __init__(
        self,
        model: RobotModel,
        *,
        world: World | None = None,
        home: Pose | None = None,
        tool: Pose | None = None,
        grasp: GraspMode = "friction",
        gripper: GripperGeometry | None = None,
        timestep_s: float = DEFAULT_TIMESTEP_S,
        gripper_min_width_mm: float | None = None,
        gripper_max_width_mm: float | None = None,
        keep_motion_on_reinit: bool = True,
        collision_force_n: float = DEFAULT_COLLISION_FORCE_N,
        dynamics: bool | None = None,
    ) -> None:
        self._mj = _import_mujoco()
        if dynamics is None:
            dynamics = has_dynamics_data(model.name)
        require_in("timestep_s", timestep_s, Bounds(0, 0.01, "s", open_low=True))
        if grasp not in GRASP_MODES:
            raise ValueError(f"grasp must be one of {', '.join(GRASP_MODES)}, got {grasp!r}")
        require_positive("collision_force_n", collision_force_n)
        geometry = gripper_geometry(gripper, gripper_min_width_mm, gripper_max_width_mm)
        world = World() if world is None else world
        self._model = model
        self._tool = tool
        self._timestep = timestep_s
        self._collision_force = collision_force_n
        self.keep_motion_on_reinit = keep_motion_on_reinit
        self._init_parts(world, grasp, geometry)
        self._xml = build_mjcf(
            model,
            self._objects,
            table_top_z_mm=world.table_top_z_mm,
            tool=tool,
            gripper=self._gripper,
            timestep_s=timestep_s,
            dynamics=dynamics,
            fixtures=world.fixtures,
        )
        self._dynamics = dynamics
        self._init_servo(model)
        self._hold = _home_joints(model, home, tool)
        self._trajectory: _Trajectory | None = None
        self._time_rate = 1.0
        self._ready = True
        self._pending_s = 0.0
        #: Simulated seconds stepped so far.
        self.sim_time_s = 0.0
        #: Wall seconds spent in the last rebuild (``reinitialize()``).
        self.last_rebuild_s = 0.0
        self.rebuilds = 0
        # Collisions: the arm's table penetration the running motion started with (m;
        # -1: none), and the fault not yet taken by the controller.
        self._start_depth = -1.0
        # ... and the arm's parts meeting each other or the mounting plane then (mm).
        self._start_body: dict[tuple[str, str], float] = {}
        self._fault: BackendFault | None = None
        self._build(None)

    def _init_servo(self, model: RobotModel) -> None:
        """The joint servo's state (used with dynamics)."""
        # Gains per joint, the integral term's torque (N m), and the last reference (rad,
        # rad/s) and the torques (N m) commanded.
        self._kp: list[float] = []
        self._kd: list[float] = []
        self._servo_joints: list[tuple[int, int, float, float, float]] = []
        self._integral = [0.0] * len(model.joints)
        self._effort = list(_URDF_EFFORT_NM.get(model.name, ()))
        #: The joints' top speeds, rad/s: the servo never turns a joint faster.
        self._top_speeds = [w * _RAD for w in model.joint_speed_deg_s]
        #: Largest tracking error seen since the last start of a motion (deg, per joint).
        self.max_tracking_error_deg = [0.0] * len(model.joints)
        #: With dynamics: the physics steps of the current move at which each joint's
        #: servo asked for more than the joint's effort and was held at it (saturated).
        self.saturated_steps = [0] * len(model.joints)
        # Stopped by a fault (dynamics): at rest once the joints stop, wherever what was
        # hit holds them; the integral term stops growing, so the servo does not press
        # ever harder into it. The next motion clears it.
        self._blocked = False

    # -- model --------------------------------------------------------------------------

    @property
    def tool(self) -> Pose | None:
        """The TCP in the flange frame (None: the TCP is the flange); fixed with the scene."""
        return self._tool

    @property
    def model(self) -> RobotModel:
        """The arm model whose kinematics and limits plan the motions."""
        return self._model

    @property
    def gripper(self) -> GripperGeometry:
        """The fingers' stroke, pads and friction."""
        return self._gripper

    @property
    def grasp(self) -> GraspMode:
        """``"friction"`` or ``"weld"``: how a part between the pads is held."""
        return self._grasp_mode

    @property
    def mjcf(self) -> str:
        """The generated MJCF scene."""
        return self._xml

    @property
    def mj_model(self) -> Any:
        """The ``mujoco.MjModel`` (rebuilt by :meth:`reinitialize`)."""
        return self._m

    @property
    def mj_data(self) -> Any:
        """The ``mujoco.MjData``."""
        return self._d

    @property
    def motion_running(self) -> bool:
        """True while a trajectory is being followed."""
        return self._trajectory is not None

    def _build(self, snapshot: dict[str, Any] | None) -> None:
        mj = self._mj
        m = mj.MjModel.from_xml_string(self._xml)
        d = mj.MjData(m)
        self._m, self._d = m, d
        self._find_arm(m, d)
        self._find_scene(m)
        if snapshot is None:
            for adr, q in zip(self._arm_qpos, self._hold, strict=True):
                d.qpos[adr] = math.radians(q)
            for adr in self._finger_qpos:
                d.qpos[adr] = self._finger_ctrl
            for k in self._queued:
                self._park(k)
        else:
            d.qpos[:] = snapshot["qpos"]
            d.qvel[:] = snapshot["qvel"]
            d.ctrl[:] = snapshot["ctrl"]
            d.time = snapshot["time"]
            m.eq_data[:] = snapshot["eq_data"]
            d.eq_active[:] = snapshot["eq_active"]
        mj.mj_forward(m, d)
        if self._dynamics and not self._kp:
            self._servo_gains(m)

    def _ident(self, m: Any, kind: Any, label: str) -> int:
        """The id of MuJoCo object ``label`` of ``kind`` (an ``mjtObj``)."""
        return int(self._mj.mj_name2id(m, kind, label))

    def _joint(self, m: Any, label: str) -> tuple[int, int]:
        """Joint ``label``'s address in qpos and in qvel."""
        j = self._ident(m, self._mj.mjtObj.mjOBJ_JOINT, label)
        return int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])

    def _find_arm(self, m: Any, d: Any) -> None:
        """The arm's joints and MjData's arrays the steps write (cached)."""
        arm = [self._joint(m, f"j{i}") for i in range(1, 7)]
        self._arm_qpos, self._arm_dof = [a for a, _ in arm], [b for _, b in arm]
        # MjData's arrays, cached: reading the attribute costs as much as the write.
        self._qpos, self._qvel, self._ctrl = d.qpos, d.qvel, d.ctrl
        self._sensordata = d.sensordata
        self._bias = d.qfrc_bias
        # The servo's acceleration feed-forward M(q) a_ref: a_ref at the arm's dofs (one
        # chain, so consecutive; the fingers' and parts' stay 0) and the torques, arrays
        # reused every step.
        import numpy as np

        first = self._arm_dof[0]
        self._arm_dofs = slice(first, first + len(self._arm_dof))
        if self._arm_dof != list(range(first, self._arm_dofs.stop)):
            raise RuntimeError(f"the arm's joints are not consecutive dofs: {self._arm_dof}")
        self._accel = np.zeros(m.nv)
        self._inertial = np.zeros(m.nv)

    def _find_scene(self, m: Any) -> None:
        """The fingers', pads', parts', fixtures' and sensors' ids and addresses."""
        obj = self._mj.mjtObj

        def ident(kind: Any, label: str) -> int:
            return self._ident(m, kind, label)

        def sensor(label: str) -> int:
            return int(m.sensor_adr[ident(obj.mjOBJ_SENSOR, label)])

        parts = range(len(self._objects))
        fingers = [self._joint(m, f"finger_{s}") for s in ("l", "r")]
        free = [self._joint(m, f"part{k}") for k in parts]
        self._finger_qpos, self._finger_dof = [a for a, _ in fingers], [b for _, b in fingers]
        self._part_qpos, self._part_dof = [a for a, _ in free], [b for _, b in free]
        self._pads = [ident(obj.mjOBJ_GEOM, f"pad_{s}") for s in ("l", "r")]
        self._table = ident(obj.mjOBJ_GEOM, "table")
        self._fixture_geom = {
            ident(obj.mjOBJ_GEOM, f"fixture{k}"): f.name for k, f in enumerate(self._fixtures)
        }
        self._tcp_body = ident(obj.mjOBJ_BODY, "tcp")
        self._flange_body = ident(obj.mjOBJ_BODY, "link6")
        self._part_body = [ident(obj.mjOBJ_BODY, f"part{k}") for k in parts]
        self._part_geom = {ident(obj.mjOBJ_GEOM, f"part{k}"): k for k in parts}
        import numpy as np

        self._force6 = np.zeros(6)  # a contact's force, for mj_contactForce
        self._welds = [ident(obj.mjOBJ_EQUALITY, f"grip{k}") for k in parts]
        self._sense_table = sensor("arm_table")
        self._sense_pads = [sensor("pad_l_touch"), sensor("pad_r_touch")]
        self._sense_pad_table = [sensor("pad_l_table"), sensor("pad_r_table")]

    def _servo_gains(self, m: Any) -> None:
        """PD gains: ``_SERVO_HZ`` / ``_SERVO_ZETA`` for each joint's inertia when ready."""
        mj = self._mj
        d = mj.MjData(m)
        for adr, q in zip(self._arm_qpos, self._model.ready_joints_deg, strict=True):
            d.qpos[adr] = math.radians(q)
        mj.mj_forward(m, d)
        import numpy as np

        full = np.zeros((m.nv, m.nv))
        mj.mj_fullM(m, d, full)
        w = 2 * math.pi * _SERVO_HZ
        for dof in self._arm_dof:
            inertia = float(full[dof, dof])  # the diagonal, armature included
            self._kp.append(inertia * w * w)
            self._kd.append(2 * _SERVO_ZETA * inertia * w)
        self._servo_joints = list(
            zip(self._arm_qpos, self._arm_dof, self._kp, self._kd, self._effort, strict=True)
        )

    def _snapshot(self) -> dict[str, Any]:
        m, d = self._m, self._d
        return {
            "qpos": d.qpos.copy(),
            "qvel": d.qvel.copy(),
            "ctrl": d.ctrl.copy(),
            "time": d.time,
            "eq_data": m.eq_data.copy(),
            "eq_active": d.eq_active.copy(),
        }

    # -- the ready / reinitialize contract ----------------------------------------------

    def invalidate(self) -> None:
        """Drop the physics view (as a scene reload would) until :meth:`reinitialize`."""
        self._ready = False

    def is_ready(self) -> bool:
        """False after :meth:`invalidate` until :meth:`reinitialize` rebuilt the model."""
        return self._ready

    def reinitialize(self) -> bool:
        """Rebuild the MuJoCo model and data from the MJCF and the last state.

        The running trajectory is kept (True) unless ``keep_motion_on_reinit`` is False:
        then the arm holds where it is and the motion is lost (False).
        """
        start = time.perf_counter()
        snapshot = self._snapshot()
        self._build(snapshot)
        self.last_rebuild_s = time.perf_counter() - start
        self.rebuilds += 1
        self._ready = True
        if self._trajectory is not None and not self.keep_motion_on_reinit:
            self.halt_motion()
            return False
        return True

    # -- arm ----------------------------------------------------------------------------

    def _current_joints(self) -> tuple[float, ...]:
        return tuple(math.degrees(self._d.qpos[a]) for a in self._arm_qpos)

    def start_motion(
        self, target: Pose, *, motion: MotionType, speed_percent: float, accel_time_s: float
    ) -> float:
        """Plan the joint trajectory to ``target`` and start it; return its duration in s."""
        if accel_time_s < 0:
            raise ValueError(f"accel_time_s must be >= 0, got {accel_time_s}")
        if not self._ready:
            raise RuntimeError("start_motion while the MuJoCo model is being rebuilt")
        here = self._command_joints()
        start = self._model.forward(here, tool=self._tool)
        try:
            samples: list[tuple[float, ...]] = [here]
            if motion is MotionType.LINE:
                path = self._model.line_joints(
                    start, target, start_joints_deg=here, tool=self._tool
                )
                samples += [tuple(q) for q in path[1:]]
                duration = self._model.line_time(
                    start,
                    target,
                    speed_percent=speed_percent,
                    accel_time_s=accel_time_s,
                    tool=self._tool,
                    samples=path,
                )
            else:
                samples.append(tuple(self._model.inverse(target, seed_deg=here, tool=self._tool)))
                duration = self._model.ptp_time(
                    here, samples[-1], speed_percent=speed_percent, accel_time_s=accel_time_s
                )
        except UnreachablePoseError as exc:
            reason: RejectReason = "reach"
            if exc.reason == "joint_limit":
                reason = "joint_limit"
            elif exc.reason == "singularity":
                reason = "singularity"
            raise MotionRejectedError(reason, str(exc)) from exc
        self._follow(samples, duration, accel_time_s)
        if motion is not MotionType.LINE:
            self._watch_speed(samples[-1], speed_percent, accel_time_s)
        return duration

    def start_joint_motion(
        self, joints_deg: Sequence[float], *, speed_percent: float, accel_time_s: float
    ) -> float:
        """Start a joint-space PTP to exactly ``joints_deg``; return its duration in s."""
        if accel_time_s < 0:
            raise ValueError(f"accel_time_s must be >= 0, got {accel_time_s}")
        if not self._ready:
            raise RuntimeError("start_joint_motion while the MuJoCo model is being rebuilt")
        here = self._command_joints()
        try:
            joints = self._model.check_joints(joints_deg, tool=self._tool)
        except UnreachablePoseError as exc:
            raise MotionRejectedError(_reject_reason(exc.reason), str(exc)) from exc
        duration = self._model.ptp_time(
            here, joints, speed_percent=speed_percent, accel_time_s=accel_time_s
        )
        self._follow([here, tuple(joints)], duration, accel_time_s)
        self._watch_speed(joints, speed_percent, accel_time_s)
        return duration

    def start_arc_motion(
        self, via: Pose, target: Pose, *, speed_percent: float, accel_time_s: float
    ) -> float:
        """Start a circular arc through ``via``'s position to ``target``; return its duration."""
        if accel_time_s < 0:
            raise ValueError(f"accel_time_s must be >= 0, got {accel_time_s}")
        if not self._ready:
            raise RuntimeError("start_arc_motion while the MuJoCo model is being rebuilt")
        here = self._command_joints()
        start = self._model.forward(here, tool=self._tool)
        try:
            path = self._model.arc_joints(
                start, via, target, start_joints_deg=here, tool=self._tool
            )
        except UnreachablePoseError as exc:
            raise MotionRejectedError(_reject_reason(exc.reason), str(exc)) from exc
        except ConfigError as exc:  # no arc through the points
            raise MotionRejectedError("reach", str(exc)) from exc
        duration = self._model.arc_time(
            start,
            via,
            target,
            speed_percent=speed_percent,
            accel_time_s=accel_time_s,
            tool=self._tool,
            samples=path,
        )
        return self._follow([here, *(tuple(q) for q in path[1:])], duration, accel_time_s)

    def _follow(
        self, samples: list[tuple[float, ...]], duration: float, accel_time_s: float
    ) -> float:
        """Start following joint ``samples`` over ``duration``; return it."""
        self._trajectory = _Trajectory(samples, duration, accel_time_s)
        self._blocked = False
        self.max_tracking_error_deg = [0.0] * len(samples[0])
        self.saturated_steps = [0] * len(samples[0])
        # A contact the arm already had (a collision it is backing out of) is known: only
        # a deeper one is a collision.
        self._start_depth = self._table_depth()
        # Where the parts were when the motion started (a pad landing on one is judged
        # against that, not against where its first soft contact pushed it).
        self._start_parts = [self._part_pose(k) for k in range(len(self._objects))]
        self._start_body = self._body_depths(self._current_joints())
        return duration

    def _watch_speed(
        self, joints: Sequence[float], speed_percent: float, accel_time_s: float
    ) -> None:
        """The PTP just started: when its TCP first runs faster than the robot's TCP speed
        limit (:func:`~._stopping.over_speed_at`, by the reference the servo follows)."""
        trajectory = self._trajectory
        assert trajectory is not None
        model = self._model
        start, end = (cast(Joints, tuple(q)) for q in (trajectory.samples[0], joints))
        speeds = model.ptp_tcp_speeds(start, end, speed_percent, accel_time_s, self._tool)
        limit = model.tcp_speed_limit_mm_s
        trajectory.over_speed = over_speed_at(speeds, trajectory.duration_s, limit)

    def _motion_fault(self, trajectory: _Trajectory) -> BackendFault | None:
        """What stops the moving arm at this physics step: a collision, an overload or a
        PTP past the TCP speed limit (None: nothing)."""
        return self._check_collision() or self._overload() or self._over_speed(trajectory)

    def _over_speed(self, trajectory: _Trajectory) -> BackendFault | None:
        """The PTP's reference reached the time its TCP first runs past the speed limit."""
        over = trajectory.over_speed
        if over is None or trajectory.braking is not None or trajectory.elapsed_s < over[0]:
            return None
        trajectory.over_speed = None
        return speed_fault(self._model.tcp_speed_limit_mm_s, over[1])

    def _body_depths(self, joints: tuple[float, ...]) -> dict[tuple[str, str], float]:
        """The arm's parts meeting each other or the mounting plane at ``joints``, mm."""
        return {
            (c.first, c.second): -c.distance_mm
            for c in body.contacts(self._model, joints, self._tool)
        }

    def _body_fault(self, joints: tuple[float, ...]) -> BackendFault | None:
        """Self-collision or a part at the mounting plane at ``joints``, deeper than when
        the motion started (the master's capsules, :mod:`tmmaster._body`), once a tick."""
        for (first, second), depth in self._body_depths(joints).items():
            if depth > self._start_body.get((first, second), -1.0) + _COLLISION_DEPTH_M * 1000:
                return BackendFault(
                    "collision", f"the arm hit {second} ({first}, {depth:.1f} mm deep)"
                )
        return None

    def _command_joints(self) -> tuple[float, ...]:
        trajectory = self._trajectory
        if trajectory is None:
            return self._hold
        return trajectory.joints_at(trajectory.elapsed_s)

    def scale_time(self, rate: float) -> None:
        """From now on, run the motion's time ``rate`` times as fast as planned (1: as
        planned), a braking included: the robot's speed override changed mid-move. The
        servo follows the faster or slower reference.

        Args:
            rate: Simulated motion seconds per simulated second, > 0.
        """
        self._time_rate = rate

    def stop_motion(self) -> None:
        """Brake to rest along the path (:mod:`._stopping`): the arm moves until at rest.

        The reference decelerates along the trajectory; once it ends, the servo holds
        where it ended (with dynamics, a payload included: no sag).
        """
        if self._trajectory is not None:
            self._trajectory.brake(self._model.joint_speed_deg_s)

    def halt_motion(self) -> None:
        """Hold the current joints now, with no braking (a stalled arm, a lost motion).

        With dynamics, the joints where they are, not the reference that leads them.
        """
        if self._trajectory is not None:
            self._hold = self._current_joints() if self._dynamics else self._command_joints()
            self._trajectory = None

    def is_settled(self) -> bool:
        """True when no trajectory runs (and, with dynamics, the joints settled at its end)."""
        if self._trajectory is not None:
            return False
        if not self._dynamics:
            return True
        qpos, qvel = self._qpos, self._qvel
        for adr, dof, q in zip(self._arm_qpos, self._arm_dof, self._hold, strict=True):
            if abs(qvel[dof] / _RAD) > SETTLE_SPEED_DEG_S:
                return False
            # Stopped by a fault, the arm rests where what it hit holds it: it may never
            # reach the joints it held at the fault, and no move of it is reported done.
            if not self._blocked and abs(qpos[adr] / _RAD - q) > SETTLE_TOLERANCE_DEG:
                return False
        return True

    @property
    def dynamics(self) -> bool:
        """True when the joints are torque-driven servos, False for the ideal servo.

        Returns:
            Whether the arm's dynamics are modelled (see the class docstring).
        """
        return self._dynamics

    def reference_joints_deg(self) -> tuple[float, ...]:
        """The joints the servo is told to be at now (the trajectory's sample), deg."""
        return self._command_joints()

    def joint_positions_deg(self) -> tuple[float, ...]:
        """Current joint angles J1..J6, degrees."""
        return self._current_joints()

    def tcp_pose(self) -> Pose:
        """Current TCP pose (the gripper's grasp point), from MuJoCo's kinematics."""
        return self._body_pose(self._tcp_body)

    def flange_pose(self) -> Pose:
        """Current flange pose (frame of J6)."""
        return self._body_pose(self._flange_body)

    # -- faults -------------------------------------------------------------------------

    def take_fault(self) -> BackendFault | None:
        """The collision or overload that stopped the arm since the last call, once.

        Returns:
            The fault, or None.
        """
        fault, self._fault = self._fault, None
        return fault

    def _table_depth(self) -> float:
        """How deep the arm, tool or pads are in the table (m); -1 when they do not touch."""
        data = self._sensordata
        adr = self._sense_table
        return -float(data[adr + 1]) if data[adr] > 0 else -1.0

    def _check_collision(self) -> BackendFault | None:
        """A contact the moving arm did not expect, from this step's contact sensors."""
        depth = self._table_depth()
        if depth >= 0 and depth > self._start_depth + _COLLISION_DEPTH_M:
            return BackendFault(
                "collision", f"the arm hit {self._obstacle()} ({depth * 1000:.1f} mm deep)"
            )
        if self._held is not None:
            return self._held_pressed(self._collision_force)
        landed = self._pad_landed()
        if landed is not None:
            return landed
        data = self._sensordata
        for adr, table, side in zip(
            self._sense_pads, self._sense_pad_table, ("left", "right"), strict=True
        ):
            if data[adr] <= 0:
                continue
            # The pad's net contact force, less what the table pushes on it: the parts'.
            force = math.hypot(*(data[adr + i] - data[table + i] for i in (1, 2, 3)))
            if force > self._collision_force:
                return BackendFault(
                    "collision", f"the {side} finger pressed on a part with {force:.0f} N"
                )
        return None

    def _overload(self) -> BackendFault | None:
        """The gripper and the part held weigh more than the arm's rated payload.

        Checked while the arm moves, not while it brakes for a stop (already stopping).
        """
        trajectory = self._trajectory
        if self._held is None or (trajectory is not None and trajectory.braking is not None):
            return None
        part: TableObject | None = self._objects[self._held]
        if self._grasp_mode == "friction" and not self._gripper.holds(
            self._objects[self._held].mass_kg, self._finger_force
        ):
            part = None  # squeezed, but too heavy for the grip: it stays behind
        return over_payload(part, self._gripper, self._model.payload_kg)

    def _stop_for(self, fault: BackendFault, joints: tuple[float, ...]) -> None:
        """Stop for ``fault``: a collision where it showed, anything else by braking.

        A collision stops the arm at the step's pose (what it hit holds it). With
        dynamics the servo then holds where the joints are, not where the reference
        was: the reference leads them, and holding it would press into what was hit;
        the arm is at rest once its joints stop (see :meth:`is_settled`). An overload
        brakes along the path as a stop does (:meth:`stop_motion`).
        """
        self._fault = fault
        if fault.kind != "collision":
            self.stop_motion()  # nothing holds the arm: it brakes along its path
            return
        self._trajectory = None
        self._hold = self._current_joints() if self._dynamics else joints
        # The integral term keeps what it held (a payload: no sag) and stops growing.
        self._blocked = self._dynamics

    # -- simulation ---------------------------------------------------------------------

    def step(self, dt: float) -> None:
        """Advance the physics by ``dt`` simulated seconds (whole physics steps)."""
        if dt < 0 or not math.isfinite(dt):
            raise ValueError(f"dt must be a finite number >= 0, got {dt}")
        if not self._ready:
            return
        self._pending_s += dt
        steps = int(self._pending_s / self._timestep + 1e-6)
        self._pending_s -= steps * self._timestep
        self._load_margin()
        moving = self._trajectory is not None
        for _ in range(steps):
            self._substep()
        if moving and steps and self._fault is None:
            joints = self._current_joints()
            fault = self._body_fault(joints)
            if fault is not None:
                self._stop_for(fault, joints)
        if self._queued:
            self._feed()  # once per tick: a waiting part appears when its spot is free
        if self._grasp_mode == "friction" and self._closing:
            self._update_held()
        if not self._dynamics:
            # Report exactly the commanded joints (the integrator moved them by a hair).
            self._set_arm(self._command_joints(), None)
        # The poses of the joints the last step ended with (mj_step leaves them one step
        # behind).
        self._mj.mj_kinematics(self._m, self._d)

    def _set_arm(self, joints: Sequence[float], velocity: Sequence[float] | None) -> None:
        # Element writes into the cached arrays: the cheapest way into MjData from Python
        # (this runs every physics step).
        qpos, qvel = self._qpos, self._qvel
        for adr, q in zip(self._arm_qpos, joints, strict=True):
            qpos[adr] = q * _RAD
        if velocity is None:
            for adr in self._arm_dof:
                qvel[adr] = 0.0
        else:
            for adr, w in zip(self._arm_dof, velocity, strict=True):
                qvel[adr] = w * _RAD

    def _servo(
        self,
        reference: Sequence[float],
        velocity: Sequence[float] | None,
        acceleration_rad: list[float] | None = None,
    ) -> None:
        """Each joint's torque towards ``reference`` (deg) moving at ``velocity`` (deg/s).

        PD on the error plus the arm's own gravity and Coriolis torques (MuJoCo's bias
        force of the last step: a part held is not in it) plus the torque of the
        reference's acceleration (``acceleration_rad``, rad/s^2) through the mass matrix
        of the last step (the arm's links, armature, gripper and fingers: a part held,
        welded or gripped, is a body of its own, not in it) plus an integral term, the
        total limited to the joint's effort (the integral stops growing at the limit).
        """
        # Plain floats (tolist) and one slice write: numpy scalars cost more than the maths.
        qpos, qvel = self._qpos.tolist(), self._qvel.tolist()
        if acceleration_rad is None:
            bias = self._bias.tolist()
        else:
            self._accel[self._arm_dofs] = acceleration_rad
            inertial = self._inertial
            self._mj.mj_mulM(self._m, self._d, inertial, self._accel)
            inertial += self._bias
            bias = inertial.tolist()
        h = self._timestep
        worst = self.max_tracking_error_deg
        saturated = self.saturated_steps
        integral = self._integral
        blocked = self._blocked
        torques = []
        for i, (adr, dof, kp, kd, effort) in enumerate(self._servo_joints):
            error = reference[i] * _RAD - qpos[adr]
            speed = qvel[dof]
            v_error = -speed if velocity is None else velocity[i] * _RAD - speed
            grown = integral[i] if blocked else integral[i] + kp * error * h / _SERVO_TI_S
            torque = kp * error + kd * v_error + bias[dof] + grown
            if -effort < torque < effort:
                integral[i] = grown
            else:
                torque = effort if torque > 0 else -effort
                saturated[i] += 1
            torques.append(torque)
            e = abs(error) / _RAD
            if e > worst[i]:
                worst[i] = e
        self._ctrl[2:8] = torques

    def _clip_speeds(self) -> None:
        """With dynamics, no joint turns faster than its top speed (a drive's speed limit)."""
        if not self._dynamics:
            return  # the joints follow the planned trajectory exactly
        qvel = self._qvel
        for dof, top in zip(self._arm_dof, self._top_speeds, strict=True):
            w = qvel[dof]
            if w > top:
                qvel[dof] = top
            elif w < -top:
                qvel[dof] = -top

    def _substep(self) -> None:
        h = self._timestep
        trajectory = self._trajectory
        now = self._hold
        if trajectory is None:
            if self._dynamics:
                self._servo(now, None)
            else:
                self._set_arm(self._hold, None)
        else:
            now = trajectory.joints_at(trajectory.elapsed_s)
            trajectory.elapsed_s += h * self._time_rate
            nxt = trajectory.joints_at(trajectory.elapsed_s)
            velocity = [(b - a) / h for a, b in zip(now, nxt, strict=True)]
            if self._dynamics:
                # Computed torque on the sampled reference, consistent with the step:
                # the arm on the reference now (joints ``now``, moving at the last step's
                # velocity, which brought it there) reaches ``nxt`` at the end of this
                # step when its velocity changes to ``velocity``, so the feed-forward
                # acceleration is that change over the step. Differencing rather than
                # the trapezoid's phase: the joint samples are a polyline swept by the
                # trapezoid, and the difference holds both the profile's acceleration and
                # the polyline's turn at a sample, the PD then seeing no error on an arm
                # that follows exactly.
                last = trajectory.velocity or [0.0] * len(velocity)
                scale = _RAD / h
                accel = [(v - u) * scale for u, v in zip(last, velocity, strict=True)]
                trajectory.velocity = velocity
                cruising = min(accel) > -_FF_MIN_ACCEL and max(accel) < _FF_MIN_ACCEL
                self._servo(now, last, None if cruising else accel)
            else:
                self._set_arm(now, velocity)
            if trajectory.elapsed_s + _EPS >= trajectory.duration_s:
                self._hold = trajectory.joints_at(trajectory.duration_s)
                self._trajectory = None
        self._drive_fingers(h)
        for k in self._queued:
            self._park(k)
        self._mj.mj_step(self._m, self._d)
        self.sim_time_s += h
        self._clip_speeds()
        if trajectory is not None:
            fault = self._motion_fault(trajectory)
            if fault is not None:
                self._stop_for(fault, now)
        if self._gripper_moving:
            self._update_gripper(h)

    # -- pictures -----------------------------------------------------------------------

    def snapshot(self, path: Path, *, width: int = 800, height: int = 600) -> Path:
        """Render the scene offscreen to a PNG at ``path`` (needs an OpenGL context: EGL/OSMesa)."""
        mj = self._mj
        renderer = mj.Renderer(self._m, height=height, width=width)
        try:
            camera = mj.MjvCamera()
            camera.lookat[:] = (0.3, 0.0, 0.1)
            camera.distance = 1.3
            camera.azimuth = 210.0
            camera.elevation = -40.0
            renderer.update_scene(self._d, camera=camera)
            pixels = renderer.render()
        finally:
            renderer.close()
        _write_png(path, pixels)
        return path


def save_snapshot(
    sim: _RunningSimulator, directory: str | Path, name: str = "cell-end.png"
) -> Path:
    """Render the MuJoCo scene of ``sim`` to ``directory/name`` (PNG); return the path.

    Needs an OpenGL context: PyOpenGL (extra ``tmmaster[mujoco-render]``) and, headless,
    ``MUJOCO_GL=egl`` set before ``mujoco`` is first imported.
    """
    from pathlib import Path

    backend = sim.backend
    if not isinstance(backend, MuJoCoBackend):
        raise ConfigError("a snapshot needs the MuJoCo backend (--sim-physics mujoco)")
    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    try:
        return sim.call(lambda: backend.snapshot(folder / name))
    except ImportError as exc:
        raise PhysicsUnavailableError(
            "offscreen rendering needs OpenGL: pip install 'tmmaster[mujoco-render]' and"
            f" set MUJOCO_GL=egl ({' '.join(str(exc).split())})"
        ) from exc


def _queued_parts(objects: Sequence[TableObject]) -> list[int]:
    """The parts that start inside an earlier one: they wait out of the scene."""
    queued: list[int] = []
    placed: list[TableObject] = []
    for k, obj in enumerate(objects):
        if any(_boxes_overlap(obj, other) for other in placed):
            queued.append(k)
        else:
            placed.append(obj)
    return queued


def _home_joints(model: RobotModel, home: Pose | None, tool: Pose | None) -> tuple[float, ...]:
    """The joints at ``home`` (None: the model's ready posture)."""
    if home is None:
        return tuple(model.ready_joints_deg)
    try:
        return tuple(model.inverse(home, tool=tool))
    except UnreachablePoseError as exc:
        raise ValueError(f"home {home} is not reachable: {exc}") from exc


def _boxes_overlap(a: TableObject, b: TableObject) -> bool:
    """True when the axis-aligned bounding boxes of two objects intersect."""
    ha, hb = a.half_extents_mm(), b.half_extents_mm()
    pa, pb = a.pose.as_list()[:3], b.pose.as_list()[:3]
    return all(abs(pa[i] - pb[i]) < ha[i] + hb[i] - 1e-6 for i in range(3))


def _write_png(path: Path, pixels: Any) -> None:
    """Write an RGB uint8 array as a PNG (zlib only, no imaging library)."""
    import struct
    import zlib

    height, width = int(pixels.shape[0]), int(pixels.shape[1])
    raw = b"".join(b"\x00" + pixels[row].tobytes() for row in range(height))

    def chunk(kind: bytes, data: bytes) -> bytes:
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 6))
    path.write_bytes(png + chunk(b"IEND", b""))


def _reject_reason(reason: str) -> RejectReason:
    """An UnreachablePoseError's reason as a MotionRejectedError's."""
    if reason == "joint_limit":
        return "joint_limit"
    if reason == "singularity":
        return "singularity"
    return "reach"
