"""The four gripper drivers against the simulator, in memory (no sockets).

Each test drives a real :class:`~tmmaster.sim.Simulator` through the public driver and
checks the outcome both from the driver's answer and from the simulated device (its
registers, its objects, the request log), so a driver that guesses cannot pass.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import get_args

import pytest

from sim_speeds import SUITE_TICK_HZ
from tmmaster import (
    AcknowledgeTimeoutError,
    Blog2FG7Gripper,
    ConfigError,
    ConnectError,
    GraspFailedError,
    GripperDevice,
    GripperError,
    GripperLink,
    GripperTimeoutError,
    OnRobot2FG7Gripper,
    PollPolicy,
    Pose,
    RegisterGripper,
    RetryPolicy,
    Robot,
    SequenceGripper,
    StopRequestedError,
    TimeoutPolicy,
    gripper_profile,
)
from tmmaster._profiles import profile_from_data
from tmmaster._registers import GripperProfile
from tmmaster.sim import DEFAULT_PART_POSE, RequestRecord, RobotSetup, Simulator, Timing

Factory = Callable[..., Simulator]


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: Factory) -> Factory:
    """The drivers are the subject here, not TCP: simulators in memory."""
    return memory_simulator_factory


#: 100 mm above the part: the fingers close on nothing there.
ABOVE_PART = Pose(300.0, -200.0, 200.0, 180.0, 0.0, 90.0)


@contextmanager
def robot_at(sim: Simulator, pose: Pose, **options: object) -> Iterator[Robot]:
    """A connected robot on ``sim`` (and its gripper), moved to ``pose``; closed afterwards.

    It polls every 10 ms (as the suite's ``robots`` fixture does) unless told otherwise:
    the simulators run at 40x, where the default 50 ms pace would make each move last
    ~0.17 s instead of ~0.04 s.
    """
    options.setdefault("polling", PollPolicy(interval_s=0.01))
    robot = Robot(sim.url, profile=sim.profile, **options)  # type: ignore[arg-type]
    with robot:
        robot.wait_until_ready(5.0)
        robot.move_to(pose, speed=100)
        yield robot


def gripper_requests(sim: Simulator) -> list[RequestRecord]:
    """Requests the separate gripper device received."""
    return [r for r in sim.request_log if r.server == "gripper"]


def writes(records: list[RequestRecord]) -> list[RequestRecord]:
    """Only the write requests."""
    return [r for r in records if r.is_write]


def held(sim: Simulator) -> bool:
    """True when the simulated world has the part between the fingers."""
    return any(o.held for o in sim.objects())


# -- article profile: gripper register on the robot's own connection ---------------------


def test_article_grip_at_the_part_holds_it_and_returns_on_detection(
    tm_simulator_factory: Factory,
) -> None:
    sim = tm_simulator_factory("article")
    settle_s = 2.0
    # The polls are counted below: at the 50 ms pace they are written for.
    with robot_at(
        sim,
        DEFAULT_PART_POSE,
        timeouts=TimeoutPolicy(gripper_settle_s=settle_s),
        polling=PollPolicy(interval_s=0.05),
    ) as robot:
        gripper = robot.gripper
        assert isinstance(gripper, RegisterGripper)
        grasp = robot.profile.field("grasp_status")
        sim.clear_request_log()
        status = gripper.grip()
        log = sim.request_log
    assert status.holding
    assert sim.field("grasp_status") == 1
    assert held(sim)
    # One write of the gripper register, then grasp_status polls until detection. A
    # driver that slept the settle time would poll about settle_s / 50 ms = 40 times.
    assert [(r.function_code, r.address, r.values) for r in writes(log)] == [
        (16, robot.profile.field("gripper_command").address, (1,))
    ]
    # The polls read the status block (robot error state and grasp in one request).
    written_at = next(i for i, r in enumerate(log) if r.is_write)
    polls = [
        r
        for r in log[written_at:]
        if not r.is_write and r.address <= grasp.address < r.address + r.count
    ]
    assert 1 <= len(polls) <= 5, len(polls)


def test_article_close_away_from_the_part_is_not_holding(tm_simulator_factory: Factory) -> None:
    sim = tm_simulator_factory("article")
    # 0.15 s of settle: ~15 ticks, the fingers close all the way in one (39 mm at 40x).
    with robot_at(sim, ABOVE_PART, timeouts=TimeoutPolicy(gripper_settle_s=0.15)) as robot:
        status = robot.gripper.close()
        assert not status.holding
        with pytest.raises(GraspFailedError):
            robot.gripper.grip()
    assert sim.field("grasp_status") == 0
    assert not held(sim)


def test_article_grasp_miss_raises_grasp_failed(tm_simulator_factory: Factory) -> None:
    sim = tm_simulator_factory("article", faults=["grasp_miss:at_grasp=1"])
    # 0.2 s of settle: the last grip must see the part within it (it takes ~1-2 ticks).
    with robot_at(sim, DEFAULT_PART_POSE, timeouts=TimeoutPolicy(gripper_settle_s=0.2)) as robot:
        with pytest.raises(GraspFailedError):
            robot.gripper.grip()
        # The miss hides one close only: after opening, the next grip succeeds.
        robot.gripper.open()
        assert robot.gripper.grip().holding
    assert held(sim)


# -- tmflow profile: gripper commands through the program's sequence handshake -----------


def test_tmflow_grip_goes_through_the_sequence_handshake(tm_simulator_factory: Factory) -> None:
    sim = tm_simulator_factory("tmflow")
    with robot_at(sim, DEFAULT_PART_POSE) as robot:
        gripper = robot.gripper
        assert isinstance(gripper, SequenceGripper)
        seq_before = sim.field("ack_seq")
        sim.clear_request_log()
        status = gripper.grip()
        log = sim.request_log
    assert status.holding
    assert sim.field("grasp_status") == 1
    assert held(sim)
    # One command write carrying command = gripper_close and a new seq, which the
    # program acknowledged and completed.
    command = robot.profile.field("command")
    sent = writes(log)
    assert len(sent) == 1
    assert sent[0].address <= command.address < sent[0].address + sent[0].count
    assert sent[0].values is not None
    assert sent[0].values[command.address - sent[0].address] == command.code_of("gripper_close")
    assert sim.field("ack_seq") == sim.field("done_seq") != seq_before


def test_tmflow_close_away_and_grasp_miss_raise_grasp_failed(
    tm_simulator_factory: Factory,
) -> None:
    sim = tm_simulator_factory("tmflow", faults=["grasp_miss:at_grasp=2"])
    with robot_at(sim, ABOVE_PART) as robot:
        assert not robot.gripper.close().holding  # grasp 1: nothing there
        robot.gripper.open()
        robot.move_to(DEFAULT_PART_POSE, speed=100)
        with pytest.raises(GraspFailedError):  # grasp 2: on the part, but missed
            robot.gripper.grip()
        assert sim.field("grasp_status") == 0
        robot.gripper.open()
        assert robot.gripper.grip().holding  # grasp 3
    assert held(sim)


# -- blog-2fg7: its own connection, control acknowledged by the device -------------------


def test_blog_grip_is_acknowledged_and_reports_gobj(tm_simulator_factory: Factory) -> None:
    sim = tm_simulator_factory("article", robot=RobotSetup(gripper="blog-2fg7"))
    assert sim.gripper_port is not None
    options = {"gripper": GripperDevice("blog-2fg7", port=sim.gripper_port)}
    with robot_at(sim, DEFAULT_PART_POSE, **options) as robot:
        gripper = robot.gripper
        assert isinstance(gripper, Blog2FG7Gripper)
        sim.clear_request_log()
        status = gripper.grip()
        log = gripper_requests(sim)
    assert status.holding
    assert held(sim)
    assert sim.field("object_status", device="gripper") == 2  # gOBJ: stopped closing on it
    assert sim.field("control", device="gripper") == 0  # cleared by the device
    profile = gripper_profile("blog-2fg7")
    # Force, width and control = 16 in ONE request, sent once.
    assert [(r.function_code, r.address, r.count) for r in writes(log)] == [(16, 0, 3)]
    assert writes(log)[0].values == (102, 0, 16)  # 40 N x 2.55, 0 mm, execute
    # The driver looked for the acknowledgement (control back to 0) before the outcome.
    control = profile.field("control").address
    first_status = next(i for i, r in enumerate(log) if r.address == 258)
    assert any(r.address == control and not r.is_write for r in log[:first_status])


def test_blog_close_on_nothing_raises_grasp_failed(tm_simulator_factory: Factory) -> None:
    sim = tm_simulator_factory("article", robot=RobotSetup(gripper="blog-2fg7"))
    assert sim.gripper_port is not None
    options = {"gripper": GripperDevice("blog-2fg7", port=sim.gripper_port)}
    with robot_at(sim, ABOVE_PART, **options) as robot, pytest.raises(GraspFailedError):
        robot.gripper.grip()
    assert sim.field("object_status", device="gripper") == 3  # at position, no object
    assert not held(sim)


def test_blog_unacknowledged_command_times_out_and_is_withdrawn(
    tm_simulator_factory: Factory,
) -> None:
    # A gripper still activating (gSTA 1) leaves control at 16: nobody acknowledges. It
    # activates 0.5 s (wall, at 1x) after the start, 0.3 s after the 0.2 s ack timeout.
    sim = tm_simulator_factory(
        "article",
        robot=RobotSetup(gripper="blog-2fg7"),
        time_scale=1.0,
        timing=Timing(tick_hz=SUITE_TICK_HZ, init_time_s=0.5),
        wait_ready=False,
    )
    assert sim.gripper_port is not None
    link = GripperLink(sim.url, sim.gripper_port, ack_timeout_s=0.2, timeout_s=5.0)
    gripper = Blog2FG7Gripper(gripper_profile("blog-2fg7"), link)
    gripper.connect()
    try:
        assert sim.field("gripper_status", device="gripper") == 1
        with pytest.raises(AcknowledgeTimeoutError, match="withdrawn"):
            gripper.close()
    finally:
        gripper.disconnect()
    # The last write withdrew the command, so the gripper, once active, does not run it.
    assert writes(gripper_requests(sim))[-1].values == (0,)
    sim.wait_for(lambda: sim.field("gripper_status", device="gripper") == 3, 5.0)
    ticks = sim.ticks
    sim.wait_for(lambda: sim.ticks >= ticks + 3, 2.0)
    assert sim.field("object_status", device="gripper") == 3
    assert sim.field("motion_state", device="gripper") == 0


# -- OnRobot 2FG7: the real map, unit id 65, one connection ------------------------------


def onrobot(sim: Simulator, **options: object) -> OnRobot2FG7Gripper:
    """A connected OnRobot driver on ``sim``'s gripper port (caller disconnects)."""
    assert sim.gripper_port is not None
    link = GripperLink(sim.url, sim.gripper_port, timeout_s=2.0)
    gripper = OnRobot2FG7Gripper(gripper_profile("onrobot-2fg7"), link, **options)  # type: ignore[arg-type]
    gripper.connect()
    return gripper


def test_onrobot_limits_are_read_from_the_device_at_connect(
    tm_simulator_factory: Factory,
) -> None:
    sim = tm_simulator_factory("article", robot=RobotSetup(gripper="onrobot-2fg7"))
    external = onrobot(sim)
    external.disconnect()
    internal = onrobot(sim, grip="internal")
    internal.disconnect()
    assert external.limits == (
        sim.field("min_external_width", device="gripper"),
        sim.field("max_external_width", device="gripper"),
    )
    assert internal.limits == (
        sim.field("min_internal_width", device="gripper"),
        sim.field("max_internal_width", device="gripper"),
    )
    assert external.limits != internal.limits
    log = gripper_requests(sim)
    # Width limits, then force ceiling (0x0405) and product code (0x0600).
    connect_reads = [(3, 259, 4), (3, 1029, 1), (3, 1536, 1)]
    assert [(r.function_code, r.address, r.count) for r in log] == connect_reads * 2
    assert {r.device_id for r in log} == {65}


def test_onrobot_writes_width_force_speed_and_command_in_one_fc16(
    tm_simulator_factory: Factory,
) -> None:
    sim = tm_simulator_factory("article", robot=RobotSetup(gripper="onrobot-2fg7"))
    gripper = onrobot(sim)
    try:
        gripper.force_n = 60.0
        gripper.speed_percent = 80
        sim.clear_request_log()
        status = gripper.move_to_width(20.0)
    finally:
        gripper.disconnect()
    assert [(r.function_code, r.address, r.count, r.values) for r in writes(sim.request_log)] == [
        (16, 0, 4, (200, 60, 80, 1))
    ]
    assert {r.device_id for r in sim.request_log} == {65}
    assert status.width_mm == pytest.approx(20.0, abs=0.5)
    assert not status.busy


def test_onrobot_completion_is_the_target_width_not_just_not_busy(
    tm_simulator_factory: Factory,
) -> None:
    # 8 ticks per second (0.4 simulated s each): the write lands just after a tick, and the
    # first status read after it comes ~120 ms before the device takes the command at the
    # next one, while the status still says "not busy" at 39 mm.
    sim = tm_simulator_factory(
        "article",
        robot=RobotSetup(gripper="onrobot-2fg7"),
        timing=Timing(tick_hz=8.0),
        time_scale=3.2,
    )
    gripper = onrobot(sim)
    try:
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks != ticks, 2.0, interval=0.001)
        sim.clear_request_log()
        status = gripper.move_to_width(10.0)
    finally:
        gripper.disconnect()
    assert status.width_mm == pytest.approx(10.0, abs=0.5)
    assert sim.field("external_width", device="gripper") == pytest.approx(10.0, abs=0.5)
    status_reads = [r for r in sim.request_log if r.address == 256]
    assert len(status_reads) >= 2  # it kept polling after a first "not busy"


