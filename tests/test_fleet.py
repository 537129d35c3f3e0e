"""Fleet: robots whose waits are polled on one event loop, checked on what the robot did.

The safety regressions and the stateful hunt also run every robot in a Fleet
(``test_safety_regressions.py``'s ``robots`` fixture, ``test_safety_stateful.py``'s Fleet
classes); these tests cover what is the fleet's own: who polls, how a wait it polls ends
early, and its life cycle.
"""

from __future__ import annotations

import _thread
import gc
import signal
import socket
import threading
import time
import weakref
from collections.abc import Callable, Iterator
from typing import Any

import pytest

import tmmaster
import tmmaster._fleet as fleet_module
from fault_proxy import FaultProxy, Rule
from tmmaster import Fleet, MovePhase, PollPolicy, Pose, Robot, TimeoutPolicy
from tmmaster._channels import channel_for
from tmmaster._following import FollowState
from tmmaster._profiles import robot_profile
from tmmaster.sim import DEFAULT_PART_POSE, Simulator

SimFactory = Callable[..., Simulator]

A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(300, -200, 180, 180, 0, 90)
C = Pose(250, 0, 160, 180, 0, 90)
PROFILES = ["article", "tmflow"]
#: Control ticks that show what the robot does on its own after a move was given up: a
#: move still running goes on at every tick, a command left armed (no fault holding it)
#: starts within two or three (test_aio.NOTHING_LATER_TICKS).
NOTHING_LATER_TICKS = 10


def ticks_pass(sim: Simulator, ticks: int) -> None:
    """Until the simulator ran ``ticks`` more control ticks: counted on its own clock, so
    a simulator slowed by load is never looked at too early."""
    start = sim.ticks
    sim.wait_for(lambda: sim.ticks >= start + ticks, timeout=5.0)


def late_ack_over(sim: Simulator, motion: tmmaster.Motion) -> None:
    """Until a command left armed under a late_ack fault (cleared by now) would have run,
    then NOTHING_LATER_TICKS more (as test_aio.late_ack_over): at once on article; on
    tmflow once the program, done waiting the delay out, answered its number."""
    seq = motion.ticket.seq  # 0: the article contract numbers nothing
    if seq:
        sim.wait_for(lambda: int(sim.field("ack_seq")) >= seq, timeout=5.0)
    ticks_pass(sim, NOTHING_LATER_TICKS)


@pytest.fixture
def fleet() -> Iterator[Fleet]:
    with Fleet() as opened:
        yield opened


@pytest.fixture
def robots(fleet: Fleet) -> Iterator[Callable[..., Robot]]:
    """Robots of the fleet, connected and ready; closed after the test (then the fleet)."""
    opened: list[Robot] = []

    def make(sim: Simulator, **options: Any) -> Robot:
        options.setdefault("gripper", None)
        options.setdefault("polling", PollPolicy(interval_s=0.01))
        robot = Robot("127.0.0.1", sim.port, profile=sim.profile, link=fleet, **options)
        opened.append(robot)
        robot.connect()
        robot.wait_until_ready(timeout_s=5)
        return robot

    yield make
    for robot in opened:
        robot.close()


