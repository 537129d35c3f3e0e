"""What ``python -m tmmaster.pickplace`` prints around the run: quiet when piped, the events
with -v or --log-json, options that cannot be refused in one line, a robot speaking
another profile, and Ctrl-C: one line and exit 130, whatever the moment and however many.

The Ctrl-C tests run the real entry point (a signal is the subject); the others call
``main()`` in-process. No assertion depends on a duration.
"""

from __future__ import annotations

import io
import json
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

import tmmaster
from tmmaster.pickplace.__main__ import EXIT_CONFIG, EXIT_INTERRUPTED, EXIT_OK, main
from tmmaster.pickplace._runner import StateEvent
from tmmaster.sim import Simulator

#: A quick --sim run (simulated time 40x faster, 20 ms polling).
SIM = ["--sim", "--sim-time-scale", "40", "--poll-interval", "0.02"]
#: A run that lasts: 50 cycles in real time (the Ctrl-C tests end it).
SLOW = ["--sim", "--sim-time-scale", "10", "--cycles", "50"]
#: One control sequence (CSI) of a terminal.
CSI = re.compile(r"\x1b\[([0-9;?]*)([A-Za-z])")

SimFactory = Callable[..., Simulator]


def _env(columns: int = 60) -> dict[str, str]:
    env = dict(os.environ)
    # The tmmaster this test imported (the working tree's src, or another checkout's).
    src = str(Path(tmmaster.__file__).resolve().parents[1])
    env["PYTHONPATH"] = src + os.pathsep + env.get("PYTHONPATH", "")
    env["COLUMNS"] = str(columns)
    env.pop("NO_COLOR", None)
    return env


def _screen(raw: str) -> list[str]:
    """What a terminal shows after ``raw``: its lines, once the carriage returns, cursor
    moves and erasures (all the live display uses) are applied; trailing blanks dropped."""
    lines: list[list[str]] = [[]]
    row = col = 0
    i = 0
    while i < len(raw):
        match = CSI.match(raw, i)
        if match:
            arg, command = match.groups()
            count = int(arg) if arg.isdigit() else 1
            if command == "A":
                row = max(row - count, 0)
            elif command == "B":
                row += count
            elif command == "K":  # erase in line: 2 all of it, else from the cursor
                lines[row] = [] if arg == "2" else lines[row][:col]
            i = match.end()
            continue
        char = raw[i]
        i += 1
        if char == "\r":
            col = 0
        elif char == "\n":
            row, col = row + 1, 0
        elif char == "\x1b" or not char.isprintable():
            continue
        else:
            line = lines[row]
            line.extend(" " * (col + 1 - len(line)))
            line[col] = char
            col += 1
        while len(lines) <= row:
            lines.append([])
    text = ["".join(line).rstrip() for line in lines]
    while text and not text[-1]:
        text.pop()
    return text


def test_the_terminal_emulation_applies_erasures() -> None:
    raw = "a\nlive 1\nlast\x1b[2K\x1b[1A\x1b[2K\rdone\n"
    assert _screen(raw) == ["a", "done"]


def test_a_ctrl_c_landing_inside_a_redraw_leaves_only_the_last_line(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A second Ctrl-C's KeyboardInterrupt lands wherever the main thread is; here inside
    # rich's redraw, as the console leaves its buffer (found by raising it at each line
    # of a redraw in turn). It left the console holding back all it wrote from then on:
    # the region stayed on the screen above the last line. Ctrl-C waits for the drawing.
    from rich.console import Console

    from tmmaster.pickplace._live import LiveProgress

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    def event(state: str, previous: str) -> StateEvent:
        return StateEvent(state, previous, 1, 50, 0.1)

    screen = Terminal()
    screen.write("simulator: tmflow profile\n")
    console = Console(file=screen, force_terminal=True, width=60, height=30)
    live = LiveProgress(console, refresh_per_second=0.01)  # no redraw but the runner's
    live.begin(50, 3.0, states=["MOVE_TO_APPROACH", "MOVE_TO_PICK"])
    live(event("MOVE_TO_APPROACH", "STARTING"))
    leave = Console.__exit__

    def ctrl_c_then_leave(self: Console, *exc: object) -> None:
        monkeypatch.setattr(Console, "__exit__", leave)  # once
        signal.raise_signal(signal.SIGINT)
        leave(self, *exc)

    monkeypatch.setattr(Console, "__exit__", ctrl_c_then_leave)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):  # delivered, after the drawing
            live(event("MOVE_TO_PICK", "MOVE_TO_APPROACH"))
    finally:
        signal.signal(signal.SIGINT, previous)
    live.end()
    screen.write("pickplace: interrupted [exit 130]\n")
    shown = [line for line in _screen(screen.getvalue()) if line.strip()]
    assert shown == ["simulator: tmflow profile", "pickplace: interrupted [exit 130]"]


