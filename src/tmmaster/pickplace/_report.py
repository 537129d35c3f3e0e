"""The JSON run report: what ran, how long each state took, what the link did, how it ended.

:class:`RunReport` is the report's pydantic model: the command builds one, writes it as
JSON (:func:`write_report`) and ``tmmaster report show|plot`` reads it back
(:func:`load_report`). Its JSON Schema ships as ``tmmaster/schemas/run-report.schema.json``.
Keys are only ever added (with a default), so an older report still reads.
"""

from __future__ import annotations

import json
import math
import os
import re
import stat
import sys
import tempfile
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from .._exceptions import ConfigError, EmergencyStopError, RobotFaultError
from .._pose import Pose
from .._tm_errors import describe
from ._runner import RunResult

#: Bumped when a key changes meaning or disappears (adding keys keeps the version).
#: 2: ``timeline`` and ``cycles.times_s`` may hold part of a long run (``timeline_scope``,
#: ``cycles.times_omitted``); every pass is still counted in ``states`` and ``cycles``.
REPORT_VERSION = 2

#: The report versions :func:`load_report` reads: every one up to this tmmaster's (keys
#: are only ever added, with defaults); a newer one may mean something else.
SUPPORTED_REPORT_VERSIONS = range(1, REPORT_VERSION + 1)

#: Largest report :func:`load_report` reads, bytes (256 MiB). A report of this tmmaster
#: lists the passes of at most 120 cycles and 2,000 cycle times (some 200 kB whatever the
#: cycles; a --sim run adds its TCP path, at most 200,000 rows, and its parts); a version 1
#: report listed every pass, about 1.3 kB per cycle. Reading one takes several times its
#: size in memory, which is what the limit protects (and reading /dev/zero would never end).
MAX_REPORT_BYTES = 256 * 1024 * 1024


class _Part(BaseModel):
    # Unknown keys (from a newer tmmaster) are ignored on reading; the docstring under a
    # field is its description in the JSON Schema.
    model_config = ConfigDict(extra="ignore", use_attribute_docstrings=True)


class ConfigRef(_Part):
    """Which configuration ran."""

    file: str | None = None
    """The configuration file given with ``--config`` (null: the defaults)."""
    digest: str | None = None
    """``sha256:`` of the normalised configuration."""


class Target(_Part):
    """The robot the run talked to."""

    host: str
    """The robot's address."""
    port: int
    """Its Modbus TCP port."""
    profile: str
    """The register profile it was spoken to in."""


class CycleSummary(_Part):
    """Cycles requested and completed, with each completed cycle's time."""

    requested: int | None = None
    """Cycles asked for (null: the run did not start)."""
    completed: int = 0
    """Cycles finished."""
    times_s: list[float] = Field(default_factory=list)
    """Seconds per completed cycle: every one, or (``times_omitted`` > 0) the first
    ``times_omitted_at`` cycles' then the latest cycles'."""
    times_omitted: int = 0
    """Cycle times left out of ``times_s`` (counted in the statistics below)."""
    times_omitted_at: int = 0
    """Where in ``times_s`` they were left out: ``times_s[i]`` is cycle ``i + 1`` before
    it, cycle ``i + 1 + times_omitted`` from it on."""
    total_s: float | None = None
    """Seconds of every completed cycle together (null: none completed, or a report older
    than this key)."""
    mean_s: float | None = None
    """Mean seconds per completed cycle (null: none, or an older report)."""
    min_s: float | None = None
    """The shortest completed cycle, seconds (null: none, or an older report)."""
    max_s: float | None = None
    """The longest completed cycle, seconds (null: none, or an older report)."""

    trend: list[tuple[int, int, float, float, float]] = Field(default_factory=list)
    """The cycle times over the whole run, at most 200 rows: ``[first_cycle, cycles,
    mean_s, min_s, max_s]`` per block of consecutive completed cycles (one cycle per
    block up to 200 cycles, then 2, 4, 8...; the last block may be shorter). Empty in a
    report older than this key."""

    def cycle_of(self, index: int) -> int:
        """The cycle (from 1) whose time is ``times_s[index]``.

        Args:
            index: A position in ``times_s``.

        Returns:
            The cycle's number, counting the cycles whose times were omitted.
        """
        return index + 1 + (self.times_omitted if index >= self.times_omitted_at > 0 else 0)


