"""Several robots from one program: one thread per robot, measured.

Runs N = 1, 2, 4, 8 simulated article-profile robots concurrently, each doing the same
fixed sequence of moves, and reports per N:

* move overshoot: wall time of ``move_to`` minus the move's expected time (arm model
  time / time_scale). At N = 1 this is the handshake's inherent cost (acknowledge on the
  next 50 Hz tick, completion seen at the next 50 ms poll); what grows with N is the
  cost of driving the robots from one process;
* poll interval: time between two status polls of the same move, as stamped by the
  simulator on arrival (the target is the 50 ms poll interval);
* master CPU %: CPU time of this process / wall time (100 % = one core);
* requests/s: Modbus requests of all robots together per wall second.

The simulators run in separate processes (``--serve``, ``--sims-per-process`` each, by
default all in one) so the CPU figure is the master's own, not the simulators' ticks.
Everything stays on 127.0.0.1. With 8 or more CPUs (``--pin auto``) the master is pinned
to the first ``--master-cpus`` (2) and the simulator processes to the rest, as in
``bench_many_robots.py``.

``--mode asyncio`` drives the same blocking code through ``asyncio.to_thread`` for
comparison: it is still one OS thread per robot underneath (the library is synchronous).
``--mode fleet`` is one thread per robot too, every robot in one :class:`tmmaster.Fleet`:
the robots' links and the polls of their waits on the fleet's event loop, the threads
woken only when a poll needs them; ``--watch HZ`` makes the fleet also read every
robot's status HZ times a second. ``--mode`` takes several modes.

``--slave light`` replaces the simulators by :class:`LightRobot` s (the article map's
clear-on-accept handshake and the arm model's move times, nothing else), cheap enough
that hundreds fit on the master's machine; ``--stagger S`` spreads the robots' first
moves over S seconds instead of starting every robot's tour together.

Usage::

    python benchmarks/bench_multi_robot.py                 # threads, N = 1 2 4 8
    python benchmarks/bench_multi_robot.py --mode both --moves 12 --repeat 3
    python benchmarks/bench_multi_robot.py --n 100 200 --sims-per-process 10 --time-scale 1
    python benchmarks/bench_multi_robot.py --slave light --sims-per-process 100 \
        --n 100 400 --moves 6 --time-scale 1 --stagger 0.5
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import struct
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from _machine import add_pin_arguments, machine_line, pin_child, pin_master, pinning_line
from _mbap import answer_frame, split_requests

from tmmaster import Fleet, MotionType, Pose, Robot

#: The fixed tour every robot drives (article pick area; the article map holds
#: |x|, |y|, |z| <= 327.67 mm), at 100 % speed, PTP.
TOUR = [
    Pose(300.0, -200.0, 200.0, 180.0, 0.0, 90.0),
    Pose(300.0, 200.0, 200.0, 180.0, 0.0, 90.0),
    Pose(250.0, 0.0, 300.0, 180.0, 0.0, 90.0),
]
POLL_S = 0.05
#: The status block the article channel polls while a move runs (FC3, address 0, 22 words).
STATUS_POLL = (3, 0)
#: The TCP pose read that ends a move (FC3, address 16).
POSE_READ = (3, 16)


# -- the simulator process -----------------------------------------------------------

#: The article map's addresses the light slave serves (profiles/article.toml).
MODE, MOTION, POSE_AT, TARGET_AT, SPEED_AT, COMMAND_AT = 0x00, 0x01, 0x10, 0x200, 0x206, 0x207
#: The light slave's control tick (the TM's 50 Hz): a command is taken on the next one.
TICK_S = 0.02


class LightRobot(asyncio.Protocol):
    """A minimal article-map robot for many-robot runs: cheap enough to host hundreds.

    Not the simulator: no faults, no gripper, no stop, no limits beyond the arm model's
    time. It answers FC3 reads from its registers and takes FC16/FC6 writes; a PTP or
    Line command written to the command register is taken on the next 20 ms tick
    (``motion_status`` = moving, then the command register cleared: the clear-on-accept
    handshake), and the move ends, pose = target and ``motion_status`` = idle, after the
    arm model's time for it (the same ``RobotModel.motion_time`` the master expects),
    divided by ``time_scale``. Every request's arrival is logged like the simulator's.
    """

    def __init__(self, time_scale: float, log: list[tuple[float, int, int]]) -> None:
        from tmmaster import robot_model

        self.model = robot_model("tm5-700")
        self.time_scale = time_scale
        self.log = log
        self.words = [0] * 0x220
        self.words[MODE] = 5  # auto
        self.pose = TOUR[2]
        self._set_pose(self.pose)
        self.buffer = b""
        self.transport: asyncio.Transport | None = None
        self.taking: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport

    def _set_pose(self, pose: Pose) -> None:
        for i, value in enumerate(pose.as_list()):
            self.words[POSE_AT + i] = round(value * 100) & 0xFFFF

    def data_received(self, data: bytes) -> None:
        frames, self.buffer = split_requests(self.buffer + data)
        for frame in frames:
            fc = frame[7]
            address, count = struct.unpack(">HH", frame[8:12])
            self.log.append((time.monotonic(), fc, address))
            if fc == 3 and address + count <= len(self.words):
                pdu = struct.pack(
                    f">BB{count}H", 3, 2 * count, *self.words[address : address + count]
                )
            elif fc in (6, 16):
                values = [count] if fc == 6 else list(struct.unpack(f">{count}H", frame[13:]))
                self.words[address : address + len(values)] = values
                pdu = frame[7:12]
                if address <= COMMAND_AT < address + len(values):
                    self._command_written()
            else:
                pdu = struct.pack(">BB", fc | 0x80, 2)
            assert self.transport is not None
            self.transport.write(answer_frame(frame, pdu))

    def _command_written(self) -> None:
        if self.words[COMMAND_AT] in (1, 2) and self.taking is None and not self.words[MOTION]:
            loop = asyncio.get_running_loop()
            now = loop.time()
            self.taking = loop.call_at(now + TICK_S - now % TICK_S, self._take)

    def _take(self) -> None:
        self.taking = None
        command = self.words[COMMAND_AT]
        if command not in (1, 2):
            return  # withdrawn before the tick
        target = Pose(*(((w ^ 0x8000) - 0x8000) / 100 for w in self.words[TARGET_AT:SPEED_AT]))
        motion = MotionType.PTP if command == 1 else MotionType.LINE
        seconds = self.model.motion_time(
            self.pose, target, speed_percent=self.words[SPEED_AT], motion=motion
        )
        self.words[MOTION] = 1  # moving, then the command cleared: the acknowledgement
        self.words[COMMAND_AT] = 0
        loop = asyncio.get_running_loop()
        end = loop.time() + seconds / self.time_scale
        loop.call_at(end + TICK_S - end % TICK_S, self._finish, target)

    def _finish(self, target: Pose) -> None:
        self.pose = target
        self._set_pose(target)
        self.words[MOTION] = 0


def serve_light(n: int, time_scale: float) -> None:
    """Child mode: ``n`` :class:`LightRobot` s on one loop, the same stdin protocol as serve."""
    logs: list[list[tuple[float, int, int]]] = [[] for _ in range(n)]

    async def main() -> None:
        loop = asyncio.get_running_loop()
        servers = [
            await loop.create_server(
                lambda log=log: LightRobot(time_scale, log),  # type: ignore[misc]
                "127.0.0.1",
                0,
            )
            for log in logs
        ]
        print(json.dumps({"ports": [s.sockets[0].getsockname()[1] for s in servers]}), flush=True)
        while True:
            line = (await loop.run_in_executor(None, sys.stdin.readline)).strip()
            if line == "clear":
                for log in logs:
                    log.clear()
                print("{}", flush=True)
            elif line == "dump":
                print(json.dumps(logs), flush=True)
            else:
                break
        for server in servers:
            server.close()

    asyncio.run(main())


def serve(n: int, time_scale: float) -> None:
    """Child mode: run ``n`` simulators, print their ports, dump request times on request."""
    from tmmaster.sim import Simulator

    # stdout carries the JSON protocol; tmmaster logs nothing unless configured to.
    sims = [Simulator("article", time_scale=time_scale).start() for _ in range(n)]
    try:
        print(json.dumps({"ports": [s.port for s in sims]}), flush=True)
        for line in sys.stdin:
            if line.strip() == "clear":
                for s in sims:
                    s.clear_request_log()
                print("{}", flush=True)
            elif line.strip() == "dump":
                dump = [[(r.time, r.function_code, r.address) for r in s.request_log] for s in sims]
                print(json.dumps(dump), flush=True)
            else:
                break
    finally:
        for s in sims:
            s.close()


class SimProcess:
    """The child process hosting the simulators."""

    def __init__(self, n: int, time_scale: float, cpus: list[int], slave: str = "sim") -> None:
        src = Path(__file__).resolve().parents[1] / "src"
        env = {**os.environ, "PYTHONPATH": f"{src}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
        cmd = [sys.executable, __file__, "--serve", str(n), "--time-scale", str(time_scale)]
        cmd += ["--slave", slave]
        if cpus:
            cmd += ["--cpus", ",".join(map(str, cpus))]
        self.proc = subprocess.Popen(
            cmd,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,  # the simulators' structlog output
            text=True,
            env=env,
        )
        self.ports: list[int] = []

    def wait_ready(self) -> None:
        """Read the ports the child listens on (it prints them once its simulators run)."""
        self.ports = self._ask(None)["ports"]

    def _ask(self, command: str | None) -> Any:
        assert self.proc.stdin is not None
        assert self.proc.stdout is not None
        if command is not None:
            self.proc.stdin.write(command + "\n")
            self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError("the simulator process ended unexpectedly")
        return json.loads(line)

    def clear(self) -> None:
        """Forget the requests received so far (connecting, homing)."""
        self._ask("clear")

    def requests(self) -> list[list[tuple[float, int, int]]]:
        """Per simulator: (arrival time, function code, address) of every request."""
        return [[(r[0], r[1], r[2]) for r in sim] for sim in self._ask("dump")]

    def close(self) -> None:
        """Stop the child and wait for it."""
        assert self.proc.stdin is not None
        try:
            self.proc.stdin.write("quit\n")
            self.proc.stdin.close()
        except OSError:
            pass
        self.proc.wait(10)


class SimFarm:
    """``n`` simulators in processes of ``per_process`` each."""

    def __init__(
        self, n: int, per_process: int, time_scale: float, cpus: list[int], slave: str = "sim"
    ) -> None:
        sizes = [per_process] * (n // per_process) + ([n % per_process] if n % per_process else [])
        self.processes: list[SimProcess] = []
        try:
            # Started together, then waited for: 40 children started one after the other
            # took over 75 s on a 16-core machine before the first move.
            for k in sizes:
                self.processes.append(SimProcess(k, time_scale, cpus, slave))
            for sims in self.processes:
                sims.wait_ready()
        except BaseException:
            self.close()
            raise
        self.ports = [port for sims in self.processes for port in sims.ports]

    def clear(self) -> None:
        """Forget the requests every simulator received so far."""
        for sims in self.processes:
            sims.clear()

    def requests(self) -> list[list[tuple[float, int, int]]]:
        """Per simulator, in port order: its requests."""
        return [log for sims in self.processes for log in sims.requests()]

    def close(self) -> None:
        """Stop every child."""
        for sims in self.processes:
            sims.close()


# -- the master side -----------------------------------------------------------------


@dataclass
class RobotRun:
    """What one robot measured."""

    overshoot_s: list[float] = field(default_factory=list)
    requests: int = 0
    error: BaseException | None = None


def drive(
    robot: Robot, moves: int, time_scale: float, start: threading.Barrier, delay_s: float = 0.0
) -> RobotRun:
    """One robot's work: wait for the others (and ``delay_s``), then drive the tour, timed."""
    run = RobotRun()
    try:
        start.wait(30)
        time.sleep(delay_s)
        before = robot.stats.requests
        for i in range(moves):
            target = TOUR[i % len(TOUR)]
            t0 = time.monotonic()
            motion = robot.move_to(target, speed=100)
            elapsed = time.monotonic() - t0
            run.overshoot_s.append(elapsed - motion.expected_s / time_scale)
        run.requests = robot.stats.requests - before
    except BaseException as exc:  # reported in the table; the benchmark must finish
        run.error = exc
    return run


