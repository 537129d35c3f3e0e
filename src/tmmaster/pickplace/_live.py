"""The live display of ``python -m tmmaster.pickplace`` on a terminal (rich).

One region at the bottom of the terminal shows the state, cycle k/N, a bar that
advances with every state of the cycle, the elapsed time, an ETA and the last event; log
records are printed *above* it through the same console (:attr:`LiveProgress.log_stream`
is what ``configure_logging`` writes to), so a log line never breaks the display.
Imported only when stderr is a terminal.
"""

from __future__ import annotations

import contextlib
import re
import sys
import threading
import time
from collections.abc import Sequence
from typing import Any

from rich.console import Console, Group
from rich.live import Live
from rich.progress_bar import ProgressBar
from rich.table import Table
from rich.text import Text

from .._sigint import deferred
from ._runner import StateEvent

#: structlog's leading ISO timestamp: the live region has its own clock.
_TIMESTAMP = re.compile(r"^\d{4}-\d\d-\d\dT[\d:.]+Z?\s+")


class _ConsoleStream:
    """A text stream whose complete lines are printed through a rich console."""

    def __init__(self, console: Console, on_line: Any) -> None:
        self._console = console
        self._on_line = on_line
        self._buffer = ""
        self._lock = threading.Lock()

    def write(self, text: str) -> int:
        """Buffer ``text``; print every complete line above the live region."""
        with self._lock:
            self._buffer += text
            *lines, self._buffer = self._buffer.split("\n")
        for line in lines:
            rendered = Text.from_ansi(line)
            self._on_line(rendered.plain)  # first: the redraw below shows it as the last event
            with deferred():  # drawing: see LiveProgress
                self._console.print(rendered, soft_wrap=True)
        return len(text)

    def flush(self) -> None:
        """Print a pending partial line."""
        with self._lock:
            pending, self._buffer = self._buffer, ""
        if pending:
            with deferred():
                self._console.print(Text.from_ansi(pending), soft_wrap=True)

    def isatty(self) -> bool:
        """True: the console renders colours (structlog colours its key=value lines)."""
        return self._console.is_terminal


#: The bar's width on the line it shares, at most and at least (narrower: a line of its own).
_BAR_WIDTH = 30
_BAR_MIN_WIDTH = 10


def _row(*cells: Any) -> Table:
    """One line of cells two columns apart, none of them wrapped or cut."""
    grid = Table.grid(padding=(0, 2))
    for _ in cells:
        grid.add_column(no_wrap=True)
    grid.add_row(*cells)
    return grid