# -- Ctrl-C ---------------------------------------------------------------------------------


def _run_on_a_terminal(
    ctrl_c: Callable[[subprocess.Popen[bytes]], None],
    command: tuple[str, ...] = ("tmmaster.pickplace",),
) -> tuple[int, str]:
    """Run a long --sim run on a pseudo-terminal (stdout and stderr), wait until the live
    display shows the first move, call ``ctrl_c``; return the exit status and all it printed.

    ``command``: what ``python -m`` runs (the module, or ``tmmaster pickplace``)."""
    import fcntl
    import pty
    import select
    import struct
    import termios

    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 30, 60, 0, 0))
    proc = subprocess.Popen(
        [sys.executable, "-m", *command, *SLOW],
        stdin=subprocess.DEVNULL,
        stdout=slave,
        stderr=slave,
        env=_env(),
    )
    os.close(slave)
    raw = b""
    signalled = False
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([master], [], [], 0.005)
            if ready:
                try:
                    chunk = os.read(master, 65536)
                except OSError:  # the child closed the terminal
                    break
                if not chunk:
                    break
                raw += chunk
            if not signalled and b"MOVE_TO_APPROACH" in raw:
                signalled = True
                ctrl_c(proc)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(master)
    assert signalled, raw.decode(errors="replace")[-2000:]
    return proc.returncode, raw.decode(errors="replace")


def test_one_ctrl_c_on_a_terminal_ends_with_one_line() -> None:
    code, raw = _run_on_a_terminal(lambda proc: proc.send_signal(signal.SIGINT))
    assert code == EXIT_INTERRUPTED, raw[-2000:]
    shown = [line for line in _screen(raw) if line.strip()]
    # What stays on the screen: the simulator's address, then why it ended, at the start of
    # a line of its own (the live region is gone, never glued to it); no summary table, no
    # warnings about the stop the user asked for.
    assert shown[0].startswith("simulator: tmflow profile on 127.0.0.1:"), shown
    (last,) = shown[1:]
    assert re.fullmatch(
        r"pickplace: interrupted in \w+ \(cycle 1\); the arm was stopped \[exit 130\]", last
    ), shown


@pytest.mark.parametrize(
    "command", [("tmmaster.pickplace",), ("tmmaster", "pickplace")], ids=["module", "tmmaster"]
)
def test_ctrl_c_pressed_again_and_again_still_exits_130_in_one_line(
    command: tuple[str, ...],
) -> None:
    def keep_pressing(proc: subprocess.Popen[bytes]) -> None:
        # Every 2 ms until the process is gone: some land while the last line is printed,
        # some while the interpreter exits.
        for _ in range(10_000):
            if proc.poll() is not None:
                return
            try:
                proc.send_signal(signal.SIGINT)
            except ProcessLookupError:
                return
            time.sleep(0.002)

    code, raw = _run_on_a_terminal(keep_pressing, command)
    assert code == EXIT_INTERRUPTED, raw[-2000:]  # never -2: killed by the signal
    shown = [line for line in _screen(raw) if line.strip()]
    assert "Traceback" not in raw
    assert len(shown) == 2, shown
    assert re.fullmatch(r"pickplace: interrupted.* \[exit 130\]", shown[1]), shown


def test_ctrl_c_when_piped_is_one_line_on_stderr_and_nothing_more_on_stdout(
    tmp_path: Path,
) -> None:
    report = tmp_path / "run.json"
    rep = str(report)
    proc = subprocess.Popen(
        [sys.executable, "-m", "tmmaster.pickplace", *SIM, "--cycles", "50", "--report", rep],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=_env(),
    )
    try:
        # Piped, the run prints nothing until it ends: interrupt it once it is connected.
        deadline = time.monotonic() + 30
        while not _connected(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.02)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == EXIT_INTERRUPTED, err
    assert out == b""
    (line,) = err.decode().splitlines()
    assert line.startswith("pickplace: interrupted")
    assert line.endswith("[exit 130]")
    assert json.loads(report.read_text())["result"] == "interrupted"


