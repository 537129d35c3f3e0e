"""The API reference is complete: what the docs site renders, checked from the source.

The reference (docs/api/*.md, mkdocstrings) renders every public name of the public
packages from its docstrings (Google style) and its signature as written in the source.
Building the site takes too long for a test, so this reads the same things directly
(``inspect`` and ``ast``; the few names shown differently on the site are listed once,
in docs_hooks/api_names.py):

- every public name has a docstring (a constant or a type alias: a string right after
  its assignment or ``#:`` comments right above it);
- every public function, method and constructor with parameters has an ``Args:``
  section naming each of them, and one that returns something has ``Returns:`` (or
  ``Yields:``);
- every public attribute of a public class (fields, class attributes, ``self.x`` set by
  ``__init__``) is documented, on its own or in the class's ``Attributes:`` section;
- no rendered signature, base class or attribute type names something private: an
  underscore name, a private module (``kin.Transform``) or a class of the package that
  no public package exports (an attribute's value naming one is not shown);
- each docs/api page renders its package, or each of its public names;
- a method made at import time from another class's (``move_to =
  _awaited(Robot.move_to)``) is checked as the method the site shows: that one's
  parameters, the docstring it has at run time; its class is listed for the site.
"""

from __future__ import annotations

import ast
import builtins
import collections
import enum
import importlib
import importlib.util
import inspect
import json
import re
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _load_names() -> Any:
    path = ROOT / "docs_hooks" / "api_names.py"
    spec = importlib.util.spec_from_file_location("tmmaster_docs_api_names", path)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


NAMES = _load_names()

_SECTION = re.compile(r"^(\w[\w ]*):\s*$")
_ARGS_SECTIONS = {"Args", "Arguments", "Parameters", "Keyword Args", "Keyword Arguments"}
_ATTRIBUTE_SECTIONS = {"Attributes"}
_RETURN_SECTIONS = {"Returns", "Yields"}

Function = ast.FunctionDef | ast.AsyncFunctionDef


@dataclass(frozen=True)
class Public:
    """One public name: where it is exported and what it is."""

    qualname: str
    value: Any


def _public_names() -> list[Public]:
    found = []
    for package in NAMES.PAGES:
        module = importlib.import_module(package)
        for name in module.__all__:
            found.append(Public(f"{package}.{name}", getattr(module, name)))
    return found


PUBLIC = _public_names()
PUBLIC_IDS = frozenset(id(entry.value) for entry in PUBLIC)


# -- source ------------------------------------------------------------------------------


@cache
def _source(module_name: str) -> str:
    return Path(inspect.getfile(importlib.import_module(module_name))).read_text("utf-8")


@cache
def _module_tree(module_name: str) -> ast.Module:
    return ast.parse(_source(module_name))


