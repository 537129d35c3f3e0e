"""The structlog side of :mod:`tmmaster._logging`, imported on the first enabled event.

structlog imports ``structlog.dev``, which imports rich when it is installed: some 0.1 s
of CPU that a program which never turns tmmaster's logging on does not pay.
"""

from __future__ import annotations

import json
import logging
from typing import Any

import structlog

#: Fields the standard record carries itself (its level, logger name and time), or that
#: :class:`LogEvent` prints on lines of their own.
_RECORD_FIELDS = frozenset({"event", "level", "logger", "timestamp", "exception", "stack"})


def _text(value: Any) -> str:
    """A field's value as one token: quoted (JSON style) when it has spaces or quotes."""
    if isinstance(value, list | tuple):
        value = "[" + ",".join(_text(item) for item in value) + "]"
    text = value if isinstance(value, str) else str(value)
    quoted = not text or any(c.isspace() or c in '"=' for c in text)
    return json.dumps(text, ensure_ascii=False) if quoted else text


class LogEvent(dict[str, Any]):
    """A structlog event as a standard log record's message.

    A dict, which ``configure_logging``'s formatter renders (key=value or JSON); as text
    (``str()``, what ``logging.Formatter`` prints as ``%(message)s``) it reads
    ``robot.connected robot=robot host=127.0.0.1 port=502``: the event first, then each
    field as key=value in the order it was bound or given. The level, the logger's name
    and the time are left to the formatter, which has them from the record; a traceback
    follows on the next lines.
    """

    __slots__ = ()

    def __str__(self) -> str:
        words = [str(self.get("event"))]
        words += [
            f"{key}={_text(value)}" for key, value in self.items() if key not in _RECORD_FIELDS
        ]
        lines = [" ".join(words)]
        lines += [str(self[key]) for key in ("stack", "exception") if self.get(key)]
        return "\n".join(lines)


def _to_record(
    logger: logging.Logger, name: str, event_dict: structlog.typing.EventDict
) -> tuple[tuple[LogEvent], dict[str, dict[str, Any]]]:
    """structlog's ``ProcessorFormatter.wrap_for_formatter``, the event as a :class:`LogEvent`."""
    return (LogEvent(event_dict),), {"extra": {"_logger": logger, "_name": name}}


_PROCESSORS: list[structlog.typing.Processor] = [
    # Before anything else: a disabled level costs one check, not a whole event.
    structlog.stdlib.filter_by_level,
    structlog.contextvars.merge_contextvars,
    structlog.stdlib.add_log_level,
    structlog.stdlib.add_logger_name,
    structlog.processors.TimeStamper(fmt="iso", utc=True),
    structlog.processors.format_exc_info,
    # The event travels to the handlers as the record's message: configure_logging's
    # formatter renders it as coloured key=value or JSON, any other formatter (a plain
    # logging.basicConfig, pytest's caplog) as "event key=value ...".
    _to_record,
]


def wrap_logger(std: logging.Logger) -> Any:
    """A structlog logger on the standard logger ``std``."""
    return structlog.wrap_logger(
        std,
        processors=_PROCESSORS,
        wrapper_class=structlog.stdlib.BoundLogger,
        cache_logger_on_first_use=True,
    )


def event_formatter(*, json: bool, colors: bool) -> logging.Formatter:
    """A formatter printing structlog events as one JSON object, or coloured key=value."""
    renderer: structlog.typing.Processor = structlog.dev.ConsoleRenderer(colors=colors)
    if json:
        renderer = structlog.processors.JSONRenderer()
    return structlog.stdlib.ProcessorFormatter(
        processors=[structlog.stdlib.ProcessorFormatter.remove_processors_meta, renderer]
    )
