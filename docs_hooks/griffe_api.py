"""Griffe extension: render the public API as a reader meets it.

Loaded by mkdocstrings (``extensions:`` in mkdocs.yml). What the source does that
static analysis would otherwise show wrong (the names involved: docs_hooks/api_names.py):

- ``#:`` comments above an assignment document it (the convention of the source, as
  Sphinx's autodoc reads it); Griffe only reads a string after the assignment.
- A public class deriving from a private helper class (``_OwnConnectionGripper``,
  ``BlockTransport``) is shown with the helper's own bases instead, and the helper's
  members as its own: the reader sees ``Blog2FG7Gripper(Gripper)`` with every method
  it has, and no name the reference does not document.
- ``tmmaster.connect`` and ``tmmaster.aio.connect`` are made at import time with
  ``Robot``'s signature (``connect = _connected(Robot)``): each is shown as the function
  it is, with ``Robot``'s parameters, its own return type and the docstring it has at
  run time.
- ``tmmaster.aio``'s methods are made at import time from the sync ones (``move_to =
  _awaited(Robot.move_to)``), or take their docstrings from them: each is shown as it
  is at run time, an ``async`` method with the sync method's parameters and the
  docstring made for it.
- A Protocol that stands for a public class in a signature (it breaks an import
  cycle: ``Fleet.latest(robot: _Closable)``) is shown as that class (``Robot``).
- Classes only the package makes (``Motion``) are shown without a constructor, and
  members that serve the package itself are left out.
- An attribute's value is shown unless it is an implementation detail: the value an
  ``__init__`` assigns (``self.gripper = self._make_gripper(...)``), or an expression
  naming something private (``MappingProxyType(_load_models())``).

tests/test_api_reference.py checks the same rules on the source, without a build.
"""

from __future__ import annotations

import ast
import functools
import importlib
import importlib.util
import inspect
import re
from pathlib import Path
from typing import Any

import griffe


def _load_names() -> Any:
    path = Path(__file__).with_name("api_names.py")
    spec = importlib.util.spec_from_file_location("tmmaster_docs_api_names", path)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


NAMES = _load_names()


@functools.cache
def _lines(filepath: str) -> list[str]:
    return Path(filepath).read_text(encoding="utf-8").splitlines()


def _comment_above(filepath: Path | list[Path] | None, lineno: int | None) -> str | None:
    """The ``#:`` comment lines right above line ``lineno`` (1-based), joined."""
    if not isinstance(filepath, Path) or lineno is None:
        return None
    lines = _lines(str(filepath))
    found: list[str] = []
    index = lineno - 2
    while index >= 0 and lines[index].strip().startswith("#:"):
        found.insert(0, lines[index].strip()[2:].strip())
        index -= 1
    return "\n".join(found) or None


class PublicAPI(griffe.Extension):
    """The three rules of the module docstring."""

    def on_attribute_instance(
        self, *, node: ast.AST | griffe.ObjectNode, attr: griffe.Attribute, **kwargs: Any
    ) -> None:
        """Document an attribute by the ``#:`` comment above it (when it has no string)."""
        _ = (node, kwargs)
        _hide_private_value(attr)
        if attr.docstring is not None:
            return
        text = _comment_above(attr.filepath, attr.lineno)
        if text:
            attr.docstring = griffe.Docstring(
                text, lineno=attr.lineno, endlineno=attr.lineno, parent=attr
            )

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        """Once the package is loaded: hide private bases, shape made-up functions."""
        _ = kwargs
        if pkg.name != "tmmaster":
            return
        for path in NAMES.INTERNAL_MEMBERS:
            owner, name = path.rsplit(".", 1)
            pkg.modules_collection.get_member(owner).del_member(name)
        for path in NAMES.MADE_BY_THE_PACKAGE:
            cls = pkg.modules_collection.get_member(path)
            # No __init__ made from dataclass fields either (Griffe's dataclasses extension).
            cls.labels.discard("dataclass")
            cls.decorators = [d for d in cls.decorators if "dataclass" not in str(d.value)]
            if "__init__" in cls.members:
                cls.del_member("__init__")
        public = _public_paths(pkg)
        for cls in _classes(pkg):
            if cls.path in public:
                _hide_private_bases(cls, public)
        for function_path, class_path in NAMES.MADE_LIKE.items():
            _shape_like(pkg, function_path, class_path)
        for class_path in NAMES.DERIVED:
            _show_as_run(pkg, class_path)
        _name_stand_ins(pkg)


