"""A driver loop that stalls must never send a command its robot has already given up.

Every network robot's requests go out on one event loop (its Fleet's, or the process's
default driver: both are tested). When that loop is held up (saturated by hundreds of
robots, a stalled machine) for longer than a request's bound, the robot's call ends with
an error and the command is given up; the request it handed over must then never be
sent once the loop runs again. Nor may it hold up the clean-up of what the robot gave up:
a Ctrl-C before the loop began polling a move stops the arm at once. The check is on what
the simulated robot did (its motion log, its pose).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import pytest

import tmmaster
import tmmaster._fleet as fleet_module
from safety_invariant import Issued, check
from tmmaster import Pose, RetryPolicy, Robot, TimeoutPolicy
from tmmaster.sim import Simulator

A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(300, -200, 180, 180, 0, 90)


COMMAND_BLOCK = {"article": 0x0200, "tmflow": 9000}


@pytest.fixture(params=["fleet", "default"])
def fleet(request: pytest.FixtureRequest) -> Iterator[tmmaster.Fleet | None]:
    """The robot's driver: a Fleet of the test's own, or None (the process's default)."""
    own = tmmaster.Fleet() if request.param == "fleet" else None
    yield own
    if own is not None:
        own.close()


def hold_loop_at_command_write(
    robot: Robot, block: int, monkeypatch: pytest.MonkeyPatch
) -> threading.Event:
    """Hold the fleet's loop just before the robot hands it its first command write.

    The loop runs a callback that waits for the returned event (at most 30 s), queued
    ahead of the write: the write waits in the loop's queue, as behind a saturated loop.
    """
    release = threading.Event()
    transport = robot._transport  # the robot's link on its driver
    exchange = transport._exchange
    fleet = transport.fleet

    def held_exchange(
        what: str, function_code: int, address: int, count: int, values: list[int] | None
    ) -> list[int]:
        if function_code == 16 and address == block and not release.is_set():
            loop = fleet._runner.loop  # the driver's own loop: the stall under test
            assert loop is not None
            loop.call_soon_threadsafe(release.wait, 30.0)
        return exchange(what, function_code, address, count, values)

    monkeypatch.setattr(transport, "_exchange", held_exchange)
    return release


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_command_handed_to_a_stalled_loop_is_never_sent_after_the_robot_gave_it_up(
    tm_simulator_factory: Callable[..., Simulator],
    profile: str,
    fleet: tmmaster.Fleet | None,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # How long a thread waits for the loop beyond a request's timeout: short, so that
    # the robot gives the move up within a second of the hold.
    monkeypatch.setattr(fleet_module, "_LOOP_GRACE_S", 0.05)
    sim = tm_simulator_factory(profile)
    robot = Robot(
        "127.0.0.1",
        sim.port,
        profile=profile,
        link=fleet,
        gripper=None,
        timeouts=TimeoutPolicy(request_s=0.1, ack_timeout_s=0.3, in_flight_s=0.2),
        # One attempt: every clean-up request (read-back, withdraw, Stop) is as doomed on
        # the held loop as the command write, and a second one only doubles the wait.
        retry=RetryPolicy(attempts=1),
    )
    issued: list[Issued] = []
    try:
        robot.connect()
        robot.move_to(A, speed=80)
        issued.append(Issued(A, 0.0, 0.0, "done"))
        release = hold_loop_at_command_write(robot, COMMAND_BLOCK[profile], monkeypatch)
        command = Issued(B, time.monotonic())
        issued.append(command)
        try:
            robot.move_to(B, speed=80)
        except tmmaster.TMMasterError as exc:
            command.outcome = type(exc).__name__
        else:
            command.outcome = "done"
        command.ended_at = time.monotonic()
        assert command.gave_up, "the move cannot have finished on a held loop"
        writes = [r for r in sim.request_log if r.is_write and r.address == COMMAND_BLOCK[profile]]
        release.set()
        # Whatever the loop still had queued runs now; give a late write time to land
        # and the robot time to take and start it.
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 10, timeout=5)
    finally:
        robot.close()
    check(issued, sim.motion_log())
    late = [r for r in sim.request_log if r.is_write and r.address == COMMAND_BLOCK[profile]]
    assert late == writes, "the command write went out after the robot gave it up"


def ctrl_c_before_the_loop_begins_the_polls(robot: Robot, monkeypatch: pytest.MonkeyPatch) -> None:
    """Ctrl-C in the thread's first wait for the loop, the loop not having begun the polls.

    The loop is held (as behind other robots' work) until the thread has given the polls
    up, so it begins them and cancels them in one turn, before their first step.
    """
    fleet = robot._transport.fleet
    loop = fleet._runner.loop
    assert loop is not None
    release = threading.Event()
    call_soon = fleet._call_soon

    def soon(callback: Callable[..., object], *args: object) -> bool:
        queued = call_soon(callback, *args)
        job = getattr(callback, "__self__", None)
        if isinstance(job, fleet_module._Job) and callback.__name__ == "cancel":
            release.set()  # the thread gave the polls up: the loop runs on
        return queued

    latch_wait = fleet_module._Latch.wait

    def interrupted(latch: fleet_module._Latch[object], bound: float) -> object:
        monkeypatch.setattr(fleet_module._Latch, "wait", latch_wait)  # once
        raise KeyboardInterrupt

    monkeypatch.setattr(fleet, "_call_soon", soon)
    monkeypatch.setattr(fleet_module._Latch, "wait", interrupted)
    loop.call_soon_threadsafe(release.wait, 30.0)


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_ctrl_c_before_the_loop_began_polling_a_move_stops_the_arm_at_once(
    tm_simulator_factory: Callable[..., Simulator],
    profile: str,
    fleet: tmmaster.Fleet | None,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The thread waits at most this long (beyond the request timeout) for the polls it
    # gave up to be over: a stop that waited it out would come after the move's end.
    monkeypatch.setattr(fleet_module, "_LOOP_GRACE_S", 5.0)
    sim = tm_simulator_factory(profile, time_scale=2)  # the move takes over a second
    robot = Robot("127.0.0.1", sim.port, profile=profile, link=fleet, gripper=None)
    try:
        robot.connect()
        motion = robot.start_move(A, speed=10)
        sim.wait_for(lambda: bool(sim.motion_log()), timeout=5)
        ctrl_c_before_the_loop_begins_the_polls(robot, monkeypatch)
        with pytest.raises(KeyboardInterrupt):
            motion.wait()
        assert motion.stop_delivered is True
        time.sleep(0.2)  # several ticks: a move that was not stopped would go on
        assert len(sim.motion_log()) == 1
        assert not sim.tcp_pose().is_close(A), "the move ran to its end after Ctrl-C"
    finally:
        robot.close()
