"""A pick & place run whose move's command write is lost on the wire never runs it twice.

The link drops exactly while the second move's command block is in flight (the
simulator's ``drop_connections`` fault, counted on writes to that block): either the
request is lost (never executed) or its answer is (executed, the reply lost). The run
must end with every move run at most once, in order, none after the run gave it up,
and report the cycle done only when every move ran (tmflow: the same sequence number
is sent again and taken once; article: a clear-on-accept command is never written
twice, docs/safety.md "Uncertain writes"). The judge is the simulator's motion log.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest

from safety_invariant import Issued, check
from sim_speeds import QUICK
from tmmaster import PollPolicy, Pose, Robot, TimeoutPolicy, TMMasterError
from tmmaster.pickplace import Runner, StepContext, TaskSequence
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]

TARGETS = (
    Pose(300, -200, 200, 180, 0, 90),
    Pose(300, -150, 180, 180, 0, 90),
    Pose(250, -150, 200, 180, 0, 90),
)
#: Where each profile's command block starts (one FC16 carries target and trigger).
COMMAND_BLOCK = {"tmflow": 9000, "article": 0x0200}


def three_moves(issued: list[Issued]) -> TaskSequence:
    """Three moves; each records what the master issued and how its call ended."""
    seq = TaskSequence("three-moves")

    def mover(target: Pose) -> Callable[[StepContext], None]:
        def move(ctx: StepContext) -> None:
            command = Issued(target, time.monotonic())
            issued.append(command)
            try:
                ctx.move(target, speed=30)
            except TMMasterError as exc:
                command.outcome = type(exc).__name__
                raise
            finally:
                command.ended_at = time.monotonic()
            command.outcome = "done"

        return move

    for index, target in enumerate(TARGETS):
        seq.add(f"MOVE_{index}", mover(target))
    return seq


@pytest.mark.parametrize("lose", ["request", "answer"])
@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_a_command_write_lost_mid_run_runs_at_most_once(
    tm_simulator_factory: SimFactory, profile: str, lose: str
) -> None:
    sim = tm_simulator_factory(profile, **QUICK)
    block = COMMAND_BLOCK[profile]
    issued: list[Issued] = []
    with Robot(
        sim.url,
        profile=profile,
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(in_flight_s=0.5),
    ) as robot:
        robot.wait_until_ready(5.0)
        robot.move_to(TARGETS[2], speed=50)  # a start the first move leaves
        before = len(sim.motion_log())
        sim.inject(f"drop_connections:on_write_to={block},after_requests=2,lose={lose}")
        result = Runner(robot).run(three_moves(issued), cycles=1)
        ended = robot.status()  # after the run: the arm at rest, nothing running
        reconnects = robot.stats.reconnects
    assert reconnects >= 1  # the fault fired on the second move's command block
    log = [m for m in sim.motion_log()[before:] if m.target is not None]
    check(issued, log)
    ran = [m.target for m in log]
    if result.ok:
        assert result.cycles_completed == 1
        assert ran == [c.target for c in issued]
        assert [c.outcome for c in issued] == ["done"] * 3
    else:  # only the article, the request lost: withdrawn, never written twice
        assert (profile, lose) == ("article", "request"), result.failure
        assert result.failure is not None
        assert result.failure.state == "MOVE_1"
        assert ran == [TARGETS[0]]
    assert not ended.moving
