"""Many robots from one program: one thread per robot, each driving its own tour.

The recommended way to drive many robots from one Python process (measured in
docs/performance.md, "Many robots from one process"):

* one :class:`tmmaster.Robot` per robot, used by ONE thread (a Robot is not shared);
  every safety rule (validation, handshake, giving a command up safely) stays in that
  Robot, so nothing here re-implements any of it;
* every Robot in one :class:`tmmaster.Fleet` (the default here; ``--no-fleet`` turns it
  off): the robots' links and the polls of their waits run on the fleet's one event
  loop, which wakes a robot's thread only when a poll needs it (acknowledged, done,
  failed, a deadline). 400 moving robots on the article's map took 57-66 % of one core
  this way against 64-84 % with each thread polling its own waits, and the fleet's loop
  cannot queue for the GIL the way 400 polling threads sometimes do; the tmflow
  profile's status is six reads, not one: about 100 driven robots per process on two
  cores (docs/performance.md);
* connecting in parallel, at most ``CONNECT_WORKERS`` robots at once: a robot that does
  not answer holds up its own connect (until its retries give up, ``--retry-s``), not
  everybody's: 50 robots with a few dead ones start moving after about one connect
  timeout, not one per dead robot;
* plain threads, one per robot (not ``asyncio.to_thread`` with its default executor,
  which has only ``min(32, cpus + 4)`` workers: robot 33 would wait for another to
  finish);
* bounded work: each thread drives a fixed number of moves and ends; every wait inside
  ``move_to`` is bounded by the robot's timeouts;
* one failure stays with its robot: a robot that fails is reported, the others carry on;
* stopping: ``Robot.interrupt()`` is the one call meant to come from another thread;
  on Ctrl-C the main thread interrupts every robot, and each ``move_to`` in progress
  gives its command up safely (withdrawn or stopped) before its thread ends;
* watching: the fleet reads every robot's status ``--watch-hz`` times a second on its
  loop, over the robot's own link (``Fleet(watch_hz=...)``, ``Fleet.latest``);
  without a fleet a :class:`tmmaster.StatusMonitor` does it from one thread, over each
  connected robot's own link too (``StatusMonitor.add_robot``: a slave that accepts one
  client still sees one). ``--watch-hz 0`` turns watching off. A status of the
  article map is one read, of the real TM table six;
* ``gc.freeze()`` once the robots are connected: with hundreds of robots, CPython's full
  garbage collections walking every long-lived object were what made the worst watch
  read 15-30 ms late (2-4 ms frozen);
* past what one process can drive, more processes (``--processes K``): this script
  runs itself K times, each child driving a contiguous share of the robots, and
  gathers their reports. Each child runs in a process group of its own: a Ctrl-C (a
  terminal's, or one sent to the parent alone) reaches the parent, which passes it on
  to every child still running, once; each gives its own commands up safely, and the
  parent waits for them and never kills one.

Run against simulators it starts itself (``--sim N``, the default: 8 robots)::

    python examples/many_robots.py --sim 8 --moves 6

or against robots (or simulators) already listening on consecutive ports::

    python -m tmmaster.sim --port 5020 &
    python -m tmmaster.sim --port 5021 &
    python examples/many_robots.py --host 127.0.0.1 --ports 5020 5021

and from several processes (here 2, each driving 4 of 8 simulators)::

    python examples/many_robots.py --sim 8 --processes 2

Robots and simulators speak the ``tmflow`` profile unless told otherwise
(``--profile article`` here, and on simulators you start, for the article's map).
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import json
import os
import signal
import statistics
import subprocess
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

from tmmaster import (
    DEFAULT_PROFILE,
    Fleet,
    MonitoredStatus,
    Pose,
    RetryPolicy,
    Robot,
    StatusMonitor,
    TMMasterError,
)
from tmmaster.sim import Simulator

HOST = "127.0.0.1"
#: The tour every robot drives, over and over (article profile: |x|, |y|, |z| <= 327 mm).
TOUR = (
    Pose(300.0, -200.0, 200.0, 180.0, 0.0, 90.0),
    Pose(300.0, 200.0, 200.0, 180.0, 0.0, 90.0),
    Pose(250.0, 0.0, 300.0, 180.0, 0.0, 90.0),
)
SPEED = 80
#: Robots connecting at the same time, at most (one thread each while they connect).
CONNECT_WORKERS = 32


@dataclass
class RobotReport:
    """What one robot's thread did."""

    name: str
    moves_done: int = 0
    move_times_s: list[float] = field(default_factory=list)
    error: TMMasterError | None = None
    #: What the fleet's StatusMonitor last saw of this robot (None: not watched).
    watched: MonitoredStatus | None = None
    #: True when its close() could not confirm that nothing it sent can still run (a
    #: withdraw or stop that did not get through: the arm may still be moving).
    unconfirmed: bool = False


