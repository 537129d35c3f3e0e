"""``[gripper] held_input`` during a run: a wrong input, one that flickers, one whose read
fails. None of them may have a part dropped (the fingers opened on a part still held).

``_release`` opens at the place only once the input says the part is still held; at the
start a part counts as held when the input or the gripper's flag says so
(tests/test_held_input.py). What the simulated world did decides: the part in the
fingers, the gripper's output (the end module's DO 0) still high.

- an input wired to nothing (DI 1): the release finds it low and fails the run
  ("lost on the way"), the fingers left closed on the part;
- an input that reads low once, at the release (a flicker: the proxy answers that read
  with the start's answer, when the gripper was empty): the same, safe side;
- the input's read refused (a Modbus exception) at the start: the run fails in IDLE,
  nothing moved, the gripper not opened; at the release: the run fails there, the part
  still held.
"""

from __future__ import annotations

from typing import Any

from fault_proxy import FaultProxy, Rule
from test_held_input import FAST, PLACE, output_high, part_held, sim  # noqa: F401 (fixture)
from tmmaster import GraspFailedError, ModbusExceptionError, robot_profile
from tmmaster._io import io_address
from tmmaster.pickplace import Runner, RunResult, pick_and_place, robot_from_config, validate_config
from tmmaster.sim import Simulator

#: The end module's DI 0: the gripper's input the program reads (DI 1 is wired to none).
DI0 = io_address(robot_profile("tmflow"), "end_module", "di", 0)


def run_through(port: int, **gripper: Any) -> RunResult:
    """One cycle of the built-in pick & place (the error reaction: stay)."""
    config = validate_config({**FAST, "gripper": {"settle_s": 0.05, **gripper}})
    with robot_from_config(config, "127.0.0.1", port) as robot:
        return Runner.from_config(robot, config).run(pick_and_place(config))


def assert_failed_at_the_release_holding_the_part(result: RunResult, world: Simulator) -> None:
    assert result.failure is not None
    assert result.failure.state == "GRIPPER_OPEN", result.failure
    assert part_held(world), "the part was dropped"
    assert output_high(world), "the gripper was opened"
    assert world.tcp_pose().distance_to(PLACE) < 1.0  # where the release was asked


def test_an_input_wired_to_nothing_fails_the_release_with_the_part_still_held(
    sim: Simulator,  # noqa: F811 (the fixture)
) -> None:
    result = run_through(sim.port, held_input=1)
    assert isinstance(result.failure and result.failure.exception, GraspFailedError)
    assert_failed_at_the_release_holding_the_part(result, sim)


def test_an_input_that_reads_low_once_at_the_release_never_drops_the_part(
    sim: Simulator,  # noqa: F811 (the fixture)
) -> None:
    with FaultProxy(sim.port) as proxy:
        # Each read of the input gets the answer the one before it got (the first is
        # relayed as is): the release's, the start's (the gripper empty): low, while the
        # part is in the fingers.
        flicker = proxy.add(Rule("stale_answer", function_code=2, address=DI0, times=99))
        result = run_through(proxy.port, held_input=0)
    assert flicker.times <= 97, "the scenario: the release's read was answered stale"
    assert isinstance(result.failure and result.failure.exception, GraspFailedError)
    assert_failed_at_the_release_holding_the_part(result, sim)


def test_an_input_read_refused_at_the_start_moves_and_opens_nothing(
    sim: Simulator,  # noqa: F811 (the fixture)
) -> None:
    motions = len(sim.motion_log())
    with FaultProxy(sim.port) as proxy:
        proxy.add(Rule("drop_request", function_code=2, address=DI0, exception=4, times=99))
        result = run_through(proxy.port, held_input=0)
    assert result.failure is not None
    assert result.failure.state == "IDLE"
    assert isinstance(result.failure.exception, ModbusExceptionError)
    assert len(sim.motion_log()) == motions
    assert not output_high(sim)  # never closed, never opened: the DO untouched


def test_an_input_read_refused_at_the_release_keeps_the_part(
    sim: Simulator,  # noqa: F811 (the fixture)
) -> None:
    with FaultProxy(sim.port) as proxy:
        proxy.add(Rule("drop_request", function_code=2, address=DI0, exception=4, nth=2))
        result = run_through(proxy.port, held_input=0)
    assert result.failure is not None
    assert isinstance(result.failure.exception, ModbusExceptionError), result.failure
    assert_failed_at_the_release_holding_the_part(result, sim)
