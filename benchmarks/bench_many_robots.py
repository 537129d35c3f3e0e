"""Many robots from one master process: poll jitter, CPU and poll rate, per design.

N simulated article-profile robots (N = 1, 25, 50, 100, 200, 400 by default) are
served by simulator *processes* (``--sims-per-process`` robots each, every robot on its
own loopback port); ONE master process polls every robot's status block at
``--rate`` Hz (20 Hz: one poll every 50 ms per robot, the robots' phases spread
evenly over the period). Per design of the master:

* ``threads``: one thread per :class:`tmmaster.Robot`, each calling ``Robot.status()``
  on its own drift-free schedule (the library's design: one thread per robot);
* ``pool``: 8 threads, each owning every 8th robot and issuing its robots' reads in due
  order (the ``scheduler`` design, 8 times over);
* ``scheduler``: ONE thread that owns every :class:`tmmaster.Robot` and issues their
  ``Robot.status()`` reads in due order from a heap (blocking reads, one at a time);
* ``asyncio``: ONE asyncio loop over pymodbus' ``AsyncModbusTcpClient``, one coroutine
  per robot reading the same 22-word status block. This is raw pymodbus (no decoding,
  none of tmmaster's logic): the ceiling a single event loop could reach, not a way to
  drive a robot safely.
* ``monitor``: :class:`tmmaster.StatusMonitor`, the library's read-only monitor: ONE
  thread, one event loop (asyncio's own here), one ``AsyncLink`` per robot (an
  asyncio protocol framed by pymodbus), each poll decoded into the same ``RobotStatus``
  as ``Robot.status()`` (jitter and response from the monitor's own schedule, through
  its private ``_timings`` record);
* ``monitor-uvloop``: the same monitor on uvloop's event loop (the ``monitor`` extra);
* ``fleet``: one :class:`tmmaster.Fleet` with ``watch_hz`` = the rate and every robot a
  connected :class:`tmmaster.Robot` of it: the robots can be driven (their links are the
  fleet's), and the fleet's loop (uvloop when installed) reads each one's status over
  that link (jitter and response from the watch's own schedule);
* ``selectors``: ONE thread, one non-blocking socket per robot, the FC3 request and
  answer framed with ``struct`` (no pymodbus, no tmmaster), every socket watched by one
  ``selectors`` loop: the least CPU a poll can cost from Python, i.e. what a shared
  poll scheduler over non-blocking links could reach at best. A poll whose slot comes
  while the robot's last answer is still awaited is counted as missed.

Figures per (design, N), each round ``--seconds`` long:

* jitter: how late each poll was issued after its due time (ms): p50, p99, max;
* response: time from issuing the read to having the answer (ms): p50, p99;
* rate: polls per robot per second achieved (the target is ``--rate``); a poll more
  than a period late is skipped, not sent in a burst, so saturation shows as a lower
  rate and ``missed`` slots;
* master CPU %: this process's CPU time / wall time (100 % = one core);
* sim CPU %: the simulator processes' CPU time / wall time, all of them together.

Where the machine has the cores (``--pin auto``: 8 or more usable CPUs), the master is
pinned to the first ``--master-cpus`` of them (2) and every simulator process to the rest,
the issue's setup (a master on 2 cores of a 16-core machine, simulators on the other 14).
Otherwise the simulators share the machine's cores with the master: on a 2-core machine
that is a pessimistic setup (real robots bring their own controllers). The simulators tick at
``--sim-tick-hz`` (default 10 Hz, not the TM's 50 Hz) so that N idle simulators do not
eat the cores the master is measured on; nothing here moves, so the tick only
publishes the pose.

``--profile tmflow`` polls tmflow-profile simulators instead (a status is six reads),
with the designs that decode a status.

Run::

    python benchmarks/bench_many_robots.py --quick          # N = 1 25 100, 3 s rounds
    python benchmarks/bench_many_robots.py --repeat 3       # the docs' table
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import functools
import heapq
import json
import math
import os
import selectors
import socket
import statistics
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from _machine import add_pin_arguments, machine_line, pin_child, pin_master, pinning_line
from _mbap import answer_frame, split_requests

from tmmaster import Fleet, MonitoredStatus, Robot, StatusMonitor
from tmmaster._transport import READ_FUNCTION, Transport
from tmmaster.sim import Timing

#: The article status block Robot.status() reads (FC3, address 0, 22 words).
STATUS_ADDRESS, STATUS_COUNT = 0, 22
DESIGNS = (
    "threads",
    "pool",
    "scheduler",
    "asyncio",
    "selectors",
    "monitor",
    "monitor-uvloop",
    "fleet",
)
#: Threads of the ``pool`` design.
POOL_THREADS = 8


# -- the simulator processes -----------------------------------------------------------


def serve(n: int, tick_hz: float, profile: str) -> None:
    """Child mode: run ``n`` simulators, print their ports, stay until stdin closes."""
    from tmmaster.sim import Simulator

    sims = [
        Simulator(profile, timing=Timing(tick_hz=tick_hz, init_time_s=0.0)).start()
        for _ in range(n)
    ]
    try:
        print(json.dumps({"ports": [s.port for s in sims]}), flush=True)
        sys.stdin.read()  # until the parent closes our stdin
    finally:
        for s in sims:
            s.close()


def idle_cost(n: int, tick_hz: float, seconds: float) -> str:
    """CPU % of ``n`` idle simulators in this process (no client), and one tick's CPU."""
    from tmmaster.sim import Simulator

    sims = [Simulator("article", timing=Timing(tick_hz=tick_hz)).start() for _ in range(n)]
    try:
        time.sleep(0.5)
        cpu0, wall0 = time.process_time(), time.monotonic()
        time.sleep(seconds)
        load = 100 * (time.process_time() - cpu0) / (time.monotonic() - wall0)
    finally:
        for s in sims:
            s.close()
    sim = Simulator("article")  # never started: its controller ticks in this thread
    controller = sim._controller
    for _ in range(50):
        controller.tick(0.02)
    cpu0 = time.process_time()
    for _ in range(2000):
        controller.tick(0.02)
    tick_us = (time.process_time() - cpu0) / 2000 * 1e6
    return (
        f"{n} idle simulators at {tick_hz:g} Hz in one process: {load:.0f} % of a core;"
        f" one idle control tick: {tick_us:.0f} µs of CPU"
    )


