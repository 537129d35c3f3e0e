"""A run of a shift or of days: the runner's memory and the report stay bounded.

Every pass through a state is counted in the per-state statistics; the passes themselves
are kept for the first cycles, the latest ones and the cycles with a retry or a failure
(up to a cap); cycle times for the first and the latest cycles. ``report show`` and
``report plot`` say what was aggregated; a version 1 report (every pass listed) still
shows. The recording layer is driven with synthetic passes where the full runner would
be too slow for 100,000 cycles.
"""

from __future__ import annotations

import json
import tracemalloc
from collections.abc import Callable, Collection
from pathlib import Path
from typing import Any

import pytest

from sim_speeds import QUICK
from tmmaster import GraspFailedError, PollPolicy, Robot
from tmmaster.pickplace import DONE, RetryRule, Runner, TaskSequence, load_report, write_report
from tmmaster.pickplace._report import build_report
from tmmaster.pickplace._runlog import RunLog
from tmmaster.pickplace._runner import RunResult, StateRecord
from tmmaster.report.__main__ import main as report_main
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
STATES = ("PICK", "GRIP", "PLACE")


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: SimFactory) -> SimFactory:
    """The runner is the subject here, not TCP: simulators in memory."""
    return memory_simulator_factory


def duration(cycle: int, i: int) -> float:
    """A deterministic, varied duration (rounded like the runner's)."""
    return round(0.1 + ((cycle * 7 + i * 13) % 97) / 1000, 4)


def synthetic_passes(cycles: int, marked: Collection[int] = ()) -> list[StateRecord]:
    """IDLE, then STATES per cycle; a marked cycle's GRIP fails once and is retried."""
    out = [StateRecord("IDLE", 0, 0.0, 0.01, "ok")]
    t = 0.01
    for c in range(1, cycles + 1):
        names = list(STATES)
        if c in marked:
            names[1:1] = ["GRIP!", "PICK"]  # GRIP retried, back to PICK
        for i, name in enumerate(names):
            d = duration(c, i)
            outcome = "retry" if name == "GRIP!" else ("skipped" if c % 5 == 0 and i == 0 else "ok")
            out.append(StateRecord(name.rstrip("!"), c, round(t, 4), d, outcome))
            t += d
    return out


def feed(log: RunLog, passes: list[StateRecord]) -> None:
    """Add ``passes`` to ``log`` as the runner does: each pass, then each cycle's time as
    the next cycle starts (the sum of its passes here)."""
    cycle, spent = 0, 0.0
    for record in passes:
        if record.cycle != cycle:
            if cycle > 0:
                log.cycle_time(round(spent, 4))
            cycle, spent = record.cycle, 0.0
        spent += record.duration_s
        log.add(record)


def timings_of(passes: list[StateRecord]) -> dict[str, dict[str, Any]]:
    """Per-state statistics computed from every pass (what version 1 reports held)."""
    out: dict[str, dict[str, Any]] = {}
    for r in passes:
        if r.outcome == "skipped":
            continue
        e = out.setdefault(
            r.state, {"count": 0, "total_s": 0.0, "max_s": 0.0, "min_s": r.duration_s}
        )
        e["count"] += 1
        e["total_s"] += r.duration_s
        e["max_s"] = max(e["max_s"], r.duration_s)
        e["min_s"] = min(e["min_s"], r.duration_s)
        e["retries"] = e.get("retries", 0) + (r.outcome == "retry")
        e["failures"] = e.get("failures", 0) + (r.outcome == "failed")
    for e in out.values():
        e["mean_s"] = round(e["total_s"] / e["count"], 4)
        e["total_s"] = round(e["total_s"], 4)
    return out


def test_the_aggregates_equal_what_every_pass_gives_on_a_small_run() -> None:
    passes = synthetic_passes(40, marked={7, 20, 25, 33})
    small = RunLog(first=2, last=3, marked=2, times=5)
    feed(small, passes)
    assert small.state_timings() == timings_of(passes)
    times = [round(sum(p.duration_s for p in passes if p.cycle == c), 4) for c in range(1, 40)]
    assert small.cycles.count == len(times)
    assert small.cycles.as_dict()["max_s"] == max(times)
    assert small.cycles.as_dict()["min_s"] == min(times)
    # Kept: cycles 0-2, the first two marked ones (7, 20), the latest three (38-40).
    assert sorted({r.cycle for r in small.records()}) == [0, 1, 2, 7, 20, 38, 39, 40]
    assert small.marked_dropped == 2  # 25 and 33: over the cap, counted
    kept_times, omitted = small.cycle_times()
    assert kept_times == times[:5] + times[-5:]
    assert omitted == len(times) - 10
    # With room for every cycle, every pass is kept, in order.
    whole = RunLog(first=100)
    feed(whole, passes)
    assert whole.records() == passes
    assert whole.state_timings() == small.state_timings()


def add_cycles(log: RunLog, cycles: range) -> None:
    """Two passes per cycle; every 500th cycle's second one is retried."""
    for c in cycles:
        log.add(StateRecord("PICK", c, float(c), 0.1, "ok"))
        log.add(StateRecord("GRIP", c, float(c), 0.2, "retry" if c % 500 == 0 else "ok"))
        log.cycle_time(0.3)


