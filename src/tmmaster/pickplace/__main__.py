"""``python -m tmmaster.pickplace``: run the article's pick & place (or any sequence).

``tmmaster pickplace`` mounts the same options: :func:`add_arguments` fills a parser,
:func:`run` runs from the parsed namespace and returns the exit code.

Exit codes (also in docs/pickplace.md; a closed stdout, as ``| head`` leaves, turns a 0
into 141 and changes nothing else: the run goes on and --report is written):

===  ===========================================================================
0    every cycle done (with --sim: and every part on the place position)
1    any other failure (unexpected error; a move refused once the run began commanding;
     with --sim: a part not on the place position)
2    invalid configuration or options: nothing was sent to the robot
3    connection failure (cannot connect, or the link was lost for good)
4    robot fault: robot error, e-stop, command rejected or in an unknown state
5    grasp failure (no object after every retry) or another gripper failure
6    timeout (motion, acknowledgement, gripper, robot not ready)
130  interrupted (Ctrl-C, SIGTERM, SIGHUP): the arm was stopped, report written
===  ===========================================================================
"""

from __future__ import annotations

import argparse
import errno
import itertools
import logging
import math
import os
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO, cast

from .._cliparse import (
    EXIT_BROKEN_PIPE,
    ArgumentParser,
    UsageError,
    did_you_mean,
    discard_stdout,
    run_command,
)
from .._exceptions import (
    ConfigError,
    ConnectRefusedError,
    EmergencyStopError,
    GripperError,
    HostNotFoundError,
    MotionTimeoutError,
    NotModbusError,
    ProfileMismatchError,
    RobotError,
    RobotFaultError,
    TransportError,
)
from .._logging import add_logging_arguments, configure_command_logging, get_logger
from .._pose import Pose
from .._profiles import DEFAULT_PROFILE, builtin_profile_names, load_profile
from .._registers import RobotProfile
from .._robot import Robot
from .._sigint import first_stops
from .._tm_errors import code_hex, describe
from .._transport import endpoint_text
from .._version import add_version_argument
from ._config import PickPlaceConfig, load_config, robot_from_config
from ._machine import IDLE, mermaid
from ._plan import CyclePlan, estimate, format_plan, validate_plan
from ._runner import Runner, RunResult, StateEvent, StopRequestedError
from ._sequences import load_sequence, pick_and_place
from ._steps import TaskSequence

if TYPE_CHECKING:  # rich loads only when a terminal shows the live display
    from rich.console import Console

    from ..sim._scene import Scene  # the simulator loads only with --sim
    from ._live import LiveProgress
    from ._report import RunReport

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_CONFIG = 2
EXIT_CONNECTION = 3
EXIT_ROBOT_FAULT = 4
EXIT_GRASP = 5
EXIT_TIMEOUT = 6
EXIT_INTERRUPTED = 130

#: Exit code -> result name in the report.
RESULT_NAMES = {
    EXIT_OK: "done",
    EXIT_FAILED: "failed",
    EXIT_CONFIG: "config_error",
    EXIT_CONNECTION: "connection_error",
    EXIT_ROBOT_FAULT: "robot_fault",
    EXIT_GRASP: "grasp_failed",
    EXIT_TIMEOUT: "timeout",
    EXIT_INTERRUPTED: "interrupted",
}

#: A write to stdout or stderr failed because nobody reads it any more: a closed pipe
#: (``| head``), a terminal hung up (an SSH session lost).
_READER_GONE = frozenset({errno.EPIPE, errno.EIO})

#: How far (mm) a part may be from the place pose to count as placed (--sim check).
PLACE_TOLERANCE_MM = 2.0

_log = get_logger("tmmaster.pickplace")


