"""Check every move of a run before the first byte, and estimate how long it takes."""

from __future__ import annotations

from dataclasses import dataclass

from .._exceptions import ConfigError, UnreachablePoseError
from .._pose import Pose
from .._robot import Robot
from .._robot_models import RobotModel
from ._steps import PlannedMove, TaskSequence


def validate_plan(robot: Robot, sequence: TaskSequence, cycles: int, *, source: str) -> int:
    """Validate every known move against the profile, arm and limits; returns the count.

    Nothing is sent: a move that cannot be encoded (e.g. beyond +/-327.67 mm in the
    article profile), that the arm cannot take (inverse kinematics from the previous
    move's joints: reach, joint ranges, singularities), a Line whose straight path
    leaves the arm's range, or a move too fast raises :class:`ConfigError` naming the
    configuration key and ``source``.

    Args:
        robot: The robot that will run it (profile, arm model, tool, limits); it need
            not be connected.
        sequence: The sequence.
        cycles: How many cycles will run.
        source: Where the sequence comes from (a file name), for the messages.

    Returns:
        How many distinct moves were checked.

    Raises:
        ConfigError: A move that cannot be sent or taken (UnreachablePoseError when the
            arm cannot reach it).
    """
    sequence.validate()
    count = 0
    # Each move continues from the previous one's joints (cycles repeat: each distinct
    # transition is checked once).
    previous: tuple[Pose, tuple[float, ...]] | None = None
    joints_after: dict[tuple[object, ...], tuple[float, ...]] = {}
    for move in sequence.planned_moves(cycles):
        # The retreat starts wherever the run stopped: its path is not known in advance.
        if move is sequence.retreat:
            previous = None
        key = (previous, move.pose, move.speed, move.motion)
        if key in joints_after:
            previous = (move.pose, joints_after[key])
            continue
        where = move.source or move.state
        try:
            joints = robot.check_move(
                move.pose,
                move.speed,
                move.motion,
                start=None if previous is None else previous[0],
                seed_deg=None if previous is None else previous[1],
            )
        except ConfigError as exc:
            message = (
                f"{source}: {where} ({move.state}): {exc} [profile {robot.profile.name},"
                f" model {robot.model.name}]"
            )
            if isinstance(exc, UnreachablePoseError):
                raise UnreachablePoseError(message, reason=exc.reason, pose=exc.pose) from None
            raise ConfigError(message) from None
        joints_after[key] = joints
        count += 1
        previous = (move.pose, joints)
    return count


@dataclass(frozen=True)
class EstimatedMove:
    """A planned move with its expected duration."""

    #: The cycle, 1-based.
    cycle: int
    #: The move.
    move: PlannedMove
    #: Its expected duration, s (from the arm model).
    expected_s: float
    #: Joints J1..J6 (deg) at the move's target, continuing from the previous move's.
    joints_deg: tuple[float, ...]


def estimate(
    sequence: TaskSequence,
    cycles: int,
    model: RobotModel,
    *,
    start: Pose,
    tool: Pose | None = None,
) -> list[EstimatedMove]:
    """Expected duration and target joints of every planned move, from ``start``.

    Args:
        sequence: The sequence.
        cycles: How many cycles.
        model: The arm model that times the moves.
        start: The TCP pose before the first move.
        tool: The TCP in the flange frame (None: the flange).

    Returns:
        Every move of every cycle, in order (empty when the moves are not known in
        advance).

    Raises:
        UnreachablePoseError: A pose the arm cannot reach.
    """
    if not any(s.move is not None for s in sequence.steps) and sequence.plan is None:
        return []
    here = start
    joints = model.inverse(start, tool=tool)
    result = []
    for cycle in range(1, cycles + 1):
        for move in sequence.moves(cycle, cycles):
            seconds = model.motion_time(
                here,
                move.pose,
                speed_percent=move.speed,
                motion=move.motion,
                start_joints_deg=joints,
                tool=tool,
            )
            joints = model.inverse(move.pose, seed_deg=joints, tool=tool)
            result.append(EstimatedMove(cycle, move, seconds, joints))
            here = move.pose
    return result


def format_plan(
    sequence: TaskSequence,
    cycles: int,
    model: RobotModel,
    *,
    start: Pose,
    profile: str,
    tool: Pose | None = None,
) -> str:
    """The --dry-run text: every move with pose, joints, speed, motion type and expected time.

    Args:
        sequence: The sequence.
        cycles: How many cycles (the first and the last are listed).
        model: The arm model that times the moves.
        start: The TCP pose before the first move.
        profile: The profile's name, for the header.
        tool: The TCP in the flange frame (None: the flange).

    Returns:
        The text, one line per move, with totals.
    """
    lines = [
        f"sequence {sequence.name}: {cycles} cycle(s), profile {profile}, model {model.name}",
        f"states: IDLE -> {' -> '.join(s.name for s in sequence.steps)} -> DONE | ERROR",
        f"start pose assumed: {start}",
        "",
        f"{'cycle':>5}  {'state':<20} {'pose [x, y, z, rx, ry, rz]':<44} {'speed':>5}"
        f"  {'motion':<6} {'expected':>9}  joints J1..J6 [deg]",
    ]
    moves = estimate(sequence, cycles, model, start=start, tool=tool)
    # Long runs: the first and last cycle say it all.
    shown = {1, cycles}
    for item in moves:
        if item.cycle not in shown:
            continue
        pose = ", ".join(f"{v:g}" for v in item.move.pose.as_list())
        joints = ", ".join(f"{q:.1f}" for q in item.joints_deg)
        lines.append(
            f"{item.cycle:>5}  {item.move.state:<20} [{pose}]".ljust(73)
            + f" {item.move.speed:>4}%  {item.move.motion.value:<6} {item.expected_s:>8.2f}s"
            + f"  [{joints}]"
        )
    if cycles > 2:
        middle = "cycle 2" if cycles == 3 else f"cycles 2..{cycles - 1}"
        lines.append(f"  ... {middle}: the same moves")
    total = sum(m.expected_s for m in moves)
    per_cycle = sum(m.expected_s for m in moves if m.cycle == 1)
    lines.append("")
    lines.append(
        f"expected motion time: {per_cycle:.2f} s for cycle 1, {total:.2f} s in total"
        " (gripper and polling time not included)"
    )
    if sequence.retreat is not None:
        r = sequence.retreat
        lines.append(
            f"on error: retreat to {r.pose} at {r.speed} % {r.motion.value}"
            " (never after an e-stop or a robot error)"
        )
    else:
        lines.append("on error: stay where it stopped")
    return "\n".join(lines)
