"""What a new user meets in the library, said plainly: no hidden connect, names as exported.

- A ``Robot`` connects in ``connect()`` (or ``with``) only: a command or a read before
  that is a ``TransportClosedError`` naming the fix, and nothing reaches the robot.
- A gripper's log events name the robot (``robot=NAME``), as the robot's own do.
- A public error reads ``tmmaster.RobotFaultError`` in a traceback from the start.
- ``tmmaster.connect`` says it returns a Robot (``aio.connect`` an AsyncRobot).
- ``EventLoopName`` (in Fleet's and StatusMonitor's signatures) can be imported.
- The robot API page's first sample runs against the simulator the README starts.
- Values no float holds (``10**5000``) are ConfigErrors naming the option, and pickplace
  names a silent robot's address once.
"""

from __future__ import annotations

import inspect
import logging
import re
import subprocess
import sys
import typing
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import pytest

import tmmaster
import tmmaster.aio
from test_not_modbus import Listener, silent
from tmmaster import (
    ConfigError,
    Fleet,
    Pose,
    Robot,
    StatusMonitor,
    TimeoutPolicy,
    TransportClosedError,
)
from tmmaster.pickplace.__main__ import EXIT_CONNECTION
from tmmaster.pickplace.__main__ import main as pickplace_main
from tmmaster.sim import Cell, Listen, Simulator, Timing, World

ROOT = Path(__file__).resolve().parents[1]

TARGET = Pose(300, -200, 200, 180, 0, 90)

#: Every kind of call that talks to the robot: a move, a read, a stop, I/O, the gripper.
CALLS: dict[str, Callable[[Robot], object]] = {
    "move_to": lambda r: r.move_to(TARGET, speed=50),
    "start_move": lambda r: r.start_move(TARGET, speed=50),
    "move_joints": lambda r: r.move_joints([0, 0, 90, 0, 90, 0]),
    "move_by": lambda r: r.move_by(dz=10),
    "status": lambda r: r.status(),
    "pose": lambda r: r.pose(),
    "wait_until_ready": lambda r: r.wait_until_ready(timeout_s=1),
    "check_fault": lambda r: r.check_fault(),
    "stop": lambda r: r.stop(),
    "project_state": lambda r: r.project_state(),
    "play": lambda r: r.play(),
    "io.set_do": lambda r: r.io.set_do(3, True),
    "io.di": lambda r: r.io.di(0),
    "gripper.open": lambda r: r.gripper.open(),
    "gripper.status": lambda r: r.gripper.status(),
}


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: Any) -> Any:
    return memory_simulator_factory


@pytest.mark.parametrize("call", list(CALLS.values()), ids=list(CALLS))
def test_a_robot_not_connected_refuses_every_call_naming_the_fix(
    tm_simulator_factory: Any, call: Callable[[Robot], object]
) -> None:
    sim = tm_simulator_factory()
    sim.clear_request_log()
    robot = Robot(sim.url, name="cell-1")
    try:
        with pytest.raises(TransportClosedError) as refused:
            call(robot)
        message = str(refused.value)
        assert message.startswith("cell-1: not connected, nothing was sent")
        assert "robot.connect()" in message
        assert "with tmmaster.connect(...) as robot:" in message
        assert sim.request_log == []  # nothing connected, nothing sent
    finally:
        robot.close()


def test_after_connect_the_same_robot_works(tm_simulator_factory: Any) -> None:
    sim = tm_simulator_factory()
    robot = Robot(sim.url, name="cell-1")
    with pytest.raises(TransportClosedError):
        robot.status()
    with robot:
        assert robot.wait_until_ready(timeout_s=5).ready
        robot.move_to(TARGET, speed=50)
    with pytest.raises(TransportClosedError, match="closed"):
        robot.status()  # closed now: the link says so, as before


@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_a_grippers_log_events_name_its_robot(
    tm_simulator_factory: Any, robots: Any, caplog: pytest.LogCaptureFixture, profile: str
) -> None:
    robot = robots(
        tm_simulator_factory(profile), name="cell-1", timeouts=TimeoutPolicy(gripper_settle_s=0.05)
    )
    with caplog.at_level(logging.INFO, "tmmaster"):
        robot.gripper.open()
        robot.gripper.close()
    lines = [r.getMessage() for r in caplog.records if r.name == "tmmaster.gripper"]
    assert any(line.startswith("gripper.command_sent") for line in lines), lines
    for line in lines:
        assert "robot=cell-1" in line, line
        assert f"gripper={robot.gripper.kind}" in line, line


def _fresh_python(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=False
    )


def test_a_traceback_names_the_error_as_exported() -> None:
    # A fresh interpreter that never reads tmmaster.RobotFaultError: the error is raised
    # from the private module, as the library itself raises it.
    done = _fresh_python(
        "from tmmaster._exceptions import RobotFaultError\n"
        "raise RobotFaultError('robot error', error_code=0x22)\n"
    )
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("tmmaster.RobotFaultError: robot error: 0x0022"), done.stderr