def exit_code_for(exc: BaseException) -> int:
    """The exit code a failure maps to (see the module docstring)."""
    if isinstance(exc, StopRequestedError | KeyboardInterrupt):
        return EXIT_INTERRUPTED
    if isinstance(exc, ConfigError):
        return EXIT_CONFIG
    # Before the timeouts: a response timeout is a link problem, not a slow robot.
    if isinstance(exc, TransportError):
        return EXIT_CONNECTION
    if isinstance(exc, MotionTimeoutError | TimeoutError):
        return EXIT_TIMEOUT
    if isinstance(exc, GripperError):
        return EXIT_GRASP
    if isinstance(exc, RobotError):
        return EXIT_ROBOT_FAULT
    return EXIT_FAILED


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the pick & place options to ``parser`` (used by ``tmmaster pickplace``); return it."""
    _add_robot_arguments(parser)
    _add_sim_arguments(parser)
    parser.add_argument(
        "--dry-run",
        action="store_true",
        help="validate and print the plan (poses, speeds, motion types, expected times);"
        " connect to nothing",
    )
    parser.add_argument(
        "--diagram", action="store_true", help="print the state machine as a mermaid diagram"
    )
    add_logging_arguments(
        parser,
        level_help="level of the events logged on stderr (default: warning; info with -v or"
        " --log-json)",
    )
    parser.add_argument(
        "--verbose",
        "-v",
        action="count",
        default=0,
        help="log the run's events on stderr (info; -vv: debug), above the live display on a"
        " terminal",
    )
    parser.add_argument(
        "--quiet",
        "-q",
        action="store_true",
        help="print only errors and the final one-line result",
    )
    add_version_argument(parser)
    parser.add_argument("--report", metavar="FILE.json", help="write a JSON run report")
    return parser


def _add_robot_arguments(parser: argparse.ArgumentParser) -> None:
    """The robot, the files and the run: --host to --poll-interval."""
    robots = [n for n in builtin_profile_names() if n in ("article", "tmflow")]
    parser.add_argument("--host", help="robot address (required unless --sim/--dry-run/--diagram)")
    parser.add_argument("--port", type=int, default=None, help="robot Modbus TCP port (502)")
    parser.add_argument(
        "--profile",
        default=None,
        metavar="NAME|FILE.toml",
        help=f"register contract: {' or '.join(robots)} or a TOML file (default:"
        f" {DEFAULT_PROFILE}, the one a real TM robot running the tmmaster TMflow program"
        " speaks; article: the article's map, for its simulator only)",
    )
    parser.add_argument("--config", metavar="FILE.toml", help="configuration file")
    parser.add_argument(
        "--sequence",
        metavar="FILE.toml",
        help="run a sequence described in TOML instead of the built-in pick & place",
    )
    parser.add_argument("--cycles", type=int, default=None, metavar="N", help="cycles to run")
    parser.add_argument(
        "--poll-interval", type=float, default=None, metavar="S", help="poll interval (0.05 s)"
    )
    parser.add_argument(
        "--release-held-part",
        action="store_const",
        const=True,
        default=None,
        help="a part the gripper holds at the start is released where the arm is (it falls"
        " there); without it such a run refuses to start, exit 2"
        " ([gripper] release_held_part_at_start)",
    )


def _add_sim_arguments(parser: argparse.ArgumentParser) -> None:
    """The embedded simulator: --sim and its options."""
    parser.add_argument(
        "--sim",
        action="store_true",
        help="start the built-in simulator on a free loopback port and run against it",
    )
    parser.add_argument(
        "--sim-time-scale",
        type=float,
        default=None,
        metavar="X",
        help="with --sim: simulated seconds per wall second (default 1.0; 10 for a quick demo)",
    )
    parser.add_argument(
        "--sim-physics",
        default=None,
        choices=["kinematic", "mujoco"],
        help="with --sim: physics backend (default kinematic; mujoco needs the extra"
        " tmmaster[mujoco] and models the arm's dynamics for the tm5-700 and tm5-900)",
    )
    parser.add_argument(
        "--sim-scene",
        metavar="FILE.toml",
        default=None,
        help="with --sim: the simulated cell from a scene file (table height, fixtures, parts,"
        " gripper; docs/simulator.md#scene-files); parts at the pick pose are the run's"
        " (none there: one per cycle is added)",
    )
    parser.add_argument(
        "--snapshot",
        metavar="DIR",
        default=None,
        help="with --sim --sim-physics mujoco: render the cell at the end to DIR/cell-end.png"
        " (needs OpenGL: MUJOCO_GL=egl and PyOpenGL, extra tmmaster[mujoco-render])",
    )


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``python -m tmmaster.pickplace``."""
    parser = ArgumentParser(
        prog="python -m tmmaster.pickplace",
        description="Pick & place on a TM robot over Modbus TCP (the article's cycle by default).",
        epilog="exit codes: 0 done, 1 other failure, 2 config error, 3 connection failure,"
        " 4 robot fault / e-stop, 5 grasp failure, 6 timeout, 130 interrupted",
    )
    return add_arguments(parser)


class _Outcome:
    """What the report needs, filled in as far as the run got."""

    def __init__(self) -> None:
        self.config_file: str | None = None
        self.config: PickPlaceConfig | None = None
        self.run: RunResult | None = None
        self.target: dict[str, Any] | None = None
        self.transport: dict[str, Any] | None = None
        self.sim: dict[str, Any] | None = None
        self.move_states: list[str] = []
        self.expected_cycle_s: float | None = None
        #: The one-line result of a successful run (printed last).
        self.done_line: str | None = None


#: Events the command's last line says again, in its own words (the reason it failed
#: or stopped): printed only when events were asked for.
_SAID_BY_THE_LAST_LINE = frozenset({"pickplace.failed", "pickplace.interrupted"})


class _Output:
    """Where the command's own lines go: plain, quiet, or a rich live display on a terminal.

    ``events``: the events were asked for (``-v``, ``--log-level``, ``--log-json``): every
    one is logged, and a Ctrl-C does not cut the output short. Otherwise the log shows
    warnings and errors, less what the last line says itself, and after a Ctrl-C only
    errors: the command ends with its one line.
    """

    def __init__(
        self,
        *,
        quiet: bool,
        live: LiveProgress | None = None,
        console: Console | None = None,
        events: bool = False,
    ) -> None:
        self.quiet = quiet
        self.live = live
        self.console = console
        self.events = events
        #: Set by the first Ctrl-C.
        self.interrupted = False
        #: Set when stdout's reader went away (``| head``): the run goes on, quietly.
        self.stdout_gone = False
        #: What the log handler lets through (None: everything at the level).
        self.log_filter: logging.Filter | None = None if events else _LogFilter(self)

    def info(self, line: str) -> None:
        """A line about the run as it goes, on stdout: on a terminal, or with -v."""
        if not self.quiet and (self.events or self.live is not None) and not self.interrupted:
            self.say(line)

    def result(self, line: str) -> None:
        """A line of the run's result on stdout (not with --quiet, nor after a Ctrl-C)."""
        if not self.quiet and (self.events or not self.interrupted):
            self.say(line)

    def say(self, line: str) -> None:
        """``line`` on stdout, flushed; once its reader went away (``| head``), nothing.

        After a closed pipe stdout points at the null device (:func:`discard_stdout`):
        later lines go nowhere, quietly, and the run carries on (it still writes its
        report) and ends with :func:`ended_quietly`'s status.
        """
        if self.stdout_gone:
            return
        try:
            print(line, flush=True)
        except OSError as exc:
            if exc.errno not in _READER_GONE:
                raise
            discard_stdout()
            self.stdout_gone = True

    def interrupt(self) -> None:
        """The first Ctrl-C: from now on the command says only how it ended (safe in a
        signal handler: it sets a flag)."""
        self.interrupted = True

    @property
    def progress(self) -> Callable[[StateEvent], None] | None:
        """The runner's on_state listener, or None."""
        return self.live


