"""One robot named two ways ("127.0.0.1", "localhost"): the process's debts are the robot's.

Three registries keep, for the whole process, what one ``Robot`` of it left unsettled
on a robot, so that the next ``Robot`` on that robot honours it (docs/safety.md): an
article Stop the link could not carry (``_command._STOPS_OWED``), a level output's
write left unanswered whose frame may still land (``_io._WATCHED``), a stand-alone
gripper's stop frame left unanswered (``_gripper._STOP_DOUBTS``). They were keyed by
the host *as the caller spelled it*, so a program that connects its second ``Robot``
as "localhost" after its first as "127.0.0.1" (a config file and a CLI flag, a retry
with the other spelling) found no debt, and the robot ran on or was undone unseen.

Here the second Robot names the robot by the other spelling. What must hold, judged on
the simulator: the article move the first Robot gave up is stopped (the arm does not
run on to its target); the gripper register the second Robot closed stays closed when
the first Robot's late open lands. A robot is who answers at an address: the key is
the address the link reached (loopback only here).
"""

from __future__ import annotations

import socket
import threading
from collections.abc import Callable, Iterator

import pytest

import tmmaster
from fault_proxy import FaultProxy, Rule
from safety_invariant import at_rest
from test_hunt6_new_robot_output import Release, executed, released  # noqa: F401 (a fixture)
from tmmaster import (
    ModbusTransport,
    PollPolicy,
    Pose,
    RegisterGripper,
    RetryPolicy,
    Robot,
    TimeoutPolicy,
)
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

START = Pose(300, -200, 200, 180, 0, 90)
FAR = Pose(300, 250, 200, 180, 0, 90)
OUTAGE_S = 1.5
RETRY = RetryPolicy(attempts=2, total_time_s=0.3, initial_backoff_s=0.05, jitter_s=0)
#: The article map's gripper register (0 open, 1 close).
GRIPPER_REGISTER = 0x0210


@pytest.fixture
def sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory("article", time_scale=2.0)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


def article_robot(host: str, port: int, retry: RetryPolicy = RETRY, **options: object) -> Robot:
    return Robot(
        host,
        port,
        profile="article",
        polling=PollPolicy(interval_s=0.02),
        retry=retry,
        **{"timeouts": TimeoutPolicy(request_s=0.2), **options},  # type: ignore[arg-type]
    )


def test_a_stop_owed_under_one_host_name_is_delivered_under_the_other(
    sim: Simulator, proxy: FaultProxy
) -> None:
    first = article_robot("127.0.0.1", proxy.port).connect()
    try:
        first.wait_until_ready(timeout_s=5)
        first.move_to(START, speed=100)
        motion = first.start_move(FAR, speed=7)  # about 3.5 s to go at 2x
        sim.wait_for(lambda: sim.tcp_pose().y > START.y + 10, timeout=20)
        proxy.outage(OUTAGE_S)
        with pytest.raises(tmmaster.TransportError):
            motion.wait()  # given up: the link is gone, and with it the Stop
    finally:
        closed = first.close(timeout_s=0.3)
    if motion.stop_delivered is not False or closed is not False:
        raise RuntimeError(f"set-up: the Stop was delivered ({motion.stop_delivered}, {closed})")
    patient = RetryPolicy(attempts=20, total_time_s=OUTAGE_S + 3, initial_backoff_s=0.05)
    with article_robot("localhost", proxy.port, patient) as second:
        second.status()
        if not sim.field("motion_status"):
            raise RuntimeError("set-up: the move was over before the new Robot connected")
        sim.wait_for(at_rest(sim), timeout=15, interval=0.1)
    rest = sim.tcp_pose()
    assert rest.distance_to(FAR) > 50, f"the given-up move ran on to {rest}"


def test_a_late_gripper_frame_under_one_host_name_is_undone_under_the_other(
    tm_simulator_factory: Factory,
    released: Release,  # noqa: F811 (the fixture imported above)
) -> None:
    # tests/test_hunt6_new_robot_output.py, the second Robot named "localhost".
    sim = tm_simulator_factory("article")
    watch = RetryPolicy(attempts=4, total_time_s=3.0, initial_backoff_s=0.01, jitter_s=0)
    with FaultProxy(sim.port) as proxy:
        release = threading.Event()
        held = proxy.add(Rule("hold", address=GRIPPER_REGISTER, release=release))
        sim.clear_request_log()
        try:
            with article_robot(
                "127.0.0.1", proxy.port, watch, gripper=RegisterGripper(settle_s=0.1)
            ) as first:
                first.wait_until_ready(timeout_s=5)
                first.gripper.open()  # the first frame held; retried, answered: open
                assert held.times == 0
            # The held open lands once the simulator executed the new Robot's close.
            released(lambda: 1 in executed(sim, (6, 16), GRIPPER_REGISTER), release)
            with article_robot(
                "localhost", proxy.port, watch, gripper=RegisterGripper(settle_s=0.1)
            ) as second:
                second.wait_until_ready(timeout_s=5)
                second.gripper.close()
                proxy.wait_held()
                sim.wait_for(lambda: executed(sim, (6, 16), GRIPPER_REGISTER).count(0) >= 2, 3)
                writes = executed(sim, (6, 16), GRIPPER_REGISTER)
                assert writes[-1] == 1, f"the fingers were left open under the part: {writes}"
                assert sim.field("gripper_command") == 1
        finally:
            release.set()


def test_every_spelling_of_one_robot_is_one_key_and_other_robots_are_not() -> None:
    def key(host: str, port: int = 502, device_id: int = 1) -> tuple[str, int, int]:
        link = ModbusTransport(host, port, device_id=device_id, timeout=0.1)
        return link.endpoint

    assert key("localhost") == key("127.0.0.1") == key("::1") == key("127.0.0.1")
    assert key("127.0.0.1", 503) != key("localhost")
    assert key("127.0.0.1", device_id=2) != key("localhost")
    assert key("192.0.2.7") != key("localhost")
    assert key("robot.invalid") == ("robot.invalid", 502, 1)  # unresolved: its own key


def test_a_name_with_several_addresses_is_one_key_whatever_order_they_come_in(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A resolver may rotate a name's addresses (round-robin DNS), and give IPv6 first.
    v4 = [(socket.AF_INET, socket.SOCK_STREAM, 6, "", (a, 502)) for a in ("10.0.0.7", "10.0.0.3")]
    v6 = [(socket.AF_INET6, socket.SOCK_STREAM, 6, "", ("fd00::7", 502, 0, 0))]
    keys = set()
    for answer in (v6 + v4, v4[::-1] + v6, v4):
        monkeypatch.setattr(socket, "getaddrinfo", lambda *_a, answer=answer, **_k: answer)
        keys.add(ModbusTransport("tm5.lan", 502, device_id=1, timeout=0.1).endpoint)
    assert keys == {("10.0.0.3", 502, 1)}
