"""Pick & place (and any other sequence) on a ``transitions`` state machine.

The article's cycle runs with ``python -m tmmaster.pickplace --sim`` (against the
built-in simulator) or ``--host H`` (a robot). From Python::

    from tmmaster import connect
    from tmmaster.pickplace import Runner, load_config, pick_and_place

    config = load_config("cell.toml")
    with connect("127.0.0.1", 5020, profile="article") as robot:
        result = Runner(robot).run(pick_and_place(config))

A :class:`TaskSequence` says what to do in each state; the :class:`Runner` runs any
sequence with the same policies (readiness, stop requests, retries, cycles, timing,
logging, error reaction). See docs/pickplace.md.
"""

from __future__ import annotations

from ._config import (
    ARTICLE_HOME,
    ARTICLE_PICK,
    ARTICLE_PLACE,
    PickPlaceConfig,
    load_config,
    robot_from_config,
    validate_config,
)
from ._machine import DONE, ERROR, IDLE, SequenceMachine, mermaid
from ._plan import estimate, format_plan, validate_plan
from ._report import build_report, write_report
from ._runner import (
    Failure,
    ReactionRecord,
    Runner,
    RunResult,
    StateEvent,
    StateRecord,
    StepContext,
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
from ._steps import PlannedMove, RetryRule, Step, TaskSequence

__all__ = [
    "ARTICLE_HOME",
    "ARTICLE_PICK",
    "ARTICLE_PLACE",
    "DONE",
    "ERROR",
    "IDLE",
    "PICK_AND_PLACE_STATES",
    "Failure",
    "Pallet",
    "PickPlaceConfig",
    "PlannedMove",
    "ReactionRecord",
    "RetryRule",
    "RunResult",
    "Runner",
    "SequenceMachine",
    "StateEvent",
    "StateRecord",
    "Step",
    "StepContext",
    "StopRequestedError",
    "TaskSequence",
    "build_report",
    "estimate",
    "format_plan",
    "grasp_detected",
    "load_config",
    "load_sequence",
    "mermaid",
    "palletizing",
    "pick_and_place",
    "robot_from_config",
    "sequence_from_data",
    "validate_config",
    "validate_plan",
    "write_report",
]
