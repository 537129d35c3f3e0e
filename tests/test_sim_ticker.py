"""The simulator's control tick: a failure stops it, and closing still frees everything;
ticks left unobserved run, each with its own due time, before a request reads them."""

from __future__ import annotations

import time
from typing import Any

import pytest

from test_sim_server import MOVE_WORDS, client, hr, write
from tmmaster import ConfigError, Pose, Robot
from tmmaster.sim import Simulator, Timing


def _fail(dt: float) -> None:
    raise ZeroDivisionError("a bug in a tick")


@pytest.mark.parametrize("listen", [True, False])
def test_a_failing_tick_is_reported_and_the_simulator_still_closes_cleanly(listen: bool) -> None:
    sim = Simulator("article", listen=listen)
    sim._controller.tick = _fail  # type: ignore[method-assign]  # a hidden bug in the tick
    with pytest.raises(RuntimeError, match="control tick failed") as caught:
        sim.start()
    assert isinstance(caught.value.__cause__, ZeroDivisionError)
    assert sim.ticks == 0
    # start() closed it: its listener, loop and thread are gone (the suite's no_leaks
    # fixture fails the test for a socket or thread left behind).
    assert not sim.running


def test_a_request_sees_every_tick_due_however_long_nothing_observed_the_robot(
    tm_simulator_factory: Any,
) -> None:
    # Due ticks may wait a whole second while nothing observes the robot: a request
    # still finds the move the write started, and the motion log dates it by its tick.
    sim = tm_simulator_factory("article", time_scale=1.0, timing=Timing(tick_hz=50, batch_s=1.0))
    with client(sim.port) as c:
        written = time.monotonic()
        write(c, 0x200, MOVE_WORDS)
        time.sleep(0.3)  # no request: the ticks since the write wait for the next one
        assert hr(c, 0x0001) == 1  # moving: those ticks ran before the read was answered
    (record,) = sim.motion_log()
    # The tick after the write was due within a period (20 ms) of it, not at the read.
    assert written <= record.wall_time < written + 0.25


def test_ticks_nothing_observes_still_run_within_their_batch(tm_simulator_factory: Any) -> None:
    sim = tm_simulator_factory("article", timing=Timing(tick_hz=50, batch_s=0.2))
    start = sim.ticks
    # sim.ticks is read without a call (no catch-up): only the batches move it.
    sim.wait_for(lambda: sim.ticks >= start + 20, timeout=5.0)


@pytest.mark.parametrize("batch_s", [-0.1, 1.5, float("nan")])
def test_a_batch_outside_zero_to_one_second_is_refused(batch_s: float) -> None:
    with pytest.raises(ConfigError, match="batch_s"):
        Timing(batch_s=batch_s)


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_batched_and_one_by_one_ticks_run_the_same_moves(
    tm_simulator_factory: Any, profile: str
) -> None:
    # The same master's moves against both ways of ticking: the same motions, each done
    # at its target (what a master sees does not depend on when unobserved ticks ran).
    targets = [Pose(300, -200, 150, 180, 0, 90), Pose(300, -150, 250, 180, 0, 90)]
    logs = []
    for batch_s in (0.0, 1.0):
        sim = tm_simulator_factory(
            profile, time_scale=40.0, timing=Timing(tick_hz=100, batch_s=batch_s)
        )
        with Robot(sim.host, sim.port, profile=profile, gripper=None) as robot:
            for target in targets * 2:
                robot.move_to(target, speed=100)
                assert sim.tcp_pose().is_close(target)
        logs.append(
            [(m.kind, m.target, m.seq, m.done_wall_time is not None) for m in sim.motion_log()]
        )
    assert logs[0] == logs[1]
    assert len(logs[0]) == 4
