"""``python -m tmmaster.pickplace`` (its ``main(argv)``, in-process) under a fault at each state.

Hunt 30, the command's side of ``test_hunt30_fault_matrix.py``. The fault fires when the
command logs that the run entered the state (``pickplace.state``, a logging handler on
the run's own event, never a count or a sleep): the operator's Ctrl-C
(``_thread.interrupt_main``: the command's own SIGINT handler), an e-stop or a robot
error during the state's move (counted from that moment by the simulator), the project
stopped or paused on the pendant, the state's command frame dropped on the wire.

Judged: the exit code and the one reason line, the report (result, failed state,
stop_delivered), and what the robot did (the simulator's motion log against every move
the command issued: ``safety_invariant.check``), nothing started after ``main`` returned.
"""

from __future__ import annotations

import _thread
import json
import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from fault_proxy import FaultProxy, Rule
from pendant import press_play_pause
from safety_invariant import Issued, check
from sim_speeds import QUICK
from tmmaster import Pose, Robot, TMMasterError
from tmmaster.pickplace import ARTICLE_PICK
from tmmaster.pickplace.__main__ import (
    EXIT_CONNECTION,
    EXIT_INTERRUPTED,
    EXIT_ROBOT_FAULT,
    EXIT_TIMEOUT,
    main,
)
from tmmaster.sim import Cell, Simulator, TableObject

Factory = Callable[..., Simulator]
PICK = Pose.from_sequence(ARTICLE_PICK)
NOMINAL = {
    "MOVE_TO_APPROACH": "ptp",
    "MOVE_TO_PICK": "line",
    "GRIPPER_CLOSE": "gripper_close",
    "CHECK_GRASP": None,
    "MOVE_TO_LIFT": "line",
    "MOVE_TO_PLACE": "ptp",
    "GRIPPER_OPEN": "gripper_open",
    "MOVE_TO_HOME": "ptp",
}
MOVE_BLOCK = {"tmflow": 9000, "article": 0x0200}
CONFIG = """
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

[on_error]
reaction = "retreat"
pose = [250, 50, 300, 180, 0, 90]
"""

#: (fault, state, profile): Ctrl-C at every state (tmflow; article at its moves and
#: gripper actions), and each other fault class once per profile where it applies.
CTRL_C = [("ctrl_c", s, "tmflow") for s in NOMINAL] + [
    ("ctrl_c", s, "article") for s in ("MOVE_TO_PICK", "GRIPPER_CLOSE", "MOVE_TO_PLACE")
]
OTHERS = [
    ("estop", "MOVE_TO_PLACE", "tmflow"),
    ("estop", "MOVE_TO_LIFT", "article"),
    ("robot_error", "MOVE_TO_PICK", "tmflow"),
    ("robot_error", "MOVE_TO_HOME", "article"),
    ("pause", "MOVE_TO_PLACE", "tmflow"),
    ("stop_project", "GRIPPER_OPEN", "tmflow"),
    ("link_drop", "MOVE_TO_LIFT", "tmflow"),
    ("link_drop", "MOVE_TO_PLACE", "article"),
]
EXIT = {
    "ctrl_c": (EXIT_INTERRUPTED,),
    "estop": (EXIT_ROBOT_FAULT,),
    "robot_error": (EXIT_ROBOT_FAULT,),
    "pause": (EXIT_ROBOT_FAULT, EXIT_TIMEOUT),
    "stop_project": (EXIT_ROBOT_FAULT,),
    "link_drop": (0, EXIT_ROBOT_FAULT, EXIT_CONNECTION),  # tmflow resends; article withdraws
}


class OnState(logging.Handler):
    """Calls ``fire`` once, as the command logs that the run entered ``state``."""

    def __init__(self, state: str, fire: Callable[[], None]) -> None:
        super().__init__(logging.INFO)
        self.state, self.fire, self.fired = state, fire, False
        self.error_at: int | None = None

    def emit(self, record: logging.LogRecord) -> None:
        message = record.getMessage()
        if "pickplace.state" not in message:
            return
        if f" state={self.state} " in f"{message} " and not self.fired:
            self.fired = True
            self.fire()


