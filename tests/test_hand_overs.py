"""What a robot's thread hands to the driver's loop: one hand-over per read, one per wait.

Each hand-over wakes two threads (the loop, then the caller), the largest share of a
request's CPU on the driver (docs/performance.md, the hot path).
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pymodbus.framer import FramerSocket
from pymodbus.pdu import DecodePDU, ModbusPDU
from pymodbus.pdu.bit_message import (
    ReadCoilsRequest,
    ReadDiscreteInputsRequest,
    WriteMultipleCoilsRequest,
    WriteSingleCoilRequest,
)
from pymodbus.pdu.register_message import (
    ReadHoldingRegistersRequest,
    ReadInputRegistersRequest,
    WriteMultipleRegistersRequest,
)

import tmmaster._fleet as fleet_module
import tmmaster._robot as robot_module
from scripted_slave import SlaveThread, answer_with, registers
from tmmaster import ModbusTransport, PollPolicy, Pose, Robot, RobotStatus
from tmmaster._fleet import LoopTransport
from tmmaster._registers import RegisterField, Role, Table
from tmmaster._retry import RetryPolicy
from tmmaster._transport import common_answer, request_frame
from tmmaster.sim import Simulator

A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(300, -200, 180, 180, 0, 90)


def refuse_per_request_hand_over(*_args: object) -> list[int]:
    raise AssertionError("a request was handed to the loop on its own")


def test_a_read_of_one_block_is_handed_over_as_a_whole_read() -> None:
    # The same path as a read of several blocks: no per-request hand-over, counted once.
    field = RegisterField(
        name="only", role=Role.STATUS, table=Table.HOLDING, address=4, type="uint16"
    )
    policy = RetryPolicy(attempts=1, total_time_s=5, initial_backoff_s=0.01, max_backoff_s=0.01)
    with (
        SlaveThread([answer_with(registers(9))]) as slave,
        ModbusTransport("127.0.0.1", slave.port, timeout=2.0, retry=policy, name="s") as link,
        pytest.MonkeyPatch.context() as patch,
    ):
        patch.setattr(LoopTransport, "_exchange", refuse_per_request_hand_over)
        assert link.read_fields([field]) == {"only": 9}
        assert link.stats.requests == 1
        assert [pdu[:3] for pdu in slave.server.requests] == [bytes([3, 0, 4])]


@pytest.mark.parametrize("profile", ["article", "tmflow"])
def test_a_move_hands_the_loop_one_read_one_write_and_its_wait(
    tm_simulator_factory: Callable[..., Simulator],
    monkeypatch: pytest.MonkeyPatch,
    profile: str,
) -> None:
    # The read before the command (what later moves reuse of the last poll aside), the
    # write, and the wait: the loop notes the acknowledgement itself and polls on to the
    # end (tmflow: with the final pose), so the robot's thread is woken once per wait.
    handed: list[str] = []
    hand_over = LoopTransport._hand_over
    follow = fleet_module.FleetMember.follow

    def counted_hand_over(link: Any, what: str, *args: Any) -> Any:
        handed.append(what.split()[0])  # "read ..." / "write ..."
        return hand_over(link, what, *args)

    def counted_follow(member: fleet_module.FleetMember, state: Any) -> Any:
        observation = follow(member, state)
        handed.append("handed back" if observation is None else "observation")
        return observation

    monkeypatch.setattr(LoopTransport, "_hand_over", counted_hand_over)
    monkeypatch.setattr(fleet_module.FleetMember, "follow", counted_follow)
    # The count, not the timing: on a starved machine the next move's checks may come
    # more than one robot tick (REUSE_DONE_READ_S) after the done poll, and read again
    # (one read more, or two on tmflow). How often reuse happens is a benchmark's figure.
    monkeypatch.setattr(robot_module, "REUSE_DONE_READ_S", 60.0)
    sim = tm_simulator_factory(profile, time_scale=2)  # the acknowledgement ticks before the end
    with Robot(
        "127.0.0.1", sim.port, profile=profile, gripper=None, polling=PollPolicy(interval_s=0.01)
    ) as robot:
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(A, speed=60)  # the first move reads what later ones reuse
        for target in (B, A, B):
            handed.clear()
            motion = robot.move_to(target, speed=60)
            assert motion.done
            assert motion.last_pose is not None
            assert motion.last_pose.is_close(target, mm=0.5)
            assert sorted(handed) == ["observation", "read", "write"]
        assert isinstance(robot.status(), RobotStatus)


def framed(tid: int, unit: int, pdu: bytes, *, length: int | None = None) -> bytes:
    """A Modbus TCP frame: the MBAP header (``length`` as given, or the true one), the PDU."""
    size = len(pdu) + 1 if length is None else length
    return struct.pack(">HHHB", tid, 0, size, unit) + pdu


def answers() -> st.SearchStrategy[bytes]:
    """Answers to reads (FC 1-4) and FC16 writes, well-formed or not quite."""
    reads = st.builds(
        lambda fc, data, tid, unit: framed(tid, unit, bytes([fc, len(data)]) + data),
        st.integers(1, 4),
        st.binary(max_size=40),
        st.integers(0, 0xFFFF),
        st.integers(0, 255),
    )
    writes = st.builds(
        lambda address, count, tid: framed(tid, 1, struct.pack(">BHH", 16, address, count)),
        st.integers(0, 0xFFFF),
        st.integers(0, 0xFFFF),
        st.integers(0, 0xFFFF),
    )
    odd = st.builds(
        lambda fc, data, length: framed(7, 1, bytes([fc, len(data)]) + data, length=length),
        st.integers(1, 16),
        st.binary(max_size=12),
        st.integers(2, 20),
    )
    return st.one_of(reads, writes, odd)


@given(answer=answers(), tail=st.binary(max_size=3))
def test_an_answer_decoded_here_is_the_one_pymodbus_decodes(answer: bytes, tail: bytes) -> None:
    # The common answers (reads, FC16 writes) are decoded without pymodbus' decoder; what
    # they decode to is what pymodbus' framer gives, and anything else is left to it.
    buffer = answer + tail
    ours = common_answer(buffer, 0)
    if ours is None:
        return
    size, pdu = FramerSocket(DecodePDU(is_server=False)).handleFrame(buffer, 0, 0)
    assert pdu is not None
    assert ours[:2] == (size, pdu.dev_id)
    assert ours[2][:2] == (pdu.transaction_id, pdu.function_code)
    fc = pdu.function_code
    words = [int(b) for b in pdu.bits] if fc <= 2 else list(pdu.registers) if fc <= 4 else []
    assert ours[2][2] == words


def requests() -> st.SearchStrategy[tuple[int, int, int, list[int] | None]]:
    """(function code, address, count, values) of every request a link sends."""
    address = st.integers(0, 0xFFFF)
    reads = st.tuples(st.integers(1, 4), address, st.integers(1, 125), st.none())
    registers = st.lists(st.integers(0, 0xFFFF), min_size=1, max_size=123)
    coils = st.lists(st.integers(0, 1), min_size=2, max_size=40)
    return st.one_of(
        reads,
        st.builds(lambda a, w: (16, a, len(w), w), address, registers),
        st.builds(lambda a, w: (15, a, len(w), w), address, coils),
        st.builds(lambda a, b: (5, a, 1, [b]), address, st.integers(0, 1)),
    )


PYMODBUS_REQUESTS: dict[int, Callable[..., ModbusPDU]] = {
    1: ReadCoilsRequest,
    2: ReadDiscreteInputsRequest,
    3: ReadHoldingRegistersRequest,
    4: ReadInputRegistersRequest,
    5: lambda words, **kw: WriteSingleCoilRequest(bits=[bool(words[0])], **kw),
    15: lambda words, **kw: WriteMultipleCoilsRequest(bits=[bool(b) for b in words], **kw),
    16: lambda words, **kw: WriteMultipleRegistersRequest(registers=words, **kw),
}


@given(request=requests(), tid=st.integers(1, 0xFFFF), unit=st.integers(0, 255))
def test_a_request_frame_built_here_is_the_one_pymodbus_builds(
    request: tuple[int, int, int, list[int] | None], tid: int, unit: int
) -> None:
    fc, address, count, values = request
    ids = {"address": address, "dev_id": unit, "transaction_id": tid}
    make = PYMODBUS_REQUESTS[fc]
    pdu = make(count=count, **ids) if values is None else make(values, **ids)
    expected = FramerSocket(DecodePDU(is_server=False)).buildFrame(pdu)
    assert request_frame(fc, address, count, values, device_id=unit, tid=tid) == expected
