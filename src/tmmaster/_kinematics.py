"""Rigid transforms, TM's Euler convention, and the serial-chain maths of an arm.

Pure Python on 4x4 homogeneous matrices (tuples of rows, millimetres): the chain has six
joints, so a numerical library would cost more to import than it saves.

**Orientation convention.** A pose's ``rx, ry, rz`` (degrees) mean
``R = Rz(rz) @ Ry(ry) @ Rx(rx)``: rotate about the fixed base X, then Y, then Z. Source:
Techman's own ROS 2 driver converts the robot's tool pose with ``quat.setRPY(rx, ry, rz)``
(``TechmanRobotInc/tmr_ros2``, ``tm_driver/src/tm_ros2_svr.cpp`` lines 144-145, commit
684faab), and tf2's ``setRPY`` is exactly that fixed-axis X-Y-Z order.

**Joint chain.** Each joint is a URDF joint: a fixed origin transform (translation, then
roll-pitch-yaw) from the previous frame, then a rotation about its own z axis. The
flange is the frame of joint 6 (Techman's ``flange_fixed_joint`` is the identity).

**Inverse kinematics** is damped least squares on the geometric Jacobian, started from a
seed (the current joints), so it converges to the solution nearest the seed; when it
fails from the seed it is restarted from a few canonical postures and the solution
nearest the seed wins. A pose no start converges to is refused as out of reach.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from ._pose import Pose

Row = tuple[float, float, float, float]
Transform = tuple[Row, Row, Row, Row]
#: A rigid frame as the three rows of a transform that matter: rotation and position.
Frame = tuple[Row, Row, Row]
Vector = tuple[float, float, float]

IDENTITY: Transform = (
    (1.0, 0.0, 0.0, 0.0),
    (0.0, 1.0, 0.0, 0.0),
    (0.0, 0.0, 1.0, 0.0),
    (0.0, 0.0, 0.0, 1.0),
)


def multiply(a: Transform, b: Transform) -> Transform:
    """The product ``a @ b`` of two homogeneous transforms."""
    b0, b1, b2 = b[0], b[1], b[2]
    rows = [
        (
            r[0] * b0[0] + r[1] * b1[0] + r[2] * b2[0],
            r[0] * b0[1] + r[1] * b1[1] + r[2] * b2[1],
            r[0] * b0[2] + r[1] * b1[2] + r[2] * b2[2],
            r[0] * b0[3] + r[1] * b1[3] + r[2] * b2[3] + r[3],
        )
        for r in a[:3]
    ]
    return (rows[0], rows[1], rows[2], IDENTITY[3])


def invert(t: Transform) -> Transform:
    """The inverse of a rigid transform (rotation transposed, translation mapped back)."""
    r = [[t[j][i] for j in range(3)] for i in range(3)]
    p = [t[0][3], t[1][3], t[2][3]]
    rows = [
        (r[i][0], r[i][1], r[i][2], -(r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2]))
        for i in range(3)
    ]
    return (rows[0], rows[1], rows[2], IDENTITY[3])


def rpy_transform(xyz: Sequence[float], rpy_rad: Sequence[float]) -> Transform:
    """Translation ``xyz`` then rotation ``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (URDF, tf2 setRPY)."""
    roll, pitch, yaw = rpy_rad
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return (
        (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr, float(xyz[0])),
        (sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr, float(xyz[1])),
        (-sp, cp * sr, cp * cr, float(xyz[2])),
        IDENTITY[3],
    )


def pose_to_transform(pose: Pose) -> Transform:
    """The transform of a TM pose (mm; rx, ry, rz in degrees, ``Rz @ Ry @ Rx``)."""
    return rpy_transform(
        (pose.x, pose.y, pose.z),
        (math.radians(pose.rx), math.radians(pose.ry), math.radians(pose.rz)),
    )


def transform_to_pose(t: Transform) -> Pose:
    """The TM pose of a transform; at ry = ±90 deg (gimbal lock) rx is reported as 0."""
    r20 = max(-1.0, min(1.0, t[2][0]))
    pitch = -math.asin(r20)
    if abs(r20) < 1.0 - 1e-12:
        roll = math.atan2(t[2][1], t[2][2])
        yaw = math.atan2(t[1][0], t[0][0])
    else:
        roll = 0.0
        yaw = math.atan2(-t[0][1], t[1][1])
    angles = (_tidy(math.degrees(roll)), _tidy(math.degrees(pitch)), _tidy(math.degrees(yaw)))
    return Pose(t[0][3], t[1][3], t[2][3], *angles)


def flange_of(tcp: Pose, tool: Pose | None) -> Pose:
    """The flange pose that puts the TCP at ``tcp`` (TCP = flange x tool); no tool: ``tcp``."""
    if tool is None:
        return tcp
    return transform_to_pose(multiply(pose_to_transform(tcp), invert(pose_to_transform(tool))))


def _tidy(angle_deg: float) -> float:
    # (-180, 180], and 180 rather than -180 for the common "tool down" rx.
    angle = math.fmod(angle_deg, 360.0)
    if angle > 180.0:
        angle -= 360.0
    elif angle <= -180.0:
        angle += 360.0
    return 180.0 if abs(angle + 180.0) < 1e-7 else 0.0 if abs(angle) < 1e-12 else angle


def rotation_error(current: Transform, target: Transform) -> Vector:
    """Rotation vector (rad, base frame) that turns ``current``'s orientation into ``target``'s."""
    # R_err = R_t @ R_c^T, then its axis-angle (log map), robust up to 180 degrees.
    # Term by term in the order sum() adds them (the same floats), without its generators.
    t, c = target, current
    r = [
        [0 + t[i][0] * c[j][0] + t[i][1] * c[j][1] + t[i][2] * c[j][2] for j in range(3)]
        for i in range(3)
    ]
    cos_angle = max(-1.0, min(1.0, (r[0][0] + r[1][1] + r[2][2] - 1.0) / 2.0))
    angle = math.acos(cos_angle)
    axis = (r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1])
    sin2 = math.hypot(*axis)  # = 2 sin(angle)
    if sin2 > 1e-9:
        scale = angle / sin2
        return (axis[0] * scale, axis[1] * scale, axis[2] * scale)
    if cos_angle > 0:
        return (0.0, 0.0, 0.0)
    # 180 degrees: the axis is the column of (R + I) with the largest norm.
    cols = [(r[0][j] + (j == 0), r[1][j] + (j == 1), r[2][j] + (j == 2)) for j in range(3)]
    col = max(cols, key=lambda c: math.hypot(*c))
    norm = math.hypot(*col)
    return (col[0] / norm * math.pi, col[1] / norm * math.pi, col[2] / norm * math.pi)


def _eliminate(a: list[list[float]], n: int) -> float:
    """Gaussian elimination with partial pivoting of the first ``n`` columns, in place.

    ``a`` (``n`` rows, ``n`` or more columns) becomes upper triangular in those columns.

    Returns:
        The sign the row swaps give a determinant (1 or -1); 0.0 for a singular matrix.
    """
    sign = 1.0
    for col in range(n):
        pivot = max(range(col, n), key=lambda i: abs(a[i][col]))
        if abs(a[pivot][col]) < 1e-300:
            return 0.0
        if pivot != col:
            a[col], a[pivot] = a[pivot], a[col]
            sign = -sign
        p = a[col]
        for i in range(col + 1, n):
            f = a[i][col] / p[col]
            if f:
                row = a[i]
                for j in range(col, len(row)):
                    row[j] -= f * p[j]
    return sign


def solve(matrix: list[list[float]], rhs: list[float]) -> list[float]:
    """Solve ``matrix @ x = rhs`` by Gaussian elimination with partial pivoting."""
    n = len(rhs)
    a = [[*row, b] for row, b in zip(matrix, rhs, strict=True)]
    if not _eliminate(a, n):
        raise ZeroDivisionError("singular matrix")
    x = [0.0] * n
    for i in range(n - 1, -1, -1):
        x[i] = (a[i][n] - sum(a[i][j] * x[j] for j in range(i + 1, n))) / a[i][i]
    return x


def determinant(matrix: list[list[float]]) -> float:
    """Determinant of a square matrix (Gaussian elimination)."""
    a = [list(row) for row in matrix]
    sign = _eliminate(a, len(a))
    return sign * math.prod(a[i][i] for i in range(len(a))) if sign else 0.0


@dataclass(frozen=True)
class Chain:
    """The fixed origin transforms of a serial arm whose joints turn about their own z."""

    origins: tuple[Transform, ...]

    def frames(self, joints_rad: Sequence[float]) -> list[Transform]:
        """Base -> frame of each joint, after the joint's rotation (the last is the flange)."""
        return [(*frame, IDENTITY[3]) for frame in self.link_frames(joints_rad)[1:]]

    def flange(self, joints_rad: Sequence[float]) -> Transform:
        """Base -> flange transform."""
        return self.frames(joints_rad)[-1]

    def link_frames(self, joints_rad: Sequence[float]) -> list[Frame]:
        """Base -> each joint's frame after its turn, as three rows (rotation, position).

        The base's frame first, the flange's last. The chain's product written out for
        turns about z, without 4x4 matrix products (about twice as fast): the inverse
        kinematics' Jacobian takes it at every step, the simulator its links every tick
        and the body check the arm at every sample of a path.
        """
        # The rotation so far, row by row, and the position of the current frame.
        r00, r01, r02, r10, r11, r12, r20, r21, r22 = 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0
        px = py = pz = 0.0
        frames = [((r00, r01, r02, px), (r10, r11, r12, py), (r20, r21, r22, pz))]
        for (a0, a1, a2, _), q in zip(self.origins, joints_rad, strict=True):
            a00, a01, a02, ax = a0
            a10, a11, a12, ay = a1
            a20, a21, a22, az = a2
            px, py, pz = (
                r00 * ax + r01 * ay + r02 * az + px,
                r10 * ax + r11 * ay + r12 * az + py,
                r20 * ax + r21 * ay + r22 * az + pz,
            )
            # This joint's origin turned by its angle (columns 0 and 1 mixed), then
            # appended to the rotation so far.
            c, s = math.cos(q), math.sin(q)
            m00, m01 = c * a00 + s * a01, c * a01 - s * a00
            m10, m11 = c * a10 + s * a11, c * a11 - s * a10
            m20, m21 = c * a20 + s * a21, c * a21 - s * a20
            r00, r01, r02, r10, r11, r12, r20, r21, r22 = (
                r00 * m00 + r01 * m10 + r02 * m20,
                r00 * m01 + r01 * m11 + r02 * m21,
                r00 * a02 + r01 * a12 + r02 * a22,
                r10 * m00 + r11 * m10 + r12 * m20,
                r10 * m01 + r11 * m11 + r12 * m21,
                r10 * a02 + r11 * a12 + r12 * a22,
                r20 * m00 + r21 * m10 + r22 * m20,
                r20 * m01 + r21 * m11 + r22 * m21,
                r20 * a02 + r21 * a12 + r22 * a22,
            )
            frames.append(((r00, r01, r02, px), (r10, r11, r12, py), (r20, r21, r22, pz)))
        return frames

    def joint_origins(self, joints_rad: Sequence[float]) -> list[Vector]:
        """Base-frame position of each joint's origin, the last the flange's, mm.

        The positions of :meth:`link_frames` (a joint's turn leaves its origin where it is).
        """
        return [(f[0][3], f[1][3], f[2][3]) for f in self.link_frames(joints_rad)[1:]]

    def jacobian(
        self, joints_rad: Sequence[float], tool: Transform = IDENTITY
    ) -> tuple[list[list[float]], Transform]:
        """Geometric Jacobian (rows: vx, vy, vz in m/rad, wx, wy, wz) of the TCP, and the TCP."""
        frames = self.frames(joints_rad)
        tcp = multiply(frames[-1], tool)
        p = (tcp[0][3], tcp[1][3], tcp[2][3])
        columns = []
        for f in frames:
            z = (f[0][2], f[1][2], f[2][2])
            d = ((p[0] - f[0][3]) / 1000.0, (p[1] - f[1][3]) / 1000.0, (p[2] - f[2][3]) / 1000.0)
            columns.append((*_cross(z, d), *z))  # linear (z x d), then angular (z)
        return [[col[i] for col in columns] for i in range(6)], tcp


