"""Simulated devices ticked directly: both robot handshakes, error codes, faults, grippers."""

from __future__ import annotations

import gc
import inspect
import math
import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import pytest

from sim_backends import SlowSettlingBackend
from tmmaster._codec import encode
from tmmaster._exceptions import ValueOutOfRangeError
from tmmaster._pose import MotionType, Pose
from tmmaster._profiles import gripper_profile, robot_profile
from tmmaster._registers import TARGET_FIELDS, Handshake, RegisterMap, RobotProfile, Table
from tmmaster._robot_models import robot_model
from tmmaster.sim import Simulator
from tmmaster.sim._backend import MotionRejectedError, RejectReason
from tmmaster.sim._bank import RegisterBank
from tmmaster.sim._clear_on_accept import ClearOnAcceptController
from tmmaster.sim._controller import RobotController, SimErrorCode
from tmmaster.sim._faults import (
    EstopFault,
    Fault,
    GraspMissFault,
    LateAckFault,
    RobotErrorFault,
    StallFault,
    parse_fault,
)
from tmmaster.sim._grippers import Blog2FG7Device, OnRobot2FG7Device
from tmmaster.sim._kinematic import DEFAULT_HOME, KinematicBackend
from tmmaster.sim._script_project import ScriptProjectController
from tmmaster.sim._tm_table import tm_table_areas, tm_table_fields
from tmmaster.sim._world import DEFAULT_PART_POSE

#: The controller class the simulator runs per handshake (tmflow: a TMflow project, its
#: robot program interpreted).
CONTROLLERS: dict[Handshake, type[RobotController]] = {
    Handshake.CLEAR_ON_ACCEPT: ClearOnAcceptController,
    Handshake.SEQUENCE: ScriptProjectController,
}


def controller_class(handshake: Handshake) -> type[RobotController]:
    return CONTROLLERS[handshake]


def controller_for(
    profile: RobotProfile, bank: RegisterBank, backend: Any, model: Any, **options: Any
) -> RobotController:
    return controller_class(profile.handshake)(profile, bank, backend, model, **options)


DT = 0.02  # 50 Hz, the article slave's tick
MODEL = robot_model("tm5-700")
INIT_S = 0.1
HOME = DEFAULT_HOME
PART = DEFAULT_PART_POSE  # (300, -200, 100, 180, 0, 90), a 30 mm part lies here
AIR = Pose(200, 100, 250, 180, 0, 0)
FAR = Pose(250, 250, 250, 180, 0, 0)  # reachable by a TM5-700, not by SMALL
SMALL = MODEL.model_copy(update={"name": "small", "reach_mm": 300.0})


class Tickable(Protocol):
    def tick(self, dt: float) -> None: ...


class ListLogger:
    """Collects structlog-style calls so tests can assert on events."""

    def __init__(self) -> None:
        self.events: list[tuple[str, str, dict[str, Any]]] = []

    def info(self, event: str, **kw: Any) -> None:
        self.events.append(("info", event, kw))

    def warning(self, event: str, **kw: Any) -> None:
        self.events.append(("warning", event, kw))

    def names(self) -> list[str]:
        return [event for _, event, _ in self.events]


class LateReadyBackend(KinematicBackend):
    """Backend whose physics view, once invalid, is valid again ``ready_after_s`` after reinit."""

    def __init__(self, *, ready_after_s: float) -> None:
        super().__init__(MODEL)
        self.ready = True
        self.ready_after_s = ready_after_s
        self.reinit_calls = 0
        self._countdown: float | None = None

    def invalidate(self) -> None:
        self.ready = False

    def is_ready(self) -> bool:
        return self.ready

    def reinitialize(self) -> bool:
        self.reinit_calls += 1
        if self._countdown is None:
            self._countdown = self.ready_after_s
        return True

    def step(self, dt: float) -> None:
        super().step(dt)
        if not self.ready and self._countdown is not None:
            self._countdown -= dt
            if self._countdown <= 1e-9:
                self.ready = True
                self._countdown = None

    def start_motion(
        self, target: Pose, *, motion: MotionType, speed_percent: float, accel_time_s: float
    ) -> float:
        assert self.ready, "the controller started a motion on an invalid physics view"
        return super().start_motion(
            target, motion=motion, speed_percent=speed_percent, accel_time_s=accel_time_s
        )


# -- helpers --------------------------------------------------------------------------


def run(devices: Tickable | Sequence[Tickable], seconds: float) -> None:
    group = [devices] if not isinstance(devices, Sequence) else list(devices)
    for _ in range(round(seconds / DT)):
        for device in group:
            device.tick(DT)


def run_until(
    devices: Tickable | Sequence[Tickable], done: Callable[[], bool], *, limit_s: float = 10.0
) -> float:
    """Tick until ``done()``; return the simulated seconds it took."""
    group = [devices] if not isinstance(devices, Sequence) else list(devices)
    for n in range(1, round(limit_s / DT) + 1):
        for device in group:
            device.tick(DT)
        if done():
            return n * DT
    raise AssertionError(f"not done after {limit_s} simulated seconds")


def words(register_map: RegisterMap, values: dict[str, Any]) -> list[int]:
    out: list[int] = []
    for name, value in values.items():
        out += encode(register_map.field(name), value)
    return out


def pose_of(bank: RegisterBank) -> Pose:
    return Pose(*(float(bank.get(f"tcp_{n}")) for n in ("x", "y", "z", "rx", "ry", "rz")))


def article(
    *,
    faults: Sequence[Fault] = (),
    backend: KinematicBackend | None = None,
    model: Any = MODEL,
    initialise: bool = True,
) -> tuple[RobotController, RegisterBank, KinematicBackend, ListLogger]:
    profile = robot_profile("article")
    bank = RegisterBank(profile)
    backend = KinematicBackend(model) if backend is None else backend
    log = ListLogger()
    ctl = controller_for(profile, bank, backend, model, faults=faults, init_time_s=INIT_S, log=log)
    if initialise:
        run(ctl, INIT_S)
    return ctl, bank, backend, log


def send_article(bank: RegisterBank, target: Pose, *, speed: int = 100, command: int = 1) -> None:
    """One FC16 write of the article's command block: six targets, speed, command last."""
    values: dict[str, Any] = dict(zip(TARGET_FIELDS, target.as_list(), strict=True))
    values |= {"speed": speed, "command": command}
    bank.write(Table.HOLDING, 0x0200, words(bank.register_map, values))


def move_article(ctl: RobotController, bank: RegisterBank, target: Pose) -> None:
    send_article(bank, target)
    run_until(ctl, lambda: bank.get("command") == 0 and bank.get("motion_status") == 0)


def tmflow(
    *,
    faults: Sequence[Fault] = (),
    backend: KinematicBackend | None = None,
    model: Any = MODEL,
    initialise: bool = True,
    initial_seq: int = 0,
) -> tuple[RobotController, RegisterBank, KinematicBackend, ListLogger]:
    profile = robot_profile("tmflow")
    bank = controller_class(profile.handshake).bank_for(profile)  # Techman's table too
    backend = KinematicBackend(model) if backend is None else backend
    log = ListLogger()
    ctl = controller_for(
        profile,
        bank,
        backend,
        model,
        faults=faults,
        init_time_s=INIT_S,
        log=log,
        initial_seq=initial_seq,
    )
    if initialise:
        run(ctl, INIT_S)
    return ctl, bank, backend, log


def send_tmflow(
    bank: RegisterBank,
    seq: int,
    *,
    command: int = 1,
    target: Pose = PART,
    speed: int = 100,
    accel_ms: int = 0,
) -> None:
    """One FC16 write of the tmflow command block, seq last."""
    values: dict[str, Any] = dict(zip(TARGET_FIELDS, target.as_list(), strict=True))
    values |= {"speed": speed, "accel_time": accel_ms, "command": command, "seq": seq}
    bank.write(Table.HOLDING, 9000, words(bank.register_map, values))


def finish_tmflow(ctl: RobotController, bank: RegisterBank, seq: int) -> float:
    return run_until(ctl, lambda: bank.get("done_seq") == seq and bank.get("robot_state") == 0)


# -- article: clear-on-accept ------------------------------------------------------------


