"""Where the TMscript parser keeps its work between processes: a private folder.

Building the LALR tables of ``grammar.lark`` takes about 0.3 s of CPU, paid by every
process that checks or runs a script (a simulated ``tmflow`` robot runs one); loading
them from lark's cache file takes about 0.015 s. That file is a pickle, and loading a
pickle runs whatever its writer put in it: lark's own default place for it is the shared
temporary folder, where another user of the machine could plant one. So the cache lives
only in a folder that this user owns and nobody else may enter (``tmmaster`` in
``$XDG_CACHE_HOME``, else ``~/.cache``; created with mode 0700), checked before each use:
a real folder, not a link, owned by this user, no permission for group or others; the
file, when it exists, a regular file (not a link) owned by this user. Without such a
folder (no home, a read-only file system, another owner, wider permissions, a system
without user ids) the tables are built in memory as before.

lark names what the file was built from (the grammar, the options, lark's and Python's
versions) in its first line and builds the tables again when any differs; a file it
cannot read (two processes writing it at once) is built again too.

Long scripts' syntax trees are kept there too (:func:`parsed_file`): parsing the robot
program a simulated ``tmflow`` robot runs (about 19 KB) takes about 0.1 s of CPU,
loading its tree about 0.006 s. The file's name is a digest of the script and of every
source file of this package (the grammar, the parser, the tree's classes): a change to
any of them names another file. The :data:`KEEP_PARSED_FILES` most recently used are kept.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import pickle
import stat
import sys
import tempfile
from functools import cache
from pathlib import Path

__all__ = ["cache_file", "keep_parsed", "load_parsed", "parsed_file", "private_folder"]

#: The folder's name inside the user's cache folder.
FOLDER_NAME = "tmmaster"

#: A script at least this long has its syntax tree kept (:func:`parsed_file`).
KEEP_PARSED_CHARS = 4096
#: How many syntax trees are kept: writing one deletes the least recently used beyond.
KEEP_PARSED_FILES = 32
#: The names of the syntax trees' files: the prefix, then a digest, then the suffix.
_PARSED_PREFIX = "tmscript-tree-"
_PARSED_SUFFIX = ".pickle"


def _user_id() -> int | None:
    getuid = getattr(os, "getuid", None)  # absent on Windows
    return None if getuid is None else int(getuid())


def _cache_base() -> Path | None:
    """``$XDG_CACHE_HOME``, else ``~/.cache``; None when neither is an absolute path."""
    base = os.environ.get("XDG_CACHE_HOME", "")
    if not os.path.isabs(base):  # the XDG rule: a relative path is ignored
        home = os.path.expanduser("~")
        if not os.path.isabs(home):
            return None
        base = os.path.join(home, ".cache")
    return Path(base)


def _private_folder_info(info: os.stat_result, uid: int) -> bool:
    """A folder (not a link) of this user's that nobody else may enter or write."""
    return stat.S_ISDIR(info.st_mode) and info.st_uid == uid and not info.st_mode & 0o077


def _own_file_info(info: os.stat_result, uid: int) -> bool:
    """A regular file (not a link) of this user's."""
    return stat.S_ISREG(info.st_mode) and info.st_uid == uid


def private_folder() -> Path | None:
    """This user's private cache folder for tmmaster, created when missing.

    Returns:
        The folder (mode 0700, owned by this user, not a symbolic link), or None when
        there is none to be had: it cannot be created, or it exists with another owner
        or wider permissions (it is left as it is), or the system has no user ids.
    """
    uid = _user_id()
    base = _cache_base()
    if uid is None or base is None:
        return None
    folder = base / FOLDER_NAME
    try:
        base.mkdir(mode=0o700, parents=True, exist_ok=True)
        with contextlib.suppress(FileExistsError):
            folder.mkdir(mode=0o700)
        info = os.lstat(folder)
    except OSError:
        return None
    return folder if _private_folder_info(info, uid) else None


def cache_file(grammar: str) -> str | None:
    """The path lark may keep ``grammar``'s tables at, or None for no cache.

    Args:
        grammar: The grammar's text (its digest names the file, so that two versions of
            the grammar never share one).

    Returns:
        A path inside :func:`private_folder`; None when there is no private folder, or
        the file there is not a regular file of this user's.
    """
    digest = hashlib.sha256(grammar.encode("utf-8")).hexdigest()[:16]
    major, minor = sys.version_info[:2]
    return _private_file(f"tmscript-grammar-{digest}-py{major}{minor}.lark")


