"""The machine, the runner's policies and the sequences, through the Python API.

Everything that moves runs against the simulator over loopback TCP.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

import tmmaster
from sim_speeds import QUICK
from tmmaster import ConfigError, PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster.pickplace import (
    ARTICLE_PICK,
    ARTICLE_PLACE,
    DONE,
    ERROR,
    IDLE,
    PICK_AND_PLACE_STATES,
    Cycles,
    Pallet,
    PickPlaceConfig,
    RetryRule,
    Runner,
    SequenceMachine,
    StateEvent,
    StepContext,
    TaskSequence,
    load_config,
    load_sequence,
    palletizing,
    pick_and_place,
    sequence_from_data,
    validate_config,
    validate_plan,
)
from tmmaster.sim import Cell, Simulator, TableObject

PICK = Pose.from_sequence(ARTICLE_PICK)
PLACE = Pose.from_sequence(ARTICLE_PLACE)
HOME = tmmaster.DEFAULT_HOME  # the article's HOME is out of a TM5's reach
#: A part released at PLACE (200 mm up) falls onto the table: it rests at PLACE's x-y
#: with its centre 100 mm up, where the parts start (issue 9: released parts fall).
PLACED = Pose(PLACE.x, PLACE.y, PICK.z, PLACE.rx, PLACE.ry, PLACE.rz)
TARGET_BLOCK = 0x0200

# The runs here are checked for the runner's outcome, not a wall-clock delay: their
# simulators run at QUICK (sim_speeds).

SimFactory = Callable[..., Simulator]


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: SimFactory) -> SimFactory:
    """The runner is the subject here, not TCP: simulators in memory."""
    return memory_simulator_factory


def fast_config(**sections: dict[str, object]) -> PickPlaceConfig:
    """The article's defaults with settings that keep a time_scale-20 run fast."""
    data: dict[str, dict[str, object]] = {
        "gripper": {"settle_s": 0.05},
        "run": {"poll_interval_s": 0.02},
        "timeouts": {"ack_s": 0.5, "motion_margin_s": 0.5},
    }
    for name, values in sections.items():
        data.setdefault(name, {}).update(values)
    return validate_config(data)


@pytest.fixture
def sim(tm_simulator_factory: SimFactory) -> Simulator:
    """An article simulator with three parts at the pick pose."""
    return tm_simulator_factory(
        "article",
        cell=Cell(scene=[TableObject(name=f"part-{i}", pose=PICK) for i in range(3)]),
        **QUICK,
    )


@pytest.fixture
def robot(sim: Simulator) -> Iterator[Robot]:
    """A connected robot with the fast settings."""
    with Robot(
        sim.url,
        profile="article",
        polling=PollPolicy(interval_s=0.02),
        timeouts=TimeoutPolicy(gripper_settle_s=0.05),
    ) as r:
        yield r


# -- configuration ---------------------------------------------------------------------


def test_defaults_are_the_articles_cycle() -> None:
    config = PickPlaceConfig()
    poses = {k: v.as_list() for k, v in config.poses.resolved().items()}
    assert poses == {
        "approach": [300, -200, 200, 180, 0, 90],
        "pick": [300, -200, 100, 180, 0, 90],
        "lift": [300, -200, 250, 180, 0, 90],
        "place": [300, 200, 200, 180, 0, 90],
        "home": [250, 0, 300, 180, 0, 90],  # not the article's: out of reach
    }
    assert config.speeds.model_dump() == {
        "approach": 30,
        "pick": 10,
        "lift": 10,
        "place": 30,
        "home": 30,
    }
    assert config.motion.model_dump(mode="json") == {
        "approach": "ptp",
        "pick": "line",
        "lift": "line",
        "place": "ptp",
        "home": "ptp",
    }
    assert config.run.poll_interval_s == 0.05
    # Issue 12: one default profile everywhere, tmflow (the article's map is opt-in).
    assert config.robot.profile == "tmflow"


def test_approach_and_lift_follow_the_pick_pose_by_their_z_offsets(tmp_path: Path) -> None:
    path = tmp_path / "cell.toml"
    path.write_text("[poses]\npick = [250, 0, 50, 180, 0, 0]\nlift_z_offset = 20\n")
    poses = load_config(path).poses.resolved()
    assert poses["approach"].as_list() == [250, 0, 150, 180, 0, 0]
    assert poses["lift"].as_list() == [250, 0, 70, 180, 0, 0]


def test_the_digest_ignores_how_the_config_was_written(tmp_path: Path) -> None:
    a = tmp_path / "a.toml"
    b = tmp_path / "b.toml"
    a.write_text("[speeds]\npick = 10\n")  # the default, spelled out
    b.write_text("")
    assert load_config(a).digest() == load_config(b).digest()
    assert load_config(a).digest() != fast_config().digest()


