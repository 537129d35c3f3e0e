"""``python -m tmmaster``: the same as the ``tmmaster`` console script."""

from ._cli import main

raise SystemExit(main())
