"""A stand-alone gripper's move that the master gives up on does not go on by itself.

A robot move the master gives up on (a timeout, a stop request, a lost answer) is
stopped (docs/safety.md); a 2FG7's fingers must be too. The check is on what the
simulated gripper did: once its fingers are at rest, they must have stopped short of
the target instead of finishing the move the master no longer follows.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import pytest

from sim_speeds import SUITE_TICK_HZ
from tmmaster import (
    Blog2FG7Gripper,
    ConfigError,
    Gripper,
    GripperLink,
    GripperTimeoutError,
    OnRobot2FG7Gripper,
    PollPolicy,
    RetryPolicy,
    Robot,
    TMMasterError,
    TransportError,
    gripper_profile,
)
from tmmaster.sim import RobotSetup, Simulator, Timing

Factory = Callable[..., Simulator]


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: Factory) -> Factory:
    """The drivers are the subject here, not TCP: simulators in memory."""
    return memory_simulator_factory


def slow_sim(factory: Factory, gripper: str, time_scale: float) -> Simulator:
    """A simulator whose fingers take a good part of a second (wall) to close."""
    return factory(
        "tmflow",
        robot=RobotSetup(gripper=gripper),
        time_scale=time_scale,
        timing=Timing(tick_hz=SUITE_TICK_HZ),
    )


def link(sim: Simulator) -> GripperLink:
    """The gripper's link, polling every 10 ms."""
    assert sim.gripper_port is not None
    retry = RetryPolicy(attempts=5, total_time_s=2.0, initial_backoff_s=0.01, jitter_s=0.0)
    return GripperLink(sim.url, sim.gripper_port, poll_interval_s=0.01, retry=retry)


def closing_on_another_thread(gripper: Gripper) -> tuple[threading.Thread, list[BaseException]]:
    """``gripper.close()`` started on a thread of its own: the thread, and the tmmaster
    errors it ended with (filled when it ends)."""
    errors: list[BaseException] = []

    def close_fingers() -> None:
        try:
            gripper.close()
        except TMMasterError as exc:
            errors.append(exc)

    thread = threading.Thread(target=close_fingers)
    thread.start()
    return thread, errors


def wait_until_moving(sim: Simulator) -> None:
    """Until the simulated fingers move."""
    sim.wait_for(lambda: sim.call(lambda: sim.backend.gripper_state().moving), 5.0)


def at_rest_width(sim: Simulator) -> float:
    """The fingers' width once they are at rest (a few ticks on: a command is taken at one)."""
    ticks = sim.ticks
    sim.wait_for(lambda: sim.ticks >= ticks + 3, 5.0)
    sim.wait_for(lambda: not sim.call(lambda: sim.backend.gripper_state().moving), 5.0)
    return float(sim.call(lambda: sim.backend.gripper_state().width_mm))


#: Each driver's slow move, and the register its command write sets.
#: OnRobot at 1 %: 16 mm/s, 39 -> 1 mm takes 2.4 simulated s, 0.6 s at 4x.
#: blog-2fg7 at 100 mm/s: 39 -> 0 mm takes 0.39 s at 1x, acknowledged at once.
TIME_SCALE = {"onrobot-2fg7": 4.0, "blog-2fg7": 1.0}
COMMAND_FIELD = {"onrobot-2fg7": "command", "blog-2fg7": "control"}


def connected_gripper(sim: Simulator, kind: str) -> Blog2FG7Gripper | OnRobot2FG7Gripper:
    """The stand-alone driver ``kind`` on ``sim``'s gripper, slow, connected."""
    profile = gripper_profile(kind)
    gripper: Blog2FG7Gripper | OnRobot2FG7Gripper = (
        OnRobot2FG7Gripper(profile, link(sim), speed_percent=1)
        if kind == "onrobot-2fg7"
        else Blog2FG7Gripper(profile, link(sim))
    )
    gripper.connect()
    return gripper


@pytest.mark.parametrize("kind", ["onrobot-2fg7", "blog-2fg7"])
def test_a_move_given_up_at_its_timeout_is_stopped(
    tm_simulator_factory: Factory, kind: str
) -> None:
    # Given up after 0.1 s, the move taken (a blog-2fg7's acknowledged).
    sim = slow_sim(tm_simulator_factory, kind, TIME_SCALE[kind])
    gripper = connected_gripper(sim, kind)
    try:
        with pytest.raises(GripperTimeoutError):
            gripper.close(timeout_s=0.1)
    finally:
        gripper.disconnect()
    assert at_rest_width(sim) > 15.0  # stopped, not closed to 1 mm


@pytest.mark.parametrize("kind", ["onrobot-2fg7", "blog-2fg7"])
def test_a_move_whose_answer_was_lost_is_stopped(tm_simulator_factory: Factory, kind: str) -> None:
    sim = slow_sim(tm_simulator_factory, kind, TIME_SCALE[kind])
    gripper = connected_gripper(sim, kind)
    command = gripper.profile.field(COMMAND_FIELD[kind]).address
    # The device takes the command, then the link is cut before its answer.
    sim.inject(f"drop_connections:on_write_to={command},lose=answer")
    try:
        with pytest.raises(TransportError):
            gripper.close()
    finally:
        gripper.disconnect()
    assert at_rest_width(sim) > 15.0


