"""Arm models: the joint chain (forward and inverse kinematics), limits, motion times.

The same model drives the simulator's motion and the master's validation and derived
timeouts, so the two can never disagree about whether a pose is reachable or how long a
move should take. The chain, joint ranges and joint speeds are Techman's own numbers
(``robot_models.toml`` cites them); the TCP speeds are typical values (marked uncertain
in ``docs/simulator-model.md``) and every field can be overridden.
"""

from __future__ import annotations

import functools
import itertools
import math
import tomllib
from collections.abc import Callable, Mapping, Sequence
from importlib import resources
from types import MappingProxyType
from typing import cast

from pydantic import BaseModel, ConfigDict, Field, model_validator

from . import _kinematics as kin
from ._error_root import ConfigError
from ._exceptions import UnknownNameError, UnreachablePoseError
from ._pose import MotionType, Pose

#: Six joint angles J1..J6, degrees.
Joints = tuple[float, float, float, float, float, float]
#: A homogeneous transform: four rows of four numbers (translation in mm).
Transform = kin.Transform


class JointSpec(BaseModel):
    """One revolute joint: its URDF origin from the previous frame, range and top speed."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: Position of the joint's frame in the previous one, mm.
    origin_xyz_mm: tuple[float, float, float]
    #: Orientation of the joint's frame in the previous one (roll, pitch, yaw), deg.
    origin_rpy_deg: tuple[float, float, float]
    #: The joint's range (lower, upper), deg.
    limits_deg: tuple[float, float]
    #: The joint's top speed at 100 % speed, deg/s.
    speed_deg_s: float = Field(gt=0)

    def _taking(self, angle_deg: float, by: float) -> JointSpec:
        """This joint with its range stretched to take ``angle_deg`` and ``by`` deg either
        side of it, where it does not already (equal to this one where nothing is)."""
        low, high = self.limits_deg
        ends = (min(low, angle_deg - by), max(high, angle_deg + by))
        return self.model_copy(update={"limits_deg": ends})

    @model_validator(mode="after")
    def _range_is_ordered(self) -> JointSpec:
        if not self.limits_deg[0] < self.limits_deg[1]:
            raise ValueError(f"limits_deg must be (lower, upper), got {self.limits_deg}")
        return self


#: The highest TCP speed limit ("TCP Speed" stop criterion) TMflow accepts, mm/s (TMflow
#: 2.24 Appendix B).
TCP_SPEED_MAX = 4500.0


class RobotModel(BaseModel):
    """One arm model: its joint chain, ranges, speeds and the motion-time model.

    The built-in models (:data:`ROBOT_MODELS`, :func:`robot_model`) are Techman's URDF
    chains; the master validates moves and times its waits with the model, and the
    simulator moves the arm with the same one.

    Example:
        ```python
        from tmmaster import MotionType, Pose, robot_model

        arm = robot_model("tm5-700")
        joints = arm.inverse(Pose(300, -200, 200, 180, 0, 90))
        print(arm.forward(joints))  # the same pose back
        print(arm.motion_time(Pose(250, 0, 300, 180, 0, 90), Pose(300, -200, 200, 180, 0, 90),
                              speed_percent=50, motion=MotionType.PTP))
        ```
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: The model's name (``"tm5-700"``...).
    name: str
    #: Datasheet reach, mm: a quick pre-check before inverse kinematics.
    reach_mm: float = Field(gt=0)
    #: The joints J1..J6.
    joints: tuple[JointSpec, JointSpec, JointSpec, JointSpec, JointSpec, JointSpec]
    #: Maximum TCP speed of a Line motion at 100 % speed, mm/s.
    tcp_speed_mm_s: float = Field(gt=0)
    #: The robot's TCP speed limit, mm/s: TMflow's Performance Safety "TCP Speed" stop
    #: criterion (default 1500, settable 0-4500: TMflow 2.24 Appendix B). A PTP whose TCP
    #: would run faster is refused by the master and stops the simulated robot (0x0021).
    tcp_speed_limit_mm_s: float = Field(default=1500.0, gt=0, le=TCP_SPEED_MAX)
    #: Rated payload, kg: the simulator raises the robot's over-payload error (0x000F) for
    #: a heavier part carried; None: not known, not checked.
    payload_kg: float | None = Field(default=None, gt=0)
    #: Time to reach top speed (TM motion nodes call it acceleration time), s.
    accel_time_s: float = Field(default=0.2, ge=0)
    #: Posture inverse kinematics starts from when nothing better is known.
    ready_joints_deg: Joints = (0.0, 0.0, 90.0, 0.0, 90.0, 0.0)
    #: Refuse joint solutions with J5 this close to 0 or 180 deg (wrist singularity).
    wrist_margin_deg: float = Field(default=5.0, ge=0)
    #: Refuse joint solutions with J3 this close to 0 deg (arm stretched: elbow singularity).
    elbow_margin_deg: float = Field(default=5.0, ge=0)
    #: Refuse wrist centres this close to the J1 axis plane (shoulder singularity), mm.
    shoulder_margin_mm: float = Field(default=20.0, ge=0)

    def __hash__(self) -> int:
        # The kinematics caches key on the model, several times a move: two fields spread
        # the models (equal models still hash alike), the joints are compared only when
        # two differ there.
        return hash((self.name, self.reach_mm))

    @property
    def shoulder_height_mm(self) -> float:
        """Height of the shoulder (J2 axis) above the base, mm."""
        return self.joints[0].origin_xyz_mm[2]

    @property
    def joint_speed_deg_s(self) -> Joints:
        """Maximum joint speeds J1..J6 at 100 % speed, deg/s."""
        return cast(Joints, tuple(j.speed_deg_s for j in self.joints))

    # -- kinematics ------------------------------------------------------------------

    def joint_frames(self, joints_deg: Sequence[float]) -> list[Transform]:
        """Base -> frame of each joint J1..J6 (after its rotation); the last is the flange.

        Args:
            joints_deg: Six joint angles, deg.

        Returns:
            Six transforms from the base frame.
        """
        return joint_chain(self).frames([math.radians(q) for q in _six(joints_deg)])

    def forward(self, joints_deg: Sequence[float], tool: Pose | None = None) -> Pose:
        """Flange pose for the joints (J1..J6, deg), or the TCP pose with a ``tool`` offset.

        Args:
            joints_deg: Six joint angles, deg.
            tool: The TCP in the flange frame (None: the flange pose).

        Returns:
            The pose in the base frame.
        """
        flange = joint_chain(self).flange([math.radians(q) for q in _six(joints_deg)])
        if tool is not None:
            flange = kin.multiply(flange, kin.pose_to_transform(tool))
        return kin.transform_to_pose(flange)

    def inverse(
        self,
        pose: Pose,
        *,
        seed_deg: Sequence[float] | None = None,
        tool: Pose | None = None,
        same_branch: bool = False,
    ) -> Joints:
        """Joints (deg) that put the flange (or the ``tool``'s TCP) at ``pose``, nearest the seed.

        Nearest: in the seed's pose configuration (shoulder, elbow and wrist,
        :meth:`configuration`) when any solution has it, as TMscript's ``inversekin``
        answers "by the current pose configuration" (TMscript 2.24, p. 207); else the
        solution with the shortest PTP from the seed (:meth:`ptp_seconds`). The master
        plans with this rule and the simulator moves with it; a real controller's own
        choice is the robot's, and the master's timeouts and arrival checks do not
        depend on it (docs/kinematics.md).

        Args:
            pose: The flange pose, or the TCP pose with ``tool``.
            seed_deg: Joints to start from (where the arm is); None: the ready posture.
            tool: The TCP in the flange frame (None: ``pose`` is the flange's).
            same_branch: Search from the seed only (no restart from other postures): a
                continuous path uses it.

        Returns:
            Six joint angles, deg.

        Raises:
            UnreachablePoseError: Out of reach, past a joint limit, or too close to a
                singularity (``reason`` says which).
        """
        seed = self.ready_joints_deg if seed_deg is None else _six(seed_deg)
        # A cycle repeats its poses from (nearly) the same joints: the answer is a pure
        # function of the pose and the seed rounded to 0.001 deg, which keeps the cache
        # hitting where solutions differ by the solver's tolerance.
        return _cached_inverse(self, pose, _rounded(seed), tool, same_branch)

    def _solve(self, pose: Pose, seed: Joints, tool: Pose | None, same_branch: bool) -> Joints:
        target = kin.pose_to_transform(pose)
        tool_t = kin.IDENTITY if tool is None else kin.pose_to_transform(tool)
        # The datasheet reach is the flange's: with a tool, the flange is where the TCP
        # pose puts it (TCP = flange x tool), so ``tool=Pose(0, 0, 0, 0, 0, 0)`` and
        # ``tool=None`` refuse the same poses.
        flange = kin.flange_of(pose, tool)
        if self._outside_reach_sphere(flange):
            raise UnreachablePoseError(
                f"pose {pose} is out of reach of a {self.name}"
                f" (the flange {self.distance_from_shoulder(flange):.0f} mm from the shoulder,"
                f" reach {self.reach_mm:.0f} mm)",
                reason="reach",
                pose=pose,
            )
        problems: list[tuple[str, str]] = []
        best: Joints | None = None
        if same_branch:
            best = self._search([seed], seed, target, tool_t, problems)
        else:
            # The canonical postures find nearly every pose; the wider search (J1 aimed at
            # the flange and its opposite, the shoulder all round) runs only when they
            # found none in the seed's configuration, so a refusal is never a missed
            # branch and another configuration is taken only when the seed's has none.
            best = self._search(self._starts(seed), seed, target, tool_t, problems)
            if best is None or self.configuration(best) != self.configuration(seed):
                wide = self._wide_starts(seed, flange)
                best = self._search(wide, seed, target, tool_t, problems, best)
        if best is not None:
            return best
        if not problems:
            raise UnreachablePoseError(
                f"pose {pose} is out of reach of a {self.name}: no joint solution takes the"
                f" {'TCP' if tool else 'flange'} there"
                f" ({self.distance_from_shoulder(flange):.0f} mm from the shoulder,"
                f" {math.hypot(flange.x, flange.y):.0f} mm from the J1 axis;"
                f" reach {self.reach_mm:.0f} mm)",
                reason="reach",
                pose=pose,
            )
        # A solution inside every joint range but too close to a singularity is the true
        # cause of the refusal: the joint ranges would have allowed that branch.
        reason, detail = min(problems, key=lambda p: p[0] != "singularity")
        raise UnreachablePoseError(
            f"pose {pose} cannot be taken by a {self.name}: {detail}", reason=reason, pose=pose
        )

    def _search(
        self,
        starts: Sequence[Joints],
        seed: Joints,
        target: kin.Transform,
        tool_t: kin.Transform,
        problems: list[tuple[str, str]],
        best: Joints | None = None,
    ) -> Joints | None:
        """The admissible solution from ``starts`` (or ``best``) that :meth:`inverse`
        prefers; appends what failed.

        Preferred: the seed's configuration (:meth:`configuration`) over any other, then
        the shortest PTP from the seed (:meth:`ptp_seconds`).
        """
        keep = self.configuration(seed)

        def preference(joints: Joints) -> tuple[bool, float]:
            return (self.configuration(joints) != keep, self.ptp_seconds(seed, joints))

        best_key = (True, math.inf) if best is None else preference(best)
        for start in starts:
            raw = kin.dls_inverse(
                joint_chain(self), target, [math.radians(q) for q in start], tool=tool_t
            )
            if raw is None:
                continue
            joints, problem = self._admissible([math.degrees(q) for q in raw], seed)
            if problem is not None:
                problems.append(problem)
                continue
            assert joints is not None
            key = preference(joints)
            if key < best_key:
                best, best_key = joints, key
            if start == seed and not key[0]:
                # The seed's own configuration, its joints moved by whole turns nearest
                # the seed (_admissible): no other start can find a preferred one.
                break
        return best

    def configuration(self, joints_deg: Sequence[float]) -> tuple[bool, bool, bool]:
        """The arm's pose configuration: shoulder, elbow and wrist.

        Techman's pose configuration (Config1-3: PTP Syntax 2 and its figure, TMscript
        2.24 pp. 332-334) tells the same three choices apart: the side the arm reaches
        to across J2's axis (Config1: a cross product of the arm's reach and the wrist
        offset, projected on the base's X-Y plane), then the signs of J3 and J5 relative
        to it. Two joint sets have the same configuration when these three are equal.

        Args:
            joints_deg: J1..J6, deg.

        Returns:
            (the wrist in front of the J2 axis, J3 >= 0, J5 >= 0).
        """
        frames = joint_chain(self).link_frames([math.radians(a) for a in _six(joints_deg)])
        # J2's axis: the z column of its frame (J2's own turn leaves it be); the wrist:
        # J5's origin.
        axis, wrist = frames[2], frames[5]
        # "Front": the J2 axis crossed with the vertical, i.e. (a_y, -a_x) in the plane.
        front = wrist[0][3] * axis[1][2] - wrist[1][3] * axis[0][2]
        return (front >= 0.0, joints_deg[2] >= 0.0, joints_deg[4] >= 0.0)

    def ptp_seconds(self, start_deg: Sequence[float], end_deg: Sequence[float]) -> float:
        """How far apart two joint sets are for a PTP: the largest joint travel over that
        joint's top speed, s at 100 % (acceleration aside).

        Args:
            start_deg: J1..J6, deg.
            end_deg: J1..J6, deg.

        Returns:
            Seconds.
        """
        return max(
            abs(b - a) / v
            for a, b, v in zip(start_deg, end_deg, self.joint_speed_deg_s, strict=True)
        )

    def start_joints(
        self, start: Pose, joints_deg: Sequence[float] | None = None, tool: Pose | None = None
    ) -> Joints:
        """The joints a move from ``start`` starts at: the given ones when they put the arm there.

        Joints whose forward kinematics (with ``tool``) put the TCP at ``start`` are kept
        (the branch the arm is on); otherwise ``start`` is solved, from ``joints_deg``
        when given, as where the arm is: without the singularity margins and the
        datasheet reach, and a joint within 1 deg of the end of its range may be solved
        up to 1 deg past it (a calibrated arm's joints solve a little off on this chain:
        tests/test_hunt35_joint_edges.py).

        Args:
            start: The TCP pose at the start.
            joints_deg: The joints the arm is believed to be at; None: not known.
            tool: The TCP in the flange frame (None: the TCP is the flange).

        Returns:
            The six joint angles, deg.

        Raises:
            UnreachablePoseError: ``start`` cannot be solved.
        """
        if joints_deg is not None:
            q0 = _six(joints_deg)
            if _cached_forward(self, q0, tool).is_close(start, mm=1e-3, deg=1e-3):
                return q0
            # A joint within 1 deg of a range's end may be solved up to 1 deg past it: a
            # calibrated arm there solves a hair past the end on this chain, and the arm is
            # where it is (J1 and J6: not the range's other turn; J3: not another
            # configuration).
            return self._taking(q0, 1.0, **_AS_IS).inverse(start, seed_deg=q0, tool=tool)
        return self.model_copy(update=_AS_IS).inverse(start, tool=tool)

    def _taking(self, joints_deg: Sequence[float], by: float, **update: object) -> RobotModel:
        """This model (``update`` applied) with each joint's range stretched to take
        ``joints_deg`` and ``by`` deg either side of them, where not already."""
        joints = tuple(j._taking(q, by) for j, q in zip(self.joints, joints_deg, strict=True))
        return self.model_copy(update={**update, "joints": joints})

    def singularity(self, joints_deg: Sequence[float]) -> str | None:
        """Which singularity the joints are too close to (wrist, elbow, shoulder), or None.

        Args:
            joints_deg: Six joint angles, deg.

        Returns:
            The singularity, in words, or None.
        """
        q = _six(joints_deg)
        if abs(math.sin(math.radians(q[4]))) < math.sin(math.radians(self.wrist_margin_deg)):
            return f"wrist singularity (J5 = {q[4]:.1f} deg, margin {self.wrist_margin_deg:g})"
        if abs(math.sin(math.radians(q[2]))) < math.sin(math.radians(self.elbow_margin_deg)):
            return f"elbow singularity (J3 = {q[2]:.1f} deg, arm stretched)"
        if (distance := self.shoulder_distance_mm(q)) < self.shoulder_margin_mm:
            return f"shoulder singularity (wrist {distance:.0f} mm from the J1 axis plane)"
        return None

    def check_joints(self, joints_deg: Sequence[float], *, tool: Pose | None = None) -> Joints:
        """Refuse joints the arm must not be commanded to; return them as a tuple.

        The same rules as :meth:`inverse` applies to its solutions: every joint inside its
        range, no joint solution too close to a singularity (:meth:`singularity`), and the
        flange inside the datasheet reach.

        Args:
            joints_deg: Six joint angles J1..J6, deg.
            tool: The TCP in the flange frame, for the pose the error names.

        Returns:
            The six joint angles, deg.

        Raises:
            UnreachablePoseError: ``reason`` ``"joint_limit"``, ``"singularity"`` or
                ``"reach"``; ``pose`` is the TCP the joints would put the arm at.
        """
        joints = _six(joints_deg)
        tcp = _cached_forward(self, joints, tool)
        for i, (q, spec) in enumerate(zip(joints, self.joints, strict=True)):
            low, high = spec.limits_deg
            if not low <= q <= high:
                raise UnreachablePoseError(
                    f"joints {_joints_text(joints)} cannot be taken by a {self.name}: J{i + 1}"
                    f" = {q:g} deg is outside {low:g}..{high:g} deg",
                    reason="joint_limit",
                    pose=tcp,
                )
        if (singular := self.singularity(joints)) is not None:
            raise UnreachablePoseError(
                f"joints {_joints_text(joints)} cannot be taken by a {self.name}: {singular}",
                reason="singularity",
                pose=tcp,
            )
        flange = _cached_forward(self, joints, None)
        if self._outside_reach_sphere(flange):
            raise UnreachablePoseError(
                f"joints {_joints_text(joints)} put the flange"
                f" {self.distance_from_shoulder(flange):.0f} mm from the shoulder of a"
                f" {self.name}, past its reach ({self.reach_mm:.0f} mm)",
                reason="reach",
                pose=tcp,
            )
        return joints

    def shoulder_distance_mm(self, joints_deg: Sequence[float]) -> float:
        """Distance of the wrist centre from the plane of the J1 axis and the J2 axis, mm.

        For this family of arms (J2, J3, J4 parallel) ``det(J)`` factors into
        ``a2 * a3 * sin(J3) * sin(J5) * d``; ``d`` is this distance.

        Args:
            joints_deg: Six joint angles, deg.

        Returns:
            The distance, mm.
        """
        q = [math.radians(a) for a in _six(joints_deg)]
        jacobian, _ = joint_chain(self).jacobian(q)
        upper_arm, forearm = self.joints[2].origin_xyz_mm[0], self.joints[3].origin_xyz_mm[0]
        scale = upper_arm * forearm * math.sin(q[2]) * math.sin(q[4])
        return 0.0 if abs(scale) < 1e-12 else abs(kin.determinant(jacobian) * 1e9 / scale)

    def _admissible(
        self, joints: list[float], seed: Sequence[float]
    ) -> tuple[Joints | None, tuple[str, str] | None]:
        """Joints moved by whole turns into range nearest the seed, or why they cannot be."""
        chosen = []
        for i, (q, s, spec) in enumerate(zip(joints, seed, self.joints, strict=True)):
            low, high = spec.limits_deg
            candidates = [q + k * 360.0 for k in range(-2, 3) if low <= q + k * 360.0 <= high]
            if not candidates:
                wrapped = (q + 180.0) % 360.0 - 180.0
                return None, (
                    "joint_limit",
                    f"J{i + 1} would be {wrapped:.1f} deg, outside {low:g}..{high:g} deg",
                )
            chosen.append(min(candidates, key=lambda c: abs(c - s)))  # nearest the seed
        result = cast(Joints, tuple(chosen))
        if (singular := self.singularity(result)) is not None:
            return None, ("singularity", singular)
        return result, None

    def _starts(self, seed: Joints) -> list[Joints]:
        """The seed first, then canonical postures (shoulder, elbow and wrist flips)."""
        j1, arms = seed[0], ((0.0, 90.0, 0.0), (-60.0, -90.0, 150.0))  # J2-J4
        flips = itertools.product((j1, j1 + 180.0, j1 - 180.0), arms, (90.0, -90.0))
        return [seed, *((base, *arm, j5, seed[5]) for base, arm, j5 in flips)]

    def _wide_starts(self, seed: Joints, flange: Pose) -> list[Joints]:
        """Starts all round the shoulder, J1 aimed at the flange and away from it.

        Both elbows at four shoulder angles, for J1 towards the flange and opposite
        it; the wrist alternates between its two flips (16 starts: a refusal pays for
        every one of them, so the grid is as coarse as finds every branch).
        """
        aim = math.degrees(math.atan2(flange.y, flange.x))
        opposite = aim + 180.0 if aim <= 0 else aim - 180.0
        return [
            (base, shoulder, elbow, 0.0, 90.0 if (i + k) % 2 == 0 else -90.0, seed[5])
            for base in (aim, opposite)
            for i, shoulder in enumerate((-135.0, -45.0, 45.0, 135.0))
            for k, elbow in enumerate((-90.0, 90.0))
        ]

    def distance_from_shoulder(self, pose: Pose) -> float:
        """Distance from the shoulder joint to the pose's position, in mm.

        Args:
            pose: A pose in the base frame.

        Returns:
            The distance, mm.
        """
        return math.dist((0.0, 0.0, self.shoulder_height_mm), (pose.x, pose.y, pose.z))

    def _outside_reach_sphere(self, pose: Pose) -> bool:
        # Conservative on purpose: the chain alone would let the flange a little past the
        # datasheet reach, which Techman does not promise.
        return self.distance_from_shoulder(pose) > self.reach_mm

    def can_reach(self, pose: Pose, *, seed_deg: Sequence[float] | None = None) -> bool:
        """True when the arm can take ``pose`` (inverse kinematics, ranges, singularities).

        Args:
            pose: The flange pose.
            seed_deg: Joints to start from; None: the ready posture.

        Returns:
            Whether :meth:`inverse` finds joints.
        """
        try:
            self.inverse(pose, seed_deg=seed_deg)
        except UnreachablePoseError:
            return False
        return True

    # -- timing ----------------------------------------------------------------------

    def ptp_time(
        self,
        start_deg: Sequence[float],
        target_deg: Sequence[float],
        *,
        speed_percent: float,
        accel_time_s: float | None = None,
    ) -> float:
        """Duration of a synchronised joint-space trapezoid between two joint vectors, s.

        Args:
            start_deg: Six joint angles at the start, deg.
            target_deg: Six joint angles at the target, deg.
            speed_percent: Speed, % of the joints' top speeds.
            accel_time_s: Time to reach top speed, s; None: the model's.

        Returns:
            The duration, s.
        """
        scale = _speed_scale(speed_percent)
        ramp = self.accel_time_s if accel_time_s is None else accel_time_s
        return max(
            trapezoid_time(abs(b - a), spec.speed_deg_s * scale, ramp)
            for a, b, spec in zip(_six(start_deg), _six(target_deg), self.joints, strict=True)
        )

    @functools.lru_cache(maxsize=4096)  # noqa: B019 (a model is immutable, kept by ROBOT_MODELS)
    def ptp_tcp_speeds(
        self, q0: Joints, q1: Joints, speed: float, accel_s: float | None, tool: Pose | None
    ) -> tuple[float, ...]:
        """The TCP's mean speed over each 100th of a PTP's duration, mm/s.

        Every joint follows the same trapezoid over :meth:`ptp_time`, as the simulator's
        arm does: the TCP (forward kinematics, with ``tool``) at 101 evenly spaced times,
        the distance between two per 100th of the duration. The robot's limit is on the
        TCP's speed, not a mean: over 20ths a sharp peak read up to 8.5 % low, over
        100ths 1.5 % (tests/test_hunt17_tcp_speed_peak.py). Cached: a cycle repeats its
        moves.

        Args:
            q0: The joints the PTP starts from, deg.
            q1: The target's joints, deg.
            speed: Speed, % (the project speed included).
            accel_s: Time to top speed, s; None: the model's.
            tool: The TCP in the flange frame (None: the flange).

        Returns:
            100 speeds, start to end (all 0 for a PTP that does not move).
        """
        seconds = self.ptp_time(q0, q1, speed_percent=speed, accel_time_s=accel_s)
        ramp, n = self.accel_time_s if accel_s is None else accel_s, 100
        fs = [trapezoid_progress(seconds * k / n, seconds, ramp) for k in range(n + 1)]
        at = [
            self.forward([a + (b - a) * f for a, b in zip(q0, q1, strict=True)], tool) for f in fs
        ]
        return tuple(n / max(seconds, 1e-9) * p.distance_to(q) for p, q in itertools.pairwise(at))

    def line_joints(
        self,
        start: Pose,
        target: Pose,
        *,
        start_joints_deg: Sequence[float] | None = None,
        tool: Pose | None = None,
        step_mm: float = 5.0,
        step_deg: float = 2.0,
    ) -> list[Joints]:
        """Joint samples along the straight TCP path from ``start`` to ``target``.

        Args:
            start: The TCP pose at the start.
            target: The TCP pose at the end.
            start_joints_deg: The joints at the start (None: searched from the ready
                posture).
            tool: The TCP in the flange frame (None: the flange).
            step_mm: Largest distance between two samples, mm.
            step_deg: Largest rotation between two samples, deg.

        Returns:
            The joints at each sample, start and target included.

        Raises:
            UnreachablePoseError: A point of the path cannot be taken, or the arm would
                have to flip configuration on the way.
        """
        q0 = _rounded(self.ready_joints_deg if start_joints_deg is None else _six(start_joints_deg))
        return list(_cached_path(self, start, None, target, q0, tool, step_mm, step_deg))

    def _path(
        self,
        start: Pose,
        via: Pose | None,
        target: Pose,
        start_joints: Joints,
        tool: Pose | None,
        step_mm: float,
        step_deg: float,
    ) -> tuple[Joints, ...]:
        """Joints at evenly spaced points of a Line (``via`` None) or an arc, at most
        ``step_mm`` and ``step_deg`` apart."""
        at, length_mm, rotation_deg = _path_geometry(start, via, target)
        steps = max(1, math.ceil(max(length_mm / step_mm, rotation_deg / step_deg)))
        what = f"the straight path to {target}" if via is None else f"the arc to {target}"
        samples, fastest = [self.start_joints(start, start_joints, tool)], 0.0
        # A joint the start has past a range's end (a calibrated arm's, on this chain) may
        # stay there, no farther: the ranges are stretched to the start, once (stretched
        # to each sample's seed, a path crept on past the end, a rounding a sample).
        model = self._taking(samples[0], 1e-3)  # and its rounding
        for k in range(1, steps + 1):
            pose = kin.transform_to_pose(at(k / steps))
            try:
                joints = model.inverse(pose, seed_deg=samples[-1], tool=tool, same_branch=True)
            except UnreachablePoseError as exc:
                raise UnreachablePoseError(
                    f"{what} leaves the arm's range at {pose}: {exc}", reason=exc.reason, pose=pose
                ) from exc
            if (jump := max(abs(x - y) for x, y in zip(joints, samples[-1], strict=True))) > 30:
                # A joint a whole turn away: its range (J1, J6: +-270 deg) ends on the path.
                wrap = jump > 300.0
                problem = "takes a joint past its range" if wrap else "needs a configuration flip"
                raise UnreachablePoseError(
                    f"{what} {problem} near {pose} (a joint jumps {jump:.0f} deg)",
                    reason="joint_limit" if wrap else "singularity",
                    pose=pose,
                )
            samples.append(joints)
            fastest = max(fastest, jump)
        if fastest > 10.0 and step_mm > 1.0:
            # A joint turning > 10 deg a sample (near a singularity) peaks between: refine.
            return self._path(start, via, target, start_joints, tool, step_mm / 3, step_deg / 3)
        return tuple(samples)

    def arc_joints(
        self,
        start: Pose,
        via: Pose,
        target: Pose,
        *,
        start_joints_deg: Sequence[float] | None = None,
        tool: Pose | None = None,
        step_mm: float = 5.0,
        step_deg: float = 2.0,
    ) -> list[Joints]:
        """Joint samples along the circular arc from ``start`` through ``via`` to ``target``.

        The TCP follows the circle through the three positions; its orientation turns
        uniformly from ``start``'s to ``target``'s (:class:`~tmmaster._kinematics.Arc`, a
        TMscript ``Circle`` with arc angle 0); ``via``'s orientation is not used.

        Args:
            start: The TCP pose at the start.
            via: A pose whose position the arc passes through.
            target: The TCP pose at the end.
            start_joints_deg: The joints at the start (None: searched from the ready
                posture).
            tool: The TCP in the flange frame (None: the flange).
            step_mm: Largest distance along the arc between two samples, mm.
            step_deg: Largest rotation between two samples, deg.

        Returns:
            The joints at each sample, start and target included (evenly spaced along
            the arc).

        Raises:
            ConfigError: No arc passes through the three points (two closer than 1 mm,
                or all three on one line).
            UnreachablePoseError: A point of the arc cannot be taken, or the arm would
                have to flip configuration on the way.
        """
        seed = self.ready_joints_deg if start_joints_deg is None else _six(start_joints_deg)
        return list(_cached_path(self, start, via, target, _rounded(seed), tool, step_mm, step_deg))

    def line_time(
        self,
        start: Pose,
        target: Pose,
        *,
        speed_percent: float,
        accel_time_s: float | None = None,
        start_joints_deg: Sequence[float] | None = None,
        tool: Pose | None = None,
        samples: Sequence[Sequence[float]] | None = None,
    ) -> float:
        """Duration of a Line move: the TCP trapezoid, slowed where a joint would be too fast.

        Args:
            start: The TCP pose at the start.
            target: The TCP pose at the end.
            speed_percent: Speed, % of the model's top TCP speed.
            accel_time_s: Time to reach top speed, s; None: the model's.
            start_joints_deg: The joints at the start (None: searched from the ready
                posture).
            tool: The TCP in the flange frame (None: the flange).
            samples: The path's joints from :meth:`line_joints`, when the caller has
                them already (they are computed otherwise).

        Returns:
            The duration, s.

        Raises:
            UnreachablePoseError: The path cannot be taken.
        """
        _speed_scale(speed_percent)
        if samples is None:
            samples = self.line_joints(start, target, start_joints_deg=start_joints_deg, tool=tool)
        return self._path_time(start, None, target, samples, speed_percent, accel_time_s)

    def arc_time(
        self,
        start: Pose,
        via: Pose,
        target: Pose,
        *,
        speed_percent: float,
        accel_time_s: float | None = None,
        start_joints_deg: Sequence[float] | None = None,
        tool: Pose | None = None,
        samples: Sequence[Sequence[float]] | None = None,
    ) -> float:
        """Duration of a Circle move: the TCP trapezoid along the arc, slowed for the joints.

        Args:
            start: The TCP pose at the start.
            via: A pose whose position the arc passes through.
            target: The TCP pose at the end.
            speed_percent: Speed, % of the model's top TCP speed.
            accel_time_s: Time to reach top speed, s; None: the model's.
            start_joints_deg: The joints at the start (None: searched from the ready
                posture).
            tool: The TCP in the flange frame (None: the flange).
            samples: The arc's joints from :meth:`arc_joints`, when the caller has them
                already (they are computed otherwise).

        Returns:
            The duration, s.

        Raises:
            ConfigError: No arc passes through the three points.
            UnreachablePoseError: The arc cannot be taken.
        """
        _speed_scale(speed_percent)
        if samples is None:
            samples = self.arc_joints(
                start, via, target, start_joints_deg=start_joints_deg, tool=tool
            )
        return self._path_time(start, via, target, samples, speed_percent, accel_time_s)

    def _path_time(
        self,
        start: Pose,
        via: Pose | None,
        target: Pose,
        samples: Sequence[Sequence[float]],
        speed_percent: float,
        accel_time_s: float | None,
    ) -> float:
        """A Cartesian path's trapezoid, slowed where a joint would be too fast, s."""
        scale = _speed_scale(speed_percent)
        ramp = self.accel_time_s if accel_time_s is None else accel_time_s
        _, length_mm, rotation_deg = _path_geometry(start, via, target)
        cartesian = max(
            trapezoid_time(length_mm, self.tcp_speed_mm_s * scale, ramp),
            trapezoid_time(rotation_deg, min(self.joint_speed_deg_s[3:]) * scale, ramp),
        )
        steps = len(samples) - 1
        # Peak path rate of a trapezoid of duration T is 1 / (T - ramp) (path fraction / s);
        # joint i moves |dq_i/ds| deg per unit path, so T >= ramp + max |dq_i/ds| / v_i.
        needed = 0.0
        for prev, cur in itertools.pairwise(samples):
            for a, b, spec in zip(prev, cur, self.joints, strict=True):
                needed = max(needed, abs(b - a) * steps / (spec.speed_deg_s * scale))
        return max(cartesian, needed + ramp if needed > 0 else 0.0)

    def motion_time(
        self,
        start: Pose,
        target: Pose,
        *,
        speed_percent: float,
        motion: MotionType,
        accel_time_s: float | None = None,
        start_joints_deg: Sequence[float] | None = None,
        tool: Pose | None = None,
    ) -> float:
        """Expected duration of a move in seconds (joint-space PTP or Cartesian Line).

        Args:
            start: The TCP pose at the start.
            target: The TCP target.
            speed_percent: Speed, %.
            motion: PTP (joint interpolation) or LINE (a straight TCP path).
            accel_time_s: Time to reach top speed, s; None: the model's.
            start_joints_deg: Where the arm is (or the seed its joints are searched
                from); None: the ready posture is the seed.
            tool: The TCP in the flange frame (None: the flange).

        Returns:
            The expected duration, s.

        Raises:
            UnreachablePoseError: The start, the target or a Line's path cannot be taken.
        """
        _speed_scale(speed_percent)
        if motion is MotionType.LINE:
            return self.line_time(
                start,
                target,
                speed_percent=speed_percent,
                accel_time_s=accel_time_s,
                start_joints_deg=start_joints_deg,
                tool=tool,
            )
        first = self.start_joints(start, start_joints_deg, tool)
        last = self.inverse(target, seed_deg=first, tool=tool)
        return self.ptp_time(first, last, speed_percent=speed_percent, accel_time_s=accel_time_s)


