"""A switch of the pick & place configuration written as a number or as text is refused.

tests/test_hunt9_config_types.py made every number key refuse text and switches; the
switches themselves kept pydantic's lax reading (found by hunt 20, fails without its
fix): ``[poses] check_units = 0`` switched the metres-and-radians check off,
``[gripper] release_held_part_at_start = 1`` released a part held at the start where
the arm was, ``open_at_start = "no"`` kept the gripper shut. Each is now refused naming
its key, exit 2 from the command, before anything connects (a TOML sequence's own
switches: tests/test_hunt20_sequence_types.py).
"""

from __future__ import annotations

import datetime
from pathlib import Path
from typing import Any

import pytest

from tmmaster import ConfigError
from tmmaster.pickplace import validate_config
from tmmaster.pickplace.__main__ import EXIT_CONFIG, main


@pytest.mark.parametrize(
    ("section", "key", "value"),
    [
        ("poses", "check_units", 0),
        ("gripper", "release_held_part_at_start", 1),
        ("gripper", "open_at_start", "no"),
        ("gripper", "open_at_start", 1.0),
        ("poses", "check_units", datetime.date(1979, 5, 27)),  # a TOML date
    ],
)
def test_a_switch_written_as_a_number_or_text_is_refused_naming_it(
    section: str, key: str, value: Any
) -> None:
    with pytest.raises(ConfigError, match=rf"{section}\.{key}: must be true or false, got "):
        validate_config({section: {key: value}})
    assert getattr(getattr(validate_config({section: {key: False}}), section), key) is False


def test_the_command_refuses_it_with_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "cell.toml"
    config.write_text("[gripper]\nrelease_held_part_at_start = 1\n")
    assert main(["--dry-run", "--config", str(config)]) == EXIT_CONFIG
    assert "gripper.release_held_part_at_start: must be true or false" in capsys.readouterr().err
