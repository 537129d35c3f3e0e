"""Ctrl-C as a command starts or while the interpreter exits: one line or nothing, never
a traceback; a Ctrl-C never cuts an exit hook (a robot's withdraw or stop) short; and
importing tmmaster changes no signal handler.

Each command runs in a child process that pauses at the point under test (the test hook
``TMMASTER_TEST_SIGINT_AT``: it says so on stderr and waits for a byte on stdin), so the
Ctrl-Cs arrive exactly there: an event, not a guessed delay.
"""

from __future__ import annotations

import contextlib
import errno
import io
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path
from types import FrameType

import pytest

import tmmaster

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")

#: The commands: ``python -m MODULE`` and the console script.
COMMANDS = {
    "sim": [sys.executable, "-m", "tmmaster.sim", "--help"],
    "pickplace": [sys.executable, "-m", "tmmaster.pickplace", "--help"],
    "report": [sys.executable, "-m", "tmmaster.report", "--help"],
    "tmscript": [sys.executable, "-m", "tmmaster.tmscript", "--help"],
    "tmmaster": [sys.executable, "-m", "tmmaster", "--help"],
    "console script": [str(Path(sys.executable).with_name("tmmaster")), "--help"],
}

#: The name each command's messages start with.
PROGS = {"console script": "tmmaster"}


def _paused(
    command: list[str], point: str, signals: int, signum: int = signal.SIGINT
) -> tuple[int, str]:
    """Run ``command`` paused at ``point``, send ``signals`` Ctrl-Cs (or ``signum``)
    there, let it go on."""
    code, err, _ = _paused_with_output(command, point, signals, signum)
    return code, err


def _paused_with_output(
    command: list[str], point: str, signals: int, signum: int = signal.SIGINT
) -> tuple[int, str, str]:
    """:func:`_paused`, with what the command wrote on stdout too (its status, stderr,
    stdout)."""
    env = {**os.environ, "TMMASTER_TEST_SIGINT_AT": point}
    proc = subprocess.Popen(
        command,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
    )
    assert proc.stdin is not None
    assert proc.stdout is not None
    assert proc.stderr is not None
    try:
        seen = proc.stderr.readline().decode()
        assert seen == f"tmmaster-test: paused at {point}\n", seen
        for _ in range(signals):
            proc.send_signal(signum)
        with contextlib.suppress(BrokenPipeError):
            proc.stdin.write(b"x")  # let it go on (it may have exited already)
            proc.stdin.flush()
        err = proc.stderr.read().decode()
        out = proc.stdout.read().decode()
        return proc.wait(timeout=30), err, out
    finally:
        proc.kill()
        proc.wait()
        with contextlib.suppress(BrokenPipeError):
            proc.stdin.close()
        proc.stdout.close()
        proc.stderr.close()


#: The commands whose Ctrl-C in the exit hooks is checked here, after ``--version`` (the
#: process's answer to it is checked too: test_public_api checks each command's main()
#: in this process). The simulator's and pick & place's are checked at the end of their
#: own process tests, after a run (test_sim_server, test_pickplace: one interpreter start
#: each, not two).
AT_EXIT = [name for name in COMMANDS if name not in ("sim", "pickplace")]


@pytest.mark.parametrize("name", AT_EXIT)
def test_ctrl_c_during_the_exit_hooks_is_quiet(name: str) -> None:
    command = [*COMMANDS[name][:-1], "--version"]
    if not Path(command[0]).exists():
        pytest.skip("the console script is not installed next to this interpreter")
    code, err, out = _paused_with_output(command, "exit", signals=2)
    assert err == ""  # no "Exception ignored in atexit callback", no traceback
    assert code == 0  # --version's status: the Ctrl-Cs changed nothing
    assert out.strip().endswith(tmmaster.__version__)  # said before the exit hooks ran


