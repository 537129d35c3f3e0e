"""examples/two_robots.py runs: on its own simulators, and on two given ports."""

from __future__ import annotations

from collections.abc import Callable
from types import ModuleType

import pytest

from examples_support import load_example
from sim_speeds import QUICK, ticking_simulator
from tmmaster.sim import Cell, Simulator, TableObject

Factory = Callable[..., Simulator]

#: The example's own simulators tick at Simulator's default 50 Hz, which allows 20x at
#: most; its tests run them at 50x with the tick raised to match (``fast_example``). The
#: example scales its gripper settle time with the time scale itself (1 / time_scale).
EXAMPLE_TIME_SCALE = 50.0
# The simulators a test starts for the example run at QUICK (sim_speeds).


@pytest.fixture(scope="module")
def example() -> ModuleType:
    """The example script, imported as a module."""
    return load_example("two_robots")


@pytest.fixture
def fast_example(example: ModuleType, monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    """The example, its own simulators ticking fast enough for their time scale.

    Only the tick rate is added: the example still builds, fills and runs its simulators
    itself; the handover is checked on events, not on wall-clock times.
    """
    monkeypatch.setattr(example, "Simulator", ticking_simulator)
    return example


def test_handover_on_its_own_simulators(fast_example: ModuleType) -> None:
    example = fast_example
    result = example.run_with_simulators(time_scale=EXAMPLE_TIME_SCALE)
    shared = result.handover
    assert shared.errors == {}
    # B came down to the handover table only after A had released and moved clear.
    assert shared.time_of("A", "released") < shared.time_of("B", "going to handover")
    assert shared.time_of("B", "waiting clear of handover") < shared.time_of("B", "picked")
    # Each simulated world: A's part on the handover table, B's part at B's place pose.
    assert example.check_worlds(result) == []
    (part_a,) = result.objects_a
    (part_b,) = result.objects_b
    assert part_a.pose.is_close(example.HANDOVER)
    assert not part_a.held
    assert part_b.pose.is_close(example.PLACE_B)
    assert not part_b.held


# main() on its own simulators: the first command of the example's docstring
# (tests/test_examples_docstrings.py).


def test_main_on_given_ports(tm_simulator_factory: Factory, example: ModuleType) -> None:
    sim_a = tm_simulator_factory(
        cell=Cell(scene=[TableObject(name="part", pose=example.PICK_A)]), **QUICK
    )
    sim_b = tm_simulator_factory(
        cell=Cell(scene=[TableObject(name="part", pose=example.HANDOVER_B)]), **QUICK
    )
    code = example.main(
        ["--port-a", str(sim_a.port), "--port-b", str(sim_b.port), "--settle", "0.05"]
    )
    assert code == 0
    assert sim_a.objects()[0].pose.is_close(example.HANDOVER)
    assert sim_b.objects()[0].pose.is_close(example.PLACE_B)
    # A's last move took it clear of the handover point, back over its own pick position.
    (*_, last_a) = [m.target for m in sim_a.motion_log() if m.target is not None]
    assert last_a.is_close(example.above(example.PICK_A))


def test_the_article_profile_on_both(tm_simulator_factory: Factory, example: ModuleType) -> None:
    sim_a = tm_simulator_factory(
        "article", cell=Cell(scene=[TableObject(name="part", pose=example.PICK_A)]), **QUICK
    )
    sim_b = tm_simulator_factory(
        "article", cell=Cell(scene=[TableObject(name="part", pose=example.HANDOVER_B)]), **QUICK
    )
    argv = ["--port-a", str(sim_a.port), "--port-b", str(sim_b.port), "--settle", "0.05"]
    assert example.main([*argv, "--profile", "article"]) == 0
    assert sim_b.objects()[0].pose.is_close(example.PLACE_B)


def test_b_does_not_pick_when_a_fails(tm_simulator_factory: Factory, example: ModuleType) -> None:
    # A's world has no part: A's grip fails, so B must not come down to the table.
    sim_a = tm_simulator_factory(cell=Cell(scene=[]))
    sim_b = tm_simulator_factory(
        cell=Cell(scene=[TableObject(name="part", pose=example.HANDOVER_B)])
    )
    shared = example.run(sim_a.port, sim_b.port, settle_s=0.05)
    assert set(shared.errors) == {"A", "B"}
    assert "robot A failed" in str(shared.errors["B"])
    assert not any(who == "B" and step == "picked" for _, who, step in shared.steps)
    assert sim_b.objects()[0].pose.is_close(example.HANDOVER_B)
    assert not sim_b.objects()[0].held


def test_ports_must_come_in_pairs(example: ModuleType) -> None:
    with pytest.raises(SystemExit):
        example.main(["--port-a", "5020"])
