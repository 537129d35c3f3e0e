"""Hunt 24: Lines that pass near the wrist singularity, against the arm's joint speeds.

[TMF]: TMflow Software Manual 2.24, Rev 1.00 (text copy: kenshu528-oss/Modbus-testkit-for-
TMflow, ``TM Doc/``). "Line mode may cause joint speeding. Try to avoid speeding close to a
singularity point" ([TMF] 9 Speed of Line Motion, p. 170). The master plans such a Line
slower, so that no joint runs past its top speed: ``RobotModel.line_time`` bounds the
duration by the path's joint samples, and the simulator runs the Line in that time. The
samples were 5 mm (or 2 deg) apart everywhere. Found by hill climbs over Lines from joints
near J5 = 5 deg (TM5-700, 100 %), where J4 turns up to 25 deg a sample:

- the samples' chords missed the joints' peak rate between two samples: the Line
  ``FAST`` below needed J4 at 1.065 times its top speed, 239.7 deg/s, over the TM5-700's
  Performance Safety "Joint Speed" limit for J4-J6 (235 deg/s, default and maximum:
  [TMF] Appendix B, p. 285), a stop criterion (0x0021, Appendix J, p. 409: "an exceeding
  TCP speed or Joint speed");
- the path of the Line ``DIP`` dips to J5 = 4.99 deg between two samples (5.02 and 5.15),
  inside the master's 5 deg margin: the master sent it;
- in the simulator, whose inverse kinematics refused the margin there, the joints then
  followed the samples' interpolation: the TCP left its line (1.7 mm for ``DIP``) and a
  joint jumped on leaving the margin (J4 at 2.8 times its top speed in one 1 ms tick).

Fixed: where a joint turns more than 10 deg between two samples, the path is sampled
again three times finer (down to 0.6 mm): ``FAST`` is planned within 0.1 % of J4's top
speed and ``DIP`` is refused before any request (``singularity``); and the simulated arm
follows its line where it passes inside a margin (the joints solved without the margins,
the arm's own): shown with a model whose margin lies between a Line's samples and its dip.
"""

from __future__ import annotations

import math

import pytest

from tmmaster import MotionType, Pose, UnreachablePoseError, robot_model
from tmmaster.sim import KinematicBackend
from tmmaster.sim._backend import MotionRejectedError

ARM = robot_model("tm5-700")
UNMARGINED = ARM.model_copy(
    update={"wrist_margin_deg": 0.0, "elbow_margin_deg": 0.0, "shoulder_margin_mm": 0.0}
)
#: (start joints, TCP offset mm): a Line at 100 %, orientation unchanged.
FAST = ((12.81, -46.0, 95.44, 8.38, -6.77, -12.46), (32.69, -52.7, 10.18))
DIP = ((-28.08, -41.47, 90.77, 14.95, -5.54, -20.72), (-21.09, -44.85, -40.13))
#: A Line whose 5 mm samples keep J5 >= 11.2687 deg while its path dips to 11.2527.
SHALLOW = ((-56.5, -27.7, 92.0, -11.6, 14.2, 40.0), (34.0, 39.0, 12.0))
TICK_S = 0.002


def _target(start: Pose, offset: tuple[float, ...]) -> Pose:
    dx, dy, dz = offset
    return Pose(start.x + dx, start.y + dy, start.z + dz, start.rx, start.ry, start.rz)


def _run_line(backend: KinematicBackend, offset: tuple[float, ...]) -> tuple[float, float]:
    """The simulated Line at 100 %, ticked every 2 ms: the TCP's largest distance from
    the straight line (mm) and the fastest joint's tick rate over its top speed."""
    start = backend.tcp_pose()
    target = _target(start, offset)
    backend.start_motion(target, motion=MotionType.LINE, speed_percent=100, accel_time_s=0.2)
    a, b = start.as_list()[:3], target.as_list()[:3]
    along = [(q - p) / start.distance_to(target) for p, q in zip(a, b, strict=True)]
    before = backend.joint_positions_deg()
    assert before is not None
    off_line = worst = 0.0
    while backend.motion_running:
        backend.step(TICK_S)
        joints, tcp = backend.joint_positions_deg(), backend.tcp_pose()
        assert joints is not None
        rel = [q - p for p, q in zip(a, tcp.as_list()[:3], strict=True)]
        ahead = sum(r * u for r, u in zip(rel, along, strict=True))
        off_line = max(off_line, math.sqrt(max(0.0, sum(r * r for r in rel) - ahead * ahead)))
        top = backend.model.joint_speed_deg_s
        rates = (abs(y - x) / TICK_S / v for x, y, v in zip(before, joints, top, strict=True))
        worst, before = max(worst, *rates), joints
    assert backend.tcp_pose() == target
    return off_line, worst


def _at(joints: tuple[float, ...]) -> KinematicBackend:
    """A TM5-700 simulated arm at ``joints`` (a slow PTP there from the ready posture)."""
    backend = KinematicBackend(ARM, home=ARM.forward(ARM.ready_joints_deg))
    backend.start_joint_motion(joints, speed_percent=20, accel_time_s=0.2)
    while backend.motion_running:
        backend.step(0.05)
    assert backend.joint_positions_deg() == joints
    return backend


def test_a_line_near_the_wrist_singularity_keeps_every_joint_within_its_top_speed() -> None:
    joints, offset = FAST
    off_line, worst = _run_line(_at(joints), offset)
    assert off_line < 0.001
    assert worst <= 1.005  # was 1.065 (J4)


def test_a_line_whose_path_dips_into_the_wrist_margin_is_refused() -> None:
    joints, offset = DIP
    start = ARM.forward(joints)
    # The premise: the path itself (no margin) passes J5 = 4.99 deg.
    path = UNMARGINED.line_joints(
        start, _target(start, offset), start_joints_deg=joints, step_mm=0.25
    )
    assert 4.98 < min(abs(q[4]) for q in path) < 4.99
    with pytest.raises(UnreachablePoseError) as caught:
        ARM.line_joints(start, _target(start, offset), start_joints_deg=joints)
    assert caught.value.reason == "singularity"
    backend = _at(joints)
    with pytest.raises(MotionRejectedError):
        backend.start_motion(
            _target(start, offset), motion=MotionType.LINE, speed_percent=100, accel_time_s=0.2
        )
    assert not backend.motion_running


def test_the_simulated_arm_keeps_to_its_line_inside_a_margin() -> None:
    # A model whose wrist margin (11.26 deg) lies between the Line's samples and its dip:
    # the master's plan passes it, and the arm follows its line through the margin.
    model = ARM.model_copy(update={"wrist_margin_deg": 11.26})
    joints, offset = SHALLOW
    backend = KinematicBackend(model, home=model.forward(joints))
    assert backend.joint_positions_deg() == pytest.approx(joints, abs=1e-6)
    start = model.forward(joints)
    samples = model.line_joints(start, _target(start, offset), start_joints_deg=joints)
    assert min(abs(q[4]) for q in samples) > 11.26
    path = UNMARGINED.line_joints(
        start, _target(start, offset), start_joints_deg=joints, step_mm=0.25
    )
    assert min(abs(q[4]) for q in path) < 11.255
    off_line, worst = _run_line(backend, offset)
    assert off_line < 0.001  # was 0.28 mm
    assert worst < 1.01  # was 1.074: a joint jumped where the solver took over again
