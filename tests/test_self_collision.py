"""Self-collision, the mounting plane and the 2FG7 housing: refused before any byte, stopped
by both simulator backends when forced (``tmmaster._body``'s capsules, fitted to Techman's
collision meshes)."""

from __future__ import annotations

import logging
import random
from collections.abc import Callable
from typing import Any

import pytest

import tmmaster
from sim_backends import BACKENDS, until_fault
from test_sim_controller import article, run_until, send_article
from tmmaster import ConfigError, Pose, Robot, UnreachablePoseError, Workspace
from tmmaster import _body as body
from tmmaster._planning import Planner, TimeoutPolicy
from tmmaster._pose import MotionType
from tmmaster.sim import KinematicBackend, Simulator, World
from tmmaster.sim._backend import BackendFault, PhysicsBackend
from tmmaster.sim._controller import SimErrorCode
from tmmaster.sim._world import Fixture

MODEL = tmmaster.robot_model("tm5-700")
READY = (0.0, 0.0, 90.0, 0.0, 90.0, 0.0)
#: The wrist folded back: the end module's camera 17 mm into the forearm's wrist end,
#: the TCP 244 mm above the base, over the table.
FOLDED = (-44.0, -8.0, 122.0, -23.0, 120.0, -136.0)
#: Behind the robot, the tool down 30 mm above the mounting plane (its table at z = 0):
#: the TCP, the flange and the tool are above the plane, the end module's camera (52 mm
#: beyond the flange) 22 mm below it.
BEHIND_HIGH = Pose(-300, 0, 300, 180, 0, -90)
BEHIND_LOW = Pose(-300, 0, 30, 180, 0, -90)
#: A TCP 180 mm beyond the flange: room for the 2FG7's 144 mm housing.
LONG_TOOL = Pose(0, 0, 180, 0, 0, 0)
#: A beam across the table at the housing's height (z 390..410) when the TCP is at 300
#: with the tool down: the pads (288..312) pass under it, the flange (480) over it.
BEAM = Fixture(name="beam", pose=Pose(450, 0, 400, 0, 0, 0), size_mm=(20, 600, 20))
BEAM_FROM = Pose(350, 0, 300, 180, 0, 90)
BEAM_TO = Pose(550, 0, 300, 180, 0, 90)


class _Settings:
    position_tolerance_mm = 0.5
    orientation_tolerance_deg = 0.5
    timeouts = TimeoutPolicy()


def planner(workspace: Workspace | None = None, tool: Pose | None = None) -> Planner:
    return Planner(
        MODEL,
        workspace=workspace or Workspace(),
        tool=tool,
        check_units=True,
        max_speed_percent=100,
        settings=_Settings(),
        log=logging.getLogger("test"),
    )


def motion_writes(sim: Simulator) -> list[object]:
    """Every FC16 that reached the robot (the command block is one FC16) but the master's
    heartbeat (9050), which is written on its own schedule."""
    return [
        r for r in sim.request_log if r.function_code == 16 and not r.refused and r.address != 9050
    ]


# -- the master ---------------------------------------------------------------------------


def test_the_capsules_name_the_colliding_pair_and_its_depth() -> None:
    found = body.contacts(MODEL, FOLDED)
    assert found, "the folded wrist collides"
    first = found[0]
    assert "link 6 camera" in (first.first, first.second)
    assert first.distance_mm < -10
    assert body.contacts(MODEL, READY) == []


def test_a_self_colliding_joint_target_is_refused_before_any_byte(
    robots: Callable[..., Robot], memory_simulator_factory: Callable[..., Simulator]
) -> None:
    sim = memory_simulator_factory("tmflow")
    robot = robots(sim)
    sim.clear_request_log()
    with pytest.raises(ConfigError, match="self-collision") as caught:
        robot.move_joints(FOLDED, speed=30)
    assert "link 6 camera" in str(caught.value)
    assert "link 3 " in str(caught.value)
    assert motion_writes(sim) == []


def test_a_self_colliding_cartesian_target_is_refused_by_validate() -> None:
    # From the ready posture the nearest solution is the folded wrist.
    target = MODEL.forward(FOLDED)
    with pytest.raises(ConfigError, match=r"self-collision.*link 6 camera"):
        planner().validate(target, 30, READY)
    # ... and the same joints as a joint target, with no joints known to start from.
    with pytest.raises(ConfigError, match=r"self-collision.*link 6 camera"):
        planner().joint_target(FOLDED, 30)


def test_a_link_below_the_mounting_plane_is_refused_with_the_tcp_above(
    robots: Callable[..., Robot], memory_simulator_factory: Callable[..., Simulator]
) -> None:
    sim = memory_simulator_factory("tmflow")
    robot = robots(sim)
    robot.workspace = Workspace(floor_z_mm=0)  # a table level with the mounting plane
    sim.clear_request_log()
    with pytest.raises(ConfigError, match="mounting plane") as caught:
        robot.move_to(BEHIND_LOW, speed=30)
    assert "link 6 camera" in str(caught.value)
    assert motion_writes(sim) == []


