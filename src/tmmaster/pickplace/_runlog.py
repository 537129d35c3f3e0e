"""What a run keeps of its passes: every pass counted, some cycles kept pass by pass.

A cell runs for a shift or for days (up to 1,000,000 cycles): a record of every pass
through a state would grow the runner's memory and the report without bound. The
:class:`RunLog` counts every pass into per-state statistics as it comes, and keeps the
passes themselves of a bounded set of cycles: the first ones (with IDLE's, cycle 0), the
latest ones, and the cycles with a retry or a failure, up to a cap. Cycle times are kept
the same way: the statistics of all, the times of the first and the latest.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any, Protocol

#: The cycles kept pass by pass from the start (cycle 0, the IDLE wait, comes with them).
FIRST_CYCLES = 10
#: The latest cycles kept pass by pass.
LAST_CYCLES = 10
#: The most other cycles with a retry or a failure kept pass by pass.
MARKED_CYCLES = 100
#: The cycle times kept from the start, and from the end (the rest are only counted).
CYCLE_TIMES = 1000
#: The most blocks of the cycle-time trend: each block is the statistics of consecutive
#: cycles, and two neighbours merge (the block twice as long) when one more is needed.
TREND_BLOCKS = 200


class Pass(Protocol):
    """A pass through a state (the runner's ``StateRecord``)."""

    @property
    def state(self) -> str: ...
    @property
    def cycle(self) -> int: ...
    @property
    def duration_s(self) -> float: ...
    @property
    def outcome(self) -> str: ...


@dataclass
class Stats:
    """Count, total, minimum and maximum of durations, added one at a time."""

    count: int = 0
    total_s: float = 0.0
    min_s: float = 0.0
    max_s: float = 0.0
    retries: int = 0
    failures: int = 0

    def add(self, seconds: float) -> None:
        """Count one duration."""
        self.min_s = seconds if not self.count else min(self.min_s, seconds)
        self.max_s = max(self.max_s, seconds)
        self.count += 1
        self.total_s += seconds

    def merged(self, other: Stats) -> Stats:
        """The statistics of both (durations only)."""
        if not other.count:
            return Stats(self.count, self.total_s, self.min_s, self.max_s)
        if not self.count:
            return other.merged(self)
        return Stats(
            self.count + other.count,
            self.total_s + other.total_s,
            min(self.min_s, other.min_s),
            max(self.max_s, other.max_s),
        )

    def as_dict(self) -> dict[str, Any]:
        """``count``, ``total_s``, ``mean_s``, ``min_s``, ``max_s`` (rounded to 0.1 ms),
        ``retries`` and ``failures``."""
        mean = self.total_s / self.count if self.count else 0.0
        return {
            "count": self.count,
            "total_s": round(self.total_s, 4),
            "mean_s": round(mean, 4),
            "min_s": round(self.min_s, 4),
            "max_s": round(self.max_s, 4),
            "retries": self.retries,
            "failures": self.failures,
        }


class RunLog:
    """Every pass counted; the passes of a bounded set of cycles kept.

    Memory stays bounded whatever the number of cycles: at most ``first + last + marked``
    cycles (plus cycle 0 and the current one) of passes, and ``2 * times`` cycle times.

    Args:
        first: Cycles kept from the start (1..first; cycle 0 always).
        last: The latest cycles kept.
        marked: The most other cycles with a retry or a failed pass kept.
        times: Cycle times kept from the start, and as many from the end.
    """

    def __init__(
        self,
        *,
        first: int = FIRST_CYCLES,
        last: int = LAST_CYCLES,
        marked: int = MARKED_CYCLES,
        times: int = CYCLE_TIMES,
    ) -> None:
        self.first, self.last, self.marked = first, last, marked
        #: Per state, the passes not skipped.
        self.states: dict[str, Stats] = {}
        #: Every completed cycle's time.
        self.cycles = Stats()
        #: Passes through any state (skipped ones too).
        self.passes = 0
        #: Cycles with a retry or a failed pass not kept (over ``marked``, not the latest).
        self.marked_dropped = 0
        self._head: list[Any] = []
        self._marked: list[list[Any]] = []
        self._tail: deque[tuple[list[Any], bool]] = deque(maxlen=last)
        self._current: list[Any] = []
        self._current_cycle = 0
        self._current_marked = False
        self._cycles_seen = 0
        self._times_head: list[float] = []
        self._times_tail: deque[float] = deque(maxlen=times)
        self._times_cap = times
        #: Cycles per block of the trend (doubles as the run goes on).
        self.block_cycles = 1
        self._blocks: list[Stats] = []

    def add(self, record: Pass) -> None:
        """Count one pass and keep it while its cycle may be kept."""
        self.passes += 1
        if record.outcome != "skipped":
            stats = self.states.setdefault(record.state, Stats())
            stats.add(record.duration_s)
            stats.retries += record.outcome == "retry"
            stats.failures += record.outcome == "failed"
        if record.cycle <= self.first:
            self._head.append(record)
            return
        if record.cycle != self._current_cycle:
            self._close_cycle()
            self._current_cycle = record.cycle
        self._current.append(record)
        self._current_marked |= record.outcome in ("retry", "failed")

    def cycle_time(self, seconds: float) -> None:
        """Count one completed cycle's time."""
        self.cycles.add(seconds)
        if not self._blocks or self._blocks[-1].count >= self.block_cycles:
            if len(self._blocks) >= TREND_BLOCKS:
                pairs = zip(self._blocks[::2], self._blocks[1::2], strict=True)
                self._blocks = [a.merged(b) for a, b in pairs]
                self.block_cycles *= 2
            self._blocks.append(Stats())
        self._blocks[-1].add(seconds)
        if len(self._times_head) < self._times_cap:
            self._times_head.append(seconds)
        else:
            self._times_tail.append(seconds)

    def _close_cycle(self) -> None:
        """File the passes of the cycle that ended: marked, latest, or let go."""
        if not self._current:
            return
        self._cycles_seen += 1
        if self._current_marked and len(self._marked) < self.marked:
            self._marked.append(self._current)
        elif self.last > 0:
            if len(self._tail) == self.last and self._tail[0][1]:
                self.marked_dropped += 1  # a marked cycle over the cap leaves the latest
            self._tail.append((self._current, self._current_marked))
        else:
            self.marked_dropped += self._current_marked
        self._current, self._current_marked = [], False

    def records(self) -> list[Any]:
        """The kept passes, in the order they ran."""
        self._close_cycle()
        tail = [kept for kept, _ in self._tail]
        cycles = sorted([*self._marked, *tail], key=lambda kept: kept[0].cycle)
        return [*self._head, *(r for kept in cycles for r in kept)]

    @property
    def times_kept_first(self) -> int:
        """How many cycle times are kept from the start."""
        return len(self._times_head)

    def cycle_times(self) -> tuple[list[float], int]:
        """The kept cycle times (the first, then the latest) and how many between them
        were only counted."""
        omitted = self.cycles.count - len(self._times_head) - len(self._times_tail)
        return [*self._times_head, *self._times_tail], omitted

    def trend(self) -> list[tuple[int, int, float, float, float]]:
        """The cycle-time trend: per block of consecutive cycles, ``(first cycle, cycles,
        mean_s, min_s, max_s)``; at most TREND_BLOCKS blocks whatever the cycles."""
        rows = []
        for i, block in enumerate(self._blocks):
            d = block.as_dict()
            rows.append(
                (i * self.block_cycles + 1, block.count, d["mean_s"], d["min_s"], d["max_s"])
            )
        return rows

    def scope(self) -> dict[str, Any]:
        """What the kept passes cover (the report's ``timeline_scope``)."""
        kept = self.records()
        listed = len({r.cycle for r in kept if r.cycle > 0})
        all_cycles = max((r.cycle for r in kept), default=0)
        return {
            "passes": self.passes,
            "listed_passes": len(kept),
            "listed_cycles": listed,
            "omitted_cycles": max(all_cycles - listed, 0),
            "first_cycles": self.first,
            "last_cycles": self.last,
            "marked_cycles": self.marked,
            "marked_cycles_omitted": self.marked_dropped,
        }

    def state_timings(self) -> dict[str, dict[str, Any]]:
        """Per state (passes not skipped): :meth:`Stats.as_dict`."""
        return {state: stats.as_dict() for state, stats in self.states.items()}
