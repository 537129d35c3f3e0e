"""How a simulated arm stops: it brakes along its path over a time, never at once.

A real TM arm told to stop (the Stop button, an e-stop, a robot error) decelerates to
rest; it does not freeze. Techman's stop-distance tables are in the robot's Safety
Manual, which is not among the manuals this project has as text; the figures known
here are (docs/simulator-model.md, "Stops"):

- TMflow SW 2.24 Software Manual, p. 112: the Category 2 stop's deceleration time, a
  Motion Setting of the S series: TM5S/TM7S default 300 ms, range 300-700 ms (TM6S to
  TM20S, TM25S/TM30S: 450 ms, 450-700 ms); the arm "achieves the specified deceleration
  within the set time".
- Techman's Safety Manual, as quoted in the project's reference notes: a TM5-700 stops
  in about 0.34-0.68 s over 9-31 deg of joint travel, depending on joint, speed and
  payload.

The model (an estimate from those figures, not Techman's controller): the arm keeps to
its path (a Line stays on its line, as in a Category 2 stop) and its path speed falls
at a constant rate such that no joint decelerates faster than its top speed per
:data:`STOP_TIME_AT_TOP_SPEED_S`. A joint at its top speed (TM5 J1-J3: 180 deg/s)
therefore stops in 0.34 s over 30.6 deg; a slower move stops sooner and shorter, in
proportion to its fastest joint's share of that joint's top speed. Payload does not
change it. A stop that the motion's own deceleration would beat (its target nearer than
the braking distance) lets the motion end at its target.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ._backend import BackendFault

#: Time a joint at its top speed takes to stop, s: the low end of the TM5-700's
#: 0.34-0.68 s in Techman's Safety Manual, within TMflow's Category 2 deceleration time
#: of 300-700 ms for the TM5S (TMflow SW 2.24 Software Manual, p. 112). An estimate.
STOP_TIME_AT_TOP_SPEED_S = 0.34


@dataclass(frozen=True)
class Braking:
    """A stop along a path: its progress (0..1 of the path) falls at a constant rate."""

    #: The path's progress when the stop began.
    from_progress: float
    #: The progress rate then, 1/s.
    rate: float
    #: How long the braking takes, s.
    duration_s: float

    @property
    def end_progress(self) -> float:
        """Where on the path the arm comes to rest (0..1)."""
        return self.from_progress + self.rate * self.duration_s / 2

    def progress(self, braking_s: float) -> float:
        """The path's progress ``braking_s`` seconds into the stop.

        Args:
            braking_s: Seconds since the stop began (>= 0).

        Returns:
            The progress, 0..1.
        """
        if braking_s >= self.duration_s:
            return self.end_progress
        t = max(braking_s, 0.0)
        return self.from_progress + self.rate * t - self.rate * t * t / (2 * self.duration_s)


def trapezoid_rate(elapsed: float, total: float, accel_time: float) -> float:
    """The rate (1/s) of :func:`~tmmaster._robot_models.trapezoid_progress` at ``elapsed``.

    Args:
        elapsed: Seconds since the motion's start.
        total: The motion's duration, s.
        accel_time: Its time to top speed, s.

    Returns:
        d(progress)/dt, 1/s (0 before the start and after the end).
    """
    if total <= 0 or elapsed >= total or elapsed <= 0:
        return 0.0
    ramp = min(accel_time, total / 2.0)
    if ramp <= 0:
        return 1.0 / total
    top = 1.0 / (total - ramp)
    if elapsed < ramp:
        return top * elapsed / ramp
    if elapsed <= total - ramp:
        return top
    return top * (total - elapsed) / ramp


def path_gradient(samples: Sequence[Sequence[float]], progress: float) -> list[float]:
    """Each joint's change per unit of progress (deg) where the path is at ``progress``.

    Args:
        samples: The path's joint samples, evenly spaced in progress (two: a PTP).
        progress: Where on the path, 0..1.

    Returns:
        d(joint)/d(progress) per joint, deg.
    """
    segments = len(samples) - 1
    if segments < 1:
        return [0.0] * (len(samples[0]) if samples else 0)
    i = min(max(int(progress * segments), 0), segments - 1)
    return [(b - a) * segments for a, b in zip(samples[i], samples[i + 1], strict=True)]


def plan_braking(
    progress: float, rate: float, gradient: Sequence[float], top_speeds_deg_s: Sequence[float]
) -> Braking | None:
    """How a motion at ``progress``, moving at ``rate``, brakes to rest.

    Args:
        progress: The path's progress now, 0..1.
        rate: Its rate now, 1/s.
        gradient: Each joint's change per unit of progress there, deg
            (:func:`path_gradient`).
        top_speeds_deg_s: The joints' top speeds, deg/s.

    Returns:
        The braking, or None when the motion's own end comes first (it then ends at its
        target, decelerating as planned).
    """
    share = max(
        (abs(g) * rate / top for g, top in zip(gradient, top_speeds_deg_s, strict=True)),
        default=0.0,
    )
    braking = Braking(progress, rate, STOP_TIME_AT_TOP_SPEED_S * share)
    if braking.end_progress >= 1.0:
        return None
    return braking


def over_speed_at(
    speeds: Sequence[float], duration_s: float, limit: float
) -> tuple[float, float] | None:
    """When a PTP's TCP first runs faster than ``limit`` (s after its start), and its top
    speed; None: it never does.

    The robot's safety stops such a PTP there (its Performance Safety "TCP Speed", a stop
    criterion: TMflow 2.24, 3 Safety Settings, Speed & Force, p. 38), and brakes.

    Args:
        speeds: The master's own measure of the TCP's speed along the PTP
            (:meth:`~tmmaster.RobotModel.ptp_tcp_speeds`: its mean over each 100th of the
            move), mm/s. Each is taken at its 100th's middle, from rest at the start; the
            limit is passed where the line between two of them crosses it.
        duration_s: The PTP's duration, s.
        limit: The robot's TCP speed limit, mm/s.

    Returns:
        (seconds after the start, the top speed in mm/s), or None.
    """
    first = next((k for k, v in enumerate(speeds) if v > limit), None)
    if first is None:
        return None
    step = duration_s / len(speeds)
    t0, v0 = ((first - 0.5) * step, speeds[first - 1]) if first else (0.0, 0.0)
    t1, v1 = (first + 0.5) * step, speeds[first]
    return (t0 + (t1 - t0) * (limit - v0) / (v1 - v0), max(speeds))


def speed_fault(limit: float, top: float) -> BackendFault:
    """The fault a PTP past the robot's TCP speed limit stops for (Techman's 0x0021).

    Args:
        limit: The robot's TCP speed limit, mm/s.
        top: The speed the PTP would have reached, mm/s.

    Returns:
        A ``"speed"`` fault naming both.
    """
    return BackendFault(
        "speed",
        f"the TCP passed the robot's TCP speed limit ({limit:g} mm/s, its Safety Settings)"
        f" on its way to {top:.0f} mm/s",
    )
