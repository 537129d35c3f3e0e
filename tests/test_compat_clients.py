"""Clients written the way public TM and OnRobot clients are, against the simulator.

They use tmmaster for nothing but starting the simulator: plain pymodbus calls at the
documented addresses (TMflow SW 2.24 Software Manual, appendix C; OnRobot Connectivity
Guide; the registers OnRobot's official ROS 2 driver's test fixture serves), their own
decoding (float32 high word first, signed 16-bit by hand), as a third-party script does.
"""

from __future__ import annotations

import struct
import time
import tomllib
from collections.abc import Callable
from importlib import resources

import pytest
from pymodbus.client import ModbusTcpClient

import tmmaster
from tmmaster import PollPolicy, robot_model
from tmmaster.sim import DEFAULT_PART_POSE, KinematicBackend, RobotSetup, Simulator

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
    sim = tm_simulator_factory("article", robot=RobotSetup(gripper="onrobot-2fg7"))
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
    sim = tm_simulator_factory("article", robot=RobotSetup(gripper="onrobot-2fg7"))
    assert sim.gripper_port is not None
    # Polled every 10 ms (the suite's pace; the default 50 ms is stretched mid-move): the
    # move only brings the fingers around the 30 mm part for the client under test.
    with tmmaster.connect(
        "127.0.0.1", port=sim.port, profile="article", polling=PollPolicy(interval_s=0.01)
    ) as robot:
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

    #: Most registers / bits one Modbus request may read (Modbus application protocol 6.1-6.4).
    MAX_REGS, MAX_BITS = 125, 2000

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

    def read_all(self, fc: int, address: int, count: int) -> list[int]:
        """``count`` addresses from ``address``, in as few requests as Modbus allows."""
        step = self.MAX_BITS if fc in (1, 2) else self.MAX_REGS
        out: list[int] = []
        for first in range(address, address + count, step):
            out += self.read(fc, first, min(step, address + count - first))
        return out

    def write(self, fc: int, address: int, values: list[int]) -> object:
        """One write request with ``fc`` (05/06 one value, 15/16 several)."""
        if fc == 5:
            (value,) = values
            return self.client.write_coil(address, bool(value), device_id=1)
        if fc == 6:
            (value,) = values
            return self.client.write_register(address, value, device_id=1)
        if fc == 15:
            return self.client.write_coils(address, [bool(v) for v in values], device_id=1)
        return self.client.write_registers(address, values, device_id=1)

    def exception_code(self, fc: int, address: int) -> int | None:
        """The exception code a one-address request with ``fc`` gets (None: answered)."""
        if fc in (1, 2, 3, 4):
            call = {
                1: self.client.read_coils,
                2: self.client.read_discrete_inputs,
                3: self.client.read_holding_registers,
                4: self.client.read_input_registers,
            }[fc]
            reply = call(address, count=1, device_id=1)
        else:
            reply = self.write(fc, address, [0])
        return getattr(reply, "exception_code", None) if reply.isError() else None

    def refused(self, fc: int, address: int) -> bool:
        return self.exception_code(fc, address) == 2

    def close(self) -> None:
        self.client.close()


