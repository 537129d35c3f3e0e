"""mkdocs hook: show the docstrings' Sphinx roles (:class:`X`, :func:`y`) as plain code.

The docstrings are written for reading in the source and in ``help()``; mkdocstrings
renders ``:class:`X``` as the text ":class:" before ``X``. This drops the role name,
and shows ``:class:`~tmmaster.Robot``` as ``Robot``, as Sphinx would.
"""

from __future__ import annotations

import re
from typing import Any

_ROLE = re.compile(r":(?:class|func|meth|attr|mod|data|exc|obj|const):<code>(~?)([^<]*)</code>")


def _code(match: re.Match[str]) -> str:
    text = match[2]
    if match[1]:  # ~a.b.C: the last part only
        text = text.rsplit(".", 1)[-1]
    return f"<code>{text}</code>"


def on_page_content(html: str, **kwargs: Any) -> str:
    """Remove the role prefixes from a rendered page."""
    _ = kwargs
    return _ROLE.sub(_code, html)
