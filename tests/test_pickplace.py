"""Pick & place against the simulator over loopback TCP: the command, end to end.

The CLI's run() is called in-process (fast) against simulators started by the
``tm_simulator_factory`` fixture (time_scale 40, 100 where ``QUICK``) with faults; a few
tests run the real ``python -m tmmaster.pickplace`` entry point as a subprocess.
"""

from __future__ import annotations

import json
import os
import pty
import select
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

import tmmaster
from exit_hooks import PAUSE_AT_EXIT, PAUSED_AT_EXIT, ctrl_c_in_the_exit_hooks
from sim_speeds import QUICK
from tmmaster import Pose
from tmmaster.pickplace import ARTICLE_PICK, ARTICLE_PLACE
from tmmaster.pickplace.__main__ import (
    EXIT_CONFIG,
    EXIT_CONNECTION,
    EXIT_GRASP,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_ROBOT_FAULT,
    EXIT_TIMEOUT,
    main,
)
from tmmaster.sim import Cell, RequestRecord, RobotSetup, Simulator, TableObject

PICK = Pose.from_sequence(ARTICLE_PICK)
PLACE = Pose.from_sequence(ARTICLE_PLACE)
# The default home (the article's (0, 0, 300, 180, 0, 0) is out of a TM5's reach).
HOME = tmmaster.DEFAULT_HOME
#: A part released at PLACE (200 mm up) falls onto the table: it rests at PLACE's x-y
#: with its centre 100 mm up, where the parts start (issue 9: released parts fall).
PLACED = Pose(PLACE.x, PLACE.y, PICK.z, PLACE.rx, PLACE.ry, PLACE.rz)
TARGET_BLOCK = 0x0200  # article: target x..rz, speed, command in one FC16
COMMAND_REGISTER = 0x0207
GRIPPER_REGISTER = 0x0210

#: Settings that keep a simulated run (time_scale 40) fast; the poses and speeds stay
#: the article's defaults.
FAST = """
[gripper]
settle_s = 0.05

[run]
poll_interval_s = 0.02

[timeouts]
ack_s = 0.5
motion_margin_s = 0.5
"""

# QUICK (sim_speeds) is for the runs whose subject is the outcome (the moves sent, where
# the part ends up, the exit code), not a wall-clock delay nor the request count a
# fault is timed by.

#: The fixed motion timeout the stall tests wait out (wall seconds). Every move that is
#: not stalled must end within it: at QUICK the longest, the retreat's 10 % PTP home
#: (2.6 simulated s), ends in about 30 ms, seen done by the master within about 60 ms.
STALL_TIMEOUT_S = 0.3

SimFactory = Callable[..., Simulator]


def parts(n: int) -> list[TableObject]:
    """``n`` parts waiting at the article's pick pose (a feeder)."""
    return [TableObject(name=f"part-{i}", pose=PICK) for i in range(1, n + 1)]


def write_config(
    tmp_path: Path, extra: str = "", name: str = "cell.toml", *, timeouts: str = "", run: str = ""
) -> Path:
    """A config file: the fast settings (plus keys for [timeouts] and [run]), then ``extra``."""
    path = tmp_path / name
    text = FAST.replace("[timeouts]", f"[timeouts]\n{timeouts}").replace("[run]", f"[run]\n{run}")
    path.write_text(text + "\n" + extra)
    return path


def run_cli(
    sim: Simulator, config: Path, tmp_path: Path, *extra: str
) -> tuple[int, dict[str, Any]]:
    """Run the command in-process against ``sim``; return exit code and report.

    These tests drive the article's map (its registers are what they check): the
    profile is given, since the command's default is tmflow.
    """
    report = tmp_path / "report.json"
    profile = [] if "--profile" in extra else ["--profile", "article"]
    code = main(
        [
            "--host",
            "127.0.0.1",
            "--port",
            str(sim.port),
            "--config",
            str(config),
            "--report",
            str(report),
            *profile,
            *extra,
        ]
    )
    return code, json.loads(report.read_text())