def drive(robot: Robot, moves: int, report: RobotReport) -> None:
    """One robot's work: ``moves`` moves of the tour, each checked by the library."""
    try:
        robot.wait_until_ready(timeout_s=10.0)
        for i in range(moves):
            started = time.monotonic()
            robot.move_to(TOUR[i % len(TOUR)], speed=SPEED)
            report.move_times_s.append(time.monotonic() - started)
            report.moves_done += 1
    except TMMasterError as exc:  # this robot's failure; the others carry on
        report.error = exc


def connect_all(
    pool: ThreadPoolExecutor, robots: Sequence[Robot], reports: Sequence[RobotReport]
) -> list[tuple[Robot, RobotReport]]:
    """Connect every robot, ``pool``'s workers at once; the connected ones, in order.

    A robot that cannot connect keeps its error in its report; the others do not wait
    for it (beyond the pool's bound).
    """

    def connect(robot: Robot, report: RobotReport) -> bool:
        try:
            robot.connect()
        except TMMasterError as exc:
            report.error = exc
            return False
        return True

    done = list(pool.map(connect, robots, reports))
    return [(robot, report) for robot, report, ok in zip(robots, reports, done, strict=True) if ok]


def run(
    ports: Sequence[int],
    *,
    host: str = HOST,
    moves: int = 6,
    profile: str = DEFAULT_PROFILE,
    watch_hz: float = 10.0,
    first_index: int = 0,
    fleet: bool = True,
    retry_s: float = 10.0,
) -> list[RobotReport]:
    """Drive one robot per port, one thread each, watched at ``watch_hz`` (> 0).

    ``fleet``: the robots in one :class:`tmmaster.Fleet`, which polls their waits and
    watches them on one event loop over their own links; else each robot polls its own
    waits, and a :class:`tmmaster.StatusMonitor` watches the connected ones over their
    links too, between their requests. The robots connect in parallel (at most
    ``CONNECT_WORKERS`` at once); each retries a failed connect or request for up to
    ``retry_s`` seconds.
    """
    shared = Fleet(watch_hz=watch_hz or None) if fleet else None
    retry = RetryPolicy(total_time_s=retry_s)
    robots = [
        Robot(
            host,
            port,
            profile=profile,
            gripper=None,
            name=f"robot{first_index + i}",
            retry=retry,
            link=shared,
        )
        for i, port in enumerate(ports)
    ]
    reports = [RobotReport(r.name) for r in robots]
    threads: list[threading.Thread] = []
    interrupted = False
    monitor = StatusMonitor(rate_hz=watch_hz) if watch_hz > 0 and shared is None else None
    pool = ThreadPoolExecutor(
        max_workers=max(1, min(len(robots), CONNECT_WORKERS)), thread_name_prefix="connect"
    )
    try:
        connected = connect_all(pool, robots, reports)
        if monitor is not None:
            # Over each robot's own link: no second connection, which a controller that
            # takes one Modbus client would refuse (or give the robot's slot away for).
            for robot, _report in connected:
                monitor.add_robot(robot)
            monitor.start()  # read-only: it never writes, so it cannot move anything
        # Everything made so far lives as long as the run: keep CPython's full garbage
        # collections from walking it again and again (with hundreds of robots they
        # made the worst poll 15-30 ms late instead of 2-4; docs/performance.md).
        gc.freeze()
        for robot, report in connected:
            thread = threading.Thread(
                target=drive, args=(robot, moves, report), name=robot.name, daemon=True
            )
            thread.start()
            threads.append(thread)
        for thread in threads:
            # join() with a timeout in a loop: the main thread stays responsive to Ctrl-C.
            while thread.is_alive():
                thread.join(0.5)
    except KeyboardInterrupt:
        interrupted = True
        for robot in robots:
            robot.interrupt()  # every move_to in progress gives its command up safely
        for thread in threads:
            thread.join(10.0)
    finally:
        gc.unfreeze()
        if monitor is not None:
            watched = monitor.snapshot()  # the connected robots
            for report in reports:
                report.watched = watched.get(report.name)
            monitor.close()
        if shared is not None and shared.watch_hz is not None:
            for robot, report in zip(robots, reports, strict=True):
                report.watched = shared.latest(robot)
        # close() says whether it could confirm that nothing the robot sent can still run.
        unconfirmed = [robot.name for robot in robots if not robot.close()]
        if shared is not None:
            unconfirmed += [name for name in shared.close() if name not in unconfirmed]
        for report in reports:  # reported with or without Ctrl-C
            report.unconfirmed = report.name in unconfirmed
        # After the robots are closed: a connect still running (Ctrl-C came during the
        # connects) ends with its robot's close.
        pool.shutdown(wait=True, cancel_futures=True)
    if interrupted:
        raise Interrupted(unconfirmed)
    return reports


