# The article's Python master, as published, for benchmarks/bench_cycle.py.
#
# Source: Ken Suzuki, "TM Robot x Isaac Sim: Externally Controlling Pick & Place via
# Modbus SLAVE Polling", Shirokuma.online, August 10, 2026, section "Python Master:
# Implementing the Polling Loop" (copy in /work/shared/seeds/000_ec7631a17b1ba018.txt).
#
# Verbatim except two patches, each marked "PATCH (tmmaster)" below:
#  1. the race: wait_motion_complete() polled "idle" right after the command write, so
#     it could see the idle state from before the slave took the command and return at
#     once. Seen against tmmaster.sim (with patch 2 only): the pick command overwrote the
#     approach command before the slave's next tick, the gripper closed with the arm
#     still at home, and the script ended in ERROR ("Grasp failed") after 0.8 s.
#     Patched: it first waits for the motion to start (the slave clears the command
#     register when it takes the command, after setting "moving").
#  2. negative coordinates: int(-200 * 100) = -20000 is not a valid uint16 register
#     value: pymodbus 3.16's write_register raises struct.error("argument out of range"),
#     which run() does not catch (it catches IOError), so the script dies on its first
#     move (APPROACH_POS has y = -200). Patched: written as 16-bit two's complement,
#     which is what the int16 registers of the map mean.
# bench_cycle.py also sets HOME_POS to tmmaster.DEFAULT_HOME before running it: the
# published HOME (0, 0, 300, 180, 0, 0) is out of a TM5's reach, and the simulator refuses
# it as the real arm would (docs/kinematics.md). This file keeps the published value.
# Kept as published, on purpose: its layout and style (excluded from ruff in
# pyproject.toml), the prints, the fixed gripper sleeps (0.8 s close, 0.5 s open), the
# 50 ms poll, ModbusTcpClient's default retries.
import time
from pymodbus.client import ModbusTcpClient
from enum import Enum, auto

class State(Enum):
    IDLE = auto()
    MOVE_TO_APPROACH = auto()
    MOVE_TO_PICK = auto()
    GRIPPER_CLOSE = auto()
    CHECK_GRASP = auto()
    MOVE_TO_LIFT = auto()
    MOVE_TO_PLACE = auto()
    GRIPPER_OPEN = auto()
    MOVE_TO_HOME = auto()
    DONE = auto()
    ERROR = auto()

# ---- Register addresses (adjust to your environment) ----
REG_MOTION_STATUS   = 0x0001  # 0=idle, 1=moving
REG_GRASP_STATUS    = 0x0002  # 0=not grasped, 1=grasped
REG_TARGET_X        = 0x0200
REG_TARGET_Y        = 0x0201
REG_TARGET_Z        = 0x0202
REG_TARGET_RX       = 0x0203
REG_TARGET_RY       = 0x0204
REG_TARGET_RZ       = 0x0205
REG_SPEED           = 0x0206
REG_COMMAND         = 0x0207
REG_GRIPPER_CMD     = 0x0210  # 0=open, 1=close

CMD_EXECUTE_PTP  = 1
CMD_EXECUTE_LINE = 2

# ---- Task coordinates (mm, deg) ----
APPROACH_POS = [300, -200, 200, 180, 0, 90]  # above the pick position
PICK_POS     = [300, -200, 100, 180, 0, 90]  # pick position
LIFT_POS     = [300, -200, 250, 180, 0, 90]  # after lifting
PLACE_POS    = [300,  200, 200, 180, 0, 90]  # place position
HOME_POS     = [  0,    0, 300, 180, 0,  0]  # home position
SPEED_NORMAL = 30   # %
SPEED_SLOW   = 10   # % (for approaching pick/place)
POLL_INTERVAL = 0.05  # 50ms
MOTION_TIMEOUT = 30   # seconds


