"""The end-of-run summary: a table of per-state times, the cycles and the result (rich).

Shown by ``python -m tmmaster.pickplace`` on a terminal after the run and by
``tmmaster report show run.json``. Imported only when needed: ``rich`` stays out of
``import tmmaster``.
"""

from __future__ import annotations

from typing import Any

from rich.console import Group
from rich.table import Table
from rich.text import Text

from ._report import RunReport

_RESULT_STYLE = {"done": "bold green", "interrupted": "bold yellow"}


def _seconds(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def summary_renderable(report: RunReport) -> Any:
    """A rich renderable: result line, per-state table and cycle times of ``report``."""
    style = _RESULT_STYLE.get(report.result, "bold red")
    head = Text()
    head.append(report.result.upper(), style=style)
    head.append(f"  exit {report.exit_code}")
    if report.sequence:
        head.append(f"  {report.sequence}")
    requested = report.cycles.requested
    head.append(f"  cycles {report.cycles.completed}/{'-' if requested is None else requested}")
    head.append(f"  {_seconds(report.duration_s)} s")
    if report.retries.grasp:
        head.append(f"  grasp retries {report.retries.grasp}")
    if report.target is not None:
        head.append(f"  {report.target.profile}@{report.target.host}:{report.target.port}")
    parts: list[Any] = [head]
    if report.reason:
        parts.append(Text(report.reason, style=style))

    if report.states:
        table = Table(title="time per state", title_justify="left", show_edge=False)
        table.add_column("state")
        table.add_column("kind")
        for name in ("passes", "total s", "mean s", "max s", "share"):
            table.add_column(name, justify="right")
        total = sum(t.total_s for t in report.states.values()) or 1.0
        moves = set(report.move_states)
        for state, timing in report.states.items():
            kind = "" if not moves else ("move" if state in moves else "wait")
            table.add_row(
                state,
                kind,
                str(timing.count),
                f"{timing.total_s:.2f}",
                f"{timing.mean_s:.2f}",
                f"{timing.max_s:.2f}",
                f"{100 * timing.total_s / total:.0f}%",
            )
        parts.append(table)
    if report.cycles.times_s:
        times = report.cycles.times_s
        parts.append(
            Text(
                f"cycle times (s): {', '.join(f'{t:.2f}' for t in times)}"
                f"  (mean {sum(times) / len(times):.2f}, max {max(times):.2f})"
            )
        )
    if report.error is not None and not report.reason:  # the reason already says it
        code = f" (robot error code {report.error.error_code})" if report.error.error_code else ""
        verb = "stopped" if report.result == "interrupted" else "failed"
        parts.append(
            Text(
                f"{verb} in {report.error.state} (cycle {report.error.cycle}):"
                f" {report.error.type}: {report.error.message}{code}",
                style="red",
            )
        )
    if report.sim is not None and report.sim.objects:
        placed = sum(o.on_place for o in report.sim.objects)
        parts.append(
            Text(f"simulator: {placed}/{len(report.sim.objects)} part(s) on the place position")
        )
    return Group(*parts)