def test_onrobot_stopped_short_without_grip_is_not_success(tm_simulator_factory: Factory) -> None:
    # grasp_miss: the fingers stop on the part (30 mm) but report no grip. Not busy,
    # not at the target and no grip: the move has not been shown to succeed.
    sim = tm_simulator_factory(
        "article", robot=RobotSetup(gripper="onrobot-2fg7"), faults=["grasp_miss"]
    )
    assert sim.gripper_port is not None
    options = {"gripper": GripperDevice("onrobot-2fg7", port=sim.gripper_port)}
    with robot_at(sim, DEFAULT_PART_POSE, **options) as robot:
        gripper = robot.gripper
        assert isinstance(gripper, OnRobot2FG7Gripper)
        with pytest.raises(GripperTimeoutError):
            gripper.move_to_width(10.0, timeout_s=0.25)  # the fingers stop after ~1 tick
        assert sim.field("external_width", device="gripper") == pytest.approx(30.0, abs=0.5)


def test_onrobot_grip_holds_the_part_and_fails_on_nothing(tm_simulator_factory: Factory) -> None:
    sim = tm_simulator_factory("article", robot=RobotSetup(gripper="onrobot-2fg7"))
    assert sim.gripper_port is not None
    options = {"gripper": GripperDevice("onrobot-2fg7", port=sim.gripper_port)}
    with robot_at(sim, DEFAULT_PART_POSE, **options) as robot:
        status = robot.gripper.grip()
        assert status.holding
        assert status.width_mm == pytest.approx(30.0, abs=0.5)  # the part's width
        assert held(sim)
        opened = robot.gripper.open()
        assert opened.width_mm == pytest.approx(39.0, abs=0.5)
        assert not opened.holding
        robot.move_to(ABOVE_PART, speed=100)
        with pytest.raises(GraspFailedError):
            robot.gripper.grip()
        assert sim.field("external_width", device="gripper") == pytest.approx(1.0, abs=0.5)