def motion_writes(log: list[RequestRecord]) -> list[RequestRecord]:
    """Every write of the article's command block (one per motion command)."""
    return [r for r in log if r.is_write and r.address == TARGET_BLOCK]


def gripper_writes(log: list[RequestRecord], value: int | None = None) -> list[RequestRecord]:
    """Writes of the gripper register (optionally only of ``value``)."""
    return [
        r
        for r in log
        if r.is_write
        and r.address == GRIPPER_REGISTER
        and (value is None or (r.values is not None and r.values[0] == value))
    ]


def last_stderr_line(err: str) -> str:
    """The reason line: the last line on stderr (the in-process simulator's events aside,
    which its loop thread may still log after the command printed its reason)."""
    lines = [line for line in err.splitlines() if line.strip() and " sim." not in line]
    assert lines, "nothing on stderr"
    return lines[-1]


def assert_one_line_reason(err: str, code: int, *needles: str) -> None:
    """The command says why in one line starting with pickplace:, never a traceback."""
    assert "Traceback" not in err
    line = last_stderr_line(err)
    assert line.startswith("pickplace: ")
    assert line.endswith(f"[exit {code}]")
    for needle in needles:
        assert needle in line


def int16(value: int) -> int:
    """Decode a register word as a signed 16-bit value."""
    return value - 0x10000 if value >= 0x8000 else value


# -- the article's cycle ---------------------------------------------------------------


def test_the_report_counts_a_stand_alone_grippers_requests_apart(
    tm_simulator_factory: SimFactory, tmp_path: Path
) -> None:
    sim = tm_simulator_factory(
        "article", robot=RobotSetup(gripper="onrobot-2fg7"), cell=Cell(scene=parts(1)), **QUICK
    )
    assert sim.gripper_port is not None
    config = write_config(tmp_path)
    own = f'[gripper]\nkind = "onrobot-2fg7"\nport = {sim.gripper_port}\n'
    config.write_text(config.read_text().replace("[gripper]\n", own))
    code, report = run_cli(sim, config, tmp_path)
    assert code == EXIT_OK
    # Its own link: its requests are counted apart from the robot's.
    assert report["transport"]["gripper"]["requests"] > 0
    assert report["transport"]["robot"]["requests"] > 0


def test_the_report_has_no_gripper_counters_for_a_gripper_on_the_robots_link(
    tm_simulator_factory: SimFactory, tmp_path: Path
) -> None:
    sim = tm_simulator_factory("article", cell=Cell(scene=parts(1)), **QUICK)
    code, report = run_cli(sim, write_config(tmp_path), tmp_path)
    assert code == EXIT_OK
    assert report["transport"]["gripper"] is None


