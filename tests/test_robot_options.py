"""Robot's options in groups: each option object reaches the part of the robot it sets.

``Robot(host, port, *, profile, model, gripper, tool, name, polling, timeouts, retry,
checks, link)``: the polling, timeout and check options come as frozen option objects
(checked when they are made, a bad value named as the argument writes it), a stand-alone
gripper as a GripperDevice, a ready link or a Fleet as ``link``. Nothing here connects.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Iterator
from typing import Any

import pydantic
import pytest

import tmmaster
import tmmaster.sim
from tmmaster import (
    Checks,
    ConfigError,
    Fleet,
    FrameCheck,
    GripperDevice,
    PollPolicy,
    Robot,
    TimeoutPolicy,
    Workspace,
    aio,
)
from tmmaster.pickplace import robot_from_config, validate_config
from tmmaster.sim import MemoryTransport, Simulator


@pytest.fixture
def made() -> Iterator[Callable[..., Robot]]:
    """``Robot(...)``, closed after the test (a network robot holds the default driver)."""
    robots: list[Robot] = []

    def make(*args: Any, **options: Any) -> Robot:
        robots.append(Robot(*args, **options))
        return robots[-1]

    yield make
    for robot in robots:
        robot.close()


SIGNATURE = [
    "host",
    "port",
    "profile",
    "model",
    "gripper",
    "tool",
    "name",
    "polling",
    "timeouts",
    "retry",
    "checks",
    "link",
]


@pytest.mark.parametrize("make", [Robot, tmmaster.connect, aio.connect])
def test_robot_and_both_connects_take_the_grouped_options(make: object) -> None:
    assert list(inspect.signature(make).parameters) == SIGNATURE  # type: ignore[arg-type]


def test_each_option_object_reaches_what_it_sets(made: Callable[..., Robot]) -> None:
    checks = Checks(
        workspace=Workspace(floor_z_mm=0),
        max_speed_percent=40,
        position_tolerance_mm=2.0,
        orientation_tolerance_deg=3.0,
        units=False,
        frame=FrameCheck.off("the tool is taught on the pendant"),
    )
    robot = made(
        "127.0.0.1",
        1,
        profile="article",
        polling=PollPolicy(interval_s=0.02),
        timeouts=TimeoutPolicy(request_s=2.5, gripper_settle_s=0.3),
        checks=checks,
    )
    assert robot.poll_interval_s == robot.polling.interval_s == 0.02
    assert robot._transport.timeout == 2.5  # type: ignore[attr-defined]
    assert robot.gripper._settle_s == 0.3  # type: ignore[attr-defined]
    assert robot.max_speed_percent == 40
    assert (robot.position_tolerance_mm, robot.orientation_tolerance_deg) == (2.0, 3.0)
    assert robot.workspace.floor_z_mm == 0
    assert robot.check_units is False
    assert robot.frame_check.enabled is False
    assert robot.checks == checks


def test_the_defaults_are_the_old_ones(made: Callable[..., Robot]) -> None:
    robot = made("127.0.0.1", 1, profile="article")
    assert robot.poll_interval_s == 0.05
    assert robot._transport.timeout == 1.0  # type: ignore[attr-defined]
    assert robot.gripper._settle_s == 0.5  # type: ignore[attr-defined]
    assert robot.checks == Checks()
    assert (robot.max_speed_percent, robot.check_units, robot.frame_check.enabled) == (
        100,
        True,
        True,
    )
    assert (robot.position_tolerance_mm, robot.orientation_tolerance_deg) == (1.0, 1.0)
    assert robot.workspace == Workspace()


def test_the_interval_and_the_polling_policy_stay_one_setting(made: Callable[..., Robot]) -> None:
    robot = made("127.0.0.1", 1, profile="article")
    robot.poll_interval_s = 0.03
    assert robot.polling.interval_s == 0.03
    robot.polling = PollPolicy(interval_s=0.2, predictive=False)
    assert robot.poll_interval_s == 0.2
    assert robot.polling.predictive is False
    robot.max_speed_percent = 20
    assert robot.checks.max_speed_percent == 20


def test_a_gripper_device_is_reached_at_its_own_address(made: Callable[..., Robot]) -> None:
    robot = made("127.0.0.1", 1, gripper=GripperDevice("onrobot-2fg7", host="127.0.0.2", port=1502))
    link = robot.gripper.transport  # type: ignore[attr-defined]
    assert (link.host, link.port) == ("127.0.0.2", 1502)
    by_name = made("127.0.0.1", 1, gripper="onrobot-2fg7").gripper.transport  # type: ignore[attr-defined]
    assert (by_name.host, by_name.port) == ("127.0.0.1", 502)  # the robot's host, port 502


@pytest.mark.parametrize(
    ("device", "named"),
    [
        (lambda: GripperDevice("auto"), "gripper.profile"),
        (lambda: GripperDevice(5), "gripper.profile"),  # type: ignore[arg-type]
        (lambda: GripperDevice("onrobot-2fg7", "127.0.0.1", 0), r"^gripper\.port: 0"),
        (lambda: GripperDevice("onrobot-2fg7", "10.0.0.1:502"), r"^gripper\.host: .*port"),
        (lambda: GripperDevice("onrobot-2fg7", transport=object()), "gripper.transport"),  # type: ignore[arg-type]
    ],
    ids=["auto", "not-a-profile", "port-0", "port-in-host", "not-a-transport"],
)
def test_a_gripper_device_refuses_what_the_robot_would(device: object, named: str) -> None:
    with pytest.raises(ConfigError, match=named):
        device()  # type: ignore[operator]


def test_a_gripper_device_at_the_robots_host_has_its_port_checked_by_the_robot(
    made: Callable[..., Robot],
) -> None:
    with pytest.raises(ConfigError, match=r"^gripper\.port: 70000"):
        made("127.0.0.1", 1, gripper=GripperDevice("onrobot-2fg7", port=70000))


def test_link_takes_a_ready_transport_or_a_fleet_and_nothing_else(
    made: Callable[..., Robot],
) -> None:
    with Simulator("article", listen=False) as sim:
        ready = MemoryTransport(sim)
        assert made("127.0.0.1", profile="article", link=ready)._transport is ready
    with Fleet() as fleet:
        robot = made("127.0.0.1", 1, profile="article", gripper=None, link=fleet)
        robot.close()
    with pytest.raises(
        ConfigError, match=r"^link must be a tmmaster\.Transport or a tmmaster\.Fleet"
    ):
        made("127.0.0.1", 1, link="127.0.0.1:502")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (
            lambda: PollPolicy(interval_s=10),
            r"^polling\.interval_s must be a number in \[0\.001, 5\] s, got 10$",
        ),
        (
            lambda: TimeoutPolicy(request_s=0),
            r"^timeouts\.request_s must be a number in \(0, 60\] s",
        ),
        (lambda: TimeoutPolicy(gripper_settle_s=61), r"^timeouts\.gripper_settle_s must be"),
        (
            lambda: Checks(max_speed_percent=0),
            r"^checks\.max_speed_percent must be an integer in \[1, 100\] %, got 0$",
        ),
        (lambda: Checks(position_tolerance_mm=51), r"^checks\.position_tolerance_mm must be"),
        (
            lambda: Checks(orientation_tolerance_deg=0),
            r"^checks\.orientation_tolerance_deg must be",
        ),
        (lambda: Checks(units="sometimes"), r"^checks\.units: "),
        (lambda: Checks(speed=50), r"^checks\.speed: Extra inputs are not permitted"),
    ],
    ids=[
        "interval",
        "request",
        "settle",
        "speed-cap",
        "position",
        "orientation",
        "units",
        "unknown",
    ],
)
def test_an_option_object_names_the_field_as_the_robot_argument_writes_it(
    make: object, message: str
) -> None:
    with pytest.raises(ConfigError, match=message):
        make()  # type: ignore[operator]


def test_in_a_configuration_file_a_policy_error_stays_the_files() -> None:
    # Validated inside another model, the error is pydantic's, located at the key.
    with pytest.raises(pydantic.ValidationError) as info:
        TimeoutPolicy.model_validate({"request_s": 0})
    assert info.value.errors()[0]["loc"] == ("request_s",)
    with pytest.raises(ConfigError, match=r"timeouts\.ack_s"):
        validate_config({"timeouts": {"ack_s": 0}})
    # The settle time is the gripper's: [timeouts] takes no second one.
    with pytest.raises(ConfigError, match=r"\[gripper\] settle_s"):
        validate_config({"timeouts": {"gripper_settle_s": 1}})


def test_the_pick_and_place_configuration_maps_onto_the_groups() -> None:
    config = validate_config(
        {
            "robot": {"host": "127.0.0.1", "max_speed": 50, "position_tolerance_mm": 2.0},
            "gripper": {"kind": "onrobot-2fg7", "host": "127.0.0.3", "port": 1503},
            "run": {"poll_interval_s": 0.02},
            "timeouts": {"request_s": 2.0, "ack_s": 3.0},
            "workspace": {"floor_z_mm": 10},
        }
    )
    robot = robot_from_config(config)
    settled = robot_from_config(validate_config({"robot": {"host": "127.0.0.1"}}), settle_scale=10)
    try:
        check_mapped(robot)
        assert settled.timeouts.gripper_settle_s == 0.1  # 0.5 / 10, never below 0.1 s
    finally:
        robot.close()
        settled.close()


def check_mapped(robot: Robot) -> None:
    """The robot ``test_the_pick_and_place_configuration_maps_onto_the_groups`` made."""
    assert robot.poll_interval_s == 0.02
    assert robot._transport.timeout == 2.0  # type: ignore[attr-defined]
    assert robot.timeouts.ack_timeout_s == 3.0
    assert (robot.max_speed_percent, robot.position_tolerance_mm) == (50, 2.0)
    assert robot.workspace.floor_z_mm == 10
    assert robot.check_units is False  # the file's poses were checked as written
    link = robot.gripper.transport  # type: ignore[attr-defined]
    assert (link.host, link.port) == ("127.0.0.3", 1503)