class StateTiming(_Part):
    """Time spent in one state over the run (skipped passes excluded)."""

    count: int
    """Passes through the state."""
    total_s: float
    """Seconds in the state, all passes together."""
    mean_s: float
    """Mean seconds per pass."""
    max_s: float
    """The longest pass, seconds."""
    min_s: float | None = None
    """The shortest pass, seconds (null: a report older than this key)."""
    retries: int = 0
    """Passes that failed and were tried again (counted in ``count``)."""
    failures: int = 0
    """Passes that failed the run (counted in ``count``)."""


class TimelineScope(_Part):
    """What ``timeline`` lists of a run: long runs list the passes of some cycles only."""

    passes: int
    """Passes through a state in the run (skipped ones too), listed or not."""
    listed_passes: int
    """Passes listed in ``timeline``."""
    listed_cycles: int
    """Cycles (from 1) whose passes are listed."""
    omitted_cycles: int
    """Cycles whose passes are only counted, in ``states``."""
    first_cycles: int
    """The first cycles are listed, up to this many (and IDLE, cycle 0)."""
    last_cycles: int
    """The latest cycles are listed, up to this many."""
    marked_cycles: int
    """The most other cycles with a retried or failed pass listed."""
    marked_cycles_omitted: int = 0
    """Cycles with a retried or failed pass not listed (over ``marked_cycles``)."""


class TimelineEntry(_Part):
    """One pass through a state."""

    state: str
    """The state."""
    cycle: int
    """The cycle, from 1."""
    started_s: float
    """Seconds since the run started."""
    duration_s: float
    """How long the pass took, seconds."""
    outcome: str
    """``ok``, ``skipped``, ``retry`` or ``failed``."""


class Retries(_Part):
    """Retries used."""

    grasp: int = 0
    """Grasps tried again after a failed one."""


class ErrorInfo(_Part):
    """The failure that ended the run."""

    state: str
    """The state that failed."""
    cycle: int
    """The cycle, from 1."""
    type: str
    """The error's type (``MotionTimeoutError``...)."""
    message: str
    """The error's message."""
    error_code: int | None = None
    """The robot's error code, when the failure carries one."""
    error_meaning: str | None = None
    """A robot fault's or e-stop's code and its text in TMflow 2.24 Appendix J
    (``0x0022 Force or Torque Over Range``; ``0x1234 (not in TMflow 2.24 Appendix J)``)."""


class ReactionInfo(_Part):
    """What was done after the failure."""

    reaction: str
    """``stay`` or ``retreat``."""
    performed: bool
    """Whether it was carried out (never a retreat after an e-stop or a robot error)."""
    detail: str
    """What happened, in words."""


class LinkStats(_Part):
    """One Modbus link's counters."""

    requests: int = 0
    """Requests sent (retries included)."""
    retries: int = 0
    """Retries of failed requests and connects."""
    reconnects: int = 0
    """Connections opened again after a lost link."""
    errors: int = 0
    """Failed requests."""
    bytes_sent: int = 0
    """Bytes sent."""
    bytes_received: int = 0
    """Bytes received."""
    requests_by_function: dict[str, int] = Field(default_factory=dict)
    """Requests per Modbus function code (keys are the codes as text)."""

    @field_validator("requests_by_function", mode="before")
    @classmethod
    def _codes_as_text(cls, value: Any) -> Any:
        if isinstance(value, dict):
            return {str(k): v for k, v in value.items()}
        return value


class TransportSummary(_Part):
    """The robot's link, and the gripper's when it has its own."""

    robot: LinkStats
    """The robot's link."""
    gripper: LinkStats | None = None
    """The gripper's own link (null: it has none)."""


class SimObject(_Part):
    """Where a simulated part ended."""

    name: str
    """The part's name."""
    pose: list[float]
    """``[x, y, z, rx, ry, rz]``, mm and degrees."""
    held: bool
    """Whether the gripper held it at the end."""
    resting_on: str | None = None
    """What the part rests on (``table`` or another part's name); null while held or falling."""
    on_place: bool
    """Whether it lies on the place position (within ``tolerance_mm``)."""
    run_part: bool = True
    """Whether the run was to place it (it waited at the pick pose); a scene's other parts
    are reported where they ended and count for nothing."""


