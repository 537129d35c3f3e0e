"""pytest fixtures for testing code that talks to a TM robot: a simulator per test.

Opt-in, so installing tmmaster costs other test suites nothing: enable it with
``-p tmmaster.sim.pytest_plugin`` (e.g. in ``addopts``) or
``pytest_plugins = ["tmmaster.sim.pytest_plugin"]`` in your top-level ``conftest.py``:

``tm_simulator``
    A started :class:`~tmmaster.sim.Simulator` speaking the ``tmflow`` profile (the
    default of every entry point) on a free loopback port, running 20x faster than real
    time; closed after the test.
``tm_simulator_factory``
    ``tm_simulator_factory(profile="tmflow", **options)`` starts a Simulator with any
    :class:`~tmmaster.sim.Simulator` options (defaults: a free port and
    ``time_scale=20``), e.g. ``tm_simulator_factory("article",
    robot=RobotSetup(gripper="onrobot-2fg7"), faults=["estop:at_move=2"])``; every one
    it made is closed after the test.

The profile is the simulator's register map, and the code under test must speak the same
one. For the article's map, ask for it: ``tm_simulator_factory("article")``, and connect
with ``Robot(sim.url, profile="article")``; ``Robot(sim.url, profile=sim.profile)`` follows
whatever the simulator speaks. A Robot on the other profile fails on its first read
with a :class:`~tmmaster.ProfileMismatchError` that names the profile the simulator
answers.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from ._simulator import Simulator

#: Simulated seconds per wall second used by the fixtures: moves of a few seconds
#: finish in a fraction of a second while a 50 Hz tick still sees every step.
FIXTURE_TIME_SCALE = 20.0


@pytest.fixture
def tm_simulator_factory() -> Iterator[Callable[..., Simulator]]:
    """Start Simulators with any options; all are closed after the test."""
    # Imported here so merely loading the plugin stays cheap for unrelated test suites.
    from ._simulator import Simulator

    made: list[Simulator] = []

    def make(profile: Any = "tmflow", **options: Any) -> Simulator:
        options.setdefault("time_scale", FIXTURE_TIME_SCALE)
        sim = Simulator(profile, **options)
        made.append(sim)
        return sim.start()

    yield make
    gone = {where for sim in made for where in _addresses(sim)}
    for sim in reversed(made):
        sim.close()
    _forget_what_robots_owe(gone)


def _addresses(sim: Simulator) -> list[tuple[str, int]]:
    """Where a Robot reaches ``sim``: its URL, and its loopback ports when it listens."""
    ports = [sim.port, sim.gripper_port] if sim.listen else []
    return [(sim.url, 0), *(("127.0.0.1", port) for port in ports if port is not None)]


def _forget_what_robots_owe(gone: set[tuple[str, int]] | None) -> None:
    """What Robots of this process left owed to the simulators at ``gone`` (None: at every
    address; a Stop the link could not carry, a late output frame, a gripper's Stop: kept
    per process and robot address) ends with them: a later test's simulator on the same
    port or name is another robot, whose first call would otherwise deliver it."""
    from .. import _channels, _command, _gripper, _io

    owed: list[dict[Any, Any]] = [_command._STOPS_OWED, _io._WATCHED, _gripper._STOP_DOUBTS]
    owed.append(_channels.STOP_SHOWS_BY)  # a Stop not shown yet: waited for by a press
    for debts in owed:
        for key in [key for key in debts if gone is None or tuple(key[:2]) in gone]:
            del debts[key]


@pytest.fixture
def tm_simulator(tm_simulator_factory: Callable[..., Simulator]) -> Simulator:
    """A started tmflow-profile Simulator on a free port (time_scale 20), closed after the test."""
    return tm_simulator_factory()
