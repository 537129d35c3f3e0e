"""Master CPU per request: tmmaster against raw pymodbus, same simulator, same run.

The simulator runs in another process (``python -m tmmaster.sim``), so only the
master's CPU time (``time.process_time``) is measured. For each profile:

* a status snapshot: ``Robot.status()`` against the same blocks read with
  ``pymodbus.client.ModbusTcpClient`` calls, CPU per request, the two measured in
  alternating batches (ABBA) so that the machine's drift during a round weighs on both
  (the moves below stay back to back: pausing between them would change what a move
  reads);
* whole moves: CPU per request while ``Robot.move_to`` runs (polls, the write, the
  final checks), against the raw status read's CPU per request; after one warm-up
  move to each pose (the first moves solve inverse kinematics, which is then cached);
* the same, against raw pymodbus reads paced like the moves' requests: a request that
  follows a sleep costs several times the CPU of one sent back to back (cold caches,
  the thread's wake-up), and a move's polls follow sleeps. The moves are run once more
  with the start time of every request on the robot's link recorded (the driver's polls
  and the tmflow heartbeat's writes included: a raw master does them too), and raw
  status reads are sent with the same gaps. "paced ratio": the moves' CPU per request
  over the raw master's whole CPU per request (its wake-ups from the sleeps included,
  as the moves' are); "request only": over the CPU of the raw reads alone.

A move's requests are every request sent on the robot's link while it runs (the
heartbeat's writes included); its CPU is the whole process's, planning included.

Each figure is the median of ``--rounds`` rounds; the budget (docs/architecture.md):
the moves' CPU per request within 1.5 times the paced raw master's. Run::

    python benchmarks/bench_hot_path.py --reads 2000 --moves 20 --rounds 5
"""

from __future__ import annotations

import argparse
import itertools
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from typing import Any

from _machine import machine_line
from pymodbus.client import ModbusTcpClient

import tmmaster
from tmmaster import Pose

A = Pose(300, -200, 200, 180, 0, 90)
B = Pose(300, -200, 120, 180, 0, 90)