class Wakes:
    """Counts what the loop handed the waiting threads: observations and hand-backs."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.observations = 0
        self.handed_back = 0
        follow = fleet_module.FleetMember.follow

        def counted(member: fleet_module.FleetMember, state: Any) -> Any:
            observation = follow(member, state)
            if observation is None:
                self.handed_back += 1
            else:
                self.observations += 1
            return observation

        monkeypatch.setattr(fleet_module.FleetMember, "follow", counted)


@pytest.mark.parametrize("profile", PROFILES)
def test_the_loop_polls_and_wakes_the_thread_only_when_the_poll_needs_it(
    tm_simulator_factory: SimFactory,
    robots: Callable[..., Robot],
    monkeypatch: pytest.MonkeyPatch,
    profile: str,
) -> None:
    wakes = Wakes(monkeypatch)  # before the robot: it takes its driver when made
    sim = tm_simulator_factory(profile, time_scale=4)  # moves of tenths of a second
    robot = robots(sim)
    requests = robot.stats.requests
    for target in (A, B, C):
        motion = robot.move_to(target, speed=60)
        assert motion.done
        assert motion.last_pose is not None
        assert motion.last_pose.is_close(target)
    assert [r.target for r in sim.motion_log()] == [A, B, C]
    # Each move: once for the acknowledgement, once for the end (one poll may see both,
    # for these short moves at 40x); nothing handed back.
    assert 3 <= wakes.observations <= 6
    assert wakes.handed_back == 0
    # The loop polled in between: far more requests than the threads were woken for
    # (each move also costs its checks and its write: about 3 requests).
    assert robot.stats.requests - requests > 3 * 3 + 2 * wakes.observations


@pytest.mark.parametrize("profile", PROFILES)
def test_two_robots_of_one_fleet_move_at_once(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sims = [tm_simulator_factory(profile) for _ in range(2)]
    pair = [robots(sim) for sim in sims]
    errors: list[BaseException] = []

    def tour(robot: Robot) -> None:
        try:
            for target in (A, B, C, A):
                robot.move_to(target, speed=80)
        except BaseException as exc:
            errors.append(exc)

    threads = [threading.Thread(target=tour, args=(robot,)) for robot in pair]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(30)
    assert errors == []
    for sim in sims:
        assert [r.target for r in sim.motion_log()] == [A, B, C, A]


@pytest.mark.parametrize("profile", PROFILES)
def test_an_interrupt_ends_a_wait_the_loop_polls_at_once_and_stops_the_arm(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile, time_scale=2)
    # Nominal polling at 1 s: only the interrupt's wake-up can end the wait quickly.
    robot = robots(sim, polling=tmmaster.PollPolicy(interval_s=1.0, predictive=False))
    motion = robot.start_move(A, speed=10)
    sim.wait_for(lambda: bool(sim.motion_log()), timeout=5)
    threading.Timer(0.1, robot.interrupt).start()
    started = time.monotonic()
    with pytest.raises(tmmaster.StopRequestedError):
        motion.wait()
    took = time.monotonic() - started
    seen = (took, motion.phase, motion.withdrawn, motion.stop_delivered, sim.motion_log())
    assert took < 0.6, seen
    assert motion.phase is MovePhase.FAILED, seen
    assert motion.stop_delivered is True, seen
    ticks_pass(sim, NOTHING_LATER_TICKS)  # a move still running would go on
    assert not sim.tcp_pose().is_close(A), seen  # stopped short of the target (seconds away)


@pytest.mark.parametrize("profile", PROFILES)
def test_ctrl_c_in_a_wait_the_loop_polls_withdraws_or_stops_before_returning(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    # The acknowledgement would come 20 simulated s (0.5 s) later: Ctrl-C at 0.2 s finds it
    # pending, and the tmflow program answers the cancel once its link is free again.
    sim = tm_simulator_factory(profile, faults=["late_ack:delay_s=20"])
    robot = robots(sim, timeouts=TimeoutPolicy(ack_timeout_s=30))
    motion = robot.start_move(A, speed=60)
    timer = threading.Timer(0.2, _thread.interrupt_main)
    # Python's own Ctrl-C handler, also where pytest started with SIGINT ignored (`&` in
    # a script, nohup): interrupt_main() does nothing then.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        timer.start()
        with pytest.raises(KeyboardInterrupt):
            motion.wait()
        timer.join()
    finally:
        signal.signal(signal.SIGINT, previous)
    assert motion.withdrawn is True
    sim.clear_faults()
    late_ack_over(sim, motion)  # a command still armed would run by now
    assert sim.motion_log() == ()


@pytest.mark.parametrize("profile", PROFILES)
def test_a_robot_failure_seen_by_the_loop_is_raised_in_the_thread(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot], profile: str
) -> None:
    sim = tm_simulator_factory(profile, faults=["estop:at_move=1"])
    robot = robots(sim)
    expected = tmmaster.RobotFaultError if profile == "article" else tmmaster.EmergencyStopError
    with pytest.raises(expected):
        robot.move_to(A, speed=30)


@pytest.mark.parametrize("own_fleet", [False, True], ids=["default-driver", "fleet"])
def test_reading_no_fields_reads_nothing_and_gives_nothing(
    tm_simulator_factory: Callable[..., Simulator], own_fleet: bool
) -> None:
    # A profile may publish none of what a read asks for (article: no joint speeds).
    sim = tm_simulator_factory(listen=True)
    fleet = Fleet() if own_fleet else None
    try:
        with Robot("127.0.0.1", sim.port, link=fleet) as robot:
            sim.clear_request_log()
            assert robot._channel.read(()) == {}  # the reads a wait or a status make
            assert list(sim.request_log) == []
    finally:
        if fleet is not None:
            fleet.close()


def test_a_request_without_an_answer_times_out_on_its_own_timeout(
    tm_simulator_factory: SimFactory, fleet: Fleet
) -> None:
    """The link's ResponseTimeoutError (a TimeoutError) is its answer, not the loop's silence."""
    sim = tm_simulator_factory("article")
    with FaultProxy(sim.port) as proxy:
        robot = Robot(
            "127.0.0.1",
            proxy.port,
            profile="article",
            gripper=None,
            retry=tmmaster.RetryPolicy(attempts=1),
            timeouts=TimeoutPolicy(request_s=0.1),
            link=fleet,
        )
        with robot:
            proxy.add(Rule("drop_answer", function_code=3))
            started = time.monotonic()
            with pytest.raises(tmmaster.ResponseTimeoutError, match="no answer"):
                robot.status()
            # The request's 0.1 s, not the 1 s more the thread would give a silent loop.
            assert time.monotonic() - started < 0.6


def test_closing_the_fleet_closes_its_robots_and_is_safe_twice(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("article", time_scale=2)
    fleet = Fleet()
    robot = Robot("127.0.0.1", sim.port, profile="article", gripper=None, link=fleet)
    robot.connect()
    robot.wait_until_ready(timeout_s=5)
    motion = robot.start_move(A, speed=10)
    sim.wait_for(lambda: bool(sim.motion_log()), timeout=5)
    fleet.close()
    fleet.close()
    assert robot.state is tmmaster.ConnectionState.CLOSED
    assert motion.stop_delivered is True  # the move outstanding was stopped first
    with pytest.raises(tmmaster.ConnectError):
        robot.status()
    with pytest.raises(tmmaster.ConfigError):
        Robot("127.0.0.1", sim.port, profile="article", gripper=None, link=fleet)


def test_a_fleet_robot_refuses_an_in_process_host(
    fleet: Fleet, tm_simulator_factory: SimFactory
) -> None:
    sim = tm_simulator_factory("article", listen=False)
    with pytest.raises(tmmaster.ConfigError, match="Modbus TCP"):
        Robot(sim.url, link=fleet)


class _NoIO:
    """A transport that fails the test on any request: a poll must only yield its reads."""

    stats = tmmaster.TransportStats()
    state = tmmaster.ConnectionState.CONNECTED
    epoch = 0

    def __getattr__(self, name: str) -> Any:
        raise AssertionError(f"a poll used the transport directly ({name})")


@pytest.mark.parametrize("profile", PROFILES)
@pytest.mark.parametrize("situation", ["pending", "running", "done", "estop", "error"])
def test_a_poll_reads_only_by_yielding_its_field_sets(profile: str, situation: str) -> None:
    """What the fleet's loop relies on: no branch of a poll reads behind its back."""
    channel = channel_for(robot_profile(profile), _NoIO())  # type: ignore[arg-type]
    ticket = tmmaster._channels.Ticket(
        tmmaster._channels.Command(tmmaster._channels.CommandKind.PTP, A, 50), [], 0.0, seq=1
    )
    values = _registers(profile, situation)
    steps = channel.poll_steps(ticket)
    fields = next(steps)
    while True:
        try:
            fields = steps.send({f.name: values.get(f.name, 0) for f in fields})
        except StopIteration as finished:
            observation = finished.value
            break
    faulted = situation in ("estop", "error")
    assert (observation.failure is not None) == faulted
    assert observation.done == (situation == "done")


