"""CPU a running Simulator costs per wall second: idle, and while a master moves it.

The test suite waits on many simulators that do nothing: a simulator's idle cost (its
control tick, the tmflow robot program polling its registers, the Modbus servers)
multiplies across it. This starts a real :class:`Simulator` (threads, event loop, and a
TCP server or none), for each profile:

- ``idle``: nobody connected; ``--idle`` wall seconds; the CPU of the whole process
  and of the simulator's own thread (``tmmaster-sim``), per wall second;
- ``moves``: a :class:`Robot` connected (in-process ``sim://`` or over loopback TCP)
  makes ``--moves`` PTPs to and fro; CPU per move, process and simulator thread.

The defaults are the test suite's simulators (tests/sim_speeds.py): 40x real time, a
100 Hz tick. Medians of ``--rounds`` rounds (a fresh simulator each). Run it on the current code,
and with ``PYTHONPATH`` pointing at another revision's ``src`` to compare::

    python benchmarks/bench_sim_idle.py --idle 3 --moves 10 --rounds 3
    python benchmarks/bench_sim_idle.py --profile tmflow --listen memory
"""

from __future__ import annotations

import argparse
import statistics
import threading
import time
from collections.abc import Callable

from _machine import machine_line

import tmmaster
from tmmaster import Pose
from tmmaster.sim import Simulator, Timing

#: Two poses the arm moves between (100 mm apart, reachable with the default tool).
TARGETS = (Pose(300, -200, 150, 180, 0, 90), Pose(300, -200, 250, 180, 0, 90))


def _thread_cpu(thread: threading.Thread) -> Callable[[], float]:
    """A clock of ``thread``'s CPU seconds (Linux: its CPU-time clock)."""
    assert thread.ident is not None
    clock = time.pthread_getcpuclockid(thread.ident)
    return lambda: time.clock_gettime(clock)


def _sim_thread() -> threading.Thread:
    return next(t for t in threading.enumerate() if t.name == "tmmaster-sim")


def idle_round(
    profile: str, listen: bool, seconds: float, time_scale: float, timing: Timing
) -> tuple[float, float]:
    """(process, simulator thread) CPU milliseconds per wall second of an idle simulator."""
    with Simulator(profile, time_scale=time_scale, listen=listen, timing=timing):
        sim_cpu = _thread_cpu(_sim_thread())
        time.sleep(0.2)  # past the start-up
        p0, s0, w0 = time.process_time(), sim_cpu(), time.perf_counter()
        time.sleep(seconds)
        p1, s1, w1 = time.process_time(), sim_cpu(), time.perf_counter()
    wall = w1 - w0
    return (p1 - p0) * 1e3 / wall, (s1 - s0) * 1e3 / wall


def move_round(
    profile: str, listen: bool, moves: int, time_scale: float, timing: Timing
) -> tuple[float, float, float]:
    """(process, simulator thread) CPU milliseconds per move, and wall seconds per move."""
    with Simulator(profile, time_scale=time_scale, listen=listen, timing=timing) as sim:
        sim_cpu = _thread_cpu(_sim_thread())
        where = (sim.host, sim.port) if listen else (sim.url,)
        with tmmaster.connect(*where, profile=profile) as robot:
            robot.move_to(TARGETS[1], speed=100)  # the first move: connections warm
            p0, s0, w0 = time.process_time(), sim_cpu(), time.perf_counter()
            for i in range(moves):
                robot.move_to(TARGETS[i % 2], speed=100)
            p1, s1, w1 = time.process_time(), sim_cpu(), time.perf_counter()
    return (p1 - p0) * 1e3 / moves, (s1 - s0) * 1e3 / moves, (w1 - w0) / moves


def main() -> None:
    """Print the idle and moving figures per profile and listener."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", choices=("tmflow", "article", "both"), default="both")
    parser.add_argument("--listen", choices=("memory", "tcp", "both"), default="both")
    parser.add_argument("--idle", type=float, default=3.0, help="wall seconds idle per round")
    parser.add_argument("--moves", type=int, default=10, help="moves per round (0: none)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--time-scale", type=float, default=40.0)
    parser.add_argument("--tick-hz", type=float, default=100.0)
    parser.add_argument(
        "--batch-s",
        type=float,
        default=Timing().batch_s,
        help="Timing.batch_s: how long due ticks may wait unobserved (0: one wake-up a tick)",
    )
    args = parser.parse_args()
    timing = Timing(tick_hz=args.tick_hz, batch_s=args.batch_s)
    print(machine_line())
    print(
        f"time scale {args.time_scale:g}, tick {args.tick_hz:g} Hz, batch {args.batch_s:g} s,"
        " kinematic backend"
    )
    profiles = ("tmflow", "article") if args.profile == "both" else (args.profile,)
    listens = (False, True) if args.listen == "both" else (args.listen == "tcp",)
    for profile in profiles:
        for listen in listens:
            where = "tcp" if listen else "memory"
            idle = [
                idle_round(profile, listen, args.idle, args.time_scale, timing)
                for _ in range(args.rounds)
            ]
            proc = statistics.median(r[0] for r in idle)
            sim = statistics.median(r[1] for r in idle)
            print(
                f"{profile:7} {where:6} idle : {proc:6.1f} ms CPU/s process,"
                f" {sim:6.1f} ms CPU/s sim thread (median of {len(idle)};"
                f" process rounds {', '.join(f'{r[0]:.1f}' for r in idle)})"
            )
            if args.moves <= 0:
                continue
            moving = [
                move_round(profile, listen, args.moves, args.time_scale, timing)
                for _ in range(args.rounds)
            ]
            proc = statistics.median(r[0] for r in moving)
            sim = statistics.median(r[1] for r in moving)
            wall = statistics.median(r[2] for r in moving)
            print(
                f"{profile:7} {where:6} moves: {proc:6.1f} ms CPU/move process,"
                f" {sim:6.1f} ms CPU/move sim thread, {wall * 1e3:.0f} ms wall/move"
                f" (median of {len(moving)};"
                f" process rounds {', '.join(f'{r[0]:.1f}' for r in moving)})"
            )
    print(f"load average after: {__import__('os').getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