#: A light slave's answers: (function code, address, count) -> the answer's PDU.
Answers = dict[tuple[int, int, int], bytes]


class Responder(asyncio.Protocol):
    """A minimal Modbus TCP slave: answers reads from a fixed image.

    The article map: FC3 reads of a fixed image of its registers. Other profiles: the
    exact reads of a status (``answers``), snapshotted from a real simulator; any other
    request is refused. Not a simulator (nothing moves, no handshake): a slave cheap
    enough that the master, not the slaves, is what a run measures.
    """

    def __init__(self, image: bytes, answers: Answers | None = None) -> None:
        self.image = image
        self.answers = answers
        self.buffer = b""
        self.transport: asyncio.Transport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport

    def data_received(self, data: bytes) -> None:
        frames, self.buffer = split_requests(self.buffer + data)
        for frame in frames:
            fc = frame[7]
            assert self.transport is not None
            if self.answers is not None:
                key = (fc, *struct.unpack(">HH", frame[8:12]))
                pdu = self.answers.get(key) or struct.pack(">BB", fc | 0x80, 2)
            elif fc == 3:
                address, count = struct.unpack(">HH", frame[8:12])
                words = self.image[2 * address : 2 * (address + count)]
                words += bytes(2 * count - len(words))
                pdu = struct.pack(">BB", 3, len(words)) + words
            else:
                pdu = struct.pack(">BB", fc | 0x80, 1)  # illegal function
            self.transport.write(answer_frame(frame, pdu))


