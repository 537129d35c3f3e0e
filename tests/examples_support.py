"""The scripts in ``examples/``: import them as modules (they are not part of the package), read
the commands their docstrings document."""

from __future__ import annotations

import ast
import importlib.util
import io
import shlex
import sys
import tokenize
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


def _docstring(source: str) -> str | None:
    """``ast.get_docstring`` of the module ``source``, parsing its first statement only.

    Every test process reads the examples' docstrings at collection; parsing each whole
    example cost several times more. The docstring is the first statement: the lines up
    to the end of the first logical line hold it (or show there is none). A first line
    that does not parse alone (a ``def`` or ``class`` header) is parsed with the rest.
    """
    lines: list[str] = []
    readline = io.StringIO(source).readline

    def read() -> str:
        lines.append(readline())
        return lines[-1]

    for token in tokenize.generate_tokens(read):
        if token.type in (tokenize.NEWLINE, tokenize.ENDMARKER):
            break
    try:
        return ast.get_docstring(ast.parse("".join(lines)))
    except SyntaxError:
        return ast.get_docstring(ast.parse(source))


def documented_commands(name: str) -> list[list[list[str]]]:
    """The command lines of ``examples/<name>.py``'s docstring, in blocks, split like a shell.

    A command line is one whose text starts with ``python ``; consecutive command lines
    form one block (run together: simulators, then the example). A trailing ``&`` (run
    in the background) is dropped.
    """
    source = (EXAMPLES / f"{name}.py").read_text(encoding="utf-8")
    docstring = _docstring(source) or ""
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
