"""Check every move of a run before the first byte, and estimate how long it takes."""

from __future__ import annotations

from dataclasses import dataclass

from .._channels import Command, CommandKind
from .._exceptions import ConfigError
from .._pose import Pose
from .._robot import Robot
from .._robot_models import RobotModel
from ._steps import PlannedMove, TaskSequence


def validate_plan(robot: Robot, sequence: TaskSequence, cycles: int, *, source: str) -> int:
    """Validate every known move against the profile, arm and limits; returns the count.

    Nothing is sent: a move that cannot be encoded (e.g. beyond +/-327.67 mm in the
    article profile), is out of reach or too fast raises :class:`ConfigError` naming
    the configuration key and ``source``.
    """
    sequence.validate()
    count = 0
    seen: set[tuple[object, ...]] = set()
    for move in sequence.planned_moves(cycles):
        key = (move.pose, move.speed, move.motion)
        if key in seen:
            continue
        seen.add(key)
        where = move.source or move.state
        try:
            robot.validate_move(move.pose, move.speed)
            robot.channel.encode_command(
                Command(CommandKind.of(move.motion), move.pose, move.speed)
            )
        except ConfigError as exc:
            raise ConfigError(
                f"{source}: {where} ({move.state}): {exc} [profile {robot.profile.name},"
                f" model {robot.model.name}]"
            ) from None
        count += 1
    return count


@dataclass(frozen=True)
class EstimatedMove:
    """A planned move with its expected duration."""

    cycle: int
    move: PlannedMove
    expected_s: float


def estimate(
    sequence: TaskSequence, cycles: int, model: RobotModel, *, start: Pose
) -> list[EstimatedMove]:
    """Expected duration of every planned move (RobotModel.motion_time), from ``start``."""
    if sequence.plan is None:
        return []
    here = start
    result = []
    for cycle in range(1, cycles + 1):
        for move in sequence.plan(cycle, cycles):
            seconds = model.motion_time(
                here, move.pose, speed_percent=move.speed, motion=move.motion
            )
            result.append(EstimatedMove(cycle, move, seconds))
            here = move.pose
    return result


def format_plan(
    sequence: TaskSequence, cycles: int, model: RobotModel, *, start: Pose, profile: str
) -> str:
    """The --dry-run text: every move with pose, speed, motion type and expected time."""
    lines = [
        f"sequence {sequence.name}: {cycles} cycle(s), profile {profile}, model {model.name}",
        f"states: IDLE -> {' -> '.join(s.name for s in sequence.steps)} -> DONE | ERROR",
        f"start pose assumed: {start}",
        "",
        f"{'cycle':>5}  {'state':<20} {'pose [x, y, z, rx, ry, rz]':<44} {'speed':>5}"
        f"  {'motion':<6} {'expected':>9}",
    ]
    moves = estimate(sequence, cycles, model, start=start)
    # Long runs: the first and last cycle say it all.
    shown = {1, cycles}
    for item in moves:
        if item.cycle not in shown:
            continue
        pose = ", ".join(f"{v:g}" for v in item.move.pose.as_list())
        lines.append(
            f"{item.cycle:>5}  {item.move.state:<20} [{pose}]".ljust(73)
            + f" {item.move.speed:>4}%  {item.move.motion.value:<6} {item.expected_s:>8.2f}s"
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
