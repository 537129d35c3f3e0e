"""Stop requests against the pick & place runner: nothing moves after one."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import pytest

from sim_speeds import QUICK
from tmmaster import ConfigError, PollPolicy, Pose, Robot, StopRequestedError
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


def test_a_robots_dwell_ends_at_once_on_a_stop_request_and_not_before_its_time(
    memory_simulator_factory: SimFactory,
) -> None:
    sim = memory_simulator_factory("article", **QUICK)
    with Robot(sim.url, profile="article", polling=PollPolicy(interval_s=0.02)) as robot:
        robot.dwell(0.05)  # its time, then on
        helper = threading.Thread(target=lambda: (time.sleep(0.05), robot.interrupt()))
        helper.start()
        started = time.monotonic()
        with pytest.raises(StopRequestedError):
            robot.dwell(30.0)
        helper.join()
        assert time.monotonic() - started < 10.0  # generous: ended by the request, not 30 s
        with pytest.raises(StopRequestedError):
            robot.dwell(0.0)  # the request stands until cleared
        robot.clear_stop_request()
        robot.dwell(0.0)
        with pytest.raises(ConfigError):
            robot.dwell(-1.0)
