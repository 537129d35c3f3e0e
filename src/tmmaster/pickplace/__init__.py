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

from types import FunctionType as _FunctionType

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
    TimelineScope,
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
    "TimelineScope",
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

# Shown as tmmaster.pickplace.Name where they are used (tracebacks, reprs, the docs), not as the
# private module that defines them.
for _name in __all__:
    _value = globals()[_name]
    if isinstance(_value, type | _FunctionType) and _value.__module__.startswith(f"{__name__}._"):
        _value.__module__ = __name__
del _name, _value