#: Every read the manual documents, transcribed here independently of tmmaster's own table:
#: (FC, first address, count, page) from TMflow SW 2.24 Software Manual (document version
#: 1.00), appendix C "Modbus List", pp. 305-319. Contiguous rows are merged into one read.
TM_READS = [
    # p. 305 Robot Status 1 (7200 link, 7201 error, 7205 get control, 7206 light coil,
    # 7207 safeguard, 7208 ESTOP, 7212-7213 remote control, 7214 AUT.P, 7215-7220, 7221)
    (2, 7200, 2, 305), (2, 7205, 1, 305), (1, 7206, 1, 305), (2, 7207, 2, 305),
    (2, 7212, 3, 305), (4, 7215, 6, 305), (2, 7221, 1, 305),
    # p. 306 Robot Status 2 (7209, 7210), Project Status (7202-7204), Control Box DO / DI
    (2, 7209, 2, 306), (2, 7202, 3, 306), (1, 0, 16, 306), (2, 0, 16, 306),
    # p. 307 End Module DI / DO / AI 0, Control Box AO / AI, External Module 0900-1699
    (2, 800, 4, 307), (1, 800, 4, 307), (4, 800, 2, 307), (3, 0, 4, 307), (4, 0, 4, 307),
    (1, 900, 800, 307), (2, 900, 800, 307), (3, 900, 800, 307), (4, 900, 800, 307),
    # pp. 308-310 Controller Safety Output Assign, Safety Output, OSSD, Input Assign, Input
    (4, 130, 8, 308), (2, 100, 8, 308), (2, 160, 8, 309), (4, 230, 8, 309), (2, 200, 8, 310),
    # pp. 310-312 Robot Coordinate (7001-7060) and at a touch stop (7401-7460)
    (4, 7001, 60, 310), (4, 7401, 60, 311),
    # p. 312 Run Setting: current project (string)
    (4, 7701, 99, 312),
    # p. 313 TCP Value (7354-7385), M/A mode (7102); p. 314 Project Speed (7101)
    (4, 7354, 32, 313), (4, 7101, 2, 313),
    # p. 315 Robot Stick Status (pressed 7149, 7151-7156; 7157-7160), End Module Button
    # (7170), TCP Speed (7859-7872), TCP Force (7801-7808)
    (2, 7149, 1, 315), (2, 7151, 10, 315), (2, 7170, 1, 315), (4, 7859, 14, 315),
    (4, 7801, 8, 315),
    # p. 316 Joint Torque raw / avg / min / max; p. 317 estimated torque, current,
    # temperature, speed (7913-7960), Current Base (8300-8311)
    (4, 7847, 12, 316), (4, 7877, 36, 316), (4, 7913, 48, 317), (4, 8300, 12, 317),
    # p. 318 Running Timer, Up Time, Safety Setting, Others 1 (time, HMI version, last
    # error, last warning, serial number, robot model), Others 2 (7340-7345)
    (4, 8200, 5, 318), (4, 8206, 5, 318), (4, 7280, 20, 318), (4, 7301, 6, 318),
    (4, 7308, 5, 318), (4, 7320, 8, 318), (4, 7390, 7, 318), (4, 7561, 19, 318),
    (4, 7340, 6, 318),
    # p. 319 Others 2 (7346-7351), Others 3 light (7332), Others 4 user define area
    (4, 7346, 6, 319), (4, 7332, 1, 319), (1, 9000, 1000, 319), (3, 9000, 1000, 319),
]  # fmt: skip

#: Every write the manual documents, as (FC, first address, values, page). Buttons are
#: written 0 (not pressed: they trigger on 1); the R/W tables get a pattern read back below.
TM_WRITES = [
    (5, 7210, [0], 306),  # Auto Remote Mode Active (write)
    (5, 0, [1], 306), (5, 15, [1], 306),  # Control Box DO
    (5, 800, [1], 307), (5, 803, [1], 307), (5, 7206, [1], 305),  # End Module DO, Light
    (16, 0, [0x3F80, 0, 0x4000, 0], 307),  # Control Box AO 0-1: 1.0 V, 2.0 V
    (5, 900, [1], 307), (5, 1699, [1], 307), (16, 1698, [0x4040, 0], 307),  # External
    (16, 7701, [0x544D, 0x666C, 0x6F77, 0], 312), (6, 7799, [0], 312),  # Run Setting
    (5, 7104, [0], 313), (5, 7105, [0], 313), (5, 7106, [0], 313),  # Play/Pause, Stop, +
    (5, 7107, [0], 314), (5, 7103, [0], 314), (5, 7108, [0], 314),  # -, Play, Pause
    (6, 7101, [50], 314),  # Change Project Speed
    (15, 9990, [1, 0, 1], 319), (6, 9999, [7], 319),  # user define area
]  # fmt: skip

#: What kenshu528-oss/Modbus-testkit-for-TMflow (commit e6217f77,
#: tmflow_modbus_testkit.py) reads, as (FC, address, count): its coordinate tests and
#: presets (read_input_registers 7001 / 7025 / 7013 x 12 and 7001 x 6, lines 569, 647-655,
#: 756-770, 1042-1046, 1068), its status test (read_discrete_inputs 7200, 7201, 7202, 7208
#: one by one, 7200 x 4 and x 2; read_input_registers 7215, 7216; lines 619-634, 777, 1048,
#: 1069), the Light preset (read_coils 7206, line 784) and its user-area test
#: (read_holding_registers 9000, 9001, 9002, 9010, 9020, 9100 and 9000 x 10, lines 671-676,
#: 791, 1050).
TESTKIT_READS = [
    (4, 7001, 12), (4, 7025, 12), (4, 7013, 12), (4, 7001, 6),
    (2, 7200, 1), (2, 7201, 1), (2, 7202, 1), (2, 7208, 1), (2, 7200, 4), (2, 7200, 2),
    (4, 7215, 1), (4, 7216, 1), (1, 7206, 1),
    (3, 9000, 1), (3, 9001, 1), (3, 9002, 1), (3, 9010, 1), (3, 9020, 1), (3, 9100, 1),
    (3, 9000, 10),
]  # fmt: skip

