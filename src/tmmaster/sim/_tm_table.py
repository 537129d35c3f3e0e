"""Techman's Modbus slave table (TMflow 2.24, appendix C) as data, served beside a profile.

``tm_table.toml`` lists every entry of the appendix (``[[entry]]``) and its plain memory
areas (``[[area]]``: the External Module range and the user define area, 9000-9999);
:func:`tm_table_fields` turns the entries into register fields for a robot profile,
leaving out every address the profile itself defines (the profile's field wins), and
:func:`tm_table_areas` gives the areas as ``(table, first address, count)``.
"""

from __future__ import annotations

import tomllib
from functools import cache
from importlib import resources
from typing import Any

from .._registers import Access, RegisterField, RegisterMap, Table
from ._memo import IdentityMemo

#: Which table each Modbus function code reads or writes (TMflow 2.24, appendix C, p. 305).
_FC_TABLE = {
    1: Table.COIL,
    2: Table.DISCRETE_INPUT,
    3: Table.HOLDING,
    4: Table.INPUT,
    5: Table.COIL,
    6: Table.HOLDING,
    15: Table.COIL,
    16: Table.HOLDING,
}
_FC_READS = frozenset({1, 2, 3, 4})

#: Keys of a table entry that describe the manual's row, not the register field.
_ROW_KEYS = ("section", "count", "fc", "page")


def _check_fc(where: str, fc: str, table: Table, access: Access) -> None:
    """Refuse an entry whose function codes disagree with its table or access."""
    codes = {int(c) for c in fc.split("/")}
    tables = {_FC_TABLE[c] for c in codes}
    if tables != {table}:
        raise ValueError(f"tm_table.toml {where}: FC {fc} does not address the {table} table")
    reads, writes = bool(codes & _FC_READS), bool(codes - _FC_READS)
    expected = Access.READ_WRITE if reads and writes else Access.WRITE if writes else Access.READ
    if access is not expected:
        raise ValueError(f"tm_table.toml {where}: FC {fc} means access {expected.value!r}")


@cache
def _document() -> dict[str, Any]:
    text = resources.files("tmmaster.sim").joinpath("tm_table.toml").read_text("utf-8")
    return tomllib.loads(text)


@cache
def _entries() -> tuple[RegisterField, ...]:
    fields: list[RegisterField] = []
    for entry in _document()["entry"]:
        spec: dict[str, Any] = {k: v for k, v in entry.items() if k not in _ROW_KEYS}
        count = int(entry.get("count", 1))
        spec["description"] = (
            f"{entry['section']} (p. {entry['page']}, FC {entry['fc']}): "
            f"{spec.get('description', '')}"
        )
        specs = (
            [spec]
            if count == 1
            else [
                {**spec, "name": f"{spec['name']}_{i}", "address": spec["address"] + i}
                for i in range(count)
            ]
        )
        for one in specs:
            field = RegisterField.model_validate(one)
            _check_fc(field.name, entry["fc"], field.table, field.access)
            fields.append(field)
    return tuple(fields)


@cache
def tm_table_areas(section: str | None = None) -> tuple[tuple[Table, int, int], ...]:
    """The plain memory areas (of one ``section``, or all) as ``(table, first, count)``."""
    areas: list[tuple[Table, int, int]] = []
    for area in _document()["area"]:
        if section is not None and area["section"] != section:
            continue
        table = Table(area["table"])
        _check_fc(area["section"], area["fc"], table, Access(area.get("access", "r")))
        areas.append((table, int(area["address"]), int(area["count"])))
    return tuple(areas)


def user_area() -> tuple[tuple[Table, int, int], ...]:
    """The user define area (9000-9999): coils and holding registers, read and write.

    A function, not a constant: reading ``tm_table.toml`` (some 40 ms) waits until a
    simulator serves the table.
    """
    return tm_table_areas("User Define Area")


def tm_table_markdown() -> str:
    """The table as Markdown, one row per entry of ``tm_table.toml`` (docs/tm-table.md)."""
    doc = _document()
    out = [
        "# Techman's Modbus table in the simulator",
        "",
        "Generated from `src/tmmaster/sim/tm_table.toml` by `tm_table_markdown()` in",
        "`src/tmmaster/sim/_tm_table.py`; do not edit. Source: TMflow SW 2.24 Software Manual",
        '(document version 1.00), appendix C "Modbus List", pp. 305-319. The simulator serves',
        "all of it beside the `tmflow` profile (a profile field at the same address wins);",
        "what it puts in the registers is in [simulator-model.md](simulator-model.md).",
        "",
        "| Section | Name | Table | Address | Type | FC | Access | Unit | Page | Meaning |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    width = {"bool": 1, "int16": 1, "uint16": 1, "int32": 2, "uint32": 2, "float32": 2}
    for e in doc["entry"]:
        last = e["address"] + width[e["type"]] * int(e.get("count", 1)) - 1
        address = str(e["address"]) if last == e["address"] else f"{e['address']}-{last}"
        kind = e["type"] if "count" not in e else f"string ({e['count']} x uint16)"
        out.append(
            f"| {e['section']} | `{e['name']}` | {e['table']} | {address} | {kind} | {e['fc']} "
            f"| {e.get('access', 'r')} | {e.get('unit', '')} | {e['page']} | {e['description']} |"
        )
    out += ["", "Plain memory areas (every address reads 0 until a master writes it):", ""]
    out += [
        "| Section | Table | Addresses | FC | Access | Page | Meaning |",
        "|---|---|---|---|---|---|---|",
    ]
    for a in doc["area"]:
        out.append(
            f"| {a['section']} | {a['table']} | {a['address']}-{a['address'] + a['count'] - 1} "
            f"| {a['fc']} | {a.get('access', 'r')} | {a['page']} | {a['description']} |"
        )
    out.append("")
    return "\n".join(out)


@cache
def _spans() -> tuple[tuple[RegisterField, frozenset[tuple[Table, int]]], ...]:
    return tuple(
        (f, frozenset((f.table, a) for a in range(f.address, f.end + 1))) for f in _entries()
    )


# tm_table_fields by the profile (by identity): every simulated tmflow robot asks again.
_FIELDS_OF: IdentityMemo[tuple[RegisterField, ...]] = IdentityMemo()


def tm_table_fields(profile: RegisterMap) -> tuple[RegisterField, ...]:
    """Table entries that ``profile`` does not define itself (by name or by address)."""
    return _FIELDS_OF.get((profile,), lambda: _fields_left_to_the_table(profile))


def _fields_left_to_the_table(profile: RegisterMap) -> tuple[RegisterField, ...]:
    taken = {(f.table, a) for f in profile.fields.values() for a in range(f.address, f.end + 1)}
    return tuple(
        f for f, span in _spans() if f.name not in profile.fields and taken.isdisjoint(span)
    )
