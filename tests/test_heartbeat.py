"""The master's heartbeat: a command on the robot lives only as long as its master.

A tmflow Robot writes ``master_heartbeat``, ``master_ttl_ms`` and ``master_session``
(9050-9052) in one FC16 request every ``TimeoutPolicy.heartbeat_s``, from its first
command to close, on its driver's loop (a network robot) or in a small thread (an
in-process one). The generated robot program, interpreted by the simulator, expires a
command whose master went silent: a move paused mid-way never resumes at Play once the
heartbeat stopped, and a live master's long move is never expired.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest

from pendant import press_play_pause, runs_again_without_moving
from tmmaster import ConfigError, Pose, Robot, TimeoutPolicy
from tmmaster._heartbeat import HEARTBEAT_MAX, Heartbeat
from tmmaster._profiles import robot_profile
from tmmaster.sim import Simulator

LEFT = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 200, 200, 180, 0, 90)  # from LEFT: a long turn of J1
#: A short time-to-live, so that an expiry is seen within a second (wall time: the
#: simulated program counts GetNowStamp in wall milliseconds whatever the time scale).
FAST = TimeoutPolicy(heartbeat_s=0.05, heartbeat_ttl_s=0.5)
#: Simulated seconds per wall second: the long move (LEFT to FAR at 5 %, 7.7 simulated
#: seconds) takes at least 1.28 s of wall time, over twice the time-to-live.
TIME_SCALE = 6


@pytest.fixture(params=["network", "in-process"])
def sim(request: pytest.FixtureRequest) -> Iterator[Simulator]:
    with Simulator(time_scale=TIME_SCALE, listen=request.param == "network") as simulator:
        yield simulator


def robot_for(sim: Simulator, **options: object) -> Robot:
    if sim.listen:
        return Robot("127.0.0.1", sim.port, **options)  # type: ignore[arg-type]
    return Robot(sim.url, **options)  # type: ignore[arg-type]


def heartbeat_writes(sim: Simulator) -> list[tuple[int, ...]]:
    return [
        r.values
        for r in sim.request_log
        if r.function_code == 16 and r.address == 9050 and r.values is not None
    ]


def test_a_robot_beats_from_its_first_command_until_it_closes(sim: Simulator) -> None:
    robot = robot_for(sim, timeouts=FAST)
    with robot:
        robot.wait_until_ready()
        time.sleep(4 * FAST.heartbeat_s)
        assert heartbeat_writes(sim) == []  # a robot that only reads claims nothing
        robot.move_to(LEFT, speed=50)
        session = robot._heartbeat.session
        requests = robot.stats.requests
        sim.wait_for(lambda: len(heartbeat_writes(sim)) >= 3, timeout=5.0)
        assert requests == robot.stats.requests
    writes = heartbeat_writes(sim)
    # One FC16 request of the three registers; the heartbeat changes every time, the TTL
    # in ms, the session the one every command carries.
    beats = [values[0] for values in writes]
    assert all(values[1:] == (500, session) for values in writes)
    assert 1 <= session <= HEARTBEAT_MAX
    # Rising from 1; a beat skipped because the link stayed busy for its period (a loaded
    # machine) still uses up its number: the program only needs each beat to differ.
    assert beats[0] == 1
    assert all(later > earlier for earlier, later in itertools.pairwise(beats))
    assert sim.field("master_ttl_ms") == 500
    assert sim.field("command_session") == session
    # Nothing after close().
    after = len(heartbeat_writes(sim))
    assert not robot._heartbeat.running
    time.sleep(4 * FAST.heartbeat_s)
    assert len(heartbeat_writes(sim)) == after


def test_the_heartbeat_wraps_to_1_after_32767() -> None:
    class Log:
        def info(self, *args: object, **kwargs: object) -> None: ...

        def warning(self, *args: object, **kwargs: object) -> None: ...

    no_link: Any = None
    beat = Heartbeat(robot_profile("tmflow"), no_link, period_s=0.4, ttl_s=2.0, log=Log())
    beat.beat = HEARTBEAT_MAX - 1
    assert [beat.next_words()[0] for _ in range(3)] == [HEARTBEAT_MAX, 1, 2]
    assert beat.next_words()[1] == 2000
    article = Heartbeat(robot_profile("article"), no_link, period_s=0.4, ttl_s=2.0, log=Log())
    assert not article.enabled


def test_the_period_and_ttl_are_checked() -> None:
    assert (TimeoutPolicy().heartbeat_s, TimeoutPolicy().heartbeat_ttl_s) == (0.4, 2.0)
    with pytest.raises(ConfigError, match=r"timeouts\.heartbeat_s"):
        TimeoutPolicy(heartbeat_s=0.6)
    with pytest.raises(ConfigError, match="at least three heartbeats"):
        TimeoutPolicy(heartbeat_s=0.5, heartbeat_ttl_s=1.0)


@pytest.mark.parametrize("master_alive", [False, True])
def test_a_paused_move_whose_master_stopped_beating_never_resumes(
    sim: Simulator, master_alive: bool
) -> None:
    robot = robot_for(sim, timeouts=FAST)
    with robot:
        robot.wait_until_ready()
        robot.move_to(LEFT, speed=50)
        start = sim.tcp_pose()
        # 0.64 s of wall time: paused 20 mm into its 400 mm, long before its end.
        motion = robot.start_move(FAR, speed=10)
        sim.wait_for(lambda: sim.tcp_pose().distance_to(start) > 20, timeout=5.0)
        press_play_pause(sim)  # the operator pauses the project mid-move
        sim.wait_for(lambda: bool(sim.field("paused")), timeout=2.0)
        if not master_alive:
            robot._heartbeat.stop()  # the master is gone: nothing beats any more
            sim.wait_for(lambda: not sim.field("project_running"), timeout=3.0)
        else:
            sim.wait_for(lambda: len(heartbeat_writes(sim)) > 12, timeout=3.0)  # > TTL
        held = sim.tcp_pose()
        press_play_pause(sim)  # the operator presses Play
        if master_alive:
            motion.wait()  # resumed and finished: a live master's move never expires
            assert sim.tcp_pose().is_close(FAR, mm=1.0, deg=1.0)
        else:
            runs_again_without_moving(sim, held, moves=2)
            assert any("heartbeat" in line for line in sim.displayed())
            assert motion.done is False
        robot.interrupt()


def test_a_long_move_of_a_live_master_is_not_expired(sim: Simulator) -> None:
    # The move takes several times the time-to-live: each heartbeat keeps it alive.
    robot = robot_for(sim, timeouts=FAST)
    with robot:
        robot.wait_until_ready()
        robot.move_to(LEFT, speed=50)
        motion = robot.move_to(FAR, speed=5)
        assert motion.done
        assert motion.finished_at is not None
        assert motion.finished_at - motion.ticket.sent_at > 2 * FAST.heartbeat_ttl_s


def test_a_beat_waits_for_a_link_the_robots_thread_holds(sim: Simulator) -> None:
    """A robot polling densely holds its link most of the time: a beat that only tried
    the link's lock missed beat after beat, and the program expired a live master's
    command. A beat waits for the link (up to its period) instead."""
    period = 0.25
    robot = robot_for(sim, timeouts=TimeoutPolicy(heartbeat_s=period, heartbeat_ttl_s=1.0))
    with robot:
        robot.wait_until_ready()
        robot.move_to(LEFT, speed=50)  # the first command: from then on it beats
        beat: Heartbeat = robot._heartbeat  # type: ignore[attr-defined]
        sim.wait_for(lambda: beat.writes >= 1, timeout=5.0)
        written = beat.writes
        while beat.writes == written:  # right after a beat: the next is a period away
            time.sleep(0.001)
        # The robot's thread in a long request: the next beat's slot comes while the link
        # is busy, and the link is free again once that beat waits for it (its let_in()
        # turn), or once it gave up (missed). Not a fixed 1.5 periods: a loaded machine
        # released the link after the beat's whole period once, and it missed.
        transport: Any = robot._transport
        with transport._lock:
            sim.wait_for(lambda: not transport._free_turn.is_set() or beat.missed > 0, 5.0)
        sim.wait_for(lambda: beat.writes >= written + 2, timeout=5.0)
        assert beat.missed == 0


def test_a_thread_reading_back_to_back_does_not_starve_the_heartbeat(sim: Simulator) -> None:
    """Locks are not fair: a thread reading the status back to back held the link at
    every look of the heartbeat, no beat got in, and the robot program expired the live
    master's long move. The thread now lets a waiting beat go first."""
    # A 1 s time-to-live, not FAST's 0.5 s: a loaded machine once kept the beats' thread
    # from running for that long, beside the reader, and the program expired the move.
    policy = TimeoutPolicy(heartbeat_s=FAST.heartbeat_s, heartbeat_ttl_s=1.0)
    robot = robot_for(sim, timeouts=policy)
    stop = threading.Event()

    def read_back_to_back() -> None:
        while not stop.is_set():
            robot.status()

    with robot:
        robot.wait_until_ready()
        robot.move_to(LEFT, speed=50)
        reader = threading.Thread(target=read_back_to_back)
        reader.start()
        try:
            motion = robot.move_to(FAR, speed=2)  # about 3 s: three times the time-to-live
        finally:
            stop.set()
            reader.join()
        assert motion.done
        assert motion.finished_at is not None
        assert motion.finished_at - motion.ticket.sent_at > 2 * policy.heartbeat_ttl_s