#: Addresses the manual does not list (with the function code of their neighbours).
UNDOCUMENTED = [
    (2, 7211), (2, 7222), (2, 7150), (2, 7161), (2, 7171), (2, 108), (2, 1700), (2, 7206),
    (4, 7061), (4, 7400), (4, 7461), (4, 7800), (4, 7961), (4, 8205), (4, 8312), (4, 138),
    (4, 7279), (4, 7800), (4, 10000),
    (1, 16), (1, 7109), (1, 7207), (1, 1700), (1, 10000),
    (3, 4), (3, 899), (3, 1700), (3, 8999), (3, 10000),
    (5, 7202), (5, 7109), (6, 7102), (6, 7700), (6, 7800),
]  # fmt: skip

_FC_TABLE = {1: "coil", 2: "discrete_input", 3: "holding", 4: "input", 5: "coil"}
_FC_TABLE |= {6: "holding", 15: "coil", 16: "holding"}


def test_the_test_lists_agree_with_tmmasters_own_transcription() -> None:
    """Two transcriptions of appendix C (this file's and tm_table.toml) cover the same addresses."""
    table = tomllib.loads(
        resources.files("tmmaster.sim").joinpath("tm_table.toml").read_text("utf-8")
    )
    width = {"bool": 1, "int16": 1, "uint16": 1, "int32": 2, "float32": 2}
    theirs: set[tuple[str, int]] = set()
    for e in table["entry"]:
        n = width[e["type"]] * e.get("count", 1)
        theirs |= {(e["table"], a) for a in range(e["address"], e["address"] + n)}
    for area in table["area"]:
        theirs |= {
            (area["table"], a) for a in range(area["address"], area["address"] + area["count"])
        }
    ours = {(_FC_TABLE[fc], a) for fc, first, n, _ in TM_READS for a in range(first, first + n)}
    ours |= {
        (_FC_TABLE[fc], a) for fc, first, v, _ in TM_WRITES for a in range(first, first + len(v))
    }
    # Write-only rows the reads above do not reach (every address of the write ranges).
    ours |= {("coil", a) for a in (7103, 7104, 7105, 7106, 7107, 7108, 7210)}
    ours |= {("holding", a) for a in (7101, *range(7701, 7800))}
    assert ours == theirs, (sorted(ours - theirs), sorted(theirs - ours))


def test_a_public_style_tm_client_reads_every_documented_address(
    tm_simulator_factory: SimFactory,
) -> None:
    backend = KinematicBackend(robot_model("tm5-700"))
    sim = tm_simulator_factory("tmflow", cell=backend)
    sim.wait_for(lambda: sim.field("project_running") is True, 2.0)
    tm = TMClient("127.0.0.1", sim.port)
    try:
        for fc, address, count, page in TM_READS:
            assert len(tm.read_all(fc, address, count)) == count, (fc, address, page)
        flange, joints, tcp = tm.floats(7001, 6), tm.floats(7013, 6), tm.floats(7025, 6)
        base_flange, base_tcp = tm.floats(7037, 6), tm.floats(7049, 6)
        pose = sim.tcp_pose().as_list()
        assert tcp == pytest.approx(pose, abs=1e-3)
        # Flange and joints are the backend's own (flange = TCP, joints 0 without a model).
        model_flange = sim.call(backend.flange_pose)
        model_joints = sim.call(backend.joint_positions_deg)
        assert flange == pytest.approx(model_flange.as_list() if model_flange else tcp, abs=1e-3)
        assert joints == pytest.approx(list(model_joints or [0.0] * 6), abs=1e-3)
        # The simulated current base is the robot base (Current Base reads 0).
        assert base_flange == pytest.approx(flange)
        assert base_tcp == pytest.approx(tcp)
        assert tm.floats(8300, 6) == [0.0] * 6
        assert tm.read(2, 7200) == [1]  # robot link
        assert tm.read(4, 7215, 2) == [0, 1]  # robot state normal, operation mode auto
        assert tm.read(4, 7102) == [1]  # M/A mode: auto, as 7216 says
        assert tm.read(2, 7201, 4) == [0, 1, 0, 0]  # no error, running, not editing/paused
        assert tm.read(2, 7214) == [1]  # AUT.P high: able to play in auto mode
        assert tm.read(4, 7101) == [100]  # project speed
        # Running time (0 when stopped) never exceeds the time since start-up.
        running, up = tm.read(4, 8200, 5), tm.read(4, 8206, 5)
        assert running[:2] == [0, 0]  # days (int32) of a short test
        assert up[:2] == [0, 0]
        assert running[2:] <= up[2:]
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