#: The blocks Robot.status() reads, per profile (checked against the request log in
#: tests/test_robot.py): (function code, address, count).
STATUS_BLOCKS = {
    "article": [(3, 0, 22)],
    "tmflow": [(2, 7201, 5), (2, 7207, 2), (4, 7025, 12), (4, 7101, 2), (4, 7320, 2), (3, 9100, 6)],
}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def interleaved_cpu_per_call(
    first: Callable[[], object], second: Callable[[], object], calls: int, batches: int = 20
) -> tuple[float, float]:
    """CPU per call of ``first`` and of ``second``, measured in alternating batches.

    The batches run in ABBA order, so a machine that speeds up or slows down during the
    measurement (other load, frequency changes, the peer process sleeping) weighs on
    both alike instead of on whichever ran last.
    """
    per_batch = max(1, calls // batches)
    totals = [0.0, 0.0]
    for batch in range(batches):
        order = (0, 1) if batch % 2 == 0 else (1, 0)
        for which in order:
            fn = (first, second)[which]
            started = time.process_time()
            for _ in range(per_batch):
                fn()
            totals[which] += time.process_time() - started
    return totals[0] / (per_batch * batches), totals[1] / (per_batch * batches)


def status_blocks(
    client: ModbusTcpClient, profile: str
) -> list[tuple[Callable[..., Any], int, int]]:
    """The profile's status blocks as (raw pymodbus read method, address, count)."""
    readers = {
        1: client.read_coils,
        2: client.read_discrete_inputs,
        3: client.read_holding_registers,
        4: client.read_input_registers,
    }
    return [(readers[fc], address, count) for fc, address, count in STATUS_BLOCKS[profile]]


def raw_status(client: ModbusTcpClient, profile: str) -> Callable[[], None]:
    blocks = status_blocks(client, profile)

    def read() -> None:
        for reader, address, count in blocks:
            response = reader(address, count=count, device_id=1)
            assert not response.isError()

    return read


def paced_raw(client: ModbusTcpClient, profile: str, gaps: list[float]) -> tuple[float, float]:
    """CPU per raw status-block read, each sent ``gaps[i]`` s after the previous one started.

    Returns:
        (the whole paced loop's CPU, its wake-ups included; the reads' CPU alone), per read.
    """
    blocks = status_blocks(client, profile)
    cpu = 0.0
    due = time.monotonic()
    whole = time.process_time()
    for i, gap in enumerate(gaps):
        due += gap
        delay = due - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        reader, address, count = blocks[i % len(blocks)]
        started = time.process_time()
        response = reader(address, count=count, device_id=1)
        cpu += time.process_time() - started
        assert not response.isError()
    whole = time.process_time() - whole
    return whole / len(gaps), cpu / len(gaps)


def sent_on_link(robot: tmmaster.Robot) -> int:
    """Requests sent on the robot's link so far (the heartbeat's, not in ``stats``, too)."""
    stream = robot._transport._link._stream  # type: ignore[attr-defined]
    return int(stream.sent)


def request_gaps(robot: tmmaster.Robot, moves: int) -> list[float]:
    """Run ``moves`` moves and return the gaps between the starts of their requests."""
    link = robot._transport._link  # type: ignore[attr-defined]
    starts: list[float] = []
    start = link.start

    def recorded(*args: object) -> object:
        starts.append(time.monotonic())
        return start(*args)

    link.start = recorded
    try:
        for i in range(moves):
            robot.move_to(B if i % 2 == 0 else A, speed=50)
    finally:
        del link.start
    return [0.0] + [b - a for a, b in itertools.pairwise(starts)]


def measure(profile: str, reads: int, moves: int, time_scale: float) -> dict[str, float]:
    port = free_port()
    sim = subprocess.Popen(
        [
            sys.executable, "-m", "tmmaster.sim", "--profile", profile, "--port", str(port),
            "--time-scale", str(time_scale), "--log-level", "error",
        ],
        stdout=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 20
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)
        requests_per_status = len(STATUS_BLOCKS[profile])
        with tmmaster.Robot("127.0.0.1", port, profile=profile, gripper=None) as robot:
            robot.wait_until_ready(timeout_s=10)
            client = ModbusTcpClient("127.0.0.1", port=port, retries=0)
            client.connect()
            try:
                raw, ours = interleaved_cpu_per_call(
                    raw_status(client, profile), robot.status, reads
                )
            finally:
                client.close()
            raw /= requests_per_status
            ours /= requests_per_status
            robot.move_to(B, speed=50)  # warm-up: each pose solved once
            robot.move_to(A, speed=50)
            before_requests, before_cpu = sent_on_link(robot), time.process_time()
            for i in range(moves):
                robot.move_to(B if i % 2 == 0 else A, speed=50)
            move_requests = sent_on_link(robot) - before_requests
            move_cpu = (time.process_time() - before_cpu) / move_requests
            gaps = request_gaps(robot, moves)
            client = ModbusTcpClient("127.0.0.1", port=port, retries=0)
            client.connect()
            try:
                raw_paced, raw_alone = paced_raw(client, profile, gaps)
            finally:
                client.close()
    finally:
        sim.terminate()
        sim.wait(10)
    return {
        "raw_us": raw * 1e6,
        "status_us": ours * 1e6,
        "status_ratio": ours / raw,
        "move_us": move_cpu * 1e6,
        "move_ratio": move_cpu / raw,
        "requests_per_move": move_requests / moves,
        "move_ms": move_cpu * move_requests / moves * 1e3,
        "paced_us": raw_paced * 1e6,
        "paced_ratio": move_cpu / raw_paced,
        "alone_ratio": move_cpu / raw_alone,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reads", type=int, default=2000)
    parser.add_argument("--moves", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--time-scale", type=float, default=5.0)
    args = parser.parse_args(argv)
    print(f"# {machine_line()}")
    print("| profile | raw pymodbus µs/req | Robot.status µs/req | ratio |"
          " during moves µs/req | ratio | requests/move | CPU ms/move |"
          " raw paced µs/req | paced ratio | request only |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for profile in ("article", "tmflow"):
        rounds = [
            measure(profile, args.reads, args.moves, args.time_scale) for _ in range(args.rounds)
        ]
        med = {k: statistics.median(r[k] for r in rounds) for k in rounds[0]}
        spread = {k: (min(r[k] for r in rounds), max(r[k] for r in rounds)) for k in rounds[0]}
        status_lo, status_hi = spread["status_ratio"]
        move_lo, move_hi = spread["move_ratio"]
        paced_lo, paced_hi = spread["paced_ratio"]
        print(
            f"| {profile} | {med['raw_us']:.0f} | {med['status_us']:.0f} |"
            f" {med['status_ratio']:.2f} ({status_lo:.2f}-{status_hi:.2f}) |"
            f" {med['move_us']:.0f} | {med['move_ratio']:.2f} ({move_lo:.2f}-{move_hi:.2f}) |"
            f" {med['requests_per_move']:.1f} | {med['move_ms']:.2f} |"
            f" {med['paced_us']:.0f} | {med['paced_ratio']:.2f} ({paced_lo:.2f}-{paced_hi:.2f}) |"
            f" {med['alone_ratio']:.2f} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
