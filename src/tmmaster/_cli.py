"""The ``tmmaster`` command: ``sim``, ``pickplace``, ``report``, ``tmscript``, ``robot``,
``profile``, ``schema`` and ``robot-program``.

Each command's options are added to its parser, and its module imported, only when that
command runs: ``tmmaster robot status`` never loads the simulator.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ._cliparse import (
    ArgumentParser,
    UsageError,
    did_you_mean,
    one_line,
    output_failed,
    run_command,
    write_stdout,
)
from ._exceptions import TMMasterError
from ._logging import LOG_LEVELS, add_logging_arguments, configure_logging
from ._profiles import builtin_profile_names, load_profile, profile_markdown
from ._sigint import run_main
from ._version import add_version_argument

#: The commands, in the order the help lists them: their one-line help, and the module
#: whose ``add_arguments(parser)`` and ``run(args)`` make them (None: this module's own).
COMMANDS: dict[str, tuple[str, str | None]] = {
    "sim": ("run the robot simulator (a Modbus TCP server)", "tmmaster.sim.__main__"),
    "pickplace": ("run a configurable pick & place", "tmmaster.pickplace.__main__"),
    "report": ("show a run report as a table, or plot it", "tmmaster.report.__main__"),
    "tmscript": ("check, evaluate or run TMscript (Script Projects)", "tmmaster.tmscript.__main__"),
    "robot": (
        "read the TMflow project's state, or press Play, Pause or Stop",
        "tmmaster._robot_cli",
    ),
    "profile": ("list or show register profiles", None),
    "schema": ("print the JSON Schema of the pick & place config (or of the run report)", None),
    "robot-program": (
        "write the TMflow Script Project the robot runs for a sequence profile (tmflow)",
        "tmmaster._robot_program",
    ),
}


class _CommandParser(ArgumentParser):
    """A command's parser, filled with its options only when the command is chosen
    (parsed) or its help is shown: the top-level help needs only the one-line help."""

    def __init__(
        self, *args: Any, fill: Callable[[ArgumentParser], object] | None = None, **kwargs: Any
    ) -> None:
        # Without fill: a command's own sub-commands (``profile list``), made by argparse.
        super().__init__(*args, **kwargs)
        self._fill: Callable[[ArgumentParser], object] | None = fill

    def filled(self) -> _CommandParser:
        """This parser, with the command's options added (once)."""
        fill, self._fill = self._fill, None
        if fill is not None:
            fill(self)
        return self

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        """Fill the parser, then parse (argparse calls this for the chosen command)."""
        return super(_CommandParser, self.filled()).parse_known_args(args, namespace)

    def format_help(self) -> str:
        """Fill the parser, then format its help."""
        return super(_CommandParser, self.filled()).format_help()


def _module(name: str) -> Any:
    """The module that makes the command ``name`` (imported now)."""
    module = COMMANDS[name][1]
    assert module is not None
    return importlib.import_module(module)


def _fill_command(name: str, parser: ArgumentParser) -> None:
    """Add the options of the command ``name`` to its ``parser``."""
    if name == "profile":
        _add_profile_commands(parser)
    elif name == "schema":
        parser.add_argument(
            "--report", action="store_true", help="the run report's schema instead of the config's"
        )
        parser.add_argument("--output", "-o", metavar="FILE.json", help="write to a file instead")
        add_logging_arguments(parser, default_level="warning")
    else:
        _module(name).add_arguments(parser)


def _add_profile_commands(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="profile_command", required=True, metavar="{list,show}")
    listing = sub.add_parser("list", help="list the built-in profiles")
    add_logging_arguments(listing, default_level="warning")
    show = sub.add_parser("show", help="print a profile as a Markdown table")
    show.add_argument("profile", help="a built-in profile name or a .toml file")
    show.add_argument("--output", "-o", metavar="FILE.md", help="write to a file instead")
    add_logging_arguments(show, default_level="warning")


def _run_profile(args: argparse.Namespace) -> int:
    if args.profile_command == "list":
        profiles = [(name, load_profile(name)) for name in builtin_profile_names()]
        text = "".join(f"{name:14} {p.kind:8} {p.description}\n" for name, p in profiles)
        return _emit(text, None)
    name, names = args.profile, builtin_profile_names()
    if name not in names and not name.endswith(".toml") and not Path(name).exists():
        raise UsageError(
            f"profile show {name}: no such profile; the built-in profiles are"
            f" {', '.join(names)} (or a profile FILE.toml){did_you_mean(name, names)}"
        )
    return _emit(profile_markdown(load_profile(name)), args.output)