class SimSummary(_Part):
    """With ``--sim``: where the parts ended, and the path the TCP took."""

    objects: list[SimObject] = Field(default_factory=list)
    """Where the parts ended: every one up to 100; beyond, the first and the last 10 of the
    run's, every other part, and up to 100 run parts not on the place position."""
    objects_total: int | None = None
    """Parts in the simulator, listed or not (null: a report older than this key, which
    lists every part)."""
    objects_on_place: int | None = None
    """Parts on the place position, listed or not (null: an older report)."""
    pick: list[float] | None = None
    """The pick pose ``[x, y, z, rx, ry, rz]``, where the parts waited (null: none, or a
    report older than this key)."""
    place: list[float] | None = None
    """The place pose ``[x, y, z, rx, ry, rz]`` (null: none)."""
    tolerance_mm: float = 2.0
    """How close to the place pose a part counts as placed, mm."""
    on_place: bool = False
    """Every part of the run (``run_part``) on the place position."""
    time_scale: float = 1.0
    """Simulated seconds per wall second."""
    physics: str = "kinematic"
    """The simulator's physics backend: ``kinematic`` or ``mujoco``."""
    tcp_path: list[tuple[float, float, float, float]] = Field(default_factory=list)
    """The TCP as the simulator saw it: ``[t_s, x, y, z]`` rows, ``t_s`` in wall seconds since
    the run started (same clock as ``timeline``), a row whenever it moved."""


class RunReport(_Part):
    """The run report written by ``--report`` (every key present; unknown values null)."""

    report_version: int = REPORT_VERSION
    """Changes when a key changes meaning or disappears (keys are only ever added)."""
    tmmaster_version: str
    """The tmmaster version that wrote the report."""
    result: str
    """``done``, ``failed``, ``config_error``, ``connection_error``, ``robot_fault``,
    ``grasp_failed``, ``timeout`` or ``interrupted``."""
    exit_code: int
    """The command's exit code (docs/pickplace.md, exit codes)."""
    reason: str | None = None
    """The one-line reason (null on success)."""
    config: ConfigRef = Field(default_factory=ConfigRef)
    """Which configuration ran."""
    target: Target | None = None
    """The robot the run talked to (null: it did not get that far)."""
    sequence: str | None = None
    """The sequence's name."""
    final_state: str | None = None
    """The state the machine ended in: ``DONE`` or ``ERROR``."""
    started_at: str | None = None
    """ISO 8601 UTC time the run started."""
    duration_s: float | None = None
    """How long the run took, seconds."""
    cycles: CycleSummary = Field(default_factory=CycleSummary)
    """Cycles requested and completed."""
    states: dict[str, StateTiming] = Field(default_factory=dict)
    """Time spent in each state, by name."""
    timeline: list[TimelineEntry] = Field(default_factory=list)
    """The passes through a state, in order: every one, or those ``timeline_scope`` says."""
    timeline_scope: TimelineScope | None = None
    """What ``timeline`` lists (null: every pass; a report older than this key)."""
    retries: Retries = Field(default_factory=Retries)
    """Retries used."""
    error: ErrorInfo | None = None
    """The failure that ended the run (null on success)."""
    reaction: ReactionInfo | None = None
    """What was done after the failure (null without one)."""
    stop_delivered: bool | None = None
    """Whether a stop reached the robot after a stop request or an abandoned move (null: none
    was needed, or the profile has no stop)."""
    transport: TransportSummary | None = None
    """The links' counters."""
    sim: SimSummary | None = None
    """With ``--sim``: where the parts ended, and the TCP's path."""
    move_states: list[str] = Field(default_factory=list)
    """The states that move the arm (known from the plan); the rest wait (gripper, checks,
    dwells). Empty in reports older than this key."""


def report_schema() -> str:
    """The JSON Schema of the run report, generated from :class:`RunReport`.

    Returns:
        The schema as indented JSON text (``tmmaster schema --report``).
    """
    schema = RunReport.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "tmmaster pick & place run report (JSON)"
    return json.dumps(schema, indent=2, sort_keys=True) + "\n"


