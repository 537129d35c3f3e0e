"""The root of tmmaster's errors and :class:`ConfigError` (the tree is in ``_exceptions.py``).

Kept apart so that the data layer (``_pose.py``) can raise a ConfigError without
importing ``_exceptions.py``, whose errors carry a :class:`~tmmaster.Pose`.
"""

from __future__ import annotations


class TMMasterError(Exception):
    """Root of every error raised by tmmaster."""


class ConfigError(TMMasterError, ValueError):
    """Invalid configuration, detected before anything is sent."""


# Shown as ``tmmaster.ConfigError`` (tracebacks, reprs, pickles) from the start, like the
# errors of _exceptions.py: both are exported by ``tmmaster``.
TMMasterError.__module__ = ConfigError.__module__ = "tmmaster"