def _emit(text: str, output: str | None) -> int:
    """Write a command's ``text`` to the file ``output`` or to stdout; the exit status.

    A file or stdout that cannot be written is one line on stderr and exit 1 (not bad
    input: see :data:`EXIT_OUTPUT_FAILED`), never a traceback.
    """
    if output is None:
        return write_stdout(text, prog="tmmaster")
    try:
        Path(output).write_text(text, encoding="utf-8")
    except OSError as exc:
        return output_failed("tmmaster", output, exc)
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The ``tmmaster`` argument parser: every command, each filled when it is chosen."""
    parser = ArgumentParser(prog="tmmaster", description="Drive a Techman robot over Modbus TCP.")
    add_version_argument(parser)
    # Also before the command (``tmmaster --log-level debug sim``): for every command.
    parser.add_argument(
        "--log-json",
        dest="global_log_json",
        action="store_true",
        help="log structured events as one JSON object per line on stderr (any command)",
    )
    parser.add_argument(
        "--log-level",
        dest="global_log_level",
        type=str.lower,
        choices=LOG_LEVELS,
        default=None,
        help="level of the events logged on stderr (any command; the command's own"
        " --log-level, after it, wins)",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_CommandParser)
    for name, (summary, _) in COMMANDS.items():
        sub.add_parser(name, help=summary, fill=functools.partial(_fill_command, name))
    # The usage line names every command (and any added later).
    sub.metavar = "{" + ",".join(sub.choices) + "}"
    return parser


def _apply_global_logging(args: argparse.Namespace, argv: Sequence[str]) -> None:
    """``--log-level``/``--log-json`` given before the command count for the command.

    The command's own ``--log-level`` (after its name) wins over the one before it.
    """
    if getattr(args, "global_log_json", False):
        args.log_json = True
    level = getattr(args, "global_log_level", None)
    if level is None or args.command is None:
        return
    after = argv[argv.index(args.command) + 1 :] if args.command in argv else []
    if not any(word == "--log-level" or word.startswith("--log-level=") for word in after):
        args.log_level = level


def config_schema() -> str:
    """The JSON Schema of the pick & place configuration file, generated from its model."""
    from .pickplace import PickPlaceConfig

    schema = PickPlaceConfig.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "tmmaster pick & place configuration (TOML)"
    return json.dumps(schema, indent=2, sort_keys=True) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``tmmaster`` console script (``argv`` None: the process's own).

    Bad usage is one line and exit 2; Ctrl-C, at any moment, one line and exit 130
    (:func:`tmmaster._sigint.run_main`). A reader of stdout that went away (``| head``)
    ends any command quietly, with the shell's status for it, 141
    (:data:`~tmmaster._cliparse.EXIT_BROKEN_PIPE`).
    """
    words = sys.argv[1:] if argv is None else argv
    return run_command("tmmaster", build_parser, lambda args: _run(args, words), argv)


def _run(args: argparse.Namespace, words: Sequence[str]) -> int:
    """Run the parsed command; ``words``: the command line it was parsed from."""
    if args.command is None:  # plain ``tmmaster``: say what it can do, as a usage error
        build_parser().print_help(sys.stderr)
        print("tmmaster: give a command [exit 2]", file=sys.stderr)
        return 2
    _apply_global_logging(args, words)
    if args.command == "pickplace":
        # Under its own name: a Ctrl-C says "pickplace: interrupted", as the module does.
        return run_main("pickplace", lambda: _module("pickplace").run(args), process=False)
    if args.command in ("sim", "report", "robot", "tmscript"):
        return int(_module(args.command).run(args))
    return _run_own(args, words)


def _run_own(args: argparse.Namespace, words: Sequence[str]) -> int:
    """``profile``, ``schema`` and ``robot-program``: text on stdout or in a file."""
    undo_logging = configure_logging(json=args.log_json, level=args.log_level, stream=sys.stderr)
    try:
        if args.command == "schema":
            from .pickplace import report_schema

            return _emit(report_schema() if args.report else config_schema(), args.output)
        if args.command == "robot-program":
            own = words[words.index("robot-program") + 1 :] if "robot-program" in words else []
            return _emit(_module("robot-program").run(args, own), args.output)
        return _run_profile(args)
    except UsageError as exc:  # a name the command line chose from a set
        print(f"tmmaster: {one_line(exc)} [exit 2]", file=sys.stderr)
        return 2
    except TMMasterError as exc:
        print(f"tmmaster: {exc}", file=sys.stderr)
        return 2
    finally:
        undo_logging()


if __name__ == "__main__":  # pragma: no cover - exercised through the console script
    raise SystemExit(main())
