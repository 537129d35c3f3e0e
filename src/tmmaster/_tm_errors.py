"""What a Techman error code means: TMflow 2.24 Appendix J as data (``tm_errors.toml``).

A TM robot reports its last error as an int32 (input registers 7320-7321, "Last error
code"). Techman's *Software Manual TMflow, SW 2.24* lists every code in Appendix J
"Error Descriptions and Suggestions": a description (pp. 349-405) and, for most codes, a
suggestion with its cause, what to check and what to do (pp. 406-641).
``tm_errors.toml`` is that appendix transcribed (the file's header says how); each entry
cites its pages. Where the manual gives no solution for a motion error, the entry carries
a short hint of ours, marked ``what_to_do_by = "tmmaster"``.

:func:`lookup_tm_error` finds one code without parsing the whole file (about 1 MB of TOML: one
entry is parsed on first use, then cached); the tests parse and validate them all.
"""

from __future__ import annotations

import functools
import re
import tomllib
from collections.abc import Mapping
from importlib import resources
from types import MappingProxyType
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from ._error_root import ConfigError

#: Where the codes come from, as messages name it.
SOURCE = "TMflow 2.24 Appendix J"
#: The data file, in the ``tmmaster`` package.
DATA_FILE = "tm_errors.toml"
#: A hint longer than this (in characters) is left to the manual's page in messages.
SHORT_HINT_CHARS = 200

_ENTRY_SEPARATOR = "\n[[error]]\n"
_CODE_LINE = re.compile(r"^code = (\d+)$", re.MULTILINE)


class TMErrorCode(BaseModel):
    """One error code of TMflow 2.24 Appendix J, with the manual's text and pages."""

    # Built on first use, not at import: only a robot error looks an entry up.
    model_config = ConfigDict(frozen=True, extra="forbid", defer_build=True)

    #: The error code (unsigned 32-bit).
    code: int = Field(ge=0, le=0xFFFFFFFF)
    #: The code as the manual prints it, eight hex digits: ``"0x00000022"``.
    hex: str
    #: The manual's description: ``"Force or Torque Over Range"``.
    text: str = Field(min_length=1)
    #: The manual's page of the description.
    page: int = Field(ge=1)
    #: The manual's page where the suggestion for this code begins (None: it has none).
    suggestion_page: int | None = Field(default=None, ge=1)
    #: The suggestion's cause, as the manual prints it.
    cause: str | None = None
    #: What the manual says to check ([Caution]).
    checks: str | None = None
    #: What to do: the manual's solution, or a hint of ours (see :attr:`what_to_do_by`).
    what_to_do: str | None = None
    #: Who wrote :attr:`what_to_do`: ``"manual"`` (Techman) or ``"tmmaster"`` (ours).
    what_to_do_by: Literal["manual", "tmmaster"] | None = None

    @model_validator(mode="after")
    def _consistent(self) -> TMErrorCode:
        if self.hex != f"0x{self.code:08X}":
            raise ValueError(f"hex {self.hex!r} does not spell code {self.code}")
        if (self.what_to_do is None) != (self.what_to_do_by is None):
            raise ValueError("what_to_do and what_to_do_by go together")
        return self

    @property
    def label(self) -> str:
        """The code and its meaning: ``"0x0022 Force or Torque Over Range"``."""
        return f"{code_hex(self.code)} {self.text}"

    def hint(self) -> str:
        """What to do, in one line for a message: the text where short, else the page.

        Returns:
            ``"what to do (TMflow 2.24 manual p. 409): To restore ..."``, ``"what to do
            (tmmaster's hint): ..."``, ``"what to do: TMflow 2.24 manual p. 414"`` for a long
            one, or ``"see TMflow 2.24 manual p. N"`` where the manual gives nothing to do.
        """
        page = self.suggestion_page or self.page
        if self.what_to_do is None:
            return f"see TMflow 2.24 manual p. {page}"
        text = " ".join(self.what_to_do.split())
        if len(text) > SHORT_HINT_CHARS:
            return f"what to do: TMflow 2.24 manual p. {page}"
        if self.what_to_do_by == "tmmaster":
            return f"what to do (tmmaster's hint, not the manual's): {text}"
        return f"what to do (TMflow 2.24 manual p. {page}): {text}"


def code_hex(code: int) -> str:
    """The code in hex, at least four digits: ``0x0022``, ``0x0005F133``-style codes in full.

    Args:
        code: An error code; a negative one is read as the int32 it came from.

    Returns:
        ``"0x0022"``, ``"0x5F133"``...
    """
    return f"0x{code & 0xFFFFFFFF:04X}"


def describe(code: int, *, hint: bool = False) -> str:
    """The code and its meaning, for one line of text. Never raises: where the data cannot
    be read (a broken install), the hex code and why.

    Args:
        code: The robot's error code.
        hint: Add what to do, where short (the message of a robot fault).

    Returns:
        ``"0x0022 Force or Torque Over Range"`` (with ``hint``: then ``"; what to do
        (TMflow 2.24 manual p. 409): ..."``), or ``"0x1234 (not in TMflow 2.24
        Appendix J)"`` for a code the manual does not list.
    """
    try:
        entry = lookup_tm_error(code)
    except (ConfigError, OSError) as exc:  # the message must not fail on the data
        return f"{code_hex(code)} (its meaning could not be read: {exc})"
    if entry is None:
        return f"{code_hex(code)} (not in {SOURCE})"
    return f"{entry.label}; {entry.hint()}" if hint else entry.label


def lookup_tm_error(code: int) -> TMErrorCode | None:
    """The entry of TMflow 2.24 Appendix J for a robot's error code.

    ``lookup_tm_error(0x22).label`` is ``"0x0022 Force or Torque Over Range"``; the entry
    also holds the manual's cause, checks, what to do and pages.

    Args:
        code: The robot's error code (a negative int32 is read as its unsigned value).

    Returns:
        The entry, or None when the manual does not list the code.

    Raises:
        ConfigError: The data file is missing or malformed (a broken install).
    """
    return _lookup(code & 0xFFFFFFFF)


@functools.cache
def _text() -> str:
    try:
        return resources.files("tmmaster").joinpath(DATA_FILE).read_text("utf-8")
    except OSError as exc:
        raise ConfigError(f"cannot read tmmaster's {DATA_FILE}: {exc}") from exc


@functools.cache
def _index() -> Mapping[int, str]:
    """Each code's TOML entry (its text, unparsed), found by its ``code = N`` line."""
    index: dict[int, str] = {}
    for chunk in _text().split(_ENTRY_SEPARATOR)[1:]:
        found = _CODE_LINE.search(chunk)
        if found is None:
            raise ConfigError(f"{DATA_FILE}: an entry without a code line: {chunk[:80]!r}")
        index[int(found.group(1))] = chunk
    return MappingProxyType(index)


@functools.cache
def _lookup(code: int) -> TMErrorCode | None:
    if (chunk := _index().get(code)) is None:
        return None
    try:
        return TMErrorCode.model_validate(tomllib.loads("[[error]]\n" + chunk)["error"][0])
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{DATA_FILE}: entry {code_hex(code)}: {exc}") from exc
    except ValidationError as exc:
        raise ConfigError(f"{DATA_FILE}: invalid entry: {exc}") from exc
