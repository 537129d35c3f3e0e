"""Move-to-move gap and completion latency, with predictive polling on and off.

Real time (time scale 1), 50 ms nominal polling, the simulator in-process on loopback
TCP (its 50 Hz control tick is part of what is measured). For consecutive moves i, i+1:

* gap = when the robot started move i+1 (the simulator's motion log) minus when move i
  really ended (its start + the expected time / the speed factor: the simulator's arm
  is the model's, ``--speed-factor`` times faster, which the master does not know): the
  slave's tick that reports the end, the master's detection, its checks before the
  next write, and the slave's tick that takes it;
* seen = when the master's poll that saw move i finished returned
  (``Motion.reported_finished_at``) minus when the simulator's tick reported it
  finished (``MotionRecord.done_wall_time``); the same clock, both in this process.
  The target: within one robot tick (20 ms);
* requests per move, from the transport's counters, and status reads per move (the
  simulator's log: the read that starts a poll, article 0x0000, tmflow 9100): the
  polls a move costs.

Run (``--speed-factor 0.5 1 2``: a slave twice as slow, as the model, twice as fast)::

    python benchmarks/bench_move_gap.py --moves 12 --rounds 3 --speed-factor 0.5 1 2
"""

from __future__ import annotations

import argparse
import statistics
import sys

import tmmaster
from tmmaster import PollPolicy, Pose
from tmmaster.sim import Cell, Simulator

#: The upper end of the moves: up to 190 mm down from it, the pads stay above the
#: simulated table (85 mm; they reach 12 mm below the TCP).
A = Pose(300, -200, 300, 180, 0, 90)
#: The first address of a profile's status read: one per poll.
STATUS_READ = {"article": 0x0000, "tmflow": 9100}


def measure(
    profile: str,
    predictive: bool,
    moves: int,
    speed_factor: float = 1.0,
    dz: float = 80.0,
    speed: int = 60,
) -> tuple[list[float], list[float], float, float]:
    b = A.offset(dz=-dz)
    with Simulator(profile, time_scale=1.0, cell=Cell(speed_factor=speed_factor)) as sim:
        with tmmaster.Robot(
            "127.0.0.1",
            sim.port,
            profile=profile,
            gripper=None,
            polling=PollPolicy(predictive=predictive),
        ) as robot:
            robot.wait_until_ready(timeout_s=10)
            robot.move_to(A, speed=60)
            expected: list[float] = []
            seen_at: list[float] = []
            before = robot.stats.requests
            sim.clear_request_log()
            for i in range(moves):
                motion = robot.move_to(b if i % 2 == 0 else A, speed=speed)
                expected.append(motion.expected_s)
                assert motion.reported_finished_at is not None
                seen_at.append(motion.reported_finished_at)
            requests = (robot.stats.requests - before) / moves
            polls = sum(
                r.function_code in (3, 4) and r.address == STATUS_READ[profile]
                for r in sim.request_log
            )
        log = [m for m in sim.motion_log() if m.target is not None][1:]
    gaps = [
        log[i + 1].wall_time - (log[i].wall_time + expected[i] / speed_factor)
        for i in range(len(log) - 1)
    ]
    seen: list[float] = []
    for record, at in zip(log, seen_at, strict=True):
        assert record.done_wall_time is not None
        # Never seen finished before the slave reported it (the arm still moving).
        early = record.done_wall_time - at
        assert early <= 0, f"seen finished {early:.3f} s before the slave said so"
        seen.append(at - record.done_wall_time)
    return gaps, seen, requests, polls / moves


def ms(values: list[float]) -> str:
    """p50 | p90 | max of ``values`` (s) in ms, as table cells."""
    q = statistics.quantiles([v * 1000 for v in values], n=10)
    return f"{statistics.median(values) * 1000:.0f} | {q[8]:.0f} | {max(values) * 1000:.0f}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--moves", type=int, default=12)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument(
        "--speed-factor",
        type=float,
        nargs="+",
        default=[1.0],
        metavar="K",
        help="the simulated arm is K times faster than the model the master plans with",
    )
    parser.add_argument("--profile", nargs="+", default=["article", "tmflow"])
    parser.add_argument(
        "--dz", type=float, default=80.0, help="the moves' length, mm (down and up; max 190)"
    )
    parser.add_argument("--speed", type=int, default=60, help="the moves' speed, %%")
    args = parser.parse_args(argv)
    print(
        "| slave speed | profile | polling | gap p50 ms | gap p90 ms | gap max ms"
        " | seen p50 ms | seen p90 ms | seen max ms | requests/move | status reads/move |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for factor in args.speed_factor:
        for profile in args.profile:
            for predictive in (False, True):
                gaps: list[float] = []
                seen: list[float] = []
                requests: list[float] = []
                polls: list[float] = []
                for _ in range(args.rounds):
                    g, d, r, p = measure(
                        profile,
                        predictive,
                        args.moves,
                        factor,
                        args.dz,
                        args.speed,
                    )
                    gaps += g
                    seen += d
                    requests.append(r)
                    polls.append(p)
                print(
                    f"| {factor:g}x | {profile} |"
                    f" {'predictive' if predictive else 'nominal 50 ms'} |"
                    f" {ms(gaps)} | {ms(seen)} | {statistics.median(requests):.1f}"
                    f" | {statistics.median(polls):.1f} |"
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
