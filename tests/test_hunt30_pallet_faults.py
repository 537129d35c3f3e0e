"""Palletizing under a fault at a state of a chosen slot's cycle, on both profiles.

Hunt 30, the multi-cycle side of ``test_hunt30_fault_matrix.py``: a 3-slot pallet, the
fault fired when the run enters ``state`` in cycle ``slot`` (the runner's ``on_state``
event): an e-stop or a robot error during that state's move (the simulator's fault,
counted from then), ``request_stop()`` from another thread once the robot started the
state's move (the simulator's motion log shows it), the state's command frame dropped or
held on the wire (a FaultProxy rule on its command block, released after the run).

Judged on the simulator: the moves ran once each in the order issued (the cycle's moves
repeat their targets, so the match is in order: ``ran_in_order``), nothing started after
the run returned; the earlier slots hold their parts and no other part was let go but at
its slot; the result says which cycle failed and how many completed.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, record_moves
from sim_speeds import QUICK
from tmmaster import PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster.pickplace import ARTICLE_PICK, Pallet, Runner, StateEvent, palletizing
from tmmaster.sim import Cell, MotionRecord, Simulator, TableObject

Factory = Callable[..., Simulator]
PICK = Pose.from_sequence(ARTICLE_PICK)
HOME = Pose(250, 0, 300, 180, 0, 90)
PALLET = Pallet(origin=Pose(220, 150, 100, 180, 0, 90), rows=1, cols=3, dx=40, dy=40)
BLOCKS = {"tmflow": (9000, 9014), "article": (0x0200, 0x0210)}
STATES = (
    "MOVE_TO_APPROACH",
    "MOVE_TO_PICK",
    "GRIPPER_CLOSE",
    "CHECK_GRASP",
    "MOVE_TO_LIFT",
    "MOVE_TO_SLOT_ABOVE",
    "MOVE_TO_SLOT",
    "GRIPPER_OPEN",
    "MOVE_TO_SLOT_CLEAR",
    "MOVE_TO_HOME",
)

#: (profile, slot, state, fault): each fault class once, at a different slot and state.
CASES = [
    ("tmflow", 1, "MOVE_TO_SLOT", "estop"),
    ("article", 2, "MOVE_TO_SLOT", "stop_moving"),
    ("tmflow", 2, "MOVE_TO_LIFT", "stop_moving"),
    ("tmflow", 2, "MOVE_TO_SLOT_ABOVE", "robot_error"),
    ("article", 3, "GRIPPER_OPEN", "estop"),
    ("tmflow", 3, "GRIPPER_OPEN", "link_hold"),
    ("article", 3, "MOVE_TO_SLOT_CLEAR", "link_drop"),
    ("tmflow", 3, "MOVE_TO_HOME", "estop"),
]


def ran_in_order(issued: Sequence[Issued], log: Sequence[MotionRecord]) -> None:
    """Each motion is the next issued move with its target, a move skipped was given up,
    every move that ended done ran exactly once, none started after it was given up."""
    motions = [m for m in log if m.target is not None]
    at = 0
    for motion in motions:
        assert motion.target is not None
        while at < len(issued) and issued[at].target.distance_to(motion.target) > 0.05:
            assert issued[at].gave_up, f"move {at} ended {issued[at].outcome} but never ran"
            at += 1
        assert at < len(issued), f"motion {motion.number} to {motion.target} matches no move"
        command = issued[at]
        if command.gave_up and command.ended_at is not None:
            assert motion.wall_time <= command.ended_at, f"move {at} ran after its give-up"
        at += 1
    for rest in issued[at:]:
        assert rest.outcome != "done", f"{rest} ended done but never ran"


@pytest.mark.parametrize(("profile", "slot", "state", "fault"), CASES)
def test_a_fault_in_a_slots_cycle_leaves_the_earlier_slots_filled_and_nothing_after(
    tm_simulator_factory: Factory, profile: str, slot: int, state: str, fault: str
) -> None:
    parts = [TableObject(name=f"p{i}", pose=PICK) for i in range(PALLET.size)]
    sim = tm_simulator_factory(profile, cell=Cell(scene=parts), **QUICK)
    proxy = FaultProxy(sim.port) if fault.startswith("link") else None
    release, fired, helpers = threading.Event(), threading.Event(), []
    issued: list[Issued] = []
    where = ("127.0.0.1", proxy.port) if proxy is not None else (sim.url,)
    seq = palletizing(pick=PICK, pallet=PALLET, home=HOME, grasp_retries=0)
    try:
        with Robot(
            *where,  # type: ignore[arg-type]
            profile=profile,
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(
                request_s=0.3, gripper_settle_s=0.05, in_flight_s=0.5, ack_timeout_s=0.5
            ),
        ) as robot:
            robot.wait_until_ready(5)
            record_moves(robot, issued)
            runner = Runner(robot, error_reaction="retreat")

            def stop_once_moving(moves: int) -> None:
                sim.wait_for(lambda: len(sim.motion_log()) > moves, timeout=5.0)
                runner.request_stop()

            def on_state(event: StateEvent) -> None:
                if event.state != state or event.cycle != slot or fired.is_set():
                    return
                fired.set()
                move_block, grip_block = BLOCKS[profile]
                if fault == "estop":
                    if state.startswith("GRIPPER"):
                        sim.press_estop()
                    else:
                        sim.inject("estop:at_move=1")
                elif fault == "robot_error":
                    sim.inject("robot_error:at_move=1,code=0x22")
                elif fault == "stop_moving":
                    helper = threading.Thread(
                        target=stop_once_moving, args=(len(sim.motion_log()),)
                    )
                    helpers.append(helper)
                    helper.start()
                else:
                    assert proxy is not None
                    block = grip_block if state.startswith("GRIPPER") else move_block
                    action = "hold" if fault == "link_hold" else "drop_request"
                    hold = release if action == "hold" else None
                    proxy.add(Rule(action, function_code=16, address=block, release=hold))

            runner.on_state = on_state
            result = runner.run(seq)
            ended = time.monotonic()
            for helper in helpers:
                helper.join(5)
        release.set()
        if proxy is not None and proxy.played("hold"):
            proxy.wait_held()
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 20, timeout=5.0)
    finally:
        if proxy is not None:
            proxy.close()
    assert fired.is_set()
    log = sim.motion_log()
    kinds = [m.kind for m in log]
    ran_in_order(issued, log)
    assert not [m for m in log if m.wall_time > ended], kinds
    if result.ok:  # a dropped frame on tmflow is sent again under its number
        assert fault.startswith("link"), result.failure
        assert profile == "tmflow", result.failure
        return
    failure = result.failure
    assert failure is not None
    names = list(STATES)
    if fault == "stop_moving":  # the move may have ended before the stop landed
        assert result.interrupted
        assert result.stop_delivered is True, result
        assert failure.state in names[names.index(state) : names.index(state) + 2], failure
    else:
        assert failure.state == state, failure
    assert failure.cycle == slot, failure
    assert result.cycles_completed == slot - 1
    # Each earlier slot holds its part; nothing was let go anywhere but at a slot.
    opens = kinds.count("gripper_open")
    released_here = failure.state in ("MOVE_TO_SLOT_CLEAR", "MOVE_TO_HOME")
    assert opens == (slot if released_here else slot - 1), kinds
    for index in range(slot - 1 + (1 if released_here else 0)):
        spot = PALLET.slot(index)
        assert any(o.pose.is_close(spot, mm=1.0) for o in sim.objects()), (index, sim.objects())
    if fault in ("estop", "robot_error", "stop_moving") and result.reaction is not None:
        assert not result.reaction.performed, result.reaction