@pytest.mark.parametrize("width", [0.5, 39.5, 60.0])
def test_onrobot_out_of_limit_width_is_refused_before_any_write(
    tm_simulator_factory: Factory, width: float
) -> None:
    sim = tm_simulator_factory("article", robot=RobotSetup(gripper="onrobot-2fg7"))
    gripper = onrobot(sim)
    try:
        sim.clear_request_log()
        with pytest.raises(ConfigError, match=r"outside 1\.\.39 mm"):
            gripper.move_to_width(width)
        assert sim.request_log == []
    finally:
        gripper.disconnect()


def test_onrobot_refuses_to_move_before_connect() -> None:
    link = GripperLink("127.0.0.1", 9)  # never contacted
    gripper = OnRobot2FG7Gripper(gripper_profile("onrobot-2fg7"), link)
    with pytest.raises(GripperError, match="not connected"):
        gripper.close()


def test_onrobot_second_connection_is_a_clear_error(tm_simulator_factory: Factory) -> None:
    sim = tm_simulator_factory("article", robot=RobotSetup(gripper="onrobot-2fg7"))
    first = onrobot(sim)
    try:
        assert sim.gripper_port is not None
        second = Robot(
            sim.url,
            sim.port,
            profile="article",
            gripper=GripperDevice("onrobot-2fg7", port=sim.gripper_port),
            # One quick retry: enough to show a retry does not get through either.
            retry=RetryPolicy(attempts=2, initial_backoff_s=0.01, jitter_s=0.01),
        )
        with pytest.raises(ConnectError, match="one Modbus TCP connection at a time"):
            second.connect()
        # The first master is not disturbed.
        assert first.status().width_mm == pytest.approx(39.0, abs=0.5)
    finally:
        first.disconnect()