def _registers(profile: str, situation: str) -> dict[str, Any]:
    """Register values (by field name) that show ``situation`` for a ticket with seq 1."""
    if profile == "article":
        return {
            "command": 1 if situation == "pending" else 0,
            "motion_status": 1 if situation in ("pending", "running") else 0,
            "robot_mode": 7 if situation in ("estop", "error") else 5,
            "error_code": 0x200 if situation in ("estop", "error") else 0,
        }
    return {
        "ack_seq": 0 if situation == "pending" else 1,
        "done_seq": 1 if situation == "done" else 0,
        "robot_state": 1 if situation in ("pending", "running") else 0,
        "estop": situation == "estop",
        "error": situation == "error",
        "project_running": situation not in ("estop", "error"),
        "last_error_code": 7 if situation in ("estop", "error") else 0,
    }


@pytest.mark.parametrize("profile", PROFILES)
def test_the_watch_reads_each_robots_status_between_its_moves_and_polls(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, time_scale=4)
    with Fleet(watch_hz=50) as fleet:
        idle = Robot("127.0.0.1", sim.port, profile=profile, gripper=None, link=fleet)
        time.sleep(0.1)
        assert fleet.latest(idle).polls == 0  # not connected: nothing read, nothing failed
        assert fleet.latest(idle).failures == 0
        robot = Robot(
            "127.0.0.1",
            sim.port,
            profile=profile,
            gripper=None,
            polling=PollPolicy(interval_s=0.01),
            link=fleet,
        )
        robot.connect()
        robot.wait_until_ready(timeout_s=5)
        before = fleet.latest(robot).polls
        for target in (A, B):
            motion = robot.move_to(target, speed=60)
            assert motion.done
        assert motion.finished_at is not None
        deadline = time.monotonic() + 2
        while (fleet.latest(robot).read_at or 0) <= motion.finished_at:  # a read after the end
            assert time.monotonic() < deadline
            time.sleep(0.01)
        seen = fleet.latest(robot)
        assert seen.polls > before  # the watch went on reading while the robot moved
        assert seen.error is None
        assert seen.status is not None
        assert seen.status.pose.is_close(B)
        assert [r.target for r in sim.motion_log()] == [A, B]
        idle.close()


