"""Techman's Modbus slave table (TMflow 2.24, appendix C) as data, served beside a profile.

``tm_table.toml`` lists the transcribed entries; :func:`tm_table_fields` turns them into
register fields for a robot profile, leaving out every address the profile itself
defines (the profile's field wins), and :data:`USER_AREA` is the user define area
(9000-9999, coils and holding registers, FC 01/03/05/06/15/16).
"""

from __future__ import annotations

import tomllib
from functools import cache
from importlib import resources
from typing import Any

from .._registers import RegisterField, RegisterMap, Table

#: The user define area: (table, first address, count); read and write.
USER_AREA = ((Table.COIL, 9000, 1000), (Table.HOLDING, 9000, 1000))


@cache
def _entries() -> tuple[RegisterField, ...]:
    text = resources.files("tmmaster.sim").joinpath("tm_table.toml").read_text("utf-8")
    fields: list[RegisterField] = []
    for entry in tomllib.loads(text)["entry"]:
        spec: dict[str, Any] = {k: v for k, v in entry.items() if k not in ("section", "count")}
        count = int(entry.get("count", 1))
        spec["description"] = f"{entry['section']}: {spec.get('description', '')}"
        if count == 1:
            fields.append(RegisterField.model_validate(spec))
            continue
        for i in range(count):
            fields.append(
                RegisterField.model_validate(
                    {**spec, "name": f"{spec['name']}_{i}", "address": spec["address"] + i}
                )
            )
    return tuple(fields)


def tm_table_fields(profile: RegisterMap) -> tuple[RegisterField, ...]:
    """Table entries that ``profile`` does not define itself (by name or by address)."""
    taken = {(f.table, a) for f in profile.fields.values() for a in range(f.address, f.end + 1)}
    return tuple(
        f
        for f in _entries()
        if f.name not in profile.fields
        and not any((f.table, a) in taken for a in range(f.address, f.end + 1))
    )
