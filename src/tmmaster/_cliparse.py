"""The commands' argument parser: a bad option is one line and exit 2, never a usage dump."""

from __future__ import annotations

import argparse
from typing import NoReturn

from ._exceptions import ConfigError


class UsageError(ConfigError):
    """A command-line option is wrong (the command exits 2)."""


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose errors raise :class:`UsageError` for ``main()``."""

    def error(self, message: str) -> NoReturn:
        """Raise instead of printing the usage and exiting: ``main()`` says it in one line."""
        raise UsageError(f"{message} (see {self.prog} --help)")


def one_line(text: object) -> str:
    """``text`` on one line (a multi-line validation report joined by spaces)."""
    return " ".join(str(text).split())
