"""Built-in profiles, loading profiles from TOML, and rendering them as Markdown.

Built-in profiles are TOML files shipped in ``tmmaster/profiles``. A user's TOML file
may start from one of them with ``extends = "article"`` and override single keys of
single fields; the result is validated as a whole, exactly like a built-in.
"""

from __future__ import annotations

import functools
import tomllib
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, TypeVar

from pydantic import Field, TypeAdapter, ValidationError

from ._codec import describe_range
from ._exceptions import RegisterMapError
from ._registers import DataType, GripperProfile, RegisterField, RobotProfile
from ._toml import read_toml

Profile = RobotProfile | GripperProfile
_KindT = TypeVar("_KindT", RobotProfile, GripperProfile)

_ADAPTER: TypeAdapter[Profile] = TypeAdapter(
    Annotated[RobotProfile | GripperProfile, Field(discriminator="kind")]
)


#: The robot profile used when none is given, by ``Robot``/``connect()``, the simulator
#: and both command lines: the sequence-number handshake, the only one that keeps the
#: command-safety invariant on a real robot (docs/safety.md).
DEFAULT_PROFILE = "tmflow"


def builtin_profile_names() -> list[str]:
    """Names of the profiles shipped with tmmaster, sorted.

    Returns:
        The names, e.g. ``["article", "blog-2fg7", "onrobot-2fg7", "tmflow"]``.
    """
    folder = resources.files("tmmaster").joinpath("profiles")
    return sorted(
        p.name.removesuffix(".toml") for p in folder.iterdir() if p.name.endswith(".toml")
    )


def _builtin_data(name: str) -> dict[str, Any]:
    known = builtin_profile_names()
    if name not in known:
        raise RegisterMapError(f"unknown profile {name!r} (built-in profiles: {', '.join(known)})")
    path = resources.files("tmmaster").joinpath("profiles", f"{name}.toml")
    return tomllib.loads(path.read_text("utf-8"))