@pytest.mark.parametrize("name", list(COMMANDS))
def test_ctrl_c_as_soon_as_a_command_starts_is_one_line(name: str) -> None:
    # The first moment of main(): the command's one wrapper already holds Ctrl-C.
    command = COMMANDS[name]
    if not Path(command[0]).exists():
        pytest.skip("the console script is not installed next to this interpreter")
    code, err = _paused(command, "start", signals=2)
    assert err == f"{PROGS.get(name, name)}: interrupted [exit 130]\n"
    assert code == 130


@pytest.mark.parametrize("name", ["tmmaster", "pickplace"])
def test_sigterm_as_soon_as_a_command_starts_is_what_ctrl_c_does(name: str) -> None:
    # A supervisor's stop (systemctl stop, docker stop, kill): the command winds down as
    # after Ctrl-C (pick & place stops its arm), in one line; a second one cuts nothing.
    code, err = _paused(COMMANDS[name], "start", signals=2, signum=signal.SIGTERM)
    assert err == f"{name}: interrupted [exit 130]\n"
    assert code == 130


def test_sigterm_during_the_exit_hooks_is_ignored_as_ctrl_c_is() -> None:
    # A robot's exit hook (its withdraw or stop) is not cut short by a supervisor's stop.
    code, err, out = _paused_with_output(
        [*COMMANDS["tmmaster"][:-1], "--version"], "exit", 2, signal.SIGTERM
    )
    assert (code, err) == (0, "")
    assert out.strip().endswith(tmmaster.__version__)


def test_a_command_started_with_ctrl_c_ignored_keeps_the_default_sigterm() -> None:
    # ``command &`` in a script: Ctrl-C stays ignored, and SIGTERM still ends it at once
    # (forwarded to an ignored Ctrl-C, nothing could end it but SIGKILL).
    ignoring = ["sh", "-c", 'trap "" INT; exec "$@"', "sh", *COMMANDS["tmmaster"]]
    code, err = _paused(ignoring, "start", signals=1, signum=signal.SIGTERM)
    assert code == -signal.SIGTERM, err


@pytest.mark.parametrize("name", list(COMMANDS))
def test_ctrl_c_while_the_package_loads_is_one_line(name: str) -> None:
    # Before main() runs: tmmaster and the command's modules still load. The process is
    # one of tmmaster's commands, so a Ctrl-C there is one line too.
    command = COMMANDS[name]
    if not Path(command[0]).exists():
        pytest.skip("the console script is not installed next to this interpreter")
    code, err = _paused(command, "import", signals=1)
    assert err == f"{PROGS.get(name, name)}: interrupted [exit 130]\n"
    assert code == 130


