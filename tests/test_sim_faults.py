"""Fault specs: validation, the discriminated union, and the CLI syntax."""

from __future__ import annotations

import pytest

from tmmaster._exceptions import ConfigError
from tmmaster._registers import Table
from tmmaster.sim._faults import (
    FAULT_ADAPTER,
    FAULT_KINDS,
    DropConnectionsFault,
    EstopFault,
    GraspMissFault,
    LateAckFault,
    ModbusExceptionFault,
    RobotErrorFault,
    SlowResponsesFault,
    StallFault,
    StopListeningFault,
    is_network_fault,
    parse_fault,
)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("robot_error:at_move=3,code=0x1F4", RobotErrorFault(at_move=3, code=500)),
        ("robot_error:at_move=2", RobotErrorFault(at_move=2, code=0x1F4)),
        ("stall:at_move=1", StallFault(at_move=1)),
        ("estop:at_move=2", EstopFault(at_move=2)),
        ("estop:after_s=1.5", EstopFault(after_s=1.5)),
        ("grasp_miss", GraspMissFault(at_grasp=1)),
        ("grasp_miss:at_grasp=2", GraspMissFault(at_grasp=2)),
        ("late_ack:delay_s=0.5", LateAckFault(delay_s=0.5)),
        ("late_ack:delay_s=1,at_move=none", LateAckFault(delay_s=1.0)),
        ("late_ack: delay_s = 2 , at_move = 4", LateAckFault(delay_s=2.0, at_move=4)),
        ("drop_connections:after_requests=5", DropConnectionsFault(after_requests=5)),
        (
            "drop_connections:after_requests=5,once=false",
            DropConnectionsFault(after_requests=5, once=False),
        ),
        (
            "stop_listening:after_requests=3,duration_s=2",
            StopListeningFault(after_requests=3, duration_s=2.0),
        ),
        ("slow_responses:delay_s=0.25", SlowResponsesFault(delay_s=0.25)),
        (
            "modbus_exception:table=holding,start=9100,end=9105",
            ModbusExceptionFault(table=Table.HOLDING, start=9100, end=9105, code=2),
        ),
        (
            "modbus_exception:table=input,start=7025,end=7036,code=4",
            ModbusExceptionFault(table=Table.INPUT, start=7025, end=7036, code=4),
        ),
    ],
)
def test_parse_fault(text: str, expected: object) -> None:
    assert parse_fault(text) == expected


def test_every_kind_parses_and_is_classified() -> None:
    network = {"drop_connections", "stop_listening", "slow_responses", "modbus_exception"}
    assert set(FAULT_KINDS) == network | {
        "robot_error",
        "stall",
        "estop",
        "grasp_miss",
        "late_ack",
    }
    assert is_network_fault(parse_fault("slow_responses:delay_s=1"))
    assert not is_network_fault(parse_fault("stall:at_move=1"))


def test_discriminated_union_from_json() -> None:
    fault = FAULT_ADAPTER.validate_json('{"kind": "stall", "at_move": 2}')
    assert fault == StallFault(at_move=2)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("nonsense:x=1", "unknown kind 'nonsense'"),
        ("robot_error:at_move=1,colour=red", "unknown key 'colour'"),
        ("robot_error:at_move=0", "key 'at_move'"),
        ("robot_error:at_move=three", "key 'at_move'"),
        ("robot_error:code=5", "key 'at_move'"),  # missing required key
        ("robot_error:at_move=1,at_move=2", "given twice"),
        ("late_ack:delay_s", "expected key=value"),
        ("late_ack:delay_s=-1", "key 'delay_s'"),
        ("estop", "exactly one of at_move or after_s"),
        ("estop:at_move=1,after_s=2", "exactly one of at_move or after_s"),
        ("modbus_exception:table=holdings,start=1,end=2", "key 'table'"),
        ("modbus_exception:table=holding,start=5,end=2", "end 2 is before start 5"),
    ],
)
def test_parse_fault_errors_name_the_problem(text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        parse_fault(text)


def test_faults_are_frozen() -> None:
    fault = StallFault(at_move=1)
    with pytest.raises(ValueError, match="frozen"):
        fault.at_move = 2  # type: ignore[misc]
