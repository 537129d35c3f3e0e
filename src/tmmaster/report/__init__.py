"""Run reports as pictures and tables: ``tmmaster report show|plot``.

``python -m tmmaster.report`` is the same command. :func:`plot_report` needs
matplotlib (``pip install 'tmmaster[plot]'``); the report model itself is
:class:`tmmaster.pickplace.RunReport`, read with :func:`tmmaster.pickplace.load_report`.
"""

from __future__ import annotations

from types import FunctionType as _FunctionType

from ._plot import plot_report

__all__ = ["plot_report"]

# Shown as tmmaster.report.Name where they are used (tracebacks, reprs, the docs), not as the
# private module that defines them.
for _name in __all__:
    _value = globals()[_name]
    if isinstance(_value, type | _FunctionType) and _value.__module__.startswith(f"{__name__}._"):
        _value.__module__ = __name__
del _name, _value
