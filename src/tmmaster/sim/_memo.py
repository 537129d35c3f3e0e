"""Values made from objects, kept by the objects' identity while they live (bounded).

A simulator builds the same things from the same register map every time one starts (its
bank's layout, the Techman table entries its profile leaves to the table): a test suite
starts hundreds. The maps are large frozen models, cheap to compare by identity and
costly to hash, so the values are kept by ``id``; each entry holds its objects, so their
ids cannot be reused while it lives.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

_V = TypeVar("_V")


class IdentityMemo(Generic[_V]):
    """What :meth:`get` made from some objects (and a hashable key), by their identity.

    Args:
        limit: How many entries it keeps; past that it starts again, empty.
    """

    def __init__(self, limit: int = 64) -> None:
        self._limit = limit
        self._entries: dict[tuple[tuple[int, ...], Hashable], tuple[tuple[object, ...], _V]] = {}

    def get(self, objects: tuple[object, ...], make: Callable[[], _V], key: Hashable = ()) -> _V:
        """The value made for ``objects`` and ``key``, made by ``make`` the first time.

        Args:
            objects: What the value is made from, compared by identity.
            make: Makes the value (called once per entry).
            key: What else the value depends on, compared by value.

        Returns:
            The value.
        """
        ident = (tuple(map(id, objects)), key)
        entry = self._entries.get(ident)
        if entry is not None and all(a is b for a, b in zip(entry[0], objects, strict=True)):
            return entry[1]
        value = make()
        if len(self._entries) >= self._limit:
            self._entries.clear()
        self._entries[ident] = (objects, value)
        return value
