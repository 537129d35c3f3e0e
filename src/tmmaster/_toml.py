"""Reading a user's TOML file (a scene, a pick & place config, a profile) safely.

Every TOML file a command reads from the user goes through :func:`read_toml`: a file too
large, not UTF-8, not TOML, nested deeper than the parser can follow or with a key of
absurdly many dotted parts ends in one :class:`~tmmaster.ConfigError` naming the file,
never a traceback or a parse that does not end.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any

from ._error_root import ConfigError

#: Largest TOML file :func:`read_toml` reads, bytes (1 MiB). A scene, a config or a
#: profile is a few kB (a scene of 10,000 parts fits); Python's TOML parser reads about
#: half a MiB a second, and reading stops here (``/dev/zero`` would never end).
MAX_TOML_BYTES = 1024 * 1024

#: Most parts a dotted key (``a.b.c = 1``, ``[a.b.c]``) may have. Python's TOML parser
#: takes time quadratic in a key's parts (some 100 s for 100,000 of them); no tmmaster
#: file nests more than four deep.
MAX_KEY_PARTS = 64

_KEY = r"""(?:[A-Za-z0-9_-]+|"(?:[^"\\\n]|\\.)*"|'[^'\n]*')"""
#: The first MAX_KEY_PARTS + 1 parts of a longer key, starting where a key can start.
#: It may also match inside a string or a comment, where such a run is as absurd.
_LONG_KEY = re.compile(rf"(?<![A-Za-z0-9_\-.]){_KEY}(?:[ \t]*\.[ \t]*{_KEY}){{{MAX_KEY_PARTS}}}")


def parse_toml(text: str, source: str, *, error: type[ConfigError] = ConfigError) -> dict[str, Any]:
    """Parse TOML text; anything that is not TOML tmmaster reads raises one ``error``.

    Args:
        text: The TOML text.
        source: What the message names (the file).
        error: The ConfigError subclass to raise (RegisterMapError for a profile).

    Returns:
        The parsed document.

    Raises:
        ConfigError: (``error``) not TOML, arrays or inline tables nested deeper than the
            parser follows (a RecursionError inside it), or a key of more than
            :data:`MAX_KEY_PARTS` dotted parts.
    """
    if _LONG_KEY.search(text) is not None:
        raise error(
            f"{source}: not valid TOML here: a key of more than {MAX_KEY_PARTS} dotted parts"
        )
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{source}: not valid TOML ({exc})") from None
    except RecursionError:
        raise error(
            f"{source}: not valid TOML here: arrays or inline tables nested too deeply"
        ) from None


def read_toml(
    path: str | Path, source: str | None = None, *, error: type[ConfigError] = ConfigError
) -> dict[str, Any]:
    """Read a UTF-8 TOML file of at most :data:`MAX_TOML_BYTES` (:func:`parse_toml`).

    Args:
        path: The file.
        source: What the message names (default: the path).
        error: The ConfigError subclass to raise (RegisterMapError for a profile).

    Returns:
        The parsed document.

    Raises:
        ConfigError: (``error``) the file is unreadable, larger than
            :data:`MAX_TOML_BYTES`, not UTF-8, or not TOML tmmaster reads
            (:func:`parse_toml`). The message names the file and says why, in one line.
    """
    where = str(path) if source is None else source
    try:
        with open(path, "rb") as handle:
            # One byte more than allowed tells a file over the limit from one at it.
            data = handle.read(MAX_TOML_BYTES + 1)
    except OSError as exc:
        raise error(f"{where}: cannot read the file ({exc.strerror or exc})") from None
    if len(data) > MAX_TOML_BYTES:
        raise error(
            f"{where}: larger than {MAX_TOML_BYTES // (1024 * 1024)} MiB, the most a TOML file"
            " tmmaster reads may be"
        )
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(
            f"{where}: not a UTF-8 text (TOML) file: byte 0x{data[exc.start]:02x}"
            f" at offset {exc.start}"
        ) from None
    return parse_toml(text, where, error=error)
