"""The state machine of a sequence, on ``transitions``: states and guarded transitions only.

The machine holds no socket and calls nothing on the robot: the runner runs a state's
action, then asks the machine to move on. Every transition is explicit and guarded:
``auto_transitions=False`` (transitions' ``to_<state>()`` helpers would skip the
guards), and an impossible trigger raises instead of being ignored.

Triggers:

* ``start``: IDLE to the first step (guard ``may_continue``: no stop requested).
* ``advance``: a step to the next one; the last step goes back to the first while
  cycles remain (``more_cycles``) or to DONE (``last_cycle``). Steps with a guard
  (e.g. CHECK_GRASP's ``grasp_detected``) only advance when it holds.
* ``retry``: a step with a retry rule back to its ``back_to`` step while attempts
  remain (``retries_left``).
* ``fail``: any step (and IDLE) to ERROR.
* ``reset``: DONE or ERROR back to IDLE.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast

from transitions import Machine

from ._steps import Step, StepContext, TaskSequence, require_count

IDLE = "IDLE"
"""The state before a run starts, and after ``reset``."""
DONE = "DONE"
"""The state after the last cycle's last step."""
ERROR = "ERROR"
"""The state after a failure (``fail``), from any step."""


class SequenceMachine:
    """The ``transitions`` model of one sequence run: current state, cycle, retries.

    A :class:`Runner` makes one per run; its triggers are ``start``, ``advance``,
    ``retry``, ``fail`` and ``reset`` (bound by ``transitions``).

    Args:
        sequence: The sequence (validated here).
        cycles: How many cycles to run, >= 1.
        stop_event: Set when a stop is requested: no transition but the end of a
            finished cycle is taken then.
        stopped: Read instead of ``stop_event``: True once a stop is requested (a
            :class:`Runner`'s, noted by a Ctrl-C's handler before its event is set).
        guard_context: What steps' guards are asked about when a trigger passes no
            context.

    Raises:
        ConfigError: An invalid sequence, or a cycle count that is not a whole number
            >= 1.
    """

    #: The current state: IDLE, a step's name, DONE or ERROR (maintained by transitions).
    state: str

    if TYPE_CHECKING:
        # Trigger methods that transitions binds onto the model at run time.
        def start(self, *context: object) -> bool: ...
        def advance(self, *context: object) -> bool: ...
        def retry(self, *context: object) -> bool: ...
        def fail(self, *context: object) -> bool: ...
        def reset(self, *context: object) -> bool: ...

    def __init__(
        self,
        sequence: TaskSequence,
        *,
        cycles: int,
        stop_event: threading.Event | None = None,
        guard_context: Callable[[], Any] | None = None,
        stopped: Callable[[], bool] | None = None,
    ) -> None:
        sequence.validate()
        require_count(cycles)
        #: The sequence it runs.
        self.sequence = sequence
        #: How many cycles to run.
        self.cycles = cycles
        #: The current cycle, 1-based (0 before the first).
        self.cycle = 0
        #: Retries used in this cycle, by step name.
        self.retries_used: dict[str, int] = {}
        self._steps = {s.name: s for s in sequence.steps}
        self._stopped = stopped or (stop_event or threading.Event()).is_set
        # Guards of steps are asked about the runner's context: the runner passes it
        # with the trigger (``advance(ctx)``); this callable is the fallback without one.
        self._guard_context: Callable[[], Any] = (
            guard_context if guard_context is not None else (lambda: None)
        )
        #: The ``transitions`` machine.
        self.machine = Machine(
            model=self,
            states=[IDLE, *self._steps, DONE, ERROR],
            transitions=self._transitions(sequence.steps),
            initial=IDLE,
            auto_transitions=False,
            ignore_invalid_triggers=False,
            send_event=False,
            queued=False,
        )

    # -- structure ----------------------------------------------------------

    def _guard(self, step: Step) -> list[str]:
        if step.guard is None:
            return []
        name = f"guard_{step.guard_name or step.name.lower()}"
        guard = step.guard

        def check(*args: object) -> bool:
            # The runner passes its step context with the trigger (advance(ctx)).
            ctx = args[0] if args else self._guard_context()
            return bool(guard(cast("StepContext", ctx)))

        setattr(self, name, check)
        return [name]

    def _transitions(self, steps: list[Step]) -> list[dict[str, Any]]:
        names = [s.name for s in steps]
        table: list[dict[str, Any]] = [
            {
                "trigger": "start",
                "source": IDLE,
                "dest": names[0],
                "conditions": ["may_continue"],
                "after": "_begin_cycle",
            }
        ]
        for index, step in enumerate(steps):
            guards = self._guard(step)
            if index + 1 < len(steps):
                table.append(
                    {
                        "trigger": "advance",
                        "source": step.name,
                        "dest": names[index + 1],
                        "conditions": ["may_continue", *guards],
                    }
                )
            else:
                table.append(
                    {
                        "trigger": "advance",
                        "source": step.name,
                        "dest": names[0],
                        "conditions": ["may_continue", "more_cycles", *guards],
                        "after": "_begin_cycle",
                    }
                )
                # A finished cycle is finished even if a stop was requested meanwhile.
                table.append(
                    {
                        "trigger": "advance",
                        "source": step.name,
                        "dest": DONE,
                        "conditions": ["last_cycle", *guards],
                    }
                )
            if step.retry is not None:
                table.append(
                    {
                        "trigger": "retry",
                        "source": step.name,
                        "dest": step.retry.back_to,
                        "conditions": ["may_continue", "retries_left"],
                        "before": "_count_retry",
                    }
                )
        table.append({"trigger": "fail", "source": [IDLE, *names], "dest": ERROR})
        table.append({"trigger": "reset", "source": [DONE, ERROR], "dest": IDLE})
        return table

    # -- guards (no I/O) ----------------------------------------------------

    def may_continue(self, *_: object) -> bool:
        """No stop has been requested.

        Returns:
            Whether the run may go on.
        """
        return not self._stopped()

    def more_cycles(self, *_: object) -> bool:
        """Cycles remain after the current one.

        Returns:
            Whether another cycle follows.
        """
        return self.cycle < self.cycles

    def last_cycle(self, *_: object) -> bool:
        """The current cycle is the last one.

        Returns:
            Whether it is the last.
        """
        return self.cycle >= self.cycles

    def retries_left(self, *_: object) -> bool:
        """The current step's retry rule allows another attempt in this cycle.

        Returns:
            Whether a retry is allowed.
        """
        step = self._steps.get(self.state)
        if step is None or step.retry is None:
            return False
        return self.retries_used.get(self.state, 0) < step.retry.attempts

    # -- callbacks -------------------------------------------------------------

    def _begin_cycle(self, *_: object) -> None:
        self.cycle += 1
        self.retries_used.clear()

    def _count_retry(self, *_: object) -> None:
        self.retries_used[self.state] = self.retries_used.get(self.state, 0) + 1

    # -- queries ---------------------------------------------------------------

    @property
    def finished(self) -> bool:
        """True in DONE or ERROR."""
        return self.state in (DONE, ERROR)

    def step(self) -> Step:
        """The step of the current state.

        Returns:
            The step.

        Raises:
            KeyError: In IDLE, DONE or ERROR.
        """
        return self._steps[self.state]

    def is_last_step(self) -> bool:
        """True while in the sequence's last step.

        Returns:
            Whether the current state is the last step.
        """
        return self.state == self.sequence.steps[-1].name


def mermaid(sequence: TaskSequence, *, cycles: int = 1) -> str:
    """The machine of ``sequence`` as a mermaid state diagram (no graphviz needed).

    ``python -m tmmaster.pickplace --diagram`` prints it.

    Args:
        sequence: The sequence.
        cycles: The cycles its machine runs (the diagram is the same for any number).

    Returns:
        The diagram's mermaid text (``stateDiagram-v2``).
    """
    from transitions.extensions import GraphMachine

    class _Model:
        pass

    model = _Model()
    probe = SequenceMachine(sequence, cycles=cycles)
    graph_machine = GraphMachine(
        model=model,
        states=list(probe.machine.states),
        transitions=probe._transitions(sequence.steps),
        initial=IDLE,
        auto_transitions=False,
        graph_engine="mermaid",
        show_conditions=True,
        title=f"{sequence.name} state machine",
    )
    _ = graph_machine
    # Guards are named for the diagram only: this model never runs.
    text: str = model.get_graph().draw(None)  # type: ignore[attr-defined]
    return text
