"""Structured logging set-up: pretty lines on a terminal, JSON lines on request.

tmmaster logs through structlog loggers named ``tmmaster.*`` and never configures
logging on import: a library must not decide for its host program. Command-line
entry points call :func:`configure_logging`.
"""

from __future__ import annotations

import logging
import sys
from typing import TextIO

import structlog


def configure_logging(
    *, json: bool = False, level: str = "info", stream: TextIO | None = None
) -> None:
    """Send tmmaster's events to ``stream`` (stderr): coloured key=value, or one JSON per line."""
    numeric = logging.getLevelNamesMapping().get(level.upper())
    if numeric is None:
        raise ValueError(f"unknown log level {level!r}")
    output = stream if stream is not None else sys.stderr
    renderer: structlog.typing.Processor
    if json:
        renderer = structlog.processors.JSONRenderer()
    else:
        renderer = structlog.dev.ConsoleRenderer(colors=output.isatty())
    # pymodbus logs every refused connection and dropped send on its own; the transport
    # reports each of those as a typed error and a structured event, so keep only its
    # critical messages out of the user's terminal.
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    structlog.configure(
        processors=[
            structlog.contextvars.merge_contextvars,
            structlog.processors.add_log_level,
            structlog.processors.TimeStamper(fmt="iso", utc=True),
            structlog.processors.format_exc_info,
            renderer,
        ],
        wrapper_class=structlog.make_filtering_bound_logger(numeric),
        logger_factory=structlog.PrintLoggerFactory(file=output),
        cache_logger_on_first_use=False,
    )
