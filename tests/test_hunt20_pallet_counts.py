"""A pallet's counts are whole numbers: a fraction is refused, not half run unchecked.

Found by hunt 20 (fails without its fix): ``Pallet(rows=1.5, cols=1, dy=100)`` was
taken. Its ``size`` (1.5) became the sequence's cycle count: ``validate_plan`` checked
the moves of cycle 1 (``cycle <= 1.5``), and the runner ran cycle 2 as well (cycle 1
was not the last, ``1 < 1.5``), placing the second part into slot 1, a row 100 mm
beyond the pallet that no plan check had seen (measured on the simulator: DONE, 2
cycles, the part at y = 200). ``rows=True`` was one row. A count must now be an int
>= 1 and a pitch a finite number, else :class:`ConfigError` names it.
"""

from __future__ import annotations

from typing import Any

import pytest

from tmmaster import ConfigError, Pose
from tmmaster.pickplace import Pallet

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
