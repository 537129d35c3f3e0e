"""A fault during a grasp retry: the retry's moves and its recover open under faults.

Hunt 30. The first close misses (the simulator's ``grasp_miss:at_grasp=1``), one retry
is allowed: CHECK_GRASP fails, the retry's ``recover`` opens the fingers, and the run goes
back to MOVE_TO_APPROACH. The fault fires as the run enters a state of that path (the
runner's ``on_state`` event; the retry's entry is the one whose previous state is
CHECK_GRASP): an e-stop during the re-approach, a stop request as CHECK_GRASP starts
(no retry may follow it), the recover's open command frame dropped on the wire (tmflow
sends it again under its number). Judged on the simulator's motion log: every move ran
once in the order issued (matched in order: the retry repeats targets), none after its
give-up, nothing after the run ended, no gripper action after an e-stop, and the result's
failed state, type and stop.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, record_moves
from test_hunt30_pallet_faults import ran_in_order
from test_hunt30_retreat_faults import missed_grasp_with_retreat
from tmmaster import PollPolicy, Robot, TimeoutPolicy
from tmmaster.pickplace import (
    Runner,
    StateEvent,
    pick_and_place,
)
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]
GRIPPER_BLOCK = {"tmflow": 9014, "article": 0x0210}


@pytest.mark.parametrize(
    ("profile", "fault"),
    [
        ("tmflow", "estop_reapproach"),
        ("article", "estop_reapproach"),
        ("tmflow", "stop_at_check"),
        ("article", "stop_at_check"),
        ("tmflow", "drop_recover_open"),
    ],
)
def test_a_fault_in_a_grasp_retry_runs_nothing_undocumented(
    tm_simulator_factory: Factory, profile: str, fault: str
) -> None:
    sim, config = missed_grasp_with_retreat(tm_simulator_factory, profile, grasp_retries=1)
    issued: list[Issued] = []
    fired = threading.Event()
    proxy = FaultProxy(sim.port)
    try:
        with Robot(
            "127.0.0.1",
            proxy.port,
            profile=profile,
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(request_s=0.3, gripper_settle_s=0.05, in_flight_s=0.5),
        ) as robot:
            robot.wait_until_ready(5)
            record_moves(robot, issued)
            runner = Runner.from_config(robot, config)

            def on_state(event: StateEvent) -> None:
                if fired.is_set():
                    return
                if fault == "estop_reapproach" and event.previous == "CHECK_GRASP":
                    fired.set()  # the retry's re-approach: the e-stop during its move
                    sim.inject("estop:at_move=1")
                elif fault == "stop_at_check" and event.state == "CHECK_GRASP":
                    fired.set()
                    helper = threading.Thread(target=runner.request_stop)
                    helper.start()
                    helper.join()
                elif fault == "drop_recover_open" and event.state == "CHECK_GRASP":
                    fired.set()  # the next gripper command is the recover's open
                    proxy.add(
                        Rule("drop_request", function_code=16, address=GRIPPER_BLOCK[profile])
                    )

            runner.on_state = on_state
            result = runner.run(pick_and_place(config), cycles=1)
            ended = time.monotonic()
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 20, timeout=5.0)
    finally:
        proxy.close()
    assert fired.is_set()
    log = sim.motion_log()
    kinds = [m.kind for m in log]
    ran_in_order(issued, log)  # the retry repeats the approach's and the pick's targets
    assert not [m for m in log if m.wall_time > ended], kinds
    if fault == "estop_reapproach":
        assert result.failure is not None
        assert result.failure.state == "MOVE_TO_APPROACH", result.failure
        assert result.failure.type in ("EmergencyStopError", "RobotFaultError"), result.failure
        # The miss, the recover's open, then the re-approach the e-stop cut: nothing else.
        assert kinds == ["ptp", "line", "gripper_close", "gripper_open", "ptp"], kinds
        assert result.reaction is not None
        assert not result.reaction.performed
        assert result.retries == 1
    elif fault == "stop_at_check":
        assert result.interrupted, result.failure
        assert result.failure is not None
        assert result.failure.state == "CHECK_GRASP", result.failure
        assert result.retries == 0  # no retry after the stop: no open, no re-approach
        assert kinds == ["ptp", "line", "gripper_close"], kinds
        assert result.stop_delivered is True, result
    else:  # the open sent again under its number, taken once: the retry completes
        assert result.ok, result.failure
        assert result.retries == 1
        assert kinds == [
            *("ptp", "line", "gripper_close", "gripper_open"),
            *("ptp", "line", "gripper_close", "line", "ptp", "gripper_open", "ptp"),
        ], kinds
