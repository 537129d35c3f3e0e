"""``python -m tmmaster.report`` (and ``tmmaster report``): show or plot a run report.

``show run.json`` prints the summary table (per-state times, cycles, result);
``plot run.json -o run.png`` draws the timeline (needs matplotlib: ``tmmaster[plot]``).
Exit codes: 0 done, 1 matplotlib missing, the image or the table cannot be written
(a full disk), 141 the reader of stdout went away (``| head``), 2 the file is not a
readable run report (not a regular file, larger than 256 MiB, not UTF-8, nested too
deeply, not a report, an unsupported ``report_version``) or an option is wrong. ``show``
prints the file's strings as text (no rich markup, control characters escaped) and a
bounded table (docs/pickplace.md).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from .._cliparse import ArgumentParser, one_line, run_command, write_stdout
from .._exceptions import ConfigError
from .._logging import add_logging_arguments, configure_logging
from .._version import add_version_argument

#: What to install when matplotlib is missing.
PLOT_EXTRA = "tmmaster[plot]"

#: The report argument's help. The size is pickplace._report.MAX_REPORT_BYTES, written out:
#: importing that module here would load the runner before the options are even parsed.
_REPORT_HELP = "a report written by --report (a UTF-8 JSON file of at most 256 MiB)"


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Add the ``show`` and ``plot`` subcommands to ``parser``; return it."""
    add_version_argument(parser)
    sub = parser.add_subparsers(dest="report_command", required=True, metavar="{show,plot}")
    show = sub.add_parser("show", help="print the summary table of a run report")
    show.add_argument("report", metavar="RUN.json", help=_REPORT_HELP)
    add_logging_arguments(show, default_level="warning")
    plot = sub.add_parser(
        "plot", help=f"draw the run as a picture (needs matplotlib: pip install '{PLOT_EXTRA}')"
    )
    plot.add_argument("report", metavar="RUN.json", help=_REPORT_HELP)
    plot.add_argument(
        "--output",
        "-o",
        metavar="FILE.png",
        help="image file; .png, .svg or .pdf (default: the report's name with .png)",
    )
    add_logging_arguments(plot, default_level="warning")
    return parser


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``python -m tmmaster.report``."""
    parser = ArgumentParser(
        prog="python -m tmmaster.report",
        description="Show or plot a pick & place run report (written by --report).",
    )
    return add_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Run ``show`` or ``plot`` from parsed ``args``; return the exit code (never raises)."""
    undo = configure_logging(json=args.log_json, level=args.log_level, stream=sys.stderr)
    try:
        return _run(args)
    finally:
        undo()


def _run(args: argparse.Namespace) -> int:
    from ..pickplace._report import load_report

    if args.report_command == "plot":
        try:
            import matplotlib  # noqa: F401  # only to say which extra is missing
        except ImportError:
            print(
                f"report: plotting needs matplotlib: pip install '{PLOT_EXTRA}' [exit 1]",
                file=sys.stderr,
            )
            return 1
    try:
        report = load_report(args.report)
    except ConfigError as exc:
        print(f"report: {one_line(exc)} [exit 2]", file=sys.stderr)
        return 2
    if args.report_command == "show":
        from rich.console import Console

        from ..pickplace._summary import summary_renderable

        # Rendered first, written by write_stdout: rich would end the process itself on a
        # closed pipe (exit 1); a reader that went away is the shared quiet 141.
        console = Console(file=sys.stdout)
        with console.capture() as captured:
            console.print(summary_renderable(report))
        return write_stdout(captured.get(), prog="report")
    from ._plot import plot_report, recorded_nothing

    output = Path(args.output) if args.output else Path(args.report).with_suffix(".png")
    try:
        plot_report(report, output)
    except (OSError, ValueError) as exc:  # unwritable path, unknown image format
        print(f"report: cannot write {output}: {one_line(exc)} [exit 1]", file=sys.stderr)
        return 1
    if recorded_nothing(report):
        why = one_line(report.reason or report.result)
        print(f"wrote {output}: nothing to plot, the run ended before its first state ({why})")
    else:
        print(f"wrote {output}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``python -m tmmaster.report``."""
    return run_command("report", build_parser, run, argv)


if __name__ == "__main__":
    sys.exit(main())
