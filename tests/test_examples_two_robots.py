"""examples/two_robots.py runs: on its own simulators, and on two given ports."""

from __future__ import annotations

from collections.abc import Callable
from types import ModuleType

import pytest

from examples_support import load_example
from tmmaster.sim import Simulator, TableObject

Factory = Callable[..., Simulator]


@pytest.fixture(scope="module")
def example() -> ModuleType:
    """The example script, imported as a module."""
    return load_example("two_robots")


def test_handover_on_its_own_simulators(example: ModuleType) -> None:
    result = example.run_with_simulators(time_scale=20.0)
    shared = result.handover
    assert shared.errors == {}
    # B came down to the handover table only after A had released and moved clear.
    assert shared.time_of("A", "released") < shared.time_of("B", "descending to handover")
    assert shared.time_of("B", "waiting above handover") < shared.time_of("B", "picked")
    # Each simulated world: A's part on the handover table, B's part at B's place pose.
    assert example.check_worlds(result) == []
    (part_a,) = result.objects_a
    (part_b,) = result.objects_b
    assert part_a.pose.is_close(example.HANDOVER)
    assert not part_a.held
    assert part_b.pose.is_close(example.PLACE_B)
    assert not part_b.held


def test_main_defaults_to_sim_and_exits_0(
    example: ModuleType, capsys: pytest.CaptureFixture[str]
) -> None:
    assert example.main(["--time-scale", "20"]) == 0
    assert "handover done" in capsys.readouterr().out


def test_main_on_given_ports(tm_simulator_factory: Factory, example: ModuleType) -> None:
    sim_a = tm_simulator_factory(objects=[TableObject(name="part", pose=example.PICK_A)])
    sim_b = tm_simulator_factory(objects=[TableObject(name="part", pose=example.HANDOVER)])
    code = example.main(
        ["--port-a", str(sim_a.port), "--port-b", str(sim_b.port), "--settle", "0.05"]
    )
    assert code == 0
    assert sim_a.objects()[0].pose.is_close(example.HANDOVER)
    assert sim_b.objects()[0].pose.is_close(example.PLACE_B)


def test_b_does_not_pick_when_a_fails(tm_simulator_factory: Factory, example: ModuleType) -> None:
    # A's world has no part: A's grip fails, so B must not come down to the table.
    sim_a = tm_simulator_factory(objects=[])
    sim_b = tm_simulator_factory(objects=[TableObject(name="part", pose=example.HANDOVER)])
    shared = example.run(sim_a.port, sim_b.port, settle_s=0.05)
    assert set(shared.errors) == {"A", "B"}
    assert "robot A failed" in str(shared.errors["B"])
    assert not any(who == "B" and step == "picked" for _, who, step in shared.steps)
    assert sim_b.objects()[0].pose.is_close(example.HANDOVER)
    assert not sim_b.objects()[0].held


def test_ports_must_come_in_pairs(example: ModuleType) -> None:
    with pytest.raises(SystemExit):
        example.main(["--port-a", "5020"])
