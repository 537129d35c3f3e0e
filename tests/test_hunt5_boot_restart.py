"""The program's start (``boot_id``, 9107) against frames written before it.

A command carries the ``boot_id`` its master read (``command_boot``, 9031); the robot
program consumes one of another start, unrun. These tests hold a command frame in the
network across a start of the project (the operator's Stop then Play, registers kept; a
controller restart, registers at 0; two restarts in a row; a power cycle that starts
random() from its seed again) and let it land after, a move's or a gripper close's: the
judge is the simulator's motion log, never what the master believes. A block written
by hand with ``command_boot`` 0 is taken as before; one of an earlier start is not.
"""

from __future__ import annotations

import random
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest
from pymodbus.client import ModbusTcpClient

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, attempt, check
from test_controller_restart import restart_controller
from test_controller_restart import robot_through as restart_master
from test_sim_controller import words
from tmmaster import Fleet, PollPolicy, Pose, RetryPolicy, Robot, TimeoutPolicy, TMMasterError
from tmmaster.sim import Simulator, Timing

STALE = Pose(300, -200, 180, 180, 0, 90)
NEXT = Pose(250, 0, 160, 180, 0, 90)
HAND = Pose(280, -100, 170, 180, 0, 90)
FAR = Pose(300, 200, 150, 180, 0, 90)


@pytest.fixture
def sim() -> Iterator[Simulator]:
    with Simulator(profile="tmflow", time_scale=20.0, timing=Timing(tick_hz=50.0)) as simulator:
        yield simulator


def robot_through(proxy: FaultProxy, link: Fleet | None = None) -> Robot:
    """A master whose command write, held, is resent for about 3 s before it gives up."""
    return restart_master(
        proxy, link, RetryPolicy(attempts=12, total_time_s=3.0, initial_backoff_s=0.02)
    )


def stop_then_play(sim: Simulator) -> None:
    """The operator's Stop, then Play, on the pendant: the registers keep their values."""
    sim.call(lambda: sim._controller.bank.set("stop_project", True))
    sim.wait_for(lambda: not sim.field("project_running"), timeout=2.0)
    sim.press_play()
    sim.wait_for(lambda: bool(sim.field("project_running")), timeout=2.0)


def program_beats(sim: Simulator) -> None:
    """Until the program's loop beats: its start-up is done."""
    beat = sim.field("heartbeat")
    sim.wait_for(lambda: sim.field("heartbeat") != beat, timeout=2.0)


def settle(sim: Simulator) -> None:
    """Four simulated seconds: room for a landed frame to start a move."""
    start = sim.ticks
    sim.wait_for(lambda: sim.ticks >= start + 10, timeout=5.0)


def held_across(
    sim: Simulator, link: Fleet | None, between: Callable[[Simulator], None], *, beat: bool
) -> tuple[list[Issued], list[int]]:
    """A move to STALE whose every write to 9000 is held; ``between`` runs (starts of
    the project) while the master still resends it. The copies land once the program
    beats again, and (``beat``) once the master beats too, while the master still waits
    for its write's answer; then the master's next command, NEXT, must run. Returns the
    commands issued and the boot_ids seen (before, after)."""
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy, robot_through(proxy, link) as robot:
        robot.wait_until_ready()
        boots = [int(sim.field("boot_id"))]
        landed = threading.Event()
        rule = proxy.add(Rule("hold", function_code=16, address=9000, release=landed, times=50))
        thread = threading.Thread(target=attempt, args=(robot, STALE, issued))
        thread.start()
        sim.wait_for(lambda: proxy.played("hold"), timeout=2.0)
        between(sim)
        boots.append(int(sim.field("boot_id")))
        program_beats(sim)
        if beat:
            sim.wait_for(lambda: sim.field("master_session") != 0, timeout=2.0)
        rule.times = 0  # the next command goes through
        landed.set()
        proxy.wait_held()
        thread.join(5.0)
        assert not thread.is_alive()
        settle(sim)
        check(issued, sim.motion_log())
        assert [r.target for r in sim.motion_log()] == []  # the held frame never ran
        assert sim.field("project_running")  # the master pressed no Stop on the new run
        sim.wait_for(lambda: sim.field("master_session") != 0, timeout=2.0)
        assert attempt(robot, NEXT, issued) == "done"
        assert [r.target for r in sim.motion_log()] == [NEXT]
    check(issued, sim.motion_log())
    return issued, boots


def test_a_frame_held_across_stop_and_play_never_runs(
    sim: Simulator, driver_or_fleet: Fleet | None
) -> None:
    """Stop then Play (registers kept) while the master's write is held: the number is
    still free after Play, the master still beats with the command's session; only the
    frame's boot_id (of the start before) keeps it from running. The master's call ends
    in an error, and its next command runs."""
    issued, boots = held_across(sim, driver_or_fleet, stop_then_play, beat=True)
    assert boots[1] not in (0, boots[0])  # shifted past the one found
    assert issued[0].gave_up, issued[0].outcome


