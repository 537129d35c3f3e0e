"""The pick & place command's report says "stop delivered" only for a stop delivered.

An interrupted run stops the arm (``Runner._stop_arm``: ``robot.stop()``); when that
Stop is refused, the run's ``stop_delivered`` is False. The command then closes the
robot, and a close that confirmed everything counted as the stop delivered after all
(``__main__._close``: meant for a Stop the link could not carry that the close
delivered). But ``close()`` also confirms when there was nothing to stop (the run's last
move had finished, or its command was withdrawn): the report then said
``stop_delivered: true`` and the last line "the arm was stopped" for a Stop the robot
never got. Now only a Stop the close delivered counts.

The judge is the simulator: no Stop reached it, and the arm stood still at the end of
its move. The stop is requested between two states (a move done, none running), the
Stop button's write refused by the proxy (a Modbus exception, as a gateway answers).
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from fault_proxy import FaultProxy, Rule
from sim_speeds import QUICK
from tmmaster import MovePhase, PollPolicy, Pose, RetryPolicy, Robot, TimeoutPolicy
from tmmaster.pickplace import ARTICLE_PICK, Runner, StateEvent, pick_and_place, validate_config
from tmmaster.pickplace.__main__ import _close, _failed, _Outcome
from tmmaster.sim import Cell, Simulator, TableObject

SimFactory = Callable[..., Simulator]
PICK = Pose.from_sequence(ARTICLE_PICK)
#: The TM Stop button (tmflow's coil 7105).
STOP_BUTTON = 7105
#: The article's command register, and its stop code.
ARTICLE_COMMAND, ARTICLE_STOP = 0x0207, 3


def stop_writes(sim: Simulator) -> list[object]:
    return [r for r in sim.request_log if r.is_write and r.address == STOP_BUTTON]


def test_a_refused_stop_is_not_reported_delivered_by_the_close(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory(
        "tmflow", cell=Cell(scene=[TableObject(name="part-1", pose=PICK)]), **QUICK
    )
    config = validate_config({"gripper": {"settle_s": 0.05}, "run": {"cycles": 1}})
    with FaultProxy(sim.port) as proxy:
        proxy.add(Rule("drop_request", function_code=5, address=STOP_BUTTON, exception=4, times=99))
        robot = Robot(
            "127.0.0.1",
            proxy.port,
            profile="tmflow",
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(gripper_settle_s=0.05),
        )
        entered: list[str] = []

        def stop_on_the_second_state(event: StateEvent) -> None:
            entered.append(event.state)
            if len(entered) == 2:  # the first state's move is done, no move is running
                runner.request_stop()

        runner = Runner(robot, on_state=stop_on_the_second_state)
        try:
            robot.connect()
            result = runner.run(pick_and_place(config))
        finally:
            outcome = _Outcome()
            outcome.run = result
            _close(robot, outcome)  # what the command does after the run
    assert result.failure is not None
    assert result.failure.interrupted
    last = robot.last_motion
    assert last is not None
    assert last.done, "the scenario: the run's last move had finished by itself"
    assert proxy.played("drop_request"), "the scenario: the Stop was refused"
    assert stop_writes(sim) == [], "no Stop reached the robot"
    assert result.stop_delivered is False  # before the fix: True, after the close
    _code, line = _failed(result)
    assert "the stop could NOT be delivered" in line, line
    assert len(sim.motion_log()) == 1
    assert sim.motion_log()[0].done_wall_time is not None  # it ended by itself


def test_a_stop_the_close_delivered_after_all_still_counts(
    tm_simulator_factory: SimFactory,
) -> None:
    # The control (article): the link goes down as the stop is requested while a move
    # runs; the run's Stops cannot be carried (owed), the link is back before the close,
    # and the close delivers the Stop: that counts as delivered.
    sim = tm_simulator_factory(
        "article", cell=Cell(scene=[TableObject(name="part-1", pose=PICK)]), time_scale=5.0
    )
    # The first move, to the approach pose, takes about 2 s of wall time.
    config = validate_config(
        {"gripper": {"settle_s": 0.05}, "run": {"cycles": 1}, "speeds": {"approach": 2}}
    )
    with FaultProxy(sim.port) as proxy:
        robot = Robot(
            "127.0.0.1",
            proxy.port,
            profile="article",
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(gripper_settle_s=0.05, request_s=0.2),
            retry=RetryPolicy(attempts=2, total_time_s=0.2),
        )
        runner = Runner(robot)
        over = threading.Event()

        def running() -> bool:
            motion = robot.last_motion
            return motion is not None and motion.phase is MovePhase.RUNNING

        def down_and_stop_while_the_first_move_runs() -> None:
            sim.wait_for(lambda: running() or over.is_set(), timeout=10.0)
            if not over.is_set():  # the master saw the robot take the move
                proxy.outage(60.0)
                runner.request_stop()

        stopper = threading.Thread(target=down_and_stop_while_the_first_move_runs)
        try:
            robot.connect()
            stopper.start()
            result = runner.run(pick_and_place(config))
        finally:
            over.set()
            stopper.join(10)
            assert result.stop_delivered is False, "the scenario: the run's Stop was owed"
            proxy.outage(0.0)  # the link is back
            sim.clear_request_log()
            outcome = _Outcome()
            outcome.run = result
            _close(robot, outcome)
    assert result.failure is not None
    assert result.failure.interrupted
    assert any(
        r.is_write and r.address == ARTICLE_COMMAND and r.values == (ARTICLE_STOP,)
        for r in sim.request_log
    ), "the close delivered the Stop"
    assert result.stop_delivered is True
    (moved,) = sim.motion_log()
    assert moved.target is not None
    assert not sim.tcp_pose().is_close(moved.target), "the scenario: stopped short"
