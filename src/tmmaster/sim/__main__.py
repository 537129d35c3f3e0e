"""``python -m tmmaster.sim``: run the simulator until Ctrl-C or SIGTERM.

``tmmaster sim`` mounts the same options: ``add_arguments(parser)`` fills a parser and
``run(args)`` runs the simulator from the parsed namespace.
"""

from __future__ import annotations

import _thread
import argparse
import os
import signal
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from types import FrameType
from typing import Any

from .._address import check_host
from .._cliparse import ArgumentParser, did_you_mean, one_line, run_command
from .._exceptions import ConfigError, TMMasterError, TMScriptError
from .._logging import add_logging_arguments, configure_logging
from .._pose import Pose
from .._profiles import DEFAULT_PROFILE, builtin_profile_names
from .._robot_models import ROBOT_MODELS
from .._version import add_version_argument
from ._backend import PhysicsUnavailableError
from ._options import Cell, Listen, RobotSetup, Timing
from ._server import RequestRecord, json_line
from ._simulator import Simulator, simulator_summary
from ._world import DEFAULT_PART_POSE, TableObject

#: Most parts ``--parts`` puts on the table: as many as ``--cycles`` of pick & place runs.
MAX_PARTS = 1_000_000

#: After SIGINT or SIGTERM the process ends within this many seconds, closed cleanly or not.
STOP_WITHIN_S = 5.0


#: The options in the order ``--help`` lists them (each concern's are defined below).
_HELP_ORDER = (
    "--profile",
    "--port",
    "--bind",
    "--time-scale",
    "--speed-factor",
    "--tick-hz",
    "--model",
    "--physics",
    "--mjcf",
    "--snapshot",
    "--tool",
    "--gripper",
    "--gripper-port",
    "--fault",
    "--program",
    "--resume-after-error",
    "--trace-requests",
    "--parts",
    "--scene",
    "--dynamics",
    "--grasp",
)


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the simulator's options to ``parser`` (used by ``tmmaster sim``); return it."""
    options = {
        **_network_options(),
        **_robot_options(),
        **_physics_options(),
        **_fault_options(),
        **_program_options(),
        **_output_options(),
    }
    # ValueError for an option missing from _HELP_ORDER: none is left out of --help.
    for flag in sorted(options, key=_HELP_ORDER.index):
        parser.add_argument(flag, **options[flag])
    add_logging_arguments(
        parser,
        default_level="info",
        level_help="level of the simulator's events on stderr (logger tmmaster.sim; default: info)",
    )
    add_version_argument(parser)
    return parser


def _network_options() -> dict[str, dict[str, Any]]:
    """Where the robot and the gripper listen: ``--bind``, ``--port``, ``--gripper-port``."""
    return {
        "--port": {
            "type": int,
            "default": 5020,
            "help": "robot Modbus TCP port; 0 picks a free one (default: 5020)",
        },
        "--bind": {
            "default": "127.0.0.1",
            "metavar": "ADDRESS",
            "help": "address to listen on (default: 127.0.0.1; Modbus has no authentication,"
            " so think twice before 0.0.0.0)",
        },
        "--gripper-port": {
            "type": int,
            "default": 5021,
            "metavar": "N",
            "help": "gripper Modbus TCP port; 0 picks a free one (default: 5021)",
        },
    }


def _robot_options() -> dict[str, dict[str, Any]]:
    """What is simulated: ``--profile``, ``--model``, ``--tool``, ``--gripper``."""
    robots = [n for n in builtin_profile_names() if n in ("article", "tmflow")]
    grippers = [n for n in builtin_profile_names() if n not in robots]
    return {
        "--profile": {
            "default": DEFAULT_PROFILE,
            "metavar": "NAME|FILE.toml",
            "help": f"robot profile: {' or '.join(robots)}, or a TOML file"
            f" (default: {DEFAULT_PROFILE})",
        },
        "--model": {
            "default": "tm5-700",
            "choices": sorted(ROBOT_MODELS),
            "help": "arm model whose reach and speed limits time the motions (default: tm5-700)",
        },
        "--tool": {
            "default": None,
            "metavar": "X,Y,Z,RX,RY,RZ",
            "help": "TCP offset in the flange frame, mm and deg (TCP = flange x tool;"
            " default: none, the TCP is the flange)",
        },
        "--gripper": {
            "default": None,
            "metavar": "NAME|FILE.toml",
            "help": f"separate gripper device: {' or '.join(grippers)}, or a TOML file"
            " (default: none; the article profile has its gripper in the robot map)",
        },
    }


