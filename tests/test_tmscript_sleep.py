"""``Sleep(ms)`` waits on the host's clock, whatever its argument's form.

A constant, a variable, an expression and a customized function's result wait the
same and return the same (TMscript 2.24 §5.5, p. 159: false at once for a negative
time).
"""

from __future__ import annotations

import pytest

from tmmaster.tmscript import ExecState, Execution, NullHost, parse


class _Clock:
    """A host clock the test advances."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


@pytest.mark.parametrize("ms", ["-5", "0", "1", "250", "1.9", "-0.5"])
def test_each_form_of_sleep_waits_and_returns_the_same(ms: str) -> None:
    typ = "double" if "." in ms else "int"
    waits: dict[str, list[str]] = {}
    for form in (ms, "v", "v + 0", "Get()"):
        clock = _Clock()
        shown: list[str] = []
        program = parse(
            f"define\n{{\n {typ} v = {ms}\n}}\n"
            f"main\n{{\n Display(Sleep({form}))\n Display(Sleep({form}))\n}}\n"
            f"{typ} Get()\n{{\n return v\n}}\n"
        )
        execution = Execution(program, NullHost(on_display=shown.append, clock=clock))
        trace: list[str] = []
        for _ in range(8):  # 0.1 s a step
            state = execution.step()
            trace.append(f"{clock.now:.1f}:{state}:{','.join(shown)}")
            if state == ExecState.ENDED:
                break
            clock.now += 0.1
        assert execution.error is None, execution.error
        waits[form] = trace
    assert waits[ms] == waits["v"] == waits["v + 0"] == waits["Get()"], waits


def test_a_sleep_stopped_while_it_waits_runs_closestop() -> None:
    clock = _Clock()
    shown: list[str] = []
    program = parse(
        'main\n{\n Sleep(1000)\n Display("woke")\n}\nclosestop\n{\n Display("stopped")\n}\n'
    )
    execution = Execution(program, NullHost(on_display=shown.append, clock=clock))
    assert execution.step().state == ExecState.BLOCKED
    clock.now = 0.5
    assert execution.step().state == ExecState.BLOCKED
    assert execution.stop() == ExecState.ENDED
    assert shown == ["stopped"]
