"""Clients written the way public TM and OnRobot clients are, against the simulator.

They use tmmaster for nothing but starting the simulator: plain pymodbus calls at the
documented addresses (TMflow SW 2.24 Software Manual, appendix C; OnRobot Connectivity
Guide; the registers OnRobot's official ROS 2 driver's test fixture serves), their own
decoding (float32 high word first, signed 16-bit by hand), as a third-party script does.
"""

from __future__ import annotations

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
