"""A ``held_input`` the robot's profile has not is refused naming the setting.

docs/pickplace.md: "An input the profile does not have ... is refused before anything
connects". The refusal used to say only what the profile lacks ("profile 'article'
declares no digital I/O"), which does not tell a reader of a config file which of its
keys to fix; it now starts with the key and its value.
"""

from __future__ import annotations

import pytest

from tmmaster import ConfigError, Robot
from tmmaster.pickplace import PickPlaceConfig, Runner, robot_from_config


def test_the_config_names_gripper_held_input() -> None:
    config = PickPlaceConfig.model_validate(
        {"robot": {"profile": "article", "host": "127.0.0.1"}, "gripper": {"held_input": 0}}
    )
    with pytest.raises(
        ConfigError, match=r"^gripper\.held_input = 0 \(end_module\): .*no digital I/O"
    ):
        robot_from_config(config)


def test_the_runner_names_held_input() -> None:
    robot = Robot("127.0.0.1", 5020)  # the tmflow profile: end module DI 0-3; never connected
    with pytest.raises(ConfigError, match=r"^held_input = 7 \(end_module\): end_module DI 7"):
        Runner(robot, held_input=7)