class _LogFilter(logging.Filter):
    """The log records :class:`_Output` shows when no events were asked for."""

    def __init__(self, out: _Output) -> None:
        super().__init__()
        self._out = out

    def filter(self, record: logging.LogRecord) -> bool:
        """False for an event the last line repeats, and below ERROR after a Ctrl-C."""
        event = record.msg.get("event") if isinstance(record.msg, dict) else None
        if event in _SAID_BY_THE_LAST_LINE:
            return False
        return not self._out.interrupted or record.levelno >= logging.ERROR


def _make_output(options: _OutputOptions, stderr: TextIO) -> _Output:
    events = bool(options.verbose or options.log_level or options.log_json)
    if options.quiet or options.log_json or not stderr.isatty():
        return _Output(quiet=options.quiet, events=events)
    try:
        from rich.console import Console

        from ._live import LiveProgress
    except ImportError:  # pragma: no cover - rich is a dependency; a stripped install
        return _Output(quiet=False, events=events)  # plain lines, as when piped
    console = Console(file=stderr)
    return _Output(quiet=False, live=LiveProgress(console), console=console, events=events)


def _log_level(options: _OutputOptions) -> str:
    """Warnings and errors by default, on a terminal or not; the events with -v (or JSON)."""
    if options.quiet:
        return "error"
    if options.log_level:
        return options.log_level
    if options.verbose >= 2:
        return "debug"
    return "info" if options.verbose or options.log_json else "warning"


def run(args: argparse.Namespace, *, output: _Output | None = None) -> int:
    """Run pick & place from parsed ``args``; returns the exit code (never raises).

    ``args`` stops here: :func:`_resolve` turns it into one frozen :class:`_Invocation`
    (the validated :class:`PickPlaceConfig` in a :class:`_Command`, and the output
    options), and everything after reads that.
    """
    stderr = sys.stderr
    outcome = _Outcome()
    invocation = _resolve(args, outcome)
    out = output if output is not None else _make_output(invocation.output, stderr)
    # The live display's stream has what a logging handler uses: write, flush, isatty.
    log_stream = cast("TextIO", out.live.log_stream) if out.live is not None else stderr
    undo_logging = configure_command_logging(
        json=invocation.output.log_json,
        level=_log_level(invocation.output),
        stream=log_stream,
        record_filter=out.log_filter,
    )
    try:
        return _run(invocation, outcome, out)
    finally:
        if out.live is not None:
            out.live.end()
        undo_logging()  # in-process callers (tests, tmmaster's CLI) get their logging back


def _one_line(text: str) -> str:
    return " ".join(text.split())


def _ended(invocation: _Invocation, outcome: _Outcome, out: _Output) -> tuple[int, str | None]:
    """Run the command; its exit code and, for any end but success, the reason."""
    try:
        return _execute(invocation.command, outcome, out)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED, "interrupted"
    except UsageError as exc:  # an option that cannot be: said as the option
        return EXIT_CONFIG, str(exc)
    except ConfigError as exc:
        return EXIT_CONFIG, f"config error: {exc}"
    except ImportError as exc:  # an optional extra (--sim-physics mujoco) is missing: say which
        return EXIT_FAILED, str(exc)
    except Exception as exc:  # the last line of defence: one line, never a traceback
        _log.error("pickplace.unexpected_error", error=str(exc), error_type=type(exc).__name__)
        return exit_code_for(exc), f"{type(exc).__name__}: {exc}"


def _run(invocation: _Invocation, outcome: _Outcome, out: _Output) -> int:
    # Here, not at the top: building the report's models costs some 60 ms that --help,
    # --version and a wrong option do not need; a run loads them before it connects.
    from ._report import build_run_report

    stderr = sys.stderr
    code, reason = _ended(invocation, outcome, out)
    if out.live is not None:
        out.live.end()
    report = build_run_report(
        exit_code=code,
        result_name=RESULT_NAMES.get(code, "failed"),
        reason=reason,
        run=outcome.run,
        config_file=outcome.config_file,
        config_digest=None if outcome.config is None else outcome.config.digest(),
        target=outcome.target,
        transport=outcome.transport,
        sim=outcome.sim,
        move_states=outcome.move_states,
    )
    try:
        _tell(out, outcome, report, (code, reason), stderr)
    except OSError as exc:  # nobody reads any more: the report is still written
        if exc.errno not in _READER_GONE:
            raise
    if invocation.output.report and not _written(invocation.output.report, report, stderr):
        return code or EXIT_FAILED
    # The report says how the run ended; the status also says the output was cut short.
    return EXIT_BROKEN_PIPE if code == EXIT_OK and out.stdout_gone else code


def _tell(
    out: _Output,
    outcome: _Outcome,
    report: RunReport,
    ended: tuple[int, str | None],
    stderr: TextIO,
) -> None:
    """The run's end on the terminal: the summary, then the last line (why, or done)."""
    code, reason = ended
    if code == EXIT_INTERRUPTED:
        out.interrupt()  # a second Ctrl-C, or one before the run: its last line only
    shown = out.events or not out.interrupted
    if out.console is not None and outcome.run is not None and not out.quiet and shown:
        _print_summary(out.console, report)
    if reason is not None:
        print(f"pickplace: {_one_line(reason)} [exit {code}]", file=stderr, flush=True)
    elif outcome.done_line is not None:
        out.say(outcome.done_line)


