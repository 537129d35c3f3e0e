"""Argument checks shared by the public constructors (one wording for one rule)."""

from __future__ import annotations

import math

from ._exceptions import ConfigError


def require_positive(name: str, value: object) -> float:
    """``value`` as a float when it is a finite number > 0; else a ConfigError naming ``name``."""
    if (
        isinstance(value, bool)
        or not isinstance(value, int | float)
        or not math.isfinite(value)
        or value <= 0
    ):
        raise ConfigError(f"{name} must be a finite number > 0, got {value!r}")
    return float(value)