def test_a_hundred_thousand_cycles_keep_a_bounded_log() -> None:
    log = RunLog()
    add_cycles(log, range(1, 100_001))
    # Every pass counted; the passes of 10 + 100 + 10 cycles and 2,000 cycle times kept.
    assert log.passes == 200_000
    assert log.state_timings()["GRIP"]["count"] == 100_000
    assert log.state_timings()["GRIP"]["retries"] == 200
    kept = log.records()
    assert len(kept) == (1 + log.first + log.marked + log.last) * 2 - 2  # no cycle 0 here
    retried = sorted({r.cycle for r in kept if r.outcome == "retry"})
    assert retried == [*range(500, 50_001, 500), 100_000]  # the first 100, and the latest
    assert log.marked_dropped == 99  # 50,500 .. 99,500: counted only
    assert len(log.cycle_times()[0]) == 2000
    # What more cycles add is not kept (before: some 1.7 kB per cycle of passes). Traced
    # from a while after the start, so what is freed was traced too (the trend's blocks
    # merge now and then: a block made before the trace is freed unseen).
    tracemalloc.start()
    try:
        add_cycles(log, range(100_001, 105_001))
        before = tracemalloc.get_traced_memory()[0]
        add_cycles(log, range(105_001, 115_001))
        grown = tracemalloc.get_traced_memory()[0] - before
    finally:
        tracemalloc.stop()
    assert grown < 16 * 1024
    assert log.passes == 230_000


def synthetic_result(cycles: int, marked: Collection[int] = ()) -> RunResult:
    """A RunResult as the runner leaves it, from synthetic passes."""
    log = RunLog()
    feed(log, synthetic_passes(cycles, marked))
    log.cycle_time(0.3)  # the last cycle's
    return RunResult(
        sequence="synthetic",
        state=DONE,
        cycles_requested=cycles,
        cycles_completed=cycles,
        records=log.records(),
        cycle_times_s=log.cycle_times()[0],
        duration_s=cycles * 0.3,
        log=log,
    )


