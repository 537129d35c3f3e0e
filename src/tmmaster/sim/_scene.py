"""Scene files: the table, the fixtures, the parts and the gripper, in TOML.

A scene file describes the cell the simulated robot works in::

    [table]
    top_z_mm = 85.0

    [[fixtures]]
    name = "wall"
    pose = [450, 120, 160, 0, 0, 0]   # the box's centre, mm / deg
    size_mm = [300, 20, 150]

    [[parts]]
    name = "part-1"
    pose = [300, -200, 100, 180, 0, 90]
    size_mm = [30, 30, 30]
    mass_kg = 0.1

    [gripper]            # optional: the default is an OnRobot 2FG7
    max_width_mm = 39.0

:func:`load_scene` reads and validates one (errors name the key);
``Simulator(cell=Cell(scene=...))`` and ``python -m tmmaster.sim --scene FILE`` run it
on either physics backend.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from .._exceptions import ConfigError
from .._toml import read_toml
from ._world import (
    DEFAULT_TABLE_TOP_Z_MM,
    TABLE,
    Fixture,
    GripperGeometry,
    TableObject,
    World,
)


class SceneTable(BaseModel):
    """The table of a scene: only its top's height can change (its footprint is fixed)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    #: Height of the table top in the robot base frame, mm.
    top_z_mm: float = Field(default=DEFAULT_TABLE_TOP_Z_MM, ge=-1000, le=2000)


class Scene(BaseModel):
    """What a simulated cell holds: the table, fixtures, parts and (optionally) the gripper.

    Parts placed in the air drop onto the table, a fixture or another part; parts at one
    pose wait there like a feeder's (the next one is there once one is taken).
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    #: The table.
    table: SceneTable = SceneTable()
    #: Fixed boxes the arm must not touch; parts rest on them.
    fixtures: tuple[Fixture, ...] = ()
    #: The parts the gripper can pick up (none: an empty table).
    parts: tuple[TableObject, ...] = ()
    #: The gripper's stroke, pads and friction (None: an OnRobot 2FG7).
    gripper: GripperGeometry | None = None

    @model_validator(mode="after")
    def _names_are_unique(self) -> Scene:
        seen: set[str] = {TABLE}
        named = [("fixtures", k, f.name) for k, f in enumerate(self.fixtures)]
        named += [("parts", k, p.name) for k, p in enumerate(self.parts)]
        for key, k, name in named:
            if name in seen:
                raise ValueError(f"{key}.{k}.name: the name {name!r} is taken")
            seen.add(name)
        return self

    def world(self) -> World:
        """A new :class:`World` holding this scene's table, fixtures and parts.

        Returns:
            The world, its parts at rest.
        """
        return World(self.parts, table_top_z_mm=self.table.top_z_mm, fixtures=self.fixtures)


def scene_from_data(data: Any, *, source: str = "scene") -> Scene:
    """Validate a scene given as data (a TOML file's tables).

    Args:
        data: The scene's tables and values.
        source: What to call the scene in an error message (its file).

    Returns:
        The scene.

    Raises:
        ConfigError: An invalid scene; the message names each bad key.
    """
    try:
        return Scene.model_validate(data)
    except ValidationError as exc:
        problems = []
        for error in exc.errors():
            location = ".".join(str(part) for part in error["loc"])
            message = error["msg"].removeprefix("Value error, ")
            problems.append(f"{location}: {message}" if location else message)
        raise ConfigError(f"{source}: invalid scene: {'; '.join(problems)}") from None


def load_scene(path: str | Path) -> Scene:
    """Read and validate a TOML scene file.

    Args:
        path: The file.

    Returns:
        The scene.

    Raises:
        ConfigError: An unreadable file, one over 1 MiB, not TOML (or nested too deeply to
            read), or an invalid scene (the message names the file and each bad key).
    """
    path = Path(path)
    data = read_toml(path, f"scene {path}")
    return scene_from_data(data, source=f"scene {path}")