def _written(path: str, report: RunReport, stderr: TextIO) -> bool:
    """Write the run report to ``path``; False (said on stderr) when it cannot be."""
    from ._report import write_report

    try:
        write_report(path, report)
    except OSError as exc:
        print(f"pickplace: cannot write the report {path}: {exc}", file=stderr)
        return False
    return True


def _print_summary(console: Console, report: RunReport) -> None:
    from ._summary import summary_renderable

    console.print(summary_renderable(report))


#: The options that set a configuration key, and the key (section, name). They are
#: applied once, by :func:`_overrides` in :func:`_command`, to the one validated
#: :class:`PickPlaceConfig` that everything downstream reads.
_CONFIG_OPTIONS: dict[str, tuple[str, str]] = {
    "host": ("robot", "host"),
    "port": ("robot", "port"),
    "profile": ("robot", "profile"),
    "cycles": ("run", "cycles"),
    "poll_interval": ("run", "poll_interval_s"),
    "release_held_part": ("gripper", "release_held_part_at_start"),
}
#: The options that say what to run (the files, the mode, the simulator): read once, by
#: :func:`_command`, into the :class:`_Command`.
_COMMAND_OPTIONS = frozenset(
    {
        "config",
        "sequence",
        "dry_run",
        "diagram",
        "sim",
        "sim_time_scale",
        "sim_physics",
        "sim_scene",
        "snapshot",
    }
)
#: The options that only shape the output: the only ones read after :func:`_command`
#: (by :func:`_resolve`, into the :class:`_OutputOptions`).
_OUTPUT_OPTIONS = frozenset({"log_json", "log_level", "quiet", "report", "verbose"})


@dataclass(frozen=True)
class _OutputOptions:
    """How the command speaks, and where its report goes."""

    quiet: bool
    verbose: int
    log_level: str | None
    log_json: bool
    #: The JSON run report to write (--report), or None.
    report: str | None


@dataclass(frozen=True)
class _SimOptions:
    """With --sim: how the embedded simulator runs."""

    time_scale: float
    physics: str
    #: Folder for the end-of-run picture (--snapshot), or None.
    snapshot: str | None
    #: The cell (--sim-scene), loaded and validated, or None: the built-in one.
    scene: Scene | None = None


@dataclass(frozen=True)
class _Command:
    """What the command runs, read from the arguments once and validated."""

    #: The configuration with the command-line options applied: the one every part reads.
    config: PickPlaceConfig
    sequence: TaskSequence
    cycles: int
    #: What a plan error names: the sequence file, the config file or the defaults.
    source: str
    #: The TOML sequence run instead of pick & place, or None.
    sequence_file: str | None
    dry_run: bool
    diagram: bool
    #: The simulator to start and run against (--sim), or None.
    sim: _SimOptions | None


@dataclass(frozen=True)
class _Invocation:
    """The command line, resolved once: what to run (or why it cannot) and the output."""

    #: What to run; or the error that reading the options and files raised, which the
    #: run reports (exit code, last line, report) as it would one of its own.
    command: _Command | BaseException
    output: _OutputOptions


def _resolve(args: argparse.Namespace, outcome: _Outcome) -> _Invocation:
    """The one place ``args`` is read: the options become a frozen :class:`_Invocation`.

    Args:
        args: The parsed command line (:func:`add_arguments`'s options).
        outcome: Filled with the configuration file and the configuration, for the
            report, as far as reading them got.

    Returns:
        The invocation; nothing after this reads ``args``.
    """
    command: _Command | BaseException
    try:
        command = _command(args, outcome)
    except (KeyboardInterrupt, Exception) as exc:  # reported by the run, with the report
        command = exc
    report: str | None = args.report
    if report is not None:
        try:
            _check_report_option(report)
        except UsageError as exc:
            report = None  # it cannot be written: one line says why the run did not start
            if isinstance(command, _Command):
                command = exc
    output = _OutputOptions(
        quiet=bool(args.quiet),
        verbose=int(args.verbose or 0),
        log_level=None if args.log_level is None else str(args.log_level),
        log_json=bool(args.log_json),
        report=report,
    )
    return _Invocation(command, output)


def _check_report_option(path: str) -> None:
    """``--report``: a file whose folder can be written, checked before anything is sent
    (the report is written at the end, after the arm moved).

    Raises:
        UsageError: ``--report out: is a folder; give a FILE.json`` and the like.
    """
    target = Path(path)
    if target.is_dir():
        raise UsageError(f"--report {path}: is a folder; give a FILE.json")
    folder = target.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent  # the report's folder is made: the nearest one that exists
    if not folder.is_dir():
        raise UsageError(f"--report {path}: {folder} is not a folder")
    try:
        if folder != target.parent:
            if not os.access(folder, os.W_OK | os.X_OK):
                raise PermissionError(errno.EACCES, os.strerror(errno.EACCES))
        else:  # the folder is there: try what the report's write will do
            fd, probe = tempfile.mkstemp(prefix=".report-", suffix=".json", dir=folder)
            os.close(fd)
            os.unlink(probe)
    except OSError as exc:
        raise UsageError(f"--report {path}: cannot be written in {folder}: {exc.strerror}") from exc


def _overrides(args: argparse.Namespace) -> dict[str, dict[str, Any]]:
    """The configuration keys the command line sets (section -> key -> value)."""
    overrides: dict[str, dict[str, Any]] = {}
    for option, (section, key) in _CONFIG_OPTIONS.items():
        value = getattr(args, option)
        if value is not None:
            overrides.setdefault(section, {})[key] = value
    return overrides


def _robot_profile_names() -> list[str]:
    """The built-in robot profiles (the others are grippers')."""
    return [n for n in builtin_profile_names() if isinstance(load_profile(n), RobotProfile)]