class LiveProgress:
    """State, cycle k/N, a progress bar, elapsed time, ETA and last event, redrawn in place.

    Each drawing in the main thread holds a Ctrl-C back until it is done (:func:`deferred`):
    a KeyboardInterrupt raised inside rich's drawing left the region on the screen, or
    erased the lines above it, when the region was cleared.
    """

    def __init__(self, console: Console, *, refresh_per_second: float = 4.0) -> None:
        self.console = console
        #: Give this to ``configure_logging(stream=...)``: records print above the display.
        self.log_stream = _ConsoleStream(console, self._log_line)
        self._refresh = refresh_per_second
        self._live: Live | None = None
        self.cycles = 0
        self.expected_cycle_s: float | None = None
        #: The states of one cycle, in order (the bar advances by one of them at a time).
        self.states: list[str] = []
        #: The share of the current cycle behind, 0..1, by its states.
        self.within_cycle = 0.0
        self.state = "STARTING"
        self.cycle = 0
        #: Completed cycles timed, and their seconds together (the ETA's mean).
        self.cycles_timed = 0
        self.cycle_total_s = 0.0
        self.last_event = ""
        self._t0 = time.monotonic()
        self._cycle_t0 = self._t0

    # -- life cycle -------------------------------------------------------------------

    def begin(
        self, cycles: int, expected_cycle_s: float | None = None, states: Sequence[str] = ()
    ) -> None:
        """Start drawing (the run is about to connect); ``states``: one cycle's, in order."""
        self.cycles = cycles
        self.expected_cycle_s = expected_cycle_s
        self.states = list(states)
        self._t0 = self._cycle_t0 = time.monotonic()
        if self._live is None:
            self._live = Live(
                get_renderable=self.renderable,
                console=self.console,
                refresh_per_second=self._refresh,
                transient=True,
                # Stray prints land above the region; stdout only when it is this
                # terminal too (``> out.txt`` keeps its lines in the file).
                redirect_stdout=sys.stdout.isatty(),
                redirect_stderr=True,
            )
            self._live.start()

    def end(self) -> None:
        """Stop drawing and clear the region (the summary follows).

        The region is let go of inside the section that holds Ctrl-C back: a Ctrl-C
        landing before that section leaves it for the next call to clear (the command
        calls this again after the run).
        """
        with deferred(), contextlib.suppress(OSError):  # a terminal hung up: gone
            if (live := self._live) is not None:
                self._live = None
                live.stop()

    def __call__(self, event: StateEvent) -> None:
        """The runner's ``on_state`` listener."""
        now = time.monotonic()
        if not self.cycle:
            self._cycle_t0 = now  # the first state of cycle 1
        elif event.cycle > self.cycle or event.state == "DONE":
            self.cycles_timed += 1
            self.cycle_total_s += now - self._cycle_t0
            self._cycle_t0 = now
        if event.state in self.states:  # entered: the states before it are behind
            self.within_cycle = self.states.index(event.state) / len(self.states)
        self.state = event.state
        self.cycle = event.cycle
        self.cycles = event.cycles
        self.last_event = f"{event.previous} -> {event.state}"
        if self._live is not None:
            try:
                with deferred():
                    self._live.refresh()
            except OSError:  # the terminal hung up (an SSH session lost): drawn no more
                self.end()  # its refresh thread stopped too

    def _log_line(self, line: str) -> None:
        text = _TIMESTAMP.sub("", line.strip())
        if text:
            self.last_event = " ".join(text.split())

    # -- drawing -----------------------------------------------------------------------

    def eta_s(self, now: float | None = None) -> float | None:
        """Seconds left: mean completed cycle (else the plan's estimate) x cycles left."""
        now = time.monotonic() if now is None else now
        if self.state in ("DONE", "ERROR"):
            return 0.0
        if self.cycles_timed:
            per_cycle: float | None = self.cycle_total_s / self.cycles_timed
        else:
            per_cycle = self.expected_cycle_s
        if per_cycle is None or self.cycles <= 0:
            return None
        left_in_cycle = max(per_cycle - (now - self._cycle_t0), 0.0) if self.cycle else per_cycle
        later = max(self.cycles - max(self.cycle, 1), 0)
        return left_in_cycle + later * per_cycle

    def progress(self) -> tuple[float, int]:
        """The bar: ``(completed, total)`` in cycles, the current one by its states behind.

        Full at DONE; at ERROR it stays where the run stopped.
        """
        total = max(self.cycles, 1)
        if self.state == "DONE":
            return float(total), total
        if self.cycle < 1:
            return 0.0, total
        return min(self.cycle - 1 + self.within_cycle, float(total)), total

    def renderable(self) -> Any:
        """What the live region shows now: a line and the last event, on a narrow terminal
        the bar on a line of its own; the state's name is never cut."""
        now = time.monotonic()
        eta = self.eta_s(now)
        style = {"DONE": "bold green", "ERROR": "bold red"}.get(self.state, "bold cyan")
        name_width = max([len(self.state), *(len(s) for s in self.states), len("STARTING")])
        state = Text(self.state.ljust(name_width), style=style)
        cycle = Text(f"cycle {max(self.cycle, 1) if self.cycles else 0}/{self.cycles}")
        # Fixed widths: the layout does not jump as the numbers grow.
        elapsed = Text(f"elapsed {now - self._t0:6.1f} s")
        left = Text("ETA     -" if eta is None else f"ETA {eta:5.1f} s")
        completed, total = self.progress()
        texts = [state, cycle, elapsed, left]
        room = self.console.width - sum(t.cell_len for t in texts) - 2 * len(texts)
        if room >= _BAR_MIN_WIDTH:  # all on one line
            bar = ProgressBar(total=total, completed=completed, width=min(room, _BAR_WIDTH))
            lines = [_row(state, cycle, bar, elapsed, left)]
        else:  # the bar below, the full width; the times too if they do not fit either
            bar = ProgressBar(total=total, completed=completed)
            if room + _BAR_MIN_WIDTH >= 0:
                lines = [_row(*texts), _row(bar)]
            else:
                lines = [_row(state, cycle), _row(elapsed, left), _row(bar)]
        last = Text(f"last: {self.last_event}", style="dim", overflow="ellipsis", no_wrap=True)
        return Group(*lines, last)
