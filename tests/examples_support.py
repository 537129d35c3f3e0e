"""The scripts in ``examples/``: import them as modules (they are not part of the package), read
the commands their docstrings document."""

from __future__ import annotations

import ast
import importlib.util
import shlex
import sys
from pathlib import Path
from types import ModuleType

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load_example(name: str) -> ModuleType:
    """Import ``examples/<name>.py`` as the module ``example_<name>``."""
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    # dataclasses look the module up in sys.modules while the class body is built.
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def documented_commands(name: str) -> list[list[list[str]]]:
    """The command lines of ``examples/<name>.py``'s docstring, in blocks, split like a shell.

    A command line is one whose text starts with ``python ``; consecutive command lines
    form one block (run together: simulators, then the example). A trailing ``&`` (run
    in the background) is dropped.
    """
    source = (EXAMPLES / f"{name}.py").read_text(encoding="utf-8")
    docstring = ast.get_docstring(ast.parse(source)) or ""
    blocks: list[list[list[str]]] = []
    block: list[list[str]] = []
    for line in [*docstring.splitlines(), ""]:
        text = line.strip()
        if text.startswith("python "):
            words = shlex.split(text)
            block.append(words[:-1] if words[-1] == "&" else words)
        elif block:
            blocks.append(block)
            block = []
    return blocks
