"""The API reference's examples run as written.

Every ```python block in the docstring of a public name (or of a public class's member)
runs here. An example that talks to ``python -m tmmaster.sim --port 5020`` (and
``--port 5021``) runs against simulators started for it on free loopback ports, their
port numbers put in place of the documented ones; an example that makes its own
simulator runs as it is.
"""

from __future__ import annotations

import contextlib
import importlib
import inspect
import re
import textwrap
from collections.abc import Iterator

import pytest

from sim_speeds import QUICK
from tmmaster.sim import Simulator

PACKAGES = (
    "tmmaster",
    "tmmaster.aio",
    "tmmaster.sim",
    "tmmaster.pickplace",
    "tmmaster.report",
    "tmmaster.tmscript",
)

#: The main entry points: each has an example.
REQUIRED = {
    "tmmaster.connect",
    "tmmaster.Robot",
    "tmmaster.Robot.move_to",
    "tmmaster.Gripper",
    "tmmaster.Fleet",
    "tmmaster.aio.connect",
    "tmmaster.aio.AsyncRobot",
    "tmmaster.sim.Simulator",
}

#: Examples that need what a test cannot give them, and why.
NOT_RUN = {"tmmaster.report.plot_report": "reads a run report file of the reader's"}

#: The documented simulator ports, replaced by real ones.
PORTS = ("5020", "5021")

_BLOCK = re.compile(r"```python\n(.*?)```", re.DOTALL)


def _documented() -> Iterator[tuple[str, str]]:
    """``(qualified name, docstring)`` of every public name and public class member."""
    seen: set[int] = set()
    for package in PACKAGES:
        module = importlib.import_module(package)
        for name in module.__all__:
            value = getattr(module, name)
            if id(value) in seen or not (inspect.isclass(value) or inspect.isfunction(value)):
                continue
            seen.add(id(value))
            yield f"{package}.{name}", value.__doc__ or ""
            if inspect.isclass(value):
                for member, attribute in vars(value).items():
                    if member.startswith("_"):
                        continue
                    if isinstance(attribute, property):
                        attribute = attribute.fget
                    elif isinstance(attribute, staticmethod | classmethod):
                        attribute = attribute.__func__
                    doc = getattr(attribute, "__doc__", None)
                    if callable(attribute) and isinstance(doc, str):
                        yield f"{package}.{name}.{member}", doc


def _examples() -> list[tuple[str, str]]:
    found = []
    for where, doc in _documented():
        if "```python\n" not in doc:
            continue  # no block in the cleaned text either (cleandoc keeps each line's end)
        for index, code in enumerate(_BLOCK.findall(inspect.cleandoc(doc))):
            found.append((f"{where}[{index}]", textwrap.dedent(code)))
    return found


EXAMPLES = _examples()


def test_the_main_entry_points_have_examples() -> None:
    with_examples = {where.rsplit("[", 1)[0] for where, _ in EXAMPLES}
    assert sorted(REQUIRED - with_examples) == []


@pytest.mark.parametrize(("where", "code"), EXAMPLES, ids=[where for where, _ in EXAMPLES])
def test_the_example_runs(where: str, code: str, capsys: pytest.CaptureFixture[str]) -> None:
    if where.rsplit("[", 1)[0] in NOT_RUN:
        pytest.skip(NOT_RUN[where.rsplit("[", 1)[0]])
    with contextlib.ExitStack() as stack:
        # In one pass, whole numbers only: a simulator's own port may contain "5021"
        # (50215 became 338775 when the ports were replaced one after the other).
        real = {
            port: str(stack.enter_context(Simulator(**QUICK)).port)
            for port in PORTS
            if re.search(rf"\b{port}\b", code)
        }
        code = re.sub(r"\b(?:" + "|".join(PORTS) + r")\b", lambda m: real[m[0]], code)
        exec(compile(code, where, "exec"), {"__name__": "__example__"})
    capsys.readouterr()
