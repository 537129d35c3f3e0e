"""Logging: structured events through the standard ``logging`` module, quiet by default.

Every tmmaster module logs through :func:`get_logger`: structlog builds the event (name,
key-value fields, level, timestamp) and hands it to the standard logger of the same name
(``tmmaster.robot``, ``tmmaster.transport``, ``tmmaster.sim`` ...). The ``tmmaster``
logger has only a ``NullHandler``: a library must not decide for its host program, so
nothing is printed unless the application configures logging (``logging.basicConfig``,
its own handlers, or :func:`configure_logging`). The simulator logs under ``tmmaster.sim``,
so its events can be filtered apart from the master's.
"""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TextIO

import structlog

if TYPE_CHECKING:
    import argparse

#: The logger every tmmaster logger descends from.
ROOT_LOGGER = "tmmaster"

logging.getLogger(ROOT_LOGGER).addHandler(logging.NullHandler())

_PROCESSORS: list[structlog.typing.Processor] = [
    # Before anything else: a disabled level costs one check, not a whole event.
    structlog.stdlib.filter_by_level,
    structlog.contextvars.merge_contextvars,
    structlog.stdlib.add_log_level,
    structlog.stdlib.add_logger_name,
    structlog.processors.TimeStamper(fmt="iso", utc=True),
    structlog.processors.format_exc_info,
    # The event dict travels to the handler's formatter; a plain formatter prints it
    # as a dict, configure_logging's renders it as key=value or JSON.
    structlog.stdlib.ProcessorFormatter.wrap_for_formatter,
]


#: The levels every command's ``--log-level`` accepts.
LOG_LEVELS = ("debug", "info", "warning", "error")


def add_logging_arguments(
    parser: argparse.ArgumentParser,
    *,
    default_level: str | None = None,
    level_help: str | None = None,
) -> None:
    """Add ``--log-json`` and ``--log-level``, which mean the same on every command."""
    parser.add_argument(
        "--log-json",
        action="store_true",
        help="log structured events as one JSON object per line on stderr",
    )
    parser.add_argument(
        "--log-level",
        default=default_level,
        choices=LOG_LEVELS,
        help=level_help or f"level of the events logged on stderr (default: {default_level})",
    )


class _BoundLogger(structlog.stdlib.BoundLogger):
    """A stdlib bound logger that drops a disabled event before building it.

    ``filter_by_level`` would drop it too, but only after structlog has copied the bound
    context and entered its processor chain (several microseconds per event); the
    library is quiet by default, so the events of every move would pay that for nothing.
    ``Logger.isEnabledFor`` is the same test, answered from the logging module's cache.
    """

    def debug(self, event: str | None = None, *args: Any, **kw: Any) -> Any:
        """Log at DEBUG, if enabled."""
        if not self._logger.isEnabledFor(logging.DEBUG):
            return None
        return super().debug(event, *args, **kw)

    def info(self, event: str | None = None, *args: Any, **kw: Any) -> Any:
        """Log at INFO, if enabled."""
        if not self._logger.isEnabledFor(logging.INFO):
            return None
        return super().info(event, *args, **kw)

    def warning(self, event: str | None = None, *args: Any, **kw: Any) -> Any:
        """Log at WARNING, if enabled."""
        if not self._logger.isEnabledFor(logging.WARNING):
            return None
        return super().warning(event, *args, **kw)

    warn = warning

    def error(self, event: str | None = None, *args: Any, **kw: Any) -> Any:
        """Log at ERROR, if enabled."""
        if not self._logger.isEnabledFor(logging.ERROR):
            return None
        return super().error(event, *args, **kw)

    def exception(self, event: str | None = None, *args: Any, **kw: Any) -> Any:
        """Log at ERROR with the current exception, if enabled."""
        if not self._logger.isEnabledFor(logging.ERROR):
            return None
        return super().exception(event, *args, **kw)


def get_logger(name: str) -> Any:
    """A structlog logger on the standard logger ``name`` (``tmmaster.*``)."""
    return structlog.wrap_logger(
        logging.getLogger(name),
        processors=_PROCESSORS,
        wrapper_class=_BoundLogger,
        cache_logger_on_first_use=True,
    )


def configure_logging(
    *, json: bool = False, level: str = "info", stream: TextIO | None = None
) -> Callable[[], None]:
    """Print tmmaster's events to ``stream`` (stderr): coloured key=value, or one JSON per line.

    For command-line tools and scripts. Returns a function that undoes it.
    """
    numeric = logging.getLevelNamesMapping().get(level.upper())
    if numeric is None:
        raise ValueError(f"unknown log level {level!r}")
    output = stream if stream is not None else sys.stderr
    renderer: structlog.typing.Processor
    if json:
        renderer = structlog.processors.JSONRenderer()
    else:
        renderer = structlog.dev.ConsoleRenderer(colors=output.isatty())
    handler = logging.StreamHandler(output)
    handler.setFormatter(
        structlog.stdlib.ProcessorFormatter(
            processors=[structlog.stdlib.ProcessorFormatter.remove_processors_meta, renderer]
        )
    )
    root = logging.getLogger(ROOT_LOGGER)
    saved = (root.level, root.propagate)
    root.addHandler(handler)
    root.setLevel(numeric)
    root.propagate = False  # printed here; not a second time by the application's root
    # pymodbus logs every refused connection and dropped send on its own; the transport
    # reports each of those as a typed error and a structured event, so keep only its
    # critical messages out of the user's terminal.
    pymodbus = logging.getLogger("pymodbus")
    pymodbus_level = pymodbus.level
    pymodbus.setLevel(logging.CRITICAL)

    def undo() -> None:
        root.removeHandler(handler)
        root.setLevel(saved[0])
        root.propagate = saved[1]
        pymodbus.setLevel(pymodbus_level)

    return undo
