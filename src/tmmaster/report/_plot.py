"""``tmmaster report plot``: a run report as a picture (matplotlib, the ``plot`` extra).

Three panels: the states of every cycle on a common time axis (seconds since the
cycle started), the whole run split into moving and waiting (with the TCP speed the
simulator saw, for a ``--sim`` run), and the TCP path seen from above with the pick and
place poses (``--sim`` runs). A run that did not end DONE says so in the title, with its
reason, and shows what it recorded; one that recorded nothing is a picture saying so.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

from ..pickplace._report import RunReport

#: Colours of the moving / waiting bands.
_MOVING = "#2a9d8f"
_WAITING = "#e9c46a"
#: Colours of the pick and place poses on the path.
_PICK = "#6a4c93"
_PLACE = "#e76f51"
#: The reason under the title is cut to this many characters.
_REASON_CHARS = 150
#: The most cycles drawn pass by pass (the first and the last half of those listed).
MAX_DRAWN_CYCLES = 60


def _drawn(report: RunReport) -> tuple[list[Any], list[int]]:
    """The timeline entries drawn, and their cycles in order: every listed cycle up to
    MAX_DRAWN_CYCLES, else the first and the last half of them."""
    cycles = sorted({e.cycle for e in report.timeline})
    if len(cycles) > MAX_DRAWN_CYCLES:
        half = MAX_DRAWN_CYCLES // 2
        cycles = cycles[:half] + cycles[-half:]
    keep = set(cycles)
    return [e for e in report.timeline if e.cycle in keep], cycles


def _cycles_note(report: RunReport, drawn: int) -> str:
    """What the cycle panel leaves out, in words ("" when nothing)."""
    total = report.cycles.completed + (1 if report.final_state != "DONE" else 0)
    listed = len({e.cycle for e in report.timeline if e.cycle > 0})
    shown = drawn - (1 if any(e.cycle == 0 for e in report.timeline) else 0)
    if shown >= listed and (
        report.timeline_scope is None or not report.timeline_scope.omitted_cycles
    ):
        return ""
    return f" ({shown} of {max(total, listed)} cycles drawn; the rest aggregated in the report)"


def _state_colours(report: RunReport) -> dict[str, Any]:
    import matplotlib

    palette = matplotlib.colormaps["tab10" if len(report.states) <= 10 else "tab20"]
    order: list[str] = []
    for entry in report.timeline:
        if entry.state not in order:
            order.append(entry.state)
    return {state: palette(i % palette.N) for i, state in enumerate(order)}


def _cycle_panel(ax: Any, report: RunReport, colours: dict[str, Any]) -> None:
    # Cycle 0 is what ran before the first cycle (IDLE: the wait for the robot to be
    # ready): its own row, "start", so a run that failed there still shows it. One row per
    # cycle drawn, in order (a long run's report lists some cycles only).
    entries, cycles = _drawn(report)
    row = {c: i for i, c in enumerate(cycles)}
    starts: dict[int, float] = {}
    for entry in entries:
        starts[entry.cycle] = min(starts.get(entry.cycle, entry.started_s), entry.started_s)
    seen: set[str] = set()
    for entry in entries:
        if entry.outcome == "skipped":
            continue
        label = entry.state if entry.state not in seen else None
        seen.add(entry.state)
        ax.barh(
            row[entry.cycle],
            max(entry.duration_s, 1e-3),
            left=entry.started_s - starts[entry.cycle],
            height=0.7,
            color=colours[entry.state],
            edgecolor="red" if entry.outcome == "failed" else "white",
            hatch="//" if entry.outcome == "retry" else None,
            label=label,
        )
    ax.set_yticks(range(len(cycles)), [f"cycle {c}" if c >= 1 else "start" for c in cycles])
    ax.invert_yaxis()
    ax.set_xlabel("seconds since the cycle started")
    ax.set_title("states per cycle" + _cycles_note(report, len(cycles)))
    if seen:
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small", frameon=False)
    ax.grid(axis="x", alpha=0.3)


def _tcp_speeds(
    path: list[tuple[float, float, float, float]], *, window_s: float = 0.1
) -> tuple[list[float], list[float]]:
    """TCP speed along ``path`` (mm per wall second), each over at least ``window_s``.

    The samples are taken by a thread, not by the simulator's tick: a window smooths
    the jitter of single intervals.
    """
    along = [0.0]
    for (_, *p0), (_, *p1) in itertools.pairwise(path):
        along.append(along[-1] + math.dist(p0, p1))
    times: list[float] = []
    speeds: list[float] = []
    j = 0
    for i in range(len(path)):
        j = max(j, i + 1)
        while j < len(path) and path[j][0] - path[i][0] < window_s:
            j += 1
        if j >= len(path):
            break
        dt = path[j][0] - path[i][0]
        times.append((path[i][0] + path[j][0]) / 2)
        speeds.append((along[j] - along[i]) / dt)
    return times, speeds


def _moving_panel(ax: Any, report: RunReport) -> None:
    moves = set(report.move_states)
    for entry in _drawn(report)[0]:
        if entry.outcome == "skipped":
            continue
        moving = entry.state in moves
        ax.barh(
            1 if moving else 0,
            max(entry.duration_s, 1e-3),
            left=entry.started_s,
            height=0.7,
            color=_MOVING if moving else _WAITING,
            edgecolor="white",
            linewidth=0.5,
        )
    ax.set_yticks([0, 1], ["waiting", "moving"])
    ax.set_ylim(-0.6, 1.6)
    ax.set_xlabel("seconds since the run started")
    share = sum(t.total_s for s, t in report.states.items() if s in moves)
    total = sum(t.total_s for t in report.states.values()) or 1.0
    title = f"moving {100 * share / total:.0f}% of the time" if moves else "moving vs waiting"
    ax.set_title(title + ("" if moves else " (this report lists no move states)"))
    ax.grid(axis="x", alpha=0.3)
    if report.sim is not None and len(report.sim.tcp_path) > 1:
        times, speeds = _tcp_speeds(report.sim.tcp_path)
        scale = report.sim.time_scale or 1.0
        twin = ax.twinx()
        twin.plot(times, [v / scale for v in speeds], color="#264653", linewidth=1.0)
        twin.set_ylabel("TCP speed, mm/s (simulated)")
        twin.set_ylim(bottom=0)


def _path_panel(ax: Any, report: RunReport) -> None:
    assert report.sim is not None
    path = report.sim.tcp_path
    xs = [row[1] for row in path]
    ys = [row[2] for row in path]
    zs = [row[3] for row in path]
    ax.plot(xs, ys, color="#999999", linewidth=0.8, zorder=1)
    low_last = sorted(range(len(path)), key=lambda i: -zs[i])  # the lowest points on top
    points = ax.scatter(
        [xs[i] for i in low_last],
        [ys[i] for i in low_last],
        c=[zs[i] for i in low_last],
        cmap="viridis",
        s=8,
        zorder=2,
    )
    ax.figure.colorbar(points, ax=ax, label="z, mm", shrink=0.8)
    ax.plot(xs[:1], ys[:1], marker="o", color="black", linestyle="", label="start")
    for name, pose, colour in (
        ("pick", report.sim.pick, _PICK),
        ("place", report.sim.place, _PLACE),
    ):
        if pose is None:
            continue
        ax.plot(
            [pose[0]],
            [pose[1]],
            marker="s",
            markersize=12,
            fillstyle="none",
            markeredgewidth=1.5,
            color=colour,
            linestyle="",
            label=f"{name} ({pose[0]:g}, {pose[1]:g}, {pose[2]:g})",
            zorder=3,
        )
        ax.annotate(
            name,
            (pose[0], pose[1]),
            xytext=(8, 8),
            textcoords="offset points",
            color=colour,
            fontweight="bold",
        )
    for i, obj in enumerate(report.sim.objects):
        ax.plot(
            [obj.pose[0]],
            [obj.pose[1]],
            marker="x",
            color=_PLACE if obj.on_place else "red",
            linestyle="",
            label="where the parts ended" if i == 0 else None,
            zorder=3,
        )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x, mm")
    ax.set_ylabel("y, mm")
    ax.set_title("TCP path from above (simulator)")
    ax.legend(loc="best", fontsize="small")
    ax.grid(alpha=0.3)


def _title(report: RunReport) -> str:
    """The result, the cycles and the time; for a run that did not end DONE, its reason."""
    cycles = report.cycles
    requested = cycles.requested if cycles.requested is not None else "-"
    if report.result == "done":
        outcome = "done"
    elif report.result == "interrupted":
        outcome = "INTERRUPTED"
    else:
        outcome = f"FAILED ({report.result.replace('_', ' ')})"
    title = (
        f"{report.sequence or 'run'}: {outcome}, {cycles.completed}/{requested} cycle(s)"
        f" in {report.duration_s if report.duration_s is not None else 0:.2f} s"
        + (f" (simulator time scale {report.sim.time_scale:g})" if report.sim else "")
    )
    if report.reason:
        reason = " ".join(report.reason.split())
        if len(reason) > _REASON_CHARS:
            reason = reason[: _REASON_CHARS - 1] + "…"
        title += f"\n{reason}"
    return title


def recorded_nothing(report: RunReport) -> bool:
    """True when ``report`` has nothing to draw: no state ran, no TCP path was sampled."""
    return not report.timeline and (report.sim is None or len(report.sim.tcp_path) < 2)


def _figure(report: RunReport) -> Any:
    """The picture of ``report`` (a matplotlib Figure)."""
    from matplotlib import pyplot as plt

    if recorded_nothing(report):
        figure = plt.figure(figsize=(10, 3))
        figure.text(
            0.5,
            0.6,
            "nothing to plot: the run ended before its first state",
            ha="center",
            va="center",
            fontsize="x-large",
        )
        figure.text(0.5, 0.3, _title(report), ha="center", va="center", wrap=True)
        return figure
    has_path = report.sim is not None and len(report.sim.tcp_path) > 1
    figure = plt.figure(figsize=(14 if has_path else 10, 6.5), layout="constrained")
    grid = figure.add_gridspec(
        2, 2 if has_path else 1, width_ratios=[3, 2] if has_path else None, height_ratios=[3, 2]
    )
    colours = _state_colours(report)
    _cycle_panel(figure.add_subplot(grid[0, 0]), report, colours)
    _moving_panel(figure.add_subplot(grid[1, 0]), report)
    if has_path:
        _path_panel(figure.add_subplot(grid[:, 1]), report)
    figure.suptitle(_title(report), color="black" if report.result == "done" else "#b00020")
    return figure


def plot_report(report: RunReport, output: str | Path, *, dpi: int = 110) -> Path:
    """Draw ``report`` into the image file ``output`` (PNG, SVG, PDF by suffix); return it.

    Needs matplotlib (``pip install 'tmmaster[plot]'``).

    Example:
        ```python
        from tmmaster.pickplace import load_report
        from tmmaster.report import plot_report

        plot_report(load_report("run.json"), "run.png")
        ```

    Args:
        report: A run report (:func:`tmmaster.pickplace.load_report`).
        output: The image file; its suffix picks the format.
        dpi: Resolution of a bitmap, dots per inch.

    Returns:
        The path of the image written.
    """
    import matplotlib

    matplotlib.use("Agg", force=True)  # files only: no display needed
    from matplotlib import pyplot as plt

    figure = _figure(report)
    target = Path(output)
    figure.savefig(target, dpi=dpi)
    plt.close(figure)
    return target
