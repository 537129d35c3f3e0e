"""The invariant checker must catch every kind of violation (a checker that cannot fail
proves nothing), and accept a clean log."""

from __future__ import annotations

import pytest

from safety_invariant import Issued, check
from tmmaster import Pose
from tmmaster.sim import MotionRecord

A = Pose(300, -200, 200, 180, 0, 90)
B = Pose(300, -200, 150, 180, 0, 90)
C = Pose(250, -150, 150, 180, 0, 90)


def ran(number: int, target: Pose, wall: float) -> MotionRecord:
    return MotionRecord(number, "ptp", 0, target, 30.0, wall, wall)


def test_a_clean_log_passes() -> None:
    issued = [
        Issued(A, 0, 1, "done"),
        Issued(B, 1, 2, "done"),
        Issued(C, 2, 2.5, "RobotFaultError"),
    ]
    check(issued, [ran(1, A, 0.1), ran(2, B, 1.1)])  # C refused before it ran: fine


@pytest.mark.parametrize(
    ("issued", "log", "needle"),
    [
        ([Issued(A, 0, 1, "done")], [ran(1, A, 0.1), ran(2, A, 0.5)], "ran 2 times"),
        ([Issued(A, 0, 1, "done")], [ran(1, A, 0.1), ran(2, B, 0.5)], "matches no command"),
        (
            [Issued(A, 0, 1, "done"), Issued(B, 1, 2, "done")],
            [ran(1, B, 1.1), ran(2, A, 1.5)],
            "out of the order",
        ),
        ([Issued(A, 0, 1, "AcknowledgeTimeoutError")], [ran(1, A, 3.0)], "after the master gave"),
        ([Issued(A, 0, 1, "done")], [], "never ran"),
    ],
)
def test_every_kind_of_violation_is_caught(
    issued: list[Issued], log: list[MotionRecord], needle: str
) -> None:
    with pytest.raises(AssertionError, match=needle):
        check(issued, log)
