"""The in-memory transport: the simulator's request path (gate, log, faults) without sockets."""

from __future__ import annotations

import socket
from collections.abc import Iterator
from typing import Any

import pytest

import tmmaster
from tmmaster import (
    ConnectError,
    ConnectionLostError,
    PollPolicy,
    ResponseTimeoutError,
    RetryPolicy,
    Robot,
    Table,
)
from tmmaster.sim import MemoryTransport, RobotSetup, Simulator

ONCE = RetryPolicy(attempts=1)


@pytest.fixture
def sim() -> Iterator[Simulator]:
    with Simulator("article", listen=False, time_scale=20) as s:
        yield s


def test_a_memory_robot_is_a_transport_and_logs_like_tcp(sim: Simulator) -> None:
    with tmmaster.connect(sim.url, profile="article", polling=PollPolicy(interval_s=0.01)) as robot:
        assert isinstance(robot._transport, tmmaster.Transport)
        assert isinstance(robot._transport, MemoryTransport)
        before = robot.stats.requests
        sim.clear_request_log()
        robot.status()
        (record,) = sim.request_log
        assert (record.server, record.function_code, record.values) == ("robot", 3, None)
        robot.move_to(tmmaster.Pose(300, -200, 200, 180, 0, 90), speed=30)
    assert sim.tcp_pose().is_close(tmmaster.Pose(300, -200, 200, 180, 0, 90), mm=0.01)
    assert robot.stats.requests == before + len(sim.request_log)
    assert robot.stats.bytes_sent > 0


def test_a_sim_without_listener_opens_no_socket_and_unknown_names_are_refused() -> None:
    with Simulator("article", listen=False) as sim:
        assert sim.port == 0
        url = sim.url
    with pytest.raises(ConnectError, match="no in-process endpoint"):
        tmmaster.Robot(url, profile="article")


def test_a_lost_answer_applies_the_write_then_raises_connection_lost(sim: Simulator) -> None:
    with MemoryTransport(sim, retry=ONCE) as link:
        sim.inject("drop_connections:lose=answer")
        with pytest.raises(ConnectionLostError):
            link.write_block(Table.HOLDING, 0x0200, [0], retry=False)
        assert sim.request_log[-1].refused == 0  # it arrived and was executed
        link.connect()  # a new link works again
        assert link.stats.reconnects == 1


def test_a_lost_request_is_never_executed(sim: Simulator) -> None:
    with MemoryTransport(sim, retry=ONCE) as link:
        sim.inject("drop_connections:lose=request")
        with pytest.raises(ConnectionLostError):
            link.write_block(Table.HOLDING, 0x0200, [0], retry=False)
        assert sim.request_log[-1].refused != 0


def test_a_slow_answer_times_out(sim: Simulator) -> None:
    with MemoryTransport(sim, retry=ONCE, timeout=0.05) as link:
        sim.inject("slow_responses:delay_s=0.1")
        with pytest.raises(ResponseTimeoutError):
            link.read_block(Table.HOLDING, 0x0200, 1)


def test_stop_listening_refuses_connections_for_a_while(sim: Simulator) -> None:
    with MemoryTransport(sim, retry=ONCE) as link:
        # 0.2 s of outage (wall time) for the refused read and connect made right after.
        sim.inject("stop_listening:after_requests=1,duration_s=0.2")
        link.read_block(Table.HOLDING, 0x0200, 1)  # answered, then the outage starts
        sim.wait_for(lambda: not sim.device_server().listening, timeout=2)
        with pytest.raises(ConnectionLostError):
            link.read_block(Table.HOLDING, 0x0200, 1)
        with pytest.raises(ConnectError):
            link.connect()
        sim.wait_for(lambda: sim.device_server().listening, timeout=2)
        link.connect()
        assert link.read_block(Table.HOLDING, 0x0200, 1) == [0]


def test_the_onrobot_gripper_serves_one_memory_link_at_a_time() -> None:
    sim = Simulator("article", listen=False, robot=RobotSetup(gripper="onrobot-2fg7"))
    with (
        sim,
        MemoryTransport(sim, "gripper", device_id=65, retry=ONCE) as first,
        MemoryTransport(sim, "gripper", device_id=65, retry=ONCE) as second,
    ):
        assert first.read_block(Table.HOLDING, 259, 1)
        with pytest.raises(ConnectionLostError):
            second.read_block(Table.HOLDING, 259, 1)


def test_a_second_running_simulator_of_one_name_is_refused_and_close_frees_it() -> None:
    # Replacing the first one's registration would send its robots to the second.
    with Simulator("article", listen=False, name="cell-a") as first:
        second = Simulator("article", listen=False, name="cell-a")
        with pytest.raises(tmmaster.ConfigError, match="sim://cell-a"):
            second.start()
        assert not second.running  # nothing started
        second.close()  # frees nothing: the name still leads to the first one
        with tmmaster.connect(
            first.url, profile="article", polling=PollPolicy(interval_s=0.01)
        ) as robot:
            robot.status()
        assert first.request_log  # the robot talked to the first simulator
    # Closed, the name is free for a new simulator.
    with Simulator("article", listen=False, name="cell-a") as again:
        assert again.url == "sim://cell-a"
        with tmmaster.connect(
            again.url, profile="article", polling=PollPolicy(interval_s=0.01)
        ) as robot:
            robot.status()


def test_an_in_process_simulator_is_never_given_to_the_name_resolver(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # What the process owes a robot is keyed by Transport.endpoint, which resolves a
    # host name; a sim:// link is its own key, its URL never sent to a DNS server.
    asked: list[object] = []
    resolve = socket.getaddrinfo

    def spy(host: object, *args: Any, **kwargs: Any) -> Any:
        asked.append(host)
        return resolve(host, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(socket, "getaddrinfo", spy)
    with (
        Simulator("article", listen=False, time_scale=20) as sim,
        Robot(sim.url, profile="article") as robot,
    ):
        robot.status()
        assert robot._transport.endpoint == (sim.url, robot._transport.port, 1)
    assert not [host for host in asked if "sim" in str(host)]