def _private_file(name: str) -> str | None:
    """The path of ``name`` in :func:`private_folder`: None when there is no such folder,
    or the file there is not a regular file of this user's."""
    folder = private_folder()
    uid = _user_id()
    if folder is None or uid is None:
        return None
    path = folder / name
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return str(path)
    except OSError:
        return None
    return str(path) if _own_file_info(info, uid) else None


@cache
def _sources_digest() -> str | None:
    """A digest of every source file of this package (None when one cannot be read),
    with the versions of Python and lark: what a syntax tree is made from and of."""
    import lark  # the parser's own dependency: already imported

    digest = hashlib.sha256(f"{sys.version_info[:2]} {lark.__version__}".encode())
    here = Path(__file__).parent
    sources = sorted([*here.glob("*.py"), *here.glob("*.lark")])
    try:
        for path in sources:
            digest.update(path.name.encode() + b"\0" + path.read_bytes())
    except OSError:
        return None
    return digest.hexdigest() if sources else None


def parsed_file(text: str) -> str | None:
    """The path the syntax tree of the script ``text`` may be kept at, or None for none.

    Args:
        text: The script.

    Returns:
        A path inside :func:`private_folder`; None when ``text`` is shorter than
        :data:`KEEP_PARSED_CHARS`, there is no private folder, a source file of this
        package cannot be read, or the file there is not a regular file of this user's.
    """
    sources = _sources_digest() if len(text) >= KEEP_PARSED_CHARS else None
    if sources is None:
        return None
    digest = hashlib.sha256(f"{sources}\0{text}".encode("utf-8", "surrogatepass"))
    return _private_file(f"{_PARSED_PREFIX}{digest.hexdigest()[:32]}{_PARSED_SUFFIX}")


def load_parsed(path: str | None) -> object | None:
    """What :func:`keep_parsed` wrote at ``path`` (a :func:`parsed_file` path), or None.

    Args:
        path: The file, or None.

    Returns:
        The object; None when ``path`` is None or there is no file, or it cannot be
        read back (being written by another process, cut short, from another version).
    """
    if path is None:
        return None
    try:
        with open(path, "rb") as file:
            kept: object = pickle.load(file)  # a file of this user's, in their private folder
    except Exception:  # no file yet; or unpickling's any error: parsed again
        return None
    with contextlib.suppress(OSError):
        os.utime(path)  # used now: kept longest (keep_parsed)
    return kept


def keep_parsed(path: str | None, tree: object) -> None:
    """Write ``tree`` at ``path`` (a :func:`parsed_file` path; None: nothing is written).

    The file is written whole under another name, then renamed: a process reading it
    meanwhile finds the old file or the new one. Then the least recently used trees
    beyond :data:`KEEP_PARSED_FILES` are deleted. Nothing is raised: a tree that cannot
    be kept is parsed again next time.

    Args:
        path: The file, or None.
        tree: What to keep.
    """
    if path is None:
        return
    folder = os.path.dirname(path)
    try:
        fd, partial = tempfile.mkstemp(dir=folder, prefix=f".{_PARSED_PREFIX}")
    except OSError:
        return
    try:
        with os.fdopen(fd, "wb") as file:
            pickle.dump(tree, file, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(partial, path)
    except (OSError, RecursionError, pickle.PicklingError):
        with contextlib.suppress(OSError):
            os.unlink(partial)
        return
    _forget_the_oldest(Path(folder))


def _forget_the_oldest(folder: Path) -> None:
    """Delete the least recently used trees beyond :data:`KEEP_PARSED_FILES`."""
    kept: list[tuple[float, Path]] = []
    for path in folder.glob(f"{_PARSED_PREFIX}*{_PARSED_SUFFIX}"):
        with contextlib.suppress(OSError):  # deleted meanwhile by another process
            kept.append((path.stat().st_mtime, path))
    for _, path in sorted(kept, reverse=True)[KEEP_PARSED_FILES:]:
        with contextlib.suppress(OSError):
            path.unlink()
