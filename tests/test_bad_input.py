"""Bad input is exit 2, always (issue 8 item 7): one stderr line naming file and key, nothing sent.

Every case runs ``main([...])`` in-process. Nothing may start: the runner and the
simulator's server are replaced by tripwires, and the cases that give a host point it
at a listener that counts connections (it must stay at zero).
"""

from __future__ import annotations

import re
import socket
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from tmmaster import ConfigError, Pose, _cli
from tmmaster.pickplace import __main__ as pickplace_main
from tmmaster.sim import Cell, Listen, RobotSetup, Timing
from tmmaster.sim import __main__ as sim_main
from tmmaster.sim._simulator import Simulator
from tmmaster.sim._world import DEFAULT_PART_POSE, TableObject

BINARY = b"\x00\x01\x02\xff\xfe\x80PK\x03\x04"
NOT_UTF8 = b'name = "caf\xe9"\n'

GOOD_SEQUENCE = """name = "s"
[poses]
p = [300, -200, 100, 180, 0, 90]
[[steps]]
do = "move"
pose = "p"
speed = 30
"""


class ConnectionCounter:
    """A TCP listener on 127.0.0.1 that counts accepted connections."""

    def __init__(self) -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen(8)
        self.port: int = self.sock.getsockname()[1]
        self.accepted = 0
        self._thread = threading.Thread(target=self._accept, daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            self.accepted += 1
            conn.close()

    def close(self) -> None:
        self.sock.close()


@pytest.fixture(scope="module")
def counter() -> Iterator[ConnectionCounter]:
    c = ConnectionCounter()
    yield c
    c.close()


@pytest.fixture(autouse=True)
def tripwires(monkeypatch: pytest.MonkeyPatch) -> None:
    def boom(*_: Any, **__: Any) -> Any:
        raise AssertionError("bad input got past validation: something was started")

    monkeypatch.setattr(pickplace_main, "_run_on", boom)
    monkeypatch.setattr(pickplace_main, "_run_with_sim", boom)
    monkeypatch.setattr(Simulator, "start", boom)


# (case id, files {name: content}, argv after "pickplace", text the line must contain)
# "{dir}" in argv is replaced with the folder holding the files; "{port}" with the counter's.
Case = tuple[str, dict[str, str | bytes], list[str], str]
HOST = ["--host", "127.0.0.1", "--port", "{port}"]


def _config(key: str, section: str, body: str) -> Case:
    return (
        f"config-{section}-{key}",
        {"c.toml": f"[{section}]\n{body}\n"},
        [*HOST, "--config", "{dir}/c.toml"],
        key,
    )


CONFIG_CASES: list[Case] = [
    ("config-binary", {"c.toml": BINARY}, [*HOST, "--config", "{dir}/c.toml"], "c.toml"),
    ("config-not-utf8", {"c.toml": NOT_UTF8}, [*HOST, "--config", "{dir}/c.toml"], "c.toml"),
    ("config-not-toml", {"c.toml": "[robot"}, [*HOST, "--config", "{dir}/c.toml"], "c.toml"),
    ("config-array-table", {"c.toml": "[[1]]\n"}, [*HOST, "--config", "{dir}/c.toml"], "1"),
    ("config-missing", {}, [*HOST, "--config", "{dir}/nope.toml"], "nope.toml"),
    ("config-directory", {}, [*HOST, "--config", "{dir}"], "config"),
    (
        "config-section-not-table",
        {"c.toml": "robot = 5\n"},
        [*HOST, "--config", "{dir}/c.toml"],
        "robot",
    ),
    ("config-run-not-table", {"c.toml": "run = [1]\n"}, [*HOST, "--config", "{dir}/c.toml"], "run"),
    ("config-unknown-section", {"c.toml": "[robo]\n"}, [*HOST, "--config", "{dir}/c.toml"], "robo"),
    _config("port", "robot", "port = 70000"),
    _config("port", "robot", "port = 0"),
    _config("port", "robot", 'port = "x"'),
    _config("model", "robot", 'model = "tm7"'),
    _config("profile", "robot", 'profile = "nope"'),
    _config("profile", "robot", "profile = 5"),
    _config("host", "robot", "host = 5"),
    _config("max_speed", "robot", "max_speed = 0"),
    _config("max_speed", "robot", "max_speed = 101"),
    _config("position_tolerance_mm", "robot", "position_tolerance_mm = nan"),
    _config("position_tolerance_mm", "robot", "position_tolerance_mm = inf"),
    _config("position_tolerance_mm", "robot", "position_tolerance_mm = 0"),
    _config("position_tolerance_mm", "robot", "position_tolerance_mm = -1"),
    _config("pick", "poses", "pick = [1, 2, 3]"),
    _config("pick", "poses", "pick = [nan, 0, 0, 0, 0, 0]"),
    _config("pick", "poses", "pick = [0, inf, 0, 0, 0, 0]"),
    _config("pick", "poses", 'pick = "here"'),
    _config("pick", "poses", 'pick = ["300", -200, 100, 180, 0, 90]'),
    _config("pick", "poses", "pick = [true, -200, 100, 180, 0, 90]"),
    _config("approach_z_offset", "poses", "approach_z_offset = nan"),
    _config("approach_z_offset", "poses", "approach_z_offset = inf"),
    _config("lift_z_offset", "poses", "lift_z_offset = -1"),
    _config("pick", "speeds", "pick = 0"),
    _config("pick", "speeds", "pick = 200"),
    _config("pick", "speeds", "pick = nan"),
    _config("pick", "motion", 'pick = "lin"'),
    _config("ack_s", "timeouts", "ack_s = nan"),
    _config("ack_s", "timeouts", "ack_s = inf"),
    _config("ack_s", "timeouts", "ack_s = 0"),
    _config("motion_factor", "timeouts", "motion_factor = nan"),
    _config("motion_margin_s", "timeouts", "motion_margin_s = -1"),
    _config("motion_s", "timeouts", "motion_s = 0"),
    _config("gripper_s", "timeouts", "gripper_s = inf"),
    _config("request_s", "timeouts", "request_s = 0"),
    _config("ready_s", "timeouts", "ready_s = nan"),
    _config("attempts", "retry", "attempts = 0"),
    _config("total_time_s", "retry", "total_time_s = nan"),
    _config("total_time_s", "retry", "total_time_s = inf"),
    _config("kind", "gripper", 'kind = "nope"'),
    _config("port", "gripper", "port = 70000"),
    _config("settle_s", "gripper", "settle_s = nan"),
    _config("settle_s", "gripper", "settle_s = 0"),
    _config("cycles", "run", "cycles = 0"),
    _config("cycles", "run", "cycles = -1"),
    _config("cycles", "run", "cycles = 1.5"),
    _config("poll_interval_s", "run", "poll_interval_s = nan"),
    _config("poll_interval_s", "run", "poll_interval_s = inf"),
    _config("poll_interval_s", "run", "poll_interval_s = 0"),
    _config("grasp_retries", "run", "grasp_retries = -1"),
    _config("reaction", "on_error", 'reaction = "jump"'),
    _config("pose", "on_error", "pose = [nan, 0, 0, 0, 0, 0]"),
    _config("speed", "on_error", "speed = 0"),
    _config("x", "workspace", "x = [nan, 1]"),
    _config("x", "workspace", "x = [1, 0]"),
    _config("y", "workspace", "y = [-inf, inf]"),
    _config("z", "workspace", "z = [1, 2, 3]"),
]

OPTION_CASES: list[Case] = [
    # The report is written after the arm moved: a path it cannot be written to is
    # refused before anything is sent.
    ("report-is-a-folder", {}, [*HOST, "--report", "{dir}"], "--report"),
    ("report-under-a-file", {"f": "x"}, [*HOST, "--report", "{dir}/f/run.json"], "--report"),
    ("opt-port-70000", {}, ["--host", "127.0.0.1", "--port", "70000"], "port"),
    ("opt-port-0", {}, ["--host", "127.0.0.1", "--port", "0"], "port"),
    ("opt-port-negative", {}, ["--host", "127.0.0.1", "--port", "-1"], "port"),
    ("opt-port-text", {}, ["--host", "127.0.0.1", "--port", "x"], "--port"),
    ("opt-cycles-negative", {}, [*HOST, "--cycles", "-1"], "cycles"),
    ("opt-cycles-zero", {}, [*HOST, "--cycles", "0"], "cycles"),
    ("opt-cycles-text", {}, [*HOST, "--cycles", "x"], "--cycles"),
    ("opt-poll-nan", {}, [*HOST, "--poll-interval", "nan"], "--poll-interval nan: must be"),
    ("opt-poll-inf", {}, [*HOST, "--poll-interval", "inf"], "--poll-interval inf: must be"),
    ("opt-poll-zero", {}, [*HOST, "--poll-interval", "0"], "--poll-interval 0: must be"),
    ("opt-poll-negative", {}, [*HOST, "--poll-interval", "-1"], "--poll-interval -1: must be"),
    ("opt-sim-scale-inf", {}, ["--sim", "--sim-time-scale", "inf"], "--sim-time-scale"),
    ("opt-sim-scale-nan", {}, ["--sim", "--sim-time-scale", "nan"], "--sim-time-scale"),
    ("opt-sim-scale-zero", {}, ["--sim", "--sim-time-scale", "0"], "--sim-time-scale"),
    ("opt-sim-scale-negative", {}, ["--sim", "--sim-time-scale", "-1"], "--sim-time-scale"),
    ("opt-sim-scale-no-sim", {}, [*HOST, "--sim-time-scale", "inf"], "--sim-time-scale"),
    # Options of the embedded simulator never pass silently on a robot.
    ("opt-sim-scale-on-a-robot", {}, [*HOST, "--sim-time-scale", "5"], "--sim-time-scale"),
    ("opt-sim-physics-on-a-robot", {}, [*HOST, "--sim-physics", "kinematic"], "--sim-physics"),
    ("opt-snapshot-on-a-robot", {}, [*HOST, "--snapshot", "{dir}"], "--snapshot"),
    ("opt-log-level", {}, [*HOST, "--log-level", "loud"], "--log-level"),
    ("opt-unknown", {}, [*HOST, "--speed", "5"], "--speed"),
    ("opt-no-host", {}, [], "--host"),
    ("opt-profile-unknown", {}, [*HOST, "--profile", "nope"], "nope"),
    ("opt-profile-gripper", {}, [*HOST, "--profile", "onrobot-2fg7"], "onrobot-2fg7"),
    ("opt-profile-missing", {}, [*HOST, "--profile", "{dir}/nope.toml"], "nope.toml"),
    ("profile-binary", {"p.toml": BINARY}, [*HOST, "--profile", "{dir}/p.toml"], "p.toml"),
    ("profile-not-utf8", {"p.toml": NOT_UTF8}, [*HOST, "--profile", "{dir}/p.toml"], "p.toml"),
    ("profile-array-table", {"p.toml": "[[1]]\n"}, [*HOST, "--profile", "{dir}/p.toml"], "p.toml"),
    (
        "profile-remove-fields-int",
        {"p.toml": 'extends = "article"\nremove_fields = 5\n'},
        [*HOST, "--profile", "{dir}/p.toml"],
        "remove_fields",
    ),
    (
        "profile-remove-fields-list-of-int",
        {"p.toml": 'extends = "article"\nremove_fields = [5]\n'},
        [*HOST, "--profile", "{dir}/p.toml"],
        "remove_fields",
    ),
    (
        "profile-fields-int",
        {"p.toml": 'extends = "article"\nfields = 5\n'},
        [*HOST, "--profile", "{dir}/p.toml"],
        "fields",
    ),
    (
        "profile-field-int",
        {"p.toml": 'extends = "article"\n[fields]\ntarget_x = 5\n'},
        [*HOST, "--profile", "{dir}/p.toml"],
        "target_x",
    ),
    (
        "profile-extends-int",
        {"p.toml": "extends = 5\n"},
        [*HOST, "--profile", "{dir}/p.toml"],
        "extends",
    ),
    (
        "profile-extends-unknown",
        {"p.toml": 'extends = "nope"\n'},
        [*HOST, "--profile", "{dir}/p.toml"],
        "nope",
    ),
    (
        "profile-kind",
        {"p.toml": 'kind = "arm"\nname = "x"\n'},
        [*HOST, "--profile", "{dir}/p.toml"],
        "kind",
    ),
    (
        "profile-split-block",
        {"p.toml": 'extends = "article"\n[fields.target_y]\naddress = 0x0220\n'},
        [*HOST, "--profile", "{dir}/p.toml"],
        "target_y",
    ),
    (
        "profile-ptp-is-none",
        {"p.toml": 'extends = "article"\n[fields.command.values]\n0 = "ptp"\n1 = "none"\n'},
        [*HOST, "--profile", "{dir}/p.toml"],
        "ptp",
    ),
    (
        "profile-scale-nan",
        {"p.toml": 'extends = "article"\n[fields.target_x]\nscale = nan\n'},
        [*HOST, "--profile", "{dir}/p.toml"],
        "scale",
    ),
    (
        "profile-minimum-nan",
        {"p.toml": 'extends = "article"\n[fields.target_x]\nminimum = nan\n'},
        [*HOST, "--profile", "{dir}/p.toml"],
        "minimum",
    ),
]


def _seq(case_id: str, body: str | bytes, named: str) -> Case:
    return (case_id, {"s.toml": body}, [*HOST, "--sequence", "{dir}/s.toml"], named)


SEQUENCE_CASES: list[Case] = [
    _seq("seq-binary", BINARY, "s.toml"),
    _seq("seq-not-utf8", NOT_UTF8, "s.toml"),
    _seq("seq-not-toml", "[[steps]", "s.toml"),
    _seq("seq-array-table", "[[1]]\n", "1"),
    _seq("seq-empty", "", "name"),
    _seq("seq-no-steps", 'name = "s"\n', "steps"),
    _seq("seq-steps-int", 'name = "s"\nsteps = 5\n', "steps"),
    _seq("seq-poses-int", GOOD_SEQUENCE.replace("[poses]\n", "poses = 5\n[x]\n"), "poses"),
    _seq("seq-z-offset-nan", GOOD_SEQUENCE + "z_offset = nan\n", "z_offset"),
    _seq("seq-z-offset-inf", GOOD_SEQUENCE + "z_offset = inf\n", "z_offset"),
    _seq("seq-speed-zero", GOOD_SEQUENCE.replace("speed = 30", "speed = 0"), "speed"),
    _seq("seq-motion-lin", GOOD_SEQUENCE + 'motion = "lin"\n', "motion"),
    _seq("seq-unknown-pose", GOOD_SEQUENCE.replace('pose = "p"', 'pose = "q"'), "q"),
    _seq("seq-pose-nan", GOOD_SEQUENCE.replace("300,", "nan,"), "p"),
    _seq("seq-pose-text", GOOD_SEQUENCE.replace("300,", '"300",'), "300"),
    _seq("seq-unknown-do", GOOD_SEQUENCE.replace('do = "move"', 'do = "jump"'), "do"),
    _seq("seq-wait-nan", GOOD_SEQUENCE + '[[steps]]\ndo = "wait"\nseconds = nan\n', "seconds"),
    _seq("seq-wait-inf", GOOD_SEQUENCE + '[[steps]]\ndo = "wait"\nseconds = inf\n', "seconds"),
    _seq(
        "seq-cycles-negative",
        GOOD_SEQUENCE.replace('name = "s"', 'name = "s"\ncycles = -1'),
        "cycles",
    ),
    _seq(
        "seq-retry-from-unknown",
        GOOD_SEQUENCE + '[[steps]]\ndo = "grip"\nretry_from = "X"\nretries = 1\n',
        "X",
    ),
    _seq("seq-missing", b"", "s.toml")
    if False
    else ("seq-missing", {}, [*HOST, "--sequence", "{dir}/nope.toml"], "nope.toml"),
]

PICKPLACE_CASES = CONFIG_CASES + OPTION_CASES + SEQUENCE_CASES


def _prepare(
    tmp_path: Path, files: dict[str, str | bytes], argv: list[str], port: int
) -> list[str]:
    for name, content in files.items():
        data = content.encode() if isinstance(content, str) else content
        (tmp_path / name).write_bytes(data)
    return [a.replace("{dir}", str(tmp_path)).replace("{port}", str(port)) for a in argv]


def _one_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, f"expected one stderr line, got:\n{err}"
    return lines[0]


Entry = Callable[[list[str]], int]
PICKPLACE_ENTRIES: dict[str, Entry] = {
    "module": lambda argv: pickplace_main.main(argv),
    "console": lambda argv: _cli.main(["pickplace", *argv]),
}


@pytest.mark.parametrize(
    ("files", "argv", "named"),
    [pytest.param(f, a, n, id=i) for i, f, a, n in PICKPLACE_CASES],
)
def test_pickplace_bad_input_is_exit_2_with_one_line(
    files: dict[str, str | bytes],
    argv: list[str],
    named: str,
    tmp_path: Path,
    counter: ConnectionCounter,
    capsys: pytest.CaptureFixture[str],
) -> None:
    args = _prepare(tmp_path, files, argv, counter.port)
    assert pickplace_main.main(args) == 2
    line = _one_line(capsys)
    assert named in line
    assert counter.accepted == 0


# The console script mounts the same options: a sample of the cases through it.
@pytest.mark.parametrize(
    ("files", "argv", "named"),
    [pytest.param(f, a, n, id=i) for i, f, a, n in PICKPLACE_CASES[::6]],
)
def test_console_pickplace_bad_input_is_exit_2(
    files: dict[str, str | bytes],
    argv: list[str],
    named: str,
    tmp_path: Path,
    counter: ConnectionCounter,
    capsys: pytest.CaptureFixture[str],
) -> None:
    args = _prepare(tmp_path, files, argv, counter.port)
    assert _cli.main(["pickplace", *args]) == 2
    assert named in _one_line(capsys)
    assert counter.accepted == 0


SIM_CASES: list[Case] = [
    ("sim-port-70000", {}, ["--port", "70000"], "port"),
    ("sim-port-negative", {}, ["--port", "-1"], "port"),
    (
        "sim-gripper-port-70000",
        {},
        ["--gripper", "onrobot-2fg7", "--gripper-port", "70000"],
        "gripper",
    ),
    ("sim-time-scale-inf", {}, ["--time-scale", "inf"], "time"),
    ("sim-time-scale-nan", {}, ["--time-scale", "nan"], "time"),
    ("sim-time-scale-zero", {}, ["--time-scale", "0"], "time"),
    ("sim-time-scale-negative", {}, ["--time-scale", "-1"], "time"),
    ("sim-tick-hz-nan", {}, ["--tick-hz", "nan"], "tick"),
    ("sim-tick-hz-zero", {}, ["--tick-hz", "0"], "tick"),
    ("sim-tick-hz-inf", {}, ["--tick-hz", "inf"], "tick"),
    ("sim-model", {}, ["--model", "tm7"], "--model"),
    ("sim-profile-unknown", {}, ["--profile", "nope"], "nope"),
    ("sim-profile-binary", {"p.toml": BINARY}, ["--profile", "{dir}/p.toml"], "p.toml"),
    ("sim-profile-not-utf8", {"p.toml": NOT_UTF8}, ["--profile", "{dir}/p.toml"], "p.toml"),
    ("sim-profile-array-table", {"p.toml": "[[1]]\n"}, ["--profile", "{dir}/p.toml"], "p.toml"),
    (
        "sim-profile-remove-fields-int",
        {"p.toml": 'extends = "article"\nremove_fields = 5\n'},
        ["--profile", "{dir}/p.toml"],
        "remove_fields",
    ),
    (
        "sim-profile-fields-int",
        {"p.toml": 'extends = "article"\nfields = 5\n'},
        ["--profile", "{dir}/p.toml"],
        "fields",
    ),
    ("sim-gripper-unknown", {}, ["--gripper", "nope"], "nope"),
    ("sim-gripper-is-robot", {}, ["--gripper", "article"], "article"),
    ("sim-fault-unknown", {}, ["--fault", "bogus"], "bogus"),
    ("sim-fault-nan", {}, ["--fault", "slow_responses:delay_s=nan"], "delay_s"),
    ("sim-fault-bad-key", {}, ["--fault", "slow_responses:nope=1"], "nope"),
    ("sim-unknown-option", {}, ["--speed", "5"], "--speed"),
    ("sim-parts-negative", {}, ["--parts", "-1"], "--parts"),
    # Bounded: a million parts settle in seconds; far more would only eat memory.
    ("sim-parts-too-many", {}, ["--parts", "1000001"], "--parts"),
    ("sim-scene-missing", {}, ["--scene", "{dir}/none.toml"], "none.toml"),
    ("sim-scene-not-toml", {"s.toml": "[table\n"}, ["--scene", "{dir}/s.toml"], "s.toml"),
    ("sim-scene-not-utf8", {"s.toml": NOT_UTF8}, ["--scene", "{dir}/s.toml"], "s.toml"),
    (
        "sim-scene-bad-key",
        {"s.toml": "[table]\ntop_z_mm = 'high'\n"},
        ["--scene", "{dir}/s.toml"],
        "table.top_z_mm",
    ),
    (
        "sim-scene-part-mass",
        {"s.toml": "[[parts]]\nname = 'p'\npose = [0, 0, 0, 0, 0, 0]\nmass_kg = 0\n"},
        ["--scene", "{dir}/s.toml"],
        "parts.0.mass_kg",
    ),
    ("sim-scene-and-parts", {"s.toml": ""}, ["--scene", "{dir}/s.toml", "--parts", "2"], "--parts"),
    ("sim-grasp-unknown", {}, ["--grasp", "glue"], "--grasp"),
    ("sim-dynamics-kinematic", {}, ["--dynamics"], "dynamics"),
]


@pytest.mark.parametrize("console", [False, True], ids=["module", "console"])
@pytest.mark.parametrize(
    ("files", "argv", "named"),
    [pytest.param(f, a, n, id=i) for i, f, a, n in SIM_CASES],
)
def test_sim_bad_input_is_exit_2_with_one_line(
    files: dict[str, str | bytes],
    argv: list[str],
    named: str,
    console: bool,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    args = _prepare(tmp_path, files, argv, 0)
    code = _cli.main(["sim", *args]) if console else sim_main.main(args)
    assert code == 2
    assert named in _one_line(capsys)


TWO_PARTS = [TableObject(name="p", pose=DEFAULT_PART_POSE)] * 2


@pytest.mark.parametrize(
    ("make", "named"),
    [
        pytest.param(lambda: Simulator(time_scale=NAN), "time_scale", id="time-scale-nan"),
        pytest.param(lambda: Simulator(time_scale=INF), "time_scale", id="time-scale-inf"),
        pytest.param(lambda: Simulator(time_scale=0.0), "time_scale", id="time-scale-zero"),
        pytest.param(lambda: Simulator(time_scale=-1.0), "time_scale", id="time-scale-negative"),
        pytest.param(lambda: Timing(tick_hz=NAN), "tick_hz", id="tick-hz-nan"),
        pytest.param(lambda: Listen(port=70000), "port", id="port-70000"),
        pytest.param(lambda: Listen(gripper_port=-1), "gripper_port", id="gripper-port-negative"),
        pytest.param(lambda: Timing(init_time_s=NAN), "init_time_s", id="init-time-nan"),
        pytest.param(
            lambda: Simulator(robot=RobotSetup(initial_seq=40000)),
            "initial_seq",
            id="initial-seq-past-seq-max",
        ),
        pytest.param(
            lambda: Simulator(robot=RobotSetup(initial_seq=-1)),
            "initial_seq",
            id="initial-seq-negative",
        ),
        pytest.param(
            lambda: Simulator("article", robot=RobotSetup(initial_seq=3)),
            "initial_seq",
            id="initial-seq-no-seq",
        ),
        pytest.param(
            lambda: Simulator(cell=Cell(scene=TWO_PARTS)), "duplicate", id="parts-duplicate-name"
        ),
        pytest.param(lambda: RobotSetup(model="tm99"), "unknown robot model", id="model-unknown"),
        pytest.param(lambda: RobotSetup(gripper="nope"), "nope", id="gripper-unknown"),
        pytest.param(lambda: Cell(physics="bullet"), "physics backend", id="physics-unknown"),
        pytest.param(lambda: Cell(speed_factor=0), "speed_factor", id="speed-factor-zero"),
        pytest.param(lambda: Cell(grasp="glue"), "grasp", id="grasp-unknown"),  # type: ignore[arg-type]
        pytest.param(lambda: Cell(dynamics=True), "dynamics", id="dynamics-kinematic"),
        pytest.param(lambda: Cell(scene="nowhere.toml"), "nowhere.toml", id="scene-missing"),
        pytest.param(lambda: Cell(scene=3), "scene", id="scene-not-a-scene"),  # type: ignore[arg-type]
        pytest.param(lambda: Simulator(cell="mujoco"), "cell must be", id="cell-a-name"),  # type: ignore[arg-type]
        pytest.param(lambda: Simulator(robot="tm12"), "robot must be", id="robot-a-name"),  # type: ignore[arg-type]
        pytest.param(lambda: Simulator(timing=50), "timing must be", id="timing-a-number"),  # type: ignore[arg-type]
        pytest.param(lambda: Simulator(listen=5020), "listen must be", id="listen-a-port"),  # type: ignore[arg-type]
    ],
)
def test_simulator_bad_arguments_raise_config_error_naming_them(
    make: Callable[[], object], named: str
) -> None:
    # A TMMasterError (ConfigError, still a ValueError), not a bare ValueError: callers
    # catch the library's errors at one root. Each group is checked when it is made.
    with pytest.raises(ConfigError, match=named):
        make()


# -- robot.io and Simulator.set_di: every argument checked before a byte is sent --------

NAN = float("nan")

# (id, call on robot.io, text the ConfigError must contain)
IO_CASES: list[tuple[str, Callable[[Any], object], str]] = [
    ("do-negative", lambda io: io.set_do(-1, True), "control_box DO -1 does not exist"),
    ("do-16", lambda io: io.set_do(16, True), "module control_box has DO 0-15"),
    ("do-bool-channel", lambda io: io.set_do(True, True), "got True (bool)"),
    ("do-nan-channel", lambda io: io.set_do(NAN, True), "got NaN (float)"),
    ("do-float-channel", lambda io: io.set_do(1.0, True), "got 1.0 (float)"),
    ("do-str-channel", lambda io: io.set_do("3", True), "got '3' (str)"),
    ("do-value-int", lambda io: io.set_do(3, 1), "control_box DO 3: the value must be True"),
    ("do-value-nan", lambda io: io.set_do(3, NAN), "got nan (float)"),
    ("do-value-none", lambda io: io.set_do(3, None), "got None"),
    ("do-value-str", lambda io: io.set_do(3, "on"), "got 'on'"),
    ("end-do-4", lambda io: io.set_do(4, True, module="end_module"), "end_module has DO 0-3"),
    ("end-do-gripper", lambda io: io.set_do(0, True, module="end_module"), "gripper"),
    ("module-unknown", lambda io: io.set_do(1, True, module="tool"), "module 'tool'"),
    ("module-none", lambda io: io.set_do(1, True, module=None), "module None"),
    ("read-do-16", lambda io: io.do(16), "control_box DO 16"),
    ("read-di-negative", lambda io: io.di(-1), "control_box DI -1"),
    ("read-di-16", lambda io: io.di(16), "module control_box has DI 0-15"),
    ("read-end-di-4", lambda io: io.di(4, module="end_module"), "end_module has DI 0-3"),
    ("read-di-bool", lambda io: io.di(False), "got False (bool)"),
    ("read-dis-module", lambda io: io.dis(module="end"), "module 'end'"),
    ("read-dos-module", lambda io: io.dos(module="Control_Box"), "module 'Control_Box'"),
]


@pytest.mark.parametrize(("call", "named"), [pytest.param(c, n, id=i) for i, c, n in IO_CASES])
def test_robot_io_bad_arguments_raise_before_any_connection(
    call: Callable[[Any], object], named: str, counter: ConnectionCounter
) -> None:
    from tmmaster import Robot

    robot = Robot("127.0.0.1", counter.port)  # not connected: a request would connect
    try:
        with pytest.raises(ConfigError, match=re.escape(named)):
            call(robot.io)
    finally:
        robot.close()
    assert counter.accepted == 0


@pytest.mark.parametrize(
    ("kwargs", "named"),
    [
        pytest.param({"channel": 16, "value": True}, "control_box DI 16", id="di-16"),
        pytest.param({"channel": -1, "value": True}, "control_box DI -1", id="di-negative"),
        pytest.param({"channel": True, "value": True}, "(bool)", id="di-bool-channel"),
        pytest.param({"channel": NAN, "value": True}, "NaN", id="di-nan-channel"),
        pytest.param({"channel": 1, "value": 1}, "True or False", id="value-int"),
        pytest.param({"channel": 1, "value": NAN}, "True or False", id="value-nan"),
        pytest.param(
            {"channel": 4, "value": True, "module": "end_module"}, "DI 0-3", id="end-di-4"
        ),
        pytest.param({"channel": 1, "value": True, "module": "box"}, "'box'", id="module"),
    ],
)
def test_simulator_set_di_bad_arguments_raise_config_error(
    kwargs: dict[str, Any], named: str
) -> None:
    sim = Simulator()  # not started (Simulator.start is a tripwire here)
    with pytest.raises(ConfigError, match=re.escape(named)):
        sim.set_di(**kwargs)
    assert sim.do(0) is False  # nothing was driven


# -- moves: joints, relative moves, arcs and speeds checked before a byte is sent --------

INF = float("inf")
READY = [0, 0, 90, 0, 90, 0]
ARC_VIA = Pose(350, -150, 200, 180, 0, 90)
ARC_END = Pose(400, -200, 200, 180, 0, 90)

# (id, call on a Robot, text the ConfigError must contain)
MOVE_CASES: list[tuple[str, Callable[[Any], object], str]] = [
    ("joints-nan", lambda r: r.move_joints([0, 0, 90, 0, NAN, 0]), "J5 must be a finite"),
    ("joints-inf", lambda r: r.move_joints([INF, 0, 90, 0, 90, 0]), "J1 must be a finite"),
    ("joints-none", lambda r: r.move_joints([0, None, 90, 0, 90, 0]), "J2 must be a finite"),
    ("joints-bool", lambda r: r.move_joints([0, 0, True, 0, 90, 0]), "J3 must be a finite"),
    ("joints-str-value", lambda r: r.move_joints([0, 0, "90", 0, 90, 0]), "J3 must be"),
    ("joints-five", lambda r: r.move_joints([0, 0, 90, 0, 90]), "six angles J1..J6 (deg), got 5"),
    ("joints-seven", lambda r: r.move_joints([*READY, 0]), "got 7"),
    ("joints-text", lambda r: r.move_joints("0,0,90,0,90,0"), "a sequence of six angles"),
    ("joints-pose", lambda r: r.move_joints(ARC_END), "a sequence of six angles"),
    ("joints-number", lambda r: r.move_joints(90), "a sequence of six angles"),
    ("joints-limit", lambda r: r.move_joints([300, 0, 90, 0, 90, 0]), "J1 = 300 deg is outside"),
    ("joints-wrist", lambda r: r.move_joints([0, 0, 90, 0, 0, 0]), "wrist singularity"),
    ("joints-elbow", lambda r: r.move_joints([0, 0, 0, 0, 90, 0]), "elbow singularity"),
    ("joints-table", lambda r: r.move_joints([0, 60, 100, 0, 90, 0]), "below the table plane"),
    ("joints-speed-0", lambda r: r.move_joints(READY, speed=0), "speed 0 %"),
    ("joints-speed-float", lambda r: r.move_joints(READY, speed=30.5), "integer percent"),
    ("joints-accel-float", lambda r: r.move_joints(READY, accel_time_ms=1.5), "accel_time_ms"),
    ("joints-accel-big", lambda r: r.move_joints(READY, accel_time_ms=20000), "accel_time"),
    ("joints-accel-negative", lambda r: r.move_joints(READY, accel_time_ms=-1), "accel_time"),
    ("by-frame", lambda r: r.move_by(dz=1, frame="world"), "frame must be 'base' or 'tool'"),
    ("by-frame-none", lambda r: r.move_by(dz=1, frame=None), "got None"),
    ("by-frame-case", lambda r: r.move_by(dz=1, frame="Tool"), "got 'Tool'"),
    ("by-nan", lambda r: r.move_by(dz=NAN), "dz must be a finite number"),
    ("by-inf", lambda r: r.move_by(drx=INF), "drx must be a finite number"),
    ("by-text", lambda r: r.move_by(dx="5"), "dx must be a finite number"),
    ("by-bool", lambda r: r.move_by(dy=True), "dy must be a finite number"),
    ("by-motion", lambda r: r.move_by(dz=1, motion="arc"), "motion must be one of"),
    ("by-both-speeds", lambda r: r.move_by(dz=1, speed=10, speed_mm_s=100), "not both"),
    ("by-ptp-mm-s", lambda r: r.move_by(dz=1, speed_mm_s=100), "a PTP's speed is a percent"),
    ("arc-via-list", lambda r: r.move_arc([350, -150, 200, 180, 0, 90], ARC_END), "via must be"),
    ("arc-to-list", lambda r: r.move_arc(ARC_VIA, [400, -200, 200, 180, 0, 90]), "target must"),
    ("arc-to-below", lambda r: r.move_arc(ARC_VIA, ARC_END.offset(dz=-210)), "table plane"),
    ("arc-via-below", lambda r: r.move_arc(ARC_VIA.offset(dz=-210), ARC_END), "table plane"),
    ("arc-too-fast", lambda r: r.move_arc(ARC_VIA, ARC_END, speed_mm_s=5000), "1..1100 mm/s"),
    ("arc-mm-s-float", lambda r: r.move_arc(ARC_VIA, ARC_END, speed_mm_s=99.5), "integer"),
    ("arc-both-speeds", lambda r: r.move_arc(ARC_VIA, ARC_END, speed=5, speed_mm_s=5), "both"),
    ("line-mm-s-ptp", lambda r: r.move_to(ARC_END, speed_mm_s=100), "a PTP's speed"),
    ("line-mm-s-0", lambda r: r.move_to(ARC_END, motion="line", speed_mm_s=0), "1..1100"),
    ("line-mm-s-bool", lambda r: r.move_to(ARC_END, motion="line", speed_mm_s=True), "integer"),
]


@pytest.mark.parametrize(("call", "named"), [pytest.param(c, n, id=i) for i, c, n in MOVE_CASES])
def test_bad_moves_raise_before_any_connection(
    call: Callable[[Any], object], named: str, counter: ConnectionCounter
) -> None:
    from tmmaster import Robot

    robot = Robot("127.0.0.1", counter.port)  # not connected: a request would connect
    try:
        with pytest.raises(ConfigError, match=re.escape(named)):
            call(robot)
    finally:
        robot.close()
    assert counter.accepted == 0


# -- tmmaster report show|plot: the report file is read bounded, strictly, and checked --


def _valid_report(path: Path, **changes: Any) -> Path:
    from tmmaster.pickplace._report import RunReport, write_report

    data = RunReport(tmmaster_version="0.1.0", result="done", exit_code=0).model_dump(mode="json")
    write_report(path, {**data, **changes})
    return path


def _report_file(kind: str, tmp_path: Path) -> Path:
    """A file that is not a readable run report, of the given kind."""
    import os

    path = tmp_path / "run.json"
    text = _valid_report(tmp_path / "good.json").read_text("utf-8")
    if kind == "latin-1":
        path.write_bytes(text.replace('"done"', '"caf\u00e9"').encode("latin-1"))
    elif kind == "utf-16":
        path.write_bytes(text.encode("utf-16"))
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "directory":
        path.mkdir()
    elif kind == "device":
        return Path("/dev/zero")
    elif kind == "too-big":
        with path.open("wb") as handle:  # sparse: nothing is written
            handle.truncate(256 * 1024 * 1024 + 1)
    elif kind == "version-999":
        _valid_report(path, report_version=999)
    elif kind == "version-0":
        _valid_report(path, report_version=0)
    elif kind == "not-json":
        path.write_text("{", encoding="utf-8")
    return path


REPORT_CASES = [
    ("latin-1", "UTF-8"),
    ("utf-16", "UTF-8"),
    ("fifo", "regular file"),
    ("directory", "regular file"),
    ("device", "regular file"),
    ("too-big", "256 MiB"),
    ("version-999", "report_version 999"),
    ("version-0", "report_version 0"),
    ("not-json", "JSON"),
]


@pytest.mark.parametrize("command", ["show", "plot"])
@pytest.mark.parametrize("console", [False, True], ids=["module", "console"])
@pytest.mark.parametrize(("kind", "named"), REPORT_CASES, ids=[k for k, _ in REPORT_CASES])
def test_report_bad_file_is_exit_2_with_one_line(
    kind: str,
    named: str,
    command: str,
    console: bool,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    pytest.importorskip("matplotlib")  # plot says "install the extra" before reading
    from tmmaster.report import __main__ as report_main

    path = _report_file(kind, tmp_path)
    argv = (
        [command, str(path), "-o", str(tmp_path / "out.png")]
        if command == "plot"
        else [
            command,
            str(path),
        ]
    )
    codes: list[int] = []
    # In a thread: a reader that blocks (a FIFO without a writer) must fail the test,
    # not hang it.
    runner = threading.Thread(
        target=lambda: codes.append(
            _cli.main(["report", *argv]) if console else report_main.main(argv)
        )
    )
    runner.start()
    runner.join(10)
    if runner.is_alive():  # let it go: a writer that closes at once ends its read
        with open(path, "wb"):
            pass
        runner.join(10)
        pytest.fail(f"report {command} blocked on {kind}")
    assert codes == [2]
    line = _one_line(capsys)
    assert named in line
    assert str(path) in line
    assert not (tmp_path / "out.png").exists()


def test_a_valid_report_still_shows(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _valid_report(tmp_path / "run.json")
    assert _cli.main(["report", "show", str(path)]) == 0
    assert "DONE" in capsys.readouterr().out


# -- output that cannot be written: one line and exit 1 (not bad input), or quiet ---------

OUTPUT_COMMANDS = [
    ["schema"],
    ["schema", "--report"],
    ["profile", "show", "tmflow"],
    ["profile", "list"],
]


@pytest.mark.parametrize("argv", OUTPUT_COMMANDS, ids=" ".join)
def test_a_full_stdout_is_one_line_and_exit_1(
    argv: list[str], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    with open("/dev/full", "w", encoding="utf-8") as full:
        monkeypatch.setattr("sys.stdout", full)
        assert _cli.main(argv) == 1
    assert "No space left on device" in _one_line(capsys)


def test_report_show_to_a_full_stdout_is_one_line_and_exit_1(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _valid_report(tmp_path / "run.json")
    with open("/dev/full", "w", encoding="utf-8") as full:
        monkeypatch.setattr("sys.stdout", full)
        assert _cli.main(["report", "show", str(path)]) == 1
    assert "No space left on device" in _one_line(capsys)


def test_a_closed_pipe_ends_quietly_with_exit_141(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import os

    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader went away (``| head``)
    with open(write_end, "w", encoding="utf-8") as pipe:
        monkeypatch.setattr("sys.stdout", pipe)
        assert _cli.main(["schema"]) == 141  # 128 + SIGPIPE, the shell's status
        monkeypatch.undo()
    # Leaving the with block flushed what was left: no second error.
    assert capsys.readouterr().err == ""


def test_schema_to_dev_full_in_a_subprocess_exits_1_with_one_line() -> None:
    # The whole process: its own exit (which flushes stdout again) must stay quiet too.
    import subprocess
    import sys

    with open("/dev/full", "wb") as full:
        done = subprocess.run(
            [sys.executable, "-m", "tmmaster", "schema"],
            stdout=full,
            stderr=subprocess.PIPE,
            text=True,
            timeout=60,
            check=False,
        )
    assert done.returncode == 1
    assert done.stderr.splitlines() == [
        "tmmaster: cannot write the output: No space left on device [exit 1]"
    ]