def test_article_initialises_then_goes_auto() -> None:
    ctl, bank, _, log = article(initialise=False)
    assert bank.get("robot_mode") == 0
    assert pose_of(bank).is_close(HOME, mm=0.01, deg=0.01)
    run(ctl, INIT_S - DT)
    assert bank.get("robot_mode") == 0
    ctl.tick(DT)
    assert bank.get("robot_mode") == 5
    assert ctl.state == "idle"
    assert "sim.initialised" in log.names()


def test_article_race_ack_happens_on_the_tick_not_at_write_time() -> None:
    ctl, bank, _, log = article()
    send_article(bank, PART)
    # Before the tick: nothing acknowledged, the article master's naive poll sees "idle".
    assert bank.get("motion_status") == 0
    assert bank.get("command") == 1
    ctl.tick(DT)
    assert bank.get("motion_status") == 1
    assert bank.get("command") == 0
    assert ctl.state == "moving"
    assert ctl.moves_started == 1
    assert "sim.command_accepted" in log.names()
    assert "sim.motion_started" in log.names()
    run_until(ctl, lambda: bank.get("motion_status") == 0)
    assert pose_of(bank).is_close(PART, mm=0.01, deg=0.01)
    assert "sim.motion_done" in log.names()


class RecordingBank(RegisterBank):
    """Records the order of device-side writes, to check the order the contracts demand.

    Both the controller's own (``set``) and the robot program's (``write(device=True)``,
    one field per register write), by field name.
    """

    def __init__(self, register_map: RegisterMap, **options: Any) -> None:
        super().__init__(register_map, **options)
        self.sets: list[tuple[str, Any]] = []

    def set(self, name: str, value: Any) -> None:
        self.sets.append((name, value))
        super().set(name, value)

    def write(self, table: Table, address: int, values: Any, *, device: bool = False) -> None:
        super().write(table, address, values, device=device)
        if device:
            for field in self.register_map.fields.values():
                if field.table is table and field.address == address:
                    self.sets.append((field.name, self.get(field.name)))


def test_article_sets_moving_before_it_clears_the_command() -> None:
    profile = robot_profile("article")
    bank = RecordingBank(profile)
    ctl = controller_for(profile, bank, KinematicBackend(MODEL), MODEL, init_time_s=0.0)
    ctl.tick(DT)
    send_article(bank, PART)
    bank.sets.clear()
    ctl.tick(DT)
    assert bank.sets.index(("motion_status", 1)) < bank.sets.index(("command", 0))


def test_article_reports_the_error_before_it_clears_the_command() -> None:
    profile = robot_profile("article")
    bank = RecordingBank(profile)
    ctl = controller_for(profile, bank, KinematicBackend(SMALL), SMALL, init_time_s=0.0)
    ctl.tick(DT)
    send_article(bank, FAR)
    bank.sets.clear()
    ctl.tick(DT)
    assert bank.sets.index(("robot_mode", 7)) < bank.sets.index(("command", 0))


def test_tmflow_writes_results_before_the_state() -> None:
    # The program's ordering rules: whoever sees the acknowledgement sees no stale state
    # (result, state, then ack_seq); a refusal writes its result before the error state;
    # done writes result and the idle state before done_seq.
    profile = robot_profile("tmflow")
    bank = RecordingBank(profile, extra_fields=tm_table_fields(profile), raw_areas=tm_table_areas())
    ctl = controller_for(profile, bank, KinematicBackend(SMALL), SMALL, init_time_s=0.0)
    ctl.tick(DT)
    send_tmflow(bank, 1, target=FAR)
    bank.sets.clear()
    # Within a tick or a few: the program's time budget per tick may end after inversekin
    # (a cold solve of an unreachable target), the refusal then comes a tick later.
    run_until(ctl, lambda: bank.get("robot_state") == 2, limit_s=4 * DT)
    assert bank.sets.index(("result_code", 0)) < bank.sets.index(("robot_state", 1))
    assert bank.sets.index(("robot_state", 1)) < bank.sets.index(("ack_seq", 1))
    assert bank.sets.index(("result_code", 1)) < bank.sets.index(("robot_state", 2))
    send_tmflow(bank, 2, command=3)
    bank.sets.clear()
    run_until(ctl, lambda: bank.get("done_seq") == 2)
    assert bank.sets.index(("robot_state", 0)) < bank.sets.index(("done_seq", 2))


def test_article_pose_is_live_during_the_motion() -> None:
    ctl, bank, _, _ = article()
    send_article(bank, PART, speed=20)
    run(ctl, 0.4)
    assert bank.get("motion_status") == 1
    mid = pose_of(bank)
    assert not mid.is_close(HOME)
    assert not mid.is_close(PART)


def test_article_unreachable_target_is_an_error_without_motion() -> None:
    ctl, bank, backend, _ = article(model=SMALL)
    send_article(bank, FAR)
    ctl.tick(DT)
    assert bank.get("robot_mode") == 7
    assert bank.get("error_code") == SimErrorCode.UNREACHABLE
    assert bank.get("command") == 0
    assert bank.get("motion_status") == 0
    assert ctl.moves_started == 0
    run(ctl, 0.5)
    assert backend.tcp_pose() == HOME
    # The error persists until the operator clears it; a command written meanwhile is
    # not executed, and the reset discards it (issue 8: a reset never arms anything).
    send_article(bank, AIR.offset(dz=-200))
    run(ctl, 0.2)
    assert bank.get("robot_mode") == 7
    assert ctl.moves_started == 0
    ctl.clear_error()
    assert bank.get("robot_mode") == 5
    assert bank.get("error_code") == 0
    assert bank.get("command") == 0
    run(ctl, 0.2)
    assert bank.get("motion_status") == 0
    assert ctl.moves_started == 0
    # A command written after the reset runs normally.
    send_article(bank, AIR.offset(dz=-200))
    ctl.tick(DT)
    assert bank.get("command") == 0
    assert bank.get("motion_status") == 1


@pytest.mark.parametrize(("speed", "command"), [(100, 9), (0, 1)])
def test_article_invalid_command_or_speed(speed: int, command: int) -> None:
    ctl, bank, _, _ = article()
    send_article(bank, PART, command=command)
    bank.write(Table.HOLDING, 0x0206, [speed])  # raw: the codec would refuse speed 0
    ctl.tick(DT)
    assert bank.get("robot_mode") == 7
    assert bank.get("error_code") == SimErrorCode.INVALID_COMMAND
    assert bank.get("command") == 0
    assert ctl.moves_started == 0


def test_article_command_during_motion_waits_for_idle() -> None:
    ctl, bank, backend, _ = article()
    send_article(bank, PART)
    ctl.tick(DT)
    send_article(bank, AIR, command=2)
    run(ctl, 0.1)
    assert bank.get("command") == 2  # pending, not taken, not lost
    assert ctl.active_target == PART
    run_until(ctl, lambda: bank.get("command") == 0)
    assert ctl.moves_started == 2
    assert backend.tcp_pose().is_close(PART, mm=0.01)  # the first motion did finish
    run_until(ctl, lambda: bank.get("motion_status") == 0)
    assert pose_of(bank).is_close(AIR, mm=0.01, deg=0.01)


def test_article_command_during_initialisation_waits() -> None:
    ctl, bank, _, _ = article(initialise=False)
    send_article(bank, AIR)
    ctl.tick(DT)
    assert bank.get("command") == 1
    run_until(ctl, lambda: bank.get("command") == 0, limit_s=INIT_S + DT)
    assert bank.get("motion_status") == 1


def test_article_stop_is_taken_while_moving() -> None:
    ctl, bank, backend, _ = article()
    send_article(bank, PART, speed=20)
    run(ctl, 0.3)
    bank.write(Table.HOLDING, 0x0207, [3])
    ctl.tick(DT)
    assert bank.get("command") == 0
    # The arm brakes to rest (a stop takes time): moving until then, idle at rest.
    assert bank.get("motion_status") == 1
    assert not backend.is_settled()
    run_until(ctl, lambda: bank.get("motion_status") == 0, limit_s=1.0)
    assert backend.is_settled()
    stopped = pose_of(bank)
    run(ctl, 1.0)
    assert pose_of(bank) == stopped
    assert not stopped.is_close(PART)
    assert ctl.state == "idle"


