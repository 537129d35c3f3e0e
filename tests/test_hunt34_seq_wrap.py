"""The tmflow command number at its edges: the wrap (32767 -> 1), restarts, stale pairs.

Hunt 34. The robot program takes a command only when ``seq == ack_seq % seq_max + 1``
and the master numbers its next command ``ack_seq % seq_max + 1`` as it reads it: the
master keeps no number of its own between commands. These tests put failures of hunt 32
(a cancel, the project stopped, a controller restart that zeroes the registers; an
e-stop and a timeout passed too, left out for time) exactly on the wrap, a new master's
first command on it, a dead master's pending command on it, lost answers and held
copies on it, and masters taking turns across it; the judge is the simulator's motion
log (``safety_invariant.check``), never what the master believes.

Found (each fails without its fix):

- a profile whose ``seq`` maximum is 1 was accepted, and its robot program reran the
  command it had just finished for ever: once done, ``ack_seq % 1 + 1`` is the number the
  block still carries (measured: 117 runs of one move in a second; the master's next
  command was refused, "command 1 is still waiting to be acknowledged"). A maximum of 0
  failed on a division by zero at the first command. Both are refused when the profile
  loads now.
- ``seq`` and ``ack_seq`` written back to 0 by hand, ``done_seq`` left at 1 (command 1,
  the first after the wrap, done): the master's next command, numbered 1 again, read
  done_seq 1 as its own done the moment it was taken (a move then failed its at-target
  check and was stopped; a gripper close returned while the gripper still closed). The
  program's start-up now writes such a done_seq 0.
- a controller restart puts the numbers back at 0, and another master's first command
  takes number 1 again: a Robot whose move numbered 1 ran before the restart, polled
  after it, said "the robot program took command 1 from another master: this one was
  never read and never runs" (it ran), or, had it seen its move taken before, read the
  other master's done_seq 1 as its own done. It now says the program started again
  under its command (it may have moved before).

- ``play()`` told the paused command it may resume by its number alone, so after such
  a restart it resumed another master's paused move that reused the number of a move
  of its own it never waited for (the arm moved 20 mm after ``play()``). It compares
  the program's start (boot_id) the command was written in too now.

The wrap itself, restarts, lost answers and held copies on it, and masters taking turns
across it: found nothing (kept as regressions).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import pytest

from fault_proxy import FaultProxy, Rule
from pendant import press_play_pause
from safety_invariant import Issued, attempt, check
from sim_speeds import QUICK
from test_controller_restart import restart_controller, robot_through
from test_hunt28_cli_play_pending import deliver, let_run
from test_hunt32_same_robot import (
    FAILURES,
    START,
    next_move_tells_the_truth,
    open_robot,
    recover,
)
from tmmaster import Pose, RegisterMapError, Robot, RobotError, TimeoutPolicy, TMMasterError
from tmmaster._channels import Command, CommandKind
from tmmaster._cli import main
from tmmaster._profiles import profile_from_data
from tmmaster.sim import RobotSetup, Simulator

SimFactory = Callable[..., Simulator]

TOP = 32767
FAR = Pose(300, 200, 200, 180, 0, 90)
A = Pose(300, -200, 200, 180, 0, 90)
B = Pose(300, -150, 200, 180, 0, 90)
C = Pose(250, -150, 200, 180, 0, 90)
D = Pose(250, -100, 180, 180, 0, 90)


def at_wrap(factory: SimFactory, last: int) -> Simulator:
    """A tmflow simulator whose program took and finished command ``last`` before."""
    return factory("tmflow", robot=RobotSetup(initial_seq=last), **QUICK)


def numbers(sim: Simulator) -> tuple[int, int, int]:
    return int(sim.field("seq")), int(sim.field("ack_seq")), int(sim.field("done_seq"))


@pytest.mark.parametrize("maximum", [0, 1])
def test_a_seq_maximum_below_2_is_refused(maximum: int) -> None:
    """With 1, ``ack_seq % 1 + 1`` is 1 again once command 1 is done: the program would
    take the block it just ran again, and again. With 0, nothing can be numbered."""
    with pytest.raises(RegisterMapError, match="maximum of 2 or more"):
        profile_from_data({"extends": "tmflow", "fields": {"seq": {"maximum": maximum}}})


def test_a_seq_maximum_of_2_alternates_and_runs_each_command_once(
    tm_simulator_factory: SimFactory,
) -> None:
    profile = profile_from_data({"extends": "tmflow", "fields": {"seq": {"maximum": 2}}})
    sim = tm_simulator_factory(profile, **QUICK)
    issued: list[Issued] = []
    with open_robot(sim) as robot:
        for target in (A, B, C):
            assert attempt(robot, target, issued) == "done"
    assert numbers(sim) == (1, 1, 1)  # 1, 2, then 1 again
    check(issued, sim.motion_log())


@pytest.mark.parametrize(
    ("last", "kind"),
    [
        pytest.param(TOP - 1, "cancel", id="failed-at-1-cancel"),
        pytest.param(TOP - 1, "project_stop", id="failed-at-1-project_stop"),
        pytest.param(TOP - 2, "cancel", id="failed-at-32767-cancel"),
        pytest.param(TOP - 2, "restart", id="failed-at-32767-restart"),
    ],
)
def test_the_next_move_after_a_failure_on_the_wrap(
    tm_simulator_factory: SimFactory, kind: str, last: int
) -> None:
    """Hunt 32's failures with START numbered ``last + 1``: FAILED is command 1 (the first
    after the wrap) or 32767 (the last before it), and the same Robot's next move runs
    once; a restart that zeroes the registers numbers it 1 again."""
    sim = at_wrap(tm_simulator_factory, last)
    issued: list[Issued] = []
    with open_robot(sim) as robot:
        robot.move_to(START, speed=50)
        issued.append(Issued(START, 0.0, 0.0, "done"))
        assert numbers(sim)[1] == last + 1
        FAILURES[kind](robot, sim, issued)
        recover(robot, sim)
        check(issued, sim.motion_log())
        next_move_tells_the_truth(robot, sim, issued)


def test_a_new_masters_first_command_lands_on_the_wrap(tm_simulator_factory: SimFactory) -> None:
    """Masters take turns, each a new Robot (a new session), across 32767 -> 1."""
    sim = at_wrap(tm_simulator_factory, TOP - 1)
    issued: list[Issued] = []
    seen = []
    for target in (A, B, C, D):
        with open_robot(sim) as robot:
            assert attempt(robot, target, issued) == "done"
        seen.append(numbers(sim)[2])
    assert seen == [TOP, 1, 2, 3]
    check(issued, sim.motion_log())


def test_two_open_masters_taking_turns_across_the_wrap(tm_simulator_factory: SimFactory) -> None:
    """Two Robots open at once, taking turns from 32766: the second's first command
    claims the robot, and from then on the first's are consumed unrun (another_master,
    docs/safety.md); nothing runs twice, the second's run in order across the wrap."""
    sim = at_wrap(tm_simulator_factory, TOP - 2)
    issued: list[Issued] = []
    with open_robot(sim) as first, open_robot(sim) as second:
        outcomes = [
            attempt(r, t, issued) for r, t in zip([first, second] * 2, (A, B, C, D), strict=True)
        ]
    assert outcomes == ["done", "done", "CommandRejectedError", "done"]
    assert [m.seq for m in sim.motion_log()] == [TOP - 1, TOP, 2]  # 1: C, consumed unrun
    check(issued, sim.motion_log())