def _check_profile_option(value: str) -> None:
    """``--profile``: a built-in robot profile, or a FILE.toml (which load_config reads)."""
    if value.endswith(".toml"):
        return
    robots = _robot_profile_names()
    if value in robots:
        return
    what = "a gripper profile" if value in builtin_profile_names() else "no such profile"
    raise UsageError(
        f"--profile {value}: {what}; the robot profiles are {', '.join(robots)}"
        f" (or a profile FILE.toml){did_you_mean(value, robots)}"
    )


def _check_option_ranges(overrides: dict[str, dict[str, Any]]) -> None:
    """A number option outside its key's range, said as the option (``--port 70000``).

    The bounds are the configuration model's own (the file's key takes the same).

    Raises:
        UsageError: ``--port 70000: must be 1..65535``.
    """
    for option, (section, key) in _CONFIG_OPTIONS.items():
        value = overrides.get(section, {}).get(key)
        if isinstance(value, bool) or not isinstance(value, int | float):
            continue  # a switch (--release-held-part) has no range
        low, high = _key_bounds(section, key)
        inside = (low is None or value >= low) and (high is None or value <= high)
        if not inside:  # nan included: no comparison holds for it
            flag = "--" + option.replace("_", "-")
            bound = (
                f"{_number(low)}..{_number(high)}"
                if low is not None and high is not None
                else (f">= {_number(low)}" if low is not None else f"<= {_number(high)}")
            )
            raise UsageError(f"{flag} {_number(value)}: must be {bound}")


def _key_bounds(section: str, key: str) -> tuple[float | None, float | None]:
    """The configuration model's bounds of ``section.key``: (ge, le), None where unbounded."""
    model = PickPlaceConfig.model_fields[section].annotation
    assert model is not None
    metadata = model.model_fields[key].metadata
    low = next((getattr(m, "ge", None) for m in metadata if hasattr(m, "ge")), None)
    high = next((getattr(m, "le", None) for m in metadata if hasattr(m, "le")), None)
    return low, high


def _number(value: float | None) -> str:
    """A bound or a value as a user writes it: 65535, 1000000, 0.005."""
    assert value is not None
    return str(int(value)) if float(value).is_integer() else f"{value:g}"


def _check_sim_options(sim: bool, overrides: dict[str, dict[str, Any]]) -> None:
    """--sim runs on a simulator of its own: a robot address with it would be ignored."""
    given = [f"--{key}" for key in ("host", "port") if key in overrides.get("robot", {})]
    if sim and given:
        raise UsageError(
            f"{' and '.join(given)} cannot be used with --sim, which runs on its own"
            " simulator on a free loopback port (drop --sim to run on the robot)"
        )


def _command(args: argparse.Namespace, outcome: _Outcome) -> _Command:
    """Read every option but the output ones, once: nothing downstream reads ``args``.

    The configuration options are applied to the file (or the defaults) in one step,
    :func:`load_config`, which validates the result; the robot, the runner, the
    simulator, the plan and the report all read that one :class:`PickPlaceConfig`.
    """
    config_file, sequence_file = args.config, args.sequence
    sim = _simulator_options(args)
    outcome.config_file = config_file
    overrides = _overrides(args)
    _check_option_ranges(overrides)
    _check_sim_options(sim is not None, overrides)
    profile = overrides.get("robot", {}).get("profile")
    if profile is not None:
        _check_profile_option(profile)
    config = load_config(config_file, overrides=overrides)
    outcome.config = config
    sequence, cycles, source = _sequence_of(config, sequence_file, config_file, overrides)
    command = _Command(
        config=config,
        sequence=sequence,
        cycles=cycles,
        source=source,
        sequence_file=sequence_file,
        dry_run=args.dry_run,
        diagram=args.diagram,
        sim=sim,
    )
    if command.diagram:  # draws the machine only: no robot, no simulator
        return command
    if config.robot.host is None and not (sim or command.dry_run):
        raise ConfigError("--host is required (or --sim, --dry-run, --diagram)")
    return command


def _simulator_options(args: argparse.Namespace) -> _SimOptions | None:
    """The embedded simulator's options with --sim; without it, none may be given."""
    on_sim, scene_file = bool(args.sim), args.sim_scene
    if scene_file is not None and not on_sim:
        raise UsageError("--sim-scene needs --sim (a robot's cell is the robot's)")
    time_scale, physics, snapshot = args.sim_time_scale, args.sim_physics, args.snapshot
    simulated = {"--sim-time-scale": time_scale, "--sim-physics": physics, "--snapshot": snapshot}
    stray = [flag for flag, value in simulated.items() if value is not None]
    if stray and not on_sim:  # never a silent no-op on a robot
        raise UsageError(f"{stray[0]} needs --sim (it shapes the embedded simulator only)")
    time_scale = 1.0 if time_scale is None else time_scale
    if not (math.isfinite(time_scale) and time_scale > 0):
        raise ConfigError(f"--sim-time-scale must be a finite number > 0, got {time_scale}")
    if not on_sim:
        return None
    return _sim_options(time_scale, physics or "kinematic", snapshot, scene_file)


def _sequence_of(
    config: PickPlaceConfig,
    sequence_file: str | None,
    config_file: str | None,
    overrides: dict[str, dict[str, Any]],
) -> tuple[TaskSequence, int, str]:
    """The sequence to run, its cycles and where it comes from (a TOML file, or the
    configuration's pick & place)."""
    if not sequence_file:
        return pick_and_place(config), config.run.cycles, config_file or "the default configuration"
    sequence = load_sequence(sequence_file)
    # --cycles (run.cycles) counts for a TOML sequence too; without it, its own count.
    given = "cycles" in overrides.get("run", {})
    return sequence, config.run.cycles if given else sequence.default_cycles, sequence_file