class Interrupted(KeyboardInterrupt):
    """Ctrl-C ended a run once every robot was closed: which ones could not confirm it."""

    def __init__(self, unconfirmed: Sequence[str]) -> None:
        super().__init__("interrupted")
        #: The robots whose withdraw or stop could not be confirmed (empty: none).
        self.unconfirmed = tuple(unconfirmed)


def report_to_json(report: RobotReport) -> dict[str, Any]:
    """A report as JSON, for a child process to hand to its parent."""
    watched = report.watched
    return {
        "name": report.name,
        "moves_done": report.moves_done,
        "move_times_s": report.move_times_s,
        "error": None if report.error is None else f"{type(report.error).__name__}: {report.error}",
        "watched": None if watched is None else [watched.polls, watched.failures],
        "unconfirmed": report.unconfirmed,
    }


def report_from_json(data: dict[str, Any]) -> RobotReport:
    """A child's report (its error keeps the type's name in the message)."""
    watched = data["watched"]
    return RobotReport(
        data["name"],
        moves_done=data["moves_done"],
        move_times_s=data["move_times_s"],
        error=None if data["error"] is None else TMMasterError(data["error"]),
        watched=None
        if watched is None
        else MonitoredStatus(None, None, None, watched[0], 0, watched[1]),
        unconfirmed=bool(data.get("unconfirmed", False)),
    )


