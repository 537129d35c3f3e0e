"""Where lark keeps the TMscript parser's tables between processes: a private folder.

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
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import stat
import sys
from pathlib import Path

__all__ = ["cache_file", "private_folder"]

#: The folder's name inside the user's cache folder.
FOLDER_NAME = "tmmaster"


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
    folder = private_folder()
    uid = _user_id()
    if folder is None or uid is None:
        return None
    digest = hashlib.sha256(grammar.encode("utf-8")).hexdigest()[:16]
    major, minor = sys.version_info[:2]
    path = folder / f"tmscript-grammar-{digest}-py{major}{minor}.lark"
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return str(path)
    except OSError:
        return None
    return str(path) if _own_file_info(info, uid) else None
