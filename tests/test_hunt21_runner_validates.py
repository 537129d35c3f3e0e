"""A library ``Runner.run()`` checks the whole plan before its first command.

The design principle: every pose, speed and register value is validated before the
first byte is sent, so nothing moves. The command (``python -m tmmaster.pickplace``)
called ``validate_plan()`` before the run; ``Runner.run()`` did not. A library user's
run of a sequence whose later step, pallet slot or cycle the arm cannot take made the
first moves (a part picked and carried) and then failed at the refused move: the part
held in the air, where the run ended.

Now the runner checks every known move of the cycles it is about to run, from the pose
and joints the ready robot reports, before its first command: such a run fails in IDLE
with ``ConfigError`` (``UnreachablePoseError``), and the simulated robot saw no command
write and made no motion (its request log and motion log say so, not the master). A
move made in a step's own code is known only when it runs: it is checked when it is
sent, as every move is.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

import tmmaster
import tmmaster.pickplace.__main__ as pickplace_main
import tmmaster.pickplace._runner as pickplace_runner
from sim_speeds import QUICK
from tmmaster import ConfigError, PollPolicy, Pose, Robot, TimeoutPolicy, UnreachablePoseError
from tmmaster.pickplace import (
    ARTICLE_PICK,
    IDLE,
    Pallet,
    Runner,
    RunResult,
    StepContext,
    TaskSequence,
    palletizing,
    pick_and_place,
    sequence_from_data,
    validate_config,
)
from tmmaster.sim import Cell, Simulator, TableObject

SimFactory = Callable[..., Simulator]
PICK = Pose.from_sequence(ARTICLE_PICK)
HOME = tmmaster.DEFAULT_HOME
#: Far beyond a TM5-700's reach (700 mm), yet a pose the tmflow profile encodes.
FAR = Pose(900, 200, 200, 180, 0, 90)
#: The tmflow command register (a move's or the gripper's command code).
COMMAND_REGISTER = 9014


@pytest.fixture
def sim(memory_simulator_factory: SimFactory) -> Simulator:
    """A tmflow simulator with three parts at the pick pose (in memory: the runner is the
    subject here, not TCP)."""
    parts = [TableObject(name=f"part-{i}", pose=PICK) for i in range(3)]
    return memory_simulator_factory("tmflow", cell=Cell(scene=parts), **QUICK)


@pytest.fixture
def robot(sim: Simulator) -> Iterator[Robot]:
    """A connected robot; the simulator's logs start empty once it is connected."""
    with Robot(
        sim.url,
        profile="tmflow",
        polling=PollPolicy(interval_s=0.02),
        timeouts=TimeoutPolicy(gripper_settle_s=0.05),
    ) as r:
        sim.clear_request_log()
        yield r


def commands(sim: Simulator) -> list[object]:
    """The writes of a command (a move or a gripper action) the simulator received."""
    return [
        r
        for r in sim.request_log
        if r.is_write and r.address <= COMMAND_REGISTER < r.address + r.count
    ]


def assert_refused_before_anything_moved(
    sim: Simulator, result: RunResult, state: str, motions: int
) -> None:
    """The run failed in IDLE naming ``state``, and the robot saw no command, no motion."""
    assert commands(sim) == [], "a command was sent before the plan was refused"
    assert len(sim.motion_log()) == motions, "the robot moved before the plan was refused"
    assert not any(o.held for o in sim.objects()), "a part was picked"
    assert not result.ok
    failure = result.failure
    assert failure is not None
    assert (failure.state, failure.cycle) == (IDLE, 0)
    assert isinstance(failure.exception, UnreachablePoseError)
    assert f"({state})" in failure.message
    assert result.cycles_completed == 0
    assert [r.state for r in result.records] == [IDLE]


def test_the_built_in_pick_and_place_with_a_place_out_of_reach_moves_nothing(
    sim: Simulator, robot: Robot
) -> None:
    # The 4th move (the place) is out of reach: the approach, pick, grip and lift used
    # to run, and the run ended with the part held above the pick.
    config = validate_config(
        {"poses": {"place": FAR.as_list()}, "gripper": {"settle_s": 0.05}, "run": {"cycles": 1}}
    )
    motions = len(sim.motion_log())
    result = Runner.from_config(robot, config).run(pick_and_place(config), source="cell.toml")
    assert_refused_before_anything_moved(sim, result, "MOVE_TO_PLACE", motions)
    assert failure_message(result).startswith("cell.toml: poses.place (MOVE_TO_PLACE): ")


def failure_message(result: RunResult) -> str:
    assert result.failure is not None
    return result.failure.message


def test_a_toml_sequence_whose_fifth_step_is_out_of_reach_moves_nothing(
    sim: Simulator, robot: Robot
) -> None:
    seq = sequence_from_data(
        {
            "name": "carry-far",
            "poses": {"part": list(ARTICLE_PICK), "far": FAR.as_list()},
            "steps": [
                {"state": "ABOVE", "do": "move", "pose": "part", "z_offset": 100, "speed": 30},
                {"state": "DOWN", "do": "move", "pose": "part", "speed": 10, "motion": "line"},
                {"state": "GRASP", "do": "grip"},
                {"state": "UP", "do": "move", "pose": "part", "z_offset": 150, "speed": 10},
                {"state": "AWAY", "do": "move", "pose": "far", "speed": 30},
                {"state": "DROP", "do": "release"},
            ],
        },
        source="carry.toml",
    )
    motions = len(sim.motion_log())
    result = Runner(robot).run(seq, source="carry.toml")
    assert_refused_before_anything_moved(sim, result, "AWAY", motions)
    assert failure_message(result).startswith("carry.toml: ")