def load_report(path: str | Path) -> RunReport:
    """Read a run report written by ``--report`` (:func:`write_report`).

    Args:
        path: the report file.

    Returns:
        The validated report.

    Raises:
        ConfigError: the file is missing or unreadable, is not a regular file (a
            directory, a FIFO, a device), is larger than :data:`MAX_REPORT_BYTES`, is not
            UTF-8, is not a run report, or has a ``report_version`` this tmmaster does not
            read (:data:`SUPPORTED_REPORT_VERSIONS`). The message names the file.
    """
    data = _parse_report_json(path, _read_report_text(path))
    version = data.get("report_version") if isinstance(data, dict) else None
    # Checked first: a report from a newer tmmaster fails validation in ways that would
    # hide the real reason (its keys may mean something else).
    if (
        isinstance(version, int)
        and not isinstance(version, bool)
        and version not in SUPPORTED_REPORT_VERSIONS
    ):
        raise ConfigError(
            f"{path}: report_version {version} is not supported (this tmmaster reads"
            f" {SUPPORTED_REPORT_VERSIONS.start}..{SUPPORTED_REPORT_VERSIONS.stop - 1};"
            " a newer tmmaster may have written it)"
        )
    try:
        return RunReport.model_validate(data)
    except ValidationError as exc:
        # The location holds the file's own keys: made printable like everything shown.
        problems = "; ".join(
            f"{printable('.'.join(str(p) for p in err['loc']), 200) or '(top)'}: {err['msg']}"
            for err in exc.errors()[:3]
        )
        raise ConfigError(f"{path}: not a tmmaster run report: {problems}") from None