def run_threads(
    robots: list[Robot], moves: int, time_scale: float, stagger_s: float = 0.0
) -> list[RobotRun]:
    """One plain thread per robot."""
    barrier = threading.Barrier(len(robots) + 1)
    results: list[RobotRun | None] = [None] * len(robots)

    def worker(i: int) -> None:
        delay = stagger_s * i / len(robots)
        results[i] = drive(robots[i], moves, time_scale, barrier, delay)

    threads = [threading.Thread(target=worker, args=(i,)) for i in range(len(robots))]
    for t in threads:
        t.start()
    barrier.wait(30)
    for t in threads:
        t.join()
    return [r for r in results if r is not None]


def run_asyncio(
    robots: list[Robot], moves: int, time_scale: float, stagger_s: float = 0.0
) -> list[RobotRun]:
    """Each robot's blocking calls in ``asyncio.to_thread``."""
    barrier = threading.Barrier(len(robots) + 1)

    async def main() -> list[RobotRun]:
        loop = asyncio.get_running_loop()
        # to_thread's default pool has min(32, cpus + 4) workers: with more robots than
        # that, robots would queue behind others (and the start barrier would never fill).
        # One worker per robot, plus one for this coroutine's own barrier wait.
        loop.set_default_executor(ThreadPoolExecutor(max_workers=len(robots) + 1))
        tasks = [
            asyncio.to_thread(drive, r, moves, time_scale, barrier, stagger_s * i / len(robots))
            for i, r in enumerate(robots)
        ]
        gathered = asyncio.gather(*tasks)
        await asyncio.to_thread(barrier.wait, 30)
        return list(await gathered)

    return asyncio.run(main())