def test_a_toml_sequence_whose_last_cycle_moves_out_of_reach_moves_nothing(
    sim: Simulator, robot: Robot
) -> None:
    # Cycles 1 and 2 are fine; only the last cycle's move (``when = "last_cycle"``) is
    # out of reach: two parts used to be carried before the third cycle was refused.
    seq = sequence_from_data(
        {
            "name": "last-far",
            "cycles": 3,
            "poses": {"part": list(ARTICLE_PICK), "far": FAR.as_list()},
            "steps": [
                {"state": "ABOVE", "do": "move", "pose": "part", "z_offset": 100, "speed": 30},
                {"state": "DOWN", "do": "move", "pose": "part", "speed": 10, "motion": "line"},
                {"state": "UP", "do": "move", "pose": "part", "z_offset": 100, "speed": 10},
                {"state": "PARK", "do": "move", "pose": "far", "speed": 30, "when": "last_cycle"},
            ],
        }
    )
    motions = len(sim.motion_log())
    result = Runner(robot).run(seq)
    assert_refused_before_anything_moved(sim, result, "PARK", motions)
    # Without a source, the message names the sequence.
    assert failure_message(result).startswith("sequence last-far: ")


def test_palletizing_with_a_later_slot_out_of_reach_moves_nothing(
    sim: Simulator, robot: Robot
) -> None:
    # Slots 1 and 2 (x 300 and 500 mm) can be reached, slot 3 (x 700 mm) cannot: two
    # parts used to be placed, the third carried from the pick and the run ended with it
    # in the air.
    pallet = Pallet(origin=Pose(300, 200, 100, 180, 0, 90), rows=1, cols=3, dx=200, dy=0)
    seq = palletizing(pick=PICK, pallet=pallet, home=HOME)
    motions = len(sim.motion_log())
    result = Runner(robot).run(seq)
    assert_refused_before_anything_moved(sim, result, "MOVE_TO_SLOT_ABOVE", motions)
    assert "slot 3 (MOVE_TO_SLOT_ABOVE)" in failure_message(result)


def test_the_check_starts_from_where_the_arm_is(
    sim: Simulator, robot: Robot, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The plan is checked from the pose and joints the ready robot reports: the first
    # move continues from the arm's own joints, as the command's check from the arm did.
    seen: list[Any] = []
    real = pickplace_runner.validate_plan

    def spy(*args: Any, **kwargs: Any) -> int:
        seen.append(kwargs["start"])
        return real(*args, **kwargs)

    config = validate_config({"gripper": {"settle_s": 0.05}, "run": {"cycles": 1}})
    status = robot.status()
    monkeypatch.setattr(pickplace_runner, "validate_plan", spy)
    result = Runner.from_config(robot, config).run(pick_and_place(config))
    assert result.ok, result.failure
    assert len(seen) == 1, "the runner checks the plan once per run"
    start = seen[0]
    assert isinstance(start, tuple)
    assert start[0].is_close(status.pose, mm=0.01)
    assert start[1] == pytest.approx(status.joints, abs=0.01)


def test_a_move_made_in_step_code_is_checked_when_it_is_sent(sim: Simulator, robot: Robot) -> None:
    # A move known only while the run goes (here from ctx.data) cannot be checked before
    # it: the moves before it run, and the move itself is refused as it is sent (the
    # robot API's check), never commanded.
    seq = TaskSequence("computed")

    @seq.step("ABOVE")
    def above(ctx: StepContext) -> None:
        ctx.data["target"] = FAR
        ctx.move(PICK.offset(dz=100), speed=30)

    @seq.step("AWAY")
    def away(ctx: StepContext) -> None:
        ctx.move(ctx.data["target"], speed=30)

    motions = len(sim.motion_log())
    result = Runner(robot).run(seq)
    assert result.failure is not None
    assert result.failure.state == "AWAY"
    assert isinstance(result.failure.exception, ConfigError)
    moved = [m for m in sim.motion_log()[motions:] if m.target is not None]
    assert [
        m.target is not None and m.target.is_close(PICK.offset(dz=100), mm=1.0) for m in moved
    ] == [True]
    assert len(commands(sim)) == 1, "only the approach was commanded"


def test_the_command_checks_the_plan_before_connecting_and_once_from_the_arm(
    tm_simulator_factory: SimFactory, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The command checks the plan from the home pose before it connects (exit 2 with
    # nothing connected, --dry-run); once connected the runner checks it from the arm.
    # Its own check from the arm is gone: two checks, as before, not three.
    calls: list[str] = []

    def counting(module: Any, name: str) -> None:
        real = module.validate_plan

        def spy(*args: Any, **kwargs: Any) -> int:
            calls.append(name)
            return int(real(*args, **kwargs))

        monkeypatch.setattr(module, "validate_plan", spy)

    counting(pickplace_main, "before connecting")
    counting(pickplace_runner, "runner")
    sim = tm_simulator_factory(
        "tmflow", cell=Cell(scene=[TableObject(name="p", pose=PICK)]), **QUICK
    )
    config = tmp_path / "cell.toml"
    config.write_text("[gripper]\nsettle_s = 0.05\n[run]\npoll_interval_s = 0.02\n")
    argv = ["--host", "127.0.0.1", "--port", str(sim.port), "--config", str(config), "-q"]
    assert pickplace_main.main(argv) == 0
    assert calls == ["before connecting", "runner"]