def test_a_write_held_between_prepare_and_landing_across_a_restart_never_runs(
    sim: Simulator, driver_or_fleet: Fleet | None
) -> None:
    """The master read boot_id and wrote its first command (number 1); the write is held
    and the controller restarts (registers at 0: number 1 free again). The copies land
    while the master still waits for the write's answer (it beats again only after):
    nothing runs, the master's call fails, its next command runs."""
    issued, boots = held_across(sim, driver_or_fleet, restart_controller, beat=False)
    assert boots[1] not in (0, boots[0])
    assert issued[0].gave_up, issued[0].outcome


def test_a_frame_held_across_two_restarts_never_runs(sim: Simulator) -> None:
    """Two controller restarts in a row (registers at 0 before each start, so no start
    can shift past the earlier one's boot_id) with the frame held from before the first.
    The simulator's random() is one generator per controller, seeded alike in every
    simulator, and its time of day reads 0: each start draws the next number, so the
    third start's boot_id is not the first's and the frame is consumed unrun."""

    def twice(sim: Simulator) -> None:
        restart_controller(sim)
        middle.append(int(sim.field("boot_id")))
        restart_controller(sim)

    middle: list[int] = []
    issued, boots = held_across(sim, None, twice, beat=False)
    assert len({boots[0], middle[0], boots[1]}) == 3, (boots, middle)
    assert issued[0].gave_up, issued[0].outcome


def hand_block(sim: Simulator, target: Pose, seq: int, boot: int) -> list[int]:
    """The 32 words of a ptp to ``target``, number ``seq``, session 0, ``command_boot``."""
    values: dict[str, Any] = dict(
        zip(
            ("target_x", "target_y", "target_z", "target_rx", "target_ry", "target_rz"),
            target.as_list(),
            strict=True,
        )
    )
    values |= {"speed": 20, "accel_time": 0, "command": 1, "seq": seq}
    values |= {f"via_{n}": 0.0 for n in ("x", "y", "z", "rx", "ry", "rz")}
    values |= {"speed_mm_s": 0, "ext_seq": 0, "command_session": 0, "command_boot": boot}
    block = words(sim.profile, values)
    assert len(block) == 32
    return block


@pytest.mark.parametrize("boot", ["zero", "another start's"])
def test_a_hand_written_block_with_command_boot_0_runs_after_a_restart(
    sim: Simulator, boot: str
) -> None:
    """A hand-made master (raw FC16 of the 32-word block, no session, no beat) after the
    operator's Stop and Play: ``command_boot`` 0 is taken as before and the arm moves;
    the boot_id of the start before Play is consumed as cancelled, and nothing moves."""
    sim.wait_for(lambda: bool(sim.field("project_running")), timeout=2.0)
    before = int(sim.field("boot_id"))
    stop_then_play(sim)
    program_beats(sim)
    seq = int(sim.field("ack_seq")) % 32767 + 1
    with ModbusTcpClient("127.0.0.1", port=sim.port, timeout=2) as client:
        stamp = 0 if boot == "zero" else before
        reply = client.write_registers(9000, hand_block(sim, HAND, seq, stamp), device_id=1)
        assert not reply.isError(), reply
    sim.wait_for(lambda: sim.field("ack_seq") == seq, timeout=2.0)
    if boot == "zero":
        sim.wait_for(lambda: sim.field("done_seq") == seq, timeout=3.0)
        assert [r.target for r in sim.motion_log()] == [HAND]
    else:
        settle(sim)
        assert sim.field("result_code") == 5  # cancelled
        assert [r.target for r in sim.motion_log()] == []


def test_a_give_up_across_a_restart_presses_no_stop_on_the_new_run(
    sim: Simulator, driver_or_fleet: Fleet | None
) -> None:
    """The master's write is held, the controller restarts, the master gives the command
    up (no answer to the write): the new run must go on, and the next command run."""
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy, robot_through(proxy, driver_or_fleet) as robot:
        robot.wait_until_ready()
        never = threading.Event()  # the copies stay in the network
        rule = proxy.add(Rule("hold", function_code=16, address=9000, release=never, times=50))
        thread = threading.Thread(target=attempt, args=(robot, STALE, issued))
        thread.start()
        sim.wait_for(lambda: proxy.played("hold"), timeout=2.0)
        restart_controller(sim)
        thread.join(5.0)
        assert not thread.is_alive()
        assert issued[0].outcome == "CommandStateUnknownError"
        rule.times = 0
        settle(sim)
        check(issued, sim.motion_log())
        assert [r.target for r in sim.motion_log()] == []
        assert sim.field("project_running")
        sim.wait_for(lambda: sim.field("master_session") != 0, timeout=2.0)
        assert attempt(robot, NEXT, issued) == "done"
    check(issued, sim.motion_log())