def dead_masters_command_on_the_wrap(sim: Simulator, *, stop: bool) -> int:
    """ack_seq 32767: a master's command to FAR, numbered 1, lands in the paused (or
    stopped) project's registers, and the master dies. Its number."""
    with Robot(sim.url, gripper=None, timeouts=TimeoutPolicy(heartbeat_ttl_s=10.0)) as first:
        first.wait_until_ready()
        ticket = first._channel.prepare(Command(CommandKind.PTP, FAR, speed=50))
        ((block, words),) = ticket.plan
        if stop:
            sim.call(lambda: sim._controller.bank.set("stop_project", True))
            sim.wait_for(lambda: not sim.field("project_running"), timeout=2.0)
        else:
            press_play_pause(sim)  # the operator's Pause
            sim.wait_for(lambda: bool(sim.field("paused")), timeout=2.0)
        deliver(sim.port, block.address, words)
        first._heartbeat.stop()  # the master is gone: no close, no clean-up
    let_run(sim, 5)
    assert ticket.seq == 1
    assert numbers(sim)[:2] == (1, TOP)  # pending: seq == ack_seq % 32767 + 1
    return ticket.seq


@pytest.mark.parametrize("stop", [False, True], ids=["paused", "stopped"])
def test_robot_play_never_runs_a_dead_masters_command_numbered_1_on_the_wrap(
    tm_simulator_factory: SimFactory, capsys: pytest.CaptureFixture[str], stop: bool
) -> None:
    """Paused, ``tmmaster robot play`` refuses (press Stop); stopped, it presses Play and
    the start-up rule consumes number 1 unrun; either way the arm stays, and a new
    master's next command (2) runs once."""
    sim = at_wrap(tm_simulator_factory, TOP)
    home = sim.tcp_pose()
    dead_masters_command_on_the_wrap(sim, stop=stop)
    code = main(["robot", "play", "--host", "127.0.0.1", "--port", str(sim.port)])
    if stop:
        assert code == 0
        sim.wait_for(lambda: sim.field("ack_seq") == 1, timeout=3.0)  # consumed
    else:
        assert code == 4
        assert "press Stop" in capsys.readouterr().err
    let_run(sim, 10)
    assert sim.motion_log() == ()
    assert sim.tcp_pose().is_close(home, mm=0.01, deg=0.01)
    if not stop:
        assert main(["robot", "stop", "--host", "127.0.0.1", "--port", str(sim.port)]) == 0
        assert main(["robot", "play", "--host", "127.0.0.1", "--port", str(sim.port)]) == 0
        sim.wait_for(lambda: sim.field("ack_seq") == 1, timeout=3.0)  # consumed at start
    issued: list[Issued] = [Issued(FAR, 0.0, 0.0, "dead")]
    with open_robot(sim) as robot:
        assert attempt(robot, A, issued) == "done"
    assert numbers(sim) == (2, 2, 2)
    check(issued, sim.motion_log())
    assert [m.target for m in sim.motion_log() if m.target] == [A]


