"""Run reports as pictures and tables: ``tmmaster report show|plot``.

``python -m tmmaster.report`` is the same command. :func:`plot_report` needs
matplotlib (``pip install 'tmmaster[plot]'``); the report model itself is
:class:`tmmaster.pickplace.RunReport`, read with :func:`tmmaster.pickplace.load_report`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING as _TYPE_CHECKING

from .._lazy import lazy_attributes as _lazy_attributes

if _TYPE_CHECKING:
    from ._plot import plot_report

_EXPORTS = {"plot_report": "._plot"}

__getattr__, __dir__ = _lazy_attributes(__name__, globals(), _EXPORTS)

__all__ = ["plot_report"]
