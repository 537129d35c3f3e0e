"""The end-of-run summary: a table of per-state times, the cycles and the result (rich).

Shown by ``python -m tmmaster.pickplace`` on a terminal after the run and by
``tmmaster report show run.json``. Imported only when needed: ``rich`` stays out of
``import tmmaster``.
"""

from __future__ import annotations

import itertools
from typing import Any

from rich.console import Group
from rich.table import Table
from rich.text import Text

from ._report import CycleSummary, RunReport, SimSummary, printable

_RESULT_STYLE = {"done": "bold green", "interrupted": "bold yellow"}

#: The most characters of a name (a state, the sequence, the host) the summary shows.
_NAME_CHARS = 80
#: The most characters of a sentence (the reason, the error's message) the summary shows.
_SENTENCE_CHARS = 1000
#: The most states the table lists (a run has about ten); the rest are counted.
MAX_STATE_ROWS = 50
#: The cycle times listed in full up to this many; beyond, the first and last halves.
MAX_LISTED_TIMES = 20


def _seconds(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def _name(text: str) -> str:
    return printable(text, _NAME_CHARS)


def _head(report: RunReport, style: str) -> Text:
    """The result line: result, exit code, sequence, cycles, duration, target."""
    head = Text()
    head.append(_name(report.result).upper(), style=style)
    head.append(f"  exit {report.exit_code}")
    if report.sequence:
        head.append(f"  {_name(report.sequence)}")
    requested = report.cycles.requested
    head.append(f"  cycles {report.cycles.completed}/{'-' if requested is None else requested}")
    head.append(f"  {_seconds(report.duration_s)} s")
    if report.retries.grasp:
        head.append(f"  grasp retries {report.retries.grasp}")
    if report.target is not None:
        target = report.target
        head.append(f"  {_name(target.profile)}@{_name(target.host)}:{target.port}")
    return head


def _state_table(report: RunReport) -> list[Any]:
    """The per-state table (at most MAX_STATE_ROWS rows) and, beyond, a count of the rest."""
    table = Table(title="time per state", title_justify="left", show_edge=False)
    table.add_column("state")
    table.add_column("kind")
    for name in ("passes", "total s", "mean s", "max s", "share"):
        table.add_column(name, justify="right")
    total = sum(t.total_s for t in report.states.values()) or 1.0
    moves = set(report.move_states)
    for state, timing in itertools.islice(report.states.items(), MAX_STATE_ROWS):
        kind = "" if not moves else ("move" if state in moves else "wait")
        # Text, not str: a cell given as a str is parsed as rich markup ("[/]" raises).
        table.add_row(
            Text(_name(state)),
            Text(kind),
            str(timing.count),
            f"{timing.total_s:.2f}",
            f"{timing.mean_s:.2f}",
            f"{timing.max_s:.2f}",
            f"{100 * timing.total_s / total:.0f}%",
        )
    parts: list[Any] = [table]
    hidden = len(report.states) - MAX_STATE_ROWS
    if hidden > 0:
        parts.append(Text(f"({hidden} more states not listed; the share is of all of them)"))
    return parts


def _cycle_times(cycles: CycleSummary) -> Text:
    """The cycle times: every one up to MAX_LISTED_TIMES, else the first and the last;
    the statistics of every completed cycle (the report's, else of the times listed)."""
    times, half = cycles.times_s, MAX_LISTED_TIMES // 2
    if len(times) <= MAX_LISTED_TIMES and not cycles.times_omitted:
        listed = ", ".join(f"{t:.2f}" for t in times)
    else:
        first = ", ".join(f"{t:.2f}" for t in times[:half])
        last = ", ".join(f"{t:.2f}" for t in times[-half:])
        more = len(times) - 2 * half + cycles.times_omitted
        listed = f"{first}, ... {more} more ..., {last}"
    mean = cycles.mean_s if cycles.mean_s is not None else sum(times) / len(times)
    longest = cycles.max_s if cycles.max_s is not None else max(times)
    shortest = f"min {cycles.min_s:.2f}, " if cycles.min_s is not None else ""
    return Text(f"cycle times (s): {listed}  ({shortest}mean {mean:.2f}, max {longest:.2f})")


def _trend(cycles: CycleSummary) -> Text | None:
    """The cycle-time trend of a run of more than 200 cycles, in one line (else None)."""
    blocks = cycles.trend
    if len(blocks) < 2 or blocks[0][1] < 2:
        return None
    worst = max(blocks, key=lambda row: row[2])
    return Text(
        f"cycle time trend (mean of each {blocks[0][1]} cycles, {len(blocks)} blocks):"
        f" first {blocks[0][2]:.2f}, last {blocks[-1][2]:.2f}, highest {worst[2]:.2f}"
        f" (cycles {worst[0]}-{worst[0] + worst[1] - 1})"
    )


def _scope(report: RunReport) -> Text | None:
    """What the timeline leaves out of a long run, in words (None: nothing)."""
    scope = report.timeline_scope
    if scope is None or not (scope.omitted_cycles or report.cycles.times_omitted):
        return None
    marked = f", up to {scope.marked_cycles} with a retry or failure"
    if scope.marked_cycles_omitted:
        marked += f" ({scope.marked_cycles_omitted} more not listed)"
    times = report.cycles.times_omitted
    return Text(
        f"long run: the report lists the passes of {scope.listed_cycles} cycle(s) (the"
        f" first {scope.first_cycles}, the latest {scope.last_cycles}{marked});"
        f" the other {scope.omitted_cycles} cycle(s) are aggregated: the table counts all"
        f" {scope.passes} passes"
        + (
            f", the cycle statistics all {times + len(report.cycles.times_s)} cycles"
            if times
            else ""
        )
    )


def _sim_parts(sim: SimSummary) -> Text:
    """How many parts ended on the place position, of all (listed in the report or not)."""
    placed = sim.objects_on_place
    placed = sum(o.on_place for o in sim.objects) if placed is None else placed
    total = len(sim.objects) if sim.objects_total is None else sim.objects_total
    return Text(f"simulator: {placed}/{total} part(s) on the place position")


def summary_renderable(report: RunReport) -> Any:
    """A rich renderable: result line, per-state table and cycle times of ``report``.

    Every string from the report is shown as text, never parsed as rich markup, with its
    control characters escaped (``printable``); the output is bounded whatever the report
    holds: at most :data:`MAX_STATE_ROWS` states and :data:`MAX_LISTED_TIMES` cycle times
    are listed, names and sentences are cut short.

    Args:
        report: The run report.

    Returns:
        A rich ``Group`` to print.
    """
    style = _RESULT_STYLE.get(report.result, "bold red")
    parts: list[Any] = [_head(report, style)]
    if report.reason:
        parts.append(Text(printable(report.reason, _SENTENCE_CHARS), style=style))
    if report.states:
        parts.extend(_state_table(report))
    if report.cycles.times_s:
        parts.append(_cycle_times(report.cycles))
    if (trend := _trend(report.cycles)) is not None:
        parts.append(trend)
    if (scope := _scope(report)) is not None:
        parts.append(scope)
    error = report.error
    if error is not None and not report.reason:  # the reason already says it
        code = f" (robot error code {error.error_code})" if error.error_code else ""
        if error.error_meaning:  # a robot fault or e-stop: TM's code, with its meaning
            shown = error.error_meaning.split()[0] in error.message
            code = "" if shown else f" (robot error {error.error_meaning})"
        verb = "stopped" if report.result == "interrupted" else "failed"
        parts.append(
            Text(
                f"{verb} in {_name(error.state)} (cycle {error.cycle}):"
                f" {_name(error.type)}: {printable(error.message, _SENTENCE_CHARS)}{code}",
                style="red",
            )
        )
    if report.sim is not None and report.sim.objects:
        parts.append(_sim_parts(report.sim))
    return Group(*parts)
