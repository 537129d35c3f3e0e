"""Ctrl-C while a command loads or while the interpreter exits: one line or nothing, never
a traceback; and a Ctrl-C never cuts an exit hook (a robot's withdraw or stop) short.

Each command runs in a child process that pauses at the point under test (the test hook
``TMMASTER_TEST_SIGINT_AT``: it says so on stderr and waits for a byte on stdin), so the
Ctrl-Cs arrive exactly there: an event, not a guessed delay.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")

#: The commands: ``python -m MODULE`` and the console script.
COMMANDS = {
    "sim": [sys.executable, "-m", "tmmaster.sim", "--help"],
    "pickplace": [sys.executable, "-m", "tmmaster.pickplace", "--help"],
    "tmmaster": [sys.executable, "-m", "tmmaster", "--help"],
    "console script": [str(Path(sys.executable).with_name("tmmaster")), "--help"],
}


def _paused(command: list[str], point: str, signals: int) -> tuple[int, str]:
    """Run ``command`` paused at ``point``, send ``signals`` Ctrl-Cs there, let it go on."""
    env = {**os.environ, "TMMASTER_TEST_SIGINT_AT": point}
    proc = subprocess.Popen(
        command,
        stdin=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env=env,
    )
    assert proc.stdin is not None
    assert proc.stderr is not None
    try:
        seen = proc.stderr.readline().decode()
        assert seen == f"tmmaster-test: paused at {point}\n", seen
        for _ in range(signals):
            proc.send_signal(signal.SIGINT)
        try:
            proc.stdin.write(b"x")  # let it go on (it may have exited already)
            proc.stdin.close()
        except BrokenPipeError:
            pass
        err = proc.stderr.read().decode()
        return proc.wait(timeout=30), err
    finally:
        proc.kill()
        proc.wait()
        proc.stderr.close()


@pytest.mark.parametrize("name", list(COMMANDS))
def test_ctrl_c_during_the_exit_hooks_is_quiet(name: str) -> None:
    command = COMMANDS[name]
    if not Path(command[0]).exists():
        pytest.skip("the console script is not installed next to this interpreter")
    code, err = _paused(command, "exit", signals=2)
    assert err == ""  # no "Exception ignored in atexit callback", no traceback
    assert code == 0  # --help's status: the Ctrl-Cs changed nothing


@pytest.mark.parametrize("name", ["sim", "console script"])
def test_ctrl_c_while_the_package_loads_is_one_line(name: str) -> None:
    command = COMMANDS[name]
    if not Path(command[0]).exists():
        pytest.skip("the console script is not installed next to this interpreter")
    code, err = _paused(command, "import", signals=1)
    prog = "sim" if name == "sim" else "tmmaster"
    assert err == f"{prog}: interrupted [exit 130]\n"
    assert code == 130


def test_a_ctrl_c_held_back_by_an_exit_hook_is_dropped_not_raised() -> None:
    # A library program (no command): a Robot's exit hook closes it under deferred();
    # two Ctrl-Cs during it neither cut it short nor come out of it as a traceback.
    script = textwrap.dedent(
        """
        import atexit, os, signal
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
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=30, check=False
    )
    assert done.stdout == "the stop ran to its end\n"
    assert done.stderr == ""
    assert done.returncode == 0
