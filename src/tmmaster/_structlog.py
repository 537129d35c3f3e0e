"""The structlog side of :mod:`tmmaster._logging`, imported on the first enabled event.

structlog imports ``structlog.dev``, which imports rich when it is installed: some 0.1 s
of CPU that a program which never turns tmmaster's logging on does not pay.
"""

from __future__ import annotations

import logging
from typing import Any

import structlog

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


def wrap_logger(std: logging.Logger) -> Any:
    """A structlog logger on the standard logger ``std``."""
    return structlog.wrap_logger(
        std,
        processors=_PROCESSORS,
        wrapper_class=_BoundLogger,
        cache_logger_on_first_use=True,
    )


def event_formatter(*, json: bool, colors: bool) -> logging.Formatter:
    """A formatter printing structlog events as one JSON object, or coloured key=value."""
    renderer: structlog.typing.Processor
    if json:
        renderer = structlog.processors.JSONRenderer()
    else:
        renderer = structlog.dev.ConsoleRenderer(colors=colors)
    return structlog.stdlib.ProcessorFormatter(
        processors=[structlog.stdlib.ProcessorFormatter.remove_processors_meta, renderer]
    )
