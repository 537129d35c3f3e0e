"""Techman's error codes (TMflow 2.24 Appendix J): the data, the errors' messages, the CLI."""

from __future__ import annotations

import functools
import json
import re
import tomllib
from collections.abc import Callable
from importlib import resources
from pathlib import Path

import pytest

import tmmaster
from tmmaster import Pose, Robot
from tmmaster._exceptions import EmergencyStopError, RobotFaultError
from tmmaster._tm_errors import DATA_FILE, TMErrorCode, code_hex, describe, lookup_tm_error
from tmmaster.pickplace.__main__ import EXIT_ROBOT_FAULT, main
from tmmaster.sim import Simulator
from tmmaster.sim._controller import SimErrorCode

SimFactory = Callable[..., Simulator]

APPROACH = Pose(300, -200, 200, 180, 0, 90)
COLLISION = "0x0022 Force or Torque Over Range"
NOT_LISTED = "(not in TMflow 2.24 Appendix J)"


# -- the data --------------------------------------------------------------------------


@functools.cache
def tm_errors() -> dict[int, TMErrorCode]:
    """Every code of Appendix J: the whole data file parsed and validated, each code once."""
    text = resources.files("tmmaster").joinpath(DATA_FILE).read_text("utf-8")
    entries: dict[int, TMErrorCode] = {}
    for data in tomllib.loads(text)["error"]:
        entry = TMErrorCode.model_validate(data)
        assert entry.code not in entries, f"code {entry.hex} listed twice"
        entries[entry.code] = entry
    return entries


def test_every_entry_has_its_code_hex_text_and_page() -> None:
    entries = tm_errors()
    assert len(entries) > 3000  # the whole appendix, not a selection
    for code, entry in entries.items():
        assert entry.code == code
        assert entry.hex == f"0x{code:08X}"
        assert int(entry.hex, 16) == code
        assert entry.text.strip() == entry.text
        assert entry.text
        assert 349 <= entry.page <= 405  # the descriptions' pages
        assert entry.suggestion_page is None or 406 <= entry.suggestion_page <= 641
        assert (entry.what_to_do is None) == (entry.what_to_do_by is None)
        for text in (entry.text, entry.cause, entry.checks, entry.what_to_do):
            # no page furniture of the PDF and no entity left in the text
            assert text is None or not re.search(r"Software Manual TMflow|&#\d+;", text)


def test_the_codes_the_simulator_raises_read_as_the_manual_prints_them() -> None:
    payload = lookup_tm_error(SimErrorCode.OVER_PAYLOAD)
    collision = lookup_tm_error(SimErrorCode.COLLISION)
    assert payload is not None
    assert collision is not None
    assert (payload.label, payload.page, payload.suggestion_page) == (
        "0x000F Over Payload Limit",
        349,
        407,
    )
    assert (collision.label, collision.page, collision.suggestion_page) == (COLLISION, 349, 409)
    assert collision.checks is not None
    assert collision.checks.startswith("1. Check if the robot collides with anything.")
    assert collision.what_to_do_by == "manual"
    assert collision.what_to_do is not None
    assert "Trigger Robot Stick Reset button" in collision.what_to_do


def test_one_lookup_reads_what_the_whole_file_says() -> None:
    entries = tm_errors()
    for code, entry in entries.items():
        assert lookup_tm_error(code) == entry
    assert lookup_tm_error(0x1234) is None
    assert lookup_tm_error(-0x10000000) == entries[0xF0000000]  # an int32 read as signed


def test_our_hints_are_marked_and_never_replace_the_manuals() -> None:
    ours = [e for e in tm_errors().values() if e.what_to_do_by == "tmmaster"]
    assert ours
    assert all(e.code < 0x100 for e in ours)
    entry = lookup_tm_error(0x06)
    assert entry is not None
    assert "tmmaster's hint" in entry.hint()


