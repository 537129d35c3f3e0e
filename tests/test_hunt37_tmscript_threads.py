"""Hunt 37: the robot program against Techman's manuals, statement by statement.

Threads of a Script Project run side by side: "there is no priority among threads in
execution, and each operates independently" ([TS] = *Programming Language TMscript*
2.24, document 1.00, §3.12 Thread, p. 47). The simulator's interpreter switches threads
only where a statement waits or a step's budget ends; these tests end a step of main
after each of its statements in turn, let the watchdog thread run a whole call in
between, and check what the program keeps then.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

import pytest

from tmmaster import Pose
from tmmaster._profiles import robot_profile
from tmmaster._robot_program import ToolSetting, robot_program
from tmmaster.tmscript import Execution, ModbusDevice, NullHost, parse

#: Two masters' sessions: S1 beat until S2 replaced it.
S1, S2 = 111, 222
#: The steps main is ended after: from before its second MasterGone() to after it.
SPLITS = range(1, 30)


def _function(text: str, signature: str) -> str:
    """The function ``signature`` of the program ``text``, from its line to its closing brace."""
    match = re.search(rf"^{re.escape(signature)}\n\{{\n.*?^\}}\n", text, re.M | re.S)
    assert match, signature
    return match.group(0)


def _program() -> str:
    return robot_program(
        robot_profile("tmflow"), tool=ToolSetting(tcp=Pose(0, 0, 100, 0, 0, 0), mass_kg=1.0)
    )


class _Slave(NullHost):
    """The robot's registers: 9050-9052 answer ``beats`` in turn (the last one for good)."""

    def __init__(self, beats: Sequence[tuple[int, int, int]]) -> None:
        super().__init__(on_display=self._show, clock=self._clock)
        self.beats = list(beats)
        self.shown: list[str] = []
        self.now = 0.0

    def _show(self, text: str) -> None:
        self.shown.append(text)

    def _clock(self) -> float:
        return self.now

    def modbus_request(
        self,
        device: ModbusDevice,
        function: int,
        address: int,
        count: int,
        values: Sequence[int] | None,
    ) -> list[int]:
        if address == 9050:
            return list(self.beats.pop(0) if len(self.beats) > 1 else self.beats[0])
        return [0] * count


def _race(beats: Sequence[tuple[int, int, int]], split: int) -> list[str]:
    """Main sees S1 beat, starts the watchdog's twin and reads the heartbeat again; its
    step ends after ``split`` statements, the twin reads it and runs a whole
    MasterGone(), then main goes on. What is shown after S1: whose call ended first
    ("main", "twin"), then former and master as main sees them at the end."""
    text = _program()
    define = _function(text, "define")
    body = (
        "main\n{\n"
        "    bool g = MasterGone()\n"
        '    Display("S1")\n'
        "    Sleep(1)\n"
        "    int t = ThreadRun(Twin(), true)\n"
        "    g = MasterGone()\n"
        '    Display("main")\n'
        "    Sleep(10)\n"
        '    Display(former + " " + master)\n'
        "}\n"
        'void Twin()\n{\n    bool h = MasterGone()\n    Display("twin")\n}\n'
    )
    functions = "".join(
        _function(text, f)
        for f in ("bool MasterGone()", "bool Silent(double now, double up)", "double UpTime()")
    )
    host = _Slave(beats)
    execution = Execution(parse(define + body + functions), host)
    execution.step(max_statements=10_000)  # to Sleep(1), once S1 beats
    assert host.shown == ["S1"]
    host.now += 1.0
    execution.step(max_statements=split)  # ThreadRun, then part of MasterGone
    execution.step(max_statements=10_000)  # the twin's whole call, then main's rest
    host.now += 1.0
    execution.step(max_statements=10_000)  # after Sleep(10)
    assert execution.error is None, execution.error
    return host.shown[1:]


@pytest.mark.parametrize("split", SPLITS)
def test_two_threads_that_see_a_new_session_keep_the_one_it_replaced(split: int) -> None:
    """[TS] §3.12, p. 47: the watchdog may run between any two statements of main."""
    # Main and the watchdog both read S2 after S1: whichever order their statements
    # take, S1 is the session replaced (former), S2 the master's. Before: main, paused
    # between its check that the session changed and `former = master`, wrote S2 as
    # the former once the watchdog had taken S2 for master; a late frame of S1 was then
    # taken for a new master's, and S1's held command could run.
    beats = [(10, 2000, S1), (1, 2000, S2)]
    assert _race(beats, split)[-1] == f"{S1} {S2}"


@pytest.mark.parametrize("split", SPLITS)
def test_an_older_reading_never_takes_the_robot_back_from_a_new_session(split: int) -> None:
    """[TS] §3.12, p. 47: the watchdog may run between any two statements of main."""
    # Main's second reading is S1's last beat, the watchdog's a moment later S2's first:
    # S2 is the master's whatever the order. Before: main, having found its (older)
    # reading of the same session as master, wrote master = S1 over the watchdog's S2.
    beats = [(10, 2000, S1), (11, 2000, S1), (1, 2000, S2)]
    assert _race(beats, split)[-1] == f"{S1} {S2}"


def test_the_splits_run_the_twin_before_main_s_call_and_after_it() -> None:
    # The sweep covers main's whole MasterGone(): at the first split the twin's call
    # ends first, at the last main's does (a longer MasterGone() needs more splits).
    beats = [(10, 2000, S1), (1, 2000, S2)]
    assert _race(beats, SPLITS[0])[:2] == ["twin", "main"]
    assert _race(beats, SPLITS[-1])[:2] == ["main", "twin"]