class _TurnsAsked(threading.Event):
    """The link's "free turn" event, counting the requests that waited on it."""

    def __init__(self) -> None:
        super().__init__()
        self.set()
        self.waits = 0

    def wait(self, timeout: float | None = None) -> bool:
        self.waits += 1
        return super().wait(timeout)


def test_a_stop_never_gives_its_turn_to_a_waiting_beat(sim: Simulator) -> None:
    """A request of the robot's thread lets a beat waiting for the link go first (the
    test above). A Stop did too: on a slow link it went out a whole beat's request later.
    Clean-up writes (and their reads) take the link as soon as it is free; the thread's
    other requests still let the beat in."""
    with robot_for(sim) as robot:
        robot.wait_until_ready()
        transport: Any = robot._transport
        turns = transport._free_turn = _TurnsAsked()
        with transport.let_in():  # a beat waiting for its turn on the link
            robot.stop()
            assert turns.waits == 0
            robot.status()
            assert turns.waits > 0


class _Link:
    """A link whose heartbeat writes are answered or not, as the test says."""

    def __init__(self) -> None:
        self.busy = False
        self.written: list[list[int]] = []

    def write_when_free(self, address: int, words: list[int], *, wait_s: float) -> bool | None:
        if self.busy:
            return True  # the link stayed busy for wait_s: nothing sent
        self.written.append(words)
        return None

    def write_block(self, table: object, address: int, words: list[int], retry: bool) -> None:
        self.written.append(words)

    def read_fields(self, fields: object) -> dict[str, int]:
        return {"master_session": 0}


