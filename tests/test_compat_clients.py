"""Clients written the way public TM and OnRobot clients are, against the simulator.

They use tmmaster for nothing but starting the simulator: plain pymodbus calls at the
documented addresses (TMflow SW 2.24 Software Manual, appendix C; OnRobot Connectivity
Guide; the registers OnRobot's official ROS 2 driver's test fixture serves), their own
decoding (float32 high word first, signed 16-bit by hand), as a third-party script does.
"""

from __future__ import annotations

import struct
import time
from collections.abc import Callable

import pytest
from pymodbus.client import ModbusTcpClient

import tmmaster
from tmmaster.sim import DEFAULT_PART_POSE, Simulator

SimFactory = Callable[..., Simulator]


def s16(word: int) -> int:
    """Two's complement of one register, as public clients write it."""
    return word - 0x10000 if word & 0x8000 else word


class TwoFG7Client:
    """A Compute Box 2FG7 client in the style of public ones: reads its limits up front."""

    UNIT = 65

    def __init__(self, host: str, port: int) -> None:
        self.client = ModbusTcpClient(host, port=port, timeout=2)
        if not self.client.connect():
            raise ConnectionError(f"cannot reach the Compute Box at {host}:{port}")
        self.product_code = self._read(0x0600)
        if self.product_code not in (0xC0, 0xC1):
            raise RuntimeError(f"not a 2FG7/2FG14: product code {self.product_code:#x}")
        self.max_force = self._read(0x0405)
        self.min_width = self._read(0x0103) / 10
        self.max_width = self._read(0x0104) / 10

    def _read(self, address: int, count: int = 1) -> int:
        reply = self.client.read_holding_registers(address, count=count, device_id=self.UNIT)
        if reply.isError():
            raise RuntimeError(f"read of {address:#06x} failed: {reply}")
        return int(reply.registers[0])

    def move(self, width_mm: float, force_n: int = 20, speed_percent: int = 10) -> None:
        width = round(min(max(width_mm, self.min_width), self.max_width) * 10)
        force = min(force_n, self.max_force)
        reply = self.client.write_registers(
            0x0000, [width, force, speed_percent, 1], device_id=self.UNIT
        )
        if reply.isError():
            raise RuntimeError(f"grip command refused: {reply}")

    def open(self) -> None:
        self.move(self.max_width)

    def busy(self) -> bool:
        return bool(self._read(0x0100) & 0x01)

    def grip_detected(self) -> bool:
        return bool(self._read(0x0100) & 0x02)

    def width(self) -> float:
        return s16(self._read(0x0101)) / 10

    def force(self) -> int:
        return s16(self._read(0x0107))

    def wait(self, timeout_s: float = 5.0) -> None:
        # Public clients sleep a little before the first status read; so does this one.
        time.sleep(0.05)
        deadline = time.monotonic() + timeout_s
        while self.busy():
            if time.monotonic() > deadline:
                raise TimeoutError("gripper still busy")
            time.sleep(0.02)

    def close(self) -> None:
        self.client.close()