def handshake_put_back(sim: Simulator, seq: int = 0) -> None:
    """The operator's Stop, ``seq`` (to ``seq``) and ``ack_seq`` (to 0) written by hand
    (``done_seq`` left as it is: docs/tmflow-program.md's commissioning steps write these
    registers with mbpoll), then Play: the program reads them back at its start."""
    sim.call(lambda: sim._controller.bank.set("stop_project", True))
    sim.wait_for(lambda: not sim.field("project_running"), timeout=2.0)

    def put_back() -> None:
        sim._controller.bank.set("seq", seq)
        sim._controller.bank.set("ack_seq", 0)

    sim.call(put_back)
    sim.press_play()
    sim.wait_for(lambda: bool(sim.field("project_running")), timeout=2.0)
    let_run(sim, 5)


@pytest.mark.parametrize(
    ("kind", "earlier"),
    [("move", 1), ("gripper", 1), ("move", 2)],
    ids=["move", "gripper", "move-after-the-start-up-rule"],
)
def test_a_done_seq_left_at_the_next_number_is_not_read_as_its_done(
    tm_simulator_factory: SimFactory, kind: str, earlier: int
) -> None:
    """Command 1 (the first after the wrap) ran and is done (done_seq 1); seq and ack_seq
    are put back to 0 by hand and the project started again: the next command is
    numbered 1 again. The done_seq 1 it finds is an older command's: no master may read
    it as this one's done (it did: a move "finished" as soon as it was taken, then failed
    its at-target check and was stopped; a gripper close returned done while the
    gripper still closed). Or commands 1 and 2 ran, seq is put back to 1 and ack_seq to
    0: the start-up rule consumes 1, and done_seq 2 is then the next number's."""
    sim = tm_simulator_factory(
        "tmflow", time_scale=20.0, robot=RobotSetup(initial_seq=TOP, gripper="blog-2fg7")
    )
    issued: list[Issued] = []
    with open_robot(sim) as robot:
        for target in (A, B)[:earlier]:
            assert attempt(robot, target, issued) == "done"
        assert numbers(sim) == (earlier, earlier, earlier)
        handshake_put_back(sim, seq=earlier - 1)
        robot.play()  # waits until it runs
        if kind == "move":
            assert attempt(robot, FAR, issued, speed=3) == "done"
            ended = issued[-1].ended_at
        else:
            assert robot.gripper is not None
            robot.gripper.close()
            ended = time.monotonic()
        ran = sim.motion_log()[-1]
        assert (ran.kind, ran.seq) == ("ptp" if kind == "move" else "gripper_close", earlier)
        assert ran.done_wall_time is not None  # finished, and before the call returned
        assert ended is not None
        assert ran.done_wall_time <= ended
    check(issued, sim.motion_log())


