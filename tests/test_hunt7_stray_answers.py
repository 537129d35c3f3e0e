"""Answers a buggy gateway garbles: relayed twice, under a foreign transaction id or unit id.

The link takes an answer only under its request's transaction id and from the robot's
unit id (tests/test_sync_link.py, against a scripted slave). Here the same faults are
played by a FaultProxy between a real ``Robot`` and the simulator, on the command
block's FC16 (the frame always reaches the robot and is executed) and on every read:

- an answer relayed twice: the second copy carries a transaction id already answered,
  and must never be taken for the next request's (every move runs once, done at its
  target);
- the command write's answer under a transaction id never sent (``NotModbusError``):
  the master cannot know the write was taken, so the call must not report done, and
  the move the robot took must be stopped before the error reaches the caller;
- the command write's answer from another unit id: skipped, so the write times out;
  the master reads the registers back, finds its write and follows it: it runs once;
- the command write's answer held past the request timeout and relayed late on the same
  connection, once the master sent its next request: never taken for that one's.

The judge is the simulator's motion log (tests/safety_invariant.py) and its arm at rest.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, at_rest, attempt, check
from tmmaster import PollPolicy, Robot, TimeoutPolicy
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

#: The command block's first register (its FC16's address), per profile.
COMMAND_BLOCK = {"article": 0x0200, "tmflow": 9000}
TIMEOUTS = TimeoutPolicy(request_s=0.3, ack_timeout_s=3.0, motion_margin_s=1.0, in_flight_s=3.0)


def options(profile: str) -> dict[str, Any]:
    return dict(
        profile=profile, gripper=None, polling=PollPolicy(interval_s=0.01), timeouts=TIMEOUTS
    )


@pytest.fixture(params=["article", "tmflow"])
def profile(request: pytest.FixtureRequest) -> str:
    return str(request.param)


def judge(sim: Simulator, issued: list[Issued]) -> None:
    """20 ticks for a frame just landed to be taken; then at rest, and the invariant."""
    ticks = sim.ticks
    sim.wait_for(lambda: sim.ticks >= ticks + 20, timeout=5.0)
    sim.wait_for(at_rest(sim), timeout=5.0, interval=0.05)
    check(issued, sim.motion_log())


def test_answers_relayed_twice_are_never_taken_for_the_next_request(
    tm_simulator_factory: Factory, profile: str
) -> None:
    sim = tm_simulator_factory(profile)
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy, Robot("127.0.0.1", proxy.port, **options(profile)) as r:
        for code in (16, 3, 4, 1, 2):
            proxy.add(Rule("duplicate_answer", function_code=code, times=10_000))
        r.wait_until_ready(timeout_s=5)
        start = r.pose()
        targets = [start.offset(dz=-40), start.offset(dz=-40, dy=40), start.offset(dy=40)]
        for target in targets:
            assert attempt(r, target, issued) == "done"
            assert sim.tcp_pose().is_close(target), (target, sim.tcp_pose())
        assert proxy.played("duplicate_answer")
    judge(sim, issued)
    assert len(sim.motion_log()) == len(targets)


def test_a_command_answer_under_a_foreign_transaction_id_leaves_no_move_behind(
    tm_simulator_factory: Factory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, time_scale=1.0)  # the move still runs when given up
    issued: list[Issued] = []
    block = COMMAND_BLOCK[profile]
    with FaultProxy(sim.port) as proxy, Robot("127.0.0.1", proxy.port, **options(profile)) as r:
        r.wait_until_ready(timeout_s=5)
        far = r.pose().offset(dz=-120)
        proxy.add(Rule("foreign_tid", function_code=16, address=block))
        outcome = attempt(r, far, issued, speed=20)
        judge(sim, issued)
        assert outcome != "done" or sim.tcp_pose().is_close(far), outcome
        if outcome != "done":
            assert not sim.tcp_pose().is_close(far, mm=1.0), "the arm ran on to the target"
        assert len(sim.motion_log()) <= 1, sim.motion_log()
        sent = [s for s in proxy.seen if s.function_code == 16 and s.address == block]
        assert len(sent) == 1, "the command write was sent again"


def test_a_command_answer_from_another_unit_id_is_followed_once(
    tm_simulator_factory: Factory, profile: str
) -> None:
    sim = tm_simulator_factory(profile)
    issued: list[Issued] = []
    block = COMMAND_BLOCK[profile]
    with FaultProxy(sim.port) as proxy, Robot("127.0.0.1", proxy.port, **options(profile)) as r:
        r.wait_until_ready(timeout_s=5)
        target = r.pose().offset(dz=-40)
        proxy.add(Rule("foreign_unit", function_code=16, address=block))
        assert attempt(r, target, issued) == "done"  # its write found in the registers
        assert proxy.played("foreign_unit")
        judge(sim, issued)
        assert len(sim.motion_log()) == 1, sim.motion_log()
        assert sim.tcp_pose().is_close(target)
        sent = [s for s in proxy.seen if s.function_code == 16 and s.address == block]
        assert len(sent) == 1, "the command write was sent again"


def test_a_late_answer_to_the_command_write_is_never_taken_for_a_later_request(
    tm_simulator_factory: Factory, profile: str
) -> None:
    """The command write is executed at once, its answer held past the request timeout and
    relayed on the same connection once the master sent its next request (its read-back
    of the registers). The master must not take it for that request's answer; it finds
    its write in the registers and follows it: the move runs once."""
    sim = tm_simulator_factory(profile)
    issued: list[Issued] = []
    release = threading.Event()
    block = COMMAND_BLOCK[profile]
    with FaultProxy(sim.port) as proxy, Robot("127.0.0.1", proxy.port, **options(profile)) as r:
        r.wait_until_ready(timeout_s=5)
        target = r.pose().offset(dz=-40)
        proxy.add(Rule("delay_answer", function_code=16, address=block, release=release))

        def release_at_the_next_request() -> None:
            sim.wait_for(lambda: proxy.played("delay_answer"), timeout=5.0)
            count = len(proxy.seen)
            sim.wait_for(lambda: len(proxy.seen) > count, timeout=5.0)
            release.set()

        threading.Thread(target=release_at_the_next_request, daemon=True).start()
        try:
            assert attempt(r, target, issued) == "done"
        finally:
            release.set()
        judge(sim, issued)
        assert len(sim.motion_log()) == 1, sim.motion_log()
        assert sim.tcp_pose().is_close(target)
        sent = [s for s in proxy.seen if s.function_code == 16 and s.address == block]
        assert len(sent) == 1, "the command write was sent again"