def test_onrobot_force_zero_is_accepted_and_the_live_ceiling_is_enforced(
    tm_simulator_factory: Factory,
) -> None:
    sim = tm_simulator_factory("article", robot=RobotSetup(gripper="onrobot-2fg7"))
    gripper = onrobot(sim, force_n=0.0, speed_percent=1)
    try:
        assert gripper.max_force_n == 100.0  # read from 0x0405 at connect
        assert gripper.product == "2FG7"
        gripper.move_to_width(20.0)  # force 0 = the device's minimum, speed 1 %
        sim.clear_request_log()
        for force in (10.0, 120.0):  # below 20 N, above the live ceiling
            gripper.force_n = force
            with pytest.raises(ConfigError, match=r"0 \(the device's minimum\) or 20\.\.100 N"):
                gripper.move_to_width(20.0)
        gripper.force_n = 40.0
        gripper.speed_percent = 0
        with pytest.raises(ConfigError, match=r"outside 1\.\.100 %"):
            gripper.move_to_width(20.0)
        assert sim.request_log == []
    finally:
        gripper.disconnect()


@pytest.mark.parametrize(("force", "speed"), [(10.0, 50), (141.0, 50), (40.0, 0), (40.0, 101)])
def test_onrobot_bad_force_or_speed_is_refused_at_construction(force: float, speed: int) -> None:
    link = GripperLink("127.0.0.1", 9)  # never contacted
    with pytest.raises(ConfigError):
        OnRobot2FG7Gripper(
            gripper_profile("onrobot-2fg7"), link, force_n=force, speed_percent=speed
        )