def test_the_report_of_a_long_run_is_bounded_and_shown(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "run.json"
    result = synthetic_result(50_000, marked={25_001})
    write_report(path, build_report(exit_code=0, result_name="done", reason=None, run=result))
    assert path.stat().st_size < 256 * 1024  # version 1: some 20 MB for this run
    report = load_report(path)
    assert report.states["PLACE"].count == 50_000
    assert report.cycles.completed == 50_000
    assert report.cycles.times_omitted == 50_000 - 2000
    assert report.cycles.cycle_of(len(report.cycles.times_s) - 1) == 50_000
    assert report.timeline_scope is not None
    assert report.timeline_scope.omitted_cycles == 50_000 - 21
    # The retried cycle is listed with its context: the failed pass and the ones after.
    retried = [e for e in report.timeline if e.cycle == 25_001]
    assert [e.outcome for e in retried][:3] == ["ok", "retry", "ok"]
    assert report_main(["show", str(path)]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "long run: the report lists the passes of 21 cycle(s)" in out
    assert "the table counts all 150003 passes" in out
    assert "the cycle statistics all 50000 cycles" in out


def test_a_long_run_is_plotted_from_its_listed_cycles(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("matplotlib")
    path = tmp_path / "run.json"
    result = synthetic_result(5000)
    write_report(path, build_report(exit_code=0, result_name="done", reason=None, run=result))
    assert report_main(["plot", str(path), "-o", str(tmp_path / "run.png")]) == 0
    assert (tmp_path / "run.png").stat().st_size > 0
    from tmmaster.report._plot import _cycles_note

    assert _cycles_note(load_report(path), 21) == (
        " (20 of 5000 cycles drawn; the rest aggregated in the report)"
    )


VERSION_1 = {
    "report_version": 1,
    "tmmaster_version": "0.9.0",
    "result": "done",
    "exit_code": 0,
    "reason": None,
    "config": {"file": None, "digest": None},
    "target": {"host": "127.0.0.1", "port": 5020, "profile": "article"},
    "sequence": "pick-and-place",
    "final_state": "DONE",
    "started_at": "2026-01-01T00:00:00.000+00:00",
    "duration_s": 2.0,
    "cycles": {"requested": 2, "completed": 2, "times_s": [1.0, 1.0]},
    "states": {"MOVE_TO_PICK": {"count": 2, "total_s": 2.0, "mean_s": 1.0, "max_s": 1.0}},
    "timeline": [
        {
            "state": "MOVE_TO_PICK",
            "cycle": c,
            "started_s": c - 1.0,
            "duration_s": 1.0,
            "outcome": "ok",
        }
        for c in (1, 2)
    ],
    "retries": {"grasp": 0},
    "error": None,
    "reaction": None,
    "transport": None,
    "sim": None,
}


def test_a_version_1_report_is_still_shown_and_plotted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "old.json"
    path.write_text(json.dumps(VERSION_1))
    report = load_report(path)
    assert report.timeline_scope is None
    assert report.cycles.mean_s is None
    assert report_main(["show", str(path)]) == 0
    out = capsys.readouterr().out
    assert "MOVE_TO_PICK" in out
    assert "cycle times (s): 1.00, 1.00  (mean 1.00, max 1.00)" in out
    assert "long run" not in out
    pytest.importorskip("matplotlib")
    assert report_main(["plot", str(path), "-o", str(tmp_path / "old.png")]) == 0


def test_a_newer_report_version_is_refused_with_its_reason(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "new.json"
    path.write_text(json.dumps({**VERSION_1, "report_version": 3}))
    assert report_main(["show", str(path)]) == 2
    assert "report_version 3 is not supported (this tmmaster reads 1..2" in capsys.readouterr().err


def test_the_runner_keeps_the_first_the_latest_and_the_retried_cycles(
    tm_simulator_factory: SimFactory, tmp_path: Path
) -> None:
    retried = {15, 40}

    def grip(ctx: Any) -> None:
        if ctx.cycle in retried and ctx.attempt == 1:
            raise GraspFailedError("no object detected (synthetic)")

    sequence = TaskSequence("synthetic")
    sequence.add("PICK", lambda ctx: None)
    sequence.add("GRIP", grip, retry=RetryRule(back_to="PICK", attempts=1))
    sequence.add("PLACE", lambda ctx: None)
    sim = tm_simulator_factory("article", **QUICK)
    robot = Robot(sim.url, profile=sim.profile, polling=PollPolicy(interval_s=0.01))
    with robot:
        result = Runner(robot).run(sequence, cycles=60)
    assert result.ok
    assert result.cycles_completed == 60
    kept = sorted({r.cycle for r in result.records})
    assert kept == [*range(11), 15, 40, *range(51, 61)]
    timings = result.state_timings()
    assert timings["PLACE"]["count"] == 60
    assert timings["GRIP"]["count"] == 62
    assert timings["GRIP"]["retries"] == 2
    assert len(result.cycle_times_s) == 60  # under the cap: every time
    report = build_report(exit_code=0, result_name="done", reason=None, run=result)
    assert report["timeline_scope"]["passes"] == 1 + 60 * 3 + 2 * 2
    assert report["timeline_scope"]["omitted_cycles"] == 60 - 22
    assert report["cycles"]["times_omitted"] == 0


def test_a_sim_report_of_many_parts_lists_the_ones_to_look_at(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from types import SimpleNamespace

    from tmmaster import Pose
    from tmmaster.pickplace._report import objects_report

    place = Pose(300, 200, 100, 180, 0, 90)
    astray = {150, 151, 152}  # parts that did not reach the place position

    def part(i: int) -> SimpleNamespace:
        x = 0.0 if i in astray else place.x
        return SimpleNamespace(
            name=f"part-{i}", pose=Pose(x, place.y, 100, 180, 0, 90), held=False, resting_on="table"
        )

    objects = [part(i) for i in range(1, 301)]
    sim = objects_report(objects, place, 2.0, {f"part-{i}" for i in range(1, 301)})
    listed = [o["name"] for o in sim["objects"]]
    expected = [*range(1, 11), *sorted(astray), *range(291, 301)]
    assert listed == [f"part-{i}" for i in expected]
    assert sim["objects_total"] == 300
    assert sim["objects_on_place"] == 297
    assert sim["on_place"] is False
    path = tmp_path / "run.json"
    write_report(
        path,
        build_report(exit_code=1, result_name="failed", reason="parts astray", sim=sim),
    )
    assert report_main(["show", str(path)]) == 0
    assert "simulator: 297/300 part(s) on the place position" in capsys.readouterr().out


def test_the_cycle_time_trend_covers_the_whole_run_in_at_most_200_blocks(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = RunLog()
    times = [round(1.0 + (c // 1000) * 0.01 + (c % 7) * 0.001, 4) for c in range(1, 5001)]
    for t in times:
        log.cycle_time(t)
    trend = log.trend()
    # 5,000 cycles: blocks of 32 cycles (1, 2, 4 ... doubled while over 200), the last short.
    assert log.block_cycles == 32
    assert len(trend) == 157
    assert [row[0] for row in trend] == list(range(1, 5001, 32))
    assert sum(row[1] for row in trend) == 5000
    for first, count, mean_s, min_s, max_s in trend:
        block = times[first - 1 : first - 1 + count]
        assert mean_s == round(sum(block) / count, 4)
        assert min_s == min(block)
        assert max_s == max(block)
    # Up to 200 cycles the trend is every cycle's time.
    short = RunLog()
    for t in times[:200]:
        short.cycle_time(t)
    assert [row[2] for row in short.trend()] == times[:200]
    # Shown in one line by `report show`.
    result = synthetic_result(5000)
    path = tmp_path / "run.json"
    write_report(path, build_report(exit_code=0, result_name="done", reason=None, run=result))
    assert len(load_report(path).cycles.trend) <= 200
    assert report_main(["show", str(path)]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "cycle time trend (mean of each 32 cycles, 157 blocks): first" in out