def _connected(pid: int) -> bool:
    """True once the process holds three sockets: its simulator's listening one, and both
    ends of the robot's connection to it."""
    sockets = 0
    try:
        for fd in os.listdir(f"/proc/{pid}/fd"):
            sockets += os.readlink(f"/proc/{pid}/fd/{fd}").startswith("socket:")
    except OSError:  # not Linux, or a descriptor closed meanwhile: look again
        return False
    return sockets >= 3


# -- piped, -v, --log-json -------------------------------------------------------------------


class _Terminal(io.StringIO):
    """A captured stderr that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def test_log_json_on_a_terminal_logs_every_event_as_json(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    stderr = _Terminal()
    monkeypatch.setattr(sys, "stderr", stderr)
    assert main([*SIM, "--log-json"]) == EXIT_OK
    events = [json.loads(line) for line in stderr.getvalue().splitlines()]
    names = {e["event"] for e in events}
    assert {"pickplace.run_started", "pickplace.state", "robot.command_done"} <= names
    assert "\x1b" not in stderr.getvalue()  # no live display, no colours
    assert capsys.readouterr().out.splitlines()[-1].startswith("DONE: 1/1")


def test_verbose_logs_the_events_when_piped(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*SIM, "-v"]) == EXIT_OK
    out, err = capsys.readouterr()
    assert "pickplace.state" in err
    assert "robot.command_done" in err
    assert "robot.command_sent" in err
    assert out.startswith("simulator: tmflow profile on 127.0.0.1:")


# -- options that cannot be -----------------------------------------------------------------


def test_a_mistyped_profile_is_one_line_naming_the_option_and_the_profiles(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["--profile", "tmfow", "--sim"]) == EXIT_CONFIG
    out, err = capsys.readouterr()
    assert out == ""
    assert err.splitlines() == [
        "pickplace: --profile tmfow: no such profile; the robot profiles are article, tmflow"
        " (or a profile FILE.toml); did you mean tmflow? [exit 2]"
    ]
    assert main(["--profile", "blog-2fg7", "--dry-run"]) == EXIT_CONFIG
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("pickplace: --profile blog-2fg7: a gripper profile; the robot")


def test_host_or_port_with_sim_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    # Refused before anything starts: no simulator, no connection (a reserved address).
    assert main(["--sim", "--host", "192.0.2.10"]) == EXIT_CONFIG
    assert main(["--sim", "--host", "192.0.2.10", "--port", "1502"]) == EXIT_CONFIG
    out, err = capsys.readouterr()
    assert out == ""
    first, second = err.splitlines()
    assert first.startswith("pickplace: --host cannot be used with --sim, which runs on its own")
    assert first.endswith("[exit 2]")
    assert second.startswith("pickplace: --host and --port cannot be used with --sim")


@pytest.mark.parametrize(("cli", "device"), [("article", "tmflow"), ("tmflow", "article")])
def test_a_robot_speaking_another_profile_is_a_config_error_in_one_line(
    tm_simulator_factory: SimFactory,
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    cli: str,
    device: str,
) -> None:
    sim = tm_simulator_factory(device)
    report = tmp_path / "run.json"
    argv = ["--host", "127.0.0.1", "--port", str(sim.port), "--profile", cli]
    assert main([*argv, "--report", str(report)]) == EXIT_CONFIG
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if " sim." not in line]
    (line,) = lines
    assert line.startswith("pickplace: wrong profile: ")
    assert f"the device answers the '{device}' profile's status registers" in line
    assert line.endswith(f"run with --profile {device} [exit 2]")
    assert line.count("Modbus exception code") == 1
    assert json.loads(report.read_text())["result"] == "config_error"
    assert sim.motion_log() == ()  # nothing moved


def test_the_plain_run_piped_prints_its_result_only(capsys: pytest.CaptureFixture[str]) -> None:
    # Piped (a log collector, CI): warnings and the result, not the run's events.
    assert main(SIM) == EXIT_OK
    out, err = capsys.readouterr()
    assert err == ""
    placed, done = out.splitlines()
    assert placed.startswith("simulator: part-1 is on the place position")
    assert done.startswith("DONE: 1/1 cycle(s) of pick-and-place")
