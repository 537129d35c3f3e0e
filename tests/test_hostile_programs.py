"""Hostile robot programs and scripts: each ends in a clean error, never a dead simulator.

A control tick that raises stops the robot in error (registers and a log line say so);
a string that doubles meets the string cap; slow statements yield on the tick's time
budget, so the Modbus server keeps answering and SIGTERM ends the simulator; ``--timeout``
holds whatever the script does; a long or deeply nested expression is a syntax error
naming line and column instead of a RecursionError.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from test_sim_controller import controller_class, controller_for
from tmmaster import ModbusTransport, RetryPolicy, TMScriptSyntaxError
from tmmaster._profiles import robot_profile
from tmmaster._robot_models import robot_model
from tmmaster.sim import RobotSetup, Simulator, Timing
from tmmaster.sim.__main__ import STOP_WITHIN_S
from tmmaster.sim._controller import RobotController, SimErrorCode
from tmmaster.sim._kinematic import KinematicBackend
from tmmaster.tmscript import ExecState, Execution, NullHost, parse
from tmmaster.tmscript.__main__ import main as tmscript_main
from tmmaster.tmscript._evaluator import TIMEOUT_CLOSESTOP_S
from tmmaster.tmscript._parser import MAX_NESTING
from tmmaster.tmscript._types import STRING_MAX

MODEL = robot_model("tm5-700")
DT = 0.02

#: Builds 2048 strings of ``length`` characters that differ only at their end, then sorts
#: them forever: each Array_Sort compares long common prefixes (milliseconds per
#: statement, tens of milliseconds at the cap), well within every cap.
SORTING = """main {{
  string p = "x"
  while (Length(p) < {half}) {{
    p = p + p
  }}
  p = p + String_Substring(p, 0, {rest})
  string[] a = {{}}
  int i = 0
  while (i < 2048) {{
    a = Array_Append(a, p + i)
    i++
  }}
  Display("sorting")
  string[] b = {{}}
  while (true) {{
    b = Array_Sort(a)
  }}
}}
"""


def sorting(length: int) -> str:
    """The sorting program with strings of about ``length`` characters (at most 64 Ki)."""
    half = 1 << (length.bit_length() - 1)
    return SORTING.format(half=half, rest=length - half)


class Log:
    """A structlog-style logger that keeps every event with its level."""

    def __init__(self) -> None:
        self.events: list[tuple[str, str, dict[str, Any]]] = []

    def info(self, event: str, **kw: Any) -> None:
        self.events.append(("info", event, kw))

    def warning(self, event: str, **kw: Any) -> None:
        self.events.append(("warning", event, kw))

    def error(self, event: str, **kw: Any) -> None:
        self.events.append(("error", event, kw))


class BombBackend(KinematicBackend):
    """The kinematic backend; ``armed``, its next step raises MemoryError (once)."""

    def __init__(self) -> None:
        super().__init__(MODEL)
        self.armed = False

    def step(self, dt: float) -> None:
        if self.armed:
            self.armed = False
            raise MemoryError
        super().step(dt)


def controller(profile: str, backend: KinematicBackend, log: Log) -> RobotController:
    regs = robot_profile(profile)
    bank = controller_class(regs.handshake).bank_for(regs)
    return controller_for(regs, bank, backend, MODEL, init_time_s=0.1, log=log)


def ticks(ctl: RobotController, seconds: float) -> None:
    for _ in range(round(seconds / DT)):
        ctl.tick(DT)


# -- a control tick that raises ---------------------------------------------------------


@pytest.mark.parametrize(
    ("profile", "code_field"), [("tmflow", "last_error_code"), ("article", "error_code")]
)
def test_a_tick_that_raises_stops_the_robot_in_error_with_one_log_line(
    profile: str, code_field: str
) -> None:
    backend, log = BombBackend(), Log()
    ctl = controller(profile, backend, log)
    ticks(ctl, 0.5)
    assert ctl.project_running
    backend.armed = True
    ctl.tick(DT)  # the MemoryError stays inside the tick
    assert ctl.error_code == SimErrorCode.TICK_FAILED
    assert int(SimErrorCode.TICK_FAILED) == 0x0108
    assert ctl.bank.get(code_field) == SimErrorCode.TICK_FAILED
    assert ctl.state == "error"
    if profile == "tmflow":
        assert not ctl.project_running
        assert ctl.bank.get("error")
        assert not ctl.bank.get("project_running")
    failed = [kw for _, event, kw in log.events if event == "sim.tick_failed"]
    assert [kw["error"] for kw in failed] == ["MemoryError"]
    assert ("error", "sim.tick_failed") in [(level, event) for level, event, _ in log.events]
    # The registers live on: the next ticks publish the clock and the pose again.
    if profile == "tmflow":
        up = ctl.bank.get("up_seconds")
        ticks(ctl, 1.0)
        assert ctl.bank.get("up_seconds") == up + 1
    backend.armed = True
    ctl.tick(DT)  # failing again before the operator's reset: logged once
    assert [event for _, event, _ in log.events].count("sim.tick_failed") == 1
    ctl.clear_error()
    assert ctl.state != "error"


def test_a_simulator_whose_tick_raises_keeps_serving_registers_in_error(
    tm_simulator_factory: Any,
) -> None:
    backend = BombBackend()
    sim: Simulator = tm_simulator_factory(cell=backend, time_scale=1.0)
    sim.wait_for(lambda: bool(sim.field("project_running")))
    backend.armed = True
    sim.wait_for(lambda: bool(sim.field("error")))
    assert sim.field("last_error_code") == SimErrorCode.TICK_FAILED
    assert not sim.field("project_running")
    ticked = sim.ticks
    sim.wait_for(lambda: sim.ticks > ticked + 5)  # the tick goes on: no frozen registers
    regs = robot_profile("tmflow")
    with ModbusTransport(
        "127.0.0.1", sim.port, timeout=1.0, retry=RetryPolicy(attempts=1), name="hostile"
    ) as link:
        running = regs.field("project_running")
        assert link.read_block(running.table, running.address, 1, retry=False) == [0]


# -- the interpreter's own failures -----------------------------------------------------


class BrokenClock(NullHost):
    """A host whose clock raises MemoryError once, when ``broken``."""

    def __init__(self) -> None:
        super().__init__()
        self.broken = False
        self.shown: list[str] = []

    def now_s(self) -> float:
        if self.broken:
            self.broken = False
            raise MemoryError
        return 0.0

    def display(self, text: str) -> None:
        self.shown.append(text)


def test_out_of_memory_inside_a_script_is_a_runtime_error_that_runs_errorstop() -> None:
    host = BrokenClock()
    text = 'main {\n  WaitFor(false, 1000)\n}\nerrorstop {\n  Display("errorstop")\n}\n'
    ex = Execution(parse(text), host)
    assert ex.step(100).state == ExecState.BLOCKED
    host.broken = True
    status = ex.step(100)  # WaitFor reads the clock: MemoryError
    assert status.state == ExecState.ERROR
    assert status.error is not None
    assert status.error.reason == "out of memory"
    assert host.shown == ["errorstop"]


# -- strings are capped -----------------------------------------------------------------

DOUBLING = """main {
  string s = "x"
  while (Length(s) < 2097152) {
    s = s + s
  }
  Display(Length(s))
}
"""


def test_a_string_doubling_program_ends_with_an_error_at_the_cap() -> None:
    shown: list[str] = []
    ex = Execution(parse(DOUBLING), NullHost(on_display=shown.append))
    assert ex.run_to_end(timeout_s=5) == ExecState.ERROR
    assert ex.error is not None
    assert (ex.error.line, ex.error.column) == (4, 11)
    assert ex.error.reason == (
        f"a string holds at most {STRING_MAX} characters, not {2 * STRING_MAX}"
    )
    assert shown == []


@pytest.mark.parametrize(
    ("setup", "statement", "column"),
    [
        # A replacement that multiplies the text: refused before it is built.
        ("", 'String_Replace(s, "x", s)', 7),
        # Display() of a string array whose text would be over the cap.
        ("string[] a = {s, s}", "Display(a)", 15),
    ],
)
def test_builtins_cannot_build_a_string_over_the_cap(
    setup: str, statement: str, column: int
) -> None:
    text = (
        f'main {{\n  string s = "x"\n  while (Length(s) < {STRING_MAX // 2}) {{\n    s = s + s\n'
        f"  }}\n  {setup}\n  {statement}\n}}\n"
    )
    ex = Execution(parse(text), NullHost(on_display=lambda line: None))
    assert ex.run_to_end(timeout_s=5) == ExecState.ERROR
    assert ex.error is not None
    assert ex.error.line == 7
    assert f"a string holds at most {STRING_MAX} characters" in ex.error.reason


def test_a_string_constant_over_the_cap_is_a_syntax_error() -> None:
    text = 'main {\n  string s = "' + "x" * (STRING_MAX + 1) + '"\n}\n'
    with pytest.raises(TMScriptSyntaxError, match="at most 65536 characters") as caught:
        parse(text)
    assert (caught.value.line, caught.value.column) == (2, 14)


# -- the time budget --------------------------------------------------------------------


def test_a_step_with_a_time_budget_yields_when_it_is_spent() -> None:
    shown: list[str] = []
    ex = Execution(
        parse('main {\n  while (true) {\n    Display("x")\n  }\n}\n'),
        NullHost(on_display=shown.append),
    )
    for _ in range(4):
        # No time at all: each step still goes on by one statement, never more.
        assert ex.step(1_000_000, max_seconds=0.0).state == ExecState.RUNNING
    assert 1 <= len(shown) <= 2
    assert ex.step(1000).state == ExecState.RUNNING
    assert len(shown) >= 500  # without a time budget, statements only


#: The simulator thread's CPU seconds a read may span under the slow program. A read
#: spans about five control ticks (the server's loop turns, a tick in each), each its
#: 20 ms budget plus the statement then running: 0.2-0.45 s measured, quiet or beside
#: eight CPU hogs alike. Without the tick's budget each of those ticks is 400
#: statements: 9-15 s a read. CPU time, not wall time: a loaded machine stretches a
#: read's wall time (past 3 s in 9 of 10 runs beside eight hogs), not the work in it.
READ_CPU_S = 2.0
#: How long a read may take at all, in wall seconds: "never answered".
ANSWER_WITHIN_S = 60.0


def read_running(port: int, reads: int, clock: int) -> list[tuple[int, float]]:
    """``reads`` reads of project_running: each value, and the CPU seconds of ``clock``
    (the simulator thread's) from its request sent to its answer back."""
    field = robot_profile("tmflow").field("project_running")
    out: list[tuple[int, float]] = []
    with ModbusTransport(
        "127.0.0.1",
        port,
        timeout=ANSWER_WITHIN_S,
        retry=RetryPolicy(attempts=1),
        name="hostile",
    ) as link:
        for _ in range(reads):
            spent = time.clock_gettime(clock)
            [value] = link.read_block(field.table, field.address, 1, retry=False)
            out.append((value, time.clock_gettime(clock) - spent))
    return out


def test_the_modbus_server_answers_while_a_program_runs_slow_statements(
    tm_simulator_factory: Any, tmp_path: Path
) -> None:
    program = tmp_path / "sorting.script"
    program.write_text(sorting(32768), encoding="utf-8")
    sim: Simulator = tm_simulator_factory(
        robot=RobotSetup(program=program), time_scale=1.0, timing=Timing(tick_hz=50)
    )
    clock = time.pthread_getcpuclockid(sim.call(threading.get_ident))  # before it sorts
    sim.wait_for(lambda: "sorting" in sim.displayed(), timeout=20)
    # Each Array_Sort takes milliseconds: 400 of them were one tick of seconds, during
    # which no request was answered. The tick's CPU-time budget yields after 20 ms.
    reads = read_running(sim.port, 5, clock)
    assert [value for value, _ in reads] == [1] * 5
    assert max(cpu_s for _, cpu_s in reads) < READ_CPU_S, reads


def test_sigterm_ends_the_simulator_under_a_slow_program(tmp_path: Path) -> None:
    program = tmp_path / "sorting.script"
    program.write_text(sorting(STRING_MAX - 8), encoding="utf-8")
    proc = subprocess.Popen(
        [sys.executable, "-m", "tmmaster.sim", "--port", "0", "--program", str(program)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stderr is not None
        deadline = time.monotonic() + 30
        line = ""
        while "text=sorting" not in line:  # the program sorts: slow statements from now
            assert time.monotonic() < deadline, "the program never started sorting"
            line = proc.stderr.readline()
        proc.send_signal(signal.SIGTERM)
        # Each Array_Sort of 64 Ki-character strings takes tens of milliseconds: 400
        # made a tick of over ten seconds, and the stop waited for it.
        out, err = proc.communicate(timeout=STOP_WITHIN_S + 2)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert "simulator stopped" in out


# -- tmscript run --timeout -------------------------------------------------------------

#: Slow statements (a String_Replace building 32 Ki characters: about 0.1 ms) in main and
#: in closestop.
SLOW_TO_STOP = """main {
  string s = "x"
  while (Length(s) < 16384) {
    s = s + s
  }
  string t = ""
  while (true) {
    t = String_Replace(s, "x", "yz")
  }
}
closestop {
  string u = "x"
  while (Length(u) < 16384) {
    u = u + u
  }
  string v = ""
  while (true) {
    v = String_Replace(u, "x", "yz")
  }
}
"""


def test_tmscript_run_keeps_its_timeout_whatever_the_script_does(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    script = tmp_path / "slow.script"
    script.write_text(SLOW_TO_STOP, encoding="utf-8")
    started = time.monotonic()
    assert tmscript_main(["run", "--timeout", "0.1", str(script)]) == 1
    elapsed = time.monotonic() - started
    # 10,000 statements ran between two looks at the clock, then closestop 100,000 more:
    # tens of seconds past the timeout.
    assert elapsed < 0.1 + TIMEOUT_CLOSESTOP_S + 2.0
    assert capsys.readouterr().err.splitlines() == [f"{script}: the script ran longer than 0.1 s"]


def test_tmscript_run_of_a_string_doubling_program_is_one_line_and_exit_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    script = tmp_path / "doubling.script"
    script.write_text(DOUBLING, encoding="utf-8")
    assert tmscript_main(["run", "--timeout", "5", str(script)]) == 1
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.splitlines() == [
        f"{script}:4:11: a string holds at most {STRING_MAX} characters, not {2 * STRING_MAX}"
    ]


# -- nesting ----------------------------------------------------------------------------


def nested(expression: str) -> str:
    return f"int f(int a) {{\n  return a\n}}\nmain {{\n  int x = {expression}\n  Display(x)\n}}\n"


DEEP = [
    pytest.param("+".join(["1"] * 1000), id="a long sum"),
    pytest.param("~" * 1000 + "1", id="deep unary"),
    pytest.param("f(" * 500 + "1" + ")" * 500, id="nested calls"),
]


@pytest.mark.parametrize("expression", DEEP)
def test_a_long_or_deeply_nested_expression_is_a_syntax_error(
    expression: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = nested(expression)
    with pytest.raises(TMScriptSyntaxError, match=f"more than {MAX_NESTING} levels") as caught:
        parse(text)
    assert caught.value.line == 5
    assert caught.value.column > 1
    script = tmp_path / "deep.script"
    script.write_text(text, encoding="utf-8")
    assert tmscript_main(["check", str(script)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"{script}:5:"), err
    assert tmscript_main(["eval", expression]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1, err
    assert f"more than {MAX_NESTING} levels" in err[0], err


def test_nesting_below_the_limit_still_runs() -> None:
    shown: list[str] = []
    count = MAX_NESTING - 20
    for expression in ("+".join(["f(1)"] * count), "f(" * (count // 2) + "1" + ")" * (count // 2)):
        ex = Execution(parse(nested(expression)), NullHost(on_display=shown.append))
        assert ex.run_to_end(timeout_s=5) == ExecState.ENDED, ex.error
    assert shown == [str(count), "1"]