def test_a_library_program_keeps_its_ctrl_c_and_an_exit_hook_is_not_cut_short() -> None:
    # Two checks, one fresh interpreter. (1) Even named as the console script (argv[0]),
    # a program that imports tmmaster and its commands' modules is not one of its
    # commands: its Ctrl-C handling stays its own. (2) A library program (no command): a
    # Robot's exit hook closes it under deferred(); two Ctrl-Cs during it neither cut it
    # short nor come out of it as a traceback.
    script = textwrap.dedent(
        """
        import atexit, importlib, os, signal, sys
        sys.argv[0] = "/usr/local/bin/tmmaster"
        before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
        for module in ("tmmaster", "tmmaster.aio", "tmmaster._cli", "tmmaster.sim.__main__",
                       "tmmaster.pickplace.__main__", "tmmaster.report.__main__",
                       "tmmaster.tmscript.__main__"):
            importlib.import_module(module)
        print((signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before,
              flush=True)

        from tmmaster._sigint import deferred

        def close_at_exit():
            with deferred():
                os.kill(os.getpid(), signal.SIGINT)
                os.kill(os.getpid(), signal.SIGINT)
                print("the stop ran to its end", flush=True)

        atexit.register(close_at_exit)
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=False
    )
    lines = done.stdout.splitlines()
    assert lines[:1] == ["True"], done.stderr  # (1)
    assert lines[1:] == ["the stop ran to its end"], done.stderr  # (2)
    assert done.stderr == ""
    assert done.returncode == 0


def test_a_ctrl_c_caught_in_generated_code_still_exits_130(tmp_path: Path) -> None:
    # CPython remembers a KeyboardInterrupt that ended code run from source text (how
    # dataclasses make their methods: a Ctrl-C can land there while a module loads) and,
    # under ``python -m``, used to end the process by SIGINT (-2) although main()
    # said 130 in one line.
    (tmp_path / "late_ctrl_c.py").write_text(
        textwrap.dedent(
            """
            import sys
            from tmmaster._sigint import run_main

            def body():
                exec("raise KeyboardInterrupt", {})  # as if in a dataclass's __init__ source
                return 0

            sys.exit(run_main("demo", body, process=True))
            """
        )
    )
    done = subprocess.run(
        [sys.executable, "-m", "late_ctrl_c"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        cwd=tmp_path,
    )
    assert done.stderr == "demo: interrupted [exit 130]\n"
    assert done.returncode == 130  # not -2: killed by the signal


def test_a_command_process_leaves_its_heap_to_the_system_after_every_exit_hook(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # run_main(process=True) as a command's process runs it, in this process: what it
    # registers at exit is recorded, not registered, and this process's Ctrl-C handling
    # is put back after.
    import gc

    from tmmaster import _sigint

    registered: list[object] = []
    monkeypatch.setattr(_sigint.atexit, "register", lambda hook, *_: registered.append(hook))
    # A command's process keeps its unraisable hook to the end; this process gets its own
    # back after the test, as its Ctrl-C handler.
    monkeypatch.setattr(sys, "unraisablehook", sys.unraisablehook)

    def command() -> int:
        registered.append("a robot's exit hook")  # as an opened Robot registers its own
        return 0

    # process=True takes over SIGTERM and SIGHUP too (then ignores them, as the process
    # would exit): all three are put back, else this process and every child it starts
    # would ignore a SIGTERM from here on.
    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    try:
        assert _sigint.run_main("demo", command, process=True) == 0
        # Registered first, so Python runs it last: after a robot's withdraw or stop and
        # logging's flush, its final collections skip the whole heap (gc.freeze).
        assert registered == [gc.freeze, "a robot's exit hook"]
        registered.clear()
        assert _sigint.run_main("demo", lambda: 0, process=False) == 0
        assert registered == []  # a caller in the same process keeps its heap collected
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)


def test_every_ctrl_c_is_noted_before_the_stop_it_sets_off_runs() -> None:
    # The first Ctrl-C's stop runs in a thread of its own, which a loaded machine may run
    # only after a second Ctrl-C's KeyboardInterrupt: the clean-up that runs then (a
    # withdraw, a stop, their log lines) must already find the command interrupted.
    from tmmaster._sigint import first_stops

    release = threading.Event()
    noted: list[int] = []
    previous = signal.getsignal(signal.SIGINT)
    try:
        with first_stops(lambda: release.wait(5), noted=lambda: noted.append(len(noted))):
            signal.raise_signal(signal.SIGINT)
            assert noted == [0]  # the stop's thread is still held
            with pytest.raises(KeyboardInterrupt):
                signal.raise_signal(signal.SIGINT)
        assert noted == [0, 1]
    finally:
        release.set()
        signal.signal(signal.SIGINT, previous)


def test_a_ctrl_c_raised_where_python_drops_exceptions_still_ends_the_command() -> None:
    # A Ctrl-C's KeyboardInterrupt raised inside a garbage collection's callback or a
    # __del__ (the simulator's program clock has one) is dropped by Python ("Exception
    # ignored in"); the command then ran on to its end, Ctrl-C ignored from then on.
    from tmmaster._sigint import run_main

    class Dropped:
        def __del__(self) -> None:
            signal.raise_signal(signal.SIGINT)
            for _ in range(1000):  # the handler runs here, inside __del__
                pass

    def body() -> int:
        Dropped()
        for _ in range(200):  # the command goes on: a Ctrl-C must end it
            time.sleep(0.005)
        return 0

    previous = signal.getsignal(signal.SIGINT)
    try:
        assert run_main("test", body, process=False) == 130
    finally:
        signal.signal(signal.SIGINT, previous)


def test_the_documented_sigterm_recipe_lets_a_clean_up_hold_it_back(
    capsys: pytest.CaptureFixture[str],
) -> None:
    # robot-api.md's recipe for a program of your own: SIGTERM does what Ctrl-C does at
    # that moment, so a robot's clean-up (deferred) holds two SIGTERMs back to its end.
    # In this process (as the two tests above): the subject is the recipe's handler and
    # deferred(), Python's own handlers, not a process's start or exit. The main thread
    # starts with a fresh interpreter's Ctrl-C handler; both handlers are put back after.
    from tmmaster._sigint import deferred

    def as_ctrl_c(signum: int, frame: FrameType | None) -> None:  # the recipe, as documented
        signal.getsignal(signal.SIGINT)(signal.SIGINT, frame)  # type: ignore[operator,misc]

    previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    previous_term = signal.signal(signal.SIGTERM, as_ctrl_c)
    try:
        try:
            with deferred():
                signal.raise_signal(signal.SIGTERM)
                signal.raise_signal(signal.SIGTERM)
                print("the clean-up ran to its end", flush=True)
        except KeyboardInterrupt:
            print("then KeyboardInterrupt", flush=True)
    finally:
        signal.signal(signal.SIGTERM, previous_term)
        signal.signal(signal.SIGINT, previous_int)
    out, err = capsys.readouterr()
    assert out.splitlines() == ["the clean-up ran to its end", "then KeyboardInterrupt"]
    assert err == ""  # no traceback, no "Exception ignored"


def test_the_interrupted_line_to_a_hung_up_terminal_still_exits_130(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # After SIGHUP, stderr is a terminal that hung up: writing the one line fails with
    # EIO. The command still ends with 130, not an OSError's traceback and exit 1.
    class HungUp(io.StringIO):
        def write(self, text: str) -> int:
            raise OSError(errno.EIO, "Input/output error")

    def interrupted() -> int:
        raise KeyboardInterrupt

    from tmmaster import _sigint

    monkeypatch.setattr(sys, "stderr", HungUp())
    before = signal.getsignal(signal.SIGINT)
    try:
        assert _sigint.run_main("demo", interrupted, process=False) == 130
    finally:
        signal.signal(signal.SIGINT, before)


def test_a_ctrl_c_inside_a_class_being_made_is_one_line_and_130(
    capsys: pytest.CaptureFixture[str],
) -> None:
    # A Ctrl-C can land while a module loads inside the command (a lazy import: the
    # logging's structlog at a pick & place start), in a dataclass field's __set_name__:
    # Python 3.11 re-raises it as a RuntimeError caused by the KeyboardInterrupt, which
    # ended such a run with a traceback and exit 1.
    from tmmaster import _sigint

    class Field:
        def __set_name__(self, owner: type, name: str) -> None:
            raise KeyboardInterrupt  # the Ctrl-C's, as the handler raises it there

    def command() -> int:
        type("Stack", (), {"exc_notes": Field()})
        return 0

    def broken() -> int:
        raise RuntimeError("a bug, not a Ctrl-C")

    previous = signal.getsignal(signal.SIGINT)
    try:
        assert _sigint.run_main("demo", command, process=False) == 130
        assert capsys.readouterr().err == "demo: interrupted [exit 130]\n"
        with pytest.raises(RuntimeError, match="a bug"):
            _sigint.run_main("demo", broken, process=False)
    finally:
        signal.signal(signal.SIGINT, previous)
