"""A gateway that answers reads from a cache one poll behind the robot.

Some Modbus gateways serve reads from a cache they refresh on their own, so an answer
can show the registers as they were one read earlier: before the master's own command
write landed, while the arm still moved, before the program acknowledged. The
FaultProxy plays such a gateway on every read (``stale_answer``: each read is answered
with what the previous identical read got; writes go through at once).

What must hold (docs/safety.md, the completion rule): a move is done only once the
robot acknowledged it, reported it finished and the TCP is at the target; a stale
"idle" or a stale "acknowledged" must never make a call return done while the arm still
moves or before it reached the target, and a relative move must never be resolved
against a pose the arm has left (it would run toward a target no call asked for). The
judge is the simulator: its motion log (tests/safety_invariant.py) and the TCP at the
moment each call returned.

A stand-alone gripper behind the same gateway: a move is done only with the fingers there.
The OnRobot 2FG7 reports its width, which a stale read cannot show at a new target. The
blog-2fg7 map has neither width nor sequence number: a stale "control = 0" reads as the
acknowledgement and a stale gOBJ as the move ended, so its moves return done before the
fingers moved (a strict xfail: a documented limit of that map, docs/safety.md).

Observed (2026-11-29): every call ends in ``RobotError`` ("the robot reported the move
finished but the TCP is at ..."): the pose read one poll behind is the previous target,
and the completion rule's pose check refuses it. The master is of no use behind such a
gateway, but never wrong on the safe side's account: each move ran once, to its own
target.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, at_rest, check
from sim_speeds import SUITE_TICK_HZ
from test_hunt2_gripper_stop import fingers
from tmmaster import (
    Blog2FG7Gripper,
    Gripper,
    GripperLink,
    OnRobot2FG7Gripper,
    PollPolicy,
    Pose,
    Robot,
    TimeoutPolicy,
    TMMasterError,
    gripper_profile,
)
from tmmaster.sim import RobotSetup, Simulator, Timing

Factory = Callable[..., Simulator]

#: How a call refused before anything was sent says why (a stale read of a move in
#: progress, or of a pose the arm has left): the channels' and the planner's refusals.
UNSENT = (
    "robot is still moving",
    "still waiting to be acknowledged",
    "still executing command",
    "is still pending",
    "nothing was sent",
)

TIMEOUTS = TimeoutPolicy(request_s=1.0, ack_timeout_s=3.0, motion_margin_s=1.0)


def options(profile: str) -> dict[str, Any]:
    return dict(
        profile=profile, gripper=None, polling=PollPolicy(interval_s=0.01), timeouts=TIMEOUTS
    )


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_reads_one_poll_behind_never_end_a_move_early_nor_resolve_a_stale_origin(
    tm_simulator_factory: Factory, profile: str
) -> None:
    sim = tm_simulator_factory(profile)
    issued: list[Issued] = []
    refused: list[int] = []  # the calls refused before anything was sent

    def call(target: Pose, move: Callable[[], object]) -> None:
        """Run ``move`` (to ``target``); a done call must find the arm there, finished."""
        command = Issued(target, time.monotonic())
        issued.append(command)
        try:
            move()
        except TMMasterError as exc:
            command.outcome = type(exc).__name__
            if any(why in str(exc) for why in UNSENT):
                refused.append(len(issued) - 1)
        else:
            command.outcome = "done"
            pose = sim.tcp_pose()
            assert pose.is_close(target), f"done at {pose}, short of {target}"
            ran = [m for m in sim.motion_log() if m.target is not None]
            assert ran[-1].done_wall_time is not None, f"done while the arm moves: {ran[-1]}"
        command.ended_at = time.monotonic()

    with FaultProxy(sim.port) as proxy, Robot("127.0.0.1", proxy.port, **options(profile)) as r:
        r.wait_until_ready(timeout_s=5)
        start = r.pose()
        for code in (1, 2, 3, 4):
            proxy.add(Rule("stale_answer", function_code=code, times=1_000_000))
        p1, p2 = start.offset(dz=-40), start.offset(dz=-40, dy=60)
        call(p1, lambda: r.move_to(p1, speed=80))
        call(p2, lambda: r.move_to(p2, speed=80))
        # Relative to where the arm is, or is going: p2, or p1 when a stale "moving" had
        # p2's call refused unsent (seen in 1 full run of 14 under load; always when the
        # simulator runs at 20x and 50 Hz, the plugin's own timing).
        p3 = [m.target for m in sim.motion_log() if m.target is not None][-1].offset(dz=-30)
        call(p3, lambda: r.move_by(dz=-30, speed=80))
        p4 = start
        call(p4, lambda: r.move_to(p4, speed=80))
        assert proxy.played("stale_answer")
    ticks = sim.ticks
    sim.wait_for(lambda: sim.ticks >= ticks + 20, timeout=5.0)
    sim.wait_for(at_rest(sim), timeout=5.0, interval=0.05)
    check(issued, sim.motion_log())
    # Each move ran once, to the target its call asked for (the relative one from where the
    # arm was); a call that ran none was refused before anything was sent.
    ran = [m.target for m in sim.motion_log() if m.target is not None][-4 + len(refused) :]
    asked = [c.target for i, c in enumerate(issued) if i not in refused]
    assert all(a.is_close(b) for a, b in zip(ran, asked, strict=True)), (ran, refused)


def fingers_still_within(sim: Simulator, low_mm: float, high_mm: float) -> None:
    """A gripper move reported done: the simulated fingers stand within the range."""
    moving, width = fingers(sim)
    assert not moving, f"done while the fingers move, at {width:.1f} mm"
    assert low_mm <= width <= high_mm, f"done with the fingers at {width:.1f} mm"


@pytest.mark.parametrize(
    "kind",
    [
        pytest.param(
            "blog-2fg7",
            marks=pytest.mark.xfail(
                strict=True,
                reason="documented limit (docs/safety.md): the blog-2fg7 map has no width"
                " and no sequence number, so a stale acknowledgement and a stale gOBJ read"
                " as the move done",
            ),
        ),
        "onrobot-2fg7",
    ],
)
def test_a_gripper_move_read_one_poll_behind_is_done_only_with_the_fingers_there(
    kind: str,
) -> None:
    # The gateway caches from the first move on: each read is answered with what the
    # gripper said at the previous identical read (before this move's write, at first).
    timing = Timing(tick_hz=SUITE_TICK_HZ)
    sim = Simulator("tmflow", robot=RobotSetup(gripper=kind), time_scale=0.5, timing=timing)
    sim.start()
    try:
        assert sim.gripper_port is not None
        with FaultProxy(sim.gripper_port) as proxy:
            for code in (1, 2, 3, 4):
                proxy.add(Rule("stale_answer", function_code=code, times=1_000_000))
            link = GripperLink("127.0.0.1", proxy.port, poll_interval_s=0.01)
            make = Blog2FG7Gripper if kind == "blog-2fg7" else OnRobot2FG7Gripper
            gripper: Gripper = make(gripper_profile(kind), link)
            gripper.connect()
            try:
                for _ in range(2):
                    gripper.close(timeout_s=5)
                    fingers_still_within(sim, 0.0, 1.5)  # the stroke ends at 1 mm
                    gripper.open(timeout_s=5)
                    fingers_still_within(sim, 38.5, 39.0)
            finally:
                gripper.disconnect()
            assert proxy.played("stale_answer")
    finally:
        sim.close()
