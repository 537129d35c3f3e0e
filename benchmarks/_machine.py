"""What every benchmark shares about the machine: the line it prints first, and CPU pinning."""

from __future__ import annotations

import argparse
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


def pin_plan(pin: str, master_count: int) -> tuple[list[int], list[int]]:
    """(master CPUs, simulator CPUs) to pin to; both empty when not pinning.

    ``pin``: "auto" pins when this process may run on 8 or more CPUs, "on" always,
    "off" never. The master gets the first ``master_count`` CPUs, the simulators the rest.
    """
    cpus = sorted(os.sched_getaffinity(0))
    if pin == "off" or (pin == "auto" and len(cpus) < 8):
        return [], []
    if len(cpus) <= master_count:
        raise SystemExit(f"--pin on needs more than {master_count} CPUs, this process has {cpus}")
    return cpus[:master_count], cpus[master_count:]


def cpu_list(cpus: list[int]) -> str:
    """``0-1`` for a run of CPUs, else a comma list."""
    if cpus == list(range(cpus[0], cpus[-1] + 1)):
        return f"{cpus[0]}-{cpus[-1]}"
    return ",".join(map(str, cpus))


def pinning_line(master_cpus: list[int], sim_cpus: list[int]) -> str:
    """How a run was pinned, for its header line."""
    if not master_cpus:
        return "not pinned"
    return f"master pinned to CPUs {cpu_list(master_cpus)}, simulators to {cpu_list(sim_cpus)}"


def add_pin_arguments(parser: argparse.ArgumentParser) -> None:
    """``--pin``, ``--master-cpus``, and the children's hidden ``--cpus``."""
    parser.add_argument(
        "--pin",
        choices=["auto", "on", "off"],
        default="auto",
        help="pin the master and the simulators to separate CPUs (auto: with 8 or more CPUs)",
    )
    parser.add_argument("--master-cpus", type=int, default=2, help="CPUs the master is pinned to")
    parser.add_argument("--cpus", help=argparse.SUPPRESS)


def pin_child(args: argparse.Namespace) -> None:
    """In a simulator process: stay on the CPUs the parent named (``--cpus``), if any."""
    if args.cpus:
        os.sched_setaffinity(0, {int(c) for c in args.cpus.split(",")})


def pin_master(args: argparse.Namespace) -> tuple[list[int], list[int]]:
    """In the master: pin this process as ``--pin`` says; return (master, simulator) CPUs."""
    master_cpus, sim_cpus = pin_plan(args.pin, args.master_cpus)
    if master_cpus:
        os.sched_setaffinity(0, master_cpus)  # every thread started later inherits it
    return master_cpus, sim_cpus