def _physics_options() -> dict[str, dict[str, Any]]:
    """How the cell moves: the clock, the backend, the table's parts, the grasp."""
    return {
        "--time-scale": {
            "type": float,
            "default": 1.0,
            "metavar": "X",
            "help": "simulated seconds per wall second (default: 1.0)",
        },
        "--speed-factor": {
            "type": float,
            "default": 1.0,
            "metavar": "K",
            "help": "the arm moves K times faster than the arm model the master plans with"
            " (0.1..10, default: 1; for testing a master against a robot it does not predict)",
        },
        "--tick-hz": {
            "type": float,
            "default": 50.0,
            "metavar": "HZ",
            "help": "control tick rate in wall Hz (default: 50, like the TM controller)",
        },
        "--physics": {
            "default": "kinematic",
            "choices": ["kinematic", "mujoco"],
            "help": "physics backend: kinematic (analytic, default) or mujoco (needs the extra"
            " tmmaster[mujoco]; docs/physics-backends.md)",
        },
        **_cell_options(),
    }


def _cell_options() -> dict[str, dict[str, Any]]:
    """The physics of the cell: ``--parts``, ``--scene``, ``--dynamics``, ``--grasp``."""
    return {
        "--parts": {
            "type": int,
            "default": None,
            "metavar": "N",
            "help": "parts waiting at the pick position, like a feeder: the next one is there"
            f" after one is taken (default: 1; 0 for an empty table; at most {MAX_PARTS:,};"
            " not with --scene)",
        },
        "--scene": {
            "default": None,
            "metavar": "FILE.toml",
            "help": "the cell from a TOML scene file: table height, fixtures the arm must not"
            " touch, parts, gripper geometry (docs/simulator.md#scene-files)",
        },
        "--dynamics": {
            "action": argparse.BooleanOptionalAction,
            "default": None,
            "help": "with --physics mujoco: the links carry Techman's masses and inertias and"
            " each joint is a servo limited to its effort (the arm lags; a move is done once it"
            " settled); --no-dynamics: the ideal servo, the joints exactly where the trajectory"
            " says (default: on for tm5-700 and tm5-900, off for the other models)",
        },
        "--grasp": {
            "default": "friction",
            "choices": ["friction", "weld"],
            "help": "how the fingers hold a part: friction (a part too heavy for the grip force"
            " slips out, default) or weld (carried whatever its mass)",
        },
    }


def _fault_options() -> dict[str, dict[str, Any]]:
    """Faults armed from the start: ``--fault``."""
    return {
        "--fault": {
            "action": "append",
            "default": [],
            "metavar": "SPEC",
            "help": 'inject a fault, e.g. "slow_responses:delay_s=0.2" (repeatable;'
            " see docs/simulator.md)",
        },
    }


def _program_options() -> dict[str, dict[str, Any]]:
    """The robot's own program (tmflow): ``--program``, ``--resume-after-error``."""
    return {
        "--program": {
            "metavar": "FILE|generated",
            "help": "tmflow: run this TMflow Script Project on the robot through the TMscript"
            " interpreter ('generated': the one tmmaster robot-program writes)",
        },
        "--resume-after-error": {
            "choices": ("on", "off"),
            "default": "off",
            "help": "tmflow: TMflow's Resumption Behavior; on: an e-stop pauses the project and"
            " Play resumes the interrupted move (default: off)",
        },
    }


def _output_options() -> dict[str, dict[str, Any]]:
    """What is written besides serving: ``--mjcf``, ``--snapshot``, ``--trace-requests``."""
    return {
        "--mjcf": {
            "default": None,
            "metavar": "FILE",
            "help": "with --physics mujoco: write the MuJoCo scene this simulator would run (the"
            " arm, gripper, table and parts, as MJCF) to FILE and exit, without serving",
        },
        "--snapshot": {
            "default": None,
            "metavar": "FILE.png",
            "help": "with --physics mujoco: render the cell this simulator would start with"
            " (the arm, gripper, table, fixtures and parts; --scene) to FILE.png and exit,"
            " without serving (needs OpenGL: the extra tmmaster[mujoco-render];"
            " MUJOCO_GL=egl headless)",
        },
        "--trace-requests": {
            "action": "store_true",
            "help": "print every Modbus request the simulator receives as one JSON line on stdout",
        },
    }


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``python -m tmmaster.sim``."""
    parser = ArgumentParser(
        prog="python -m tmmaster.sim",
        description="Simulated TM robot (and gripper) served over Modbus TCP.",
    )
    return add_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Run the simulator described by parsed ``args`` until SIGINT/SIGTERM; return 0."""

    def echo(record: RequestRecord) -> None:
        print(json_line(record), flush=True)

    undo_logging = configure_logging(json=args.log_json, level=args.log_level, stream=sys.stderr)
    try:
        return _serve(args, echo)
    finally:
        undo_logging()


