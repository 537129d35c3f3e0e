"""The article's pick & place cycle: its published master against tmmaster, same simulator.

Both masters run the article's cycle (approach, pick, close, check, lift, place, open,
home; its poses and speeds) against a fresh ``tmmaster.sim.Simulator("article")`` in
real time (time scale 1, 50 Hz tick), alternately, in the same process:

* ``article``: ``benchmarks/article_master.py``, the article's script as published
  (two patches, see its header);
* ``tmmaster``: ``tmmaster.pickplace`` with its defaults (which reproduce the article's
  poses, speeds and 50 ms polling) and the default ``PollPolicy`` (predictive polling).

What the slave did is read from the simulator itself: its physics backend is the stock
``KinematicBackend`` with a recorder that stamps (``time.monotonic()``, on the
simulator's tick) when each motion starts and settles and when the fingers start and
stop. Per master, per round:

* cycle: first motion start to last motion end (the slave's clock);
* motion: the sum of the five motions' durations; gripper: the fingers' travel time;
* no-feedback wait: the article map's gripper has no busy flag, so a master must wait a
  fixed time after "open" (and the article's master after "close" too): the part of
  such a wait beyond the fingers' travel is reported separately, not as overhead;
* overhead = cycle - motion - gripper - no-feedback wait: what the master costs; shown
  in % of motion + gripper (the issue's target for tmmaster: <= 3 %);
* gap: from a motion's end to the next motion's start, for the moves with no gripper
  action between them (approach -> pick, lift -> place);
* requests per move: Modbus requests from a move's command write to the next command
  write (the move's polls and the next command's checks), from the simulator's log;
* master CPU: the CPU time of the thread that runs the master's cycle
  (``time.thread_time``: the simulator's threads are not counted; connecting and
  building the master are not in it), per cycle and per request made in that time. The
  article's master is written on raw pymodbus calls, so this compares tmmaster with a
  raw pymodbus master over whole moves, on the same simulator in the same run, each
  paced by its own polling.

Run::

    python benchmarks/bench_cycle.py --quick        # 1 round each
    python benchmarks/bench_cycle.py --rounds 3     # the docs' table
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import itertools
import json
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

from _machine import machine_line

from tmmaster import DEFAULT_HOME, MotionType, PollPolicy, Pose, robot_model
from tmmaster.pickplace import PickPlaceConfig, Runner, pick_and_place, robot_from_config
from tmmaster.sim import KinematicBackend, Simulator

#: The cycle's transitions, slave side: (what ended, what started next).
TRANSITIONS = (
    "approach end -> pick start",
    "pick end -> close start",
    "close end -> lift start",
    "lift end -> place start",
    "place end -> open start",
    "open end -> home start",
)

#: Command register and gripper register of the article map.
COMMAND, TARGET_X, GRIPPER = 0x0207, 0x0200, 0x0210


@dataclass
class Event:
    """One thing the slave did, stamped on its tick."""

    kind: str  # "motion" or "gripper"
    start: float
    end: float | None = None


class RecordingBackend(KinematicBackend):
    """The stock kinematic backend, stamping when motions and finger moves start and end."""

    def __init__(self) -> None:
        super().__init__(robot_model("tm5-700"))
        self.events: list[Event] = []

    def start_motion(
        self, target: Pose, *, motion: MotionType, speed_percent: float, accel_time_s: float
    ) -> float:
        """Start the motion and stamp it."""
        duration = super().start_motion(
            target, motion=motion, speed_percent=speed_percent, accel_time_s=accel_time_s
        )
        self.events.append(Event("motion", time.monotonic()))
        return duration

    def drive_gripper(self, width_mm: float, *, speed_mm_s: float, force_n: float) -> None:
        """Start the fingers and stamp it."""
        super().drive_gripper(width_mm, speed_mm_s=speed_mm_s, force_n=force_n)
        event = Event("gripper", time.monotonic())
        self.events.append(event)
        if not self.gripper_state().moving:
            event.end = event.start

    def step(self, dt: float) -> None:
        """Advance, then stamp what ended on this tick."""
        super().step(dt)
        now = time.monotonic()
        for event in self.events[-2:]:
            if event.end is not None:
                continue
            if (event.kind == "motion" and self.is_settled()) or (
                event.kind == "gripper" and not self.gripper_state().moving
            ):
                event.end = now


@dataclass
class Round:
    """What one cycle of one master measured."""

    master: str
    cycle_s: float
    motion_s: float
    gripper_s: float
    no_feedback_s: float
    overhead_s: float
    gaps_ms: list[float] = field(default_factory=list)
    #: Every transition's gap (TRANSITIONS order), ms.
    transitions_ms: list[float] = field(default_factory=list)
    requests_per_move: float = 0.0
    requests_per_cycle: int = 0
    #: CPU time of the master's thread over its cycle (connecting not included), s,
    #: and the requests it made in that time.
    master_cpu_s: float = 0.0
    master_requests: int = 0

    @property
    def cpu_per_request_us(self) -> float:
        """The master's CPU per request of its run, µs."""
        return 1e6 * self.master_cpu_s / max(1, self.master_requests)

    @property
    def overhead_pct(self) -> float:
        """Overhead in % of the slave's motion + gripper time."""
        return 100 * self.overhead_s / (self.motion_s + self.gripper_s)


