"""A long sequence file loads in time proportional to its steps; a name used twice is
still refused however the steps were added.

Found by hunt 20: ``TaskSequence.add`` looked for a step of the same name by scanning
every step before it, so a sequence file at the 1 MiB limit (34,951 ``wait`` steps)
took 20 s to load (94 s under a profiler: 610 million comparisons) before ``--dry-run``
or the run said anything. The names are now kept as they are added (measured: 0.65 s
for the same file). Not timed here (the suite times nothing); this guards what the
index must keep doing: a name used twice is refused, also after ``steps`` was changed
directly.
"""

from __future__ import annotations

import pytest

from tmmaster import ConfigError
from tmmaster.pickplace import Step, TaskSequence, sequence_from_data


def _nothing(_ctx: object) -> None:
    return None


def test_a_long_sequence_loads_and_a_name_used_twice_is_refused() -> None:
    steps = [{"do": "wait", "seconds": 1} for _ in range(3000)]
    seq = sequence_from_data({"name": "long", "open_at_start": False, "steps": steps})
    assert [s.name for s in seq.steps[-2:]] == ["WAIT_2999", "WAIT_3000"]
    with pytest.raises(ConfigError, match=r"steps\.3000\.state: .*'WAIT_7' defined twice"):
        sequence_from_data(
            {"name": "long", "steps": [*steps, {"state": "WAIT_7", "do": "wait", "seconds": 1}]}
        )


def test_a_name_used_twice_is_refused_after_the_steps_were_changed_directly() -> None:
    seq = TaskSequence("edited").add("A", _nothing)
    seq.steps.append(Step("B", _nothing))
    with pytest.raises(ConfigError, match="'B' defined twice"):
        seq.add("B", _nothing)
    seq.steps = [Step("C", _nothing)]
    seq.add("A", _nothing)  # A is gone with the old list
    with pytest.raises(ConfigError, match="'C' defined twice"):
        seq.add("C", _nothing)


def test_a_name_made_twice_by_editing_the_steps_in_place_is_refused_by_validate() -> None:
    seq = TaskSequence("edited").add("A", _nothing).add("B", _nothing)
    seq.steps[1] = Step("A", _nothing)
    with pytest.raises(ConfigError, match="'A' defined twice"):
        seq.validate()