def run_in_processes(
    ports: Sequence[int],
    *,
    processes: int,
    host: str = HOST,
    moves: int = 6,
    profile: str = DEFAULT_PROFILE,
    watch_hz: float = 10.0,
    first_index: int = 0,
    fleet: bool = True,
    retry_s: float = 10.0,
) -> list[RobotReport]:
    """Drive the robots from ``processes`` child processes of this script, a share each.

    Each child runs in a process group of its own (POSIX): a Ctrl-C, a terminal's or one
    sent to this process alone, reaches this process only, which passes it on to every
    child still running, once (two at once could land inside a child's own clean-up
    and hang it there: measured, 3 runs in 30). SIGTERM and SIGHUP (a closed terminal)
    are taken as Ctrl-C meanwhile, so the children never drive on without a parent.
    """
    share, extra = divmod(len(ports), processes)
    children: list[tuple[list[int], int, subprocess.Popen[str]]] = []
    options = [
        "--host", host, "--moves", str(moves), "--profile", profile, "--watch-hz",
        str(watch_hz), "--json", "--retry-s", str(retry_s), *([] if fleet else ["--no-fleet"]),
    ]  # fmt: skip
    own_group: dict[str, Any] = {"process_group": 0} if os.name == "posix" else {}
    reports: list[RobotReport] = []
    first = 0
    with _terminate_as_ctrl_c():
        try:
            for k in range(processes):
                group = list(ports[first : first + share + (k < extra)])
                if not group:
                    break
                command = [sys.executable, __file__, "--ports", *map(str, group), *options]
                command += ["--first-index", str(first_index + first)]
                child = subprocess.Popen(command, stdout=subprocess.PIPE, text=True, **own_group)
                children.append((group, first, child))
                first += len(group)
            for group, first, child in children:
                reports += _child_reports(
                    child, [first_index + first + i for i in range(len(group))]
                )
        except KeyboardInterrupt:
            # Passed on to every child still running, the only Ctrl-C it gets: without it
            # the children drove their whole tours. Each gives its commands up itself:
            # wait for them; killing one could cut a withdraw or a stop short.
            for _, _, child in children:
                child.send_signal(signal.SIGINT)  # nothing once it has ended
            for _, _, child in children:
                child.wait()
            raise
    return reports


def _child_reports(child: subprocess.Popen[str], numbers: list[int]) -> list[RobotReport]:
    """A child's reports, one per robot it was given (numbered ``numbers``)."""
    out, _ = child.communicate()
    got = [report_from_json(json.loads(line)) for line in out.splitlines() if line[:1] == "{"]
    for number in numbers[len(got) :]:  # a child that ended before reporting
        reason = f"its process ended with code {child.returncode} before reporting"
        got.append(RobotReport(f"robot{number}", error=TMMasterError(reason)))
    return got


@contextlib.contextmanager
def _terminate_as_ctrl_c() -> Iterator[None]:
    """SIGTERM and SIGHUP raise KeyboardInterrupt meanwhile (POSIX, main thread only)."""

    def as_ctrl_c(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    names = ("SIGTERM", "SIGHUP")
    wanted = [getattr(signal, n) for n in names if hasattr(signal, n)]
    if threading.current_thread() is not threading.main_thread():
        wanted = []
    previous = {signum: signal.signal(signum, as_ctrl_c) for signum in wanted}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)


def drive_all(
    ports: Sequence[int],
    *,
    processes: int = 1,
    host: str = HOST,
    moves: int = 6,
    profile: str = DEFAULT_PROFILE,
    watch_hz: float = 10.0,
    first_index: int = 0,
    fleet: bool = True,
    retry_s: float = 10.0,
) -> list[RobotReport]:
    """:func:`run` in this process, or :func:`run_in_processes` when ``processes`` > 1."""
    options: dict[str, Any] = {
        "host": host,
        "moves": moves,
        "profile": profile,
        "watch_hz": watch_hz,
        "first_index": first_index,
        "fleet": fleet,
        "retry_s": retry_s,
    }
    if processes > 1:
        return run_in_processes(ports, processes=processes, **options)
    return run(ports, **options)


def run_with_simulators(
    n: int,
    *,
    moves: int = 6,
    time_scale: float = 10.0,
    watch_hz: float = 10.0,
    processes: int = 1,
    fleet: bool = True,
    profile: str = DEFAULT_PROFILE,
) -> list[RobotReport]:
    """Start ``n`` simulators on 127.0.0.1 in this process, drive them, close them."""
    sims = [Simulator(profile, time_scale=time_scale).start() for _ in range(n)]
    try:
        ports = [s.port for s in sims]
        return drive_all(
            ports,
            processes=processes,
            moves=moves,
            profile=profile,
            watch_hz=watch_hz,
            fleet=fleet,
        )
    finally:
        for sim in sims:
            sim.close()


