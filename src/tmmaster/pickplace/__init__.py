"""Pick & place (and any other sequence) on a ``transitions`` state machine.

The article's cycle runs with ``python -m tmmaster.pickplace --sim`` (against the
built-in simulator) or ``--host H`` (a robot). From Python:

```python
from tmmaster import connect
from tmmaster.pickplace import Runner, load_config, pick_and_place

config = load_config("cell.toml")
with connect("127.0.0.1", 5020, profile="article") as robot:
    result = Runner(robot).run(pick_and_place(config))
```

A :class:`TaskSequence` says what to do in each state; the :class:`Runner` runs any
sequence with the same policies (readiness, stop requests, retries, cycles, timing,
logging, error reaction). See docs/pickplace.md.
"""

from __future__ import annotations

from typing import TYPE_CHECKING as _TYPE_CHECKING

from .._lazy import lazy_attributes as _lazy_attributes

if _TYPE_CHECKING:
    from ._config import (
        ARTICLE_HOME,
        ARTICLE_PICK,
        ARTICLE_PLACE,
        GripperSection,
        MotionSection,
        OnErrorSection,
        PickPlaceConfig,
        PosesSection,
        RetrySection,
        RobotSection,
        RunSection,
        SpeedsSection,
        TimeoutsSection,
        WorkspaceSection,
        load_config,
        robot_from_config,
        validate_config,
    )
    from ._machine import DONE, ERROR, IDLE, SequenceMachine, mermaid
    from ._plan import EstimatedMove, estimate, format_plan, validate_plan
    from ._report import (
        ConfigRef,
        CycleSummary,
        ErrorInfo,
        LinkStats,
        ReactionInfo,
        Retries,
        RunReport,
        SimObject,
        SimSummary,
        StateTiming,
        Target,
        TimelineEntry,
        TransportSummary,
        build_report,
        load_report,
        report_schema,
        write_report,
    )
    from ._runner import (
        Failure,
        ReactionRecord,
        Runner,
        RunResult,
        StateEvent,
        StateRecord,
        StopRequestedError,
    )
    from ._sequences import (
        PICK_AND_PLACE_STATES,
        Pallet,
        grasp_detected,
        load_sequence,
        palletizing,
        pick_and_place,
        sequence_from_data,
    )
    from ._steps import Cycles, PlannedMove, RetryRule, Step, StepContext, TaskSequence

#: Public name -> the private module that defines it (imported on first use).
_EXPORTS = {
    "ARTICLE_HOME": "._config",
    "ARTICLE_PICK": "._config",
    "ARTICLE_PLACE": "._config",
    "ConfigRef": "._report",
    "CycleSummary": "._report",
    "Cycles": "._steps",
    "DONE": "._machine",
    "ERROR": "._machine",
    "ErrorInfo": "._report",
    "EstimatedMove": "._plan",
    "Failure": "._runner",
    "GripperSection": "._config",
    "IDLE": "._machine",
    "LinkStats": "._report",
    "MotionSection": "._config",
    "OnErrorSection": "._config",
    "PICK_AND_PLACE_STATES": "._sequences",
    "Pallet": "._sequences",
    "PickPlaceConfig": "._config",
    "PlannedMove": "._steps",
    "PosesSection": "._config",
    "ReactionInfo": "._report",
    "ReactionRecord": "._runner",
    "Retries": "._report",
    "RetryRule": "._steps",
    "RetrySection": "._config",
    "RobotSection": "._config",
    "RunReport": "._report",
    "RunResult": "._runner",
    "RunSection": "._config",
    "Runner": "._runner",
    "SequenceMachine": "._machine",
    "SimObject": "._report",
    "SimSummary": "._report",
    "SpeedsSection": "._config",
    "StateEvent": "._runner",
    "StateRecord": "._runner",
    "StateTiming": "._report",
    "Step": "._steps",
    "StepContext": "._steps",
    "StopRequestedError": "._runner",
    "Target": "._report",
    "TaskSequence": "._steps",
    "TimelineEntry": "._report",
    "TimeoutsSection": "._config",
    "TransportSummary": "._report",
    "WorkspaceSection": "._config",
    "build_report": "._report",
    "estimate": "._plan",
    "format_plan": "._plan",
    "grasp_detected": "._sequences",
    "load_config": "._config",
    "load_report": "._report",
    "load_sequence": "._sequences",
    "mermaid": "._machine",
    "palletizing": "._sequences",
    "pick_and_place": "._sequences",
    "report_schema": "._report",
    "robot_from_config": "._config",
    "sequence_from_data": "._sequences",
    "validate_config": "._config",
    "validate_plan": "._plan",
    "write_report": "._report",
}

__getattr__, __dir__ = _lazy_attributes(__name__, globals(), _EXPORTS)

__all__ = [
    "ARTICLE_HOME",
    "ARTICLE_PICK",
    "ARTICLE_PLACE",
    "DONE",
    "ERROR",
    "IDLE",
    "PICK_AND_PLACE_STATES",
    "ConfigRef",
    "CycleSummary",
    "Cycles",
    "ErrorInfo",
    "EstimatedMove",
    "Failure",
    "GripperSection",
    "LinkStats",
    "MotionSection",
    "OnErrorSection",
    "Pallet",
    "PickPlaceConfig",
    "PlannedMove",
    "PosesSection",
    "ReactionInfo",
    "ReactionRecord",
    "Retries",
    "RetryRule",
    "RetrySection",
    "RobotSection",
    "RunReport",
    "RunResult",
    "RunSection",
    "Runner",
    "SequenceMachine",
    "SimObject",
    "SimSummary",
    "SpeedsSection",
    "StateEvent",
    "StateRecord",
    "StateTiming",
    "Step",
    "StepContext",
    "StopRequestedError",
    "Target",
    "TaskSequence",
    "TimelineEntry",
    "TimeoutsSection",
    "TransportSummary",
    "WorkspaceSection",
    "build_report",
    "estimate",
    "format_plan",
    "grasp_detected",
    "load_config",
    "load_report",
    "load_sequence",
    "mermaid",
    "palletizing",
    "pick_and_place",
    "report_schema",
    "robot_from_config",
    "sequence_from_data",
    "validate_config",
    "validate_plan",
    "write_report",
]