def test_robot_close_on_another_thread_stops_a_stand_alone_gripper_move() -> None:
    # close() ends the gripper's wait and closes its link: the move it gave up must not
    # go on to 1 mm, whichever of the two threads gets to the link first. Over loopback
    # TCP, where close() closes the gripper's link before the waiting thread gets to it.
    timing = Timing(tick_hz=SUITE_TICK_HZ)
    sim = Simulator(
        "tmflow", robot=RobotSetup(gripper="onrobot-2fg7"), time_scale=4.0, timing=timing
    )
    sim.start()
    try:
        assert sim.gripper_port is not None
        retry = RetryPolicy(attempts=5, total_time_s=2.0, initial_backoff_s=0.01, jitter_s=0.0)
        device_link = GripperLink("127.0.0.1", sim.gripper_port, poll_interval_s=0.01, retry=retry)
        gripper = OnRobot2FG7Gripper(gripper_profile("onrobot-2fg7"), device_link, speed_percent=1)
        robot = Robot("127.0.0.1", sim.port, gripper=gripper, polling=PollPolicy(interval_s=0.01))
        robot.connect()
        thread, errors = closing_on_another_thread(gripper)
        try:
            wait_until_moving(sim)
        finally:
            robot.close()
            thread.join(5.0)
        assert errors  # the wait was given up
        assert at_rest_width(sim) > 15.0
    finally:
        sim.close()


def test_a_stop_that_could_not_be_delivered_is_written_again_at_disconnect(
    tm_simulator_factory: Factory,
) -> None:
    # One attempt per write: the stop after the timeout is lost (its connection cut
    # before the device got it), so the move is still under way; disconnect() (what
    # Robot.close() calls) must write the stop again rather than forget the move.
    sim = slow_sim(tm_simulator_factory, "onrobot-2fg7", 4.0)
    assert sim.gripper_port is not None
    once = GripperLink(
        sim.url, sim.gripper_port, poll_interval_s=0.01, retry=RetryPolicy(attempts=1)
    )
    gripper = OnRobot2FG7Gripper(gripper_profile("onrobot-2fg7"), once, speed_percent=1)
    gripper.connect()
    command = gripper.profile.field("command").address
    # The 2nd write covering the command register (the stop) is lost; the 1st runs.
    sim.inject(f"drop_connections:on_write_to={command},lose=request,after_requests=2")
    try:
        with pytest.raises(GripperTimeoutError):
            gripper.close(timeout_s=0.1)
    finally:
        gripper.disconnect()
    assert at_rest_width(sim) > 15.0


def test_robot_close_bounds_the_gripper_stop_it_cannot_deliver(
    tm_simulator_factory: Factory,
) -> None:
    # Every write to the command register after the move's is lost, so the stop that
    # close() owes the gripper cannot be delivered: close(timeout_s=0.3) must give it up
    # at its deadline (not after the gripper link's 4 s of retries) and say so (False).
    sim = slow_sim(tm_simulator_factory, "onrobot-2fg7", 1.0)
    assert sim.gripper_port is not None
    patient = RetryPolicy(attempts=100, total_time_s=4.0, initial_backoff_s=0.05, jitter_s=0.0)
    device_link = GripperLink(sim.url, sim.gripper_port, poll_interval_s=0.01, retry=patient)
    gripper = OnRobot2FG7Gripper(gripper_profile("onrobot-2fg7"), device_link, speed_percent=1)
    robot = Robot(sim.url, gripper=gripper, polling=PollPolicy(interval_s=0.01))
    robot.connect()
    thread, errors = closing_on_another_thread(gripper)
    try:
        wait_until_moving(sim)
        command = gripper.profile.field("command").address
        sim.inject(f"drop_connections:on_write_to={command},lose=request,once=false")
        started = time.monotonic()
        confirmed = robot.close(timeout_s=0.3)
        took = time.monotonic() - started
    finally:
        robot.close()
        thread.join(5.0)
    assert confirmed is False  # the gripper's stop was not delivered
    assert took < 2.0, f"close(timeout_s=0.3) took {took:.2f} s"  # the bound is the feature
    assert errors  # the move was given up


@pytest.mark.parametrize("kind", ["onrobot-2fg7", "blog-2fg7"])
def test_a_second_command_on_another_thread_is_refused_unsent(
    tm_simulator_factory: Factory, kind: str
) -> None:
    # Thread A closes the fingers; a command from another thread meanwhile would replace
    # A's (and A's stop could halt it): it is refused before any write, and A's move ends.
    sim = slow_sim(tm_simulator_factory, kind, TIME_SCALE[kind])
    gripper = connected_gripper(sim, kind)
    thread, errors = closing_on_another_thread(gripper)
    try:
        wait_until_moving(sim)
        writes = gripper.transport.stats.requests_by_function.get(16, 0)  # FC16
        with pytest.raises(ConfigError, match=kind):
            gripper.open()
        assert gripper.transport.stats.requests_by_function.get(16, 0) == writes  # unsent
    finally:
        thread.join(5.0)
        gripper.disconnect()
    assert errors == []  # thread A's close was neither replaced nor stopped
    assert at_rest_width(sim) < 2.0
