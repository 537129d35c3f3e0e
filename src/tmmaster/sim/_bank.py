"""The register memory of one simulated device: the single source of truth.

Both sides use the same bank. The network side (the Modbus server) calls
:meth:`RegisterBank.read` and :meth:`RegisterBank.write` with raw addresses and words and
gets the same refusals a real device gives (:class:`IllegalAddressError`). The device
side (controller, gripper logic) calls :meth:`RegisterBank.get` / :meth:`RegisterBank.set`
with field names and engineering values; every conversion goes through
:mod:`tmmaster._codec`, and the device may set fields the master may not write.

What a master may address:

* read: every address covered by a field, plus the unused addresses of a gap of at most
  ``register_map.max_read_gap`` between two fields of the same table (they read as 0),
  so that a master can fetch two neighbouring blocks in one request;
* write: only addresses covered by a field whose access is ``w`` or ``rw``, never in
  the read-only tables, never in a gap. A write is all or nothing.
"""

from __future__ import annotations

from bisect import bisect_right
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise
from math import copysign, nan

from .._codec import Decoder, Encoder, Value, decoder, encoder
from .._exceptions import IllegalAddressError, IllegalValueError
from .._registers import RegisterField, RegisterMap, RobotProfile, Table
from ._memo import IdentityMemo


def _sign(value: float) -> float:
    """1.0 or -1.0: the sign of ``value``, a zero's too."""
    return copysign(1.0, value)


def _merge(addresses: set[int]) -> list[tuple[int, int]]:
    """Contiguous runs of ``addresses`` as ``(first address, count)``, in address order."""
    runs: list[tuple[int, int]] = []
    for address in sorted(addresses):
        if runs and runs[-1][0] + runs[-1][1] == address:
            runs[-1] = (runs[-1][0], runs[-1][1] + 1)
        else:
            runs.append((address, 1))
    return runs


@dataclass(frozen=True)
class _Layout:
    """What a bank serves where, for one map, its extra fields and its raw areas."""

    #: Every served word of each table, 0 (copied into each bank's memory).
    zeros: dict[Table, dict[int, int]]
    #: Address -> the field covering it.
    owner: dict[Table, dict[int, RegisterField]]
    #: Unused addresses between two fields that a read may cover.
    gaps: dict[Table, set[int]]
    #: Plain memory addresses (no field).
    raw: dict[Table, set[int]]
    #: The extra fields by name (those the map does not define).
    extra: dict[str, RegisterField]
    #: ``RegisterBank.served`` and ``RegisterBank.readable`` of each table.
    served: dict[Table, tuple[tuple[int, int], ...]]
    readable: dict[Table, tuple[tuple[int, int], ...]]
    #: The first address of each readable run, in order (to find a read's run).
    readable_starts: dict[Table, tuple[int, ...]]


# Layouts by their map and extra fields (by identity) and their raw areas: a simulator
# builds the same bank each time (a tmflow robot's, with Techman's table: thousands of
# addresses), so a test suite that starts many built it again each time.
_LAYOUTS: IdentityMemo[_Layout] = IdentityMemo()


def _layout(
    register_map: RegisterMap,
    extra_fields: tuple[RegisterField, ...],
    raw_areas: tuple[tuple[Table, int, int], ...],
) -> _Layout:
    return _LAYOUTS.get(
        (register_map, *extra_fields),
        lambda: _build_layout(register_map, extra_fields, raw_areas),
        key=raw_areas,
    )


def _build_layout(
    register_map: RegisterMap,
    extra_fields: tuple[RegisterField, ...],
    raw_areas: tuple[tuple[Table, int, int], ...],
) -> _Layout:
    zeros: dict[Table, dict[int, int]] = {table: {} for table in Table}
    owner: dict[Table, dict[int, RegisterField]] = {table: {} for table in Table}
    raw: dict[Table, set[int]] = {table: set() for table in Table}
    extra = {f.name: f for f in extra_fields if f.name not in register_map.fields}
    for field in (*register_map.fields.values(), *extra.values()):
        for address in range(field.address, field.end + 1):
            zeros[field.table][address] = 0
            owner[field.table][address] = field
    for table, first, count in raw_areas:
        for address in range(first, first + count):
            if address not in zeros[table]:
                zeros[table][address] = 0
                raw[table].add(address)
    gaps = {table: _gaps(register_map, table) for table in Table}
    return _Layout(zeros, owner, gaps, raw, extra, *_runs(zeros, gaps))


