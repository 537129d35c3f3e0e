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

import functools
import logging
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TextIO

if TYPE_CHECKING:
    import argparse

#: The logger every tmmaster logger descends from.
ROOT_LOGGER = "tmmaster"

logging.getLogger(ROOT_LOGGER).addHandler(logging.NullHandler())
# pymodbus logs on "pymodbus.*" without a handler of its own (its NullHandler is on
# "pymodbus_internal"), so Python's last-resort handler printed its warnings and errors
# ("Invalid Modbus protocol id: 21584") on stderr of every program using tmmaster. The
# same NullHandler: they reach an application's handlers only once it configures logging.
logging.getLogger("pymodbus").addHandler(logging.NullHandler())


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
        type=str.lower,  # DEBUG, Debug and debug alike
        choices=LOG_LEVELS,
        help=level_help or f"level of the events logged on stderr (default: {default_level})",
    )


class _Logger:
    """What :func:`get_logger` returns: a structlog logger built on the first enabled event.

    An event below the standard logger's level costs one ``isEnabledFor`` check (answered
    from the logging module's cache) and never imports structlog; ``bind`` keeps the
    context for when an event is enabled: a disabled event never enters structlog's
    processors.
    """

    __slots__ = ("_context", "_std", "_wrapped")

    def __init__(self, std: logging.Logger, context: dict[str, Any]) -> None:
        self._std = std
        self._context = context
        self._wrapped: Any = None

    def bind(self, **new_values: Any) -> _Logger:
        """This logger with ``new_values`` added to every event's fields."""
        return _Logger(self._std, {**self._context, **new_values})

    def is_enabled_for(self, level: int) -> bool:
        """True when an event at ``level`` would be logged (build costly fields only then)."""
        return self._std.isEnabledFor(level)

    def _emit(
        self, level: int, method: str, event: str | None = None, *args: Any, **kw: Any
    ) -> Any:
        """Log ``event`` at ``level`` through structlog's ``method``, if enabled."""
        if not self._std.isEnabledFor(level):
            return None
        wrapped = self._wrapped
        if wrapped is None:
            from ._structlog import wrap_logger

            # Two threads may both build it: the same logger, one of them kept.
            wrapped = self._wrapped = wrap_logger(self._std).bind(**self._context)
        return getattr(wrapped, method)(event, *args, **kw)

    # ``log.info(event, **fields)``: one level each; ``exception`` adds the traceback.
    debug = functools.partialmethod(_emit, logging.DEBUG, "debug")
    info = functools.partialmethod(_emit, logging.INFO, "info")
    warning = functools.partialmethod(_emit, logging.WARNING, "warning")
    error = functools.partialmethod(_emit, logging.ERROR, "error")
    exception = functools.partialmethod(_emit, logging.ERROR, "exception")


def get_logger(name: str) -> Any:
    """A structlog logger on the standard logger ``name`` (``tmmaster.*``)."""
    return _Logger(logging.getLogger(name), {})


def configure_logging(
    *, json: bool = False, level: str = "info", stream: TextIO | None = None
) -> Callable[[], None]:
    """Print tmmaster's events to ``stream`` (stderr): coloured key=value, or one JSON per line.

    For command-line tools and scripts; a library user's own logging configuration
    (tmmaster logs on the standard loggers ``tmmaster.*``) needs none of it.

    Args:
        json: One JSON object per line instead of key=value text.
        level: The lowest level shown: ``"debug"``, ``"info"``, ``"warning"`` or
            ``"error"``.
        stream: Where to print; None: stderr.

    Returns:
        A function that undoes the configuration.

    Raises:
        ValueError: An unknown level.
    """
    return configure_command_logging(json=json, level=level, stream=stream)


def configure_command_logging(
    *, json: bool, level: str, stream: TextIO | None, record_filter: logging.Filter | None = None
) -> Callable[[], None]:
    """:func:`configure_logging`, with ``record_filter`` on the handler (for a command that
    says some events itself, in its own words)."""
    numeric = logging.getLevelNamesMapping().get(level.upper())
    if numeric is None:
        raise ValueError(f"unknown log level {level!r}")
    from ._structlog import event_formatter

    output = stream if stream is not None else sys.stderr
    handler = logging.StreamHandler(output)
    handler.setFormatter(event_formatter(json=json, colors=output.isatty()))
    if record_filter is not None:
        handler.addFilter(record_filter)
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