class PathGauge:
    """How much of a move's path a pose the robot reports has covered, by the arm model.

    A Line's TCP runs along a straight segment, so the fraction is the pose's
    projection on it. A PTP's joints share one profile, so the TCP passes the forward
    kinematics of the interpolated joints: the fraction is read from the remaining
    distance to the target along those samples, where it decreases all the way (else
    the gauge cannot tell, and says None).
    """

    __slots__ = ("_line", "_remaining", "_rotation", "_start", "_target", "_total")

    #: Samples along a PTP's joint path.
    SAMPLES = 20

    def __init__(self, start: Pose, target: Pose, remaining: tuple[float, ...] | None) -> None:
        self._start, self._target = start, target
        self._line = remaining is None
        self._remaining = remaining or ()
        self._total = start.distance_to(target)
        self._rotation = self._total < 1.0  # a pure rotation: gauge the angle instead

    def fraction(self, pose: Pose) -> float | None:
        """The fraction (0..1) of the path covered at ``pose``; None when it cannot tell."""
        start, target = self._start, self._target
        if self._rotation:
            total = start.rotation_to(target)
            return None if total < 0.5 else min(max(1 - pose.rotation_to(target) / total, 0.0), 1.0)
        if self._line:
            along = (
                (pose.x - start.x) * (target.x - start.x)
                + (pose.y - start.y) * (target.y - start.y)
                + (pose.z - start.z) * (target.z - start.z)
            )
            return min(max(along / self._total**2, 0.0), 1.0)
        left = pose.distance_to(target)
        samples = self._remaining
        for i in range(len(samples) - 1):
            if samples[i] >= left >= samples[i + 1]:
                span = samples[i] - samples[i + 1]
                step = 1.0 / (len(samples) - 1)
                return step * (i + (samples[i] - left) / span if span > 0 else i)
        return None

    @classmethod
    def along(cls, start: Pose, target: Pose, poses: Sequence[Pose]) -> PathGauge:
        """The gauge of a path through ``poses`` (evenly spaced, ``start`` to ``target``).

        Args:
            start: The TCP pose at the start.
            target: The TCP target.
            poses: TCP poses along the path, evenly spaced, the first at ``start`` and
                the last at ``target``.

        Returns:
            A gauge that reads the fraction from the distance left to ``target`` (it
            cannot tell where that distance does not shrink all the way).
        """
        remaining = tuple(p.distance_to(target) for p in poses)
        if any(b >= a for a, b in itertools.pairwise(remaining)):
            remaining = ()
        return cls(start, target, remaining)

    @classmethod
    def of(
        cls,
        model: RobotModel,
        start: Pose,
        target: Pose,
        *,
        motion: MotionType,
        start_joints_deg: Sequence[float] | None,
        target_joints_deg: Sequence[float],
        tool: Pose | None,
    ) -> PathGauge:
        """The gauge of a move from ``start`` (at ``start_joints_deg``) to ``target``."""
        if motion is MotionType.LINE or start.distance_to(target) < 1.0:
            return cls(start, target, None)
        first = model.start_joints(start, start_joints_deg, tool)
        return _cached_gauge(model, start, target, _rounded(first), _six(target_joints_deg), tool)


