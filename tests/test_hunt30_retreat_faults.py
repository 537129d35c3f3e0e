"""A fault during the runner's own retreat: the result says whether the arm was stopped.

Hunt 30. ``on_error.reaction = "retreat"`` moves the arm after a failure that allows it
(here a grasp missed, no retries: ``GraspFailedError`` in CHECK_GRASP): straight up, then
to the retreat pose. ``RunResult.stop_delivered`` was settled before that reaction ran,
so a retreat move the run itself gave up was never counted:

- the link lost for good while the retreat's move runs (its write executed, the answer
  lost, then the robot unreachable): the move is given up, its stop cannot be sent, the
  arm may still move; the result said ``stop_delivered=None`` ("no stop was needed") and
  the command's reason line left out "the stop could NOT be delivered";
- a stop requested while the retreat's command is on its way (its frame held in the
  network, tmflow): the run withdrew it, and said ``stop_delivered=None``.

Found by this hunt (both fail without the fix): a retreat move given up counts as the
run's own: ``stop_delivered`` says whether its stop was delivered (False wins over an
earlier True). The judge of what the arm did is the simulator's motion log.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from fault_proxy import FaultProxy, Rule
from sim_speeds import QUICK
from tmmaster import PollPolicy, Pose, RetryPolicy, Robot, TimeoutPolicy
from tmmaster.pickplace import (
    ARTICLE_PICK,
    PickPlaceConfig,
    Runner,
    RunResult,
    StateEvent,
    pick_and_place,
    validate_config,
)
from tmmaster.pickplace.__main__ import EXIT_GRASP, main
from tmmaster.sim import Cell, Simulator, TableObject

Factory = Callable[..., Simulator]
PICK = Pose.from_sequence(ARTICLE_PICK)
RETREAT = Pose(250, 50, 300, 180, 0, 90)
MOVE_BLOCK = {"tmflow": 9000, "article": 0x0200}
CLI_CONFIG = """
[gripper]
settle_s = 0.05

[run]
poll_interval_s = 0.01
grasp_retries = 0

[timeouts]
ack_s = 0.5
motion_margin_s = 0.5
request_s = 0.3
in_flight_s = 0.5

[retry]
attempts = 2
total_time_s = 0.5

