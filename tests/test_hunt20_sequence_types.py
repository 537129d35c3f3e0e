"""A TOML sequence's number or switch written as text or as the other kind is refused.

docs/pickplace.md: a wrong type is reported with its key and the file, exit 2, nothing
sent (``port = "502"``, ``floor_z_mm = true`` in the configuration:
tests/test_hunt9_config_types.py). The sequence file's own keys took pydantic's lax
coercion (found by hunt 20, fails without its fix): ``z_offset = true`` moved the arm
1 mm above the pose, ``z_offset = "100"`` 100 mm, ``retries = true`` allowed a retry,
``cycles = "3"`` ran three cycles, ``seconds = "1"`` dwelt, ``holding = 1`` required a
part, and ``check_units = 0`` switched the metres-and-radians check off. Each is now
refused naming its key; the speeds were strict already (guarded once).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from tmmaster import ConfigError
from tmmaster.pickplace import sequence_from_data
from tmmaster.pickplace.__main__ import EXIT_CONFIG, main

MOVE = {"do": "move", "pose": [300, -200, 200, 180, 0, 90], "speed": 30}
GRIP = {"state": "G", "do": "grip", "retry_from": "G"}

CASES: list[tuple[dict[str, Any], dict[str, Any], str]] = [
    ({}, {**MOVE, "z_offset": True}, "steps.0.move.z_offset"),
    ({}, {**MOVE, "z_offset": "100"}, "steps.0.move.z_offset"),
    ({}, {**GRIP, "retries": True}, "steps.0.grip.retries"),
    ({}, {**GRIP, "retries": "2"}, "steps.0.grip.retries"),
    ({}, {"do": "wait", "seconds": "1"}, "steps.0.wait.seconds"),
    ({}, {"do": "wait", "seconds": True}, "steps.0.wait.seconds"),
    ({}, {"do": "check", "holding": 1}, "steps.0.check.holding"),
    ({}, {"do": "check", "holding": "no"}, "steps.0.check.holding"),
    ({"cycles": "3"}, MOVE, "cycles"),
    ({"cycles": True}, MOVE, "cycles"),
    ({"open_at_start": "yes"}, MOVE, "open_at_start"),
    ({"check_units": 0}, MOVE, "check_units"),
    ({}, {**MOVE, "speed": True}, "steps.0.move.speed"),  # strict already
]


@pytest.mark.parametrize(("top", "step", "key"), CASES)
def test_a_sequence_key_of_the_wrong_kind_is_refused_naming_it(
    top: dict[str, Any], step: dict[str, Any], key: str
) -> None:
    with pytest.raises(ConfigError, match="seq.toml: " + re.escape(key) + ": "):
        sequence_from_data({"name": "s", **top, "steps": [step]}, source="seq.toml")


def test_the_command_refuses_it_with_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "s.toml"
    path.write_text(
        'name = "s"\n[[steps]]\ndo = "move"\npose = [300, -200, 200, 180, 0, 90]\n'
        "speed = 30\nz_offset = true\n"
    )
    assert main(["--dry-run", "--sequence", str(path)]) == EXIT_CONFIG
    assert "steps.0.move.z_offset" in capsys.readouterr().err