def pose_error(current: Transform, target: Transform) -> list[float]:
    """Twist from ``current`` to ``target``: position in metres, rotation vector in rad."""
    position = [(target[i][3] - current[i][3]) / 1000.0 for i in range(3)]
    return [*position, *rotation_error(current, target)]


def _damped_gram(jac: list[list[float]], damping: float) -> list[list[float]]:
    """``jac @ jac.T + damping**2 * I`` of a 6x6 Jacobian (its rows: the six twist parts).

    Written out term by term in the order ``sum`` adds them (the same floats to the last
    bit): the inverse kinematics spends most of its time here. The product is symmetric
    (``a * b == b * a`` exactly), so each pair off the diagonal is computed once.
    """
    d2 = damping**2
    out = [[0.0] * 6 for _ in range(6)]
    for i, a in enumerate(jac):
        for j in range(i, 6):
            b = jac[j]
            s = 0 + a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
            s = s + a[3] * b[3] + a[4] * b[4] + a[5] * b[5]
            if i == j:
                out[i][i] = s + d2
            else:
                out[i][j] = out[j][i] = s + 0.0
    return out


def _transposed_times(jac: list[list[float]], y: list[float]) -> list[float]:
    """``jac.T @ y`` of a 6x6 Jacobian, term by term in the order ``sum`` adds them."""
    j0, j1, j2, j3, j4, j5 = jac
    y0, y1, y2, y3, y4, y5 = y
    return [
        0 + j0[k] * y0 + j1[k] * y1 + j2[k] * y2 + j3[k] * y3 + j4[k] * y4 + j5[k] * y5
        for k in range(6)
    ]