[on_error]
reaction = "retreat"
pose = [250, 50, 300, 180, 0, 90]
"""


def missed_grasp_with_retreat(
    factory: Factory, profile: str, *, grasp_retries: int
) -> tuple[Simulator, PickPlaceConfig]:
    """A simulator whose first grasp misses, and a run that retries ``grasp_retries``
    times, polling densely, and reacts to a failure by retreating to ``RETREAT``."""
    sim = factory(
        profile,
        cell=Cell(scene=[TableObject(name="part", pose=PICK)]),
        faults=["grasp_miss:at_grasp=1"],
        **QUICK,
    )
    config = validate_config(
        {
            "robot": {"profile": profile},
            "gripper": {"settle_s": 0.05},
            "run": {"poll_interval_s": 0.01, "grasp_retries": grasp_retries},
            "timeouts": {"ack_s": 0.5, "motion_margin_s": 0.5, "in_flight_s": 0.5},
            "on_error": {"reaction": "retreat", "pose": list(RETREAT.as_list())},
        }
    )
    return sim, config


def run_with_retreat_fault(
    factory: Factory, profile: str, action: str, then: Callable[[FaultProxy, Runner], None]
) -> tuple[RunResult, Simulator, float, FaultProxy, threading.Event]:
    """One cycle whose grasp misses; ``action`` on the retreat's first command write, and
    ``then`` once the proxy played it (on the proxy's event, never a count or a sleep)."""
    sim, config = missed_grasp_with_retreat(factory, profile, grasp_retries=0)
    proxy = FaultProxy(sim.port)
    release, ended_event = threading.Event(), threading.Event()
    helpers: list[threading.Thread] = []
    with Robot(
        "127.0.0.1",
        proxy.port,
        profile=profile,
        polling=PollPolicy(interval_s=0.01),
        retry=RetryPolicy(attempts=2, total_time_s=0.5),
        timeouts=TimeoutPolicy(request_s=0.3, gripper_settle_s=0.05, in_flight_s=0.5),
    ) as robot:
        robot.wait_until_ready(5)
        runner = Runner.from_config(robot, config)

        def once_played() -> None:
            while not proxy.played(action):
                if ended_event.wait(0.005):
                    return
            then(proxy, runner)

        def on_state(event: StateEvent) -> None:
            if event.state == "ERROR":  # the reaction comes next: its first write
                hold = release if action == "hold" else None
                proxy.add(
                    Rule(action, function_code=16, address=MOVE_BLOCK[profile], release=hold)  # type: ignore[arg-type]
                )
                helper = threading.Thread(target=once_played)
                helpers.append(helper)
                helper.start()

        runner.on_state = on_state
        try:
            result = runner.run(pick_and_place(config), cycles=1)
        finally:
            ended_event.set()
            for helper in helpers:
                helper.join(5)
        ended = time.monotonic()
    return result, sim, ended, proxy, release


@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_a_retreat_move_given_up_with_its_stop_undelivered_says_so(
    tm_simulator_factory: Factory, profile: str
) -> None:
    def link_gone_for_good(proxy: FaultProxy, _: Runner) -> None:
        proxy.outage(60)

    result, sim, _, proxy, _ = run_with_retreat_fault(
        tm_simulator_factory, profile, "drop_answer", link_gone_for_good
    )
    proxy.close()
    assert result.failure is not None
    assert result.failure.type == "GraspFailedError"
    assert result.reaction is not None
    assert not result.reaction.performed, result.reaction
    assert result.reaction.detail.startswith("retreat failed"), result.reaction
    # The robot took the retreat's first move (its write was executed, the answer lost).
    assert [m.kind for m in sim.motion_log()][-1:] == ["line"], sim.motion_log()
    # The run gave that move up and could not stop it: never "no stop was needed".
    assert result.stop_delivered is False, result


def test_a_stop_requested_while_the_retreat_is_on_its_way_says_the_arm_was_stopped(
    tm_simulator_factory: Factory,
) -> None:
    def stop(_: FaultProxy, runner: Runner) -> None:
        runner.request_stop()

    result, sim, ended, proxy, release = run_with_retreat_fault(
        tm_simulator_factory, "tmflow", "hold", stop
    )
    try:
        moves_at_end = len(sim.motion_log())
        release.set()  # the held retreat frame lands now, after the run gave it up
        proxy.wait_held()
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 20, timeout=5.0)
    finally:
        proxy.close()
    log = sim.motion_log()
    assert len(log) == moves_at_end
    assert not [m for m in log if m.wall_time > ended], log
    assert result.reaction is not None
    assert result.reaction.detail.startswith("retreat failed: "), result.reaction
    assert "stop was requested" in result.reaction.detail, result.reaction
    assert result.stop_delivered is True, result


def test_the_command_says_the_retreats_stop_could_not_be_delivered(
    tm_simulator_factory: Factory, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = tm_simulator_factory(
        "tmflow",
        cell=Cell(scene=[TableObject(name="part", pose=PICK)]),
        faults=["grasp_miss:at_grasp=1"],
        **QUICK,
    )
    config, report = tmp_path / "cell.toml", tmp_path / "report.json"
    config.write_text(CLI_CONFIG)
    ended, helpers = threading.Event(), []
    with FaultProxy(sim.port) as proxy:

        def link_gone_once_the_answer_is_lost() -> None:
            while not proxy.played("drop_answer"):
                if ended.wait(0.005):
                    return
            proxy.outage(60)

        class OnError(logging.Handler):
            def emit(self, record: logging.LogRecord) -> None:
                if "pickplace.state" in record.getMessage() and " state=ERROR " in (
                    f"{record.getMessage()} "
                ):
                    proxy.add(Rule("drop_answer", function_code=16, address=MOVE_BLOCK["tmflow"]))
                    helper = threading.Thread(target=link_gone_once_the_answer_is_lost)
                    helpers.append(helper)
                    helper.start()

        handler = OnError(logging.INFO)
        logger = logging.getLogger("tmmaster.pickplace")
        logger.addHandler(handler)
        try:
            code = main(
                [
                    *("--host", "127.0.0.1", "--port", str(proxy.port)),
                    *("--config", str(config), "--report", str(report), "--log-level", "info"),
                ]
            )
        finally:
            ended.set()
            logger.removeHandler(handler)
            for helper in helpers:
                helper.join(5)
    err = capsys.readouterr().err
    line = [x for x in err.splitlines() if x.startswith("pickplace: ")][-1]
    assert code == EXIT_GRASP, line
    assert "the stop could NOT be delivered" in line, line
    assert json.loads(report.read_text())["stop_delivered"] is False
