"""Two Ctrl-Cs while a command's process runs Python's exit hooks, where the test hook
``TMMASTER_TEST_SIGINT_AT=exit`` pauses it (it says so on stderr and waits for a byte on
stdin): for a process test that already runs a command to its end, so the check costs no
interpreter start of its own (test_sigint_exit does it after ``--version`` for the others).
"""

from __future__ import annotations

import contextlib
import signal
import subprocess
import time

#: What the command says on stderr where it pauses in its exit hooks.
PAUSED_AT_EXIT = "tmmaster-test: paused at exit\n"

#: The environment entry that makes a command pause there.
PAUSE_AT_EXIT = {"TMMASTER_TEST_SIGINT_AT": "exit"}


def ctrl_c_in_the_exit_hooks(
    proc: subprocess.Popen[str], timeout: float = 60
) -> tuple[str, str, str]:
    """Let ``proc`` (started with :data:`PAUSE_AT_EXIT`, stdin, stdout and stderr piped,
    text) end: read its stderr up to the pause, send two Ctrl-Cs there, let it go on.

    Returns:
        Its stderr up to and with the pause line (or all of it, if it never paused), its
        stdout, and its stderr after the pause.
    """
    assert proc.stdin is not None
    assert proc.stderr is not None
    before = ""
    deadline = time.monotonic() + timeout
    while not before.endswith(PAUSED_AT_EXIT) and time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break  # it ended without pausing
        before += line
    if before.endswith(PAUSED_AT_EXIT):
        proc.send_signal(signal.SIGINT)
        proc.send_signal(signal.SIGINT)
    with contextlib.suppress(BrokenPipeError):
        proc.stdin.write("x")  # let it go on (it may have exited already)
        proc.stdin.flush()
    out, after = proc.communicate(timeout=timeout)
    return before, out, after