#: The inverse kinematics has converged within this distance, m, ...
IK_TOLERANCE_M = 1e-6
#: ... and this rotation, rad, ...
IK_TOLERANCE_RAD = 1e-6
#: ... or gives up after this many steps.
IK_ITERATIONS = 100


def dls_inverse(
    chain: Chain, target: Transform, seed_rad: Sequence[float], *, tool: Transform = IDENTITY
) -> list[float] | None:
    """Damped-least-squares IK from ``seed_rad``: the joints (rad), or None without convergence."""
    q = list(seed_rad)
    damping = 1e-3
    previous = best = math.inf
    since_best = 0
    for _ in range(IK_ITERATIONS):
        jac, tcp = chain.jacobian(q, tool)
        error = pose_error(tcp, target)
        position = math.hypot(*error[:3])
        rotation = math.hypot(*error[3:])
        converged = position < IK_TOLERANCE_M and rotation < IK_TOLERANCE_RAD
        norm = position + rotation
        # A pose out of reach stalls at a nonzero error: give up once it stops improving.
        if norm < best * 0.99:
            best, since_best = norm, 0
        else:
            since_best += 1
            if since_best > 8:
                return None
        # Adapt the damping: shrink it while converging, grow it when an update overshoots.
        damping = max(damping * 0.5, 1e-6) if norm < previous else min(damping * 4.0, 1.0)
        previous = norm
        try:
            y = solve(_damped_gram(jac, damping), error)
        except ZeroDivisionError:
            return None
        step = _transposed_times(jac, y)
        if converged:
            # One more step from within the tolerance: the answer then no longer depends
            # on the seed it was approached from, and a repeating cycle's seeds settle.
            return [a + b for a, b in zip(q, step, strict=True)]
        # Bound a single update so a far target is approached, not jumped over.
        largest = max(abs(s) for s in step)
        if largest > 0.5:
            step = [s * 0.5 / largest for s in step]
        q = [a + b for a, b in zip(q, step, strict=True)]
    return None