def _configured_robot(config: PickPlaceConfig) -> Robot:
    """The robot the configuration names, not connected; it checks the plan, and runs it
    unless --sim. Without a host (--dry-run, --sim) it stands on the loopback, unused."""
    if config.robot.host is None:
        return robot_from_config(config, "127.0.0.1")
    return robot_from_config(config)


def _execute(
    command: _Command | BaseException, outcome: _Outcome, out: _Output
) -> tuple[int, str | None]:
    # 1. Every option was read and validated (by _resolve) before anything connects.
    if isinstance(command, BaseException):
        raise command
    config, sequence, cycles = command.config, command.sequence, command.cycles
    if command.diagram:
        out.say(mermaid(sequence, cycles=cycles))
        return EXIT_OK, None
    # 2. Every move of the run is checked on the configured robot, still sending nothing.
    robot = _configured_robot(config)
    keep = False
    try:
        validate_plan(robot, sequence, cycles, source=command.source)
        outcome.move_states = CyclePlan(sequence, cycles).states()
        home = config.poses.resolved()["home"]
        planned = estimate(sequence, 1, robot.model, start=home)
        outcome.expected_cycle_s = sum(m.expected_s for m in planned) or None
        if command.dry_run:
            out.say(
                format_plan(
                    sequence,
                    cycles,
                    robot.model,
                    start=home,
                    profile=robot.profile.name,
                    tool=robot.tool,
                )
            )
            return EXIT_OK, None
        keep = command.sim is None  # with --sim, the robot is the simulator's
    finally:
        if not keep:
            robot.close()
    # 3. Run: on the simulator (--sim), or on the robot just checked.
    if command.sim is not None:
        return _run_with_sim(command, outcome, out)
    assert config.robot.host is not None
    return _run_on(command, robot, (config.robot.host, config.robot.port), outcome, out)


def _at(pose: Pose, pick: Pose) -> bool:
    """Whether a part at ``pose`` waits at the pick pose (its x-y within the tolerance)."""
    return math.hypot(pose.x - pick.x, pose.y - pick.y) <= PLACE_TOLERANCE_MM


def _sim_scene(scene: Scene | None, pick: Pose, cycles: int) -> tuple[Scene, set[str]]:
    """The simulated cell: the scene given (or the built-in one) with the run's parts.

    The parts a scene puts at the pick pose wait there like a feeder's, which hands them
    out in order: the first ``cycles`` are the run's (a scene with fewer runs out, as a
    real feeder would). A scene with none there (and the built-in cell) gets one part per
    cycle at the pick pose.

    Returns:
        The scene, and the names of the run's parts.
    """
    from ..sim import Scene, TableObject

    scene = Scene() if scene is None else scene
    waiting = [p.name for p in scene.parts if _at(p.pose, pick)]
    if not waiting:
        taken = {p.name for p in scene.parts}
        names = (f"part-{i}" for i in itertools.count(1) if f"part-{i}" not in taken)
        feeder = [TableObject(name=next(names), pose=pick) for _ in range(cycles)]
        scene = scene.model_copy(update={"parts": (*scene.parts, *feeder)})
        waiting = [p.name for p in feeder]
    return scene, set(waiting[:cycles])


def _sim_options(
    time_scale: float, physics: str, snapshot: str | None, scene_file: str | None
) -> _SimOptions:
    """With --sim: the embedded simulator's options (the simulator loads here, when asked)."""
    from ..sim import load_scene

    sim = _SimOptions(
        time_scale, physics, snapshot, None if scene_file is None else load_scene(scene_file)
    )
    if sim.physics == "mujoco":
        from ..sim._mujoco import require_mujoco

        if sim.snapshot is not None:
            # Headless rendering: EGL, read by mujoco when it is first imported.
            os.environ.setdefault("MUJOCO_GL", "egl")

        require_mujoco()  # a missing extra is said first, in one line
    return sim


def _run_with_sim(command: _Command, outcome: _Outcome, out: _Output) -> tuple[int, str | None]:
    from ..sim import Cell, RobotSetup, Simulator

    options, config = command.sim, command.config
    assert options is not None
    if options.snapshot is not None and options.physics != "mujoco":
        raise ConfigError("--snapshot needs --sim-physics mujoco")
    poses = config.poses.resolved()
    scene, run_parts = _sim_scene(options.scene, poses["pick"], command.cycles)
    sim = Simulator(
        config.robot_profile(),
        time_scale=options.time_scale,
        robot=RobotSetup(model=config.robot.model, gripper=config.gripper_profile()),
        cell=Cell(scene=scene, physics=options.physics),
    )
    with sim:
        # MuJoCo models the arm's dynamics where it can (the simulator's default): said.
        physics = (
            f", {sim.physics} physics, arm dynamics {'on' if sim.dynamics else 'off'}"
            if sim.physics == "mujoco"
            else ""
        )
        out.info(
            f"simulator: {config.robot.profile} profile on {sim.host}:{sim.port}"
            f" (time scale {options.time_scale:g}{physics}), {len(run_parts)} part(s) at the"
            " pick pose"
        )
        floor = config.workspace.floor_z_mm
        if options.scene is not None and floor != scene.table.top_z_mm:
            # The master plans with [workspace]; the scene is what the robot meets.
            _log.warning(
                "pickplace.scene_table_differs",
                scene_table_top_z_mm=scene.table.top_z_mm,
                workspace_floor_z_mm=floor,
            )
        if outcome.expected_cycle_s is not None:  # the plan is in simulated seconds
            outcome.expected_cycle_s /= options.time_scale
        sampler = _TcpSampler(sim.tcp_pose)
        robot = robot_from_config(
            config,
            sim.host,
            sim.port,
            gripper_port=sim.gripper_port,
            # Simulated time runs faster: so does a gripper's settle time.
            settle_scale=options.time_scale,
        )
        code, reason = _run_on(command, robot, (sim.host, sim.port), outcome, out, sampler=sampler)
        from ._report import objects_report

        place = poses["place"] if command.sequence_file is None else None
        outcome.sim = objects_report(sim.objects(), place, PLACE_TOLERANCE_MM, run_parts)
        outcome.sim["pick"] = None if place is None else poses["pick"].as_list()
        outcome.sim["time_scale"] = options.time_scale
        outcome.sim["physics"] = options.physics
        outcome.sim["tcp_path"] = sampler.rows()
    if options.snapshot is not None:
        from ..sim._mujoco import save_snapshot

        out.result(f"simulator: snapshot {save_snapshot(sim, options.snapshot)}")
    if place is not None and not _parts_placed(outcome.sim, out) and code == EXIT_OK:
        return EXIT_FAILED, "the run ended DONE but a part is not on the place position"
    return code, reason


