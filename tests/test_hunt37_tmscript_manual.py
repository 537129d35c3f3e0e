"""Hunt 37: what the simulator's TMscript ran where TMflow 2.24 refuses it.

Each test cites *Programming Language TMscript* 2.24 (document 1.00), [TS], or the
*TMflow SW 2.24 Software Manual* (document 1.00), [TMF].
"""

from __future__ import annotations

import pytest

from tmmaster.tmscript import Execution, MotionCall, NullHost, parse


class _MotionHost(NullHost):
    """Takes every motion and records it; its clock moves 10 ms at each reading."""

    def __init__(self) -> None:
        super().__init__(on_display=self.shown_append, clock=self._clock)
        self.shown: list[str] = []
        self.motions: list[MotionCall] = []
        self.now = 0.0

    def shown_append(self, text: str) -> None:
        self.shown.append(text)

    def _clock(self) -> float:
        self.now += 0.01
        return self.now

    def motion(self, call: MotionCall) -> bool:
        self.motions.append(call)
        return True


@pytest.mark.parametrize("section", ["closestop", "errorstop"])
@pytest.mark.parametrize(
    "motion",
    [
        'PTP("JPP", {0, 0, 90, 0, 90, 0}, 10, 200, 0, false)',
        'Line("CPP", {400, 0, 300, 180, 0, 90}, 10, 200, 0, false)',
        'ChangeTCP("RobotEndFlange")',
        'ChangeBase("RobotBase")',
        "StopAndClearBuffer()",
    ],
)
def test_a_motion_function_called_through_a_function_in_a_stop_section_fails(
    section: str, motion: str
) -> None:
    """[TS] §3.3 closestop, p. 30 and §3.4 errorstop, p. 31: "This function does not go
    with motion commands"; [TMF] appendix J, 0x00048B53 "The function syntax could not
    called in closestop or errorstop". An error there "will not run the errorstop
    function but end the project running directly" (p. 30).

    The simulator refused the call written in the section itself but ran it from a
    function the section calls: the arm moved after the project had stopped.
    """
    ending = "Exit(1)" if section == "closestop" else "Exit(false, -1)"
    script = (
        f"main\n{{\n    {ending}\n}}\n"
        f'{section}\n{{\n    Retreat()\n    Display("after")\n}}\n'
        f'void Retreat()\n{{\n    bool ok = {motion}\n    Display("moved")\n}}\n'
    )
    host = _MotionHost()
    execution = Execution(parse(script), host)
    execution.run_to_end(timeout_s=5)
    assert host.motions == []
    assert host.shown == []
    assert execution.error is not None
    assert "closestop or errorstop" in execution.error.reason


def test_main_still_moves_through_a_function() -> None:
    host = _MotionHost()
    script = (
        "main\n{\n    Move()\n}\n"
        'void Move()\n{\n    bool ok = PTP("JPP", {0, 0, 90, 0, 90, 0}, 10, 200, 0, false)\n}\n'
    )
    execution = Execution(parse(script), host)
    execution.run_to_end(timeout_s=5)
    assert execution.error is None
    assert len(host.motions) == 1
