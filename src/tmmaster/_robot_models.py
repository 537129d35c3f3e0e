"""Arm models (reach, joint and TCP speed limits) and motion-time estimates.

The same estimate drives the simulator's motion timing and the master's derived
timeouts, so the two can never disagree about how long a move should take.
Figures come from Techman datasheets where known; the TCP speeds are typical values
(marked uncertain in ``docs/simulator.md``) and every field can be overridden.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType

from pydantic import BaseModel, ConfigDict, Field

from ._exceptions import UnknownNameError
from ._pose import MotionType, Pose


class RobotModel(BaseModel):
    """Kinematic limits of one arm model."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: str
    reach_mm: float = Field(gt=0)
    shoulder_height_mm: float = Field(default=145.0, ge=0)
    #: Maximum joint speeds J1..J6 at 100 % speed, deg/s.
    joint_speed_deg_s: tuple[float, float, float, float, float, float]
    #: Maximum TCP speed of a Line motion at 100 % speed, mm/s.
    tcp_speed_mm_s: float = Field(gt=0)
    #: Time to reach top speed (TM motion nodes call it acceleration time), s.
    accel_time_s: float = Field(default=0.2, ge=0)

    def distance_from_shoulder(self, pose: Pose) -> float:
        """Distance from the shoulder joint to the TCP, in mm."""
        return math.dist((0.0, 0.0, self.shoulder_height_mm), (pose.x, pose.y, pose.z))

    def can_reach(self, pose: Pose) -> bool:
        """True when the TCP position is inside the arm's reach sphere."""
        return self.distance_from_shoulder(pose) <= self.reach_mm

    def motion_time(
        self,
        start: Pose,
        target: Pose,
        *,
        speed_percent: float,
        motion: MotionType,
        accel_time_s: float | None = None,
    ) -> float:
        """Expected duration of a move in seconds, from a trapezoidal speed profile."""
        if not 0 < speed_percent <= 100:
            raise ValueError(f"speed_percent must be in (0, 100], got {speed_percent}")
        ramp = self.accel_time_s if accel_time_s is None else accel_time_s
        scale = speed_percent / 100.0
        wrist = min(self.joint_speed_deg_s[3:]) * scale
        rotation = trapezoid_time(start.rotation_to(target), wrist, ramp)
        if motion is MotionType.LINE:
            travel = trapezoid_time(start.distance_to(target), self.tcp_speed_mm_s * scale, ramp)
            return max(travel, rotation)
        base = trapezoid_time(
            abs(_wrap(_azimuth(target) - _azimuth(start))),
            self.joint_speed_deg_s[0] * scale,
            ramp,
        )
        # Shoulder and elbow: approximate the joint swing by the change of the TCP's
        # position relative to the shoulder, measured as an angle over half the reach.
        radial_change = math.hypot(_radius(target) - _radius(start), target.z - start.z)
        arm = trapezoid_time(
            math.degrees(radial_change / (self.reach_mm / 2.0)),
            min(self.joint_speed_deg_s[1:3]) * scale,
            ramp,
        )
        return max(base, arm, rotation)


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


def _azimuth(pose: Pose) -> float:
    return math.degrees(math.atan2(pose.y, pose.x))


def _radius(pose: Pose) -> float:
    return math.hypot(pose.x, pose.y)


def _wrap(angle: float) -> float:
    return (angle + 180.0) % 360.0 - 180.0


ROBOT_MODELS: Mapping[str, RobotModel] = MappingProxyType(
    {
        model.name: model
        for model in (
            RobotModel(
                name="tm5-700",
                reach_mm=700,
                joint_speed_deg_s=(180, 180, 180, 225, 225, 225),
                tcp_speed_mm_s=1100,
            ),
            RobotModel(
                name="tm5-900",
                reach_mm=900,
                joint_speed_deg_s=(180, 180, 180, 225, 225, 225),
                tcp_speed_mm_s=1400,
            ),
            RobotModel(
                name="tm12",
                reach_mm=1300,
                shoulder_height_mm=165,
                joint_speed_deg_s=(120, 120, 180, 180, 180, 180),
                tcp_speed_mm_s=1300,
            ),
            RobotModel(
                name="tm14",
                reach_mm=1100,
                shoulder_height_mm=165,
                joint_speed_deg_s=(120, 120, 180, 180, 180, 180),
                tcp_speed_mm_s=1100,
            ),
        )
    }
)


def robot_model(name: str) -> RobotModel:
    """Return a built-in arm model by name (``tm5-700``, ``tm5-900``, ``tm12``, ``tm14``)."""
    try:
        return ROBOT_MODELS[name]
    except KeyError:
        known = ", ".join(sorted(ROBOT_MODELS))
        raise UnknownNameError(f"unknown robot model {name!r} (known: {known})") from None
