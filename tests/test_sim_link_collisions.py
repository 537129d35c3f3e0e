"""The arm's links and a held part collide with the table and the fixtures, in both backends.

The kinematic backend checks links 2-5 as the MuJoCo scene's capsules (45 mm round the
segment between two joint origins, ``tmmaster.sim._collide``), the held part as its box,
against the table top and each fixture. Each scenario runs on both backends (MuJoCo
when the extra is installed, with its ideal servo): they stop the arm at the same place.
A part set down on a support, and the ordinary pick and place cycles, are no collision.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import tmmaster
from sim_backends import BACKENDS, NEEDS_MUJOCO, until_fault
from test_sim_controller import article, run_until, send_article
from tmmaster import Pose
from tmmaster import _kinematics as kin
from tmmaster._pose import MotionType
from tmmaster.sim import KinematicBackend, TableObject, World
from tmmaster.sim._backend import BackendFault, PhysicsBackend
from tmmaster.sim._collide import (
    ARM_RADIUS_MM,
    FLANGE_RADIUS_MM,
    PALM_CENTRE_MM,
    PALM_HALF_MM,
    Box,
    box_depth,
    segment_depth,
)
from tmmaster.sim._controller import SimErrorCode
from tmmaster.sim._scene import load_scene
from tmmaster.sim._world import DEFAULT_TABLE_TOP_Z_MM, Fixture

MODEL = tmmaster.robot_model("tm5-700")
EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "scene.toml"
DOWN = (180.0, 0.0, 90.0)  # the tool pointing down, the fingers closing along the base x
FAR_PART = TableObject(name="far", pose=Pose(500, 300, 100, *DOWN))

#: A post beside the base (x 140..200, up to 400 mm): the forearm sweeps over it when J1
#: turns the arm from one side to the other, the TCP passes 140 mm beyond it.
POST = Fixture(name="post", pose=Pose(170, 0, 242.5, 0, 0, 0), size_mm=(60, 60, 315))
POST_START = Pose(300, -200, 200, *DOWN)
POST_END = Pose(300, 200, 200, *DOWN)
#: Where the forearm touches the post (MuJoCo: 339.41, -121.67).
POST_TOUCH = (339.4, -121.7)

#: The tool pointing back at the robot (along -x), the TCP 20 mm short of the table's
#: near edge (x = 150): the pads and the palm stay off the table, the wrist's capsule
#: reaches over its edge, 45 mm under the flange.
EDGE_ABOVE = Pose(130, 0, 250, 0, -90, 0)
EDGE_BELOW = Pose(130, 0, 100, 0, -90, 0)

#: A 90 mm tall part, held at its middle: it reaches 45 mm under the TCP, the pads 12.
TALL = TableObject(name="tall", pose=Pose(300, -200, 130, *DOWN), size_mm=(30, 30, 90))
#: A 30 mm block on the table (top at 115 mm) in the tall part's way.
BLOCK = Fixture(name="block", pose=Pose(400, -200, 100, 0, 0, 0), size_mm=(60, 60, 30))
CARRY = Pose(300, -200, 145, *DOWN)  # the part's bottom 15 mm under the block's top


def make(name: str, world: World, home: Pose) -> PhysicsBackend:
    if name == "kinematic":
        return KinematicBackend(MODEL, world=world, home=home)
    from tmmaster.sim._mujoco import MuJoCoBackend

    return MuJoCoBackend(MODEL, world=world, home=home, dynamics=False)


def move(
    b: PhysicsBackend, target: Pose, kind: MotionType = MotionType.LINE, speed: float = 20
) -> BackendFault | None:
    b.start_motion(target, motion=kind, speed_percent=speed, accel_time_s=0.1)
    return until_fault(b, b.is_settled, limit_s=8.0)


def grip(b: PhysicsBackend, width_mm: float) -> BackendFault | None:
    b.drive_gripper(width_mm, speed_mm_s=100, force_n=40)
    return until_fault(b, lambda: not b.gripper_state().moving)


def collision(fault: BackendFault | None, obstacle: str) -> BackendFault:
    assert fault is not None
    assert fault.kind == "collision"
    assert obstacle in fault.message
    return fault


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_the_forearm_hitting_a_tall_fixture_stops_the_arm_with_the_tcp_clear(
    backend_name: str,
) -> None:
    b = make(backend_name, World([FAR_PART], fixtures=[POST]), POST_START)
    fault = collision(move(b, POST_END, MotionType.PTP), "fixture post")
    if backend_name == "kinematic":
        assert "link 3" in fault.message  # the forearm
    tcp = b.tcp_pose()
    assert (tcp.x, tcp.y) == pytest.approx(POST_TOUCH, abs=0.5)
    assert b.is_settled()
    # The TCP, and so the tool and its pads, are far from the post (x 140..200).
    assert tcp.x - 200 > 130
    # Going back the way it came is no new collision.
    assert move(b, POST_START, MotionType.PTP) is None


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_the_forearm_collision_is_tms_error_0x22_and_the_error_state(backend_name: str) -> None:
    backend = make(backend_name, World([FAR_PART], fixtures=[POST]), POST_START)
    ctl, bank, _, log = article(backend=backend)  # type: ignore[arg-type]
    send_article(bank, POST_END, speed=20, command=1)  # a PTP
    run_until(ctl, lambda: bank.get("error_code") != 0)
    assert bank.get("error_code") == SimErrorCode.COLLISION == 0x22
    assert bank.get("robot_mode") == 7  # error
    assert "sim.backend_fault" in log.names()
    tcp = backend.tcp_pose()
    assert (tcp.x, tcp.y) == pytest.approx(POST_TOUCH, abs=0.5)


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_a_wrist_link_dipping_over_the_table_edge_is_a_collision(backend_name: str) -> None:
    b = make(backend_name, World([FAR_PART]), EDGE_ABOVE)
    fault = collision(move(b, EDGE_BELOW), "the table")
    if backend_name == "kinematic":
        assert "link 5" in fault.message
    # The wrist's capsule ends 45 mm from the flange (the TCP here), 45 mm round its axis:
    # it meets the table top (85 mm) with the TCP 45 mm above it. MuJoCo stops within
    # its 2 ms step.
    assert b.tcp_pose().z == pytest.approx(DEFAULT_TABLE_TOP_Z_MM + ARM_RADIUS_MM, abs=0.5)
    assert move(b, EDGE_ABOVE) is None  # backing out


def pick_tall(backend_name: str) -> PhysicsBackend:
    b = make(backend_name, World([TALL], fixtures=[BLOCK]), TALL.pose)
    assert grip(b, 0) is None
    assert b.gripper_state().contact
    assert move(b, CARRY) is None  # lifted off the table it rested on
    return b


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_a_held_part_dragged_into_a_fixture_is_a_collision(backend_name: str) -> None:
    b = pick_tall(backend_name)
    fault = collision(move(b, CARRY.offset(dx=150)), "")
    # The block's side is at x = 370, the part's face 15 mm ahead of the TCP: the pads
    # (18 mm above the block) and the wrist pass over it.
    if backend_name == "kinematic":
        assert "held part tall hit fixture block" in fault.message
        assert b.tcp_pose().x == pytest.approx(370 - 15, abs=0.5)
    else:
        # MuJoCo: the block stops the part, which turns in the grip until a pad presses
        # on it with more than 150 N, some 11 mm further.
        assert 370 - 15 < b.tcp_pose().x < 370
    assert move(b, CARRY) is None  # backing out


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_a_held_part_set_down_on_a_fixture_is_placed(backend_name: str) -> None:
    b = pick_tall(backend_name)
    above = Pose(400, -200, 200, *DOWN)
    on_block = above.offset(dz=115 + 45 - above.z)  # its bottom on the block's top
    assert move(b, above, MotionType.PTP) is None
    assert move(b, on_block) is None
    assert grip(b, 39) is None
    assert move(b, above) is None
    tall = next(o for o in b.objects() if o.name == "tall")
    assert tall.resting_on == "block"
    assert tall.pose.z == pytest.approx(160, abs=0.5)


def test_a_held_part_pushed_into_its_support_is_a_collision() -> None:
    # Set down, then pressed 5 mm on: the kinematic part does not slip in the grip (MuJoCo's
    # friction grip lets it), it is pushed into the block.
    b = pick_tall("kinematic")
    on_block = Pose(400, -200, 160, *DOWN)
    assert move(b, on_block.offset(dz=40), MotionType.PTP) is None
    assert move(b, on_block) is None
    collision(move(b, on_block.offset(dz=-5)), "held part tall hit fixture block")
    assert b.tcp_pose().z == pytest.approx(160 - 0.2, abs=0.05)


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_the_default_cells_pick_and_place_is_no_collision(backend_name: str) -> None:
    # The article's cycle (benchmarks/bench_physics.py), then a place set down on the table.
    pick = Pose(300, -200, 100, *DOWN)
    place = Pose(300, 200, 100, *DOWN)
    b = make(backend_name, World(), Pose(250, 0, 300, *DOWN))
    assert move(b, pick.offset(dz=100), MotionType.PTP, 30) is None
    assert move(b, pick, speed=10) is None
    assert grip(b, 0) is None
    assert move(b, pick.offset(dz=150), speed=10) is None
    assert move(b, place.offset(dz=100), MotionType.PTP, 30) is None
    assert grip(b, 39) is None  # dropped from 100 mm
    assert move(b, pick, MotionType.PTP, 30) is None
    assert grip(b, 0) is None  # nothing there now: the fingers close on air
    assert grip(b, 39) is None
    assert move(b, place.offset(dz=50), MotionType.PTP, 30) is None
    assert move(b, place, speed=10) is None
    assert grip(b, 0) is None
    assert move(b, place.offset(dz=150), speed=10) is None
    assert move(b, place.offset(dx=100, dz=30), MotionType.PTP, 30) is None
    assert move(b, place.offset(dx=100), speed=10) is None  # set down on the table
    assert grip(b, 39) is None
    assert move(b, Pose(250, 0, 300, *DOWN), MotionType.PTP, 30) is None
    part = b.objects()[0]
    assert part.resting_on == "table"
    assert (part.pose.x, part.pose.y) == pytest.approx((400, 200), abs=1)


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_the_example_scenes_pick_and_place_is_no_collision(backend_name: str) -> None:
    # part-1 from the feeder, over the jig, set down on a corner of the shelf beside the
    # part already there; then part-2, which was waiting, dropped onto the table.
    scene = load_scene(EXAMPLE)
    b = make(backend_name, scene.world(), Pose(250, 0, 300, *DOWN))
    pick = Pose(300, -200, 100, *DOWN)
    shelf = Pose(465, 165, 135 + 15, *DOWN)  # the shelf's top at 135 mm
    for target, drop in ((shelf, 0.0), (Pose(300, 100, 100, *DOWN), 100.0)):
        assert move(b, pick.offset(dz=100), MotionType.PTP, 30) is None
        assert move(b, pick, speed=10) is None
        assert grip(b, 0) is None
        assert move(b, pick.offset(dz=150), speed=10) is None
        assert move(b, target.offset(dz=drop + 60), MotionType.PTP, 30) is None
        assert move(b, target.offset(dz=drop), speed=10) is None
        assert grip(b, 39) is None
        assert move(b, target.offset(dz=drop + 60), speed=10) is None
    assert move(b, Pose(250, 0, 300, *DOWN), MotionType.PTP, 30) is None
    rest = {o.name: o.resting_on for o in b.objects()}
    assert rest == {"part-1": "shelf", "part-2": "table", "on-shelf": "shelf"}


@NEEDS_MUJOCO
def test_the_mujoco_scene_has_the_shapes_the_kinematic_backend_checks() -> None:
    # One geometry: the MJCF's link capsules, flange disc and palm box are the numbers of
    # tmmaster.sim._collide.
    from tmmaster.sim._mujoco import build_mjcf

    mjcf = build_mjcf(MODEL, [], table_top_z_mm=DEFAULT_TABLE_TOP_Z_MM)
    radii = set(re.findall(r'type="capsule" fromto="[^"]*" size="([^"]*)"', mjcf))
    assert radii == {f"{ARM_RADIUS_MM / 1000:g}"}
    flange = re.search(r'name="flange" type="cylinder" pos="[^"]*" size="([^ ]*) ', mjcf)
    assert flange is not None
    assert float(flange.group(1)) * 1000 == pytest.approx(FLANGE_RADIUS_MM)
    palm = re.search(r'name="palm" type="box" pos="([^"]*)" size="([^"]*)"', mjcf)
    assert palm is not None
    assert [float(v) * 1000 for v in palm.group(1).split()] == pytest.approx(PALM_CENTRE_MM)
    assert [float(v) * 1000 for v in palm.group(2).split()] == pytest.approx(PALM_HALF_MM)


def test_a_capsules_depth_in_a_box_is_its_radius_less_its_distance_or_more_inside() -> None:
    cube = Box.at("cube", Pose(0, 0, 0, 0, 0, 0), (20, 20, 20))
    assert segment_depth(cube, (0, 0, 15), (0, 0, 100), 10) == pytest.approx(5)  # 5 above
    assert segment_depth(cube, (0, 0, 40), (0, 0, 100), 10) == -1.0  # 30 above
    # Passing its vertical edge (x = y = 10) at sqrt(200) mm: the nearest point of the
    # segment is inside its span, not an end.
    assert segment_depth(cube, (20, 20, -50), (20, 20, 50), 15) == pytest.approx(15 - 200**0.5)
    # Through its centre: the radius and the 10 mm the axis gets inside.
    assert segment_depth(cube, (0, 0, -50), (0, 0, 50), 10) == pytest.approx(20, abs=1e-6)
    # A box turned 45 deg about z, checked in its own frame: a point off its long axis but
    # inside its bounding box is 16.2 mm clear of it.
    bar = Box.at("bar", Pose(0, 0, 0, 0, 0, 45), (100, 10, 10))
    clear = 30 * 2**0.5 / 2 - 5
    assert segment_depth(bar, (30, 0, 0), (30, 0, 0), clear + 1) == pytest.approx(1)


def test_a_boxs_depth_in_a_box_is_the_shortest_move_apart() -> None:
    big = Box.at("big", Pose(0, 0, 0, 0, 0, 0), (40, 40, 40))
    half = (10.0, 10.0, 10.0)
    beside = Pose(27, 0, 0, 0, 0, 0)
    assert box_depth(big, kin.pose_to_transform(beside), half) == pytest.approx(3)
    # Turned 45 deg: its corner reaches 10 sqrt(2) mm towards the big box.
    turned = Pose(32, 0, 0, 0, 0, 45)
    assert box_depth(big, kin.pose_to_transform(turned), half) == pytest.approx(
        20 + 10 * 2**0.5 - 32, abs=1e-6
    )
    apart = Pose(35, 0, 0, 0, 0, 45)
    assert box_depth(big, kin.pose_to_transform(apart), half) == -1.0
    # Turned about two axes, its lowest corner 17.3 mm under its centre (10 sqrt(3)).
    tilted = Pose(0, 0, 20 + 10 * 3**0.5 - 2, 45, 35.2643897, 0)
    assert box_depth(big, kin.pose_to_transform(tilted), half) == pytest.approx(2, abs=1e-3)


#: A thin plate in the pads' way, 5 mm off the TCP along the tool's x: between a pad's
#: corners (x = +/-10 mm) and clear of the TCP, so only the pads' boxes can meet it.
PLATE_TCP = Pose(400, 0, 200, *DOWN)
PLATE = Fixture(
    name="plate",
    pose=kin.transform_to_pose(
        kin.multiply(
            kin.pose_to_transform(PLATE_TCP), kin.rpy_transform((5.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        )
    ),
    size_mm=(4, 80, 16),
)


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_a_plate_thinner_than_a_pad_stops_the_pads_coming_down(backend_name: str) -> None:
    b = make(backend_name, World([FAR_PART], fixtures=[PLATE]), PLATE_TCP.offset(dz=60))
    collision(move(b, PLATE_TCP), "fixture plate")
    # The pads (12 mm under the TCP) met the plate's top (8 mm over the TCP's target).
    assert b.tcp_pose().z == pytest.approx(PLATE_TCP.z + 20, abs=1.0)


#: A small block between the open pads, up at the palm: only the palm's box meets it.
NUB = Fixture(
    name="nub",
    pose=kin.transform_to_pose(
        kin.multiply(
            kin.pose_to_transform(PLATE_TCP),
            kin.rpy_transform((5.0, 0.0, PALM_CENTRE_MM[2]), (0.0, 0.0, 0.0)),
        )
    ),
    size_mm=(4, 10, 6),
)


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_a_block_between_the_open_pads_stops_the_palm(backend_name: str) -> None:
    # A 100 mm tool keeps the wrist's capsule well above the palm.
    tool = Pose(0, 0, 100, 0, 0, 0)
    world, home = World([FAR_PART], fixtures=[NUB]), PLATE_TCP.offset(dz=60)
    if backend_name == "kinematic":
        b: PhysicsBackend = KinematicBackend(MODEL, world=world, home=home, tool=tool)
    else:
        from tmmaster.sim._mujoco import MuJoCoBackend

        b = MuJoCoBackend(MODEL, world=world, home=home, tool=tool, dynamics=False)
    assert grip(b, 39) is None  # wide open: the block passes between the pads
    fault = collision(move(b, PLATE_TCP), "fixture nub")
    assert "link" not in fault.message  # the tool, not the arm
    # The palm's underside (4 mm under its centre) met the block's top (3 mm over its).
    assert b.tcp_pose().z == pytest.approx(PLATE_TCP.z + 7, abs=1.0)
