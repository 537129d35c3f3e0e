"""The plan is lazy: checking and timing a run of 1,000,000 cycles asks for a few cycles.

The cycles between the first and the last repeat the same moves; once they fall into a
loop (a cycle starting where an earlier one started) the loop stands for the rest. The
checks, the --dry-run text and its totals are those of the whole run.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tmmaster import MotionType, Robot
from tmmaster.pickplace import Pallet, estimate, format_plan, palletizing, pick_and_place
from tmmaster.pickplace._config import load_config, robot_from_config
from tmmaster.pickplace._plan import CyclePlan, validate_plan
from tmmaster.pickplace._steps import Cycles, PlannedMove, TaskSequence

MILLION = 1_000_000


class _Asked:
    """Counts the cycles a sequence is asked for; more than ``limit`` is not lazy."""

    def __init__(self, sequence: TaskSequence, limit: int = 50) -> None:
        self.cycles: list[int] = []
        moves = sequence.moves

        def counted(cycle: int, cycles: int) -> list[PlannedMove]:
            self.cycles.append(cycle)
            assert len(self.cycles) <= limit, "the plan is made cycle by cycle, up front"
            return moves(cycle, cycles)

        sequence.moves = counted  # type: ignore[method-assign]


@pytest.fixture
def robot() -> Iterator[Robot]:
    config = load_config(None)
    robot = robot_from_config(config, "127.0.0.1")  # never connected
    yield robot
    robot.close()


def test_a_plan_of_a_million_cycles_is_made_when_asked() -> None:
    sequence = pick_and_place()
    asked = _Asked(sequence)
    plan = CyclePlan(sequence, MILLION)
    assert asked.cycles == []  # building it plans nothing
    assert plan.repeats
    assert "MOVE_TO_PICK" in plan.states()
    assert len(asked.cycles) <= 3


def test_checking_a_million_cycles_asks_for_a_few(robot: Robot) -> None:
    sequence = pick_and_place()
    asked = _Asked(sequence)
    assert validate_plan(robot, sequence, MILLION, source="x") == validate_plan(
        robot,
        pick_and_place(),
        3,
        source="x",
    )
    assert asked.cycles[-1] == MILLION  # the last cycle is checked, from where it starts


def test_the_dry_run_of_a_million_cycles_counts_every_cycle(robot: Robot) -> None:
    model = robot.model
    home = load_config(None).poses.resolved()["home"]
    sequence = pick_and_place()
    asked = _Asked(sequence)
    text = format_plan(sequence, MILLION, model, start=home, profile="tmflow")
    assert "cycles 2..999999: the same moves" in text
    per_cycle = sum(m.expected_s for m in estimate(pick_and_place(), 1, model, start=home))
    middle = [m for m in estimate(pick_and_place(), 3, model, start=home) if m.cycle == 2]
    last = [m for m in estimate(pick_and_place(), 2, model, start=home) if m.cycle == 2]
    total = (
        per_cycle
        + sum(m.expected_s for m in middle) * (MILLION - 2)
        + sum(m.expected_s for m in last)
    )
    assert f"{total:.2f} s in total" in text
    assert len(asked.cycles) <= 10


@pytest.mark.parametrize("cycles", range(1, 8))
def test_the_lazy_dry_run_says_what_the_whole_one_says(robot: Robot, cycles: int) -> None:
    model = robot.model
    home = load_config(None).poses.resolved()["home"]
    sequence = pick_and_place()
    sequence.add(
        "ONCE", move=PlannedMove("ONCE", home.offset(dz=-30), 20, _ptp()), when="first_cycle"
    )
    sequence.add(
        "LAST", move=PlannedMove("LAST", home.offset(dx=-30), 20, _ptp()), when=Cycles.LAST
    )
    text = format_plan(sequence, cycles, model, start=home, profile="tmflow")
    moves = estimate(sequence, cycles, model, start=home)
    assert f"{sum(m.expected_s for m in moves):.2f} s in total" in text
    assert CyclePlan(sequence, cycles).states() == sorted(
        {m.state for m in sequence.planned_moves(cycles)}
    )


def _ptp() -> MotionType:
    return MotionType.PTP


def test_a_move_only_the_last_of_a_million_cycles_makes_is_still_checked(robot: Robot) -> None:
    from tmmaster._exceptions import ConfigError

    config = load_config(None)
    far = config.poses.resolved()["home"].offset(dx=5000)  # beyond any arm's reach
    sequence = pick_and_place(config)
    sequence.add("FAR", move=PlannedMove("FAR", far, 20, _ptp(), "far"), when="last_cycle")
    with pytest.raises(ConfigError, match="far"):
        validate_plan(robot, sequence, MILLION, source="x")


def test_moves_that_change_every_cycle_are_each_checked(robot: Robot) -> None:
    poses = load_config(None).poses.resolved()
    pallet = Pallet(origin=poses["place"], rows=2, cols=3, dx=40, dy=40)
    sequence = palletizing(pick=poses["pick"], pallet=pallet, home=poses["home"])
    plan = CyclePlan(sequence, pallet.size)
    assert not plan.repeats
    asked = _Asked(sequence)
    validate_plan(robot, sequence, pallet.size, source="x")
    assert asked.cycles == list(range(1, pallet.size + 1))


@pytest.mark.parametrize("period", [1, 2, 3])
@pytest.mark.parametrize("cycles", range(1, 12))
def test_a_loop_of_middle_cycles_stands_for_the_rest(period: int, cycles: int) -> None:
    sequence = pick_and_place()
    plan = CyclePlan(sequence, cycles)

    def run_cycle(cycle: int, moves: list[PlannedMove], start: int) -> tuple[int, int]:
        _ = moves
        return (start + 1) % period, start * 10 + (cycle in (1, cycles))

    runs = list(plan.run(0, run_cycle))
    whole = []
    state = 0
    for cycle in range(1, cycles + 1):
        state, result = run_cycle(cycle, [], state)
        whole.append(result)
    assert sum(r.result * r.times for r in runs) == sum(whole)
    assert sum(r.times for r in runs) == cycles
    # The first, the middle ones up to the repeat, the loop again, the last.
    assert len(runs) <= 2 * period + 2