def test_a_gripper_close_held_across_stop_and_play_never_runs(sim: Simulator) -> None:
    """A tmflow gripper command goes through the same block, from 9014. Its write is held
    across Stop then Play (registers kept, the master beating): the copies land after,
    and the gripper never closes; the master's close fails, its next close runs."""
    with FaultProxy(sim.port) as proxy:
        robot = Robot(
            "127.0.0.1",
            proxy.port,
            profile="tmflow",
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(request_s=0.3, ack_timeout_s=0.5, motion_margin_s=1.0),
            retry=RetryPolicy(attempts=12, total_time_s=3.0, initial_backoff_s=0.02),
        )
        with robot:
            robot.wait_until_ready()
            before = int(sim.field("boot_id"))
            landed = threading.Event()
            rule = proxy.add(Rule("hold", function_code=16, address=9014, release=landed, times=50))
            outcome: list[object] = []

            def close() -> None:
                try:
                    outcome.append(robot.gripper.close(timeout_s=3.0))
                except TMMasterError as exc:
                    outcome.append(exc)

            thread = threading.Thread(target=close)
            thread.start()
            sim.wait_for(lambda: proxy.played("hold"), timeout=2.0)
            stop_then_play(sim)
            assert int(sim.field("boot_id")) not in (0, before)
            program_beats(sim)
            rule.times = 0
            landed.set()
            proxy.wait_held()
            thread.join(5.0)
            assert not thread.is_alive()
            settle(sim)
            kinds = [m.kind for m in sim.motion_log()]
            assert "gripper_close" not in kinds, kinds  # the held close never ran
            assert len(outcome) == 1
            assert isinstance(outcome[0], TMMasterError), outcome
            assert sim.field("project_running")
            robot.gripper.close(timeout_s=3.0)  # the next command: a close of its own
    assert [m.kind for m in sim.motion_log()] == ["gripper_close"]


def power_cycle(sim: Simulator, clock: tuple[int, int, int]) -> None:
    """A power cycle as commit 81d0c05 supposes one may be: the controller's random()
    starts from the same seed again, its time of day (7304-7306, hour, minute, second)
    reads ``clock``; the project stops, its registers read 0, and it starts again. The
    simulator keeps no clock of its own: its time of day reads 0 (the first start's)."""

    def reseed() -> None:
        controller: Any = sim._controller  # the tmflow project's: its random() lives there
        controller.random = random.Random(0)
        for name, value in zip(("time_hour", "time_minute", "time_second"), clock, strict=True):
            sim._controller.bank.set(name, value)

    sim.call(reseed)
    restart_controller(sim)


def first_copy_across_a_power_cycle(sim: Simulator, clock: tuple[int, int, int]) -> list[int]:
    """The first copy of a move to FAR is held; its resend runs (``start_move``: no wait
    polls it, so the master beats on with that command's session). A power cycle cuts
    the move, the master beats again, and the held copy lands. Returns the boot_ids."""
    issued: list[Issued] = []
    with FaultProxy(sim.port) as proxy, robot_through(proxy) as robot:
        robot.wait_until_ready()
        boots = [int(sim.field("boot_id"))]
        landed = threading.Event()
        proxy.add(Rule("hold", function_code=16, address=9000, release=landed, times=1))
        command = Issued(FAR, time.monotonic())
        issued.append(command)
        motion = robot.start_move(FAR, speed=20)  # its resend, taken
        sim.wait_for(lambda: sim.field("ack_seq") == 1, timeout=2.0)
        power_cycle(sim, clock)
        boots.append(int(sim.field("boot_id")))
        sim.wait_for(lambda: sim.field("master_session") != 0, timeout=2.0)
        landed.set()
        proxy.wait_held()
        settle(sim)
        assert [r.target for r in sim.motion_log()] == [FAR]  # the resend's, cut short
        with pytest.raises(TMMasterError) as failed:
            motion.wait()
        command.outcome, command.ended_at = type(failed.value).__name__, time.monotonic()
    check(issued, sim.motion_log())
    return boots


def test_a_copy_held_across_a_power_cycle_that_reseeds_random_never_runs(
    sim: Simulator,
) -> None:
    """random() drawn from the same seed after the power cycle draws the first start's
    number again; the time of day (five minutes on) keeps the two boot_ids apart, so the
    held first copy is consumed unrun and FAR runs once."""
    boots = first_copy_across_a_power_cycle(sim, (0, 5, 0))
    assert boots[1] not in (0, boots[0]), boots
