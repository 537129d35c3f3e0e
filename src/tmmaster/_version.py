"""tmmaster's version, from one place: the installed package's metadata."""

from __future__ import annotations

from functools import cache
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import argparse


@cache
def version() -> str:
    """The installed tmmaster version ("0.0.0" when running from an uninstalled tree)."""
    from importlib import metadata  # not at import time: it costs ~40 ms

    try:
        return metadata.version("tmmaster")
    except metadata.PackageNotFoundError:
        return "0.0.0"


def add_version_argument(parser: argparse.ArgumentParser) -> None:
    """Give ``parser`` a ``--version`` option printing tmmaster's version."""
    parser.add_argument("--version", action="version", version=f"%(prog)s {version()}")