def _beating(link: _Link) -> Heartbeat:
    class Log:
        def info(self, *args: object, **kwargs: object) -> None: ...

        def warning(self, *args: object, **kwargs: object) -> None: ...

    transport: Any = link
    beat = Heartbeat(robot_profile("tmflow"), transport, period_s=0.4, ttl_s=2.0, log=Log())
    beat._thread = threading.Thread(target=print)  # running, without a writer of its own
    beat.claim(None)
    return beat


@pytest.mark.parametrize("how", ["renewed beat missed", "older beat answered after it"])
def test_a_command_beats_first_when_the_robot_may_hold_another_session(how: str) -> None:
    # A command carries the master's session; the program refuses one whose session is
    # not the last beat's (another_master). After a renewal whose beat the robot may not
    # hold, the next command's claim beats with the new session before it is sent.
    link = _Link()
    beat = _beating(link)
    assert not beat.claim_due
    older = beat.next_words()  # a slot's beat, built before the renewal, still waiting
    link.busy = how == "renewed beat missed"
    session = beat.renew()
    if how == "older beat answered after it":
        assert beat.wrote(None, older) == 0.0  # the next slot at once, with the new session
    assert beat.claim_due
    link.busy = False
    assert beat.claim(None) == session
    assert link.written[-1][2] == session
    assert not beat.claim_due