_PRIVATE_NAME = re.compile(r"(?<![\w.])_[A-Za-z]\w*|\._\w+|\bself\.")


def _hide_private_value(attr: griffe.Attribute) -> None:
    """No value for an instance attribute, nor one that names something private."""
    if "instance-attribute" in attr.labels or (
        attr.value is not None and _PRIVATE_NAME.search(str(attr.value))
    ):
        attr.value = None


def _public_paths(pkg: griffe.Module) -> set[str]:
    """Canonical paths of every object a public package exports."""
    paths: set[str] = set()
    for package in NAMES.PAGES:
        module = pkg if package == "tmmaster" else pkg[package.removeprefix("tmmaster.")]
        for name in module.exports or ():
            if not isinstance(name, str) or name not in module.members:
                continue
            member = module.members[name]
            try:
                paths.add(member.final_target.path if member.is_alias else member.path)
            except griffe.AliasResolutionError:
                continue
    return paths


def _classes(obj: griffe.Object) -> list[griffe.Class]:
    found: list[griffe.Class] = []
    for member in obj.members.values():
        if member.is_alias:
            continue
        if isinstance(member, griffe.Class):
            found.append(member)
            found.extend(_classes(member))
        elif isinstance(member, griffe.Module):
            found.extend(_classes(member))
    return found


def _is_private(base: griffe.Class, public: set[str]) -> bool:
    """A base of the package that the reference does not show (underscore or unexported)."""
    if base.name.startswith("_"):
        return True
    return base.path.split(".")[0] == "tmmaster" and base.path not in public


def _hide_private_bases(cls: griffe.Class, public: set[str]) -> None:
    """Replace private bases by their bases, and take over their members."""
    bases: list[str | griffe.Expr] = []
    for expr, resolved in zip(cls.bases, _resolved(cls), strict=True):
        if resolved is None or not _is_private(resolved, public):
            bases.append(expr)
            continue
        for inner in _ancestors_shown(resolved, public):
            bases.append(inner)
        _adopt_members(cls, resolved, public)
    cls.bases = bases


def _resolved(cls: griffe.Class) -> list[griffe.Class | None]:
    found: list[griffe.Class | None] = []
    for base in cls.bases:
        target = None
        if isinstance(base, griffe.Expr):
            try:
                candidate = cls.modules_collection.get_member(base.canonical_path)
                target = candidate.final_target if candidate.is_alias else candidate
            except (KeyError, griffe.AliasResolutionError, ValueError):
                target = None
        found.append(target if isinstance(target, griffe.Class) else None)
    return found


def _ancestors_shown(base: griffe.Class, public: set[str]) -> list[str | griffe.Expr]:
    """The bases of a private base, with private ones replaced in turn.

    ``ABC`` is left out: it made the helper abstract, not the public class.
    """
    shown: list[str | griffe.Expr] = []
    for expr, resolved in zip(base.bases, _resolved(base), strict=True):
        if resolved is not None and _is_private(resolved, public):
            shown.extend(_ancestors_shown(resolved, public))
        elif str(expr) not in {"ABC", "abc.ABC"} and expr not in shown:
            shown.append(expr)
    return shown


def _adopt_members(cls: griffe.Class, base: griffe.Class, public: set[str]) -> None:
    """Show ``base``'s public members (and its private bases') as members of ``cls``."""
    for name, member in base.members.items():
        if name.startswith("_") and name != "__init__":
            continue
        if name in cls.members or name == "__init__":
            continue
        cls.set_member(name, griffe.Alias(name, member, parent=cls))
    for resolved in _resolved(base):
        if resolved is not None and _is_private(resolved, public):
            _adopt_members(cls, resolved, public)


