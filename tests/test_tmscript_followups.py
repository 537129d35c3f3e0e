"""TMscript and the generated robot program: warnings said once, Display of a customized
function's array, no whitespace-only line in the program made for a named tool.

[TS] is *Programming Language TMscript* 2.24 (document 1.00).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

import pytest

from tmmaster._cli import main as tmmaster_main
from tmmaster._profiles import robot_profile
from tmmaster._robot_program import ToolSetting, robot_program
from tmmaster.sim import RobotSetup, Simulator
from tmmaster.sim._script_project import SCRIPT_ERROR
from tmmaster.tmscript import Execution, NullHost, parse

ARRAY_STORES = (
    "define\n{\n    int[] a = {1, 2, 3}\n}\nmain\n{\n"
    '    a[Length("\'") - 1] = 2\n    a[Length(foo) - 3]++\n    a[Length(bar) - 3] += 1\n'
    "    Display(a)\n}\n"
)


def test_a_warning_in_an_array_elements_index_is_given_once() -> None:
    # An element store compiled its array and index twice (once to store, once to read
    # for ++ and +=), and so gave each warning in the index twice.
    messages = [(w.line, w.column, w.message) for w in parse(ARRAY_STORES).warnings]
    assert len(messages) == len(set(messages)) == 3, messages


@pytest.mark.parametrize("command", ["run", "check"])
def test_tmscript_prints_each_warning_once(
    command: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    script = tmp_path / "w.tms"
    script.write_text(ARRAY_STORES, encoding="utf-8")
    assert tmmaster_main(["tmscript", command, str(script)]) == 0
    lines = [line for line in capsys.readouterr().err.splitlines() if ": warning: " in line]
    assert len(lines) == len(set(lines)) == 3, lines
    assert [line.split(":")[1:3] for line in lines] == [["7", "14"], ["8", "14"], ["9", "14"]]


def _shown(text: str) -> list[str]:
    shown: list[str] = []
    execution = Execution(parse(text), NullHost(on_display=shown.append, clock=lambda: 0.0))
    execution.run_to_end(timeout_s=5)
    assert execution.error is None, execution.error
    return shown


@pytest.mark.parametrize(
    ("typ", "value", "text"),
    [
        ("int", "{4, 5}", "{4,5}"),
        ("float", "{1.5, 10.0 / 3}", "{1.5,3.333333}"),
        ("string", '{"a", "b"}', "{a,b}"),
        ("bool", "{true}", "{true}"),
        ("byte", "{0x01, 255}", "{1,255}"),
    ],
)
def test_display_shows_a_functions_array_as_a_variables(typ: str, value: str, text: str) -> None:
    # Display() of an array shows it, "Display(var_array0) // {110,111,112,113,114}"
    # ([TS] §4.41, p. 132), and a customized function returns the type it defines
    # ([TS] §3.5, p. 32): its array is shown as the variable holding it is. The
    # simulator refused Display(F()) ("a int[] cannot be assigned to a string").
    program = (
        f"main\n{{\n    {typ}[] v = F()\n    Display(v)\n    Display(F())\n"
        f'    Display("Green", "Yellow", "F", F())\n}}\n{typ}[] F()\n{{\n    return {value}\n}}\n'
    )
    assert _shown(program) == [text, text, f"F: {text}"]


@pytest.mark.parametrize(
    "arguments",
    [
        ["--tool-name", "Gripper_2FG7"],
        ["--tool-name", "T", "--gripper", "none"],
        ["--tool", "0,0,150,0,0,0", "--tool-mass", "1.1"],
        ["--tool", "0,0,150,0,0,0", "--tool-mass", "1.1", "--gripper", "none"],
        ["--tool", "0,0,150,0,0,0", "--tool-mass", "1.1", "--tool-inertia", "1,2,3,0,0,0,0,0,0"],
    ],
)
def test_the_generated_program_has_no_whitespace_only_line_and_checks(
    arguments: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # With --tool-name the tool declares nothing: its template line was left as four spaces.
    out = tmp_path / "x.tms"
    assert tmmaster_main(["robot-program", *arguments, "-o", str(out)]) == 0
    lines = out.read_text(encoding="utf-8").splitlines()
    blank = [n for n, line in enumerate(lines, 1) if line != line.rstrip() or line.isspace()]
    assert blank == []
    capsys.readouterr()
    assert tmmaster_main(["tmscript", "check", str(out)]) == 0
    assert capsys.readouterr().err == ""


def test_a_program_for_a_named_tool_stops_in_the_simulator_saying_what_to_do(
    tm_simulator_factory: Callable[..., Simulator],
    tmp_path: Path,
    caplog: pytest.LogCaptureFixture,
) -> None:
    # The simulator knows no TMflow tool by name but RobotEndFlange: the program made with
    # --tool-name stops at its ChangeTCP with a script error, naming the tool and the way
    # to run it in the simulator (docs/simulator.md, the --tool row).
    program = tmp_path / "named.tms"
    tool = ToolSetting(name="Gripper_2FG7")
    program.write_text(robot_program(robot_profile("tmflow"), tool=tool), encoding="utf-8")
    with caplog.at_level(logging.WARNING, "tmmaster"):
        sim = tm_simulator_factory("tmflow", robot=RobotSetup(program=program))
        sim.wait_for(lambda: sim.field("last_error_code") == SCRIPT_ERROR, 5.0)
        sim.wait_for(lambda: "sim.program_error" in caplog.text, 5.0)
    assert "TCP 'Gripper_2FG7'" in caplog.text
    assert "--tool X,Y,Z,RX,RY,RZ --tool-mass KG" in caplog.text
