"""A number key of the pick & place configuration written as text or as a switch.

docs/pickplace.md: "a wrong type or an out-of-range value is reported with its dotted key
and the file", exit 2, nothing sent. The speeds, counts and poses were strict, but every
other number key took pydantic's lax coercion: ``floor_z_mm = true`` was a table plane
at 1 mm (the table guard lowered by 84 mm: a pick 60 mm up, 25 mm into the table,
passed the plan), ``port = "502"`` a port, ``ack_timeout_s = "1"`` a timeout. Each is
now refused before anything connects, naming the key; the run's simulator sees no
request at all. NaN, infinity and the out-of-range numbers were refused already
(guarded here once each).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from tmmaster.pickplace.__main__ import EXIT_CONFIG, main
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]

CASES = [
    ("workspace", "floor_z_mm", "true"),
    ("workspace", "floor_z_mm", '"85"'),
    ("robot", "port", '"502"'),
    ("robot", "position_tolerance_mm", "true"),
    ("gripper", "settle_s", "true"),
    ("gripper", "port", "true"),
    ("timeouts", "ack_timeout_s", '"1"'),
    ("timeouts", "motion_timeout_s", "true"),
    ("retry", "max_backoff_s", '"1"'),
    ("run", "poll_interval_s", "true"),
    ("poses", "approach_z_offset", '"100"'),
    ("poses", "lift_z_offset", "false"),
    # Refused before this change too: the edges of a number's range.
    ("run", "poll_interval_s", "nan"),
    ("timeouts", "ack_timeout_s", "inf"),
    ("poses", "lift_z_offset", "-1"),
    ("robot", "position_tolerance_mm", "0"),
    ("gripper", "settle_s", "1e308"),
]


@pytest.mark.parametrize(("section", "key", "value"), CASES)
def test_a_number_key_written_as_text_or_a_switch_is_refused_and_nothing_is_sent(
    tm_simulator_factory: SimFactory,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    section: str,
    key: str,
    value: str,
) -> None:
    sim = tm_simulator_factory("tmflow")
    sim.clear_request_log()
    config = tmp_path / "cell.toml"
    config.write_text(f"[{section}]\n{key} = {value}\n")

    code = main(["--host", "127.0.0.1", "--port", str(sim.port), "--config", str(config)])

    assert code == EXIT_CONFIG
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert f"{section}.{key}" in line
    assert str(config) in line
    assert sim.request_log == [], "a refused configuration must send nothing"


def test_a_switch_for_the_table_height_does_not_lower_the_table_guard(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A pick 60 mm up, under the default table top (85 mm): with `floor_z_mm = true`
    # taken as 1 mm the plan passed it.
    config = tmp_path / "cell.toml"
    config.write_text(
        "[workspace]\nfloor_z_mm = true\n[poses]\npick = [300, -200, 60, 180, 0, 90]\n"
    )

    assert main(["--config", str(config), "--dry-run"]) == EXIT_CONFIG
    assert "workspace.floor_z_mm" in capsys.readouterr().err