def _merge(base: Mapping[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    merged = dict(base)
    for key, value in override.items():
        both = isinstance(value, Mapping) and isinstance(merged.get(key), Mapping)
        merged[key] = _merge(merged[key], value) if both else value
    return merged


def profile_from_data(data: Mapping[str, Any], *, source: str = "<data>") -> Profile:
    """Validate a profile given as a mapping (``extends`` resolves a built-in base)."""
    data = dict(data)
    base_name = data.pop("extends", None)
    if base_name is not None:
        if not isinstance(base_name, str):
            raise RegisterMapError(f"{source}: extends must be a profile name")
        base = _builtin_data(base_name)
        remove = data.pop("remove_fields", [])
        if not isinstance(remove, list) or not all(isinstance(n, str) for n in remove):
            raise RegisterMapError(f"{source}: remove_fields must be a list of field names")
        if not isinstance(data.get("fields", {}), Mapping):
            raise RegisterMapError(f"{source}: fields must be a table of field tables")
        data = _merge(base, data)
        for name in remove:
            data.get("fields", {}).pop(name, None)
    if data.get("kind") not in ("robot", "gripper"):
        raise RegisterMapError(f'{source}: kind must be "robot" or "gripper"')
    try:
        return _ADAPTER.validate_python(data)
    except ValidationError as exc:
        raise RegisterMapError(f"{source}: invalid profile:\n{_format_errors(exc)}") from exc


def load_profile(name_or_path: str | Path) -> Profile:
    """A built-in profile by name, or a profile from a TOML file.

    Args:
        name_or_path: A built-in profile's name (:func:`builtin_profile_names`), or the
            path of a TOML file (a ``str`` ending in ``.toml``, or a ``Path``).

    Returns:
        The validated robot or gripper profile.

    Raises:
        RegisterMapError: An unknown name, an unreadable file or an invalid profile
            (the message names every problem).
    """
    path = Path(name_or_path)
    if isinstance(name_or_path, str) and path.suffix != ".toml":
        return _builtin_profile(name_or_path)
    data = read_toml(path, f"profile {path}", error=RegisterMapError)
    return profile_from_data(data, source=str(path))


@functools.cache
def _builtin_profile(name: str) -> Profile:
    # Validated once per name: a built-in profile is immutable data (frozen models) that
    # every Robot, Simulator and gripper of a process may share. An unknown name raises
    # and is not cached.
    return profile_from_data(_builtin_data(name), source=f"profile {name}")


def _of_kind(name_or_path: str | Path | Profile, kind: type[_KindT]) -> _KindT:
    """A profile of ``kind`` (returned as is) or loaded; RegisterMapError for the other kind."""
    profile = name_or_path if isinstance(name_or_path, Profile) else load_profile(name_or_path)
    if not isinstance(profile, kind):
        named = profile.name if profile is name_or_path else name_or_path
        wanted = "robot" if kind is RobotProfile else "gripper"
        raise RegisterMapError(f"{named} is a {profile.kind} profile, not a {wanted} one")
    return profile


def robot_profile(name_or_path: str | Path | RobotProfile) -> RobotProfile:
    """Load a robot profile, refusing gripper profiles.

    Args:
        name_or_path: A built-in name, a TOML file, or a profile (returned as is).

    Returns:
        The robot profile.

    Raises:
        RegisterMapError: As :func:`load_profile`, or a gripper profile.
    """
    return _of_kind(name_or_path, RobotProfile)


def gripper_profile(name_or_path: str | Path | GripperProfile) -> GripperProfile:
    """Load a gripper profile, refusing robot profiles.

    Args:
        name_or_path: A built-in name, a TOML file, or a profile (returned as is).

    Returns:
        The gripper profile.

    Raises:
        RegisterMapError: As :func:`load_profile`, or a robot profile.
    """
    return _of_kind(name_or_path, GripperProfile)


def _format_errors(exc: ValidationError) -> str:
    lines = []
    for error in exc.errors():
        # The first location part is the union tag ("robot" / "gripper"): noise to a user.
        location = ".".join(str(part) for part in error["loc"][1:])
        message = error["msg"].removeprefix("Value error, ")
        lines.append(f"  {location or '<profile>'}: {message}")
    return "\n".join(lines)


def _address(field: RegisterField) -> str:
    if field.width == 1:
        return f"{field.address} (0x{field.address:04X})"
    return f"{field.address}-{field.end} (0x{field.address:04X}-0x{field.end:04X})"


def _meaning(field: RegisterField) -> str:
    parts = [field.description] if field.description else []
    if field.values:
        parts.append(", ".join(f"{k} {v}" for k, v in sorted(field.values.items())))
    if field.bits:
        parts.append(
            ", ".join(f"bit{b} {n}" for n, b in sorted(field.bits.items(), key=lambda i: i[1]))
        )
    return "; ".join(parts).replace("|", "\\|")


def profile_markdown(profile: Profile) -> str:
    """The profile as a Markdown document: header facts and one table row per field.

    ``tmmaster profile show NAME`` prints it (the docs' profile pages are made so).

    Args:
        profile: A robot or gripper profile.

    Returns:
        The Markdown text.
    """
    out = [f"# Profile `{profile.name}`", "", profile.description, ""]
    facts = [f"- kind: {profile.kind}", f"- Modbus unit id: {profile.device_id}"]
    if isinstance(profile, RobotProfile):
        facts.append(f"- handshake: `{profile.handshake.value}`")
        if profile.has("robot_mode"):
            facts.append(f"- robot_mode auto = {profile.mode_auto}, error = {profile.mode_error}")
    else:
        facts.append(f"- driver: `{profile.driver}`")
        if profile.max_connections is not None:
            facts.append(f"- at most {profile.max_connections} TCP connection(s) at a time")
    facts.append(f"- a read may span up to {profile.max_read_gap} unused address(es)")
    out += [*facts, ""]
    out.append(
        "| Field | Role | Table | Address | Type | Scale | Word order | Access | Unit "
        "| Allowed | Meaning |"
    )
    out.append("|---|---|---|---|---|---|---|---|---|---|---|")
    for f in sorted(profile.fields.values(), key=lambda f: (f.table.value, f.address)):
        word_order = f.word_order.value if f.width == 2 else ""
        scale = "" if f.scale == 1 else f"x{f.scale:g}"
        allowed = "" if f.dtype is DataType.BOOL else describe_range(f).split(",")[0]
        out.append(
            f"| `{f.name}` | {f.role.value} | {f.table.value} | {_address(f)} | {f.dtype.value} "
            f"| {scale} | {word_order} | {f.access.value} | {f.unit} | {allowed} | {_meaning(f)} |"
        )
    out.append("")
    if isinstance(profile, RobotProfile) and profile.digital_io:
        out += [
            "Digital I/O (`Robot.io`): DO n is the coil at the first address + n (FC 01 read,"
            " FC 05 write), DI n the discrete input at the first address + n (FC 02).",
            "",
            "| Module | DO | Coils | DI | Discrete inputs | Source |",
            "|---|---|---|---|---|---|",
        ]
        for name, module in sorted(profile.digital_io.items()):
            out.append(
                f"| `{name}` | {_io_range(module.do_count)}"
                f" | {_io_range(module.do_count, module.do_address)}"
                f" | {_io_range(module.di_count)}"
                f" | {_io_range(module.di_count, module.di_address)} | {module.source} |"
            )
        out.append("")
    return "\n".join(out)


def _io_range(count: int, first: int = 0) -> str:
    """``first``..``first + count - 1`` as ``0-15``; empty when there are none."""
    return "" if count == 0 else f"{first}" if count == 1 else f"{first}-{first + count - 1}"
