"""A long TMscript's syntax tree is kept in this user's private cache folder, read back
when the same script is parsed again, and never from a file another user could plant."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from tmmaster.tmscript import _grammar_cache, _parser
from tmmaster.tmscript._parser import parse_script

pytestmark = pytest.mark.skipif(not hasattr(os, "getuid"), reason="user ids (POSIX)")

SHORT = 'main\n{\n    int x = 1 + 2\n    Display("x " + x)\n}\n'


def _long_script(n: int = 0) -> str:
    """A script of ``KEEP_PARSED_CHARS`` or more (a long comment: quick to parse); ``n``
    makes it another one."""
    comment = "// " + "x" * _grammar_cache.KEEP_PARSED_CHARS
    return f"{comment}\nmain\n{{\n    int v = 1 + {n}\n    Display(v)\n}}\n"


@pytest.fixture
def folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The private cache folder, in an empty XDG cache home (created on first use)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache-home"))
    return tmp_path / "cache-home" / _grammar_cache.FOLDER_NAME


def _trees(folder: Path) -> list[Path]:
    return sorted(folder.glob("tmscript-tree-*.pickle")) if folder.is_dir() else []


def _not_parsed(text: str) -> None:
    raise AssertionError("parsed by lark, not read back from the kept tree")


def test_a_long_scripts_tree_is_kept_and_read_back_instead_of_parsed(
    folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    text = _long_script()
    parsed = parse_script(text)
    (kept,) = _trees(folder)
    info = os.lstat(kept)
    assert stat.S_ISREG(info.st_mode)
    assert stat.S_IMODE(info.st_mode) & 0o077 == 0  # this user's only
    assert parse_script(SHORT) == parse_script(SHORT)
    assert _trees(folder) == [kept]  # a short script is parsed each time
    monkeypatch.setattr(_parser, "_parse", _not_parsed)
    assert parse_script(text) == parsed


def test_a_tree_file_that_cannot_be_read_back_is_parsed_again_and_rewritten(
    folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    text = _long_script()
    parsed = parse_script(text)
    (kept,) = _trees(folder)
    kept.write_bytes(b"cut short")  # as if another process were writing it
    assert parse_script(text) == parsed
    monkeypatch.setattr(_parser, "_parse", _not_parsed)
    assert parse_script(text) == parsed  # rewritten whole


def test_a_tree_planted_behind_a_link_is_not_read(folder: Path, tmp_path: Path) -> None:
    text, other = _long_script(1), _long_script(2)
    parse_script(other)
    (planted,) = _trees(folder)
    path = _grammar_cache.parsed_file(text)
    assert path is not None
    elsewhere = tmp_path / "planted.pickle"
    planted.rename(elsewhere)
    Path(path).symlink_to(elsewhere)  # the tree of another script
    assert _grammar_cache.parsed_file(text) is None
    assert parse_script(text) == _parser._parse(text)
    assert Path(path).is_symlink()  # left as it was, nothing written through it
    Path(path).unlink()
    parse_script(text)
    assert Path(path).is_file()  # where the tree goes when no link is in the way


def test_a_folder_others_may_enter_gets_no_tree(folder: Path) -> None:
    folder.mkdir(parents=True)
    folder.chmod(0o755)
    text = _long_script()
    assert parse_script(text) == _parser._parse(text)
    assert _trees(folder) == []
    folder.chmod(0o700)  # this user's alone: the tree is kept
    parse_script(text)
    assert len(_trees(folder)) == 1


def test_only_the_most_recently_used_trees_are_kept(
    folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(_grammar_cache, "KEEP_PARSED_FILES", 2)
    first, second, third = (_long_script(n) for n in (1, 2, 3))
    parse_script(first)
    parse_script(second)
    paths = {text: Path(str(_grammar_cache.parsed_file(text))) for text in (first, second)}
    os.utime(paths[first], (1000, 1000))
    os.utime(paths[second], (2000, 2000))
    parse_script(first)  # read back: now the most recently used
    parse_script(third)
    assert set(_trees(folder)) == {paths[first], Path(str(_grammar_cache.parsed_file(third)))}


def test_a_tree_is_named_by_the_script_and_by_the_parsers_sources(
    folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    text = _long_script()
    path = _grammar_cache.parsed_file(text)
    assert path is not None
    assert _grammar_cache.parsed_file(_long_script(1)) != path
    read: list[str] = []
    real_read_bytes = Path.read_bytes

    def read_bytes(self: Path) -> bytes:
        read.append(self.name)
        return real_read_bytes(self)

    monkeypatch.setattr(Path, "read_bytes", read_bytes)
    sources = _grammar_cache._sources_digest.__wrapped__()  # type: ignore[attr-defined]
    assert {"grammar.lark", "_parser.py", "_ast.py", "_types.py"} <= set(read)
    monkeypatch.setattr(_grammar_cache, "_sources_digest", lambda: sources + "changed")
    assert _grammar_cache.parsed_file(text) not in (path, None)