@pytest.mark.parametrize("fault", ["drop_answer", "hold"])
def test_a_write_of_number_1_answered_late_or_held_runs_once(
    tm_simulator_factory: SimFactory, fault: str
) -> None:
    """The first command after the wrap (number 1): its write's answer lost, or its first
    copy held in the network (the resend lands) and released once the next command (2)
    is done: B runs once, C once, and the late copy of 1 never."""
    sim = at_wrap(tm_simulator_factory, TOP - 1)
    issued: list[Issued] = []
    release = threading.Event()
    with FaultProxy(sim.port) as proxy, robot_through(proxy) as robot:
        robot.wait_until_ready()
        assert attempt(robot, A, issued) == "done"
        rule = Rule(fault, function_code=16, address=9000, release=release)
        proxy.add(rule)
        assert attempt(robot, B, issued) == "done"
        assert proxy.played(fault)
        assert attempt(robot, C, issued) == "done"
        release.set()
        let_run(sim, 10)
        assert numbers(sim)[1:] == (2, 2)
    check(issued, sim.motion_log())
    assert [m.seq for m in sim.motion_log()] == [TOP, 1, 2]


def test_play_never_resumes_another_masters_move_that_reuses_its_number(
    tm_simulator_factory: SimFactory,
) -> None:
    """Master A starts a move (number 1) and never waits for it; the controller restarts
    (its registers at 0); master B's first move is number 1 too; the operator pauses it
    and B dies (no close, within its heartbeat's time-to-live). A's play() must refuse:
    the paused move is not A's, whatever its number."""
    sim = tm_simulator_factory("tmflow", time_scale=5.0)
    ttl = TimeoutPolicy(heartbeat_ttl_s=10.0)
    with open_robot(sim, gripper=None, timeouts=ttl) as first:
        mine = first.start_move(A, speed=50)
        sim.wait_for(lambda: sim.field("done_seq") == 1, timeout=5.0)
        # A beats no more: a beat of A's while B's command is pending or paused is another
        # master's, and the program gives it up itself (one master at a time), before A's
        # play() is asked anything (seen on a loaded machine).
        first._heartbeat.stop()
        restart_controller(sim)
        with open_robot(sim, gripper=None, timeouts=ttl) as second:
            theirs = second.start_move(FAR, speed=5)
            sim.wait_for(lambda: len(sim.motion_log()) == 2, timeout=5.0)
            assert mine.ticket.seq == theirs.ticket.seq == 1
            press_play_pause(sim)  # the operator's Pause
            sim.wait_for(lambda: bool(sim.field("paused")), timeout=2.0)
            second._heartbeat.stop()  # B is gone: no close, no clean-up
            let_run(sim, 5)
            here = sim.tcp_pose()
            with pytest.raises(RobotError, match="another master's"):
                first.play()
            let_run(sim, 20)
            assert sim.tcp_pose().is_close(here, mm=0.01, deg=0.01)  # B's move stays paused


@pytest.mark.parametrize("seen", ["never", "taken"])
def test_a_move_from_before_a_restart_is_never_read_as_another_runs_number(
    tm_simulator_factory: SimFactory, seen: str
) -> None:
    """Master A's move, number 1, ran (A saw it taken, or never polled it); the controller
    restarts (its registers at 0) and master B's first move, number 1 too, runs to its
    end. A's wait must say that the program started again under its command (it may
    have moved before): not "never read and never runs" (it ran), and not done (the
    done_seq 1 is B's)."""
    sim = tm_simulator_factory("tmflow", time_scale=5.0)
    with open_robot(sim, gripper=None) as first:
        mine = first.start_move(A, speed=50)
        if seen == "taken":
            sim.wait_for(lambda: len(sim.motion_log()) == 1, timeout=5.0)
            mine.progress()
            assert mine.ticket.acknowledged
        sim.wait_for(lambda: sim.field("done_seq") == 1, timeout=5.0)
        # A beats no more while B moves: a beat of A's during B's move is another
        # master's, and the program would give B's command up (one master at a time).
        first._heartbeat.stop()
        restart_controller(sim)
        with open_robot(sim, gripper=None) as second:
            second.move_to(FAR, speed=100)
            assert second.last_motion is not None
            assert second.last_motion.ticket.seq == mine.ticket.seq == 1
        with pytest.raises(TMMasterError, match="started again under command 1") as failed:
            mine.wait()
        assert "never read" not in str(failed.value)
    assert [m.target for m in sim.motion_log()] == [A, FAR]