def _absolute(module_name: str, level: int, name: str | None) -> str:
    if level == 0:
        return name or ""
    base = module_name.split(".")
    if not hasattr(importlib.import_module(module_name), "__path__"):
        base = base[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join([*base, name] if name else base)


#: Where an import can be: a statement, never part of an expression.
_STATEMENTS = ast.stmt | ast.excepthandler | ast.match_case


def _walk_statements(tree: ast.AST) -> Iterator[ast.AST]:
    """``ast.walk(tree)``'s nodes that are statements, in its order, without visiting any
    expression (none holds a statement)."""
    todo: collections.deque[ast.AST] = collections.deque([tree])
    while todo:
        node = todo.popleft()
        todo.extend(child for child in ast.iter_child_nodes(node) if isinstance(child, _STATEMENTS))
        yield node


@cache
def _imports_of(module_name: str) -> dict[str, tuple[str, str | None]]:
    """``{local name: (module, name in it, or None for the module)}``: every import."""
    bound: dict[str, tuple[str, str | None]] = {}
    for node in _walk_statements(_module_tree(module_name)):
        if isinstance(node, ast.ImportFrom):
            source = _absolute(module_name, node.level, node.module)
            for alias in node.names:
                bound[alias.asname or alias.name] = (source, alias.name)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname:
                    bound[alias.asname] = (alias.name, None)
                else:
                    head = alias.name.split(".")[0]
                    bound[head] = (head, None)
    return bound


_MISSING = object()


def _resolve(module_name: str, name: str) -> Any:
    """What ``name`` means in ``module_name`` (imports under TYPE_CHECKING included)."""
    value = vars(importlib.import_module(module_name)).get(name, _MISSING)
    if value is not _MISSING:
        return value
    imported = _imports_of(module_name).get(name)
    if imported is not None:
        source, attribute = imported
        if attribute is None:
            return importlib.import_module(source)
        try:
            return importlib.import_module(f"{source}.{attribute}")
        except ImportError:
            return getattr(importlib.import_module(source), attribute, _MISSING)
    return getattr(builtins, name, _MISSING)


def _assigned_name(node: ast.stmt) -> str | None:
    if isinstance(node, ast.Assign) and len(node.targets) == 1:
        target = node.targets[0]
        return target.id if isinstance(target, ast.Name) else None
    if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
        return node.target.id
    type_alias = getattr(ast, "TypeAlias", None)  # ``type X = ...`` (3.12)
    if type_alias is not None and isinstance(node, type_alias):
        return node.name.id  # type: ignore[attr-defined, no-any-return]
    return None


def _defining_module(package: str, name: str) -> str:
    """The module whose source assigns ``name``, following re-exports."""
    module_name = package
    for _ in range(10):
        if any(_assigned_name(node) == name for node in _module_tree(module_name).body):
            return module_name
        imported = _imports_of(module_name).get(name)
        if imported is None or imported[1] is None:
            break
        module_name = imported[0]
    raise AssertionError(f"{package}.{name}: no assignment found")


def _attribute_doc(module_name: str, body: list[ast.stmt], index: int) -> str | None:
    """The docstring of the assignment ``body[index]``: ``#:`` comment lines right above
    it, or a string right after it (the site reads both: docs_hooks/griffe_api.py).
    """
    lines = _source(module_name).splitlines()
    above = body[index].lineno - 2
    comments: list[str] = []
    while above >= 0 and lines[above].strip().startswith("#:"):
        comments.insert(0, lines[above].strip()[2:].strip())
        above -= 1
    if comments:
        return "\n".join(comments)
    if index + 1 < len(body):
        following = body[index + 1]
        if isinstance(following, ast.Expr) and isinstance(following.value, ast.Constant):
            text = following.value.value
            if isinstance(text, str) and text.strip():
                return inspect.cleandoc(text)
    return None


@cache
def _home_module(value: Any) -> str:
    """The module whose source defines a class or function (public ones are rehomed)."""
    for module_name, module in sorted(sys.modules.items()):
        if module_name.split(".")[0] != "tmmaster" or module is None:
            continue
        if vars(module).get(value.__name__) is not value:
            continue
        for node in _module_tree(module_name).body:
            if value.__name__ in (getattr(node, "name", None), _assigned_name(node)):
                return module_name
    raise AssertionError(f"no source for {value!r}")


def _path(value: Any) -> str:
    """Where the source defines a class: ``tmmaster._robot.Robot``."""
    return f"{_home_module(value)}.{value.__name__}"


@cache
def _class_node(cls: type) -> ast.ClassDef:
    for node in _module_tree(_home_module(cls)).body:
        if isinstance(node, ast.ClassDef) and node.name == cls.__name__:
            return node
    raise AssertionError(cls)


def _function_node(function: Any) -> Function:
    for node in _module_tree(_home_module(function)).body:
        if isinstance(node, Function) and node.name == function.__name__:
            return node
    raise AssertionError(function)


def _made_from(owner: type, name: str) -> Any:
    """The method a class attribute was made from at import time (``move_to =
    _awaited(Robot.move_to)``), or None: a function that names what it wraps."""
    value = inspect.getattr_static(owner, name, None)
    if inspect.isfunction(value) and inspect.isfunction(getattr(value, "__wrapped__", None)):
        return value.__wrapped__
    return None


def _method_source(method: Any) -> tuple[str, Function]:
    """The module and the ``def`` of a method of a class of the package."""
    owner = getattr(sys.modules[method.__module__], method.__qualname__.split(".")[0])
    for item in _class_node(owner).body:
        if isinstance(item, Function) and item.name == method.__name__:
            return _home_module(owner), item
    raise AssertionError(method)


# -- docstrings --------------------------------------------------------------------------


def _sections(docstring: str) -> dict[str, list[str]]:
    """Google-style sections: ``{"Args": [its lines], ...}`` (the text before them: "")."""
    sections: dict[str, list[str]] = {"": []}
    current = ""
    in_fence = False
    for line in docstring.splitlines():
        if line.strip().startswith("```"):
            in_fence = not in_fence
        match = None if in_fence or line.startswith(" ") else _SECTION.match(line)
        if match:
            current = match[1]
            sections.setdefault(current, [])
        else:
            sections[current].append(line)
    return sections


def _entries(docstring: str, kinds: set[str]) -> set[str]:
    """The names that a docstring's sections of ``kinds`` describe (``name: ...``)."""
    names: set[str] = set()
    for title, lines in _sections(docstring).items():
        if title in kinds:
            for line in lines:
                match = re.match(r"^    (\*{0,2}\w+)(?: \([^)]*\))?:", line)
                if match:
                    names.add(match[1].lstrip("*"))
    return names


def _own_docstring(value: Any) -> str | None:
    if inspect.isclass(value):
        doc = vars(value).get("__doc__")
        if not isinstance(doc, str) or doc.startswith(f"{value.__name__}("):
            return None  # none, or a dataclass's generated one
    else:
        doc = getattr(value, "__doc__", None)
    return inspect.cleandoc(doc) if isinstance(doc, str) and doc.strip() else None


def _decorators(node: Function) -> set[str]:
    return {ast.unparse(d).split("(")[0].split(".")[-1] for d in node.decorator_list}


def _parameters(node: Function, *, method: bool) -> list[str]:
    args = node.args
    names = [a.arg for a in (*args.posonlyargs, *args.args)]
    if method and names and "staticmethod" not in _decorators(node):
        names = names[1:]
    names += [a.arg for a in args.kwonlyargs]
    names += [a.arg for a in (args.vararg, args.kwarg) if a is not None]
    return [name for name in names if not name.startswith("_")]  # ``*_``: ignored


def _returns_something(node: Function) -> bool:
    if node.returns is None or node.name == "__init__":
        return False
    if _decorators(node) & {"property", "cached_property"}:
        return False  # the summary says what it is
    return ast.unparse(node.returns).strip("'\"") not in {"None", "NoReturn", "Never"}


# -- what the reference renders ------------------------------------------------------


@dataclass(frozen=True)
class Rendered:
    """One function or method the reference shows: its source and docstring."""

    where: str
    module: str
    node: Function
    docstring: str | None
    method: bool


def _shown_classes(cls: type) -> list[type]:
    """``cls`` and its private bases: the reference shows their members as its own (a
    public base's members are on the base's own entry)."""
    return [
        c
        for c in cls.__mro__
        if c.__module__.split(".")[0] == "tmmaster" and (c is cls or id(c) not in PUBLIC_IDS)
    ]


def _is_internal(owner: type, name: str) -> bool:
    return f"{_path(owner)}.{name}" in NAMES.INTERNAL_MEMBERS


def _class_members(entry: Public) -> Iterator[Rendered]:
    cls = entry.value
    seen: set[str] = set()
    for owner in _shown_classes(cls):
        module = _home_module(owner)
        for item in _class_node(owner).body:
            made = _made_method(entry, owner, item)
            if made is not None:
                yield made
                continue
            if not isinstance(item, Function) or item.name in seen:
                continue
            name = item.name
            if name.startswith("_") and name != "__init__":
                continue
            if _decorators(item) & {"overload", "setter", "deleter"} or _is_internal(owner, name):
                continue
            seen.add(name)
            member = inspect.getattr_static(owner, name)
            if isinstance(member, property):
                member = member.fget
            elif isinstance(member, staticmethod | classmethod):
                member = member.__func__
            doc = _own_docstring(member)
            if name != "__init__":
                yield Rendered(f"{entry.qualname}.{name}", module, item, doc, method=True)
            elif owner is cls and _path(cls) not in NAMES.MADE_BY_THE_PACKAGE:
                # Rendered with the class (merge_init_into_class): either docstring.
                both = "\n\n".join(d for d in (_own_docstring(cls), doc) if d)
                where = f"{entry.qualname} (class or __init__ docstring)"
                yield Rendered(where, module, item, both or None, method=True)


def _made_method(entry: Public, owner: type, item: ast.stmt) -> Rendered | None:
    """A public method made at import time (``move_to = _awaited(Robot.move_to)``): shown
    with the parameters of the method it was made from and its own docstring."""
    name = _assigned_name(item)
    if name is None or name.startswith("_") or (made_from := _made_from(owner, name)) is None:
        return None
    module, node = _method_source(made_from)
    doc = _own_docstring(inspect.getattr_static(owner, name))
    return Rendered(f"{entry.qualname}.{name}", module, node, doc, method=True)


def _callables() -> Iterator[Rendered]:
    for entry in PUBLIC:
        value = entry.value
        if inspect.isclass(value):
            yield from _class_members(entry)
        elif inspect.isfunction(value) and _path(value) not in NAMES.MADE_LIKE:
            node = _function_node(value)
            doc = _own_docstring(value)
            yield Rendered(entry.qualname, _home_module(value), node, doc, method=False)


def _self_assignments(init: Function) -> Iterator[tuple[str, list[ast.stmt], int]]:
    """``(name, body, index)`` of every ``self.name = ...`` in ``__init__``."""
    for block in ast.walk(init):
        body = getattr(block, "body", None)
        if not isinstance(body, list):
            continue
        for index, statement in enumerate(body):
            target: ast.expr | None = None
            if isinstance(statement, ast.Assign) and len(statement.targets) == 1:
                target = statement.targets[0]
            elif isinstance(statement, ast.AnnAssign):
                target = statement.target
            if (
                isinstance(target, ast.Attribute)
                and isinstance(target.value, ast.Name)
                and target.value.id == "self"
            ):
                yield target.attr, body, index


def _undocumented_attributes(cls: type) -> Iterator[str]:
    """Public attributes of ``cls`` (and its package bases) that have no docstring."""
    listed = _entries(_own_docstring(cls) or "", _ATTRIBUTE_SECTIONS)
    for owner in _shown_classes(cls):
        module = _home_module(owner)
        node = _class_node(owner)
        found: list[tuple[str, list[ast.stmt], int]] = [
            (name, node.body, index)
            for index, item in enumerate(node.body)
            if (name := _assigned_name(item)) is not None
        ]
        for item in node.body:
            if isinstance(item, ast.FunctionDef) and item.name == "__init__":
                found += _self_assignments(item)
        for name, body, index in found:
            if name.startswith("_") or name in listed or name == "model_config":
                continue
            if _made_from(owner, name) is not None:
                continue  # a method: checked as one (_made_method)
            if _is_internal(owner, name):
                continue
            if isinstance(inspect.getattr_static(owner, name, None), property):
                continue
            listed.add(name)
            if _attribute_doc(module, body, index) is None:
                yield name


# -- private names ---------------------------------------------------------------------


def _expressions(node: Function) -> Iterator[ast.expr]:
    args = node.args
    for arg in (*args.posonlyargs, *args.args, *args.kwonlyargs, args.vararg, args.kwarg):
        if arg is not None and arg.annotation is not None:
            yield arg.annotation
    yield from (d for d in (*args.defaults, *args.kw_defaults) if d is not None)
    if node.returns is not None:
        yield node.returns


def _private_parts(expression: ast.expr, module_name: str) -> Iterator[str]:
    """What a rendered expression names that the reference does not show."""
    for node in ast.walk(expression):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            try:  # a forward reference: "Robot"
                inner = ast.parse(node.value, mode="eval").body
            except SyntaxError:
                continue
            if not isinstance(inner, ast.Constant):
                yield from _private_parts(inner, module_name)
        elif isinstance(node, ast.Attribute) and node.attr.startswith("_"):
            yield ast.unparse(node)
        elif isinstance(node, ast.Name):
            value = _resolve(module_name, node.id)
            if inspect.isclass(value) and value.__module__.split(".")[0] == "tmmaster":
                if _path(value) in NAMES.STAND_INS:
                    continue  # shown as the public class it stands for
                if id(value) not in PUBLIC_IDS:
                    yield f"{node.id} (not exported by a public package)"
            elif node.id.startswith("_"):
                yield node.id
            elif inspect.ismodule(value) and any(
                part.startswith("_") for part in value.__name__.split(".")
            ):
                yield f"{node.id} (the private module {value.__name__})"


def _shown_bases(cls: type) -> Iterator[tuple[ast.expr, str]]:
    """The bases the reference shows: a private base is replaced by its own bases."""
    module = _home_module(cls)
    for base in _class_node(cls).bases:
        value = _resolve(module, ast.unparse(base).split(".")[0].split("[")[0])
        private = inspect.isclass(value) and (
            value.__name__.startswith("_")
            or (value.__module__.split(".")[0] == "tmmaster" and id(value) not in PUBLIC_IDS)
        )
        if private:
            yield from ((b, m) for b, m in _shown_bases(value) if ast.unparse(b) != "ABC")
        else:
            yield base, module


def _signature_problems() -> Iterator[str]:
    for rendered in _callables():
        for expression in _expressions(rendered.node):
            for part in _private_parts(expression, rendered.module):
                yield f"{rendered.where}: {part}"
    for entry in PUBLIC:
        cls = entry.value
        if not inspect.isclass(cls):
            continue
        for base, module in _shown_bases(cls):
            for part in _private_parts(base, module):
                yield f"{entry.qualname} base: {part}"
        for owner in _shown_classes(cls):
            module = _home_module(owner)
            for item in _class_node(owner).body:
                name = _assigned_name(item)
                if name is None or name.startswith("_") or _is_internal(owner, name):
                    continue
                # The type only: a value naming something private is not shown.
                annotation = getattr(item, "annotation", None)
                if isinstance(annotation, ast.expr):
                    for part in _private_parts(annotation, module):
                        yield f"{entry.qualname}.{name}: {part}"
    for entry in PUBLIC:
        if inspect.isclass(entry.value) or inspect.isfunction(entry.value):
            continue
        if entry.qualname in NAMES.NOT_RENDERED:
            continue
        package, name = entry.qualname.rsplit(".", 1)
        module = _defining_module(package, name)
        for item in _module_tree(module).body:
            annotation = getattr(item, "annotation", None)
            if _assigned_name(item) == name and isinstance(annotation, ast.expr):
                for part in _private_parts(annotation, module):
                    yield f"{entry.qualname}: {part}"


# -- the tests -----------------------------------------------------------------------


def test_every_public_name_has_a_docstring() -> None:
    missing = []
    for entry in PUBLIC:
        if entry.qualname in NAMES.NOT_RENDERED:
            continue
        value = entry.value
        if inspect.isclass(value) or inspect.isfunction(value):
            if _own_docstring(value) is None:
                missing.append(entry.qualname)
            continue
        package, name = entry.qualname.rsplit(".", 1)
        module_name = _defining_module(package, name)
        body = _module_tree(module_name).body
        index = next(i for i, node in enumerate(body) if _assigned_name(node) == name)
        if _attribute_doc(module_name, body, index) is None:
            missing.append(f"{entry.qualname} (in {module_name})")
    assert missing == [], "public names without a docstring"


def test_every_public_callable_documents_its_arguments_and_result() -> None:
    problems = []
    for rendered in _callables():
        doc = rendered.docstring
        if not doc:
            problems.append(f"{rendered.where}: no docstring")
            continue
        parameters = _parameters(rendered.node, method=rendered.method)
        documented = _entries(doc, _ARGS_SECTIONS)
        undocumented = [p for p in parameters if p not in documented]
        if undocumented:
            problems.append(f"{rendered.where}: Args lacks {', '.join(undocumented)}")
        unknown = sorted(documented - set(parameters))
        if unknown:
            problems.append(f"{rendered.where}: Args names no parameter {', '.join(unknown)}")
        if _returns_something(rendered.node) and not set(_sections(doc)) & _RETURN_SECTIONS:
            problems.append(f"{rendered.where}: no Returns section")
    assert problems == []


def test_every_public_attribute_is_documented() -> None:
    problems = []
    for entry in PUBLIC:
        cls = entry.value
        if not inspect.isclass(cls) or issubclass(cls, BaseException | enum.Enum):
            continue  # exceptions' attributes: their docstring; enum members: their values
        problems += [f"{entry.qualname}.{name}" for name in _undocumented_attributes(cls)]
    assert problems == []


def test_no_rendered_signature_names_something_private() -> None:
    assert sorted(set(_signature_problems())) == []


def test_functions_made_like_a_class_take_its_arguments() -> None:
    for function_path, class_path in NAMES.MADE_LIKE.items():
        module, name = function_path.rsplit(".", 1)
        function = getattr(importlib.import_module(module), name)
        module, name = class_path.rsplit(".", 1)
        cls = getattr(importlib.import_module(module), name)
        made = inspect.signature(function)
        assert made.parameters == inspect.signature(cls).parameters, function_path
        # What the function returns (a Robot, an AsyncRobot), not the constructor's None.
        assert made.return_annotation == function.__annotations__["return"], function_path
        assert _own_docstring(function), function_path


def _set_at_import_time(owner: type) -> Iterator[str]:
    """Public members of ``owner`` made at import time, or given their docstring then."""
    for item in _class_node(owner).body:
        if isinstance(item, Function):
            if item.name.startswith("_") or _decorators(item) & {"overload", "setter", "deleter"}:
                continue
            if _own_docstring(inspect.getattr_static(owner, item.name)) != ast.get_docstring(item):
                yield item.name
        elif (name := _assigned_name(item)) is not None and _made_from(owner, name) is not None:
            yield name


def test_classes_with_methods_made_at_import_time_are_shown_as_they_run() -> None:
    """The site shows a method made at import time, or a docstring set then, only for a
    class in ``DERIVED`` (docs_hooks/griffe_api.py); else it would show an attribute."""
    unlisted = []
    for entry in PUBLIC:
        cls = entry.value
        if not inspect.isclass(cls) or _path(cls) in NAMES.DERIVED:
            continue
        for owner in _shown_classes(cls):
            unlisted += [f"{entry.qualname}.{name}" for name in _set_at_import_time(owner)]
    assert unlisted == []


def _lookup(path: str) -> Any:
    """The object at a dotted source path: ``tmmaster._robot.Motion``, a member of it."""
    parts = path.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            value: Any = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for part in parts[cut:]:
            fields = getattr(value, "__dataclass_fields__", {})
            value = inspect.getattr_static(value, part, fields.get(part, _MISSING))
            if value is _MISSING:
                break
        return value
    return _MISSING


def test_the_names_shown_differently_exist() -> None:
    listed = [
        *NAMES.STAND_INS,
        *NAMES.STAND_INS.values(),
        *NAMES.MADE_BY_THE_PACKAGE,
        *NAMES.INTERNAL_MEMBERS,
        *NAMES.MADE_LIKE,
        *NAMES.MADE_LIKE.values(),
        *NAMES.DERIVED,
    ]
    assert [path for path in listed if _lookup(path) is _MISSING] == []


def _directives(page: str) -> Iterator[tuple[str, dict[str, Any]]]:
    """``(identifier, options)`` of each ``::: identifier`` block of a docs page."""
    lines = page.splitlines()
    for index, line in enumerate(lines):
        if not line.startswith("::: "):
            continue
        options: dict[str, Any] = {}
        for option in lines[index + 1 :]:
            if not option.startswith("    "):
                break
            key, _, value = option.strip().partition(":")
            if value.strip():
                options[key] = json.loads(value.strip()) if "[" in value else value.strip()
        yield line[4:].strip(), options


def _kept(name: str, filters: list[str]) -> bool:
    """Whether mkdocstrings' ``filters`` keep ``name``: the last matching filter decides;
    no match keeps it unless every filter is an inclusion."""
    kept: bool | None = None
    for pattern in filters:
        if re.search(pattern.removeprefix("!"), name):
            kept = not pattern.startswith("!")
    if kept is None:
        return any(pattern.startswith("!") for pattern in filters)
    return kept


@pytest.mark.parametrize("package", NAMES.PAGES)
def test_each_page_renders_every_public_name(package: str) -> None:
    page = (ROOT / NAMES.PAGES[package]).read_text("utf-8")
    rendered: set[str] = set(NAMES.NOT_RENDERED)
    module = importlib.import_module(package)
    for identifier, options in _directives(page):
        if identifier != package:
            rendered.add(identifier)
        elif options.get("members") != "false":
            filters = options.get("filters", ["!^_"])
            rendered |= {f"{package}.{n}" for n in module.__all__ if _kept(n, filters)}
    missing = [name for name in module.__all__ if f"{package}.{name}" not in rendered]
    assert missing == [], f"{NAMES.PAGES[package]} does not render these"
