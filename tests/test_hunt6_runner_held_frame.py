"""A pick & place run stopped while its command frame is held in the network (tmflow).

The pick & place runner drives every move and both gripper commands through the robot
program's sequence handshake. For each state of the cycle that sends a command, a
FaultProxy holds that state's command write (FC16 to the command block: 9000 for a
move, 9014 for a gripper command; armed when the runner enters the state, never counted),
and the run's stop is requested as soon as the frame is held. The run ends interrupted;
only then does the held frame land. What must hold, judged on the simulator: nothing the
robot does starts after the run ended (no motion, no gripper command), the command of
the stopped state never ran, and the end-module gripper output is where the run left
it; the run pressed Stop (it was interrupted), and the operator's Play afterwards runs
nothing. (Three guards stand here at once: the cancel record, the new session after a
write in doubt, the stopped project and its start-up rule; removing the first two by
hand was not caught, the third holds alone.)
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy, Rule
from pendant import runs_again_without_moving
from safety_invariant import at_rest
from sim_speeds import QUICK
from tmmaster import PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster.pickplace import ARTICLE_PICK, Runner, StateEvent, pick_and_place, validate_config
from tmmaster.sim import Cell, Simulator, TableObject

Factory = Callable[..., Simulator]
PICK = Pose.from_sequence(ARTICLE_PICK)
#: Each state of the cycle that sends a command, and what the robot logs when it runs it.
COMMANDS = {
    "MOVE_TO_APPROACH": "ptp",
    "MOVE_TO_PICK": "line",
    "GRIPPER_CLOSE": "gripper_close",
    "MOVE_TO_LIFT": "line",
    "MOVE_TO_PLACE": "ptp",
    "GRIPPER_OPEN": "gripper_open",
    "MOVE_TO_HOME": "ptp",
}
#: The first address of a move's command block, and of a gripper command's.
MOVE_BLOCK, GRIPPER_BLOCK = 9000, 9014


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory(
        "tmflow", cell=Cell(scene=[TableObject(name="part", pose=PICK)]), **QUICK
    )


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


@pytest.mark.parametrize("state", list(COMMANDS))
def test_a_run_stopped_while_its_command_frame_is_held_never_runs_it_later(
    sim: Simulator, proxy: FaultProxy, state: str
) -> None:
    config = validate_config(
        {
            "gripper": {"settle_s": 0.05},
            "run": {"poll_interval_s": 0.01},
            "timeouts": {"ack_s": 0.5, "motion_margin_s": 0.5},
        }
    )
    release, ended = threading.Event(), threading.Event()
    with Robot(
        "127.0.0.1",
        proxy.port,
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(request_s=0.3, gripper_settle_s=0.05),
    ) as robot:
        robot.wait_until_ready(5)
        runner = Runner(robot)

        def on_state(event: StateEvent) -> None:
            if event.state == state and not proxy.played("hold"):
                block = GRIPPER_BLOCK if state.startswith("GRIPPER") else MOVE_BLOCK
                proxy.add(Rule("hold", function_code=16, address=block, release=release))

        def stop_once_held() -> None:
            while not proxy.played("hold"):
                if ended.wait(0.005):
                    return
            runner.request_stop()

        runner.on_state = on_state
        helper = threading.Thread(target=stop_once_held)
        helper.start()
        try:
            result = runner.run(pick_and_place(config), cycles=1)
        finally:
            ended.set()
            helper.join(5)
        ran_at_end, output_at_end = len(sim.motion_log()), sim.do(0, module="end_module")
        run_ended = time.monotonic()
        release.set()  # the held frame lands now, after the run gave it up
        proxy.wait_held()
        landed = [
            r
            for r in sim.request_log
            if r.function_code == 16 and r.address in (MOVE_BLOCK, GRIPPER_BLOCK)
        ]
        assert landed, "no command block reached the robot"
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 20, timeout=5.0)  # room to take it
        sim.wait_for(at_rest(sim), timeout=5.0, interval=0.05)
        log = sim.motion_log()
        assert result.interrupted, result.failure
        assert result.failure is not None
        assert result.failure.state == state
        late = [m for m in log if m.wall_time > run_ended]
        assert not late, f"started after the run ended: {late}"
        # Every command before the stopped state's ran once; that one, and nothing after.
        before = list(COMMANDS.values())[: list(COMMANDS).index(state)]
        assert [m.kind for m in log] == before
        assert len(log) == ran_at_end
        assert sim.do(0, module="end_module") is output_at_end
        # The interrupted run pressed Stop: the operator's Play runs nothing either.
        assert not sim.field("project_running")
        sim.press_play()
        runs_again_without_moving(sim, sim.tcp_pose(), ran_at_end)
        assert sim.do(0, module="end_module") is output_at_end