@pytest.fixture
def issued(monkeypatch: pytest.MonkeyPatch) -> list[Issued]:
    """Every ``Robot.move_to`` the command makes (its steps' and its retreat's)."""
    made: list[Issued] = []
    original = Robot.move_to

    def record(self: Robot, pose: Pose, **kwargs: Any) -> Any:
        command = Issued(pose, time.monotonic())
        made.append(command)
        try:
            result = original(self, pose, **kwargs)
        except TMMasterError as exc:
            command.outcome = type(exc).__name__
            raise
        finally:
            command.ended_at = time.monotonic()
        command.outcome = "done"
        return result

    monkeypatch.setattr(Robot, "move_to", record)
    return made


def firing(
    fault: str, sim: Simulator, proxy: FaultProxy | None, profile: str
) -> Callable[[], None]:
    def fire() -> None:
        if fault == "ctrl_c":
            _thread.interrupt_main()
        elif fault == "estop":
            sim.inject("estop:at_move=1")
        elif fault == "robot_error":
            sim.inject("robot_error:at_move=1,code=0x22")
        elif fault == "pause":
            press_play_pause(sim)
            sim.wait_for(lambda: bool(sim.field("paused")), timeout=2.0)
        elif fault == "stop_project":
            sim.call(lambda: sim._controller.bank.set("stop_project", True))
            sim.wait_for(lambda: not sim.field("project_running"), timeout=2.0)
        else:
            assert proxy is not None
            proxy.add(Rule("drop_request", function_code=16, address=MOVE_BLOCK[profile]))

    return fire


@pytest.mark.parametrize(("fault", "state", "profile"), CTRL_C + OTHERS)
def test_the_command_under_a_fault_at_a_state_exits_truthfully_and_moves_nothing_after(
    tm_simulator_factory: Factory,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    issued: list[Issued],
    fault: str,
    state: str,
    profile: str,
) -> None:
    sim = tm_simulator_factory(
        profile, cell=Cell(scene=[TableObject(name="p", pose=PICK)]), **QUICK
    )
    proxy = FaultProxy(sim.port) if fault.startswith("link") else None
    config, report = tmp_path / "cell.toml", tmp_path / "report.json"
    config.write_text(CONFIG)
    port = sim.port if proxy is None else proxy.port
    handler = OnState(state, firing(fault, sim, proxy, profile))
    logger = logging.getLogger("tmmaster.pickplace")
    logger.addHandler(handler)
    try:
        code = main(
            [
                "--host",
                "127.0.0.1",
                "--port",
                str(port),
                "--profile",
                profile,
                "--config",
                str(config),
                "--report",
                str(report),
                "--log-level",
                "info",
            ]
        )
        ended = time.monotonic()
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 20, timeout=5.0)  # room to take any
    finally:
        logger.removeHandler(handler)
        if proxy is not None:
            proxy.close()
    err = capsys.readouterr().err
    assert handler.fired
    data = json.loads(report.read_text())
    log = sim.motion_log()
    kinds = [m.kind for m in log]
    check(issued, log)
    assert not [m for m in log if m.wall_time > ended], kinds
    assert code in EXIT[fault], (code, err[-2000:])
    assert data["exit_code"] == code
    assert "Traceback" not in err
    if code == 0:
        assert data["result"] == "done"
        return
    line = [x for x in err.splitlines() if x.startswith("pickplace: ")][-1]
    assert line.endswith(f"[exit {code}]"), line
    names = list(NOMINAL)
    before = [k for k in list(NOMINAL.values())[: names.index(state)] if k is not None]
    own = NOMINAL[state]
    failed = data["error"]["state"]
    if own is None:  # a read-only state: met at the next command
        assert failed in (state, names[names.index(state) + 1]), data["error"]
    else:
        assert failed == state, data["error"]
    assert kinds[: len(before)] == before, kinds
    rest = kinds[len(before) :]
    performed = bool(data["reaction"] and data["reaction"]["performed"])
    if fault in ("ctrl_c", "estop", "robot_error"):
        assert not performed, data["reaction"]
        assert rest in ([], [own]), kinds
    if fault == "ctrl_c":
        assert data["result"] == "interrupted"
        assert line.startswith(f"pickplace: interrupted in {failed} (cycle 1); ")
        assert data["stop_delivered"] is True, data
        assert "the arm was stopped" in line
    if performed:
        assert "retreated" in line
    assert (" did not retreat" in line) == (
        data["reaction"] is not None
        and data["reaction"]["reaction"] == "retreat"
        and not performed
        and fault != "ctrl_c"
    ), line