@functools.lru_cache(maxsize=256)
def _cached_gauge(
    model: RobotModel, start: Pose, target: Pose, first: Joints, last: Joints, tool: Pose | None
) -> PathGauge:
    # A repeating cycle gauges the same moves: forward kinematics once per move.
    n = PathGauge.SAMPLES
    poses = [
        model.forward([a + (b - a) * k / n for a, b in zip(first, last, strict=True)], tool)
        for k in range(n + 1)
    ]
    return PathGauge.along(start, target, poses)


#: What the start of a move is solved without, the arm being there (jogged into a
#: singularity's margin, stretched past the datasheet reach, a calibrated arm's joints
#: solved a little off on this chain): the singularity margins and the reach.
_AS_IS = dict(wrist_margin_deg=0.0, elbow_margin_deg=0.0, shoulder_margin_mm=0.0, reach_mm=math.inf)

# Pure functions of the model and their arguments, cached: a repeating cycle solves the
# same poses and paths from the same known joints (a solve is about 40 us).
_cached_inverse = functools.lru_cache(maxsize=16384)(RobotModel._solve)
_cached_forward = functools.lru_cache(maxsize=1024)(RobotModel.forward)
_cached_path = functools.lru_cache(maxsize=2048)(RobotModel._path)


def _path_geometry(
    start: Pose, via: Pose | None, target: Pose
) -> tuple[Callable[[float], Transform], float, float]:
    """A Line's (``via`` None) or an arc's path: the TCP at a fraction of it, its length
    (mm) and its rotation (deg).

    Raises:
        ConfigError: No arc passes through the three points.
    """
    if via is None:
        a, b = kin.pose_to_transform(start), kin.pose_to_transform(target)
        return (lambda f: kin.interpolate(a, b, f)), start.distance_to(target), _turn_deg(a, b)
    arc = arc_through(start, via, target)
    return arc.at, arc.length_mm, _turn_deg(arc.start, arc.end)