def test_article_error_shows_moving_until_the_arm_is_at_rest() -> None:
    ctl, bank, backend, _ = article()
    send_article(bank, PART, speed=20)
    run(ctl, 0.3)
    ctl.press_estop()  # the error stops the arm: it brakes, it does not halt
    ctl.tick(DT)
    assert ctl.error_code != 0
    assert not backend.is_settled()
    assert bank.get("motion_status") == 1  # still moving while it brakes
    run_until(ctl, lambda: bank.get("motion_status") == 0, limit_s=1.0)
    assert backend.is_settled()


def test_article_stop_while_idle_just_clears() -> None:
    ctl, bank, _, _ = article()
    bank.write(Table.HOLDING, 0x0207, [3])
    ctl.tick(DT)
    assert bank.get("command") == 0
    assert bank.get("robot_mode") == 5


def test_article_slow_settling_keeps_moving_until_settled() -> None:
    backend = SlowSettlingBackend(MODEL, settle_time_s=1.0, invalidate_after_motions=None)
    ctl, bank, _, _ = article(backend=backend)
    send_article(bank, AIR)
    run_until(ctl, lambda: not backend.motion_running)
    assert bank.get("motion_status") == 1  # at the target, still oscillating
    took = run_until(ctl, lambda: bank.get("motion_status") == 0)
    assert took == pytest.approx(1.0, abs=2 * DT)


def test_article_backend_not_ready_keeps_the_command_pending() -> None:
    backend = LateReadyBackend(ready_after_s=0.3)
    ctl, bank, _, log = article(backend=backend)
    backend.invalidate()
    send_article(bank, AIR)
    ctl.tick(DT)
    assert backend.reinit_calls == 1
    assert bank.get("command") == 1  # queued, not acknowledged
    assert bank.get("motion_status") == 0
    run(ctl, 0.2)
    assert bank.get("command") == 1
    assert backend.reinit_calls == 1  # retried only after REINITIALIZE_RETRY_S
    took = run_until(ctl, lambda: bank.get("command") == 0)
    assert took <= 0.2
    assert bank.get("motion_status") == 1
    run_until(ctl, lambda: bank.get("motion_status") == 0)
    assert pose_of(bank).is_close(AIR, mm=0.01, deg=0.01)
    assert "sim.backend_reinitialize" in log.names()


def test_article_slow_settling_backend_invalidated_after_each_motion() -> None:
    backend = SlowSettlingBackend(MODEL, settle_time_s=0.2, invalidate_after_motions=1)
    ctl, bank, _, _ = article(backend=backend)
    move_article(ctl, bank, AIR)
    move_article(ctl, bank, PART)
    assert backend.reinitialize_count >= 2
    assert backend.rejected_commands == 0
    assert pose_of(bank).is_close(PART, mm=0.01, deg=0.01)


def test_article_robot_error_at_the_nth_move() -> None:
    ctl, bank, backend, log = article(faults=[RobotErrorFault(at_move=2, code=0x1F4)])
    move_article(ctl, bank, AIR)
    assert bank.get("robot_mode") == 5
    send_article(bank, PART)
    ctl.tick(DT)
    assert bank.get("motion_status") == 1  # acknowledged, then fails during the motion
    run_until(ctl, lambda: bank.get("robot_mode") == 7)
    assert bank.get("error_code") == 0x1F4
    # The arm brakes to rest, reported moving until then.
    run_until(ctl, lambda: bank.get("motion_status") == 0, limit_s=1.0)
    assert backend.is_settled()
    stopped = backend.tcp_pose()
    run(ctl, 1.0)
    assert backend.tcp_pose() == stopped
    assert not stopped.is_close(PART)
    assert ctl.error_code == 0x1F4
    assert ("warning", "sim.fault_fired") in [(lvl, ev) for lvl, ev, _ in log.events]


def test_article_motion_record_notes_the_tick_that_reported_the_end() -> None:
    ctl, bank, _, _ = article(faults=[RobotErrorFault(at_move=2, code=0x1F4)])
    send_article(bank, AIR)
    run_until(ctl, lambda: bank.get("motion_status") == 1)
    assert ctl.motion_log[-1].done_wall_time is None  # running: no end reported yet
    run_until(ctl, lambda: bank.get("motion_status") == 0)
    first = ctl.motion_log[-1]
    assert first.done_wall_time is not None
    assert first.done_wall_time >= first.wall_time
    # The second move fails with a robot error: it never reported an end.
    send_article(bank, PART)
    run_until(ctl, lambda: bank.get("robot_mode") == 7)
    assert [r.done_wall_time is None for r in ctl.motion_log] == [False, True]


def test_article_robot_error_code_must_fit_the_error_register() -> None:
    profile = robot_profile("article")
    with pytest.raises(ValueOutOfRangeError, match="error_code"):
        controller_for(
            profile,
            RegisterBank(profile),
            KinematicBackend(MODEL),
            MODEL,
            faults=[RobotErrorFault(at_move=1, code=70000)],
        )


def test_article_stall_never_completes_until_stopped() -> None:
    ctl, bank, _, _ = article(faults=[StallFault(at_move=1)])
    send_article(bank, PART)
    run(ctl, 0.5)
    frozen = pose_of(bank)
    run(ctl, 5.0)
    assert bank.get("motion_status") == 1
    assert bank.get("robot_mode") == 5
    assert pose_of(bank) == frozen
    assert not frozen.is_close(PART)
    assert not frozen.is_close(HOME)
    bank.write(Table.HOLDING, 0x0207, [3])
    ctl.tick(DT)
    assert bank.get("motion_status") == 0


def test_article_estop_at_move() -> None:
    ctl, bank, backend, _ = article(faults=[EstopFault(at_move=1)])
    send_article(bank, PART)
    run_until(ctl, lambda: bank.get("robot_mode") == 7)
    assert bank.get("error_code") == SimErrorCode.EMERGENCY_STOP
    assert not backend.tcp_pose().is_close(PART)
    run_until(ctl, lambda: bank.get("motion_status") == 0, limit_s=1.0)  # braked to rest
    assert backend.is_settled()
    assert ctl.estop_pressed
    ctl.clear_error()
    assert not ctl.estop_pressed
    assert bank.get("robot_mode") == 5


def test_article_estop_after_time() -> None:
    ctl, bank, _, _ = article(faults=[EstopFault(after_s=0.5)], initialise=False)
    run(ctl, 0.48)
    assert bank.get("robot_mode") == 5
    run(ctl, 0.04)
    assert bank.get("robot_mode") == 7
    assert bank.get("error_code") == SimErrorCode.EMERGENCY_STOP


def _close_article(ctl: RobotController, bank: RegisterBank, value: int) -> None:
    bank.write(Table.HOLDING, 0x0210, [value])
    run(ctl, 1.0)


def test_article_gripper_detects_the_part() -> None:
    ctl, bank, backend, _ = article()
    move_article(ctl, bank, PART)
    _close_article(ctl, bank, 1)
    assert bank.get("grasp_status") == 1
    assert backend.gripper_state().width_mm == pytest.approx(30.0)
    _close_article(ctl, bank, 0)
    assert bank.get("grasp_status") == 0


def test_article_gripper_in_the_air_grips_nothing() -> None:
    ctl, bank, _, _ = article()
    _close_article(ctl, bank, 1)
    assert bank.get("grasp_status") == 0


def test_article_grasp_miss() -> None:
    ctl, bank, _, _ = article(faults=[GraspMissFault(at_grasp=1)])
    move_article(ctl, bank, PART)
    _close_article(ctl, bank, 1)
    assert bank.get("grasp_status") == 0  # the fingers are on the part, no grip reported
    _close_article(ctl, bank, 0)
    _close_article(ctl, bank, 1)
    assert ctl.grasps == 2
    assert bank.get("grasp_status") == 1


def test_article_late_ack_delays_every_command() -> None:
    ctl, bank, _, _ = article(faults=[LateAckFault(delay_s=0.5)])
    send_article(bank, AIR)
    run(ctl, 0.48)
    assert bank.get("command") == 1
    assert bank.get("motion_status") == 0
    took = run_until(ctl, lambda: bank.get("command") == 0)
    assert took <= 0.04
    assert bank.get("motion_status") == 1


def test_article_late_ack_at_one_move_only() -> None:
    ctl, bank, _, _ = article(faults=[LateAckFault(delay_s=1.0, at_move=2)])
    send_article(bank, AIR)
    ctl.tick(DT)
    assert bank.get("command") == 0  # move 1 is on time
    run_until(ctl, lambda: bank.get("motion_status") == 0)
    send_article(bank, PART)
    took = run_until(ctl, lambda: bank.get("command") == 0)
    assert took == pytest.approx(1.0, abs=2 * DT)


