"""Stop requests against the pick & place runner: nothing moves after one."""

from __future__ import annotations

import threading
from collections.abc import Callable

from sim_speeds import QUICK
from tmmaster import PollPolicy, Pose, Robot
from tmmaster.pickplace import ARTICLE_PICK, Runner, StepContext, TaskSequence
from tmmaster.sim import Simulator

PICK = Pose.from_sequence(ARTICLE_PICK)
TARGET_BLOCK = 0x0200

SimFactory = Callable[..., Simulator]


def test_a_stop_requested_on_the_robot_ends_a_dwell_and_nothing_moves_after(
    memory_simulator_factory: SimFactory,
) -> None:
    sim = memory_simulator_factory("article", **QUICK)
    dwelling = threading.Event()
    seq = TaskSequence("dwell-then-move")

    @seq.step("DWELL")
    def dwell(ctx: StepContext) -> None:
        dwelling.set()
        ctx.wait(3.0)

    seq.add("MOVE", lambda ctx: ctx.move(PICK.offset(dz=100), speed=30))
    with Robot(sim.url, profile="article", polling=PollPolicy(interval_s=0.02)) as robot:

        def interrupt_while_dwelling() -> None:
            dwelling.wait(5)
            robot.interrupt()  # Ctrl-C handler or another thread: not the runner's own stop

        helper = threading.Thread(target=interrupt_while_dwelling)
        helper.start()
        result = Runner(robot).run(seq)
        helper.join()
    assert result.interrupted
    assert result.failure is not None
    # The dwell itself ended on the request (it did not sit out its 3 s first).
    assert result.failure.state == "DWELL"
    assert "dwell" in result.failure.message
    assert not [r for r in sim.request_log if r.is_write and r.address == TARGET_BLOCK]