def _shape_like(pkg: griffe.Module, function_path: str, class_path: str) -> None:
    """Turn the attribute at ``function_path`` into a function with the class's signature."""
    module_path, name = function_path.rsplit(".", 1)
    module = pkg.modules_collection.get_member(module_path)
    attribute = module.members[name]
    cls = pkg.modules_collection.get_member(class_path)
    init = cls.members["__init__"]
    parameters = griffe.Parameters(*[p for p in init.parameters if p.name != "self"])
    runtime = getattr(importlib.import_module(module_path), name)
    # What the function returns (``tmmaster.aio.connect``: an AsyncRobot), else the class.
    returns = getattr(runtime, "__annotations__", {}).get("return", cls.name)
    function = griffe.Function(
        name,
        lineno=attribute.lineno,
        endlineno=attribute.endlineno,
        parameters=parameters,
        returns=griffe.ExprName(str(returns), parent=module),
    )
    doc = inspect.getdoc(runtime)
    if doc:
        function.docstring = griffe.Docstring(
            doc, lineno=attribute.lineno, endlineno=attribute.endlineno, parent=function
        )
    module.set_member(name, function)


def _show_as_run(pkg: griffe.Module, class_path: str) -> None:
    """Show the members of ``class_path`` made at import time as they are at run time."""
    cls = pkg.modules_collection.get_member(class_path)
    module_path, name = class_path.rsplit(".", 1)
    runtime = getattr(importlib.import_module(module_path), name)
    for member_name, member in list(cls.members.items()):
        if member.is_alias or member_name.startswith("_"):
            continue
        value = inspect.getattr_static(runtime, member_name, None)
        made_from = getattr(value, "__wrapped__", None)
        if isinstance(member, griffe.Attribute) and inspect.isfunction(made_from):
            cls.set_member(member_name, _awaited_method(pkg, cls, member, value, made_from))
        elif (doc := inspect.getdoc(value)) and doc != getattr(member.docstring, "value", None):
            member.docstring = _docstring_like(cls, doc, member)  # set at import time


def _awaited_method(
    pkg: griffe.Module, cls: griffe.Class, member: griffe.Object, value: Any, sync: Any
) -> griffe.Function:
    """An ``async`` method with ``sync``'s parameters and ``value``'s docstring."""
    made_from = pkg.modules_collection.get_member(f"{sync.__module__}.{sync.__qualname__}")
    returns = inspect.signature(value).return_annotation
    same = returns == inspect.signature(sync).return_annotation
    function = griffe.Function(
        member.name,
        lineno=member.lineno,
        endlineno=member.endlineno,
        # Copies: a Function takes its parameters as its own (``parameter.function``).
        parameters=griffe.Parameters(
            *[
                griffe.Parameter(p.name, annotation=p.annotation, kind=p.kind, default=p.default)
                for p in made_from.parameters
            ]
        ),
        returns=made_from.returns if same else griffe.ExprName(str(returns), parent=cls),
    )
    function.labels.add("async")
    function.docstring = _docstring_like(cls, inspect.getdoc(value) or "", function)
    return function


def _docstring_like(cls: griffe.Class, text: str, owner: griffe.Object) -> griffe.Docstring:
    """``owner``'s docstring ``text``, parsed as the class's own (Google style)."""
    model = cls.docstring
    return griffe.Docstring(
        text,
        lineno=owner.lineno,
        endlineno=owner.endlineno,
        parent=owner,
        parser=None if model is None else model.parser,
        parser_options=None if model is None else model.parser_options,
    )


def _name_stand_ins(pkg: griffe.Module) -> None:
    """Show the public class where a signature names a Protocol standing for it."""
    for obj in _callables_and_attributes(pkg):
        expressions: list[Any] = []
        if isinstance(obj, griffe.Function):
            expressions += [p.annotation for p in obj.parameters]
            expressions.append(obj.returns)
        else:
            expressions.append(obj.annotation)
        for expression in expressions:
            if not isinstance(expression, griffe.Expr):
                continue
            for name in expression.iterate(flat=True):
                if not isinstance(name, griffe.ExprName):
                    continue
                try:
                    public = NAMES.STAND_INS.get(name.canonical_path)
                except Exception:  # a name Griffe cannot resolve
                    continue
                if public is not None:
                    package, short = public.rsplit(".", 1)
                    name.name = short
                    name.parent = pkg.modules_collection.get_member(package)


def _callables_and_attributes(obj: griffe.Object) -> list[griffe.Object]:
    found: list[griffe.Object] = []
    for member in obj.members.values():
        if member.is_alias:
            continue
        if isinstance(member, griffe.Function | griffe.Attribute):
            found.append(member)
        elif isinstance(member, griffe.Class | griffe.Module):
            found.extend(_callables_and_attributes(member))
    return found