def test_latest_needs_a_watching_fleet_and_one_of_its_robots(
    fleet: Fleet, tm_simulator_factory: SimFactory
) -> None:
    sim = tm_simulator_factory("article")
    robot = Robot("127.0.0.1", sim.port, profile="article", gripper=None, link=fleet)
    with pytest.raises(tmmaster.ConfigError, match="watch_hz"):
        fleet.latest(robot)
    with Fleet(watch_hz=20) as other, pytest.raises(tmmaster.ConfigError, match="not one"):
        other.latest(robot)
    with pytest.raises(tmmaster.ConfigError, match="watch_hz"):
        Fleet(watch_hz=0)
    robot.close()


def test_the_watch_does_not_read_again_what_a_moves_poll_just_read(
    tm_simulator_factory: SimFactory,
) -> None:
    """Article: a move's polls read the whole status, so the watch adds no reads then."""
    sim = tm_simulator_factory("article", time_scale=1)
    with Fleet(watch_hz=20) as fleet:
        reads: list[tuple[float, float]] = []
        fleet._timings = reads  # one entry per read the watch made itself
        robot = Robot(
            "127.0.0.1",
            sim.port,
            profile="article",
            gripper=None,
            # polls 5 ms apart: always fresher than half a slot
            polling=tmmaster.PollPolicy(interval_s=0.005, predictive=False),
            link=fleet,
        )
        with robot:
            robot.wait_until_ready(timeout_s=5)
            time.sleep(0.2)
            assert reads  # the watch reads an idle robot itself
            before = len(reads)
            published = fleet.latest(robot).polls
            motion = robot.move_to(A, speed=50)  # 0.68 s: thirteen watch slots
            assert motion.expected_s > 0.3  # real time: six watch slots or more
            # The move's polls were published in its slots; the watch read at most at the
            # edges (without this, about one read per slot: six or more).
            assert len(reads) - before <= 2
            assert fleet.latest(robot).polls - published >= 6


