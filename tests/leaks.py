"""What a test may leave behind: the process's open sockets and new threads, looked at again
until they are gone (the suite's leak check, and the long-run hunt's)."""

from __future__ import annotations

import gc
import os
import stat
import threading
import time


def open_sockets() -> set[int]:
    """The inodes of this process's open sockets (Linux: /proc/self/fd lists its fds).

    ``os.fstat`` of each descriptor, not ``os.readlink`` of its /proc link: the same
    socket inode for a fraction of the CPU (every test calls this twice).
    """
    found = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            info = os.fstat(int(fd))
        except OSError:  # closed since (the listing's own descriptor among them)
            continue
        if stat.S_ISSOCK(info.st_mode):
            found.add(info.st_ino)
    return found


def left_open(
    sockets_before: set[int], threads_before: set[threading.Thread], *, collect: bool = False
) -> tuple[list[threading.Thread], set[int]]:
    """The threads and sockets new since ``*_before`` still there after up to 2 s of looking.

    With ``collect``, a collection is made once something new is found: it can close
    unreachable sockets, never open one (a collection costs tens of milliseconds here).
    """
    deadline = time.monotonic() + 2.0
    while True:
        new_threads = [t for t in threading.enumerate() if t not in threads_before and t.is_alive()]
        new_sockets = open_sockets() - sockets_before
        if (not new_threads and not new_sockets) or time.monotonic() > deadline:
            return new_threads, new_sockets
        if collect:
            gc.collect()
        time.sleep(0.02)