def test_a_cell_without_a_floor_may_reach_below_the_mounting_plane() -> None:
    high = MODEL.inverse(BEHIND_HIGH, seed_deg=READY)
    planner(Workspace(floor_z_mm=None)).validate(BEHIND_LOW, 30, high)
    with pytest.raises(ConfigError, match="mounting plane"):
        planner(Workspace(floor_z_mm=0)).validate(BEHIND_LOW, 30, high)


#: The tool tilted sideways 124 mm above the table: the pads and the tool's extent above
#: it (85 mm), the 2FG7 housing's 40 mm radius under it.
TILTED = (61.3, 29.7, 100.4, 49.8, 61.3, 90.0)


def test_the_2fg7_housing_below_the_table_is_refused() -> None:
    cell = Workspace(arm_radius_mm=None)  # the links' own check aside
    with pytest.raises(ConfigError, match="2FG7 housing at z = 8"):
        planner(cell, tool=LONG_TOOL).validate(MODEL.forward(TILTED, LONG_TOOL), 30, TILTED)
    # The TCP at the flange leaves no room for a housing: the same joints pass.
    planner(cell).validate(MODEL.forward(TILTED), 30, TILTED)


def test_ordinary_targets_over_the_table_are_still_accepted() -> None:
    # 200 random targets over the table, the tool down, J6 within 90 deg of its middle:
    # none refused by the body checks, the PTP from the ready posture included.
    rng = random.Random(5)
    p = planner()
    accepted = 0
    while accepted < 200:
        pose = Pose(
            round(rng.uniform(300, 600), 1),
            round(rng.uniform(-300, 300), 1),
            round(rng.uniform(150, 400), 1),
            180.0,
            0.0,
            round(90 + rng.uniform(-90, 90), 1),
        )
        try:
            joints = MODEL.inverse(pose, seed_deg=READY)
        except UnreachablePoseError:
            continue
        try:
            p.workspace.check_arm(MODEL, joints)
        except ConfigError:
            continue
        accepted += 1
        p.validate(pose, 50, READY)


# -- the simulator ---------------------------------------------------------------------


def make(name: str, home: Pose, **options: Any) -> PhysicsBackend:
    if name == "kinematic":
        return KinematicBackend(MODEL, home=home, **options)
    from tmmaster.sim._mujoco import MuJoCoBackend

    return MuJoCoBackend(MODEL, home=home, dynamics=False, **options)


def collision(fault: BackendFault | None, *names: str) -> None:
    assert fault is not None
    assert fault.kind == "collision"
    for name in names:
        assert name in fault.message


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_a_forced_self_colliding_joint_move_stops_the_arm(backend_name: str) -> None:
    b = make(backend_name, MODEL.forward(READY), world=World())
    b.start_joint_motion(FOLDED, speed_percent=50, accel_time_s=0.2)
    collision(until_fault(b, b.is_settled, limit_s=8.0), "link 6 camera", "link 3")
    assert b.is_settled()


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_a_forced_move_below_the_mounting_plane_stops_the_arm(backend_name: str) -> None:
    b = make(backend_name, BEHIND_HIGH, world=World())
    b.start_motion(BEHIND_LOW, motion=MotionType.LINE, speed_percent=30, accel_time_s=0.2)
    collision(until_fault(b, b.is_settled, limit_s=8.0), "the mounting plane", "link 6 camera")
    # Stopped with the camera at the plane (its 2 mm margin): the TCP 52 + 2 mm above it.
    assert b.tcp_pose().z == pytest.approx(54, abs=3)


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_the_mounting_plane_is_tms_collision_error(backend_name: str) -> None:
    backend = make(backend_name, BEHIND_HIGH, world=World())
    ctl, bank, _, _ = article(backend=backend)  # type: ignore[arg-type]
    send_article(bank, BEHIND_LOW, speed=20, command=2)  # a Line
    run_until(ctl, lambda: bank.get("error_code") != 0)
    assert bank.get("error_code") == SimErrorCode.COLLISION
    assert bank.get("robot_mode") == 7  # error


@pytest.mark.parametrize("backend_name", BACKENDS)
def test_a_beam_at_the_2fg7_housings_height_stops_the_arm(backend_name: str) -> None:
    clear = make(backend_name, BEAM_FROM, tool=LONG_TOOL, world=World())
    clear.start_motion(BEAM_TO, motion=MotionType.LINE, speed_percent=30, accel_time_s=0.2)
    assert until_fault(clear, clear.is_settled, limit_s=8.0) is None
    b = make(backend_name, BEAM_FROM, tool=LONG_TOOL, world=World(fixtures=[BEAM]))
    b.start_motion(BEAM_TO, motion=MotionType.LINE, speed_percent=30, accel_time_s=0.2)
    collision(until_fault(b, b.is_settled, limit_s=8.0), "fixture beam")
    # The housing's 40 mm radius meets the beam's near face (x = 440).
    assert b.tcp_pose().x == pytest.approx(400, abs=1)