@dataclass
class Row:
    """One line of the result table."""

    mode: str
    n: int
    wall_s: float
    overshoot_ms: list[float]
    poll_ms: list[float]
    cpu_percent: float
    requests_per_s: float
    errors: int
    first_error: str | None
    #: Fleet mode with --watch: what the fleet's status watch did.
    watch: str | None = None


def poll_intervals(requests: list[tuple[float, int, int]]) -> list[float]:
    """Intervals between successive status polls of one move.

    A move's polls run from its command write (FC16) to the pose read that ends it
    (FC3 at the pose registers); the status read before the next write is not a poll.
    """
    intervals: list[float] = []
    last: float | None = None
    active = False
    for arrived, fc, address in requests:
        if fc == 16:
            active, last = True, None
        elif (fc, address) == POSE_READ:
            active = False
        elif active and (fc, address) == STATUS_POLL:
            if last is not None:
                intervals.append(arrived - last)
            last = arrived
    return intervals


def measure(
    mode: str,
    n: int,
    moves: int,
    time_scale: float,
    per_process: int,
    sim_cpus: list[int],
    slave: str = "sim",
    stagger_s: float = 0.0,
    watch_hz: float = 0.0,
) -> Row:
    """Start n simulators, connect n robots, run the tour concurrently, measure."""
    sims = SimFarm(n, per_process or n, time_scale, sim_cpus, slave)
    fleet = Fleet(watch_hz=watch_hz or None) if mode == "fleet" else None
    robots = [
        Robot("127.0.0.1", port, profile="article", gripper=None, name=f"robot{i}", link=fleet)
        for i, port in enumerate(sims.ports)
    ]
    try:
        for robot in robots:
            robot.connect()
            robot.wait_until_ready(10.0)
        sims.clear()
        cpu0, wall0 = time.process_time(), time.monotonic()
        runner = run_asyncio if mode == "asyncio" else run_threads
        runs = runner(robots, moves, time_scale, stagger_s)
        wall = time.monotonic() - wall0
        cpu = time.process_time() - cpu0
        requests = sims.requests()
        watch = None
        if fleet is not None and fleet.watch_hz is not None:
            seen = [fleet.latest(robot) for robot in robots]
            watch = (
                f"watch: {sum(s.polls for s in seen)} reads,"
                f" {sum(s.skipped for s in seen)} slots skipped,"
                f" {sum(s.failures for s in seen)} failed (whole run, setup included)"
            )
    finally:
        for robot in robots:
            robot.close()
        if fleet is not None:
            fleet.close()
        sims.close()
    polls = [dt for sim in requests for dt in poll_intervals(sim)]
    return Row(
        mode=mode,
        n=n,
        wall_s=wall,
        overshoot_ms=[o * 1000 for r in runs for o in r.overshoot_s],
        poll_ms=[p * 1000 for p in polls],
        cpu_percent=100 * cpu / wall,
        requests_per_s=sum(r.requests for r in runs) / wall,
        errors=sum(r.error is not None for r in runs),
        first_error=next((repr(r.error) for r in runs if r.error is not None), None),
        watch=watch,
    )