def test_every_exported_error_lives_in_tmmaster_from_the_start() -> None:
    done = _fresh_python(
        "import importlib, tmmaster\n"
        "errors = importlib.import_module('tmmaster._exceptions')\n"
        "for name in tmmaster.__all__:\n"
        "    value = getattr(errors, name, None)\n"
        "    if isinstance(value, type) and issubclass(value, BaseException):\n"
        "        print(name, value.__module__)\n"
    )
    assert done.returncode == 0, done.stderr
    homes = dict(line.split() for line in done.stdout.splitlines())
    assert "RobotFaultError" in homes
    assert "TMMasterError" in homes  # defined in _error_root, exported through _exceptions
    assert {name for name, home in homes.items() if home != "tmmaster"} == set()


def test_every_public_error_of_the_exceptions_module_is_exported() -> None:
    # A class shown as tmmaster.X must be reachable there (tracebacks, pickles).
    import tmmaster._exceptions as module

    for name, value in vars(module).items():
        shown_as_exported = inspect.isclass(value) and value.__module__ == "tmmaster"
        if shown_as_exported and issubclass(value, BaseException):
            assert getattr(tmmaster, name) is value, name
    assert tmmaster.UnknownNameError is module.UnknownNameError


def test_connect_says_what_it_returns() -> None:
    sync, unsync = inspect.signature(tmmaster.connect), inspect.signature(tmmaster.aio.connect)
    assert sync.return_annotation == "Robot"
    assert unsync.return_annotation == "AsyncRobot"
    assert str(sync).endswith("-> 'Robot'")
    assert sync.parameters == inspect.signature(Robot).parameters == unsync.parameters


def test_event_loop_name_can_be_imported_and_is_the_one_the_signatures_name() -> None:
    from tmmaster import EventLoopName

    assert typing.get_args(EventLoopName) == ("auto", "asyncio", "uvloop")
    assert typing.get_type_hints(Fleet.__init__)["event_loop"] == EventLoopName
    assert typing.get_type_hints(StatusMonitor.__init__)["event_loop"] == EventLoopName
    assert "EventLoopName" in tmmaster.__all__


def test_the_robot_api_pages_first_sample_runs_against_the_readmes_simulator(
    capsys: pytest.CaptureFixture[str],
) -> None:
    # The README starts `python -m tmmaster.sim --port 5020`: the default profile, tmflow.
    text = (ROOT / "docs" / "robot-api.md").read_text(encoding="utf-8")
    first = re.search(r"^```python\n(.*?)^```", text, re.DOTALL | re.MULTILINE)
    assert first is not None
    assert "5020" in first.group(1)
    # As `python -m tmmaster.sim` (tmflow).
    sim = Simulator(time_scale=40, timing=Timing(tick_hz=100))
    with sim:
        code = first.group(1).replace("5020", str(sim.port))
        exec(compile(code, "docs/robot-api.md (first sample)", "exec"), {"__name__": "sample"})
    assert capsys.readouterr().out.startswith("RobotStatus(running, idle")


def test_a_do_number_no_float_holds_is_a_config_error() -> None:
    robot = Robot("127.0.0.1", 1)  # never connected: the check comes before any I/O
    try:
        with pytest.raises(ConfigError, match=r"control_box DO 1\.000e\+5000 does not exist"):
            robot.io.set_do(10**5000, True)
        with pytest.raises(ConfigError, match=r"control_box DI 1\.000e\+5000 does not exist"):
            robot.io.di(10**5000)
    finally:
        robot.close()


@pytest.mark.parametrize(
    ("group", "option", "value"),
    [
        (None, "time_scale", 10**400),
        (None, "time_scale", "2"),
        (Timing, "tick_hz", 10**400),
        (Timing, "init_time_s", 10**400),
        (Timing, "init_time_s", 10**5000),
        (Cell, "speed_factor", 10**5000),
        (Listen, "port", 10**5000),
        (Listen, "gripper_port", 1.5),
    ],
    ids=lambda v: v if isinstance(v, str) else getattr(v, "__name__", type(v).__name__),
)
def test_a_simulator_option_no_float_holds_is_a_config_error_naming_it(
    group: Callable[..., object] | None, option: str, value: object
) -> None:
    with pytest.raises(ConfigError, match=rf"^{option} must be"):
        (group or partial(Simulator, listen=False))(**{option: value})


def test_a_table_height_no_float_holds_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match=r"^table_top_z_mm must be a finite number"):
        World(table_top_z_mm=10**400)


def test_a_mujoco_time_step_no_float_holds_is_a_config_error() -> None:
    pytest.importorskip("mujoco")
    from tmmaster import robot_model
    from tmmaster.sim._mujoco import MuJoCoBackend

    for option, value in (("timestep_s", 10**400), ("collision_force_n", 10**400)):
        with pytest.raises(ConfigError, match=rf"^{option} must be"):
            MuJoCoBackend(robot_model("tm5-700"), **{option: value})


def test_pickplace_names_a_silent_robots_address_once(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "cell.toml"
    config.write_text("[timeouts]\nrequest_s = 0.3\n")
    with Listener(silent) as server:
        args = ["--host", "127.0.0.1", "--port", str(server.port), "--config", str(config)]
        assert pickplace_main(args) == EXIT_CONNECTION
    line = capfd.readouterr().err.strip()
    assert line.count(f"127.0.0.1:{server.port}") == 1, line
    assert "never answered" in line
