"""The fault proxy itself: each fault does what it says, seen from both ends."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import pytest

from fault_proxy import Action, FaultProxy, Rule
from tmmaster import (
    ConnectError,
    ConnectionLostError,
    DeviceBusyError,
    DeviceFailureError,
    ModbusTransport,
    NotModbusError,
    ResponseTimeoutError,
    RetryPolicy,
)
from tmmaster._registers import Table
from tmmaster.sim import Simulator

NO_RETRY = RetryPolicy(attempts=1)


@pytest.fixture
def sim(tm_simulator_factory: object) -> Simulator:
    return tm_simulator_factory("article")  # type: ignore[operator, no-any-return]


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


@pytest.fixture
def link(proxy: FaultProxy) -> Iterator[ModbusTransport]:
    # No test of this link waits for its timeout to expire: a generous one, so a loaded
    # machine (six test workers on two cores) is not taken for a fault.
    with ModbusTransport("127.0.0.1", proxy.port, timeout=2.0, retry=NO_RETRY) as t:
        yield t


@pytest.fixture
def quick_link(proxy: FaultProxy) -> Iterator[ModbusTransport]:
    """Like ``link``, with a 0.2 s answer timeout: for the tests that wait for it to expire."""
    with ModbusTransport("127.0.0.1", proxy.port, timeout=0.2, retry=NO_RETRY) as t:
        yield t


def writes_at(sim: Simulator, address: int) -> int:
    return sum(1 for r in sim.request_log if r.is_write and r.address == address)


def test_requests_pass_through_untouched(sim: Simulator, link: ModbusTransport) -> None:
    assert link.read_block(Table.HOLDING, 0, 4) == [int(sim.field("robot_mode")), 0, 0, 0]
    link.write_block(Table.HOLDING, 0x0210, [1], retry=False)
    assert writes_at(sim, 0x0210) == 1


def test_drop_request_never_reaches_the_slave(
    sim: Simulator, proxy: FaultProxy, quick_link: ModbusTransport
) -> None:
    proxy.add(Rule("drop_request", function_code=16))
    with pytest.raises(ResponseTimeoutError):
        quick_link.write_block(Table.HOLDING, 0x0210, [1], retry=False)
    assert writes_at(sim, 0x0210) == 0


def test_drop_answer_executes_but_the_master_cannot_know(
    sim: Simulator, proxy: FaultProxy, quick_link: ModbusTransport
) -> None:
    proxy.add(Rule("drop_answer", function_code=16))
    with pytest.raises(ResponseTimeoutError):
        quick_link.write_block(Table.HOLDING, 0x0210, [1], retry=False)
    assert writes_at(sim, 0x0210) == 1


def test_close_after_executes_then_breaks_the_link(
    sim: Simulator, proxy: FaultProxy, link: ModbusTransport
) -> None:
    proxy.add(Rule("close_after", function_code=16))
    with pytest.raises(ConnectionLostError):
        link.write_block(Table.HOLDING, 0x0210, [1], retry=False)
    assert writes_at(sim, 0x0210) == 1
    link.read_block(Table.HOLDING, 0, 1)  # the next request reconnects


def test_hold_delivers_late_even_after_the_master_gave_up(
    sim: Simulator, proxy: FaultProxy, quick_link: ModbusTransport
) -> None:
    # Delivered 0.45 s after it was sent: 0.25 s after the master's 0.2 s timeout.
    proxy.add(Rule("hold", function_code=16, delay_s=0.45))
    with pytest.raises(ResponseTimeoutError):
        quick_link.write_block(Table.HOLDING, 0x0210, [1], retry=False)
    quick_link.close()  # the master is gone; the frame is still on its way
    assert writes_at(sim, 0x0210) == 0
    sim.wait_for(lambda: writes_at(sim, 0x0210) == 1, timeout=3)


def test_an_exception_instead_of_forwarding_never_reaches_the_slave(
    sim: Simulator, proxy: FaultProxy, link: ModbusTransport
) -> None:
    proxy.add(Rule("drop_request", function_code=16, exception=6))
    with pytest.raises(DeviceBusyError):
        link.write_block(Table.HOLDING, 0x0210, [1], retry=False)
    assert writes_at(sim, 0x0210) == 0
    assert link.read_block(Table.HOLDING, 0x0210, 1) == [0]  # the link goes on


def test_an_exception_after_forwarding_executes_the_request(
    sim: Simulator, proxy: FaultProxy, link: ModbusTransport
) -> None:
    proxy.add(Rule("drop_answer", function_code=16, exception=4))
    with pytest.raises(DeviceFailureError):
        link.write_block(Table.HOLDING, 0x0210, [1], retry=False)
    assert writes_at(sim, 0x0210) == 1


def test_an_exception_then_the_held_frame_delivers_it_late(
    sim: Simulator, proxy: FaultProxy, link: ModbusTransport
) -> None:
    release = threading.Event()
    proxy.add(Rule("hold", function_code=16, exception=11, release=release))
    with pytest.raises(ResponseTimeoutError, match="exception 11"):  # a gateway's "no answer"
        link.write_block(Table.HOLDING, 0x0210, [1], retry=False)
    assert writes_at(sim, 0x0210) == 0
    release.set()
    sim.wait_for(lambda: writes_at(sim, 0x0210) == 1, timeout=3)


def test_a_write_answered_at_once_is_delivered_late(
    sim: Simulator, proxy: FaultProxy, link: ModbusTransport
) -> None:
    release = threading.Event()
    proxy.add(Rule("hold", function_code=16, address=0x0210, answer_now=True, release=release))
    link.write_block(Table.HOLDING, 0x0210, [1], retry=False)  # answered as done
    assert writes_at(sim, 0x0210) == 0
    release.set()
    sim.wait_for(lambda: writes_at(sim, 0x0210) == 1, timeout=3)


def test_a_duplicated_answer_is_relayed_twice(
    sim: Simulator, proxy: FaultProxy, link: ModbusTransport
) -> None:
    # The second copy carries a transaction id already answered: never taken for the next.
    proxy.add(Rule("duplicate_answer", function_code=3, address=0x0207))
    assert link.read_block(Table.HOLDING, 0x0207, 1) == [0]
    for _ in range(3):
        assert link.read_block(Table.HOLDING, 0, 4) == [int(sim.field("robot_mode")), 0, 0, 0]
    assert proxy.played("duplicate_answer")


def test_delay_answer_executes_at_once_and_answers_late(
    sim: Simulator, proxy: FaultProxy, quick_link: ModbusTransport
) -> None:
    release = threading.Event()
    proxy.add(Rule("delay_answer", function_code=16, address=0x0210, release=release))
    with pytest.raises(ResponseTimeoutError):
        quick_link.write_block(Table.HOLDING, 0x0210, [1], retry=False)
    assert writes_at(sim, 0x0210) == 1  # executed; only its answer waits
    release.set()  # the answer comes now, after the master dropped that connection
    for _ in range(3):  # the late answer (no words) is never taken for a later request's
        assert len(quick_link.read_block(Table.HOLDING, 0, 4)) == 4


@pytest.mark.parametrize(
    ("action", "error"),
    [("foreign_tid", NotModbusError), ("foreign_unit", ResponseTimeoutError)],
)
def test_an_answer_with_a_foreign_header_is_not_taken(
    sim: Simulator,
    proxy: FaultProxy,
    quick_link: ModbusTransport,
    action: Action,
    error: type[Exception],
) -> None:
    proxy.add(Rule(action, function_code=16, address=0x0210))
    with pytest.raises(error):
        quick_link.write_block(Table.HOLDING, 0x0210, [1], retry=False)
    assert writes_at(sim, 0x0210) == 1  # executed; its answer is what is garbled


def test_duplicate_request_executes_it_twice(
    sim: Simulator, proxy: FaultProxy, link: ModbusTransport
) -> None:
    release = threading.Event()
    proxy.add(Rule("duplicate_request", function_code=16, address=0x0210, release=release))
    link.write_block(Table.HOLDING, 0x0210, [1], retry=False)
    assert writes_at(sim, 0x0210) == 1
    release.set()
    sim.wait_for(lambda: writes_at(sim, 0x0210) == 2, timeout=3)
    assert len(link.read_block(Table.HOLDING, 0, 4)) == 4  # the copy's answer is not taken


def test_stale_answer_relays_the_previous_identical_requests_answer(
    proxy: FaultProxy, link: ModbusTransport
) -> None:
    proxy.add(Rule("stale_answer", function_code=3, address=0x0210, times=10))
    assert link.read_block(Table.HOLDING, 0x0210, 1) == [0]
    link.write_block(Table.HOLDING, 0x0210, [1], retry=False)
    assert link.read_block(Table.HOLDING, 0x0210, 1) == [0]  # one read behind
    assert link.read_block(Table.HOLDING, 0x0210, 1) == [1]


def test_delay_holds_back_one_request_only(
    sim: Simulator, proxy: FaultProxy, link: ModbusTransport
) -> None:
    proxy.add(Rule("delay", function_code=3, nth=2, delay_s=0.1))
    link.read_block(Table.HOLDING, 0, 1)
    started = time.monotonic()
    link.read_block(Table.HOLDING, 0, 1)
    assert time.monotonic() - started >= 0.1
    assert [s.action for s in proxy.seen] == ["pass", "delay"]


def test_an_outage_refuses_connections_for_a_while(proxy: FaultProxy) -> None:
    started = time.monotonic()
    proxy.outage(0.3)
    # The proxy accepts and resets at once: depending on who is first, the connect itself
    # fails or the request on the reset link does. Either way nothing gets through.
    with (
        pytest.raises((ConnectError, ConnectionLostError, ResponseTimeoutError)),
        ModbusTransport("127.0.0.1", proxy.port, timeout=0.3, retry=NO_RETRY) as refused,
    ):
        refused.read_block(Table.HOLDING, 0, 1)
    # Past the outage with margin for a loaded machine: 0.2 s after it ended.
    time.sleep(max(0.0, started + 0.5 - time.monotonic()))
    with ModbusTransport("127.0.0.1", proxy.port, timeout=0.3, retry=NO_RETRY) as back:
        back.read_block(Table.HOLDING, 0, 1)
