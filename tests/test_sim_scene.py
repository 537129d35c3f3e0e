"""Scene files: the shipped example loads, a pick runs against it, fixtures stop the arm.

The example scene (``examples/scene.toml``) puts two parts at the feeder, a jig the arm
must not touch, a shelf with a part on it and the default gripper in the cell; both
backends build their world from it, and ``Simulator(scene=...)`` and ``--scene`` run it.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import tmmaster
from sim_backends import BACKENDS, HAS_MUJOCO, STEP_S, until_fault
from tmmaster import Pose
from tmmaster._pose import MotionType
from tmmaster.sim import Cell, KinematicBackend, Simulator
from tmmaster.sim import __main__ as sim_main
from tmmaster.sim._backend import BackendFault, PhysicsBackend
from tmmaster.sim._scene import Scene, load_scene, scene_from_data
from tmmaster.sim._world import Fixture

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "scene.toml"
MODEL = tmmaster.robot_model("tm5-700")
PICK = Pose(300, -200, 100, 180, 0, 90)
#: Beside the jig (x 390..510, y -110..-50, top at 185 mm), low enough for the pads.
BESIDE_JIG = Pose(320, -80, 150, 180, 0, 90)
THROUGH_JIG = BESIDE_JIG.offset(dx=240)


def make(name: str, scene: Scene, home: Pose, **options: object) -> PhysicsBackend:
    if name == "kinematic":
        return KinematicBackend(
            MODEL,
            world=scene.world(),
            gripper=scene.gripper,
            home=home,
            **options,  # type: ignore[arg-type]
        )
    from tmmaster.sim._mujoco import MuJoCoBackend

    return MuJoCoBackend(
        MODEL,
        world=scene.world(),
        gripper=scene.gripper,
        home=home,
        **options,  # type: ignore[arg-type]
    )


def line(b: PhysicsBackend, target: Pose, speed: float = 50) -> BackendFault | None:
    b.start_motion(target, motion=MotionType.LINE, speed_percent=speed, accel_time_s=0.1)
    return until_fault(b, b.is_settled)


def test_the_example_scene_loads_with_its_fixtures_parts_and_gripper() -> None:
    scene = load_scene(EXAMPLE)
    assert scene.table.top_z_mm == 85.0
    assert [f.name for f in scene.fixtures] == ["jig", "shelf"]
    assert [p.name for p in scene.parts] == ["part-1", "part-2", "on-shelf"]
    assert scene.gripper is not None
    assert scene.gripper.max_width_mm == 39.0
    world = scene.world()
    # A part placed in the air drops onto the fixture under it, and says so.
    assert world.resting_on("on-shelf") == "shelf"
    assert world.get("on-shelf").pose.z == pytest.approx(135 + 15)
    assert world.resting_on("part-1") == "table"


def test_a_pick_runs_against_the_example_scene_on_the_kinematic_backend() -> None:
    b = make("kinematic", load_scene(EXAMPLE), home=PICK.offset(dz=100))
    assert line(b, PICK) is None
    b.drive_gripper(0, speed_mm_s=100, force_n=40)
    assert until_fault(b, lambda: not b.gripper_state().moving) is None
    assert b.gripper_state().contact
    assert line(b, PICK.offset(dz=100)) is None
    held = {o.name: o for o in b.objects() if o.held}
    assert list(held) == ["part-1"]
    assert held["part-1"].pose.z == pytest.approx(200)
    # The feeder's next part is waiting where the first one was.
    waiting = {o.name: o for o in b.objects()}["part-2"]
    assert waiting.resting_on == "table"
    assert waiting.pose.z == pytest.approx(100)


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_the_arm_moving_through_a_fixture_is_a_collision(backend_name: str) -> None:
    b = make(backend_name, load_scene(EXAMPLE), home=BESIDE_JIG)
    fault = line(b, THROUGH_JIG, speed=20)
    assert fault is not None
    assert fault.kind == "collision"
    # Stopped where the wrist (a 45 mm capsule round the flange, here the TCP) touches the
    # jig's side (x = 390), before the open pad's outer face (39 / 2 + 8 mm from the TCP).
    assert "fixture jig" in fault.message
    assert b.tcp_pose().x == pytest.approx(390 - 45, abs=3)
    # Backing out is no new collision.
    assert line(b, BESIDE_JIG, speed=20) is None


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_moving_over_a_fixture_is_no_collision(backend_name: str) -> None:
    b = make(backend_name, load_scene(EXAMPLE), home=BESIDE_JIG.offset(dz=60))
    # The pads' bottom (12 mm under the TCP) passes 13 mm above the jig's top.
    assert line(b, THROUGH_JIG.offset(dz=60), speed=50) is None


def test_a_fixture_without_the_world_never_stops_the_arm() -> None:
    # The same move with no jig in the scene: the collision above is the jig's.
    scene = load_scene(EXAMPLE).model_copy(update={"fixtures": ()})
    b = make("kinematic", scene, home=BESIDE_JIG)
    assert line(b, THROUGH_JIG, speed=50) is None


def test_a_rotated_fixture_is_checked_in_its_own_frame() -> None:
    wall = Fixture(name="wall", pose=Pose(0, 0, 0, 0, 0, 45), size_mm=(100, 10, 10))
    assert wall.depth_of((30, 30, 0)) == pytest.approx(5)  # on its long axis
    assert wall.depth_of((30, 0, 0)) == -1.0  # inside its bounding box, not in it


@pytest.mark.skipif(not HAS_MUJOCO, reason="the MuJoCo backend needs the extra")
def test_the_mujoco_scene_has_the_fixtures_and_the_part_rests_on_the_shelf() -> None:
    b = make("mujoco", load_scene(EXAMPLE), home=PICK.offset(dz=100))
    assert 'name="fixture0"' in b.mjcf
    assert 'name="fixture1"' in b.mjcf
    for _ in range(50):
        b.step(STEP_S)
    shelf = {o.name: o for o in b.objects()}["on-shelf"]
    assert shelf.pose.z == pytest.approx(150, abs=1)
    assert shelf.resting_on == "shelf"


def test_simulator_runs_a_scene_file_with_its_gripper_and_grasp() -> None:
    sim = Simulator(cell=Cell(scene=EXAMPLE, grasp="weld"), listen=False)
    try:
        assert [o.name for o in sim.objects()] == ["part-1", "part-2", "on-shelf"]
        backend = sim.backend
        assert isinstance(backend, KinematicBackend)
        assert backend.grasp == "weld"
        assert [f.name for f in backend.world.fixtures] == ["jig", "shelf"]
    finally:
        sim.close()


def test_the_cli_mjcf_of_a_scene_holds_its_fixtures(tmp_path: Path) -> None:
    if not HAS_MUJOCO:
        pytest.skip("the MuJoCo backend needs the extra")
    out = tmp_path / "scene.xml"
    code = sim_main.main(
        ["--physics", "mujoco", "--scene", str(EXAMPLE), "--port", "0", "--mjcf", str(out)]
    )
    assert code == 0
    assert 'name="fixture1"' in out.read_text()


@pytest.mark.parametrize(
    ("data", "named"),
    [
        pytest.param({"table": {"top_z_mm": "high"}}, "table.top_z_mm", id="table-not-number"),
        pytest.param({"table": {"top_z_mm": float("nan")}}, "table.top_z_mm", id="table-nan"),
        pytest.param({"tabel": {}}, "tabel", id="unknown-key"),
        pytest.param(
            {"parts": [{"name": "p", "pose": [1, 2, 3]}]}, "parts.0.pose", id="pose-three"
        ),
        pytest.param(
            {"parts": [{"name": "p", "pose": [0] * 6, "mass_kg": -1}]},
            "parts.0.mass_kg",
            id="mass-negative",
        ),
        pytest.param(
            {"fixtures": [{"name": "f", "pose": [0] * 6, "size_mm": [1, 0, 1]}]},
            "fixtures.0.size_mm",
            id="fixture-flat",
        ),
        pytest.param(
            {"fixtures": [{"name": "f", "pose": [0] * 6}]}, "fixtures.0.size_mm", id="no-size"
        ),
        pytest.param(
            {
                "fixtures": [{"name": "p", "pose": [0] * 6, "size_mm": [1, 1, 1]}],
                "parts": [{"name": "p", "pose": [0] * 6}],
            },
            "parts.0.name",
            id="name-taken",
        ),
        pytest.param(
            {"fixtures": [{"name": "table", "pose": [0] * 6, "size_mm": [1, 1, 1]}]},
            "fixtures.0.name",
            id="name-table",
        ),
        pytest.param({"gripper": {"max_width_mm": 0.5}}, "gripper", id="gripper-stroke"),
        pytest.param({"gripper": {"fingers": 3}}, "gripper.fingers", id="gripper-unknown"),
    ],
)
def test_a_bad_scene_names_the_key(data: dict[str, object], named: str) -> None:
    with pytest.raises(tmmaster.ConfigError, match=named.replace(".", r"\.")):
        scene_from_data(data)


def test_a_scene_file_that_is_not_toml_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("[table\n")
    with pytest.raises(tmmaster.ConfigError, match=r"bad\.toml"):
        load_scene(path)
