"""A grasp retry whose recovery the robot refuses is reported as the pass that failed.

A missed grasp (the simulator's ``grasp_miss``) makes CHECK_GRASP fail; its retry rule
opens the fingers (the recovery) and goes back to the approach. The operator presses
the e-stop exactly as that open lands (the simulator's request listener, on the write
to the gripper command block once the run is in CHECK_GRASP): the recovery fails, and
the run ends there. The report said that CHECK_GRASP pass was a ``retry`` (the state's
``retries`` 1, ``failures`` 0) while its ``error`` named CHECK_GRASP as the state that
failed the run, and nothing was tried again: the robot never moved after the close.

Found by this hunt (fails without its fix): the pass is recorded once its recovery
succeeded (``retry``), else as ``failed``. The judge for "never tried again" is the
simulator's motion log.
"""

from __future__ import annotations

from collections.abc import Callable

from sim_speeds import QUICK
from tmmaster import EmergencyStopError, PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster.pickplace import (
    ARTICLE_PICK,
    Runner,
    StateEvent,
    pick_and_place,
    validate_config,
)
from tmmaster.sim import Cell, RequestRecord, Simulator, TableObject

Factory = Callable[..., Simulator]
#: Where a gripper command's block starts (tmflow).
GRIPPER_BLOCK = 9014


def test_a_retry_whose_recovery_fails_is_the_failed_pass_not_a_retry(
    tm_simulator_factory: Factory,
) -> None:
    armed: list[bool] = []
    sims: list[Simulator] = []

    def estop_as_the_open_lands(record: RequestRecord) -> None:  # on the loop thread
        if armed == [True] and record.is_write and record.address == GRIPPER_BLOCK:
            armed.append(True)
            sims[0].press_estop()

    part = TableObject(name="p", pose=Pose.from_sequence(ARTICLE_PICK))
    sim = tm_simulator_factory(
        "tmflow",
        cell=Cell(scene=[part]),
        faults=["grasp_miss:at_grasp=1"],
        request_listener=estop_as_the_open_lands,
        **QUICK,
    )
    sims.append(sim)
    config = validate_config({"gripper": {"settle_s": 0.05}, "run": {"poll_interval_s": 0.01}})

    def arm(event: StateEvent) -> None:
        if event.state == "CHECK_GRASP" and not armed:
            armed.append(True)

    with Robot(
        "127.0.0.1",
        sim.port,
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(gripper_settle_s=0.05),
    ) as robot:
        result = Runner(robot, on_state=arm).run(pick_and_place(config))

    assert armed == [True, True], "the e-stop did not fire on the recovery's open"
    assert [m.kind for m in sim.motion_log()] == ["ptp", "line", "gripper_close"]
    assert result.failure is not None
    assert result.failure.state == "CHECK_GRASP"
    assert isinstance(result.failure.exception, EmergencyStopError)
    assert result.retries == 0
    assert [(r.state, r.outcome) for r in result.records][-1] == ("CHECK_GRASP", "failed")
    check = result.state_timings()["CHECK_GRASP"]
    assert (check["retries"], check["failures"]) == (0, 1)
