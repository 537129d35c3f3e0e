"""``tmmaster robot status|play|pause|stop``: the TMflow project's state and its buttons.

``add_arguments(parser)`` fills the subcommand's parser and ``run(args)`` runs it: one
connection, one action, one answer on stdout, and an exit status:

===  ====================================================================
0    done (``status``: read; ``play``: running; ``pause``: paused or stopped;
     ``stop``: the arm at rest)
2    bad options (checked before anything is sent), or a profile without a TMflow
     project (article: play/pause)
3    the connection failed
4    the robot refused: in error or e-stop, Manual mode, or the project did not
     change (``stop``: the arm still moved) within ``--timeout``, or (``stop``) the
     project still runs once the arm is at rest: the Stop never reached it
===  ====================================================================
"""

from __future__ import annotations

import argparse
import sys

from ._address import check_host
from ._checks import require_positive
from ._cliparse import one_line, write_stdout
from ._exceptions import ConfigError, RobotError, TMMasterError, TransportError
from ._logging import add_logging_arguments, configure_logging
from ._profiles import DEFAULT_PROFILE, builtin_profile_names
from ._project import PRESS_TIMEOUT_S
from ._robot import Robot
from ._status import ProjectState, RobotStatus

#: The actions, in the order ``--help`` lists them.
ACTIONS = ("status", "play", "pause", "stop")

EXIT_CONFIG, EXIT_CONNECTION, EXIT_REFUSED = 2, 3, 4
#: The exit status of a failure, by its class (the first that matches; else refused).
_EXIT_CODES = ((ConfigError, EXIT_CONFIG), (TransportError, EXIT_CONNECTION))


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the ``robot`` subcommand's arguments to ``parser``; return it.

    Args:
        parser: The subcommand's parser.

    Returns:
        ``parser``.
    """
    robots = [n for n in builtin_profile_names() if n in ("article", "tmflow")]
    parser.add_argument(
        "action",
        choices=ACTIONS,
        help="status: the project's state and the robot's; play: press Play on a stopped or"
        " paused project; pause: press Pause on a running one; stop: press Stop",
    )
    parser.add_argument("--host", required=True, help="robot address (or sim://NAME)")
    parser.add_argument("--port", type=int, default=502, help="robot Modbus TCP port (502)")
    parser.add_argument(
        "--profile",
        default=DEFAULT_PROFILE,
        metavar="NAME|FILE.toml",
        help=f"robot profile: {' or '.join(robots)}, or a TOML file (default: {DEFAULT_PROFILE})",
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=PRESS_TIMEOUT_S,
        metavar="S",
        help="play/pause: seconds to wait for the project's new state; stop: for the arm"
        f" to come to rest (default: {PRESS_TIMEOUT_S:g})",
    )
    add_logging_arguments(parser, default_level="warning")
    return parser


def _status_lines(status: RobotStatus, moving: bool) -> str:
    # An e-stop the profile does not report (article: an error code) is not "released".
    estop = "PRESSED" if status.estop else "released" if "estop" in status.raw else "unknown"
    lines = [
        f"project  {status.project or 'none (this profile has no TMflow project)'}",
        f"mode     {status.mode}",
        f"moving   {'yes' if moving else 'no'}",
        f"error    {status.error_code if status.error else 'none'}",
        f"e-stop   {estop}",
        f"ready    {'yes' if status.ready else 'no'}",
        f"pose     {status.pose}",
    ]
    return "".join(f"{line}\n" for line in lines)


def _act(robot: Robot, action: str, timeout_s: float) -> str:
    """Run ``action`` on a connected ``robot``; what to print."""
    if action in ("play", "pause"):
        return f"project  {(robot.play if action == 'play' else robot.pause)(timeout_s)}\n"
    if action == "stop":
        robot.stop()
        robot.wait_until_at_rest(timeout_s)  # not robot.status().moving: tmflow's is the program's
        # Read back: a Stop answered and never delivered (a gateway) leaves the project
        # running, to take the next move; it shows stopped long before 0.5 s of rest.
        if (project := robot.status().project) in (ProjectState.RUNNING, ProjectState.PAUSED):
            raise RobotError(f"the arm is at rest, the project still {project}: Stop never landed")
        return "stop     pressed; the arm is at rest\n"
    # tmflow's status().moving is the robot program's state, idle as soon as the project
    # stops while the arm still brakes: Techman's Joint Speed (7949-7960) shows the arm.
    status = robot.status()
    return _status_lines(status, status.moving or robot._joints_turning())


def run(args: argparse.Namespace) -> int:
    """Run ``tmmaster robot ACTION`` from parsed ``args``; the exit status.

    Args:
        args: The parsed options.

    Returns:
        0, or the status of the module's table.
    """
    undo_logging = configure_logging(json=args.log_json, level=args.log_level, stream=sys.stderr)
    try:
        require_positive("--timeout", args.timeout)  # before the first byte, as --host
        host = check_host(args.host, field="--host", port_field="--port")
        with Robot(host, args.port, profile=args.profile) as robot:
            text = _act(robot, args.action, args.timeout)
    except TMMasterError as exc:
        code = next((c for kind, c in _EXIT_CODES if isinstance(exc, kind)), EXIT_REFUSED)
        print(f"tmmaster robot {args.action}: {one_line(exc)} [exit {code}]", file=sys.stderr)
        return code
    finally:
        undo_logging()
    return write_stdout(text, prog="tmmaster robot")