def test_codes_are_shown_in_hex_with_their_meaning() -> None:
    assert code_hex(0x22) == "0x0022"
    assert code_hex(0x5F133) == "0x5F133"
    assert describe(0x22) == COLLISION
    assert describe(0x1234) == f"0x1234 {NOT_LISTED}"
    assert tmmaster.lookup_tm_error(0x22) == lookup_tm_error(0x22)
    assert isinstance(lookup_tm_error(0x22), tmmaster.TMErrorCode)


# -- the errors ------------------------------------------------------------------------


def test_a_fault_names_its_code_its_meaning_and_what_to_do() -> None:
    error = RobotFaultError("robot error", error_code=0x22)
    assert str(error).startswith(
        f"robot error: {COLLISION}; what to do (TMflow 2.24 manual p. 409)"
    )
    assert "Trigger Robot Stick Reset button" in str(error)
    assert error.code == error.error_code == 0x22
    assert error.tm_error == lookup_tm_error(0x22)


def test_an_unknown_code_says_the_manual_does_not_list_it() -> None:
    error = RobotFaultError("robot error", error_code=0x1234)
    assert str(error) == f"robot error: 0x1234 {NOT_LISTED}"
    assert error.code == 0x1234
    assert error.tm_error is None


def test_old_constructor_calls_keep_working() -> None:
    plain = RobotFaultError("the TMflow project is not running")
    assert str(plain) == "the TMflow project is not running"
    assert plain.code is None
    assert plain.tm_error is None
    assert plain.error_code == 0
    named = RobotFaultError(f"robot error {COLLISION}", error_code=0x22)
    assert str(named) == f"robot error {COLLISION}"  # named once, not twice
    estop = EmergencyStopError("emergency stop is pressed", error_code=0x52)
    assert str(estop).startswith("emergency stop is pressed: 0x0052 Robot performed Cat.1 stop.")
    assert estop.tm_error is not None
    assert estop.tm_error.page == 350


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_simulated_collision_code_reads_as_techmans_text(
    memory_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = memory_simulator_factory(profile, faults=["robot_error:at_move=1,code=0x22"])
    robot = robots(sim)
    with pytest.raises(RobotFaultError) as info:
        robot.move_to(APPROACH, speed=30, timeout=30)
    assert COLLISION in str(info.value)
    assert "what to do (TMflow 2.24 manual p. 409)" in str(info.value)
    assert info.value.code == 0x22
    assert info.value.tm_error == lookup_tm_error(0x22)


def test_a_simulated_stand_in_code_is_said_to_be_not_techmans(
    memory_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = memory_simulator_factory("tmflow", faults=["robot_error:at_move=1,code=0x1F4"])
    robot = robots(sim)
    with pytest.raises(RobotFaultError) as info:
        robot.move_to(APPROACH, speed=30, timeout=30)
    assert f"0x01F4 {NOT_LISTED}" in str(info.value)
    assert info.value.tm_error is None


# -- the command line ------------------------------------------------------------------


def test_pickplace_names_the_collision_in_its_line_and_report(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A block where the part is set down: the simulated arm meets it (TM's 0x22).
    scene = tmp_path / "cell.toml"
    scene.write_text(
        '[[fixtures]]\nname = "block"\npose = [300, 200, 165, 0, 0, 0]\nsize_mm = [80, 80, 160]\n'
    )
    report = tmp_path / "r.json"
    argv = ["--sim", "--sim-time-scale", "40", "--poll-interval", "0.02"]
    code = main([*argv, "--sim-scene", str(scene), "--report", str(report)])
    assert code == EXIT_ROBOT_FAULT
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert line.startswith("pickplace: ")
    assert COLLISION in line
    assert line.count("0x0022") == 1  # once: not again as "(robot error code 34)"
    error = json.loads(report.read_text())["error"]
    assert error["error_code"] == 0x22
    assert error["error_meaning"] == COLLISION
