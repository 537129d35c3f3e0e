"""``wait_until_at_rest()`` under a lagging status report, an e-stop, a link drop, a stop
request from another thread, and a timeout below the 0.5 s stall floor; both profiles,
and ``AsyncRobot``'s.

What must hold (docs/safety.md, "A stop is delivered, not waited out"): the wait answers
"at rest" only for an arm that is still, judged on the simulated arm (it does not move
after the answer), never on what the master read; anything else ends in an error (a
timeout, the stop request, the lost link), never in a rest.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import wait_braked
from test_fleet import ticks_pass
from tmmaster import (
    MotionTimeoutError,
    PollPolicy,
    Pose,
    RetryPolicy,
    Robot,
    RobotStatus,
    StopRequestedError,
    TimeoutPolicy,
    TransportError,
    aio,
)
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
PROFILES = ["tmflow", "article"]
#: Both in the article's register range (+/-327.67 mm), the PTP between them too.
A = Pose(250, -150, 200, 180, 0, 90)
FAR = Pose(250, 150, 200, 180, 0, 90)
#: Techman's Joint Speed J1..J6 (TMflow 2.24 appendix C p. 317), read by the wait only.
JOINT_SPEED = 7949
#: Simulator ticks after the answer that the arm must stand still for.
STILL_TICKS = 10


def robot_at(port: int, profile: str) -> Robot:
    return Robot(
        "127.0.0.1",
        port,
        profile=profile,
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(request_s=0.3),
        retry=RetryPolicy(attempts=2, total_time_s=0.3),
    )


def stopped_mid_move(sim: Simulator, robot: Robot) -> None:
    """Start a fast move to FAR and press Stop well under way: the arm brakes."""
    robot.move_to(A, speed=100)
    robot.start_move(FAR, speed=100)
    sim.wait_for(lambda: sim.tcp_pose().distance_to(A) > 60, timeout=5.0)
    robot.stop()


def assert_still_after(sim: Simulator, status: RobotStatus) -> None:
    """The arm stands where it was when the wait answered, and stays there."""
    answered = sim.tcp_pose()
    ticks_pass(sim, STILL_TICKS)
    assert sim.tcp_pose() == answered, "the arm moved after the wait said at rest"
    assert status.pose.is_close(answered, mm=0.5, deg=0.5)


@pytest.fixture
def proxied(tm_simulator_factory: SimFactory) -> Iterator[Callable[[str], tuple]]:
    made: list[FaultProxy] = []

    def make(profile: str) -> tuple[Simulator, FaultProxy]:
        sim = tm_simulator_factory(profile, time_scale=5.0)
        made.append(proxy := FaultProxy(sim.port))
        return sim, proxy

    yield make
    for proxy in made:
        proxy.close()


@pytest.mark.parametrize("profile", PROFILES)
def test_a_status_report_one_read_behind_never_answers_rest_while_the_arm_brakes(
    proxied: Callable[[str], tuple[Simulator, FaultProxy]], profile: str
) -> None:
    # A gateway serving a cache one poll behind: every read (the status, the pose, the
    # joint speeds) gets the answer the previous identical read got.
    sim, proxy = proxied(profile)
    with robot_at(proxy.port, profile) as robot:
        stopped_mid_move(sim, robot)
        for code in (1, 2, 3, 4):
            proxy.add(Rule("stale_answer", function_code=code, times=10_000))
        status = robot.wait_until_at_rest(timeout_s=10)
        assert proxy.played("stale_answer")
        assert_still_after(sim, status)


def test_a_sample_served_twice_answers_rest_with_the_pose_the_arm_rests_at(
    tm_simulator_factory: SimFactory,
) -> None:
    # A gateway whose cache refreshes slower than the master reads serves one sample
    # twice; the arm comes to rest between the wait's pose read and its joint-speed read
    # (held here until the braking arm stands). "Still" rests on the joint speeds then,
    # and the status answered must be read after them: where the arm rests, not where it
    # passed before they were read.
    sim = tm_simulator_factory("tmflow", time_scale=0.25)  # it brakes about 1 s, 100 mm
    proxy, release = FaultProxy(sim.port), threading.Event()

    def release_once_the_arm_rests() -> None:
        sim.wait_for(lambda: proxy.played("hold"), timeout=10.0)
        wait_braked(sim, ticks=5)
        release.set()

    try:
        # request_s: the held read is answered, not timed out.
        with Robot("127.0.0.1", proxy.port, timeouts=TimeoutPolicy(request_s=10)) as robot:
            stopped_mid_move(sim, robot)
            proxy.add(Rule("hold", function_code=4, address=JOINT_SPEED, release=release))
            for code in (1, 2, 3, 4):
                proxy.add(Rule("stale_answer", function_code=code, times=10_000))
            helper = threading.Thread(target=release_once_the_arm_rests)
            helper.start()
            status = robot.wait_until_at_rest(timeout_s=10)
            helper.join(10)
            assert_still_after(sim, status)
    finally:
        release.set()
        proxy.close()


@pytest.mark.parametrize("profile", PROFILES)
def test_an_estop_while_the_arm_brakes_answers_rest_only_once_it_is_still(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, time_scale=5.0)
    with robot_at(sim.port, profile) as robot:
        robot.move_to(A, speed=100)
        robot.start_move(FAR, speed=100)
        sim.wait_for(lambda: sim.tcp_pose().distance_to(A) > 60, timeout=5.0)
        sim.press_estop()
        status = robot.wait_until_at_rest(timeout_s=10)
        assert status.estop or status.error  # the article's slave reports it as an error
        assert_still_after(sim, status)


@pytest.mark.parametrize("profile", PROFILES)
def test_a_link_lost_during_the_wait_ends_it_in_an_error_not_a_rest(
    proxied: Callable[[str], tuple[Simulator, FaultProxy]],
    profile: str,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    sim, proxy = proxied(profile)
    with robot_at(proxy.port, profile) as robot:
        stopped_mid_move(sim, robot)
        real, reads = robot.status, []

        def status_then_outage() -> RobotStatus:
            reads.append(1)
            if len(reads) == 2:  # the wait's second read: the link goes down first
                proxy.outage(60.0)
            return real()

        monkeypatch.setattr(robot, "status", status_then_outage)
        with pytest.raises(TransportError):
            robot.wait_until_at_rest(timeout_s=10)
        assert len(reads) == 2
        monkeypatch.undo()
        proxy.outage(0.0)  # back, for the close


@pytest.mark.parametrize("profile", PROFILES)
def test_a_stop_request_from_another_thread_ends_the_wait(
    tm_simulator_factory: SimFactory, profile: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    sim = tm_simulator_factory(profile, time_scale=5.0)
    with robot_at(sim.port, profile) as robot:
        stopped_mid_move(sim, robot)
        real, reads = robot.status, []

        def status_then_interrupt() -> RobotStatus:
            reads.append(1)
            if len(reads) == 1:  # during the wait: another thread asks to stop
                other = threading.Thread(target=robot.interrupt)
                other.start()
                other.join(5)
            return real()

        monkeypatch.setattr(robot, "status", status_then_interrupt)
        with pytest.raises(StopRequestedError):
            robot.wait_until_at_rest(timeout_s=10)
        assert len(reads) == 1  # no read after the request
        monkeypatch.undo()
        robot.clear_stop_request()
        assert_still_after(sim, robot.wait_until_at_rest(timeout_s=10))


@pytest.mark.parametrize("profile", PROFILES)
@pytest.mark.parametrize("timeout_s", [0.01, 0.2, 0.49])
def test_a_timeout_below_the_floor_answers_rest_only_for_a_still_arm(
    tm_simulator_factory: SimFactory, profile: str, timeout_s: float
) -> None:
    sim = tm_simulator_factory(profile, time_scale=5.0)
    with robot_at(sim.port, profile) as robot:
        stopped_mid_move(sim, robot)
        try:
            status = robot.wait_until_at_rest(timeout_s=timeout_s)
        except MotionTimeoutError:
            return  # the safe answer for an arm that braked during the wait
        assert_still_after(sim, status)


@pytest.mark.parametrize("profile", PROFILES)
def test_the_async_wait_answers_rest_only_once_still_and_a_cancel_ends_it(
    tm_simulator_factory: SimFactory, profile: str
) -> None:
    sim = tm_simulator_factory(profile, time_scale=5.0)

    async def scenario() -> None:
        async with aio.connect(
            sim.url, profile=profile, polling=PollPolicy(interval_s=0.01)
        ) as robot:
            await robot.move_to(A, speed=100)
            await robot.start_move(FAR, speed=100)
            sim.wait_for(lambda: sim.tcp_pose().distance_to(A) > 60, timeout=5.0)
            await robot.stop()
            with pytest.raises(TimeoutError):  # cancelled by the timeout: no rest claimed
                await asyncio.wait_for(robot.wait_until_at_rest(timeout_s=10), 0.05)
            status = await robot.wait_until_at_rest(timeout_s=10)
            assert_still_after(sim, status)

    asyncio.run(scenario())