def load_article_master() -> ModuleType:
    """Import benchmarks/article_master.py (not a package)."""
    path = Path(__file__).with_name("article_master.py")
    spec = importlib.util.spec_from_file_location("article_master", path)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run_article(sim: Simulator) -> tuple[list[float], bool, float, int]:
    """The article's master, one cycle: its fixed gripper sleeps, success, cycle CPU (s)."""
    article = load_article_master()
    # Its HOME (0, 0, 300, 180, 0, 0) is out of a TM5's reach (docs/kinematics.md): the
    # simulator refuses it as a real arm would. Both masters go home to the same pose.
    article.HOME_POS = list(DEFAULT_HOME.as_list())
    ctrl = article.PickAndPlaceController("127.0.0.1", port=sim.port)
    assert ctrl.connect()
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # its progress prints
            requests_before, cpu_started = len(sim.request_log), time.thread_time()
            ctrl.run()
            cpu_s = time.thread_time() - cpu_started
            requests = len(sim.request_log) - requests_before
    finally:
        ctrl.disconnect()
    return [0.8, 0.5], ctrl.state is article.State.DONE, cpu_s, requests


def run_tmmaster(sim: Simulator, policy: PollPolicy) -> tuple[list[float], bool, float, int]:
    """tmmaster.pickplace with its defaults, one cycle: its open settle, success, cycle CPU."""
    config = PickPlaceConfig.model_validate({"robot": {"profile": "article"}})
    robot = robot_from_config(config, "127.0.0.1", sim.port)
    robot.polling = policy
    with robot:
        robot.wait_until_ready(timeout_s=10)
        runner, sequence = Runner(robot), pick_and_place(config)
        requests_before, cpu_started = len(sim.request_log), time.thread_time()
        result = runner.run(sequence)
        cpu_s = time.thread_time() - cpu_started
        requests = len(sim.request_log) - requests_before
    # Close stops at grasp_status = 1 (feedback); open waits the settle time (none).
    return [0.0, config.gripper.settle_s], result.ok, cpu_s, requests


def analyse(master: str, sim: Simulator, events: list[Event], waits: list[float]) -> Round:
    """Turn the slave's stamps and request log into one Round."""
    motions = [e for e in events if e.kind == "motion"]
    assert len(motions) == 5, events
    assert all(e.end is not None for e in events), events
    first, last = motions[0].start, motions[-1].end
    assert last is not None
    in_cycle = [e for e in events if first <= e.start <= last]
    grippers = [e for e in in_cycle if e.kind == "gripper"]
    motion_s = sum(e.end - e.start for e in motions if e.end is not None)
    gripper_s = sum(e.end - e.start for e in grippers if e.end is not None)
    # The fixed waits after close and open, beyond what the fingers needed.
    no_feedback = sum(
        max(0.0, wait - ((g.end or g.start) - g.start))
        for wait, g in zip(waits, grippers, strict=True)
    )
    cycle = last - first
    transitions = [
        (after.start - (before.end or before.start)) * 1000
        for before, after in itertools.pairwise(in_cycle)
    ]
    assert len(transitions) == len(TRANSITIONS), in_cycle
    gaps = [
        gap
        for gap, before, after in zip(transitions, in_cycle, in_cycle[1:], strict=False)
        if before.kind == after.kind == "motion"
    ]
    log = sim.request_log
    commands = [
        i
        for i, r in enumerate(log)
        if r.is_write
        and (
            (r.function_code == 16 and r.address == TARGET_X)
            or (r.function_code == 6 and r.address in (TARGET_X, GRIPPER))
            or (r.function_code == 16 and r.address == GRIPPER)
        )
    ]
    move_windows = [
        (a, b)
        for a, b in zip(commands, [*commands[1:], len(log)], strict=True)
        if log[a].address == TARGET_X
    ]
    per_move = statistics.fmean(b - a for a, b in move_windows)
    return Round(
        master=master,
        cycle_s=cycle,
        motion_s=motion_s,
        gripper_s=gripper_s,
        no_feedback_s=no_feedback,
        overhead_s=cycle - motion_s - gripper_s - no_feedback,
        gaps_ms=gaps,
        transitions_ms=transitions,
        requests_per_move=per_move,
        requests_per_cycle=len(log),
    )