def rotation_matrix(rotation_vector: Vector) -> tuple[Vector, Vector, Vector]:
    """The rotation matrix of a rotation vector (axis times angle in rad), by Rodrigues."""
    angle = math.hypot(*rotation_vector)
    if angle < 1e-15:
        return ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    x, y, z = (c / angle for c in rotation_vector)
    c, s = math.cos(angle), math.sin(angle)
    v = 1.0 - c
    return (
        (c + x * x * v, x * y * v - z * s, x * z * v + y * s),
        (y * x * v + z * s, c + y * y * v, y * z * v - x * s),
        (z * x * v - y * s, z * y * v + x * s, c + z * z * v),
    )


def interpolate(a: Transform, b: Transform, fraction: float) -> Transform:
    """The pose ``fraction`` (0..1) of the way from ``a`` to ``b``: straight line, shortest turn."""
    w = rotation_error(a, b)
    r = rotation_matrix((w[0] * fraction, w[1] * fraction, w[2] * fraction))
    # a's orientation turned that far (r @ a); its position moved along the line.
    turned = multiply(((*r[0], 0.0), (*r[1], 0.0), (*r[2], 0.0), IDENTITY[3]), a)
    return _placed(turned, [a[i][3] + (b[i][3] - a[i][3]) * fraction for i in range(3)])


def _placed(t: Transform, position: Sequence[float]) -> Transform:
    """``t``'s orientation at ``position`` (mm)."""
    x, y, z = position
    return ((*t[0][:3], x), (*t[1][:3], y), (*t[2][:3], z), IDENTITY[3])


def _add(a: Vector, b: Vector) -> Vector:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def _sub(a: Vector, b: Vector) -> Vector:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _cross(a: Vector, b: Vector) -> Vector:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _dot(a: Vector, b: Vector) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _scaled(a: Vector, k: float) -> Vector:
    return (a[0] * k, a[1] * k, a[2] * k)