def _parse_report_json(path: str | Path, text: str) -> Any:
    """The report's JSON value; ConfigError (naming the file) for anything json refuses."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(
            f"{path}: not a tmmaster run report: invalid JSON at line {exc.lineno}"
            f" column {exc.colno}: {exc.msg}"
        ) from None
    except RecursionError:  # the C parser's guard against deep nesting
        raise ConfigError(
            f"{path}: not a tmmaster run report: arrays or objects nested too deeply"
        ) from None
    except ValueError:  # an integer of more digits than Python converts
        raise ConfigError(
            f"{path}: not a tmmaster run report: an integer of more than"
            f" {sys.get_int_max_str_digits()} digits"
        ) from None


#: Characters a terminal acts on instead of showing: C0 and C1 controls (ESC starts the
#: ANSI sequences that move the cursor, clear the screen or set the window title), DEL,
#: the line and paragraph separators, and the bidirectional overrides that reorder text.
_UNPRINTABLE = re.compile("[\x00-\x1f\x7f-\x9f\u061c\u200e\u200f\u2028-\u202e\u2066-\u2069]")


def printable(text: str, limit: int) -> str:
    """``text`` safe to print on a terminal: every control character escaped, at most ``limit``.

    Each control character (:data:`_UNPRINTABLE`) is written as Python writes it in a
    string (``\\x1b``, ``\\n``, ``\\u202e``), so the text shows what the file holds
    and never moves the cursor or recolours the terminal; a longer text is cut to ``limit``
    characters and ends with ``...``. (Rich markup is a separate matter: strings shown
    through rich go in ``Text`` objects, never parsed as markup.)

    Args:
        text: A string taken from a file.
        limit: The most characters to keep (at least 4).

    Returns:
        The printable text.
    """
    if len(text) > limit:
        text = text[: limit - 3] + "..."
    return _UNPRINTABLE.sub(lambda m: m[0].encode("unicode_escape").decode("ascii"), text)


def _read_report_text(path: str | Path) -> str:
    """The report's text: a regular file of at most MAX_REPORT_BYTES, strict UTF-8."""
    # O_NONBLOCK: opening a FIFO without a writer would otherwise wait forever; a regular
    # file reads the same with it. (Not on Windows, which has no FIFOs to open here.)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the report: {exc.strerror or exc}") from None
    too_big = ConfigError(
        f"{path}: larger than {MAX_REPORT_BYTES // (1024 * 1024)} MiB, the most a run report may be"
    )
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise ConfigError(
                f"{path}: not a regular file (a run report is a JSON file written by --report)"
            )
        if info.st_size > MAX_REPORT_BYTES:
            raise too_big
        with os.fdopen(fd, "rb") as handle:
            fd = -1  # the file object closes it now
            # One byte more than allowed: a file that grew since fstat is still caught.
            data = handle.read(MAX_REPORT_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the report: {exc.strerror or exc}") from None
    finally:
        if fd >= 0:
            os.close(fd)
    if len(data) > MAX_REPORT_BYTES:
        raise too_big
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(
            f"{path}: not UTF-8 text (byte {exc.start}: {data[exc.start : exc.start + 1]!r});"
            " a run report is UTF-8 JSON"
        ) from None


def objects_report(
    objects: list[Any],
    place: Pose | None,
    tolerance_mm: float,
    run_parts: set[str] | None = None,
) -> dict[str, Any]:
    """Where the simulator's objects ended, and whether they are on the place position.

    The place check is the same for every physics backend: a part released at the place
    pose falls onto the surface below it, so it is on the place position when it is not
    held, rests on something (the table or another part) and its x-y is within
    ``tolerance_mm`` of the place pose's x-y (docs/simulator-model.md, "Falling").

    Args:
        objects: The simulator's objects (``name``, ``pose``, ``held``, ``resting_on``).
        place: The place pose, or None (a sequence without one).
        tolerance_mm: How close to the place pose's x-y a part counts as placed, mm.
        run_parts: The names of the parts the run was to place; None: every object.

    Returns:
        The report's ``sim`` fields: ``objects``, ``place``, ``tolerance_mm``, ``on_place``
        (every run part on the place position).
    """
    items = [
        {
            "name": obj.name,
            "pose": obj.pose.as_list(),
            "held": obj.held,
            "resting_on": obj.resting_on,
            "on_place": place is not None
            and not obj.held
            and obj.resting_on is not None
            and math.hypot(obj.pose.x - place.x, obj.pose.y - place.y) <= tolerance_mm,
            "run_part": run_parts is None or obj.name in run_parts,
        }
        for obj in objects
    ]
    counted = [i for i in items if i["run_part"]]
    return {
        "objects": _listed_objects(items),
        "objects_total": len(items),
        "objects_on_place": sum(bool(i["on_place"]) for i in items),
        "place": None if place is None else place.as_list(),
        "tolerance_mm": tolerance_mm,
        "on_place": place is not None and bool(counted) and all(i["on_place"] for i in counted),
    }


#: Parts listed one by one in a --sim report whatever their number; beyond, see
#: :func:`_listed_objects` (a --sim run has one part per cycle).
MAX_LISTED_OBJECTS = 100


def _listed_objects(items: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Every part up to MAX_LISTED_OBJECTS; beyond, in order: the first and the last 10 of
    the run's parts, every part of the scene's own, and up to MAX_LISTED_OBJECTS run parts
    not on the place position (the ones to look at)."""
    if len(items) <= MAX_LISTED_OBJECTS:
        return items
    run = [i for i, item in enumerate(items) if item["run_part"]]
    keep = {*run[:10], *run[-10:]}
    keep |= {i for i, item in enumerate(items) if not item["run_part"]}
    misplaced = [i for i in run if not items[i]["on_place"]]
    keep |= set(misplaced[:MAX_LISTED_OBJECTS])
    return [items[i] for i in sorted(keep)]


def build_report(
    *,
    exit_code: int,
    result_name: str,
    reason: str | None,
    run: RunResult | None = None,
    config_file: str | None = None,
    config_digest: str | None = None,
    target: dict[str, Any] | None = None,
    transport: dict[str, Any] | None = None,
    sim: dict[str, Any] | None = None,
    move_states: list[str] | None = None,
) -> dict[str, Any]:
    """Assemble the report as JSON-ready data (every key present; unknown values null).

    Args:
        exit_code: The command's exit code.
        result_name: ``done``, ``failed``, ``config_error``... (RunReport.result).
        reason: The one-line reason (None on success).
        run: The runner's result (None: the run did not start).
        config_file: The configuration file (None: the defaults).
        config_digest: The configuration's digest (``PickPlaceConfig.digest()``).
        target: The robot's ``host``, ``port`` and ``profile``.
        transport: The links' counters (``robot``, ``gripper``).
        sim: With ``--sim``: where the parts ended and the TCP's path.
        move_states: The states that move the arm.

    Returns:
        The report as a dict of JSON values (validated as a RunReport).
    """
    return build_run_report(
        exit_code=exit_code,
        result_name=result_name,
        reason=reason,
        run=run,
        config_file=config_file,
        config_digest=config_digest,
        target=target,
        transport=transport,
        sim=sim,
        move_states=move_states,
    ).model_dump(mode="json")


def build_run_report(
    *,
    exit_code: int,
    result_name: str,
    reason: str | None,
    run: RunResult | None = None,
    config_file: str | None = None,
    config_digest: str | None = None,
    target: dict[str, Any] | None = None,
    transport: dict[str, Any] | None = None,
    sim: dict[str, Any] | None = None,
    move_states: list[str] | None = None,
) -> RunReport:
    """Assemble the report as a validated :class:`RunReport`."""
    from .. import __version__

    data = {
        "report_version": REPORT_VERSION,
        "tmmaster_version": __version__,
        "result": result_name,
        "exit_code": exit_code,
        "reason": reason,
        "config": {"file": config_file, "digest": config_digest},
        "target": target,
        **_run_fields(run),
        "transport": transport,
        "sim": sim,
        "move_states": list(move_states or []),
    }
    return RunReport.model_validate(data)


def fault_meaning(exc: BaseException) -> str | None:
    """The code and meaning of a robot fault or e-stop, for a report.

    Args:
        exc: The error that ended a run.

    Returns:
        ``"0x0022 Force or Torque Over Range"`` for a RobotFaultError or EmergencyStopError
        with a code (TMflow's codes), else None (other errors' codes are not Techman's).
    """
    if not isinstance(exc, RobotFaultError | EmergencyStopError) or not exc.error_code:
        return None
    return describe(exc.error_code)


def _run_fields(run: RunResult | None) -> dict[str, Any]:
    """The report's fields that come from the run (their empty values without one)."""
    if run is None:
        return {
            "sequence": None,
            "final_state": None,
            "started_at": None,
            "duration_s": None,
            "cycles": {"requested": None, "completed": 0, "times_s": []},
            "states": {},
            "timeline": [],
            "timeline_scope": None,
            "retries": {"grasp": 0},
            "error": None,
            "reaction": None,
            "stop_delivered": None,
        }
    failure, reaction = run.failure, run.reaction
    counted = run.log.cycles.count
    omitted = max(counted - len(run.cycle_times_s), 0)
    cycle_stats = run.log.cycles.as_dict() if counted else {}
    return {
        "sequence": run.sequence,
        "final_state": run.state,
        "started_at": run.started_at,
        "duration_s": run.duration_s,
        "cycles": {
            "requested": run.cycles_requested,
            "completed": run.cycles_completed,
            "times_s": run.cycle_times_s,
            "times_omitted": omitted,
            "times_omitted_at": run.log.times_kept_first if omitted else 0,
            **{k: cycle_stats.get(k) for k in ("total_s", "mean_s", "min_s", "max_s")},
            "trend": run.log.trend(),
        },
        "states": run.state_timings(),
        "timeline": [
            {
                "state": r.state,
                "cycle": r.cycle,
                "started_s": r.started_s,
                "duration_s": r.duration_s,
                "outcome": r.outcome,
            }
            for r in run.records
        ],
        # Null for a RunResult made without a runner (its records are all there is).
        "timeline_scope": run.log.scope() if run.log.passes else None,
        "retries": {"grasp": run.retries},
        "error": None
        if failure is None
        else {**failure.as_dict(), "error_meaning": fault_meaning(failure.exception)},
        "reaction": None
        if reaction is None
        else {
            "reaction": reaction.reaction,
            "performed": reaction.performed,
            "detail": reaction.detail,
        },
        # Whether a stop reached the robot after a stop request or an abandoned move
        # (null: none was needed, or the profile has no stop).
        "stop_delivered": run.stop_delivered,
    }


#: A JSON array of numbers only, as ``json.dumps(indent=2)`` spreads it over lines.
_NUMBER_ARRAY = re.compile(r"\[\s*\n\s*(-?[\d.eE+-]+(?:,\s*\n\s*-?[\d.eE+-]+)*)\s*\n\s*\]")


def _dumps(report: dict[str, Any]) -> str:
    """Indented JSON with every array of numbers on one line (poses, times, TCP rows)."""
    text = json.dumps(report, indent=2, sort_keys=False)
    return _NUMBER_ARRAY.sub(lambda m: "[" + re.sub(r",\s*\n\s*", ", ", m[1]) + "]", text)


def write_report(path: str | Path, report: RunReport | dict[str, Any]) -> None:
    """Write the report atomically (a crash never leaves half a JSON file).

    Args:
        path: The file (its folder is made if needed).
        report: The report, as a RunReport or as :func:`build_report`'s data.
    """
    if isinstance(report, RunReport):
        report = report.model_dump(mode="json")
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".report-", suffix=".json", dir=target.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(_dumps(report))
            handle.write("\n")
        # mkstemp makes the file private (0600); a report is an ordinary file (0644
        # under the usual umask 022), like one opened with open(path, "w").
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
