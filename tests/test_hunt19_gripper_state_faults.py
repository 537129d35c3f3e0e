"""An e-stop or the Pause button while the pick & place runner waits on the gripper (tmflow).

The existing runner hunts fault the moves (tests/test_hunt9_cli_truth.py: robot error,
e-stop, stall at the 2nd and 4th move) and hold each command frame in the network
(tests/test_hunt6_runner_held_frame.py). This guard faults the two gripper states: the
operator presses the e-stop or Pause exactly as the runner's gripper command lands (the
simulator's request listener, on the write to the gripper command block once the runner
is in that state), before the robot program takes it. What must hold, judged on the
simulator: the run ends in that state with the robot's reason, it reports ``ok`` only
for the states before it, the given-up gripper command never runs, nothing starts after
the run ended, and the operator's reset and Play afterwards run nothing (no new record,
the end-module gripper output and the arm where the run left them). Hunt 19 found these
to hold.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest

from safety_invariant import at_rest
from sim_speeds import QUICK
from tmmaster import EmergencyStopError, PollPolicy, Pose, ProjectPausedError, Robot, TimeoutPolicy
from tmmaster.pickplace import (
    ARTICLE_PICK,
    PICK_AND_PLACE_STATES,
    Runner,
    StateEvent,
    pick_and_place,
    validate_config,
)
from tmmaster.sim import Cell, RequestRecord, Simulator, TableObject

Factory = Callable[..., Simulator]
PICK = Pose.from_sequence(ARTICLE_PICK)
PRESS: dict[str, Callable[[Simulator], None]] = {
    "estop": Simulator.press_estop,
    "pause": Simulator.press_play,  # Play/Pause on a running project pauses it
}
RAISED = {"estop": EmergencyStopError, "pause": ProjectPausedError}
#: Where a gripper command's block starts (tmflow; a move's starts at 9000).
GRIPPER_BLOCK = 9014


@pytest.mark.parametrize("fault", list(PRESS))
@pytest.mark.parametrize("state", ["GRIPPER_CLOSE", "GRIPPER_OPEN"])
def test_a_fault_as_the_gripper_acts_ends_the_run_there_and_nothing_runs_later(
    tm_simulator_factory: Factory, state: str, fault: str
) -> None:
    armed: list[bool] = []
    sims: list[Simulator] = []

    def press_as_the_command_lands(record: RequestRecord) -> None:  # on the loop thread
        if armed == [True] and record.is_write and record.address == GRIPPER_BLOCK:
            armed.append(True)
            PRESS[fault](sims[0])

    sim = tm_simulator_factory(
        "tmflow",
        cell=Cell(scene=[TableObject(name="p", pose=PICK)]),
        request_listener=press_as_the_command_lands,
        **QUICK,
    )
    sims.append(sim)
    config = validate_config({"gripper": {"settle_s": 0.05}, "run": {"poll_interval_s": 0.01}})

    def arm(event: StateEvent) -> None:
        if event.state == state and not armed:
            armed.append(True)

    with Robot(
        "127.0.0.1",
        sim.port,
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(gripper_settle_s=0.05, ack_timeout_s=0.3),
    ) as robot:
        robot.wait_until_ready(5)
        before = len(sim.motion_log())
        result = Runner(robot, on_state=arm).run(pick_and_place(config), cycles=1)
        returned = time.monotonic()

    assert armed == [True, True], "the fault did not fire on the gripper command"
    assert result.failure is not None
    assert (result.failure.state, type(result.failure.exception)) == (state, RAISED[fault])
    states = list(PICK_AND_PLACE_STATES)
    claimed = [r.state for r in result.records if r.outcome == "ok" and r.state != "IDLE"]
    assert claimed == states[: states.index(state)]
    sim.wait_for(at_rest(sim), timeout=5.0, interval=0.02)
    assert all(m.wall_time <= returned for m in sim.motion_log()), "started after the run"
    # The operator resets and presses Play: nothing the run gave up runs now.
    ran, where, output = len(sim.motion_log()), sim.tcp_pose(), sim.do(0, module="end_module")
    assert state.lower() not in [m.kind for m in sim.motion_log()[before:]]  # never ran
    sim.clear_error()
    sim.press_play()
    sim.wait_for(lambda: bool(sim.field("project_running")) and not sim.field("paused"), 2.0)
    ticks = sim.ticks
    sim.wait_for(lambda: sim.ticks >= ticks + 20, timeout=5.0)
    assert len(sim.motion_log()) == ran
    assert sim.tcp_pose().is_close(where, mm=1e-6, deg=1e-6)
    assert sim.do(0, module="end_module") is output