#: An arc's three points must be this far apart, mm, and its radius at most this large.
ARC_MIN_SPACING_MM = 1.0
ARC_MAX_RADIUS_MM = 100_000.0


@dataclass(frozen=True)
class Arc:
    """The circular arc from a start pose through a via point to an end pose.

    The TCP runs along the circle through the three positions, from the start through the
    via to the end; its orientation turns uniformly (the shortest turn) from the start's
    to the end's along the arc, as a TMscript ``Circle`` with arc angle 0 moves ("linear
    interpolation on pose", TMscript 2.24, 13.12, p. 343). The via's orientation is not
    used: :meth:`at` gives the one the TCP has there.
    """

    start: Transform
    end: Transform
    #: The circle's centre, mm.
    centre: Vector
    radius_mm: float
    #: Unit vector from the centre to the start, and the one 90 degrees ahead of it in the
    #: direction of travel: the arc's point at angle phi is centre + r (cos u + sin w).
    u: Vector
    w: Vector
    #: The angle swept from the start to the end, rad (0 < sweep < 2 pi).
    sweep_rad: float
    #: Where the via point lies on the arc (fraction of the sweep, 0 < f < 1).
    via_fraction: float

    @classmethod
    def through(cls, start: Pose, via: Pose, end: Pose) -> Arc:
        """The arc from ``start`` through ``via``'s position to ``end``.

        Raises:
            ValueError: two of the points are closer than 1 mm, the three lie on one
                line (no circle passes through them), or the radius is over 100 m.
        """
        p0, p1, p2 = (start.x, start.y, start.z), (via.x, via.y, via.z), (end.x, end.y, end.z)
        a, b = _sub(p1, p0), _sub(p2, p0)
        for name, (p, q) in (
            ("start and via", (p0, p1)),
            ("via and end", (p1, p2)),
            ("start and end", (p0, p2)),
        ):
            if math.dist(p, q) < ARC_MIN_SPACING_MM:
                raise ValueError(
                    f"the arc's {name} are {math.dist(p, q):.2f} mm apart: an arc needs three"
                    f" distinct points (at least {ARC_MIN_SPACING_MM:g} mm apart)"
                )
        n = _cross(a, b)
        n2 = _dot(n, n)
        if math.sqrt(n2) < 1e-6 * math.hypot(*a) * math.hypot(*b):
            raise ValueError(
                "the arc's start, via and end lie on one line: no circle passes through them"
            )
        # Circumcentre: p0 + (|a|^2 (b x n) + |b|^2 (n x a)) / (2 |n|^2).
        first, second = _scaled(_cross(b, n), _dot(a, a)), _scaled(_cross(n, a), _dot(b, b))
        centre = _add(p0, _scaled(_add(first, second), 1.0 / (2.0 * n2)))
        radius = math.dist(centre, p0)
        if radius > ARC_MAX_RADIUS_MM:
            raise ValueError(
                f"the arc's radius is {radius / 1000:.0f} m: its start, via and end are too"
                " nearly on one line (use a Line)"
            )
        u = _scaled(_sub(p0, centre), 1.0 / radius)
        normal = _scaled(n, 1.0 / math.sqrt(n2))
        w = _cross(normal, u)

        def angle(p: Vector) -> float:
            d = _sub(p, centre)
            return math.atan2(_dot(d, w), _dot(d, u)) % (2.0 * math.pi)

        via_angle, end_angle = angle(p1), angle(p2)
        if via_angle > end_angle:
            # Through the via, the arc runs the other way round the normal.
            w = _scaled(w, -1.0)
            via_angle, end_angle = 2.0 * math.pi - via_angle, 2.0 * math.pi - end_angle
        return cls(
            pose_to_transform(start),
            pose_to_transform(end),
            centre,
            radius,
            u,
            w,
            end_angle,
            via_angle / end_angle,
        )

    @property
    def length_mm(self) -> float:
        """The arc's length, mm."""
        return self.radius_mm * self.sweep_rad

    def at(self, fraction: float) -> Transform:
        """The TCP ``fraction`` (0..1) of the way along the arc: on the circle, turned that far."""
        if fraction >= 1.0:
            return self.end
        turned = interpolate(self.start, self.end, fraction)
        phi = self.sweep_rad * fraction
        c, s = math.cos(phi) * self.radius_mm, math.sin(phi) * self.radius_mm
        return _placed(turned, [self.centre[i] + c * self.u[i] + s * self.w[i] for i in range(3)])