class PickAndPlaceController:
    def __init__(self, host: str, port: int = 502):
        self.client = ModbusTcpClient(host, port=port)
        self.state = State.IDLE

    def connect(self) -> bool:
        return self.client.connect()

    def disconnect(self):
        self.client.close()

    # ---- Register access ----
    def read_register(self, address: int) -> int:
        result = self.client.read_holding_registers(address, count=1)
        if result.isError():
            raise IOError(f"Register read error: {address:#x}")
        return result.registers[0]

    def write_register(self, address: int, value: int):
        result = self.client.write_register(address, value)
        if result.isError():
            raise IOError(f"Register write error: {address:#x}")

    # ---- Polling: wait for motion completion ----
    def wait_motion_complete(self, timeout: float = MOTION_TIMEOUT) -> bool:
        deadline = time.time() + timeout
        # PATCH (tmmaster) 1: wait for the slave to take the command (it clears the
        # command register after setting "moving") before polling for idle.
        while self.read_register(REG_COMMAND) != 0:
            if time.time() >= deadline:
                return False
            time.sleep(POLL_INTERVAL)
        while time.time() < deadline:
            status = self.read_register(REG_MOTION_STATUS)
            if status == 0:  # idle = motion complete
                return True
            time.sleep(POLL_INTERVAL)
        return False  # timeout

    # ---- Motion command ----
    def move_to(self, pos: list, speed: int, motion_type: int = CMD_EXECUTE_PTP):
        # Convert coordinates to integer registers (×100) and write them
        addrs = [REG_TARGET_X, REG_TARGET_Y, REG_TARGET_Z,
                 REG_TARGET_RX, REG_TARGET_RY, REG_TARGET_RZ]
        for addr, val in zip(addrs, pos):
            # PATCH (tmmaster) 2: int16 registers, two's complement (was int(val * 100)).
            self.write_register(addr, int(val * 100) & 0xFFFF)
        self.write_register(REG_SPEED, speed)
        self.write_register(REG_COMMAND, motion_type)

    # ---- Gripper control ----
    def gripper_open(self):
        self.write_register(REG_GRIPPER_CMD, 0)

    def gripper_close(self):
        self.write_register(REG_GRIPPER_CMD, 1)

    def check_grasp_success(self) -> bool:
        return self.read_register(REG_GRASP_STATUS) == 1

    # ---- Main loop ----
    def run(self):
        self.state = State.MOVE_TO_APPROACH
        print("[START] Starting Pick & Place")

        while self.state not in (State.DONE, State.ERROR):
            try:
                self._step()
            except IOError as e:
                print(f"[ERROR] Communication error: {e}")
                self.state = State.ERROR

        print(f"[{self.state.name}] Finished")

    def _step(self):
        s = self.state

        if s == State.MOVE_TO_APPROACH:
            print("  → Moving to approach position")
            self.move_to(APPROACH_POS, SPEED_NORMAL)
            if not self.wait_motion_complete():
                self.state = State.ERROR; return
            self.state = State.MOVE_TO_PICK

        elif s == State.MOVE_TO_PICK:
            print("  → Descending to pick position")
            self.move_to(PICK_POS, SPEED_SLOW, CMD_EXECUTE_LINE)
            if not self.wait_motion_complete():
                self.state = State.ERROR; return
            self.state = State.GRIPPER_CLOSE

        elif s == State.GRIPPER_CLOSE:
            print("  → Closing gripper")
            self.gripper_close()
            time.sleep(0.8)  # wait for gripper motion
            self.state = State.CHECK_GRASP

        elif s == State.CHECK_GRASP:
            if self.check_grasp_success():
                print("  ✓ Grasp successful")
                self.state = State.MOVE_TO_LIFT
            else:
                print("  ✗ Grasp failed")
                self.state = State.ERROR

        elif s == State.MOVE_TO_LIFT:
            print("  → Lifting")
            self.move_to(LIFT_POS, SPEED_SLOW, CMD_EXECUTE_LINE)
            if not self.wait_motion_complete():
                self.state = State.ERROR; return
            self.state = State.MOVE_TO_PLACE

        elif s == State.MOVE_TO_PLACE:
            print("  → Moving to place position")
            self.move_to(PLACE_POS, SPEED_NORMAL)
            if not self.wait_motion_complete():
                self.state = State.ERROR; return
            self.state = State.GRIPPER_OPEN

        elif s == State.GRIPPER_OPEN:
            print("  → Opening gripper")
            self.gripper_open()
            time.sleep(0.5)
            self.state = State.MOVE_TO_HOME

        elif s == State.MOVE_TO_HOME:
            print("  → Returning home")
            self.move_to(HOME_POS, SPEED_NORMAL)
            if not self.wait_motion_complete():
                self.state = State.ERROR; return
            self.state = State.DONE


if __name__ == "__main__":
    ctrl = PickAndPlaceController(host="192.168.1.100")  # TM Robot's IP
    if ctrl.connect():
        ctrl.run()
        ctrl.disconnect()
    else:
        print("Connection failed")