def _parts_placed(sim_report: dict[str, Any], out: _Output) -> bool:
    """Say where each part ended; whether every run part is on the place position."""
    for item in sim_report["objects"]:
        pose = ", ".join(f"{v:g}" for v in item["pose"][:3])
        if not item["run_part"]:  # a scene's other part: where it is, nothing asked
            out.info(f"simulator: {item['name']} rests on {item['resting_on']} ({pose})")
            continue
        where = "on the place position" if item["on_place"] else "NOT on the place position"
        out.result(f"simulator: {item['name']} is {where} ({pose})")
    unlisted = sim_report["objects_total"] - len(sim_report["objects"])
    if unlisted:  # a long run: one part per cycle, only some listed
        on = sim_report["objects_on_place"] - sum(i["on_place"] for i in sim_report["objects"])
        out.result(
            f"simulator: {unlisted} more part(s) not listed: {on} on the place position,"
            f" {unlisted - on} not"
        )
    return bool(sim_report["on_place"])


def _close(robot: Robot, outcome: _Outcome) -> None:
    """Close ``robot``: a stop the run could not deliver that close() delivered counts
    (not a close confirmed with nothing to stop: a move that had finished by itself)."""
    robot.close()
    run, motion = outcome.run, robot.last_motion
    if run is not None and run.stop_delivered is False and motion and motion.stop_delivered:
        run.stop_delivered = True


def _run_on(
    command: _Command,
    robot: Robot,
    address: tuple[str, int],
    outcome: _Outcome,
    out: _Output,
    *,
    sampler: _TcpSampler | None = None,
) -> tuple[int, str | None]:
    """Connect ``robot`` (at ``address``: the configured robot's or the simulator's),
    run the command's sequence on it and close it."""
    sequence, cycles = command.sequence, command.cycles
    host, port = address
    outcome.target = {"host": host, "port": port, "profile": robot.profile.name}
    runner = Runner.from_config(robot, command.config, on_state=out.progress)

    # The first Ctrl-C stops the run (the arm is stopped, the report written); a second
    # one gives up at once. Each marks the output interrupted first (only the last line)
    # and the run stopping: no next state starts before the stop's thread has run.
    def noted() -> None:  # in the signal handler: flags only
        out.interrupt()
        runner.note_stop()

    with first_stops(runner.request_stop, noted=noted):
        if out.live is not None:
            out.live.begin(cycles, outcome.expected_cycle_s, [step.name for step in sequence.steps])
        try:
            refused = _connect(robot, host, port) or _speaks_the_profile(robot)
            if refused is not None:
                return refused
            if sampler is not None:
                sampler.start()
            try:  # kept at once: a second Ctrl-C in the sampler's join keeps the record
                result = outcome.run = runner.run(sequence, cycles=cycles, source=command.source)
            finally:
                if sampler is not None:
                    # The runner's clock: timeline and TCP path share one time axis.
                    sampler.stop(origin=runner.run_started)
        finally:
            # The robot first: a second Ctrl-C's KeyboardInterrupt (one at most) landing
            # here skips what follows it, and the display is ended again after the run.
            _close(robot, outcome)
            outcome.transport = {"robot": robot.stats.as_dict(), "gripper": _gripper_stats(robot)}
            if out.live is not None:
                out.live.end()
    if result.ok:
        shown = result.cycle_times_s
        times = ", ".join(f"{t:.2f}" for t in (shown if len(shown) <= 20 else shown[:10]))
        if len(shown) > 20:  # a long run: the first and the latest, not a line per cycle
            more = result.cycles_completed - 20
            times += f", ... {more} more ..., " + ", ".join(f"{t:.2f}" for t in shown[-10:])
        outcome.done_line = (
            f"DONE: {result.cycles_completed}/{cycles} cycle(s) of {sequence.name} in"
            f" {result.duration_s:.2f} s (cycle times: {times} s;"
            f" {result.retries} grasp retr{'y' if result.retries == 1 else 'ies'})"
        )
        return EXIT_OK, None
    return _failed(result)


def _speaks_the_profile(robot: Robot) -> tuple[int, str] | None:
    """Whether the connected robot speaks the configured profile (one status read).

    The run's moves are checked once more from where the arm is by the runner itself,
    before its first command (``Runner.run``): the plan was checked from the home pose
    before connecting, and the robot's reported pose and joints may make a move one the
    arm cannot take (another configuration, a self-collision on its path). That refusal
    fails the run in IDLE: exit 2, nothing sent but reads.

    Returns:
        None, or the exit code and reason of a robot that speaks another profile (its
        first status read tells: the article profile's connect reads nothing).
    """
    try:
        robot.status()
    except ProfileMismatchError as exc:
        return EXIT_CONFIG, _mismatch_reason(exc)
    return None


