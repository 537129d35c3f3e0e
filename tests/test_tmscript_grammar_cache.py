"""The TMscript parser's tables are cached only in a private folder of this user's."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from tmmaster.tmscript import _grammar_cache
from tmmaster.tmscript._parser import build_parser

pytestmark = pytest.mark.skipif(not hasattr(os, "getuid"), reason="user ids (POSIX)")

GRAMMAR = (Path(_grammar_cache.__file__).parent / "grammar.lark").read_text(encoding="utf-8")
SCRIPT = 'main\n{\n    int x = 1 + 2\n    Display("x " + x)\n}\n'


@pytest.fixture
def cache_home(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty XDG cache home."""
    home = tmp_path / "cache-home"
    monkeypatch.setenv("XDG_CACHE_HOME", str(home))
    return home


def test_the_tables_are_kept_in_a_folder_only_this_user_may_enter(cache_home: Path) -> None:
    path = _grammar_cache.cache_file(GRAMMAR)
    assert path is not None
    folder = cache_home / _grammar_cache.FOLDER_NAME
    assert Path(path).parent == folder
    info = os.lstat(folder)
    assert stat.S_ISDIR(info.st_mode)
    assert stat.S_IMODE(info.st_mode) & 0o077 == 0
    assert info.st_uid == os.getuid()

    built = build_parser(GRAMMAR, path)
    assert Path(path).is_file()
    loaded = build_parser(GRAMMAR, path)
    assert loaded.source_path == "<deserialized>"  # lark read the tables back
    assert loaded.parse(SCRIPT) == built.parse(SCRIPT)


def test_a_folder_others_may_enter_is_not_used(cache_home: Path) -> None:
    folder = cache_home / _grammar_cache.FOLDER_NAME
    folder.mkdir(parents=True)
    folder.chmod(0o755)
    assert _grammar_cache.private_folder() is None
    assert _grammar_cache.cache_file(GRAMMAR) is None
    assert stat.S_IMODE(os.lstat(folder).st_mode) == 0o755  # left as it was
    assert list(folder.iterdir()) == []


def test_a_linked_folder_is_not_used(cache_home: Path, tmp_path: Path) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir(mode=0o700)
    cache_home.mkdir()
    (cache_home / _grammar_cache.FOLDER_NAME).symlink_to(elsewhere)
    assert _grammar_cache.cache_file(GRAMMAR) is None


def test_a_cache_file_that_is_a_link_is_not_used(cache_home: Path, tmp_path: Path) -> None:
    path = _grammar_cache.cache_file(GRAMMAR)
    assert path is not None
    target = tmp_path / "planted"
    target.write_bytes(b"not lark's")
    Path(path).symlink_to(target)
    assert _grammar_cache.cache_file(GRAMMAR) is None


def test_a_relative_cache_home_is_ignored_for_the_home_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/cache")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    path = _grammar_cache.cache_file(GRAMMAR)
    assert path is not None
    assert Path(path).parent == tmp_path / "home" / ".cache" / _grammar_cache.FOLDER_NAME


def test_no_folder_to_be_had_builds_in_memory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    blocked = tmp_path / "a-file"
    blocked.write_text("not a folder")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocked))
    assert _grammar_cache.cache_file(GRAMMAR) is None
    assert build_parser(GRAMMAR, None).parse(SCRIPT) is not None