def test_article_pose_that_cannot_be_encoded_is_an_error() -> None:
    # int16 x100 ends at 327.67. (The article's (0, 0, 400, ...) is out of a TM5's reach.)
    backend = KinematicBackend(MODEL, home=Pose(400, 0, 300, 180, 0, 90))
    profile = robot_profile("article")
    bank = RegisterBank(profile)
    ctl = controller_for(profile, bank, backend, MODEL, init_time_s=INIT_S, log=ListLogger())
    run(ctl, INIT_S)
    assert bank.get("robot_mode") == 7
    assert bank.get("error_code") == SimErrorCode.POSE_OUT_OF_RANGE
    # The encodable range rule: the registers hold the pose saturated at the range's end.
    assert bank.get("tcp_x") == pytest.approx(327.67)


def test_dt_must_be_valid() -> None:
    ctl, _, _, _ = article()
    with pytest.raises(ValueError, match="dt"):
        ctl.tick(-0.1)
    with pytest.raises(ValueError, match="dt"):
        ctl.tick(math.nan)


# -- tmflow: sequence handshake ----------------------------------------------------------


def test_tmflow_project_runs_once_initialised_and_heartbeat_ticks() -> None:
    ctl, bank, _, _ = tmflow(initialise=False)
    assert bank.get("project_running") is False
    run(ctl, INIT_S)
    assert bank.get("project_running") is True
    assert bank.get("ma_mode") == 1
    beat = int(bank.get("heartbeat"))
    run(ctl, 5 * DT)
    assert bank.get("heartbeat") == beat + 5


def test_tmflow_heartbeat_counts_every_program_loop_and_wraps() -> None:
    from tmmaster import tmscript

    ctl, bank, _, _ = tmflow()
    beat = int(bank.get("heartbeat"))
    run(ctl, 5 * DT)
    assert int(bank.get("heartbeat")) == beat + 5  # one idle loop per tick
    # The program's own expression, written with an int16 preset: 0..32767.
    assert "hb = (hb + 1) % 32768" in (ctl.program_text or "")  # type: ignore[attr-defined]
    assert tmscript.evaluate("(32767 + 1) % 32768")[0] == 0


def test_tmflow_sequence_handshake() -> None:
    ctl, bank, _, log = tmflow()
    send_tmflow(bank, 1)
    assert bank.get("ack_seq") == 0  # nothing before the tick
    ctl.tick(DT)
    assert bank.get("ack_seq") == 1
    assert bank.get("robot_state") == 1
    assert bank.get("done_seq") == 0
    finish_tmflow(ctl, bank, 1)
    assert bank.get("result_code") == 0
    assert pose_of(bank).is_close(PART, mm=0.001, deg=0.001)
    names = log.names()
    assert names.index("sim.motion_started") < names.index("sim.motion_done")


def test_tmflow_duplicate_seq_is_not_executed_twice() -> None:
    ctl, bank, backend, _ = tmflow()
    send_tmflow(bank, 1)
    finish_tmflow(ctl, bank, 1)
    send_tmflow(bank, 1, target=AIR)  # a resent write: same seq, even with new data
    run(ctl, 1.0)
    assert ctl.moves_started == 1
    assert backend.tcp_pose().is_close(PART, mm=0.001)


def test_tmflow_seq_zero_is_never_executed() -> None:
    ctl, bank, _, _ = tmflow()
    send_tmflow(bank, 0)
    run(ctl, 0.5)
    assert ctl.moves_started == 0
    assert bank.get("ack_seq") == 0


def test_tmflow_takes_only_the_next_seq() -> None:
    ctl, bank, _, _ = tmflow()
    send_tmflow(bank, 1)
    finish_tmflow(ctl, bank, 1)
    # A seq put back by a withdrawing master (behind ack_seq) and a skipped one are not
    # new commands; only ack_seq + 1 is.
    for stale in (32767, 3):
        send_tmflow(bank, stale, target=AIR)
        run(ctl, 0.5)
        assert ctl.moves_started == 1
        assert bank.get("ack_seq") == 1
    send_tmflow(bank, 2, target=AIR)
    finish_tmflow(ctl, bank, 2)
    assert ctl.moves_started == 2


def test_tmflow_seq_walks_32766_32767_1() -> None:
    # As if 32766 commands had been taken before (ack_seq survives project restarts).
    ctl, bank, _, _ = tmflow(initial_seq=32766)
    assert (bank.get("seq"), bank.get("ack_seq"), bank.get("done_seq")) == (32766, 32766, 32766)
    send_tmflow(bank, 32767, target=AIR)
    finish_tmflow(ctl, bank, 32767)
    send_tmflow(bank, 1, target=PART)
    finish_tmflow(ctl, bank, 1)
    assert ctl.moves_started == 2
    assert bank.get("ack_seq") == 1


def write_raw_seq(bank: RegisterBank, raw: int) -> None:
    """A master that treats seq as uint16 writes the raw word, e.g. 32768 after 32767."""
    bank.write(Table.HOLDING, bank.register_map.field("seq").address, [raw])


@pytest.mark.parametrize("raw", [32768, 65535, 0])
def test_tmflow_uint16_style_seq_is_never_taken(raw: int) -> None:
    ctl, bank, _, _ = tmflow(initial_seq=32766)
    send_tmflow(bank, 32767, target=AIR)
    finish_tmflow(ctl, bank, 32767)
    # The block a uint16 master would send next: 32768 (or 65535 -> "0", or 0) as seq.
    send_tmflow(bank, 1, target=PART)
    write_raw_seq(bank, raw)  # the program reads it as int16: -32768, -1, 0
    run(ctl, 0.5)
    assert ctl.moves_started == 1
    assert bank.get("ack_seq") == 32767
    assert bank.get("robot_state") == 0
    # The right number is still taken afterwards.
    write_raw_seq(bank, 1)
    finish_tmflow(ctl, bank, 1)
    assert ctl.moves_started == 2


def test_tmflow_initial_seq_is_checked() -> None:
    with pytest.raises(ValueError, match="initial_seq"):
        tmflow(initial_seq=32768)


def test_tmflow_unreachable_is_a_program_error_not_a_robot_error() -> None:
    ctl, bank, _, _ = tmflow(model=SMALL)
    send_tmflow(bank, 1, target=FAR)
    ctl.tick(DT)
    assert bank.get("ack_seq") == 1
    assert bank.get("robot_state") == 2
    assert bank.get("result_code") == 1
    assert bank.get("done_seq") == 0
    assert bank.get("error") is False
    assert ctl.moves_started == 0
    # The program takes the next command.
    send_tmflow(bank, 2, target=Pose(250, 0, 250, 180, 0, 90))
    finish_tmflow(ctl, bank, 2)
    assert bank.get("result_code") == 0


@pytest.mark.parametrize(
    ("command", "speed", "target"),
    [(7, 100, PART), (1, 0, PART)],
)
def test_tmflow_invalid_command(command: int, speed: int, target: Pose) -> None:
    ctl, bank, _, _ = tmflow()
    send_tmflow(bank, 1, command=command, target=target)
    bank.write(Table.HOLDING, 9012, [speed])  # raw: the codec would refuse speed 0
    ctl.tick(DT)
    assert bank.get("ack_seq") == 1
    assert bank.get("robot_state") == 2
    assert bank.get("result_code") == 2
    assert bank.get("done_seq") == 0