def one_round(master: str, policy: PollPolicy) -> Round:
    """A fresh simulator, one cycle of ``master``, analysed."""
    backend = RecordingBackend()
    with Simulator("article", time_scale=1.0, cell=backend) as sim:
        sim.wait_for(lambda: sim.field("robot_mode") == 5, timeout=10)
        sim.clear_request_log()
        if master == "article":
            waits, ok, master_cpu_s, cycle_requests = run_article(sim)
        else:
            waits, ok, master_cpu_s, cycle_requests = run_tmmaster(sim, policy)
        if not ok:
            raise RuntimeError(f"the {master} master did not finish its cycle")
        events = list(backend.events)
        if master == "tmmaster":
            # pickplace opens the fingers before the first approach (outside the cycle).
            events = events[1:] if events and events[0].kind == "gripper" else events
        measured = analyse(master, sim, events, waits)
        measured.master_cpu_s = master_cpu_s
        measured.master_requests = cycle_requests
        return measured


def summary(rounds: list[Round]) -> str:
    """Median per master, with the range of the overhead."""
    lines = [
        "| master | cycle s | motion s | gripper s | no-feedback wait s | overhead s"
        " | overhead % (range) | move-to-move gap ms p50 / max | requests/move"
        " | requests/cycle | master CPU ms/cycle | master CPU µs/request |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for master in dict.fromkeys(r.master for r in rounds):
        rs = [r for r in rounds if r.master == master]

        def med(key: str, rs: list[Round] = rs) -> float:
            return float(statistics.median(float(getattr(r, key)) for r in rs))

        pcts = [r.overhead_pct for r in rs]
        gaps = [g for r in rs for g in r.gaps_ms]
        lines.append(
            f"| {master} | {med('cycle_s'):.3f} | {med('motion_s'):.3f}"
            f" | {med('gripper_s'):.3f} | {med('no_feedback_s'):.3f}"
            f" | {med('overhead_s'):.3f}"
            f" | {statistics.median(pcts):.2f} ({min(pcts):.2f}-{max(pcts):.2f})"
            f" | {statistics.median(gaps):.0f} / {max(gaps):.0f}"
            f" | {med('requests_per_move'):.1f} | {med('requests_per_cycle'):.0f}"
            f" | {1000 * med('master_cpu_s'):.1f} | {med('cpu_per_request_us'):.0f} |"
        )
    return "\n".join(lines)


def cpu_ratios(rounds: list[Round]) -> str:
    """tmmaster's master CPU over the article's, per round (both ran in the same round)."""
    pairs = [
        (a, t)
        for a, t in itertools.pairwise(rounds)
        if a.master == "article" and t.master == "tmmaster"
    ]
    if not pairs:
        return ""
    per_request = [t.cpu_per_request_us / a.cpu_per_request_us for a, t in pairs]
    per_cycle = [t.master_cpu_s / a.master_cpu_s for a, t in pairs]
    return (
        "master CPU, tmmaster / article (raw pymodbus), median of rounds (range):"
        f" per request {statistics.median(per_request):.2f}"
        f" ({min(per_request):.2f}-{max(per_request):.2f}),"
        f" per cycle {statistics.median(per_cycle):.2f}"
        f" ({min(per_cycle):.2f}-{max(per_cycle):.2f})"
    )


def breakdown(rounds: list[Round]) -> str:
    """Median gap of every transition per master: where the cycle's extra time goes."""
    masters = list(dict.fromkeys(r.master for r in rounds))
    lines = [
        "| transition (slave side) | " + " | ".join(f"{m} gap ms" for m in masters) + " |",
        "|---|" + "---|" * len(masters),
    ]
    for i, label in enumerate(TRANSITIONS):
        cells = [
            f"{statistics.median(r.transitions_ms[i] for r in rounds if r.master == m):.0f}"
            for m in masters
        ]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the rounds, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="one round per master")
    parser.add_argument(
        "--policy",
        default="{}",
        help="PollPolicy fields for tmmaster as JSON, e.g. '{\"interval_s\": 0.02}'",
    )
    args = parser.parse_args(argv)
    policy_fields: dict[str, Any] = json.loads(args.policy)
    policy = PollPolicy(**policy_fields)
    rounds: list[Round] = []
    for _ in range(1 if args.quick else args.rounds):
        for master in ("article", "tmmaster"):
            rounds.append(one_round(master, policy))
            r = rounds[-1]
            print(
                f"{master}: cycle {r.cycle_s:.3f} s, overhead {r.overhead_s * 1000:.0f} ms"
                f" ({r.overhead_pct:.2f} %), transitions {[round(g) for g in r.transitions_ms]} ms,"
                f" master CPU {r.master_cpu_s * 1000:.1f} ms"
                f" ({r.cpu_per_request_us:.0f} µs/request)",
                file=sys.stderr,
                flush=True,
            )
    print(f"# {machine_line()}; tmmaster {policy!r}")
    print(summary(rounds))
    print()
    print(cpu_ratios(rounds))
    print()
    print(breakdown(rounds))
    return 0


if __name__ == "__main__":
    sys.exit(main())