def pct(values: list[float], q: float) -> float:
    """The q-th percentile (nearest rank); NaN for no values."""
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, round(q / 100 * (len(ordered) - 1)))]


def table(rows: list[Row]) -> str:
    """The results as a Markdown table."""
    head = (
        "| mode | N | wall s | overshoot ms mean / p95 / max | poll interval ms"
        " mean / p95 / max | master CPU % | requests/s | errors |\n"
        "|---|---|---|---|---|---|---|---|"
    )
    lines = [head]
    for r in rows:
        o, p = r.overshoot_ms, r.poll_ms
        lines.append(
            f"| {r.mode} | {r.n} | {r.wall_s:.2f}"
            f" | {statistics.fmean(o):.1f} / {pct(o, 95):.1f} / {max(o):.1f}"
            f" | {statistics.fmean(p):.1f} / {pct(p, 95):.1f} / {max(p):.1f}"
            f" | {r.cpu_percent:.1f} | {r.requests_per_s:.0f} | {r.errors} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, nargs="+", default=[1, 2, 4, 8])
    parser.add_argument("--moves", type=int, default=12)
    parser.add_argument("--time-scale", type=float, default=10.0)
    parser.add_argument("--repeat", type=int, default=1, help="runs per (mode, N)")
    parser.add_argument(
        "--mode",
        choices=["threads", "asyncio", "fleet", "both"],
        nargs="+",
        default=["threads"],
        help="both: threads and asyncio",
    )
    parser.add_argument("--json", action="store_true", help="also print raw rows as JSON")
    parser.add_argument(
        "--sims-per-process", type=int, default=0, help="simulators per process (0: all in one)"
    )
    parser.add_argument(
        "--slave",
        choices=["sim", "light"],
        default="sim",
        help="sim: tmmaster.sim simulators; light: minimal article-map robots (LightRobot)",
    )
    parser.add_argument(
        "--watch",
        type=float,
        default=0.0,
        metavar="HZ",
        help="fleet mode: the fleet also reads every robot's status HZ times a second",
    )
    parser.add_argument(
        "--stagger",
        type=float,
        default=0.0,
        metavar="S",
        help="spread the robots' first moves evenly over S seconds (0: all start together)",
    )
    add_pin_arguments(parser)
    parser.add_argument("--serve", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve is not None:
        pin_child(args)
        if args.slave == "light":
            serve_light(args.serve, args.time_scale)
        else:
            serve(args.serve, args.time_scale)
        return 0
    master_cpus, sim_cpus = pin_master(args)
    # tmmaster logs nothing unless configured to: no log output costs CPU or floods the table.
    modes = [
        m for mode in args.mode for m in (["threads", "asyncio"] if mode == "both" else [mode])
    ]
    rows = [
        measure(
            mode,
            n,
            args.moves,
            args.time_scale,
            args.sims_per_process,
            sim_cpus,
            args.slave,
            args.stagger,
            args.watch,
        )
        for n in args.n
        for mode in modes
        for _ in range(args.repeat)
    ]
    print(
        f"# {machine_line()}; time_scale {args.time_scale:g}, {args.moves} moves per robot,"
        f" poll {POLL_S * 1000:.0f} ms, first moves spread over {args.stagger:g} s,"
        f" fleet watch {args.watch:g} Hz,"
        f" {args.slave} slaves: {args.sims_per_process or 'all'} per"
        f" process, {pinning_line(master_cpus, sim_cpus)}"
    )
    print(table(rows))
    for r in rows:
        if r.watch:
            print(f"{r.mode} N={r.n}: {r.watch}")
        if r.first_error:
            print(f"{r.mode} N={r.n}: {r.errors} robot(s) failed, first: {r.first_error}")
    if args.json:
        print(json.dumps([r.__dict__ for r in rows]))
    return 1 if any(r.errors for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