def _connect(robot: Robot, host: str, port: int) -> tuple[int, str] | None:
    """Connect ``robot``; None, or the exit code and reason it could not."""
    try:
        robot.connect()
    except ProfileMismatchError as exc:
        return EXIT_CONFIG, _mismatch_reason(exc)
    except (ConnectRefusedError, HostNotFoundError, NotModbusError) as exc:
        return EXIT_CONNECTION, str(exc)  # says what happened, naming the address
    except TransportError as exc:
        return EXIT_CONNECTION, _unreachable(host, port, exc)
    except StopRequestedError:
        return EXIT_INTERRUPTED, f"interrupted while connecting to {host}:{port}"
    return None


def _code_suffix(code: int | None, message: str) -> str:
    """What a one-line report adds for a robot's error code, unless the message names it.

    Args:
        code: The robot's error code (None or 0: none).
        message: The error's message (a RobotFaultError's already names its code).

    Returns:
        ``" (robot error 0x0022 Force or Torque Over Range)"``, or ``""``.
    """
    if not code or code_hex(code) in message:
        return ""
    return f" (robot error {describe(code)})"


def _failed(result: RunResult) -> tuple[int, str]:
    """The exit code and reason of a run that did not end DONE."""
    failure = result.failure
    assert failure is not None
    if isinstance(failure.exception, ProfileMismatchError):
        return EXIT_CONFIG, _mismatch_reason(failure.exception)
    code = exit_code_for(failure.exception)
    if code == EXIT_CONFIG and failure.state != IDLE:
        # Refused once the run had begun commanding the robot (the gripper opened, moves
        # made): exit 2 says nothing was sent, which is no longer true.
        code = EXIT_FAILED
    if failure.interrupted:
        stopped = {
            True: "the arm was stopped",
            False: "the stop could NOT be delivered (check the robot)",
            None: "this profile has no stop command",
        }[result.stop_delivered]
        return code, f"interrupted in {failure.state} (cycle {failure.cycle}); {stopped}"
    label = RESULT_NAMES[code].replace("_", " ")
    if isinstance(failure.exception, RobotFaultError | EmergencyStopError):  # TM's codes
        code_text = _code_suffix(failure.error_code, failure.message)
    else:
        code_text = f" (robot error code {failure.error_code})" if failure.error_code else ""
    reaction = ""
    if result.reaction is not None and result.reaction.reaction == "retreat":
        reaction = "; retreated" if result.reaction.performed else "; did not retreat"
    if result.stop_delivered is False:  # a move given up whose stop the link never carried
        reaction += "; the stop could NOT be delivered: the arm may still move (check the robot)"
    return code, (
        f"{label} in {failure.state} (cycle {failure.cycle}): {failure.type}:"
        f" {failure.message}{code_text}{reaction}"
    )


def _unreachable(host: str, port: int, exc: TransportError) -> str:
    """Why the robot could not be reached, naming its address once.

    An error that already names the address (a listener that accepted and never
    answered) is said in its own words; any other is prefixed with it.
    """
    where = endpoint_text(host, port)
    text = str(exc)
    return text if where in text else f"robot at {where} unreachable: {text}"


def _mismatch_reason(exc: ProfileMismatchError) -> str:
    """The robot speaks another profile: nothing was commanded, the option is wrong."""
    return f"wrong profile: {exc}; run with --profile {exc.device_profile}"


class _TcpSampler:
    """With --sim: the TCP seen by the simulator, sampled in the background while the run runs."""

    #: Wall seconds between samples (the simulator's default tick is 50 Hz).
    INTERVAL_S = 0.02
    #: A row only when the TCP moved this far (mm) since the last row.
    MIN_STEP_MM = 0.5
    #: Enough for an hour at full rate; the report stays bounded.
    MAX_ROWS = 200_000

    def __init__(self, read_pose: Callable[[], Any]) -> None:
        self._read = read_pose
        self._rows: list[tuple[float, float, float, float]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="tcp-sampler", daemon=True)
        self._origin: float | None = None

    def start(self) -> None:
        """Start sampling."""
        self._thread.start()

    def stop(self, origin: float | None) -> None:
        """Stop sampling; ``origin`` (monotonic seconds) is time 0 of the rows."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self._origin = origin

    def _loop(self) -> None:
        last: tuple[float, float, float] | None = None
        while len(self._rows) < self.MAX_ROWS:
            now = time.monotonic()
            try:
                pose = self._read()
            except Exception:  # the simulator is closing: the path ends here
                return
            here = (pose.x, pose.y, pose.z)
            if last is None or math.dist(here, last) >= self.MIN_STEP_MM:
                self._rows.append((now, *here))
                last = here
            if self._stop.wait(self.INTERVAL_S):
                return

    def rows(self) -> list[list[float]]:
        """``[t_s, x, y, z]`` rows, ``t_s`` from the origin given to :meth:`stop`."""
        origin = (
            self._origin if self._origin is not None else (self._rows[0][0] if self._rows else 0.0)
        )
        return [
            [round(t - origin, 3), round(x, 2), round(y, 2), round(z, 2)]
            for t, x, y, z in self._rows
        ]


def _gripper_stats(robot: Robot) -> dict[str, Any] | None:
    transport = robot.gripper.transport
    return None if transport is None else dict(transport.stats.as_dict())


def main(argv: Sequence[str] | list[str] | None = None) -> int:
    """Entry point of ``python -m tmmaster.pickplace`` (``argv`` None: the process's own).

    Bad options are one line and exit 2; Ctrl-C, at any moment, one line and exit 130
    (:func:`tmmaster._sigint.run_main`).
    """
    return run_command("pickplace", build_parser, run, argv)


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["add_arguments", "build_parser", "exit_code_for", "main", "run"]
