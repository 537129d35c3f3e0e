"""Pick & place on a robot the master's model does not predict.

The runner plans and times its moves from the arm model. A real cell differs: the arm
runs slower or faster than the model (``Cell(speed_factor=)``), the operator has lowered
the project speed, the arm is a calibrated variant. Whatever differs, two full cycles must
run as on the model: the run ends ok, the robot ran exactly the cycle's commands in
order (its own log, never the master's belief), each move ended at rest before the next
started, and both parts lie at the place pose.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

import pytest

from sim_speeds import QUICK
from test_hunt6_runner_held_frame import COMMANDS
from test_hunt11_calibrated_arm import NOMINAL, calibrated, left_flipped
from tmmaster import PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster.pickplace import ARTICLE_PICK, ARTICLE_PLACE, Runner, pick_and_place, validate_config
from tmmaster.sim import Cell, RobotSetup, Simulator, TableObject

Factory = Callable[..., Simulator]
PICK = Pose.from_sequence(ARTICLE_PICK)
PLACE = Pose.from_sequence(ARTICLE_PLACE)
CYCLES = 2

#: Each robot off the model: the simulator options that make it so.
OFF_MODEL: dict[str, dict[str, Any]] = {
    "slower": {"cell_options": {"speed_factor": 0.3}},
    "faster": {"cell_options": {"speed_factor": 2.5}},
    "project_speed_40": {"robot": RobotSetup(project_speed=40)},
    "calibrated": {"robot": RobotSetup(model=calibrated(1.5))},
    "calibrated_slower": {
        "robot": RobotSetup(model=calibrated(-1.5)),
        "cell_options": {"speed_factor": 0.5},
    },
}


def run_cycles(factory: Factory, profile: str, case: str) -> tuple[Simulator, Any]:
    options = dict(OFF_MODEL[case])
    cell = Cell(
        scene=[TableObject(name=f"part-{i}", pose=PICK) for i in range(CYCLES)],
        **options.pop("cell_options", {}),
    )
    sim = factory(profile, cell=cell, **options, **QUICK)
    config = validate_config(
        {
            "robot": {"profile": profile},
            "gripper": {"settle_s": 0.05},
            "run": {"poll_interval_s": 0.02},
            "timeouts": {"ack_s": 1.0, "motion_margin_s": 0.5},
        }
    )
    with Robot(
        sim.url,
        profile=profile,
        polling=PollPolicy(interval_s=0.02),
        timeouts=TimeoutPolicy(gripper_settle_s=0.05),
    ) as robot:
        robot.wait_until_ready(5)
        result = Runner(robot).run(pick_and_place(config), cycles=CYCLES)
    return sim, result


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: Factory) -> Factory:
    """The runner is the subject here, not TCP: simulators in memory."""
    return memory_simulator_factory


@pytest.mark.parametrize("case", list(OFF_MODEL))
@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_two_cycles_run_as_on_the_model(
    tm_simulator_factory: Factory, profile: str, case: str
) -> None:
    if profile == "article" and case in ("project_speed_40",):
        pytest.skip("the article's robot has no project speed")
    sim, result = run_cycles(tm_simulator_factory, profile, case)
    assert result.ok, result.failure
    assert result.cycles_completed == CYCLES
    log = sim.motion_log()
    moves = [kind for kind in COMMANDS.values() if not kind.startswith("gripper")]
    if profile == "tmflow":
        assert [m.kind for m in log] == list(COMMANDS.values()) * CYCLES
    else:  # the article's gripper is a register of its own, not a motion
        assert [m.kind for m in log if not m.kind.startswith("gripper")] == moves * CYCLES
    runs = [m for m in log if m.target is not None]
    for before, after in itertools.pairwise(runs):
        assert before.done_wall_time is not None, before
        assert before.done_wall_time <= after.wall_time, (before, after)
    placed = [
        o for o in sim.objects() if abs(o.pose.x - PLACE.x) < 2 and abs(o.pose.y - PLACE.y) < 2
    ]
    assert len(placed) == CYCLES, sim.objects()


def test_a_run_from_a_wrist_flipped_arm_refuses_its_first_move_unsent(
    tm_simulator_factory: Factory,
) -> None:
    """An earlier program left the arm wrist-flipped at HOME (tmflow: the robot reports
    its joints; the article's map has none, tests/test_hunt11_article_start_posture.py).
    The cycle's first PTP, to the approach, would pass the camera through the wrist: the
    run fails on it before anything is sent, and the arm stays where it was."""
    sim = tm_simulator_factory(
        "tmflow", cell=Cell(scene=[TableObject(name="part", pose=PICK)]), **QUICK
    )
    left_flipped(sim, NOMINAL)
    before, where = len(sim.motion_log()), sim.tcp_pose()
    config = validate_config({"gripper": {"settle_s": 0.05}, "run": {"poll_interval_s": 0.02}})
    with Robot(sim.url, polling=PollPolicy(interval_s=0.02)) as robot:
        result = Runner(robot).run(pick_and_place(config), cycles=CYCLES)
    assert not result.ok
    assert result.failure is not None
    # The runner checks the plan from the arm's joints before its first command (hunt 21,
    # tests/test_hunt21_runner_validates.py): refused in IDLE, naming the approach, the
    # gripper not even opened; it used to be refused as the approach was sent.
    assert result.failure.state == "IDLE"
    assert "(MOVE_TO_APPROACH)" in result.failure.message
    assert "self-collision" in result.failure.message
    assert len(sim.motion_log()) == before
    assert sim.tcp_pose().is_close(where, mm=1e-6, deg=1e-6)