def _scene(count: int | None, scene: str | None) -> str | list[TableObject]:
    """The ``--scene`` file, or the ``--parts`` feeder (one part by default)."""
    if scene is not None:
        if count is not None:
            raise ConfigError("--parts: give the parts in the --scene file, not both")
        return scene
    count = 1 if count is None else count
    if not 0 <= count <= MAX_PARTS:
        raise ConfigError(f"--parts must be 0..{MAX_PARTS:,}, got {count}")
    return [TableObject(name=f"part-{i}", pose=DEFAULT_PART_POSE) for i in range(1, count + 1)]


def _tool(text: str | None) -> Pose | None:
    """The ``--tool`` pose, or None; a bad value raises ConfigError naming --tool."""
    if text is None:
        return None
    try:
        return Pose.parse(text)
    except ConfigError as exc:
        raise ConfigError(f"--tool X,Y,Z,RX,RY,RZ: {exc} (got {text!r})") from exc


def _check_names(args: argparse.Namespace) -> None:
    """A profile, gripper or fault kind not among the known ones, with the closest one.

    Raises:
        ConfigError: ``--gripper onrobot: no such gripper profile; the gripper profiles
            are blog-2fg7, onrobot-2fg7 (or a FILE.toml); did you mean onrobot-2fg7?``
    """
    from ._faults import FAULT_KINDS

    robots = [n for n in builtin_profile_names() if n in ("article", "tmflow")]
    grippers = [n for n in builtin_profile_names() if n not in robots]
    for option, value, names, what in (
        ("--profile", args.profile, robots, "robot profile"),
        ("--gripper", args.gripper, grippers, "gripper profile"),
    ):
        if value is None or value in names or value.endswith(".toml") or Path(value).exists():
            continue
        raise ConfigError(
            f"{option} {value}: no such {what}; the {what}s are {', '.join(names)}"
            f" (or a FILE.toml){did_you_mean(value, names)}"
        )
    for fault in args.fault:
        kind = str(fault).split(":", 1)[0].strip()
        if kind and kind not in FAULT_KINDS:
            raise ConfigError(
                f"--fault {fault}: unknown kind {kind!r} (known: {', '.join(FAULT_KINDS)})"
                f"{did_you_mean(kind, FAULT_KINDS)}"
            )


def _serve(args: argparse.Namespace, echo: Callable[[RequestRecord], None]) -> int:
    """Build the simulator of ``args``, then write its scene or serve it; the exit code."""
    for option, value in (("--mjcf", args.mjcf), ("--snapshot", args.snapshot)):
        if value is not None and args.physics != "mujoco":
            print(f"sim: {option} needs --physics mujoco [exit 2]", file=sys.stderr)
            return 2
    if args.snapshot is not None:
        # Headless rendering: EGL, read by mujoco when it is first imported (below).
        os.environ.setdefault("MUJOCO_GL", "egl")
    sim = _build(args, echo)
    if isinstance(sim, int):
        return sim
    if args.mjcf is not None or args.snapshot is not None:
        return _write_scene(sim, args.mjcf, args.snapshot)
    signals = _Signals()
    try:
        try:
            sim.start()
        except OSError as exc:
            print(f"sim: {exc} [exit 1]", file=sys.stderr)
            return 1
        _print_banner(sim, args.fault)
        _wait(sim, signals)
    finally:
        sim.close()
        signals.restore()
    print("simulator stopped", flush=True)
    return 0


def _build(args: argparse.Namespace, echo: Callable[[RequestRecord], None]) -> Simulator | int:
    """The simulator ``args`` describe (not started), or the exit code of a refusal."""
    try:
        _check_names(args)
        return Simulator(
            args.profile,
            time_scale=args.time_scale,
            # An address alone (a port goes in --port): said as the option, exit 2.
            listen=Listen(
                host=check_host(args.bind, field="--bind", port_field="--port"),
                port=args.port,
                gripper_port=args.gripper_port,
            ),
            robot=RobotSetup(
                model=args.model,
                gripper=args.gripper,
                program=args.program,
                resume_after_error=args.resume_after_error == "on",
            ),
            cell=Cell(
                scene=_scene(args.parts, args.scene),
                physics=args.physics,
                tool=_tool(args.tool),
                grasp=args.grasp,
                dynamics=args.dynamics,
                speed_factor=args.speed_factor,
            ),
            timing=Timing(tick_hz=args.tick_hz),
            faults=args.fault,
            request_listener=echo if args.trace_requests else None,
        )
    except PhysicsUnavailableError as exc:  # an optional extra is missing: say which
        print(f"sim: {one_line(exc)} [exit 1]", file=sys.stderr)
        return 1
    except TMScriptError as exc:  # the --program file: said as a compiler says it
        where = f"{args.program}:{exc.line}:{exc.column}" if args.program else "program"
        print(f"sim: {where}: {one_line(exc.reason)} [exit 2]", file=sys.stderr)
        return 2
    except (TMMasterError, ValueError, KeyError) as exc:
        print(f"sim: {one_line(exc)} [exit 2]", file=sys.stderr)
        return 2