def test_a_gripper_command_through_the_robot_program_is_followed_by_the_loop(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    """tmflow: grip and release are commands of the sequence handshake, waited for alike."""
    sim = tm_simulator_factory("tmflow")
    robot = robots(sim, gripper="auto")
    robot.move_to(DEFAULT_PART_POSE, speed=100)
    assert robot.gripper.grip().holding
    assert sim.field("grasp_status") == 1
    assert any(o.held for o in sim.objects())
    robot.gripper.open()
    assert sim.field("grasp_status") == 0


def test_a_fleet_robot_that_cannot_connect_raises_connect_error(fleet: Fleet) -> None:
    with socket.socket() as unused:  # a loopback port nothing listens on
        unused.bind(("127.0.0.1", 0))
        port = unused.getsockname()[1]
    robot = Robot(
        "127.0.0.1",
        port,
        profile="article",
        gripper=None,
        retry=tmmaster.RetryPolicy(attempts=2, initial_backoff_s=0.01),
        link=fleet,
    )
    with pytest.raises(tmmaster.ConnectError):
        robot.connect()
    assert robot.state is tmmaster.ConnectionState.CLOSED  # closed by the failed connect


def test_a_stop_request_just_before_the_loops_first_nap_is_not_slept_through(
    tm_simulator_factory: SimFactory,
    robots: Callable[..., Robot],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The stop event set after the thread handed the wait over, before the loop's nap,
    with no wake-up call (the race interrupt() has with the loop): the loop sees it."""
    sim = tm_simulator_factory("article", time_scale=2)
    robot = robots(sim, polling=tmmaster.PollPolicy(interval_s=1.0, predictive=False))
    due = FollowState.due

    def due_then_stop(state: FollowState) -> float:
        when = due(state)
        if threading.current_thread().name == "tmmaster-fleet":
            state.stop_event.set()  # as interrupt() does, minus its wake-up call
        return when

    monkeypatch.setattr(FollowState, "due", due_then_stop)
    motion = robot.start_move(A, speed=10)
    started = time.monotonic()
    with pytest.raises(tmmaster.StopRequestedError):
        motion.wait()
    assert time.monotonic() - started < 0.5  # not the 1 s nap
    assert motion.stop_delivered is True or motion.withdrawn is True


@pytest.mark.parametrize("profile", PROFILES)
def test_closing_the_fleet_while_a_thread_waits_ends_the_wait_and_stops_the_arm(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, time_scale=2)
    fleet = Fleet(watch_hz=20)
    robot = Robot("127.0.0.1", sim.port, profile=profile, gripper=None, link=fleet)
    robot.connect()
    robot.wait_until_ready(timeout_s=5)
    ended: list[BaseException] = []

    def drive() -> None:
        try:
            robot.move_to(A, speed=10)  # seconds long
        except BaseException as exc:
            ended.append(exc)

    thread = threading.Thread(target=drive)
    thread.start()
    sim.wait_for(lambda: bool(sim.motion_log()), timeout=5)
    fleet.close()
    thread.join(5)
    assert not thread.is_alive()
    assert len(ended) == 1
    assert isinstance(ended[0], tmmaster.TMMasterError)  # StopRequested, or the link closed
    motion = robot.last_motion
    assert motion is not None
    assert motion.stop_delivered is True
    ticks_pass(sim, NOTHING_LATER_TICKS)  # a move still running would go on
    assert not sim.tcp_pose().is_close(A)  # stopped short of the target


@pytest.mark.parametrize("profile", PROFILES)
def test_closing_a_fleet_with_a_dead_robot_stops_every_robot_at_once_within_its_budget(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    # Four robots moving back and forth; one robot's simulator vanishes mid-move. Closing
    # the fleet must not wait on the dead robot's retries before the others: no robot
    # starts a motion after close() is called, and close() returns within its budget,
    # naming the robot it could not confirm.
    sims = [tm_simulator_factory(profile) for _ in range(4)]
    fleet = Fleet()
    robots = [
        Robot(
            "127.0.0.1",
            sim.port,
            profile=profile,
            gripper=None,
            name=f"r{i}",
            polling=PollPolicy(interval_s=0.01),
            link=fleet,
        )
        for i, sim in enumerate(sims)
    ]

    def drive(robot: Robot) -> None:
        for i in range(10_000):
            try:
                robot.move_to(A if i % 2 else B, speed=100)
            except tmmaster.TMMasterError:
                return

    threads = []
    for robot in robots:
        robot.connect()
        robot.wait_until_ready(timeout_s=5)
        threads.append(threading.Thread(target=drive, args=(robot,)))
    for thread in threads:
        thread.start()
    dead = sims[0]
    dead.wait_for(lambda: len(dead.motion_log()) >= 2, timeout=5)
    dead.close()  # mid-move: the robot's link is refused from now on
    time.sleep(0.05)
    called = time.monotonic()
    unconfirmed = fleet.close(timeout_s=1.0)  # (2 s by default)
    took = time.monotonic() - called
    for thread in threads:
        thread.join(15)
    assert not any(thread.is_alive() for thread in threads)
    assert took < 2.0, f"Fleet.close(timeout_s=1.0) took {took:.2f} s with one dead robot"
    # The dead robot is named when it had a move outstanding (it usually has: its link
    # died mid-move); between two moves it had nothing to give up.
    assert unconfirmed in (("r0",), ())
    for sim, robot in zip(sims[1:], robots[1:], strict=True):
        late = [m for m in sim.motion_log() if m.wall_time > called]
        if not late:
            continue
        # Only a command written before close() closed that robot's gate may start after
        # close() was called (the robot takes it at its next tick): the last one, which
        # close() then gave up. The gates close while close() runs (a loaded machine saw
        # one written 2 ms after the call), never after it returned.
        motion = robot.last_motion
        assert motion is not None
        assert motion.target is not None
        assert len(late) == 1, f"motions {[m.number for m in late]} started after close()"
        assert late[0].target is not None
        assert late[0].target.is_close(motion.target)
        assert motion.ticket.sent_at < called + took
    assert all(robot.state is tmmaster.ConnectionState.CLOSED for robot in robots[1:])
    # The dead robot's clean-up goes on past the budget, bounded by its retries.
    deadline = time.monotonic() + 10
    while robots[0].state is not tmmaster.ConnectionState.CLOSED:
        assert time.monotonic() < deadline
        time.sleep(0.05)


def test_a_fleet_refuses_what_it_cannot_serve(tm_simulator_factory: SimFactory) -> None:
    with pytest.raises(tmmaster.ConfigError, match="watch_hz"):
        Fleet(watch_hz=1e6)
    with pytest.raises(tmmaster.ConfigError, match="watch_hz"):
        Fleet(watch_hz=float("nan"))
    with pytest.raises(
        tmmaster.ConfigError, match=r"link must be a tmmaster\.Transport or a tmmaster\.Fleet"
    ):
        Robot("127.0.0.1", 1, profile="article", link=object())  # type: ignore[arg-type]
    with Fleet(watch_hz=20) as fleet:
        with pytest.raises(tmmaster.ConfigError, match="not one"):
            fleet.latest(object())  # type: ignore[arg-type]
        with pytest.raises(tmmaster.ConfigError, match="timeout_s"):
            fleet.close(timeout_s=0)


def test_starting_a_running_fleet_again_leaves_nothing_behind() -> None:
    # start() runs at every robot's join and, for the default driver, at every reconnect
    # attempt: a running fleet's start() is a no-op, never one more finalizer a call (a
    # flaky link's reconnects grew the process for the fleet's whole life).
    def finalizers() -> int:
        return sum(1 for o in gc.get_objects() if type(o) is weakref.finalize)

    with Fleet() as fleet:
        fleet.start()
        before = finalizers()
        for _ in range(100):
            fleet.start()
        assert finalizers() == before