def _turn_deg(a: Transform, b: Transform) -> float:
    """The rotation from ``a``'s orientation to ``b``'s, deg."""
    return math.degrees(math.hypot(*kin.rotation_error(a, b)))


def arc_through(start: Pose, via: Pose, target: Pose) -> kin.Arc:
    """The arc from ``start`` through ``via`` to ``target``; ConfigError when there is none."""
    try:
        return kin.Arc.through(start, via, target)
    except ValueError as exc:
        raise ConfigError(f"no arc from {start} through {via} to {target}: {exc}") from None


# Keyed by the model (its joints compared), not stored on it: model_copy(update=...)
# would carry a stored chain over to a model with other joints.
@functools.lru_cache(maxsize=32)
def joint_chain(model: RobotModel) -> kin.Chain:
    """The arm's serial chain (its joints' fixed origins), made once per model.

    Args:
        model: The arm.

    Returns:
        The chain.
    """
    origins = [(j.origin_xyz_mm, list(map(math.radians, j.origin_rpy_deg))) for j in model.joints]
    return kin.Chain(tuple(kin.rpy_transform(xyz, rpy) for xyz, rpy in origins))


def _speed_scale(speed_percent: float) -> float:
    if not 0 < speed_percent <= 100:
        raise ValueError(f"speed_percent must be in (0, 100], got {speed_percent}")
    return speed_percent / 100.0