def _print_banner(sim: Simulator, faults: Sequence[str]) -> None:
    """What runs where, the armed faults, and how to stop it (the simulator has started)."""
    for line in simulator_summary(sim):
        print(line, flush=True)
    for fault in faults:
        print(f"fault   armed: {fault}", flush=True)
    print(
        f"press Ctrl-C to stop; kill -USR1 {os.getpid()} resets a robot error or e-stop",
        flush=True,
    )
    if sim.profile.has("play_pause"):
        # Printed once start() returned: the project runs, a master may connect now.
        print(
            "project running; after a stop or a reset: tmmaster robot play"
            f" --host {sim.host} --port {sim.port}",
            flush=True,
        )


def _wait(sim: Simulator, signals: _Signals) -> None:
    """Serve until SIGINT or SIGTERM; a SIGUSR1 resets the robot's error meanwhile."""
    # Short sleeps keep the main thread responsive to signals.
    while not signals.stopping:
        time.sleep(0.05)
        if signals.reset_asked:
            signals.reset_asked = False
            sim.clear_error()
            print("robot error reset (SIGUSR1)", flush=True)


class _Signals:
    """SIGINT and SIGTERM stop the simulator, SIGUSR1 resets a robot error (installed now).

    The stop always ends the process: a second SIGINT/SIGTERM ends it at once, and a
    simulator that has not closed :data:`STOP_WITHIN_S` after the first is left behind
    (exit 1, one line on stderr) rather than ignoring the signal. The handler takes no
    lock (it sets plain flags, which the main thread polls, and starts the watchdog with
    ``_thread``): a lock taken there could be one the interrupted main thread holds.
    """

    def __init__(self) -> None:
        self.stopping = False
        self.reset_asked = False
        self._closed = False
        self._previous = {
            sig: signal.signal(sig, self._on_signal)
            for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1)
        }

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        _ = frame
        if signum == signal.SIGUSR1:
            # The operator's reset on the pendant: clear the error, keep running.
            self.reset_asked = True
            return
        if self.stopping:
            _exit_now(f"{signal.Signals(signum).name} while stopping: exited without closing")
        self.stopping = True
        _thread.start_new_thread(self._watch, ())

    def _watch(self) -> None:
        """The watchdog: the process ends if the simulator has not closed in time."""
        time.sleep(STOP_WITHIN_S)
        if not self._closed:
            _exit_now(f"the simulator did not close within {STOP_WITHIN_S:g} s of the signal")

    def restore(self) -> None:
        """The simulator closed: the watchdog stands down, the previous handlers are back."""
        self._closed = True
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)


def _exit_now(reason: str) -> None:
    """End the process at once (exit 1) with one line on stderr."""
    os.write(2, f"sim: {reason} [exit 1]\n".encode())
    os._exit(1)


def _write_scene(sim: Simulator, mjcf: str | None, snapshot: str | None) -> int:
    """Write ``sim``'s MuJoCo scene (MJCF) and/or its picture (never started); the exit code."""
    # Imported here: mujoco is loaded already (the backend was built with it).
    from ._mujoco import MuJoCoBackend

    try:
        backend = sim.backend
        assert isinstance(backend, MuJoCoBackend)  # --physics mujoco
        option = "--mjcf"
        try:
            if mjcf is not None:
                Path(mjcf).write_text(backend.mjcf, encoding="utf-8")
                print(f"mjcf    written to {mjcf}", flush=True)
            option = "--snapshot"
            if snapshot is not None:
                backend.snapshot(Path(snapshot))
                print(f"picture written to {snapshot}", flush=True)
        except OSError as exc:
            print(f"sim: {option}: {one_line(exc)} [exit 1]", file=sys.stderr)
            return 1
        except ImportError as exc:  # PyOpenGL missing, or no EGL / OSMesa library
            print(
                "sim: --snapshot: offscreen rendering needs OpenGL: pip install"
                f" 'tmmaster[mujoco-render]' and set MUJOCO_GL=egl ({one_line(exc)}) [exit 1]",
                file=sys.stderr,
            )
            return 1
    finally:
        sim.close()
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m tmmaster.sim``."""
    return run_command("sim", build_parser, run, argv)


if __name__ == "__main__":
    sys.exit(main())