def test_article_cycle_ends_done_with_the_part_on_the_place_position(
    tm_simulator_factory: SimFactory, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = tm_simulator_factory("article", cell=Cell(scene=parts(1)), **QUICK)
    code, report = run_cli(sim, write_config(tmp_path), tmp_path)

    assert code == EXIT_OK
    (part,) = sim.objects()
    assert not part.held
    assert part.pose.is_close(PLACED, mm=1.0)
    assert report["result"] == "done"
    assert report["final_state"] == "DONE"
    assert report["cycles"]["completed"] == 1
    assert list(report["states"]) == [
        "IDLE",
        "MOVE_TO_APPROACH",
        "MOVE_TO_PICK",
        "GRIPPER_CLOSE",
        "CHECK_GRASP",
        "MOVE_TO_LIFT",
        "MOVE_TO_PLACE",
        "GRIPPER_OPEN",
        "MOVE_TO_HOME",
    ]
    assert report["config"]["digest"].startswith("sha256:")
    assert report["transport"]["robot"]["requests"] > 0
    # The article's poses, speeds and motion types, in order, one FC16 each.
    sent = [
        ([int16(v) / 100 for v in r.values[:6]], r.values[6], r.values[7])
        for r in motion_writes(sim.request_log)
        if r.values is not None
    ]
    assert sent == [
        ([300, -200, 200, 180, 0, 90], 30, 1),
        ([300, -200, 100, 180, 0, 90], 10, 2),
        ([300, -200, 250, 180, 0, 90], 10, 2),
        ([300, 200, 200, 180, 0, 90], 30, 1),
        ([250, 0, 300, 180, 0, 90], 30, 1),
    ]
    assert all(r.function_code == 16 for r in motion_writes(sim.request_log))
    assert "DONE: 1/1 cycle(s)" in capsys.readouterr().out


def test_several_cycles_place_every_part(tm_simulator_factory: SimFactory, tmp_path: Path) -> None:
    sim = tm_simulator_factory("article", cell=Cell(scene=parts(3)), **QUICK)
    code, report = run_cli(sim, write_config(tmp_path), tmp_path, "--cycles", "3")

    assert code == EXIT_OK
    assert report["cycles"]["completed"] == 3
    assert len(report["cycles"]["times_s"]) == 3
    assert report["states"]["MOVE_TO_PICK"]["count"] == 3
    # Every part went to the place x-y; each later one fell onto the one before (issue 9).
    stack = sorted(sim.objects(), key=lambda obj: obj.pose.z)
    for k, obj in enumerate(stack):
        assert obj.pose.is_close(PLACED.offset(dz=30 * k), mm=1.0)
        assert not obj.held
    assert len(motion_writes(sim.request_log)) == 15


# -- faults: each ends with its own exit code and one line -------------------------------


def test_stall_times_out_stops_the_arm_and_exits_with_the_timeout_code(
    tm_simulator_factory: SimFactory, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = tm_simulator_factory(
        "article", cell=Cell(scene=parts(1)), faults=["stall:at_move=2"], **QUICK
    )
    config = write_config(tmp_path, timeouts=f"motion_s = {STALL_TIMEOUT_S}")
    code, report = run_cli(sim, config, tmp_path)

    assert code == EXIT_TIMEOUT
    assert_one_line_reason(capsys.readouterr().err, code, "MOVE_TO_PICK", "MotionTimeoutError")
    assert report["result"] == "timeout"
    assert report["error"]["state"] == "MOVE_TO_PICK"
    assert report["reaction"]["reaction"] == "stay"
    stops = [
        r
        for r in sim.request_log
        if r.is_write and r.address == COMMAND_REGISTER and r.values == (3,)
    ]
    assert len(stops) == 1, "the stalled arm must be stopped"
    assert len(motion_writes(sim.request_log)) == 2


def test_stall_with_retreat_goes_up_then_home_at_low_speed(
    tm_simulator_factory: SimFactory, tmp_path: Path
) -> None:
    sim = tm_simulator_factory(
        "article", cell=Cell(scene=parts(1)), faults=["stall:at_move=2"], **QUICK
    )
    config = write_config(
        tmp_path, '[on_error]\nreaction = "retreat"\n', timeouts=f"motion_s = {STALL_TIMEOUT_S}"
    )
    code, report = run_cli(sim, config, tmp_path)

    assert code == EXIT_TIMEOUT
    assert report["reaction"]["performed"] is True
    assert sim.tcp_pose().is_close(HOME, mm=1.0)
    retreat = motion_writes(sim.request_log)[2:]
    assert [r.values[6] for r in retreat if r.values] == [10, 10]  # both at 10 %
    assert [r.values[7] for r in retreat if r.values] == [2, 1]  # Line up, then PTP


def test_robot_error_exits_with_the_fault_code_and_never_retreats(
    tm_simulator_factory: SimFactory, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = tm_simulator_factory(
        "article", cell=Cell(scene=parts(1)), faults=["robot_error:at_move=3,code=0x1F4"], **QUICK
    )
    config = write_config(tmp_path, '[on_error]\nreaction = "retreat"\n')
    code, report = run_cli(sim, config, tmp_path)

    assert code == EXIT_ROBOT_FAULT
    assert_one_line_reason(
        capsys.readouterr().err, code, "MOVE_TO_LIFT", "0x01F4 (not in TMflow 2.24 Appendix J)"
    )
    assert report["error"] == {
        "state": "MOVE_TO_LIFT",
        "cycle": 1,
        "type": "RobotFaultError",
        "message": report["error"]["message"],
        "error_code": 500,
        "error_meaning": "0x01F4 (not in TMflow 2.24 Appendix J)",
    }
    assert report["reaction"]["performed"] is False
    assert len(motion_writes(sim.request_log)) == 3, "nothing may move after a robot error"


def test_estop_never_moves_again(
    tm_simulator_factory: SimFactory, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = tm_simulator_factory(
        "article", cell=Cell(scene=parts(1)), faults=["estop:at_move=4"], **QUICK
    )
    config = write_config(tmp_path, '[on_error]\nreaction = "retreat"\n')
    code, report = run_cli(sim, config, tmp_path)

    assert code == EXIT_ROBOT_FAULT
    assert_one_line_reason(capsys.readouterr().err, code, "MOVE_TO_PLACE", "0x0200 (not in")
    assert report["reaction"]["performed"] is False
    assert len(motion_writes(sim.request_log)) == 4


def test_grasp_miss_is_retried_and_the_cycle_completes(
    tm_simulator_factory: SimFactory, tmp_path: Path
) -> None:
    sim = tm_simulator_factory(
        "article", cell=Cell(scene=parts(1)), faults=["grasp_miss:at_grasp=1"], **QUICK
    )
    code, report = run_cli(sim, write_config(tmp_path), tmp_path)

    assert code == EXIT_OK
    assert report["retries"]["grasp"] == 1
    assert [t["outcome"] for t in report["timeline"] if t["state"] == "CHECK_GRASP"] == [
        "retry",
        "ok",
    ]
    assert len(gripper_writes(sim.request_log, 1)) == 2  # closed twice
    assert sim.objects()[0].pose.is_close(PLACED, mm=1.0)


def test_grasp_miss_after_every_retry_exits_with_the_grasp_code(
    tm_simulator_factory: SimFactory, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    misses = [f"grasp_miss:at_grasp={n}" for n in (1, 2, 3)]
    sim = tm_simulator_factory("article", cell=Cell(scene=parts(1)), faults=misses, **QUICK)
    config = write_config(tmp_path, run="grasp_retries = 2")
    code, report = run_cli(sim, config, tmp_path)

    assert code == EXIT_GRASP
    assert_one_line_reason(capsys.readouterr().err, code, "CHECK_GRASP", "GraspFailedError")
    assert report["result"] == "grasp_failed"
    assert report["retries"]["grasp"] == 2
    assert len(gripper_writes(sim.request_log, 1)) == 3  # 1 try + 2 retries
    # Never lifted: the moves are approach/pick three times.
    assert len(motion_writes(sim.request_log)) == 6


#: Where the link drops: right after the answer to the n-th write of a register, so the
#: drop lands in the same phase of the cycle whatever the poll schedule. The gripper's
#: opening at the start (before any move), its closing on the part (while the grasp is
#: checked), the lift's command block (while the arm moves with the part).
DROP_POINTS = {
    "start": (GRIPPER_REGISTER, 1),
    "grasp": (GRIPPER_REGISTER, 2),
    "lift": (TARGET_BLOCK, 3),
}


@pytest.mark.parametrize("where", list(DROP_POINTS))
def test_a_dropped_connection_is_survived_without_sending_any_command_twice(
    tm_simulator_factory: SimFactory, tmp_path: Path, where: str
) -> None:
    register, nth_write = DROP_POINTS[where]
    drop = f"drop_connections:on_write_to={register},after_requests={nth_write}"
    sim = tm_simulator_factory("article", cell=Cell(scene=parts(1)), faults=[drop])
    code, report = run_cli(sim, write_config(tmp_path), tmp_path)

    assert code == EXIT_OK
    assert report["transport"]["robot"]["reconnects"] >= 1
    assert len(motion_writes(sim.request_log)) == 5, "a motion command was written twice"
    assert len(gripper_writes(sim.request_log)) == 3  # open at start, close, open
    assert sim.objects()[0].pose.is_close(PLACED, mm=1.0)


# -- invalid configuration: nothing at all is sent ----------------------------------------


@pytest.mark.parametrize(
    ("extra", "needles"),
    [
        # Beyond the article profile's int16 x100 range (+/-327.67 mm).
        ("[poses]\nplace = [400, 200, 200, 180, 0, 90]\n", ["poses.place", "out of range"]),
        ("[speeds]\npick = 150\n", ["speeds.pick"]),
        ("[speeds]\npick = '10'\n", ["speeds.pick"]),
        ("[poses]\npick = [300, -200, 100]\n", ["poses.pick"]),
        ("[run]\ncylces = 3\n", ["run.cylces", "unknown key"]),
        (
            "[poses]\napproach = [300, -200, 200, 180, 0, 90]\napproach_z_offset = 50\n",
            ["approach_z_offset"],
        ),
        ("[gripper]\nkind = 'no-such-gripper'\n", ["no-such-gripper"]),
    ],
)
def test_an_invalid_config_sends_nothing_and_names_field_and_file(
    tm_simulator_factory: SimFactory,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    extra: str,
    needles: list[str],
) -> None:
    sim = tm_simulator_factory("article", cell=Cell(scene=parts(1)))
    config = tmp_path / "broken.toml"
    config.write_text(extra)
    code, report = run_cli(sim, config, tmp_path)

    assert code == EXIT_CONFIG
    assert_one_line_reason(capsys.readouterr().err, code, "broken.toml", *needles)
    assert report["result"] == "config_error"
    assert sim.request_log == [], "an invalid config must not send a single request"


def test_a_config_that_is_not_toml_is_a_config_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "bad.toml"
    config.write_text("[run\ncycles = 1\n")
    assert main(["--host", "127.0.0.1", "--config", str(config)]) == EXIT_CONFIG
    assert_one_line_reason(capsys.readouterr().err, EXIT_CONFIG, "bad.toml", "not valid TOML")


def test_host_is_required_without_sim_dry_run_or_diagram(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main([]) == EXIT_CONFIG
    assert_one_line_reason(capsys.readouterr().err, EXIT_CONFIG, "--host is required")


def test_connection_refused_exits_with_the_connection_code(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    config = write_config(tmp_path, "[retry]\nattempts = 1\n")
    code = main(["--host", "127.0.0.1", "--port", str(port), "--config", str(config)])
    assert code == EXIT_CONNECTION
    assert_one_line_reason(capsys.readouterr().err, code, f"127.0.0.1:{port}")


# -- plan, diagram ---------------------------------------------------------------------


def test_dry_run_prints_the_plan_and_connects_to_nothing(
    tm_simulator_factory: SimFactory, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = tm_simulator_factory("article")
    assert main(["--host", "127.0.0.1", "--port", str(sim.port), "--dry-run"]) == EXIT_OK
    out = capsys.readouterr().out
    assert "[300, -200, 200, 180, 0, 90]" in out
    assert "[250, 0, 300, 180, 0, 90]" in out
    assert "line" in out
    assert "ptp" in out
    assert "expected motion time" in out
    assert sim.request_log == []


def test_diagram_is_mermaid_with_the_guarded_transitions(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["--diagram"]) == EXIT_OK
    out = capsys.readouterr().out
    assert "stateDiagram-v2" in out
    assert "CHECK_GRASP --> MOVE_TO_APPROACH: retry [may_continue & retries_left]" in out
    assert "CHECK_GRASP --> MOVE_TO_LIFT: advance [may_continue & guard_grasp_detected]" in out
    assert "MOVE_TO_HOME --> DONE: advance [last_cycle]" in out


def test_sim_option_runs_in_process_and_reports_where_the_part_is(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report = tmp_path / "r.json"
    config = write_config(tmp_path)
    code = main(
        ["--sim", "--sim-time-scale", "40", "--config", str(config), "--report", str(report)]
    )
    assert code == EXIT_OK
    data = json.loads(report.read_text())
    assert data["sim"]["on_place"] is True
    assert "part-1 is on the place position" in capsys.readouterr().out


# -- the real entry point ----------------------------------------------------------------


def _env() -> dict[str, str]:
    env = dict(os.environ)
    src = str(Path(__file__).resolve().parents[1] / "src")
    env["PYTHONPATH"] = src + os.pathsep + env.get("PYTHONPATH", "")
    return env


def test_entry_point_runs_the_article_cycle_on_the_simulator(tmp_path: Path) -> None:
    # The entry point's whole life in one process: the cycle and its report, then two
    # Ctrl-Cs while Python runs the exit hooks (the test hook pauses there; for the
    # other commands after --help: test_sigint_exit). They change nothing: no line on
    # stderr (no "Exception ignored in atexit callback"), the status stays 0.
    report = tmp_path / "r.json"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "tmmaster.pickplace",
            "--sim",
            "--sim-time-scale",
            "40",
            # The default 50 ms polls, stretched mid-move, cost half a second of the run's
            # waits at 40x; the entry point, not the pace, is the subject here.
            "--poll-interval",
            "0.02",
            "--report",
            str(report),
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**_env(), **PAUSE_AT_EXIT},
    )
    try:
        err, out, after_the_pause = ctrl_c_in_the_exit_hooks(proc)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert err.endswith(PAUSED_AT_EXIT), err + after_the_pause
    assert after_the_pause == ""
    assert proc.returncode == EXIT_OK, err
    assert "part-1 is on the place position" in out
    assert json.loads(report.read_text())["result"] == "done"


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_sigint_or_sigterm_stops_the_arm_and_writes_the_report(
    tmp_path: Path, signum: signal.Signals
) -> None:
    # SIGTERM is a supervisor's stop (systemctl stop, docker stop, kill): the same as
    # Ctrl-C, never a process gone with its arm moving and no report.
    report = tmp_path / "r.json"
    # The gripper's settle time (0.5 s at scale 1) only delays the first move, before the
    # moment this test is about: the moves themselves keep their real-time durations.
    config = tmp_path / "settle.toml"
    config.write_text("[gripper]\nsettle_s = 0.05\n")
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "tmmaster.pickplace",
            "--sim",
            "--profile",
            "article",
            "--config",
            str(config),
            "--log-json",
            "--report",
            str(report),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=_env(),
    )
    try:
        assert proc.stderr is not None
        deadline = time.monotonic() + 30
        for line in proc.stderr:  # real time (scale 1): each move takes over a second
            if '"robot.command_acknowledged"' in line:
                break
            assert time.monotonic() < deadline
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == EXIT_INTERRUPTED, err
    assert "Traceback" not in err
    assert last_stderr_line(err).startswith("pickplace: interrupted in MOVE_TO_APPROACH")
    data = json.loads(report.read_text())
    assert data["result"] == "interrupted"
    assert '"robot.stop_sent"' in err


@pytest.mark.skipif(shutil.which("setsid") is None, reason="needs util-linux's setsid")
def test_a_terminal_hang_up_stops_the_arm_and_writes_the_report(tmp_path: Path) -> None:
    # An SSH session lost: the run's terminal (a pty here, its controlling terminal)
    # hangs up mid-move, the kernel sends SIGHUP and every later write to it fails (EIO).
    # The arm is stopped and the report written, as after Ctrl-C, never a process gone
    # with its arm moving (SIGHUP's default) nor a run failed by its own output.
    report = tmp_path / "r.json"
    config = tmp_path / "settle.toml"
    config.write_text("[gripper]\nsettle_s = 0.05\n")
    command = [sys.executable, "-m", "tmmaster.pickplace", "--sim", "--profile", "article"]
    terminal, child_side = pty.openpty()
    proc = subprocess.Popen(
        ["setsid", "--ctty", *command, "--config", str(config), "--report", str(report)],
        stdin=child_side,
        stdout=child_side,
        stderr=child_side,
        env={**_env(), "TERM": "xterm", "COLUMNS": "100"},
    )
    os.close(child_side)
    try:
        shown, deadline = b"", time.monotonic() + 30
        while b"MOVE_TO_APPROACH" not in shown:  # the live display, in real time
            assert time.monotonic() < deadline, shown
            if select.select([terminal], [], [], 0.5)[0]:
                shown += os.read(terminal, 65536)
        os.close(terminal)  # the hang-up
        code = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert code == EXIT_INTERRUPTED
    data = json.loads(report.read_text())
    assert data["result"] == "interrupted"
    assert data["reason"].endswith("the arm was stopped"), data["reason"]


@pytest.mark.parametrize("after_s", [0.0, 0.2, 0.5])
def test_sigint_at_any_moment_exits_130_in_one_line(tmp_path: Path, after_s: float) -> None:
    # From the first moment of main() (the test hook pauses the command there), whether
    # the options are read, the simulator is starting or the run is under way: exit 130,
    # one line, never a traceback (issue 8, failure 8). Before main() runs (Python
    # starting, the modules loading), Ctrl-C is Python's own (docs/safety.md, Limits).
    proc = subprocess.Popen(
        [sys.executable, "-m", "tmmaster.pickplace", "--sim", "--sim-time-scale", "5"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**_env(), "TMMASTER_TEST_SIGINT_AT": "start"},
    )
    try:
        assert proc.stdin is not None
        assert proc.stderr is not None
        assert proc.stderr.readline() == "tmmaster-test: paused at start\n"
        proc.stdin.write("x")  # main() goes on
        proc.stdin.flush()
        time.sleep(after_s)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == EXIT_INTERRUPTED, err
    assert "Traceback" not in err
    assert last_stderr_line(err).startswith("pickplace: interrupted")


def test_a_report_file_has_ordinary_permissions(tmp_path: Path) -> None:
    from tmmaster.pickplace import write_report

    previous = os.umask(0o022)
    try:
        write_report(tmp_path / "r.json", {"result": "done"})
    finally:
        os.umask(previous)
    assert (tmp_path / "r.json").stat().st_mode & 0o777 == 0o644


def test_three_ctrl_c_on_a_slow_link_leave_nothing_armed_after_exit(
    tm_simulator_factory: Callable[..., Simulator],
) -> None:
    # A robot in its own process, its commands taken late, every answer 40 ms late from
    # its first command on: the first Ctrl-C starts the withdraw, the second and third
    # land in the middle of it and of the close. Whatever the master printed, nothing
    # may start once it has exited. (The connection and the start-up checks before the
    # first command go at full speed: they are not the subject, and took 1.2 s slowed.)
    from fault_proxy import FaultProxy, Rule

    profile = "tmflow"
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=8"])  # 0.2 s wall
    with FaultProxy(sim.port) as proxy:
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "tmmaster.pickplace",
                "--host",
                "127.0.0.1",
                "--port",
                str(proxy.port),
                "--profile",
                profile,
                "--log-json",
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=_env(),
        )
        try:
            assert proc.stderr is not None
            deadline = time.monotonic() + 30
            for line in proc.stderr:
                if '"robot.command_sent"' in line:
                    proxy.add(Rule("delay", delay_s=0.04, times=1_000_000))
                    break
                assert time.monotonic() < deadline
            for _ in range(3):
                proc.send_signal(signal.SIGINT)
                time.sleep(0.03)
            _, err = proc.communicate(timeout=30)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
        exited = time.monotonic()
        assert proc.returncode == EXIT_INTERRUPTED, err
        assert "Traceback" not in err
        start = sim.ticks
        sim.wait_for(lambda: sim.ticks >= start + 40, timeout=5)  # 16 simulated s
    late = [(m.number, m.kind) for m in sim.motion_log() if m.wall_time > exited]
    assert late == [], f"{late} started after the master exited: {last_stderr_line(err)}"
