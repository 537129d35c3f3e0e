"""A pallet or a cycle count made with numpy is taken, as a Pose takes numpy's numbers.

b691028 and f8c0314 refuse a count that is not a whole number (1.5 rows ran an unchecked
cycle) by ``isinstance(count, int)``: numpy's integers are whole numbers but not ``int``,
and numpy's float32 a finite number but not ``float``, so ``Pallet(rows=numpy.int64(2))``,
a pitch from a float32 computation, and ``Runner.run(..., cycles=numpy.int64(3))``, all
taken at 437eb5b, were refused. Whole numbers are ``numbers.Integral`` now (not a bool),
numbers ``numbers.Real``; a fraction and a bool are still refused.
"""

from __future__ import annotations

import pytest

from tmmaster import ConfigError, Pose, Robot
from tmmaster.pickplace import Pallet, palletizing, validate_plan
from tmmaster.pickplace._steps import require_count

numpy = pytest.importorskip("numpy")

ORIGIN = Pose(300, -100, 100, 180, 0, 90)
PICK = Pose(300, -250, 100, 180, 0, 90)
HOME = Pose(250, 0, 300, 180, 0, 90)


def test_numpy_counts_and_pitches_make_the_pallet_they_say() -> None:
    pallet = Pallet(ORIGIN, rows=numpy.int64(2), cols=numpy.int32(3), dx=numpy.float32(40), dy=50)
    assert (pallet.rows, pallet.cols, pallet.size) == (2, 3, 6)
    assert type(pallet.size) is int  # the sequence's cycle count, a plain int
    assert pallet.slot(5).is_close(ORIGIN.offset(dx=80, dy=50))
    assert palletizing(pick=PICK, pallet=pallet, home=HOME).default_cycles == 6
    require_count(numpy.int64(3))


@pytest.mark.parametrize(
    "kwargs",
    [
        {"rows": numpy.float64(1.5)},
        {"rows": numpy.bool_(True)},
        {"cols": 2.0},
        {"dx": numpy.float32("nan")},
        {"dy": numpy.bool_(True)},
    ],
)
def test_a_fraction_a_switch_or_nan_is_still_refused(kwargs: dict[str, object]) -> None:
    options: dict[str, object] = {"rows": 1, "cols": 1, "dx": 40.0, "dy": 40.0, **kwargs}
    with pytest.raises(ConfigError, match=f"pallet {next(iter(kwargs))} must be"):
        Pallet(ORIGIN, **options)  # type: ignore[arg-type]
    for cycles in (numpy.float64(1.5), numpy.bool_(True), 0):
        with pytest.raises(ConfigError, match="cycles must be a whole number"):
            require_count(cycles)


def test_a_numpy_cycle_count_is_planned_as_it_runs() -> None:
    pallet = Pallet(ORIGIN, rows=2, cols=1, dx=40.0, dy=50.0)
    robot = Robot("127.0.0.1", 1)  # not connected: the plan reads nothing
    assert (
        validate_plan(
            robot, palletizing(pick=PICK, pallet=pallet, home=HOME), numpy.int64(2), source="t"
        )
        > 0
    )
