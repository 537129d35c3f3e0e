"""The package's modules parsed once per test process.

The tests that read the source (the house limits, the import graph) share the trees:
parsing all of ``src/tmmaster`` takes about a second. Nothing may change a tree it is
given.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path


@functools.cache
def source(path: Path) -> tuple[str, ast.Module]:
    """The text of the module at ``path`` and its syntax tree (read and parsed once).

    Args:
        path: A module's file, resolved (the same file is one cache entry).

    Returns:
        Its text (UTF-8) and ``ast.parse`` of it.
    """
    text = path.read_text(encoding="utf-8")
    return text, ast.parse(text)