_Runs = dict[Table, tuple[tuple[int, int], ...]]


def _runs(
    zeros: dict[Table, dict[int, int]], gaps: dict[Table, set[int]]
) -> tuple[_Runs, _Runs, dict[Table, tuple[int, ...]]]:
    """Per table: the served runs, the readable runs (the gaps a read may cover too), and
    the first address of each readable run."""
    served = {table: tuple(_merge(set(zeros[table]))) for table in Table}
    readable = {table: tuple(_merge(set(zeros[table]) | gaps[table])) for table in Table}
    starts = {table: tuple(first for first, _ in runs) for table, runs in readable.items()}
    return served, readable, starts


def _gaps(register_map: RegisterMap, table: Table) -> set[int]:
    """The unused addresses of ``table`` between two of the map's fields that a read may cover."""
    gaps: set[int] = set()
    ordered = sorted(
        (f for f in register_map.fields.values() if f.table is table),
        key=lambda f: f.address,
    )
    for before, after in pairwise(ordered):
        gap = after.address - before.end - 1
        if 0 < gap <= register_map.max_read_gap:
            gaps.update(range(before.end + 1, after.address))
    return gaps


class _Slot:
    """One field as :meth:`RegisterBank.set` stores it, and the last value it encoded."""

    __slots__ = ("addresses", "encode", "memory", "table", "value", "words")

    def __init__(self, encode: Encoder, memory: dict[int, int], field: RegisterField) -> None:
        #: The codec's encoder of the field (equal to encode()).
        self.encode = encode
        #: The bank's words of the field's table, by address; the field's addresses.
        self.memory = memory
        self.table = field.table
        self.addresses = tuple(range(field.address, field.end + 1))
        #: The last value encoded (NaN at first: equal to no value) and its words.
        self.value: Value = nan
        self.words: list[int] = []


