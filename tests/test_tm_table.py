"""The TM table loader: every entry's function codes agree with its table and access."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from tmmaster import Pose, robot_model
from tmmaster._registers import Access, Table
from tmmaster.sim import KinematicBackend, Simulator
from tmmaster.sim._tm_table import (
    _check_fc,
    _entries,
    tm_table_areas,
    tm_table_markdown,
    user_area,
)


def test_the_function_codes_of_the_manual_name_the_table_and_access() -> None:
    _check_fc("light", "01/05", Table.COIL, Access.READ_WRITE)
    _check_fc("stop", "05", Table.COIL, Access.WRITE)
    _check_fc("speed", "06", Table.HOLDING, Access.WRITE)
    _check_fc("project", "06/16", Table.HOLDING, Access.WRITE)
    _check_fc("ao", "03/16", Table.HOLDING, Access.READ_WRITE)
    _check_fc("error", "02", Table.DISCRETE_INPUT, Access.READ)
    _check_fc("pose", "04", Table.INPUT, Access.READ)


@pytest.mark.parametrize(
    ("fc", "table", "access"),
    [
        ("04", Table.HOLDING, Access.READ),  # FC 04 reads input registers
        ("02", Table.COIL, Access.READ),
        ("01/05", Table.COIL, Access.WRITE),  # FC 01 reads it too
        ("05", Table.COIL, Access.READ_WRITE),  # write-only
        ("03/06", Table.INPUT, Access.READ_WRITE),
        ("01/03", Table.COIL, Access.READ),  # two tables
    ],
)
def test_an_entry_whose_fc_disagrees_is_refused(fc: str, table: Table, access: Access) -> None:
    with pytest.raises(ValueError, match="FC"):
        _check_fc("x", fc, table, access)


def test_the_table_loads_and_names_its_areas() -> None:
    fields = _entries()
    assert len({f.name for f in fields}) == len(fields)
    assert all("p. 3" in f.description for f in fields)  # every entry cites its page
    assert user_area() == ((Table.COIL, 9000, 1000), (Table.HOLDING, 9000, 1000))
    assert (Table.INPUT, 900, 800) in tm_table_areas("External Module")


def test_the_table_doc_is_generated_from_the_toml() -> None:
    committed = (Path(__file__).parent.parent / "docs" / "tm-table.md").read_text("utf-8")
    assert committed == tm_table_markdown(), (
        "docs/tm-table.md is stale: run python -c 'from tmmaster.sim._tm_table import"
        ' tm_table_markdown; print(tm_table_markdown(), end="")\' > docs/tm-table.md'
    )


class JointModelBackend(KinematicBackend):
    """A backend with a (fixed, made-up) joint model: flange and joints of its own."""

    FLANGE = Pose(300.0, -200.0, 300.0, 180.0, 0.0, 90.0)
    JOINTS = (10.0, -20.0, 30.0, -40.0, 50.0, -60.0)

    def joint_positions_deg(self) -> tuple[float, ...] | None:
        return self.JOINTS

    def flange_pose(self) -> Pose | None:
        return self.FLANGE


def test_flange_and_joints_come_from_the_backend_when_it_has_them(
    tm_simulator_factory: Callable[..., Simulator],
) -> None:
    sim = tm_simulator_factory("tmflow", cell=JointModelBackend(robot_model("tm5-700")))
    sim.wait_for(lambda: sim.field("joint_6") == pytest.approx(-60.0), 2.0)
    flange = [sim.field(f"flange_{a}") for a in ("x", "y", "z", "rx", "ry", "rz")]
    base_flange = [sim.field(f"robot_base_flange_{a}") for a in ("x", "y", "z", "rx", "ry", "rz")]
    joints = [sim.field(f"joint_{j}") for j in range(1, 7)]
    tcp = [sim.field(f"robot_base_tcp_{a}") for a in ("x", "y", "z", "rx", "ry", "rz")]
    assert flange == pytest.approx(JointModelBackend.FLANGE.as_list())
    assert base_flange == pytest.approx(flange)
    assert joints == pytest.approx(list(JointModelBackend.JOINTS))
    assert tcp == pytest.approx(sim.tcp_pose().as_list(), abs=1e-3)
    assert flange != pytest.approx(tcp)  # the TCP is not the flange here
