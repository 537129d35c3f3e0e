"""The line every benchmark prints first: which Python, how many cores, which CPU, how busy."""

from __future__ import annotations

import os
import platform
from pathlib import Path


def machine_line() -> str:
    """``CPython 3.11.7, nproc 2 (<CPU model>), load average 0.42``."""
    cpuinfo = Path("/proc/cpuinfo")
    lines = cpuinfo.read_text().splitlines() if cpuinfo.exists() else []
    model = next(
        (line.split(":", 1)[1].strip() for line in lines if line.startswith("model name")),
        platform.processor(),
    )
    return (
        f"{platform.python_implementation()} {platform.python_version()},"
        f" nproc {os.cpu_count()} ({model}), load average {os.getloadavg()[0]:.2f}"
    )