def test_a_public_style_2fg7_client_opens_moves_and_reads_status(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("article", gripper="onrobot-2fg7")
    assert sim.gripper_port is not None
    gripper = TwoFG7Client("127.0.0.1", sim.gripper_port)  # reads 0x0405 and the limits
    try:
        assert gripper.product_code == 0xC0
        assert gripper.max_force == 100
        assert (gripper.min_width, gripper.max_width) == (1.0, 39.0)
        gripper.move(12.0, force_n=40, speed_percent=50)
        gripper.wait()
        assert gripper.width() == pytest.approx(12.0, abs=0.5)
        assert not gripper.grip_detected()
        assert gripper.force() == 0
        gripper.open()
        gripper.wait()
        assert gripper.width() == pytest.approx(39.0, abs=0.5)
    finally:
        gripper.close()
    assert sim.field("external_width", device="gripper") == pytest.approx(39.0, abs=0.5)


def test_the_2fg7_clients_force_reads_negative_on_a_part(tm_simulator_factory: SimFactory) -> None:
    sim = tm_simulator_factory("article", gripper="onrobot-2fg7")
    assert sim.gripper_port is not None
    with tmmaster.connect("127.0.0.1", port=sim.port, profile="article") as robot:
        robot.wait_until_ready(timeout_s=5)
        robot.move_to(DEFAULT_PART_POSE, speed=100)  # fingers around the 30 mm part
    gripper = TwoFG7Client("127.0.0.1", sim.gripper_port)
    try:
        gripper.move(5.0, force_n=40)
        gripper.wait()
        assert gripper.grip_detected()
        assert gripper.width() == pytest.approx(30.0, abs=0.5)
        assert gripper.force() == -40  # signed, as OnRobot's fixture seeds it
    finally:
        gripper.close()


class TMClient:
    """A TM robot client in the style of public TMflow Modbus tools (plain pymodbus)."""

    def __init__(self, host: str, port: int) -> None:
        self.client = ModbusTcpClient(host, port=port, timeout=2)
        assert self.client.connect()

    def _ok(self, reply: object) -> object:
        assert not reply.isError(), reply  # type: ignore[attr-defined]
        return reply

    def floats(self, address: int, n: int) -> list[float]:
        reply = self.client.read_input_registers(address, count=2 * n, device_id=1)
        regs = self._ok(reply).registers  # type: ignore[attr-defined]
        return [
            struct.unpack(">f", struct.pack(">HH", regs[i], regs[i + 1]))[0]
            for i in range(0, 2 * n, 2)
        ]

    def read(self, fc: int, address: int, count: int = 1) -> list[int]:
        call = {
            1: self.client.read_coils,
            2: self.client.read_discrete_inputs,
            3: self.client.read_holding_registers,
            4: self.client.read_input_registers,
        }[fc]
        reply = self._ok(call(address, count=count, device_id=1))
        if fc in (1, 2):
            return [int(b) for b in reply.bits[:count]]  # type: ignore[attr-defined]
        return list(reply.registers)  # type: ignore[attr-defined]

    def refused(self, fc: int, address: int) -> bool:
        call = {2: self.client.read_discrete_inputs, 4: self.client.read_input_registers}[fc]
        reply = call(address, count=1, device_id=1)
        return bool(reply.isError()) and getattr(reply, "exception_code", None) == 2

    def close(self) -> None:
        self.client.close()


#: Documented addresses (TMflow SW 2.24 Software Manual, appendix C) as (FC, first, count).
TM_DOCUMENTED = [
    (2, 7200, 1), (2, 7201, 1), (2, 7202, 3), (2, 7205, 1), (1, 7206, 1), (2, 7207, 2),
    (2, 7209, 2), (2, 7212, 3), (4, 7215, 6), (2, 7221, 1),
    (1, 0, 16), (2, 0, 16), (2, 800, 4), (1, 800, 4), (4, 800, 2), (3, 0, 4), (4, 0, 4),
    (4, 7001, 60), (4, 7101, 2), (2, 7149, 1), (2, 7151, 7),
    (4, 7301, 6), (4, 7308, 5), (4, 7320, 8), (4, 7332, 1), (4, 7340, 12),
    (4, 7390, 7), (4, 7561, 19), (4, 7354, 32), (4, 7801, 8), (4, 7847, 26), (4, 7877, 36),
    (1, 9000, 1000), (3, 9000, 125), (3, 9875, 125),
]  # fmt: skip


def test_a_public_style_tm_client_reads_every_documented_address(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("tmflow")
    sim.wait_for(lambda: sim.field("project_running") is True, 2.0)
    tm = TMClient("127.0.0.1", sim.port)
    try:
        for fc, address, count in TM_DOCUMENTED:
            assert len(tm.read(fc, address, count)) == count, (fc, address)
        flange, joints, tcp = tm.floats(7001, 6), tm.floats(7013, 6), tm.floats(7025, 6)
        base_flange, base_tcp = tm.floats(7037, 6), tm.floats(7049, 6)
        pose = sim.tcp_pose().as_list()
        assert tcp == pytest.approx(pose, abs=1e-3)
        # No tool and no joint model in the kinematic backend: flange = TCP, joints 0.
        assert flange == pytest.approx(tcp)
        assert base_flange == pytest.approx(flange)
        assert base_tcp == pytest.approx(tcp)
        assert joints == [0.0] * 6
        assert tm.read(2, 7200) == [1]  # robot link
        assert tm.read(4, 7215, 2) == [0, 1]  # robot state normal, operation mode auto
        # The user define area is plain memory: FC 06 / 16 / 05 / 15 and back.
        assert not tm.client.write_register(9020, 12345, device_id=1).isError()
        assert not tm.client.write_registers(9500, [1, 2, 3], device_id=1).isError()
        assert not tm.client.write_coil(9001, True, device_id=1).isError()
        assert tm.read(3, 9020) == [12345]
        assert tm.read(3, 9500, 3) == [1, 2, 3]
        assert tm.read(1, 9001) == [1]
        # Undocumented addresses answer exception 2.
        assert tm.refused(2, 7211)
        assert tm.refused(4, 7400)
        assert tm.refused(4, 10000)
    finally:
        tm.close()
