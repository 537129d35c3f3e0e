"""Lazy public namespaces: a package exposes its names without importing every module.

``import tmmaster`` must stay cheap (a script that only needs the exceptions, or a
command whose Ctrl-C handler must be in place before pymodbus and pydantic load), so
each package maps its public names to the private module defining them and imports a
module on first access (PEP 562 module ``__getattr__``). Type checkers see ordinary
imports under ``TYPE_CHECKING``.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable, Mapping
from typing import Any


def lazy_attributes(
    package: str,
    namespace: dict[str, Any],
    exports: Mapping[str, str],
    computed: Mapping[str, Callable[[], Any]] | None = None,
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for ``package`` exporting ``{name: ".module"}``.

    ``computed`` names are produced by a function on first access (e.g. ``__version__``).
    """
    computed = computed or {}

    def getattr_(name: str) -> Any:
        module = exports.get(name)
        if module is not None:
            value = getattr(importlib.import_module(module, package), name)
            _rehome(value, package)
        elif name in computed:
            value = computed[name]()
        else:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        namespace[name] = value  # later lookups are plain global lookups
        return value

    def dir_() -> list[str]:
        return sorted({*namespace, *exports, *computed})

    return getattr_, dir_


def _rehome(value: Any, package: str) -> None:
    """Show a public class or function as ``package.Name`` (tracebacks, reprs, docs).

    Only names defined in a private module of tmmaster (``tmmaster._x``,
    ``tmmaster.sim._x``): their private home is an implementation detail.
    """
    module = getattr(value, "__module__", None)
    if not (inspect.isclass(value) or inspect.isfunction(value)) or not isinstance(module, str):
        return
    if module.startswith("tmmaster.") and module.rsplit(".", 1)[-1].startswith("_"):
        value.__module__ = package
