"""Argument checks shared by the public constructors (one wording for one rule)."""

from __future__ import annotations

import functools
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from decimal import Decimal
from typing import Any, ClassVar, TypeGuard

from pydantic import BaseModel, ConfigDict, ValidationError

from ._error_root import ConfigError

#: The largest magnitude a float holds; an int beyond it has no float (OverflowError).
_FLOAT_MAX = sys.float_info.max

#: The longest ``repr`` :func:`shown` quotes in a message before cutting it short.
_SHOWN_CHARS = 100


def is_finite_number(value: object) -> TypeGuard[int | float]:
    """True for a finite int or float (not a bool, not a string, not nan or inf).

    An int too large for a float (``10**400``) is not one: it has no float to become.

    Args:
        value: Anything a caller passed.

    Returns:
        Whether ``value`` is a number a float holds.
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    # An int compared exactly (no conversion), so 10**400 is refused, not an OverflowError.
    return -_FLOAT_MAX <= value <= _FLOAT_MAX if isinstance(value, int) else math.isfinite(value)


def shown(value: object) -> str:
    """``value`` as an error message quotes it: its ``repr``, cut to 100 characters.

    An int too large for a float is written in scientific notation (``1.000e+400``):
    Python refuses to write an int of more than 4300 digits (a ValueError).

    Args:
        value: Anything a caller passed.

    Returns:
        A short text for a message.
    """
    if isinstance(value, int) and not isinstance(value, bool) and not is_finite_number(value):
        return f"{Decimal(value):.3e}"
    text = repr(value)
    return text if len(text) <= _SHOWN_CHARS else f"{text[: _SHOWN_CHARS - 3]}..."


def require_positive(name: str, value: object) -> float:
    """``value`` as a float when it is a finite number > 0; else a ConfigError naming ``name``."""
    if not is_finite_number(value) or value <= 0:
        raise ConfigError(f"{name} must be a finite number > 0, got {shown(value)}")
    return float(value)


@dataclass(frozen=True)
class Bounds:
    """The range a numeric option must lie in: ``low`` (excluded when ``open_low``) to
    ``high`` (included), in ``unit``."""

    low: float
    high: float
    unit: str
    #: True: ``low`` itself is refused (``(0, 50]``); False: allowed (``[0.001, 5]``).
    open_low: bool = False

    def __str__(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        return f"{'(' if self.open_low else '['}{self.low:g}, {self.high:g}]{unit}"

    def admits(self, value: float) -> bool:
        """True when ``value`` lies in the range."""
        above = value > self.low if self.open_low else value >= self.low
        return above and value <= self.high


def require_in(name: str, value: object, bounds: Bounds) -> float:
    """``value`` as a float when it is a finite number within ``bounds``.

    Otherwise a ConfigError naming ``name`` and the range, for instance
    ``poll_interval_s must be a number in [0.001, 5] s, got 1e9``.
    """
    if not is_finite_number(value) or not bounds.admits(value):
        raise ConfigError(f"{name} must be a number in {bounds}, got {shown(value)}")
    return float(value)


class Policy(BaseModel):
    """A frozen options object of :class:`~tmmaster.Robot` (``polling=PollPolicy(...)``).

    Built in code, an invalid value is a :class:`ConfigError` naming the field as the
    robot's argument writes it (``polling.interval_s must be a number in [0.001, 5] s,
    got 1e9``); validated inside another pydantic model (a configuration file), it stays
    that model's validation error.
    """

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    #: The Robot argument that takes this policy: the prefix of a field's name in errors.
    argument: ClassVar[str] = ""

    def __init__(self, /, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as exc:
            raise ConfigError(self._problems(exc)) from exc

    # Validated inside another model (model_validate, a configuration section), pydantic
    # skips this __init__, as it does BaseModel's and RootModel's (their same marker):
    # the error stays a ValidationError located at the field.
    __init__.__pydantic_base_init__ = True  # type: ignore[attr-defined]

    @classmethod
    def _problems(cls, exc: ValidationError) -> str:
        """Every problem of ``exc``, each naming its field (``checks.units: ...``)."""
        problems = []
        for error in exc.errors():
            cause = error.get("ctx", {}).get("error")
            if isinstance(cause, ConfigError):
                problems.append(str(cause))  # already names the field and its range
                continue
            where = ".".join(str(part) for part in (cls.argument, *error["loc"]) if part)
            got = "" if error["type"] == "missing" else f", got {shown(error['input'])}"
            problems.append(f"{where}: {error['msg']}{got}")
        return "; ".join(problems)


def bounded(name: str, bounds: Bounds) -> Callable[[object], float]:
    """A pydantic "before" check of a field: ``value`` in ``bounds``, else a ConfigError.

    It sees the value as given (a bool, a string, nan, 10**400 are refused as
    :func:`require_in` refuses them), so the message is the one a setter gives.
    """
    return functools.partial(require_in, name, bounds=bounds)