def test_every_documented_write_is_taken_and_rw_tables_read_back(
    tm_simulator_factory: SimFactory,
) -> None:
    sim = tm_simulator_factory("tmflow")
    sim.wait_for(lambda: sim.field("project_running") is True, 2.0)
    tm = TMClient("127.0.0.1", sim.port)
    try:
        for fc, address, values, page in TM_WRITES:
            reply = tm.write(fc, address, values)
            assert not reply.isError(), (fc, address, page, reply)  # type: ignore[attr-defined]
        # Read/write tables (FC 01/05, 03/16) hold what was written.
        assert tm.read(1, 0, 16) == [1] + [0] * 14 + [1]
        assert tm.read(1, 800, 4) == [1, 0, 0, 1]
        assert tm.read(1, 7206) == [1]
        assert tm.read(3, 0, 4) == [0x3F80, 0, 0x4000, 0]
        assert tm.read(1, 900) == [1]
        assert tm.read(1, 1699) == [1]
        assert tm.read(3, 1698, 2) == [0x4040, 0]
        assert tm.read(1, 9990, 3) == [1, 0, 1]
        assert tm.read(3, 9999) == [7]
        # Buttons written 0 press nothing: the project still runs.
        assert tm.read(2, 7202) == [1]
        # Stop (FC 05, 1) stops the project; the running timer returns to 0.
        assert tm.write(5, 7105, [1]).isError() is False  # type: ignore[attr-defined]
        sim.wait_for(lambda: tm.read(2, 7202) == [0], 2.0)
        sim.wait_for(lambda: tm.read(4, 8200, 5) == [0] * 5, 2.0)
    finally:
        tm.close()


def test_the_public_testkits_reads_are_all_answered(tm_simulator_factory: SimFactory) -> None:
    sim = tm_simulator_factory("tmflow")
    sim.wait_for(lambda: sim.field("project_running") is True, 2.0)
    tm = TMClient("127.0.0.1", sim.port)
    try:
        for fc, address, count in TESTKIT_READS:
            assert len(tm.read(fc, address, count)) == count, (fc, address)
        # Its user-area write test: write_register(9000, v), then read it back.
        assert not tm.client.write_register(9000, 4242, device_id=1).isError()
        assert tm.read(3, 9000) == [4242]
    finally:
        tm.close()


def test_undocumented_addresses_answer_exception_2(tm_simulator_factory: SimFactory) -> None:
    sim = tm_simulator_factory("tmflow")
    tm = TMClient("127.0.0.1", sim.port)
    try:
        refused = {(fc, a): tm.exception_code(fc, a) for fc, a in UNDOCUMENTED}
        assert refused == dict.fromkeys(refused, 2)
    finally:
        tm.close()


def test_the_tm_status_follows_an_emergency_stop(tm_simulator_factory: SimFactory) -> None:
    sim = tm_simulator_factory("tmflow")
    sim.wait_for(lambda: sim.field("project_running") is True, 2.0)
    tm = TMClient("127.0.0.1", sim.port)
    try:
        sim.press_estop()
        sim.wait_for(lambda: tm.read(2, 7202) == [0], 2.0)  # the project stopped
        assert tm.read(2, 7201) == [1]  # error
        assert tm.read(2, 7208) == [1]  # ESTOP
        assert tm.read(4, 7215) == [4]  # robot state: STO (including ESTOP)
        code = tm.read(4, 7320, 2)
        assert code != [0, 0]  # last error code (int32)
        sim.clear_error()
        sim.wait_for(lambda: tm.read(2, 7201) == [0] and tm.read(2, 7208) == [0], 2.0)
        assert tm.read(4, 7215) == [0]
        assert tm.read(4, 7320, 2) == code  # the *last* error stays
    finally:
        tm.close()