def test_a_pose_out_of_the_article_encoding_is_refused_before_connecting() -> None:
    config = validate_config({"poses": {"home": [250, 0, 400, 180, 0, 90]}})
    robot = Robot("127.0.0.1", 1, profile="article")  # never connected
    try:
        with pytest.raises(ConfigError, match=r"cell\.toml: poses\.home.*target_z"):
            validate_plan(robot, pick_and_place(config), 1, source="cell.toml")
    finally:
        robot.close()


# -- the machine -------------------------------------------------------------------------


def test_machine_has_the_article_states_and_no_auto_transitions() -> None:
    machine = SequenceMachine(pick_and_place(), cycles=1)
    assert list(machine.machine.states) == [IDLE, *PICK_AND_PLACE_STATES, DONE, ERROR]
    assert not hasattr(machine, "to_DONE")
    assert machine.state == IDLE
    # Only the declared triggers exist: advancing from IDLE is not one of them.
    from transitions import MachineError

    with pytest.raises(MachineError):
        machine.advance()


def test_check_grasp_only_advances_when_its_guard_holds() -> None:
    holding = {"value": False}

    def guard(_ctx: object) -> bool:
        return holding["value"]

    seq = TaskSequence("t")
    seq.add("A", lambda ctx: None)
    seq.add("CHECK", lambda ctx: None, guard=guard, retry=RetryRule("A", attempts=1))
    machine = SequenceMachine(seq, cycles=1)
    assert machine.start()
    assert machine.advance()
    assert machine.state == "CHECK"
    assert not machine.advance()  # guard false: stays
    assert machine.state == "CHECK"
    assert machine.retry()
    assert machine.state == "A"
    machine.advance()
    assert not machine.retry()  # one attempt only per cycle
    holding["value"] = True
    assert machine.advance()
    assert machine.state == DONE


def test_a_retry_may_not_jump_forward() -> None:
    seq = TaskSequence("t")
    seq.add("A", lambda ctx: None, retry=RetryRule("B", attempts=1))
    seq.add("B", lambda ctx: None)
    with pytest.raises(ConfigError, match="earlier step"):
        SequenceMachine(seq, cycles=1)


def test_reserved_and_duplicate_step_names_are_refused() -> None:
    seq = TaskSequence("t")
    with pytest.raises(ConfigError, match="reserved"):
        seq.add("DONE", lambda ctx: None)
    seq.add("A", lambda ctx: None)
    with pytest.raises(ConfigError, match="twice"):
        seq.add("A", lambda ctx: None)


# -- the runner ------------------------------------------------------------------------


def test_runner_runs_the_article_cycle_and_times_every_state(sim: Simulator, robot: Robot) -> None:
    events: list[StateEvent] = []
    runner = Runner(robot, on_state=events.append)
    assert runner.run_started is None
    before = time.monotonic()
    result = runner.run(pick_and_place(fast_config()), cycles=2)
    after = time.monotonic()
    # The run's clock (time 0 of its records and duration) is readable: the CLI's TCP path
    # is timed on it.
    assert runner.run_started is not None
    assert before <= runner.run_started <= after - result.duration_s + 0.001
    assert result.ok
    assert result.cycles_completed == 2
    assert [e.state for e in events][:3] == ["MOVE_TO_APPROACH", "MOVE_TO_PICK", "GRIPPER_CLOSE"]
    assert events[-1].state == DONE
    timings = result.state_timings()
    assert timings["MOVE_TO_PLACE"]["count"] == 2
    assert timings["MOVE_TO_PLACE"]["total_s"] > 0
    # The second part fell onto the first at the place x-y (issue 9: released parts fall).
    placed = [
        o
        for o in sim.objects()
        if any(o.pose.is_close(PLACED.offset(dz=dz), mm=1.0) for dz in (0, 30))
    ]
    assert len(placed) == 2


def test_a_stop_request_is_honoured_between_states(sim: Simulator, robot: Robot) -> None:
    runner = Runner(robot)

    def on_state(event: StateEvent) -> None:
        if event.state == "MOVE_TO_PICK":
            runner.request_stop()

    runner.on_state = on_state
    result = runner.run(pick_and_place(fast_config()))
    assert result.interrupted
    assert result.state == ERROR
    assert result.failure is not None
    assert result.failure.state == "MOVE_TO_PICK"
    # The pick move was never sent: only the approach went out.
    assert len([r for r in sim.request_log if r.is_write and r.address == TARGET_BLOCK]) == 1