def test_onrobot_refuses_a_device_that_is_not_a_2fg(tm_simulator_factory: Factory) -> None:
    sim = tm_simulator_factory("article", robot=RobotSetup(gripper="onrobot-2fg7"))
    sim._call(lambda: sim._gripper_bank.set("product_code", 0x20))  # type: ignore[union-attr]
    with pytest.raises(GripperError, match=r"0x0020 \(RG2\), not a 2FG7"):
        onrobot(sim)


def test_onrobot_dual_quick_changer_unit_ids(tm_simulator_factory: Factory) -> None:
    secondary = profile_from_data({"extends": "onrobot-2fg7", "device_id": 67})
    assert isinstance(secondary, GripperProfile)
    sim = tm_simulator_factory("article", robot=RobotSetup(gripper=secondary))
    assert sim.gripper_port is not None
    link = GripperLink(sim.url, sim.gripper_port, timeout_s=2.0)
    gripper = OnRobot2FG7Gripper(secondary, link)
    gripper.connect()
    try:
        gripper.move_to_width(15.0)
    finally:
        gripper.disconnect()
    assert {r.device_id for r in gripper_requests(sim)} == {67}
    with pytest.raises(ConfigError, match="65, 66 or 67"):
        profile_from_data({"extends": "onrobot-2fg7", "device_id": 1})


