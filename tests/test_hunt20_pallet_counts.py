"""A pallet's counts are whole numbers: a fraction is refused, not half run unchecked.

Found by hunt 20 (fails without its fix): ``Pallet(rows=1.5, cols=1, dy=100)`` was
taken. Its ``size`` (1.5) became the sequence's cycle count: ``validate_plan`` checked
the moves of cycle 1 (``cycle <= 1.5``), and the runner ran cycle 2 as well (cycle 1
was not the last, ``1 < 1.5``), placing the second part into slot 1, a row 100 mm
beyond the pallet that no plan check had seen (measured on the simulator: DONE, 2
cycles, the part at y = 200). ``rows=True`` was one row. A count must now be an int
>= 1 and a pitch a finite number, else :class:`ConfigError` names it. The same for a
cycle count given to ``validate_plan`` and ``Runner.run`` (``cycles=1.5``: one cycle
checked, two run): refused by both, nothing sent.
"""

from __future__ import annotations

from typing import Any

import pytest

from tmmaster import ConfigError, Pose
from tmmaster.pickplace import (
    Pallet,
    Runner,
    palletizing,
    robot_from_config,
    validate_config,
    validate_plan,
)

ORIGIN = Pose(250, 100, 100, 180, 0, 90)


@pytest.mark.parametrize(
    ("key", "value"),
    [("rows", 1.5), ("cols", 2.0), ("layers", True), ("rows", 0), ("dx", "40"), ("dz", True)],
)
def test_a_pallet_count_or_pitch_of_the_wrong_kind_is_refused(key: str, value: Any) -> None:
    grid: dict[str, Any] = {"rows": 2, "cols": 2, "dx": 40.0, "dy": 40, key: value}
    with pytest.raises(ConfigError, match=f"pallet {key} must be"):
        Pallet(origin=ORIGIN, **grid)
    assert Pallet(origin=ORIGIN, rows=2, cols=3, dx=40, dy=40.5, layers=2, dz=30).size == 12


@pytest.mark.parametrize("cycles", [1.5, True, 0])
def test_a_cycle_count_that_is_not_a_whole_number_is_refused_by_plan_and_run(
    cycles: Any,
) -> None:
    pallet = Pallet(origin=ORIGIN, rows=2, cols=1, dx=0, dy=100)
    seq = palletizing(pick=Pose(300, -200, 100, 180, 0, 90), pallet=pallet, home=ORIGIN)
    robot = robot_from_config(validate_config({}), "127.0.0.1")  # never connected
    with pytest.raises(ConfigError, match="cycles must be a whole number"):
        validate_plan(robot, seq, cycles, source="test")
    with pytest.raises(ConfigError, match="cycles must be a whole number"):
        Runner(robot).run(seq, cycles=cycles)