def test_a_stop_request_interrupts_a_running_wait_and_stops_the_arm(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("article", faults=["stall:at_move=1"])
    with Robot(sim.url, profile="article", polling=PollPolicy(interval_s=0.02)) as robot:
        runner = Runner(robot)
        seq = TaskSequence("one-move")
        seq.add("MOVE", lambda ctx: ctx.move(PICK.offset(dz=100), speed=30))

        def stop_when_moving() -> None:
            sim.wait_for(lambda: sim.field("motion_status") == 1, timeout=5)
            runner.request_stop()

        helper = threading.Thread(target=stop_when_moving)
        helper.start()
        result = runner.run(seq)
        helper.join()
    assert result.interrupted
    assert result.failure is not None
    assert result.failure.state == "MOVE"
    stops = [r for r in sim.request_log if r.is_write and r.values == (3,)]
    assert len(stops) == 1
    # Only a stop ends a stalled motion (docs/simulator-model.md).
    sim.wait_for(lambda: sim.field("motion_status") == 0, timeout=2)


def test_a_user_sequence_in_python_gets_the_shared_retry_policy(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("article", faults=["grasp_miss:at_grasp=1"], **QUICK)
    above = PICK.offset(dz=50)
    seq = TaskSequence("custom")

    @seq.step("ABOVE")
    def go_above(ctx: StepContext) -> None:
        ctx.move(above, speed=50)

    @seq.step("DOWN")
    def go_down(ctx: StepContext) -> None:
        ctx.move(PICK, speed=20, motion="line")

    seq.add("GRIP", lambda ctx: ctx.grip(), retry=RetryRule("ABOVE", 1, recover=_open))
    seq.add("UP", lambda ctx: ctx.move(above, speed=20, motion="line"))
    with Robot(
        sim.url,
        profile="article",
        polling=PollPolicy(interval_s=0.02),
        timeouts=TimeoutPolicy(gripper_settle_s=0.05),
    ) as robot:
        result = Runner(robot).run(seq)
    assert result.ok
    assert result.retries == 1
    assert sim.objects()[0].held


def _open(ctx: StepContext) -> None:
    ctx.open_gripper()


# -- palletizing and TOML sequences -----------------------------------------------------


def test_pallet_slots_fill_rows_then_layers() -> None:
    pallet = Pallet(origin=PLACE, rows=2, cols=3, dx=40, dy=50, layers=2, dz=30)
    assert pallet.size == 12
    assert pallet.slot(0) == PLACE
    assert pallet.slot(2) == PLACE.offset(dx=80)
    assert pallet.slot(3) == PLACE.offset(dy=50)
    assert pallet.slot(6) == PLACE.offset(dz=30)
    with pytest.raises(ConfigError):
        pallet.slot(12)


def test_palletizing_places_each_part_into_its_slot(tm_simulator_factory: SimFactory) -> None:
    pallet = Pallet(origin=Pose(250, 150, 100, 180, 0, 90), rows=1, cols=2, dx=40, dy=40)
    sim = tm_simulator_factory(
        "article",
        cell=Cell(scene=[TableObject(name=f"p{i}", pose=PICK) for i in range(pallet.size)]),
        **QUICK,
    )
    seq = palletizing(pick=PICK, pallet=pallet, home=HOME)
    with Robot(
        sim.url,
        profile="article",
        polling=PollPolicy(interval_s=0.02),
        timeouts=TimeoutPolicy(gripper_settle_s=0.05),
    ) as robot:
        validate_plan(robot, seq, pallet.size, source="test")
        result = Runner(robot).run(seq)
    assert result.ok
    assert result.cycles_completed == 2
    slots = [pallet.slot(i) for i in range(2)]
    for obj in sim.objects():
        assert any(obj.pose.is_close(s, mm=1.0) for s in slots), obj
    assert sim.tcp_pose().is_close(HOME, mm=1.0)


def test_a_toml_sequence_names_the_bad_key_and_file(tmp_path: Path) -> None:
    path = tmp_path / "seq.toml"
    path.write_text('name = "x"\n[[steps]]\ndo = "move"\npose = "nowhere"\nspeed = 30\n')
    with pytest.raises(ConfigError, match=r"seq\.toml: steps\.0\.pose: unknown pose 'nowhere'"):
        load_sequence(path)
    path.write_text('name = "x"\n[[steps]]\ndo = "fly"\n')
    with pytest.raises(ConfigError, match=r"seq\.toml: steps\.0"):
        load_sequence(path)


def test_a_toml_sequence_runs_with_retries(tm_simulator_factory: SimFactory) -> None:
    sim = tm_simulator_factory("article", faults=["grasp_miss:at_grasp=1"], **QUICK)
    seq = sequence_from_data(
        {
            "name": "data",
            "poses": {"part": list(ARTICLE_PICK), "home": HOME.as_list()},
            "steps": [
                {"state": "ABOVE", "do": "move", "pose": "part", "z_offset": 100, "speed": 30},
                {"state": "DOWN", "do": "move", "pose": "part", "speed": 10, "motion": "line"},
                {"state": "GRASP", "do": "grip", "retry_from": "ABOVE", "retries": 2},
                {"state": "HOME", "do": "move", "pose": "home", "speed": 30},
                {"state": "DROP", "do": "release"},
                {"state": "EMPTY", "do": "check", "holding": False},
            ],
        }
    )
    with Robot(
        sim.url,
        profile="article",
        polling=PollPolicy(interval_s=0.02),
        timeouts=TimeoutPolicy(gripper_settle_s=0.05),
    ) as robot:
        result = Runner(robot).run(seq)
    assert result.ok, result.failure
    assert result.retries == 1
    # Released at HOME (300 mm up), it fell onto the table below (issue 9).
    assert sim.objects()[0].pose.is_close(Pose(HOME.x, HOME.y, PICK.z, *HOME.as_list()[3:]), mm=1.0)


# -- each sequence described once: the plan comes from the steps -------------------------


def test_the_plan_is_derived_from_the_steps_moves() -> None:
    pallet = Pallet(origin=PLACE, rows=1, cols=2, dx=60.0, dy=0.0)
    seq = palletizing(pick=PICK, pallet=pallet, home=HOME)
    first, last = seq.moves(1, 2), seq.moves(2, 2)
    # Each move-making step carries its move; cycle 2 goes to slot 2, then home.
    assert [m.state for m in first] == [
        "MOVE_TO_APPROACH",
        "MOVE_TO_PICK",
        "MOVE_TO_LIFT",
        "MOVE_TO_SLOT_ABOVE",
        "MOVE_TO_SLOT",
        "MOVE_TO_SLOT_CLEAR",
    ]
    assert [m.state for m in last] == [*(m.state for m in first), "MOVE_TO_HOME"]
    assert first[4].pose == pallet.slot(0)
    assert last[4].pose == pallet.slot(1)
    assert last[-1].pose == HOME
    # The steps say the same: the slot move of a step follows the cycle it runs in.
    step = next(s for s in seq.steps if s.name == "MOVE_TO_SLOT")
    assert step.move_of(2).pose == pallet.slot(1)


def test_a_toml_step_when_decides_the_plan_and_the_run_alike() -> None:
    seq = sequence_from_data(
        {
            "name": "w",
            "poses": {"a": list(ARTICLE_PICK)},
            "steps": [
                {"state": "FIRST", "do": "move", "pose": "a", "speed": 30, "when": "first_cycle"},
                {"state": "ALWAYS", "do": "move", "pose": "a", "z_offset": 50, "speed": 30},
                {"state": "LAST", "do": "move", "pose": "a", "speed": 30, "when": "last_cycle"},
            ],
        }
    )
    assert [m.state for m in seq.moves(1, 3)] == ["FIRST", "ALWAYS"]
    assert [m.state for m in seq.moves(2, 3)] == ["ALWAYS"]
    assert [m.state for m in seq.moves(3, 3)] == ["ALWAYS", "LAST"]
    # The run's skip condition is the same rule object the plan reads.
    whens = {s.name: s.when for s in seq.steps}
    assert whens["ALWAYS"] is None
    assert whens["FIRST"] is Cycles.FIRST
    assert whens["LAST"] is Cycles.LAST


def test_a_step_without_action_or_move_is_refused_and_plan_is_deprecated() -> None:
    with pytest.raises(ConfigError, match="action, a move"):
        TaskSequence("t").add("A")
    with pytest.warns(DeprecationWarning, match="plan"):
        seq = TaskSequence("t", plan=lambda _c, _n: [])
    assert seq.moves(1, 1) == []


def test_a_bug_in_step_code_surfaces_as_itself(robot: Robot) -> None:
    seq = TaskSequence("bug")

    @seq.step("A")
    def broken(ctx: StepContext) -> None:
        ctx.no_such_method()  # type: ignore[attr-defined]

    with pytest.raises(AttributeError, match="no_such_method"):
        Runner(robot).run(seq)


def test_a_robot_error_in_step_code_is_a_run_failure(robot: Robot) -> None:
    seq = TaskSequence("fails")

    @seq.step("A")
    def refused(ctx: StepContext) -> None:
        ctx.move(PICK, speed=1000)

    result = Runner(robot).run(seq)
    assert not result.ok
    assert result.failure is not None
    assert (result.failure.state, result.failure.type) == ("A", "ConfigError")


def test_runner_from_config_takes_reaction_and_readiness(robot: Robot) -> None:
    config = validate_config({"on_error": {"reaction": "retreat"}, "timeouts": {"ready_s": 3.5}})
    runner = Runner.from_config(robot, config)
    assert runner.error_reaction == "retreat"
    assert runner.ready_timeout_s == 3.5