def _joints_text(joints: Sequence[float]) -> str:
    """``(0, -10.5, 90, 0, 90, 0)``: joints as written in messages."""
    return "(" + ", ".join(f"{round(q, 3) + 0.0:g}" for q in joints) + ")"


def _rounded(joints: Joints) -> Joints:
    return cast(Joints, tuple(round(q, 3) for q in joints))


def _six(joints: Sequence[float]) -> Joints:
    if len(joints) != 6:
        raise ValueError(f"need 6 joint values J1..J6, got {len(joints)}")
    return cast(Joints, tuple(map(float, joints)))


def trapezoid_time(distance: float, top_speed: float, accel_time: float) -> float:
    """Time to cover ``distance`` starting and ending at rest, ramping over ``accel_time``."""
    if distance <= 0:
        return 0.0
    if accel_time <= 0:
        return distance / top_speed
    if distance >= top_speed * accel_time:
        return distance / top_speed + accel_time
    # Never reaches top speed: triangular profile with acceleration top_speed / accel_time.
    return 2.0 * math.sqrt(distance * accel_time / top_speed)


def trapezoid_progress(elapsed: float, total: float, accel_time: float) -> float:
    """Fraction (0..1) of the path covered after ``elapsed`` seconds of a ``total`` move."""
    if total <= 0 or elapsed >= total:
        return 1.0
    if elapsed <= 0:
        return 0.0
    ramp = min(accel_time, total / 2.0)
    if ramp <= 0:
        return elapsed / total
    # Normalised trapezoid: top speed v so that the area under the profile is 1.
    v = 1.0 / (total - ramp)
    a = v / ramp
    if elapsed < ramp:
        return 0.5 * a * elapsed**2
    if elapsed <= total - ramp:
        return 0.5 * a * ramp**2 + v * (elapsed - ramp)
    remaining = total - elapsed
    return 1.0 - 0.5 * a * remaining**2


def _load_models() -> dict[str, RobotModel]:
    text = resources.files("tmmaster").joinpath("robot_models.toml").read_text("utf-8")
    return {
        entry["name"]: RobotModel.model_validate(entry) for entry in tomllib.loads(text)["model"]
    }


#: The built-in arm models, by name (read-only).
ROBOT_MODELS: Mapping[str, RobotModel] = MappingProxyType(_load_models())


def robot_model(name: str) -> RobotModel:
    """A built-in arm model by name (``tm5-700``, ``tm5-900``, ``tm12``, ``tm14``).

    Args:
        name: The model's name.

    Returns:
        The model.

    Raises:
        RegisterMapError: An unknown name (the message lists the models); also a
            KeyError.
    """
    try:
        return ROBOT_MODELS[name]
    except KeyError:
        known = ", ".join(sorted(ROBOT_MODELS))
        raise UnknownNameError(f"unknown robot model {name!r} (known: {known})") from None