def status_answers(profile: str) -> Answers:
    """The answers to a status poll of ``profile``, read once from a real simulator."""
    from tmmaster.sim import Simulator

    answers: Answers = {}
    with Simulator(profile, timing=Timing(init_time_s=0.0)) as sim:
        robot = Robot("127.0.0.1", sim.port, profile=profile, gripper=None).connect()
        try:
            channel, transport = robot._channel, robot._transport
            assert isinstance(transport, Transport)  # a Modbus TCP link here
            plan = transport.read_plan(channel.status_fields, max_gap=channel.profile.max_read_gap)
            for block in plan.blocks:
                words = transport.read_block(block.table, block.address, block.count)
                function = READ_FUNCTION[block.table]
                if function in (1, 2):
                    packed = bytes(
                        sum(bit << i for i, bit in enumerate(words[k : k + 8]))
                        for k in range(0, len(words), 8)
                    )
                else:
                    packed = struct.pack(f">{len(words)}H", *words)
                answers[(function, block.address, block.count)] = (
                    struct.pack(">BB", function, len(packed)) + packed
                )
        finally:
            robot.close()
    return answers


def serve_light(n: int, profile: str = "article") -> None:
    """Child mode: ``n`` minimal responders on one asyncio loop."""
    image = bytearray(2 * 0x220)
    struct.pack_into(">HHHH", image, 0, 5, 0, 0, 0)  # mode auto, idle, no grasp, no error
    struct.pack_into(">6h", image, 2 * 0x10, 30000, -20000, 20000, 18000, 0, 9000)
    answers = None if profile == "article" else status_answers(profile)

    async def main() -> None:
        loop = asyncio.get_running_loop()
        servers = [
            await loop.create_server(lambda: Responder(bytes(image), answers), "127.0.0.1", 0)
            for _ in range(n)
        ]
        print(json.dumps({"ports": [s.sockets[0].getsockname()[1] for s in servers]}), flush=True)
        await loop.run_in_executor(None, sys.stdin.read)
        for s in servers:
            s.close()

    asyncio.run(main())


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class SimFarm:
    """Simulator processes serving ``n`` robots between them."""

    def __init__(
        self,
        n: int,
        per_process: int,
        tick_hz: float,
        slave: str,
        cpus: list[int] | None,
        profile: str = "article",
    ) -> None:
        src = Path(__file__).resolve().parents[1] / "src"
        env = {**os.environ, "PYTHONPATH": f"{src}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
        sizes = [per_process] * (n // per_process) + ([n % per_process] if n % per_process else [])
        self.procs = [
            subprocess.Popen(
                [sys.executable, __file__, "--serve", str(k), "--sim-tick-hz", str(tick_hz)]
                + (["--slave", "light"] if slave == "light" else [])
                + (["--cpus", ",".join(map(str, cpus))] if cpus else [])
                + ["--profile", profile],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                text=True,
                env=env,
            )
            for k in sizes
        ]
        self.ports: list[int] = []
        for proc in self.procs:
            assert proc.stdout is not None
            line = proc.stdout.readline()
            if not line:
                self.close()
                raise RuntimeError("a simulator process ended unexpectedly")
            self.ports += json.loads(line)["ports"]

    def cpu(self) -> float:
        """CPU seconds used so far by all simulator processes."""
        return sum(cpu_seconds(p.pid) for p in self.procs)

    def close(self) -> None:
        """End every simulator process and wait for it."""
        for proc in self.procs:
            assert proc.stdin is not None
            with contextlib.suppress(OSError):
                proc.stdin.close()
        for proc in self.procs:
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5)


# -- the master designs ----------------------------------------------------------------


@dataclass
class Samples:
    """What one round measured."""

    lateness_s: list[float] = field(default_factory=list)
    response_s: list[float] = field(default_factory=list)
    missed: int = 0
    errors: int = 0
    first_error: str | None = None

    def merge(self, other: Samples) -> None:
        """Add another's samples to these."""
        self.lateness_s += other.lateness_s
        self.response_s += other.response_s
        self.missed += other.missed
        self.errors += other.errors
        self.first_error = self.first_error or other.first_error


def next_due(due: float, period: float, now: float, samples: Samples) -> float:
    """The next due time after ``due``; slots already more than a period past are skipped."""
    due += period
    if now - due > period:
        skipped = math.floor((now - due) / period)
        samples.missed += skipped
        due += skipped * period
    return due


def poll_robot(robot: Robot, samples: Samples) -> None:
    """One timed ``Robot.status()``; a failure is counted, not raised."""
    sent = time.monotonic()
    try:
        robot.status()
    except Exception as exc:  # reported in the table; the benchmark must finish
        samples.errors += 1
        samples.first_error = samples.first_error or repr(exc)
        return
    samples.response_s.append(time.monotonic() - sent)


def run_threads(robots: list[Robot], period: float, start: float, end: float) -> Samples:
    """One thread per robot, each on its own schedule."""
    per_robot = [Samples() for _ in robots]

    def worker(i: int) -> None:
        robot, samples = robots[i], per_robot[i]
        due = start + period * i / len(robots)
        while due < end:
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            samples.lateness_s.append(time.monotonic() - due)
            poll_robot(robot, samples)
            due = next_due(due, period, time.monotonic(), samples)

    threads = [threading.Thread(target=worker, args=(i,)) for i in range(len(robots))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    total = Samples()
    for s in per_robot:
        total.merge(s)
    return total


def run_scheduler(robots: list[Robot], period: float, start: float, end: float) -> Samples:
    """One thread issuing every robot's reads in due order."""
    samples = Samples()
    heap = [(start + period * i / len(robots), i) for i in range(len(robots))]
    heapq.heapify(heap)
    while heap:
        due, i = heapq.heappop(heap)
        if due >= end:
            continue
        delay = due - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        samples.lateness_s.append(time.monotonic() - due)
        poll_robot(robots[i], samples)
        heapq.heappush(heap, (next_due(due, period, time.monotonic(), samples), i))
    return samples


def run_pool(robots: list[Robot], period: float, start: float, end: float) -> Samples:
    """A few threads, each running the one-thread scheduler over its share of the robots."""
    k = min(POOL_THREADS, len(robots))
    results: list[Samples] = [Samples() for _ in range(k)]

    def worker(j: int) -> None:
        share = robots[j::k]
        # Phases stay spread over the period across all robots, as in the other designs.
        offset = period * j / len(robots)
        results[j] = run_scheduler(share, period, start + offset, end)

    threads = [threading.Thread(target=worker, args=(j,)) for j in range(k)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    total = Samples()
    for s in results:
        total.merge(s)
    return total


def run_asyncio(
    ports: list[int], period: float, seconds: float, sim_cpu: Callable[[], float]
) -> tuple[Samples, float, float, float]:
    """One event loop, one raw pymodbus async client per robot.

    Returns (samples, master CPU s, wall s, simulators' CPU s), all over the polling only.
    """
    from pymodbus.client import AsyncModbusTcpClient

    async def main() -> tuple[Samples, float, float, float]:
        clients = [AsyncModbusTcpClient("127.0.0.1", port=p, retries=0, timeout=1.0) for p in ports]
        for c in clients:
            if not await c.connect():
                raise RuntimeError("asyncio client could not connect")
        loop = asyncio.get_running_loop()
        samples = Samples()
        start = time.monotonic() + 0.2
        end = start + seconds - period / 2  # exactly rate x seconds slots per robot

        async def robot(i: int) -> None:
            client = clients[i]
            due = start + period * i / len(clients)
            while due < end:
                delay = due - time.monotonic()
                if delay > 0:
                    await asyncio.sleep(delay)
                sent = time.monotonic()
                samples.lateness_s.append(sent - due)
                try:
                    answer = await client.read_holding_registers(
                        STATUS_ADDRESS, count=STATUS_COUNT, device_id=1
                    )
                    if answer.isError():
                        raise RuntimeError(f"device refused: {answer}")
                    samples.response_s.append(time.monotonic() - sent)
                except Exception as exc:
                    samples.errors += 1
                    samples.first_error = samples.first_error or repr(exc)
                due = next_due(due, period, time.monotonic(), samples)

        del loop
        sim0, cpu0, wall0 = sim_cpu(), time.process_time(), time.monotonic()
        await asyncio.gather(*(robot(i) for i in range(len(clients))))
        cpu, wall = time.process_time() - cpu0, time.monotonic() - wall0
        sims = sim_cpu() - sim0
        for c in clients:
            c.close()
        return samples, cpu, wall, sims

    return asyncio.run(main())


def run_selectors(
    ports: list[int], period: float, seconds: float, sim_cpu: Callable[[], float]
) -> tuple[Samples, float, float, float]:
    """One thread, one non-blocking socket per robot, one ``selectors`` loop.

    Returns (samples, master CPU s, wall s, simulators' CPU s), all over the polling only.
    """
    selector = selectors.DefaultSelector()
    links: list[socket.socket] = []
    for i, port in enumerate(ports):
        link = socket.create_connection(("127.0.0.1", port), timeout=5)
        link.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        link.setblocking(False)
        selector.register(link, selectors.EVENT_READ, i)
        links.append(link)
    n = len(links)
    answer_size = 9 + 2 * STATUS_COUNT  # MBAP (7) + function code + byte count + words
    words_format = f">{STATUS_COUNT}H"
    sent_at: list[float | None] = [None] * n
    tids = [0] * n
    buffers = [b""] * n
    samples = Samples()
    start = time.monotonic() + 0.2
    end = start + seconds - period / 2  # exactly rate x seconds slots per robot
    heap = [(start + period * i / n, i) for i in range(n)]
    heapq.heapify(heap)
    sim0, cpu0, wall0 = sim_cpu(), time.process_time(), time.monotonic()
    try:
        while True:
            now = time.monotonic()
            while heap and heap[0][0] <= now:
                due, i = heapq.heappop(heap)
                if due >= end:
                    continue
                if sent_at[i] is not None:
                    samples.missed += 1  # the last answer is still awaited
                else:
                    samples.lateness_s.append(now - due)
                    tids[i] = (tids[i] + 1) & 0xFFFF
                    links[i].send(
                        struct.pack(">HHHBBHH", tids[i], 0, 6, 1, 3, STATUS_ADDRESS, STATUS_COUNT)
                    )
                    sent_at[i] = now
                heapq.heappush(heap, (next_due(due, period, now, samples), i))
            waiting = [t for t in sent_at if t is not None]
            if not heap and not waiting:
                break
            if waiting and now - min(waiting) > 1.0:
                samples.errors += sum(1 for t in waiting if now - t > 1.0)
                samples.first_error = samples.first_error or "no answer within 1 s"
                sent_at = [None if t is not None and now - t > 1.0 else t for t in sent_at]
            timeout = max(0.0, heap[0][0] - now) if heap else 0.05
            for key, _events in selector.select(timeout):
                i = key.data
                buffers[i] += links[i].recv(4096)
                while len(buffers[i]) >= answer_size:
                    frame, buffers[i] = buffers[i][:answer_size], buffers[i][answer_size:]
                    tid, _proto, _length, _unit, fc, _count = struct.unpack(">HHHBBB", frame[:9])
                    sent = sent_at[i]
                    if fc != 3 or tid != tids[i] or sent is None:
                        samples.errors += 1
                        samples.first_error = samples.first_error or f"bad answer {frame!r}"
                        continue
                    struct.unpack(words_format, frame[9:])  # the status words, decoded
                    samples.response_s.append(time.monotonic() - sent)
                    sent_at[i] = None
        cpu, wall = time.process_time() - cpu0, time.monotonic() - wall0
        return samples, cpu, wall, sim_cpu() - sim0
    finally:
        selector.close()
        for link in links:
            link.close()


def watched_round(
    seen: Callable[[], list[MonitoredStatus]],
    timings: list[tuple[float, float]],
    seconds: float,
    sim_cpu: Callable[[], float],
) -> tuple[Samples, float, float, float]:
    """Measure ``seconds`` of a running watch: what ``seen()`` and ``timings`` record.

    Returns (samples, master CPU s, wall s, simulators' CPU s), over the polling only.
    """
    time.sleep(0.2)  # the first slots of every robot
    before = seen()
    del timings[:]
    sim0, cpu0, wall0 = sim_cpu(), time.process_time(), time.monotonic()
    time.sleep(seconds)
    cpu, wall = time.process_time() - cpu0, time.monotonic() - wall0
    sims = sim_cpu() - sim0
    taken = list(timings)
    after = seen()
    samples = Samples(
        lateness_s=[late for late, _ in taken],
        response_s=[response for _, response in taken],
        missed=sum(a.skipped - b.skipped for a, b in zip(after, before, strict=True)),
        errors=sum(a.failures - b.failures for a, b in zip(after, before, strict=True)),
    )
    failed = [s.error for s in after if s.error is not None]
    samples.first_error = repr(failed[0]) if failed else None
    return samples, cpu, wall, sims


def run_monitor(
    ports: list[int],
    period: float,
    seconds: float,
    sim_cpu: Callable[[], float],
    event_loop: Literal["asyncio", "uvloop"] = "asyncio",
    profile: str = "article",
) -> tuple[Samples, float, float, float]:
    """One :class:`tmmaster.StatusMonitor` over every robot (one thread, one event loop).

    Measured after ``start()``: the links are open and the schedules running.
    """
    monitor = StatusMonitor(rate_hz=1.0 / period, timeout_s=1.0, event_loop=event_loop)
    for i, port in enumerate(ports):
        monitor.add(f"robot{i}", "127.0.0.1", port, profile=profile)
    timings: list[tuple[float, float]] = []
    monitor._timings = timings  # lateness and response of every answered poll
    with monitor:
        return watched_round(lambda: list(monitor.snapshot().values()), timings, seconds, sim_cpu)


def run_fleet(
    ports: list[int],
    period: float,
    seconds: float,
    sim_cpu: Callable[[], float],
    profile: str = "article",
) -> tuple[Samples, float, float, float]:
    """One :class:`tmmaster.Fleet` watching every robot at the rate (robots that can be driven).

    Each robot is a connected :class:`tmmaster.Robot` of the fleet, idle: the fleet's loop
    reads its status over the robot's own link (``watch_hz``), as ``run_monitor`` does
    over links of its own.
    """
    fleet = Fleet(watch_hz=1.0 / period)
    timings: list[tuple[float, float]] = []
    fleet._timings = timings  # lateness and response of every answered watch read
    with fleet:
        robots = [
            Robot("127.0.0.1", port, profile=profile, gripper=None, name=f"robot{i}", link=fleet)
            for i, port in enumerate(ports)
        ]
        for robot in robots:
            robot.connect()
        return watched_round(
            lambda: [fleet.latest(robot) for robot in robots], timings, seconds, sim_cpu
        )


# -- measuring -------------------------------------------------------------------------


@dataclass
class Row:
    """One line of the result table."""

    design: str
    n: int
    round: int
    wall_s: float
    polls: int
    jitter_ms: tuple[float, float, float]
    response_ms: tuple[float, float]
    rate_hz: float
    missed: int
    master_cpu: float
    sim_cpu: float
    errors: int
    first_error: str | None


def pct(values: list[float], q: float) -> float:
    """The q-th percentile (nearest rank); NaN for no values."""
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, math.ceil(q / 100 * len(ordered)) - 1)]


def measure(
    design: str,
    farm: SimFarm,
    n: int,
    rate: float,
    seconds: float,
    round_: int,
    profile: str = "article",
) -> Row:
    """One round of one design against the running simulators."""
    period = 1.0 / rate
    loops: dict[str, Callable[..., tuple[Samples, float, float, float]]] = {
        "asyncio": run_asyncio,
        "selectors": run_selectors,
        "monitor": functools.partial(run_monitor, profile=profile),
        "monitor-uvloop": functools.partial(run_monitor, event_loop="uvloop", profile=profile),
        "fleet": functools.partial(run_fleet, profile=profile),
    }
    if design in loops:
        samples, cpu, wall, sim_cpu = loops[design](farm.ports, period, seconds, farm.cpu)
    else:
        robots = [
            Robot("127.0.0.1", port, profile=profile, gripper=None, name=f"robot{i}")
            for i, port in enumerate(farm.ports)
        ]
        try:
            for robot in robots:
                robot.connect()
                robot.status()  # the read plan is built before the clock starts
            start = time.monotonic() + 0.2
            end = start + seconds - period / 2  # exactly rate x seconds slots per robot
            runner = {"threads": run_threads, "pool": run_pool, "scheduler": run_scheduler}[design]
            sim0, cpu0, wall0 = farm.cpu(), time.process_time(), time.monotonic()
            samples = runner(robots, period, start, end)
            cpu, wall = time.process_time() - cpu0, time.monotonic() - wall0
            sim_cpu = farm.cpu() - sim0
        finally:
            for robot in robots:
                robot.close()
    lateness = [x * 1000 for x in samples.lateness_s]
    response = [x * 1000 for x in samples.response_s]
    return Row(
        design=design,
        n=n,
        round=round_,
        wall_s=wall,
        polls=len(samples.response_s),
        jitter_ms=(pct(lateness, 50), pct(lateness, 99), max(lateness, default=float("nan"))),
        response_ms=(pct(response, 50), pct(response, 99)),
        # Answered polls per slot: polls skipped for lateness count as not achieved.
        rate_hz=rate * len(samples.response_s) / max(1, len(lateness) + samples.missed),
        missed=samples.missed,
        master_cpu=100 * cpu / wall,
        sim_cpu=100 * sim_cpu / wall,
        errors=samples.errors,
        first_error=samples.first_error,
    )


def table(rows: list[Row]) -> str:
    """The results as a Markdown table, one line per round."""
    lines = [
        "| design | N | round | jitter ms p50 / p99 / max | response ms p50 / p99"
        " | polls/s per robot | missed | master CPU % | sim CPU % | errors |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        j, p = r.jitter_ms, r.response_ms
        lines.append(
            f"| {r.design} | {r.n} | {r.round} | {j[0]:.2f} / {j[1]:.2f} / {j[2]:.1f}"
            f" | {p[0]:.2f} / {p[1]:.2f} | {r.rate_hz:.2f} | {r.missed}"
            f" | {r.master_cpu:.0f} | {r.sim_cpu:.0f} | {r.errors} |"
        )
    return "\n".join(lines)


def summary(rows: list[Row]) -> str:
    """Median of the rounds per (design, N), with the range of the p99 jitter."""
    lines = [
        "| design | N | jitter p50 ms | jitter p99 ms (range) | jitter max ms"
        " | polls/s per robot | master CPU % (range) | sim CPU % |",
        "|---|---|---|---|---|---|---|---|",
    ]
    keys = sorted({(r.n, DESIGNS.index(r.design)) for r in rows})
    for n, d in keys:
        rs = [r for r in rows if r.n == n and r.design == DESIGNS[d]]

        def med(values: list[float]) -> float:
            return statistics.median(values)

        p99 = [r.jitter_ms[1] for r in rs]
        cpu = [r.master_cpu for r in rs]
        lines.append(
            f"| {DESIGNS[d]} | {n} | {med([r.jitter_ms[0] for r in rs]):.2f}"
            f" | {med(p99):.2f} ({min(p99):.2f}-{max(p99):.2f})"
            f" | {med([r.jitter_ms[2] for r in rs]):.1f}"
            f" | {med([r.rate_hz for r in rs]):.2f}"
            f" | {med(cpu):.0f} ({min(cpu):.0f}-{max(cpu):.0f})"
            f" | {med([r.sim_cpu for r in rs]):.0f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, nargs="+", default=[1, 25, 50, 100, 200, 400])
    parser.add_argument("--design", choices=[*DESIGNS, "all"], nargs="+", default=["all"])
    parser.add_argument("--rate", type=float, default=20.0, help="polls per robot per second")
    parser.add_argument("--seconds", type=float, default=5.0, help="length of one round")
    parser.add_argument("--repeat", type=int, default=3, help="rounds per (design, N)")
    parser.add_argument("--sims-per-process", type=int, default=50)
    parser.add_argument("--sim-tick-hz", type=float, default=10.0)
    parser.add_argument(
        "--slave",
        choices=["sim", "light"],
        default="sim",
        help="sim: tmmaster.sim simulators; light: minimal read-only responders",
    )
    parser.add_argument("--quick", action="store_true", help="N = 1 25 100, 3 s, 1 round")
    parser.add_argument("--json", action="store_true", help="also print raw rows as JSON")
    parser.add_argument(
        "--idle-cost",
        type=int,
        metavar="N",
        help="only measure what N idle simulators cost in one process, and exit",
    )
    parser.add_argument(
        "--profile",
        choices=["article", "tmflow"],
        default="article",
        help="the robots' profile (tmflow: the designs that decode a status, i.e. threads,"
        " pool, scheduler, monitor, monitor-uvloop; its light slaves answer a status poll's"
        " reads as a real simulator answered them once)",
    )
    add_pin_arguments(parser)
    parser.add_argument("--serve", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.serve is not None:
        pin_child(args)
        if args.slave == "light":
            serve_light(args.serve, args.profile)
        else:
            serve(args.serve, args.sim_tick_hz, args.profile)
        return 0
    if args.idle_cost is not None:
        print(idle_cost(args.idle_cost, args.sim_tick_hz, args.seconds))
        return 0
    if args.quick:
        args.n, args.seconds, args.repeat = [1, 25, 100], 3.0, 1
    designs = list(DESIGNS) if "all" in args.design else args.design
    if args.profile != "article":
        raw = {"asyncio", "selectors"} & set(designs)
        if raw and "all" not in args.design:
            parser.error(f"--profile {args.profile}: the raw designs read the article map only")
        designs = [d for d in designs if d not in ("asyncio", "selectors")]
    master_cpus, sim_cpus = pin_master(args)
    rows: list[Row] = []
    for n in args.n:
        farm = SimFarm(
            n, args.sims_per_process, args.sim_tick_hz, args.slave, sim_cpus, args.profile
        )
        try:
            for round_ in range(1, args.repeat + 1):
                for design in designs:
                    rows.append(
                        measure(design, farm, n, args.rate, args.seconds, round_, args.profile)
                    )
                    print(table(rows[-1:]).splitlines()[-1], file=sys.stderr, flush=True)
        finally:
            farm.close()
    print(
        f"# {machine_line()}; {args.profile} profile, {args.rate:g} Hz polling,"
        f" {args.seconds:g} s rounds, simulators: {args.sims_per_process} per process,"
        f" {args.sim_tick_hz:g} Hz tick, same machine, {pinning_line(master_cpus, sim_cpus)}"
    )
    print(summary(rows))
    print()
    print(table(rows))
    for r in rows:
        if r.first_error:
            print(f"{r.design} N={r.n}: {r.errors} failed polls, first: {r.first_error}")
    if args.json:
        print(json.dumps([r.__dict__ for r in rows]))
    return 1 if any(r.errors for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