def test_a_garbage_collection_inside_a_tick_does_not_spend_the_programs_budget(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A collection the program's tick happens to trigger, as slow as one in a process
    # with a large heap (30 ms of CPU, over the tick's 20 ms budget): the program still
    # takes the command written before that tick, in that tick.
    ctl, bank, _, _ = tmflow()
    send_tmflow(bank, 1, command=7, target=PART)  # an invalid command: answered at once
    collections: list[str] = []

    def slow_collection(phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            collections.append(phase)
            spent = time.thread_time() + 0.03
            while time.thread_time() < spent:
                pass

    read = bank.read

    def read_then_collect(*args: Any, **kwargs: Any) -> list[int]:
        if not collections:
            gc.collect()
        return read(*args, **kwargs)

    monkeypatch.setattr(bank, "read", read_then_collect)
    gc.callbacks.append(slow_collection)
    try:
        ctl.tick(DT)
    finally:
        gc.callbacks.remove(slow_collection)
    assert collections == ["start"]  # the collection fell in the tick
    assert bank.get("ack_seq") == 1
    assert bank.get("result_code") == 2


def test_tmflow_command_none_is_a_cancel_that_uses_the_number_up() -> None:
    ctl, bank, _, _ = tmflow()
    send_tmflow(bank, 1, command=0, target=PART)
    ctl.tick(DT)
    assert bank.get("ack_seq") == 1
    assert bank.get("robot_state") == 2
    assert bank.get("result_code") == 5  # cancelled
    assert bank.get("done_seq") == 0
    # A late copy of the original frame (same seq, command ptp) can never run now.
    send_tmflow(bank, 1, command=1, target=PART)
    run(ctl, 0.5)
    assert ctl.moves_started == 0
    # The next number runs normally.
    send_tmflow(bank, 2, command=1, target=PART)
    finish_tmflow(ctl, bank, 2)
    assert ctl.moves_started == 1


def test_tmflow_nan_target_is_invalid() -> None:
    ctl, bank, _, _ = tmflow()
    send_tmflow(bank, 1)
    bank.write(Table.HOLDING, 9000, [0x7FC0, 0x0000])  # float32 NaN in target_x
    ctl.tick(DT)
    assert bank.get("result_code") == 2


def test_tmflow_command_during_motion_waits() -> None:
    ctl, bank, _, _ = tmflow()
    send_tmflow(bank, 1, target=PART)
    ctl.tick(DT)
    send_tmflow(bank, 2, target=AIR)
    run(ctl, 0.1)
    assert bank.get("ack_seq") == 1
    run_until(ctl, lambda: bank.get("ack_seq") == 2)
    assert bank.get("done_seq") == 1
    finish_tmflow(ctl, bank, 2)
    assert pose_of(bank).is_close(AIR, mm=0.001, deg=0.001)


def test_tmflow_accel_time_register_slows_the_motion() -> None:
    ctl, bank, _, _ = tmflow()
    send_tmflow(bank, 1, target=AIR, accel_ms=0)
    quick = finish_tmflow(ctl, bank, 1)
    send_tmflow(bank, 2, target=HOME, accel_ms=2000)
    slow = finish_tmflow(ctl, bank, 2)
    assert slow > quick + 0.5


def test_tmflow_gripper_close_reports_grasp_status() -> None:
    ctl, bank, _, _ = tmflow()
    send_tmflow(bank, 1, target=PART)
    finish_tmflow(ctl, bank, 1)
    send_tmflow(bank, 2, command=4)
    ctl.tick(DT)
    assert bank.get("robot_state") == 1
    finish_tmflow(ctl, bank, 2)
    assert bank.get("grasp_status") == 1
    send_tmflow(bank, 3, command=3)
    finish_tmflow(ctl, bank, 3)
    assert bank.get("grasp_status") == 0


def test_tmflow_gripper_record_notes_the_tick_that_reported_the_end() -> None:
    ctl, bank, _, _ = tmflow()
    send_tmflow(bank, 1, command=4)
    ctl.tick(DT)
    assert ctl.motion_log[-1].kind == "gripper_close"
    assert ctl.motion_log[-1].done_wall_time is None
    finish_tmflow(ctl, bank, 1)
    assert ctl.motion_log[-1].done_wall_time is not None


def test_tmflow_gripper_close_on_nothing_is_done_but_empty() -> None:
    ctl, bank, _, _ = tmflow()
    send_tmflow(bank, 1, command=4)
    finish_tmflow(ctl, bank, 1)
    assert bank.get("grasp_status") == 0
    assert bank.get("result_code") == 0


def test_tmflow_grasp_miss() -> None:
    ctl, bank, _, _ = tmflow(faults=[GraspMissFault()])
    send_tmflow(bank, 1, target=PART)
    finish_tmflow(ctl, bank, 1)
    send_tmflow(bank, 2, command=4)
    finish_tmflow(ctl, bank, 2)
    assert bank.get("grasp_status") == 0
    send_tmflow(bank, 3, command=3)
    finish_tmflow(ctl, bank, 3)
    send_tmflow(bank, 4, command=4)
    finish_tmflow(ctl, bank, 4)
    assert bank.get("grasp_status") == 1


def test_tmflow_robot_error_stops_the_project() -> None:
    ctl, bank, backend, _ = tmflow(faults=[RobotErrorFault(at_move=1, code=0x1F4)])
    send_tmflow(bank, 1, target=PART)
    run_until(ctl, lambda: bank.get("error") is True)
    assert bank.get("last_error_code") == 0x1F4
    assert bank.get("project_running") is False
    assert bank.get("ack_seq") == 1
    assert bank.get("done_seq") == 0
    beat = bank.get("heartbeat")
    run_until(ctl, backend.is_settled, limit_s=1.0)  # the arm brakes to rest
    stopped = backend.tcp_pose()
    run(ctl, 1.0)
    assert bank.get("heartbeat") == beat  # the program no longer runs
    assert backend.tcp_pose() == stopped
    send_tmflow(bank, 2, target=AIR)
    run(ctl, 0.2)
    assert bank.get("ack_seq") == 1
    # Play is refused while the error is active.
    bank.write(Table.COIL, 7104, [1])
    ctl.tick(DT)
    assert bank.get("play_pause") is False
    assert bank.get("project_running") is False
    ctl.clear_error()
    assert bank.get("error") is False
    assert bank.get("last_error_code") == 0x1F4  # the *last* error code stays readable
    bank.write(Table.COIL, 7104, [1])
    ctl.tick(DT)
    assert bank.get("project_running") is True
    # The start-up rule: the command written while the project was stopped is consumed as
    # cancelled, never executed (issue 8); seq 1 does not run again either.
    assert bank.get("ack_seq") == 2
    assert bank.get("result_code") == 5
    run(ctl, 0.5)
    assert ctl.moves_started == 1
    send_tmflow(bank, 3, target=AIR)
    finish_tmflow(ctl, bank, 3)
    assert ctl.moves_started == 2


def test_tmflow_estop_after_time() -> None:
    ctl, bank, _, _ = tmflow(faults=[EstopFault(after_s=0.3)])
    run(ctl, 0.3 - INIT_S - DT)
    assert bank.get("estop") is False
    run(ctl, 0.02)
    assert bank.get("estop") is True
    assert bank.get("error") is True
    assert bank.get("project_running") is False
    assert bank.get("last_error_code") == SimErrorCode.EMERGENCY_STOP
    ctl.clear_error()
    assert bank.get("estop") is False
    assert bank.get("error") is False


def test_tmflow_estop_at_move() -> None:
    ctl, bank, backend, _ = tmflow(faults=[EstopFault(at_move=1)])
    send_tmflow(bank, 1)
    run_until(ctl, lambda: bank.get("estop") is True)
    assert bank.get("project_running") is False
    assert not backend.tcp_pose().is_close(PART)


def test_tmflow_stall_keeps_the_program_busy() -> None:
    ctl, bank, _, _ = tmflow(faults=[StallFault(at_move=1)])
    send_tmflow(bank, 1)
    run(ctl, 5.0)
    assert bank.get("robot_state") == 1
    assert bank.get("done_seq") == 0
    assert bank.get("error") is False


def test_tmflow_stop_button_stops_the_project_and_play_restarts_it() -> None:
    ctl, bank, backend, _ = tmflow()
    send_tmflow(bank, 1, target=PART)
    run(ctl, 0.2)
    bank.write(Table.COIL, 7105, [1])
    ctl.tick(DT)
    assert bank.get("stop_project") is False  # a button springs back
    assert bank.get("project_running") is False
    run_until(ctl, backend.is_settled, limit_s=1.0)  # the arm brakes to rest
    stopped = backend.tcp_pose()
    run(ctl, 1.0)
    assert backend.tcp_pose() == stopped
    assert bank.get("done_seq") == 0
    bank.write(Table.COIL, 7104, [1])
    ctl.tick(DT)
    assert bank.get("play_pause") is False
    assert bank.get("project_running") is True
    # The start-up rule: the command at ack_seq never finished, so the state says error
    # (a master that polls only now reads the failure), and nothing is redone.
    assert bank.get("robot_state") == 2
    run(ctl, 0.5)
    assert ctl.moves_started == 1  # seq 1 was acknowledged before the stop: not redone


def test_tmflow_late_ack() -> None:
    ctl, bank, _, _ = tmflow(faults=[LateAckFault(delay_s=0.3)])
    send_tmflow(bank, 1, command=4)
    run(ctl, 0.28)
    assert bank.get("ack_seq") == 0
    took = run_until(ctl, lambda: bank.get("ack_seq") == 1)
    assert took <= 0.04


def test_tmflow_backend_not_ready() -> None:
    # The program takes the command; the move waits in the buffer for the backend.
    backend = LateReadyBackend(ready_after_s=0.2)
    ctl, bank, _, _ = tmflow(backend=backend)
    backend.invalidate()
    send_tmflow(bank, 1, target=AIR)
    run(ctl, 0.1)
    assert ctl.moves_started == 0
    assert backend.reinit_calls == 1
    finish_tmflow(ctl, bank, 1)
    assert pose_of(bank).is_close(AIR, mm=0.001, deg=0.001)


# -- grippers -----------------------------------------------------------------------------


def blog(
    backend: KinematicBackend, *, faults: Sequence[Fault] = (), step_backend: bool = True
) -> tuple[Blog2FG7Device, RegisterBank]:
    profile = gripper_profile("blog-2fg7")
    bank = RegisterBank(profile)
    device = Blog2FG7Device(
        profile,
        bank,
        backend,
        faults=faults,
        init_time_s=INIT_S,
        step_backend=step_backend,
        log=ListLogger(),
    )
    return device, bank


def blog_move(device: Blog2FG7Device, bank: RegisterBank, width_mm: float) -> None:
    bank.write(Table.HOLDING, 0, words(bank.register_map, {"force": 40, "width": width_mm}))
    bank.write(Table.HOLDING, 2, [16])


def test_blog_gripper_activates() -> None:
    device, bank = blog(KinematicBackend(MODEL, home=PART))
    assert bank.get("gripper_status") == 1
    run(device, INIT_S)
    assert bank.get("gripper_status") == 3
    assert bank.get("object_status") == 3


def test_blog_gripper_grips_the_part() -> None:
    device, bank = blog(KinematicBackend(MODEL, home=PART))
    run(device, INIT_S)
    blog_move(device, bank, 10.0)
    assert bank.get("control") == 16
    device.tick(DT)
    assert bank.get("control") == 0  # taken
    assert bank.get("motion_state") == 1
    assert bank.get("object_status") == 0
    run_until(device, lambda: bank.get("motion_state") == 0)
    assert bank.get("object_status") == 2
    blog_move(device, bank, 160.0)
    run(device, DT)
    run_until(device, lambda: bank.get("motion_state") == 0)
    assert bank.get("object_status") == 3


def test_blog_gripper_in_the_air_and_grasp_miss() -> None:
    device, bank = blog(KinematicBackend(MODEL))
    run(device, INIT_S)
    blog_move(device, bank, 10.0)
    run(device, 1.0)
    assert bank.get("object_status") == 3
    device, bank = blog(KinematicBackend(MODEL, home=PART), faults=[GraspMissFault()])
    run(device, INIT_S)
    blog_move(device, bank, 10.0)
    run(device, 1.0)
    assert bank.get("object_status") == 3


def test_blog_gripper_stop() -> None:
    backend = KinematicBackend(MODEL)
    device, bank = blog(backend)
    run(device, INIT_S)
    blog_move(device, bank, 1.0)
    run(device, 0.1)
    bank.write(Table.HOLDING, 2, [0])
    device.tick(DT)
    width = backend.gripper_state().width_mm
    run(device, 0.5)
    assert backend.gripper_state().width_mm == width
    assert 1.0 < width < 39.0
    assert bank.get("motion_state") == 0


def onrobot(
    backend: KinematicBackend, *, faults: Sequence[Fault] = (), **options: Any
) -> tuple[OnRobot2FG7Device, RegisterBank]:
    profile = gripper_profile("onrobot-2fg7")
    bank = RegisterBank(profile)
    device = OnRobot2FG7Device(
        profile, bank, backend, faults=faults, init_time_s=INIT_S, log=ListLogger(), **options
    )
    run(device, INIT_S)
    return device, bank


def onrobot_grip(
    bank: RegisterBank, width_mm: float, *, command: int = 1, speed: int = 100, force: int = 60
) -> None:
    values = {"target_width": width_mm, "target_force": force, "target_speed": speed}
    bank.write(Table.HOLDING, 0, [*words(bank.register_map, values), command])


def busy(bank: RegisterBank) -> bool:
    return bank.register_map.field("status").bit(int(bank.get("status")), "busy")


def gripped(bank: RegisterBank) -> bool:
    return bank.register_map.field("status").bit(int(bank.get("status")), "grip_detected")


def test_onrobot_presets() -> None:
    _, bank = onrobot(KinematicBackend(MODEL))
    assert bank.get("product_code") == 0xC0
    assert [
        bank.get(f"{m}_{k}_width") for k in ("external", "internal") for m in ("min", "max")
    ] == [
        1.0,
        39.0,
        35.0,
        73.0,
    ]
    assert bank.get("external_width") == 39.0
    assert bank.get("internal_width") == 73.0
    assert not busy(bank)


def test_onrobot_grip_external_on_the_part() -> None:
    device, bank = onrobot(KinematicBackend(MODEL, home=PART))
    onrobot_grip(bank, 10.0)
    device.tick(DT)
    assert bank.get("command") == 0
    assert busy(bank)
    run_until(device, lambda: not busy(bank))
    assert gripped(bank)
    assert bank.get("external_width") == 30.0
    # Signed, negative while closing on the object (OnRobot's fixture seeds -40).
    assert bank.get("force") == -60
    assert bank.read(Table.HOLDING, 263, 1) == [65536 - 60]


@pytest.mark.parametrize(("requested", "applied"), [(0, 20), (5, 20), (60, 60), (140, 100)])
def test_onrobot_force_zero_is_the_minimum_and_max_force_is_the_ceiling(
    requested: int, applied: int
) -> None:
    device, bank = onrobot(KinematicBackend(MODEL, home=PART))
    assert bank.get("max_force") == 100  # the default power setting's ceiling (fixture)
    onrobot_grip(bank, 10.0, force=requested)
    device.tick(DT)
    run_until(device, lambda: not busy(bank))
    assert bank.get("force") == -applied


def test_onrobot_serves_the_official_fixtures_identity_registers() -> None:
    _, bank = onrobot(KinematicBackend(MODEL))
    assert bank.read(Table.HOLDING, 0x0600, 1) == [0xC0]
    assert bank.read(Table.HOLDING, 0x0604, 2) == [0x0100, 33]
    assert bank.read(Table.HOLDING, 0x0404, 4) == [14, 100, 0, 95]
    assert bank.read(Table.HOLDING, 0x0220, 10)[0] == 0xB422
    _, bank14 = onrobot(KinematicBackend(MODEL), product_code=0xC1)
    assert bank14.read(Table.HOLDING, 0x0600, 1) == [0xC1]
    assert bank14.read(Table.HOLDING, 0x0604, 2) == [0x0101, 21]
    assert bank14.read(Table.HOLDING, 0x0407, 1) == [196]
    with pytest.raises(ValueError, match="product_code"):
        onrobot(KinematicBackend(MODEL), product_code=0x20)


def test_onrobot_grip_in_the_air_and_grasp_miss() -> None:
    device, bank = onrobot(KinematicBackend(MODEL))
    onrobot_grip(bank, 10.0)
    device.tick(DT)
    run_until(device, lambda: not busy(bank))
    assert not gripped(bank)
    assert bank.get("external_width") == 10.0
    device, bank = onrobot(KinematicBackend(MODEL, home=PART), faults=[GraspMissFault()])
    onrobot_grip(bank, 10.0)
    device.tick(DT)
    run_until(device, lambda: not busy(bank))
    assert not gripped(bank)


def test_onrobot_speed_mapping_drives_the_fingers() -> None:
    device, _ = onrobot(KinematicBackend(MODEL))
    # Target speed is 1..100 %.
    assert device.speed_mm_s(1) == pytest.approx(16.0)
    assert device.speed_mm_s(100) == pytest.approx(450.0)
    assert device.speed_mm_s(50.5) == pytest.approx(233.0)
    slow_device, slow_bank = onrobot(KinematicBackend(MODEL))
    onrobot_grip(slow_bank, 7.0, speed=1)  # 32 mm at 16 mm/s: 2 s
    slow_device.tick(DT)
    took = run_until(slow_device, lambda: not busy(slow_bank))
    assert took == pytest.approx(2.0, abs=2 * DT)


def test_onrobot_internal_grip_and_stop() -> None:
    backend = KinematicBackend(MODEL)
    device, bank = onrobot(backend)
    onrobot_grip(bank, 40.0, command=2, speed=10)  # internal 40 mm = external 6 mm
    device.tick(DT)
    run(device, 0.5)
    bank.write(Table.HOLDING, 3, [3])
    device.tick(DT)
    assert bank.get("command") == 0
    assert not busy(bank)
    width = backend.gripper_state().width_mm
    run(device, 0.5)
    assert backend.gripper_state().width_mm == width > 6.0
    onrobot_grip(bank, 40.0, command=2)
    device.tick(DT)
    run_until(device, lambda: not busy(bank))
    assert bank.get("internal_width") == 40.0
    assert bank.get("external_width") == 6.0


def test_robot_and_gripper_share_one_backend() -> None:
    backend = KinematicBackend(MODEL)
    ctl, robot_bank, _, _ = tmflow(backend=backend)
    profile = gripper_profile("onrobot-2fg7")
    gripper_bank = RegisterBank(profile)
    gripper = OnRobot2FG7Device(
        profile, gripper_bank, backend, init_time_s=0.0, step_backend=False, log=ListLogger()
    )
    devices: list[Tickable] = [ctl, gripper]
    send_tmflow(robot_bank, 1, target=PART)
    run_until(devices, lambda: robot_bank.get("done_seq") == 1)
    onrobot_grip(gripper_bank, 10.0)
    run(devices, DT)
    run_until(devices, lambda: not busy(gripper_bank))
    assert gripped(gripper_bank)
    send_tmflow(robot_bank, 2, target=AIR)
    run_until(devices, lambda: robot_bank.get("done_seq") == 2)
    held = next(o for o in backend.objects() if o.name == "part")
    assert held.held
    assert held.pose.is_close(AIR, mm=0.001)


# -- run-time fault injection -------------------------------------------------------------


def test_injected_faults_count_from_the_injection() -> None:
    ctl, bank, _, _ = article()
    move_article(ctl, bank, AIR)
    ctl.inject(StallFault(at_move=1))  # the *next* motion
    send_article(bank, PART)
    run(ctl, 3.0)
    assert bank.get("motion_status") == 1
    bank.write(Table.HOLDING, 0x0207, [3])
    ctl.tick(DT)
    ctl.inject(EstopFault(after_s=0.2))
    run(ctl, 0.18)
    assert bank.get("robot_mode") == 5
    run(ctl, 0.04)
    assert bank.get("error_code") == SimErrorCode.EMERGENCY_STOP


def test_clear_faults_forgets_pending_faults() -> None:
    ctl, bank, _, _ = article(faults=[RobotErrorFault(at_move=1), GraspMissFault()])
    ctl.clear_faults()
    move_article(ctl, bank, PART)
    assert bank.get("robot_mode") == 5
    _close_article(ctl, bank, 1)
    assert bank.get("grasp_status") == 1


def test_network_faults_are_not_the_controllers() -> None:
    ctl, _, _, _ = article()
    with pytest.raises(ValueError, match="network fault"):
        ctl.inject(parse_fault("slow_responses:delay_s=1"))


def test_gripper_inject_grasp_miss() -> None:
    device, bank = onrobot(KinematicBackend(MODEL, home=PART))
    onrobot_grip(bank, 10.0)
    device.tick(DT)
    run_until(device, lambda: not busy(bank))
    assert gripped(bank)
    device.inject(GraspMissFault())
    onrobot_grip(bank, 5.0)  # squeeze again: the next close
    device.tick(DT)
    run(device, 0.2)
    assert not gripped(bank)
    device.clear_faults()


def test_tmflow_accel_time_beyond_its_maximum_is_an_invalid_command() -> None:
    # docs/tmflow-program.md, check M2: accel_time 0..10000 ms. A raw write can hold more.
    ctl, bank, _, _ = tmflow()
    send_tmflow(bank, 1, target=AIR)
    bank.write(Table.HOLDING, bank.register_map.field("accel_time").address, [10001])
    ctl.tick(DT)
    assert bank.get("ack_seq") == 1
    assert (bank.get("robot_state"), bank.get("result_code")) == (2, 2)
    assert ctl.moves_started == 0


# -- the backend's own rejection and a motion lost on re-initialise (issue 9 item 5) --------


class RejectingBackend(KinematicBackend):
    """Refuses every motion with the given reason, as a backend with joint limits would."""

    def __init__(self, reason: RejectReason) -> None:
        super().__init__(MODEL)
        self.reason: RejectReason = reason

    def start_motion(
        self, target: Pose, *, motion: MotionType, speed_percent: float, accel_time_s: float
    ) -> float:
        raise MotionRejectedError(self.reason, f"{target} rejected: {self.reason}")


@pytest.mark.parametrize(
    ("reason", "code"),
    [
        ("reach", SimErrorCode.UNREACHABLE),
        ("joint_limit", SimErrorCode.JOINT_LIMIT),
        ("singularity", SimErrorCode.SINGULARITY),
    ],
)
def test_article_backend_rejection_is_an_error_with_the_reasons_code(
    reason: RejectReason, code: SimErrorCode
) -> None:
    profile = robot_profile("article")
    bank = RecordingBank(profile)
    log = ListLogger()
    backend = RejectingBackend(reason)
    ctl = controller_for(profile, bank, backend, MODEL, init_time_s=INIT_S, log=log)
    run(ctl, INIT_S)
    bank.sets.clear()
    send_article(bank, AIR)
    ctl.tick(DT)
    assert bank.get("error_code") == code
    assert bank.get("robot_mode") == 7
    assert bank.get("motion_status") == 0
    assert ctl.moves_started == 0
    # Error first, acknowledgement last; moving (motion_status = 1) never shows.
    names = [name for name, _ in bank.sets]
    assert names.index("error_code") < names.index("command")
    assert ("motion_status", 1) not in bank.sets
    assert any(e[1] == "sim.command_rejected" and e[2].get("reason") == reason for e in log.events)


def test_tmflow_a_target_the_model_cannot_reach_is_result_unreachable() -> None:
    # The program's inversekin() answers first: nothing reaches a motion function.
    ctl, bank, _, _ = tmflow()
    send_tmflow(bank, 1, target=Pose(2000, 0, 300, 180, 0, 90))
    ctl.tick(DT)
    assert bank.get("ack_seq") == 1
    assert (bank.get("result_code"), bank.get("robot_state")) == (1, 2)
    assert bank.get("done_seq") == 0
    assert bank.get("error") is False
    assert ctl.moves_started == 0


def test_tmflow_a_motion_the_backend_refuses_is_an_error_stop() -> None:
    # A target the model takes but the physics refuses reaches the motion function: a
    # motion error stops the project (errorstop reports the command failed).
    ctl, bank, _, _ = tmflow(backend=RejectingBackend("joint_limit"))
    send_tmflow(bank, 1, target=AIR)
    run(ctl, 2 * DT)
    assert bank.get("ack_seq") == 1
    assert (bank.get("result_code"), bank.get("robot_state")) == (3, 2)
    assert bank.get("done_seq") == 0
    assert bank.get("error") is True
    assert bank.get("project_running") is False
    assert ctl.moves_started == 0


def test_article_motion_lost_on_reinitialise_is_an_error_never_done() -> None:
    backend = SlowSettlingBackend(
        MODEL, settle_time_s=0.0, invalidate_after_motions=None, motion_survives_reinit=False
    )
    ctl, bank, _, log = article(backend=backend)
    send_article(bank, AIR)
    run(ctl, 0.2)
    assert bank.get("motion_status") == 1
    backend.invalidate()
    ctl.tick(DT)
    assert backend.reinitialize_count == 1
    assert bank.get("error_code") == SimErrorCode.MOTION_LOST
    run_until(ctl, lambda: bank.get("motion_status") == 0, limit_s=1.0)  # at rest
    assert "sim.motion_lost" in log.names()
    run(ctl, 2.0)
    assert not backend.tcp_pose().is_close(AIR, mm=1.0)  # stopped where it was
    assert "sim.motion_done" not in log.names()


def test_tmflow_motion_lost_on_reinitialise_fails_the_command() -> None:
    backend = SlowSettlingBackend(
        MODEL, settle_time_s=0.0, invalidate_after_motions=None, motion_survives_reinit=False
    )
    ctl, bank, _, log = tmflow(backend=backend)
    send_tmflow(bank, 1, target=AIR)
    run(ctl, 0.2)
    assert bank.get("robot_state") == 1
    backend.invalidate()
    ctl.tick(DT)
    # A motion error: the project stops, errorstop reports the command failed.
    assert (bank.get("result_code"), bank.get("robot_state")) == (3, 2)
    run(ctl, 2.0)
    assert bank.get("done_seq") == 0  # never reported done
    assert "sim.motion_done" not in log.names()
    # After the operator's reset and Play, the program takes the next command.
    ctl.clear_error()
    ctl.press_play()
    run(ctl, DT)
    send_tmflow(bank, 2, target=AIR)
    finish_tmflow(ctl, bank, 2)
    assert pose_of(bank).is_close(AIR, mm=0.01, deg=0.01)


def test_a_motion_that_survives_reinitialise_completes() -> None:
    backend = SlowSettlingBackend(MODEL, settle_time_s=0.0, invalidate_after_motions=None)
    ctl, bank, _, log = article(backend=backend)
    send_article(bank, AIR)
    run(ctl, 0.2)
    backend.invalidate()
    run_until(ctl, lambda: bank.get("motion_status") == 0)
    assert backend.reinitialize_count == 1
    assert bank.get("error_code") == 0
    assert pose_of(bank).is_close(AIR, mm=0.01, deg=0.01)
    assert "sim.motion_lost" not in log.names()


class SignedZeroFlangeBackend(KinematicBackend):
    """A backend whose flange pose is set by the test (a zero of either sign)."""

    flange = Pose(300.0, -200.0, 300.0, 180.0, 0.0, 90.0)

    def flange_pose(self) -> Pose | None:
        return self.flange


def test_tm_table_stays_what_the_robot_publishes_at_every_tick() -> None:
    # An idle robot's Techman table is unchanged from tick to tick; whatever changed its
    # words meanwhile is overwritten at the next tick, and the clock goes on.
    backend = SignedZeroFlangeBackend(MODEL)
    ctl, bank, _, _ = tmflow(backend=backend)
    run(ctl, 1.0)
    flange_x, joint_1, up = bank.get("flange_x"), bank.get("joint_1"), bank.get("up_seconds")
    tcp = pose_of(bank)
    bank.set("tcp_z", tcp.z + 10.0)
    bank.set("flange_x", flange_x + 10.0)
    bank.set("joint_1", joint_1 + 12.0)
    bank.set("robot_link", False)
    bank.set("tm_robot_state", 2)
    bank.set("running_hours", 3)
    ctl.tick(DT)
    assert pose_of(bank) == tcp
    assert bank.get("flange_x") == flange_x
    assert bank.get("joint_1") == joint_1
    assert bank.get("robot_link") is True
    assert bank.get("tm_robot_state") == 0
    assert bank.get("running_hours") == 0
    run(ctl, 1.0)
    assert bank.get("up_seconds") == up + 1
    # The sign of a zero is published too (a float32 register keeps it).
    rx = bank.field("flange_rx")
    backend.flange = Pose(300.0, -200.0, 300.0, -0.0, 0.0, 90.0)
    ctl.tick(DT)
    assert bank.read(rx.table, rx.address, 2) == encode(rx, -0.0)
    backend.flange = Pose(300.0, -200.0, 300.0, 0.0, 0.0, 90.0)
    ctl.tick(DT)
    assert bank.read(rx.table, rx.address, 2) == encode(rx, 0.0)
    ctl.press_estop()
    ctl.tick(DT)
    assert bank.get("tm_robot_state") == 4


class SetTcpBackend(KinematicBackend):
    """A backend whose TCP pose is set by the test, held still between ticks."""

    tcp = Pose(300.0, -200.0, 300.0, 180.0, 0.0, 90.0)

    def tcp_pose(self) -> Pose:
        return self.tcp


def test_a_still_pose_is_published_again_when_a_zero_changes_sign() -> None:
    # The same pose tick after tick is published unchanged; a zero's sign is published.
    backend = SetTcpBackend(MODEL)
    ctl, bank, _, _ = tmflow(backend=backend)
    rz = bank.field("tcp_rz")
    run(ctl, 0.2)
    assert pose_of(bank) == backend.tcp
    backend.tcp = Pose(300.0, -200.0, 300.0, 180.0, 0.0, -0.0)
    run(ctl, 0.1)
    assert bank.read(rz.table, rz.address, 2) == encode(rz, -0.0)
    backend.tcp = Pose(300.0, -200.0, 300.0, 180.0, 0.0, 0.0)
    ctl.tick(DT)
    assert bank.read(rz.table, rz.address, 2) == encode(rz, 0.0)


def test_a_still_pose_leaving_the_range_is_saturated_and_an_error_once() -> None:
    backend = SetTcpBackend(MODEL)
    ctl, bank, _, log = article(backend=backend)
    run(ctl, 0.2)
    assert pose_of(bank) == backend.tcp
    backend.tcp = Pose(350.0, -200.0, 300.0, 180.0, 0.0, 90.0)  # x beyond 327.67
    run(ctl, 0.2)
    assert bank.get("tcp_x") == pytest.approx(327.67)
    assert bank.get("error_code") == SimErrorCode.POSE_OUT_OF_RANGE
    assert log.names().count("sim.pose_out_of_range") == 1
    ctl.clear_error()
    run(ctl, 0.2)  # still there: no new error for the same rest
    assert bank.get("error_code") == 0
    backend.tcp = Pose(300.0, -200.0, 300.0, 180.0, 0.0, 90.0)
    run(ctl, 0.2)
    assert pose_of(bank) == backend.tcp
    names = log.names()
    assert (names.count("sim.pose_saturated"), names.count("sim.pose_in_range")) == (1, 1)


# -- the structure: one controller per handshake, one device prologue ----------------------


@pytest.mark.parametrize(("name", "tm_table"), [("article", False), ("tmflow", True)])
def test_each_handshake_runs_in_its_own_controller_class(name: str, tm_table: bool) -> None:
    profile = robot_profile(name)
    cls = controller_class(profile.handshake)
    assert not inspect.isabstract(cls)
    bank = cls.bank_for(profile)
    assert bank.has("flange_x") is tm_table  # Techman's fixed table beside tmflow only
    ctl = controller_for(profile, bank, KinematicBackend(MODEL), MODEL, log=ListLogger())
    assert type(ctl) is cls
    sim = Simulator(name, listen=False)  # built, not started: no thread, no socket
    assert type(sim._controller) is cls  # the simulator runs the same class
    sim.close()


def test_every_handshake_has_a_controller_class_of_its_own() -> None:
    classes = {controller_class(handshake) for handshake in Handshake}
    assert len(classes) == len(Handshake)
    assert all(issubclass(cls, RobotController) for cls in classes)


@pytest.mark.parametrize("device", ["robot", "gripper"])
def test_robot_and_gripper_share_the_rebuild_prologue(device: str) -> None:
    backend = LateReadyBackend(ready_after_s=0.2)
    log = ListLogger()
    ticked: RobotController | OnRobot2FG7Device
    if device == "robot":
        profile = robot_profile("article")
        ticked = controller_for(
            profile, RegisterBank(profile), backend, MODEL, init_time_s=INIT_S, log=log
        )
    else:
        gripper = gripper_profile("onrobot-2fg7")
        ticked = OnRobot2FG7Device(
            gripper, RegisterBank(gripper), backend, init_time_s=INIT_S, log=log
        )
    run(ticked, INIT_S)
    backend.invalidate()
    run(ticked, 0.5)
    names = log.names()
    assert names.count("sim.initialised") == 1
    assert names.count("sim.backend_reinitialize") == 1  # retried only after 1 s
    assert names.index("sim.backend_reinitialize") < names.index("sim.backend_ready")
    assert backend.reinit_calls == 1
