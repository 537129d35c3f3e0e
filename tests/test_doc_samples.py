"""The README's and the docs' Python samples run as written, right after a simulator starts.

Every ```python block of README.md and docs/*.md runs here, the blocks of one page in
order and in one namespace (a later block may use an earlier one's imports), as a reader
would paste them. A block that talks to ``python -m tmmaster.sim --port 5020`` runs
against a simulator started for it the moment before, on a free loopback port put in
place of 5020: the profile the page tells the reader to start (``--profile article``
for a block with ``profile="article"``, else the default tmflow) and, for a block with
``onrobot-2fg7`` and 5021, that gripper on the port put in place of 5021. No block waits
for the simulator: ``Simulator.start()`` returns once the robot is ready.

An HTML comment on the line before a block says what it needs:

- ``<!-- sample: robot -->``: a fragment that continues with a connected ``robot`` (the
  page's "a simulator started with ... --port 5020"): it gets one, closed after;
- ``<!-- sample: skip (REASON) -->``: not run, for the reason given (a real robot's
  address, a sketch for another program, a signature). Keep these few.

Simulators a block makes itself run at the suite's pace (their explicit options kept).
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

import tmmaster
import tmmaster.sim
from sim_speeds import QUICK
from tmmaster.sim import RobotSetup, Simulator, Timing

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

_BLOCK = re.compile(r"^```python\n(.*?)^```", re.DOTALL | re.MULTILINE)
_MARK = re.compile(r"<!-- sample: (robot|skip)(?: \((.+)\))? -->")


@dataclass(frozen=True)
class Sample:
    """One ```python block: where it is, its code and its mark."""

    where: str
    code: str
    mark: str | None
    reason: str | None


def _samples(page: Path) -> list[Sample]:
    text = page.read_text(encoding="utf-8")
    found = []
    for match in _BLOCK.finditer(text):
        before = text[: match.start()].rstrip().splitlines()
        mark = _MARK.fullmatch(before[-1].strip()) if before else None
        line = text[: match.start()].count("\n") + 1
        found.append(
            Sample(
                f"{page.relative_to(ROOT)}:{line}",
                match.group(1),
                mark.group(1) if mark else None,
                mark.group(2) if mark else None,
            )
        )
    return found


def _has_samples(page: Path) -> bool:
    """Whether ``_samples(page)`` finds a block, without cutting the page at each one.

    Every test process reads this at collection. A block starts at or after the first
    ``"```python\n"``, so the search starts there (``^`` still matches after a newline).
    """
    text = page.read_text(encoding="utf-8")
    first = text.find("```python\n")
    return first >= 0 and _BLOCK.search(text, first) is not None


PAGES_WITH_SAMPLES = [p for p in PAGES if _has_samples(p)]

#: The start-up of a simulator, in wall seconds: a sample that ran before the robot is
#: ready would fail, not slip through. With Simulator's wait for the start-up turned off,
#: 0.1 s still fails the three pages whose samples command at once (README.md, index.md,
#: robot-api.md), under load as well; 0.05 s let one or two of them through.
START_UP_S = 0.1


def _paced(time_scale: float) -> Timing:
    """The suite's tick rate, and ``START_UP_S`` of wall time to start up at ``time_scale``."""
    return Timing(tick_hz=QUICK["timing"].tick_hz, init_time_s=START_UP_S * time_scale)


#: The suite's pace.
PACE: dict[str, Any] = {**QUICK, "timing": _paced(QUICK["time_scale"])}


class _SuitePaced(Simulator):
    """A block's own Simulator at the suite's pace unless it says otherwise.

    A block that gives its own ``time_scale`` (``Simulator("article", time_scale=10)``)
    keeps it, and starts up in ``START_UP_S`` of wall time all the same (the suite's
    ``init_time_s`` at that scale would take 10 times as long).
    """

    def __init__(self, *args: Any, **options: Any) -> None:
        time_scale = options.setdefault("time_scale", PACE["time_scale"])
        options.setdefault("timing", _paced(time_scale))
        for key, value in PACE.items():
            options.setdefault(key, value)
        super().__init__(*args, **options)


@contextlib.contextmanager
def _simulators(code: str) -> Iterator[str]:
    """Start what ``code`` expects on 5020 (and 5021); yield the code with their ports."""
    with contextlib.ExitStack() as stack:
        if "5020" in code:
            gripper = "onrobot-2fg7" if "onrobot-2fg7" in code and "5021" in code else None
            profile = "article" if 'profile="article"' in code else "tmflow"
            sim = stack.enter_context(Simulator(profile, robot=RobotSetup(gripper=gripper), **PACE))
            real = {"5020": str(sim.port)}
            if gripper is not None:
                real["5021"] = str(sim.gripper_port)
            # In one pass, whole numbers only: the robot's port may contain "5021".
            code = re.sub(r"\b(?:5020|5021)\b", lambda m: real.get(m[0], m[0]), code)
        yield code


#: An address literal: a sample runs only if each is a loopback one.
_ADDRESS = re.compile(r"\b\d{1,3}(?:\.\d{1,3}){3}\b")


def _run(sample: Sample, namespace: dict[str, Any]) -> None:
    # Never anything but loopback: a sample for a real cell is marked skip.
    outside = [a for a in _ADDRESS.findall(sample.code) if not a.startswith("127.")]
    assert not outside, f"{sample.where} talks to {outside}: mark it <!-- sample: skip (...) -->"
    with _simulators(sample.code) as code, contextlib.ExitStack() as stack:
        if sample.mark == "robot":
            sim = stack.enter_context(Simulator(**PACE))
            namespace["robot"] = stack.enter_context(tmmaster.connect(sim.host, sim.port))
        exec(compile(code, sample.where, "exec"), namespace)


def test_every_page_with_samples_is_found() -> None:
    names = {p.name for p in PAGES_WITH_SAMPLES}
    assert {"README.md", "robot-api.md", "simulator.md"} <= names


def test_the_skipped_samples_are_few_and_say_why() -> None:
    skipped = [s for p in PAGES_WITH_SAMPLES for s in _samples(p) if s.mark == "skip"]
    assert all(s.reason for s in skipped), [s.where for s in skipped if not s.reason]
    assert len(skipped) <= 10, [s.where for s in skipped]


@pytest.mark.parametrize("page", PAGES_WITH_SAMPLES, ids=lambda p: p.name)
def test_the_samples_of_a_page_run_right_after_start_up(
    page: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(tmmaster.sim, "Simulator", _SuitePaced)
    namespace: dict[str, Any] = {"__name__": "__sample__"}
    for sample in _samples(page):
        if sample.mark == "skip":
            continue
        if "mujoco" in sample.code:
            pytest.importorskip("mujoco")
        _run(sample, namespace)
    capsys.readouterr()