# -- a gripper instance in Robot(gripper=...), the driver registry, timeouts --------------


def test_a_gripper_instance_keeps_its_options_and_is_guarded_by_the_robot(
    tm_simulator_factory: Factory,
) -> None:
    sim = tm_simulator_factory("article", robot=RobotSetup(gripper="onrobot-2fg7"))
    assert sim.gripper_port is not None
    link = GripperLink(sim.url, sim.gripper_port, timeout_s=2.0)
    gripper = OnRobot2FG7Gripper(
        gripper_profile("onrobot-2fg7"), link, force_n=60.0, speed_percent=80
    )
    with robot_at(sim, ABOVE_PART, gripper=gripper) as robot:
        assert robot.gripper is gripper
        sim.clear_request_log()
        gripper.move_to_width(20.0)
        sent = writes(gripper_requests(sim))
        # The robot's stop request ends the gripper's waits: the robot mounted it.
        robot.interrupt()
        with pytest.raises(StopRequestedError):
            gripper.open()
    assert [r.values for r in sent] == [(200, 60, 80, 1)]


def test_a_robot_wired_gripper_needs_a_robot() -> None:
    with pytest.raises(GripperError, match="not mounted"):
        RegisterGripper(settle_s=0.3).close()
    with pytest.raises(GripperError, match="not mounted"):
        SequenceGripper().status()


def test_article_register_gripper_instance_and_timeout(tm_simulator_factory: Factory) -> None:
    sim = tm_simulator_factory("article")
    with robot_at(sim, ABOVE_PART, gripper=RegisterGripper(settle_s=3.0)) as robot:
        assert isinstance(robot.gripper, RegisterGripper)
        # No busy flag: an open lasts the settle time; a shorter timeout_s ends the wait.
        with pytest.raises(GripperTimeoutError, match=r"0\.15 s"):
            robot.gripper.open(timeout_s=0.15)
        with pytest.raises(ConfigError, match="timeout_s"):
            robot.gripper.close(timeout_s=0)


def test_every_gripper_protocol_has_one_driver_and_one_simulated_device() -> None:
    from tmmaster._gripper import GRIPPER_DRIVERS
    from tmmaster._registers import GripperDriverName
    from tmmaster.sim._grippers import GRIPPER_DEVICES

    names = get_args(GripperDriverName)
    assert set(GRIPPER_DRIVERS) == set(GRIPPER_DEVICES) == set(names)
    for name in names:
        profile = next(
            p for p in ("blog-2fg7", "onrobot-2fg7") if gripper_profile(p).driver == name
        )
        link = GripperLink("127.0.0.1", 1)
        assert isinstance(
            tmmaster_gripper_for(gripper_profile(profile), link), GRIPPER_DRIVERS[name]
        )


def tmmaster_gripper_for(profile: GripperProfile, link: GripperLink) -> object:
    """The registry's choice for ``profile`` (opens nothing), as a Robot makes it."""
    from tmmaster._gripper import GRIPPER_DRIVERS

    return GRIPPER_DRIVERS[profile.driver](profile, link)
