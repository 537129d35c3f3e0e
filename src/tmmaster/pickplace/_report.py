"""The JSON run report: what ran, how long each state took, what the link did, how it ended."""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

from .._pose import Pose
from ._runner import RunResult

#: Bumped when a key changes meaning or disappears (adding keys keeps the version).
REPORT_VERSION = 1


def objects_report(objects: list[Any], place: Pose | None, tolerance_mm: float) -> dict[str, Any]:
    """Where the simulator's objects ended, and whether they are on the place position.

    The place check is the same for every physics backend: a part released at the place
    pose falls onto the surface below it, so it is on the place position when it is not
    held, rests on something (the table or another part) and its x-y is within
    ``tolerance_mm`` of the place pose's x-y (docs/simulator-model.md, "Falling").
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
        }
        for obj in objects
    ]
    return {
        "objects": items,
        "place": None if place is None else place.as_list(),
        "tolerance_mm": tolerance_mm,
        "on_place": place is not None and bool(items) and all(i["on_place"] for i in items),
    }


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
) -> dict[str, Any]:
    """Assemble the report (every key always present; unknown values are null)."""
    from .. import __version__

    return {
        "report_version": REPORT_VERSION,
        "tmmaster_version": __version__,
        "result": result_name,
        "exit_code": exit_code,
        "reason": reason,
        "config": {"file": config_file, "digest": config_digest},
        "target": target,
        "sequence": None if run is None else run.sequence,
        "final_state": None if run is None else run.state,
        "started_at": None if run is None else run.started_at,
        "duration_s": None if run is None else run.duration_s,
        "cycles": {
            "requested": None if run is None else run.cycles_requested,
            "completed": 0 if run is None else run.cycles_completed,
            "times_s": [] if run is None else run.cycle_times_s,
        },
        "states": {} if run is None else run.state_timings(),
        "timeline": []
        if run is None
        else [
            {
                "state": r.state,
                "cycle": r.cycle,
                "started_s": r.started_s,
                "duration_s": r.duration_s,
                "outcome": r.outcome,
            }
            for r in run.records
        ],
        "retries": {"grasp": 0 if run is None else run.retries},
        "error": None if run is None or run.failure is None else run.failure.as_dict(),
        "reaction": None
        if run is None or run.reaction is None
        else {
            "reaction": run.reaction.reaction,
            "performed": run.reaction.performed,
            "detail": run.reaction.detail,
        },
        # Whether a stop reached the robot after a stop request or an abandoned move
        # (null: none was needed, or the profile has no stop).
        "stop_delivered": None if run is None else run.stop_delivered,
        "transport": transport,
        "sim": sim,
    }


def write_report(path: str | Path, report: dict[str, Any]) -> None:
    """Write the report atomically (a crash never leaves half a JSON file)."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".report-", suffix=".json", dir=target.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            json.dump(report, handle, indent=2, sort_keys=False)
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