def print_reports(reports: Sequence[RobotReport]) -> int:
    """One line per robot; returns 0 when every robot finished its moves, else 1 (also
    for a robot whose close could not confirm its give-up)."""
    for r in reports:
        if r.error is not None:
            print(f"{r.name}: FAILED after {r.moves_done} move(s): {r.error}")
        else:
            mean = statistics.fmean(r.move_times_s) if r.move_times_s else 0.0
            print(f"{r.name}: {r.moves_done} moves, mean {mean:.3f} s per move")
        if r.unconfirmed:
            print(f"  {r.name}: could NOT confirm that it gave its command up: check the arm")
        if r.watched is not None:
            print(f"  watched: {r.watched.polls} status polls, {r.watched.failures} failed")
    failed = sum(r.error is not None or r.unconfirmed for r in reports)
    print(f"{len(reports) - failed} of {len(reports)} robots done")
    return 1 if failed else 0


def build_parser() -> argparse.ArgumentParser:
    """The command line's options."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sim", type=int, default=None, metavar="N", help="start N simulators")
    parser.add_argument("--host", default=HOST)
    parser.add_argument("--ports", type=int, nargs="+", default=None)
    parser.add_argument("--moves", type=int, default=6)
    parser.add_argument(
        "--profile", default=DEFAULT_PROFILE, help=f"robots' profile (default: {DEFAULT_PROFILE})"
    )
    parser.add_argument("--time-scale", type=float, default=10.0, help="with --sim")
    parser.add_argument(
        "--watch-hz", type=float, default=10.0, help="status watch rate; 0: no watch"
    )
    parser.add_argument(
        "--no-fleet",
        dest="fleet",
        action="store_false",
        help="no Fleet: each robot polls its own waits; a StatusMonitor watches",
    )
    parser.add_argument(
        "--processes", type=int, default=1, help="child processes sharing the robots"
    )
    parser.add_argument(
        "--retry-s",
        type=float,
        default=10.0,
        help="how long a robot retries a failed connect or request, s (default 10)",
    )
    # Used by --processes for its children: their robots' numbers, and JSON reports.
    parser.add_argument("--first-index", type=int, default=0, help=argparse.SUPPRESS)
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: ``--sim N`` (default) or ``--ports P1 P2 ...``; ``--processes K``."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.sim is not None and args.ports is not None:
        parser.error("--sim and --ports are exclusive")
    if args.moves < 1:
        parser.error("--moves must be >= 1")
    if not args.watch_hz >= 0:
        parser.error("--watch-hz must be >= 0")
    if args.processes < 1:
        parser.error("--processes must be >= 1")
    if not 0 < args.retry_s <= 600:
        parser.error("--retry-s must be in (0, 600]")
    try:
        if args.ports is not None:
            reports = drive_all(
                args.ports,
                processes=args.processes,
                host=args.host,
                moves=args.moves,
                profile=args.profile,
                watch_hz=args.watch_hz,
                first_index=args.first_index,
                fleet=args.fleet,
                retry_s=args.retry_s,
            )
        else:
            n = 8 if args.sim is None else args.sim
            if n < 1:
                parser.error("--sim must be >= 1")
            reports = run_with_simulators(
                n,
                moves=args.moves,
                time_scale=args.time_scale,
                watch_hz=args.watch_hz,
                processes=args.processes,
                fleet=args.fleet,
                profile=args.profile,
            )
    except Interrupted as exc:
        if exc.unconfirmed:
            names = ", ".join(exc.unconfirmed)
            print(f"interrupted: could NOT confirm that {names} gave up: check", file=sys.stderr)
        else:
            print("interrupted: every robot gave its command up", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        # Again before every robot was closed, or in --processes' parent (each child
        # reports its own robots): a robot still open gives up as the program exits.
        print("interrupted: each robot still open gives its command up at exit", file=sys.stderr)
        return 130
    if args.json:
        for report in reports:
            print(json.dumps(report_to_json(report)))
        return 1 if any(r.error is not None or r.unconfirmed for r in reports) else 0
    return print_reports(reports)


if __name__ == "__main__":
    sys.exit(main())