class RegisterBank:
    """Register memory of one device, serving exactly the addresses of its register map."""

    def __init__(
        self,
        register_map: RegisterMap,
        *,
        extra_fields: Sequence[RegisterField] = (),
        raw_areas: Sequence[tuple[Table, int, int]] = (),
    ) -> None:
        """Serve ``register_map``; plus ``extra_fields`` (served and settable by name,
        e.g. Techman's fixed table) and ``raw_areas`` ``(table, first, count)`` of plain
        read/write memory (e.g. the user define area) wherever no field is."""
        self._map = register_map
        layout = _layout(register_map, tuple(extra_fields), tuple(raw_areas))
        # Each bank's own memory, all zeros; the rest of the layout is shared, read only.
        self._words: dict[Table, dict[int, int]] = {
            table: dict(words) for table, words in layout.zeros.items()
        }
        # Address -> the field covering it, to check write access per address.
        self._owner = layout.owner
        self._gaps = layout.gaps
        self._raw = layout.raw
        self._extra = layout.extra
        self._layout = layout
        # What set() needs of each field, found once by name (a moving arm's pose changes
        # some thirty fields a tick), and the last value it encoded with its words: a
        # device publishes most fields unchanged at every tick.
        self._slots: dict[str, _Slot] = {}
        # Each field's decoder, table and first address, found once by name.
        self._getters: dict[str, tuple[Decoder, Table, int]] = {}
        self._version = 0
        self._table_changes: dict[Table, int] = dict.fromkeys(Table, 0)
        self._network_writes = 0
        self._field_writes: dict[str, int] = dict.fromkeys(register_map.fields, 0)
        # Which network write last touched each field (1: the first; 0: none yet).
        self._field_last_write: dict[str, int] = dict.fromkeys(register_map.fields, 0)

    @property
    def register_map(self) -> RegisterMap:
        """The map whose fields this bank serves."""
        return self._map

    @property
    def version(self) -> int:
        """Counter incremented by every change (device ``set`` or network ``write``)."""
        return self._version

    def changes(self, table: Table) -> int:
        """Counter incremented by every change of a word in ``table`` (device or network).

        Args:
            table: A Modbus table.

        Returns:
            The count of changes so far: while it stays, every word of ``table`` does.
        """
        return self._table_changes[table]

    def changes_in(self, tables: tuple[Table, ...]) -> int:
        """The sum of :meth:`changes` over ``tables``: while it stays, every word of them does
        (each count only grows). One call for a device's check at every tick.

        Args:
            tables: Modbus tables.

        Returns:
            The sum of their change counts so far.
        """
        counts = self._table_changes
        total = 0
        for table in tables:  # no comprehension: one or two tables, at every tick
            total += counts[table]
        return total

    @property
    def network_writes(self) -> int:
        """Number of successful network writes so far."""
        return self._network_writes

    def field_writes(self, name: str) -> int:
        """How many network writes touched field ``name`` (even with an unchanged value)."""
        self._map.field(name)  # KeyError naming the map for an unknown field
        return self._field_writes[name]

    def last_write(self, name: str) -> int:
        """Which network write last touched field ``name`` (1: the first; 0: none yet):
        of two fields, the one written later has the larger number."""
        self._map.field(name)  # KeyError naming the map for an unknown field
        return self._field_last_write[name]

    # -- device side -------------------------------------------------------------------

    def has(self, name: str) -> bool:
        """True when ``name`` is a field of the map or an extra field."""
        return name in self._map.fields or name in self._extra

    def field(self, name: str) -> RegisterField:
        """The field ``name`` of the map or of the extra fields.

        Args:
            name: A field name.

        Returns:
            Its :class:`~tmmaster._registers.RegisterField`.

        Raises:
            KeyError: No such field.
        """
        return self._field(name)

    def _field(self, name: str) -> RegisterField:
        extra = self._extra.get(name)
        return extra if extra is not None else self._map.field(name)

    def get(self, name: str) -> Value:
        """Engineering value of field ``name``."""
        getter = self._getters.get(name)
        if getter is None:
            field = self._field(name)
            getter = self._getters[name] = (decoder(field), field.table, field.address)
        # decode() of the field's words: its decoder reads them where they are stored (the
        # words of a table by address). decode()'s own checks hold here by construction:
        # a field has its width of words, and every stored word is 0..65535 (set() stores
        # what its encoder made; write() refuses any other value).
        read, table, first = getter
        return read(self._words[table], first)  # type: ignore[arg-type]

    def set(self, name: str, value: Value) -> None:
        """Store ``value`` in field ``name`` (device side: read-only fields too)."""
        slot = self._slots.get(name) or self._slot(name)
        last = slot.value
        # The same value of the same type encodes to the same words, but for the sign of a
        # float zero (-0.0 == 0.0, yet a float32 field stores its sign).
        if (
            last.__class__ is value.__class__
            and last == value
            and (value or value.__class__ is not float or _sign(value) == _sign(last))
        ):
            new = slot.words
        else:
            # The encoder raises ValueOutOfRangeError before anything is stored.
            new = slot.encode(value)
            slot.value, slot.words = value, new
        words = slot.memory
        addresses = slot.addresses
        # Most fields are published unchanged at every tick: compared word by word, no list;
        # a field of one or two words (all but a few) without a loop (a zip costs more
        # than the compare).
        if len(addresses) == 2:
            first, second = addresses
            high, low = new
            if words[first] == high and words[second] == low:
                return
            words[first], words[second] = high, low
        elif len(addresses) == 1:
            (word,) = new
            if words[addresses[0]] == word:
                return
            words[addresses[0]] = word
        elif not self._store(words, addresses, new):
            return
        self._version += 1
        self._table_changes[slot.table] += 1

    @staticmethod
    def _store(words: dict[int, int], addresses: tuple[int, ...], new: list[int]) -> bool:
        """Store ``new`` at ``addresses`` unless they hold it; whether anything changed."""
        for address, word in zip(addresses, new, strict=True):
            if words[address] != word:
                break
        else:
            return False
        for address, word in zip(addresses, new, strict=True):
            words[address] = word
        return True

    def check(self, name: str, value: Value) -> None:
        """Encode ``value`` for field ``name`` as :meth:`set` would, storing nothing.

        A :meth:`set` of the same value that follows does not encode it again (a moving
        arm's pose is checked whole before any of it is stored).

        Raises:
            ValueOutOfRangeError: What :meth:`set` would raise.
        """
        slot = self._slots.get(name) or self._slot(name)
        slot.words = slot.encode(value)
        slot.value = value

    def _slot(self, name: str) -> _Slot:
        """What set() needs of field ``name`` (KeyError: no such field), kept."""
        field = self._field(name)
        slot = self._slots[name] = _Slot(encoder(field), self._words[field.table], field)
        return slot

    # -- network side ------------------------------------------------------------------

    def served(self, table: Table) -> list[tuple[int, int]]:
        """Addresses covered by fields, as contiguous ``(first address, count)`` runs."""
        return list(self._layout.served[table])

    def readable(self, table: Table) -> list[tuple[int, int]]:
        """Addresses a read may cover (fields plus bridgeable gaps), as ``(first, count)``."""
        return list(self._layout.readable[table])

    def read(self, table: Table, address: int, count: int) -> list[int]:
        """Words (or 0/1 per bit) at ``address``..``address + count - 1``; gaps read as 0."""
        if count < 1 or address < 0 or address + count - 1 > 65535:  # _check_range's test
            self._check_range(table, address, count)
        words = self._words[table]
        # Inside one readable run (its words and gaps, merged), every address is served:
        # one look-up instead of one per address. Otherwise each address is checked.
        layout = self._layout
        runs = layout.readable[table]
        k = bisect_right(layout.readable_starts[table], address) - 1
        if k < 0 or address + count > runs[k][0] + runs[k][1]:
            gaps = self._gaps[table]
            for a in range(address, address + count):
                if a not in words and a not in gaps:
                    raise IllegalAddressError(
                        f"{self._map.name}: {table.value} address {a} is not served"
                        f" (read of {count} from {address})"
                    )
        return [words.get(a, 0) for a in range(address, address + count)]

    def write(
        self, table: Table, address: int, values: Sequence[int], *, device: bool = False
    ) -> None:
        """Store words (or 0/1 bits) from the network; all or nothing.

        ``device``: written by the robot's own program (a Script Project's Modbus client),
        which may write the fields a master may not (its feedback); not counted as a
        network write.
        """
        count = len(values)
        if count < 1 or address < 0 or address + count - 1 > 65535:  # _check_range's test
            self._check_range(table, address, count)
        if table.read_only and not device:
            raise IllegalAddressError(
                f"{self._map.name}: the {table.value} table is read-only (write at {address})"
            )
        touched = self._writable_fields(table, address, values, device=device)
        words = self._words[table]
        changed = False
        for offset, value in enumerate(values):
            if words[address + offset] != value:
                words[address + offset] = value
                changed = True
        if not device:
            for name in touched:
                if name in self._field_writes:
                    self._field_writes[name] += 1
                    self._field_last_write[name] = self._network_writes + 1
            self._network_writes += 1
        if changed:
            self._version += 1
            self._table_changes[table] += 1

    def _writable_fields(
        self, table: Table, address: int, values: Sequence[int], *, device: bool
    ) -> dict[str, RegisterField]:
        """The fields a write of ``values`` at ``address`` touches, by name; checked first.

        Raises:
            IllegalAddressError: An address no field or raw area covers, or a field only
                the device writes (unless ``device``).
            IllegalValueError: A value that does not fit its word (or bit).
        """
        owners = self._owner[table]
        raw = self._raw[table]
        limit = 1 if table.is_bit else 0xFFFF
        touched: dict[str, RegisterField] = {}
        for offset, value in enumerate(values):
            a = address + offset
            field = owners.get(a)
            if field is None and a in raw:
                self._check_value(table, a, value, limit)
                continue
            if field is None:
                raise IllegalAddressError(
                    f"{self._map.name}: {table.value} address {a} is not served"
                    f" (write of {len(values)} at {address})"
                )
            if not field.access.writable and not device:
                raise IllegalAddressError(
                    f"{self._map.name}: field {field.name} ({table.value} {a}) is written by"
                    " the device only"
                )
            self._check_value(table, a, value, limit)
            touched[field.name] = field
        return touched

    def _check_value(self, table: Table, address: int, value: int, limit: int) -> None:
        if not 0 <= value <= limit:
            raise IllegalValueError(
                f"{self._map.name}: value {value} does not fit {table.value} address {address}"
            )

    def _check_range(self, table: Table, address: int, count: int) -> None:
        if count < 1 or address < 0 or address + count - 1 > 65535:
            raise IllegalAddressError(
                f"{self._map.name}: bad {table.value} range: {count} from {address}"
            )


def digital_io_areas(profile: RobotProfile) -> tuple[tuple[Table, int, int], ...]:
    """Every module's coils and discrete inputs as ``(table, first address, count)``.

    Args:
        profile: The robot profile.

    Returns:
        The areas, module by module (none for a profile without digital I/O).
    """
    return tuple(span for module in profile.digital_io.values() for span in module.spans())
