"""``robot.check_units``, ``robot.workspace`` and ``robot.model`` set after the Robot was made.

docs/robot-api.md lists them among the options "meant to change while it runs", each a
property with a setter, and the Robot's docstring says "the setters of the options check
what the option objects check". These three took any value unchecked: a string, None or
0 was stored, and the next move failed with an ``AttributeError`` (``'str' object has no
attribute 'check'``, ``'NoneType' object has no attribute 'inverse'``) from inside the
planner; ``check_units`` took ``"no"`` as true and ``0`` as false without a word.

Found by this hunt (each fails without its fix): the assignment now raises a
``ConfigError`` naming the option, the value is not taken, and the next move runs with
the setting the robot had. Judged by what the simulator ran (its request and motion logs).
"""

from __future__ import annotations

from collections.abc import Callable

import pytest

from test_hunt14_edge_inputs import TARGET, ready_robot
from tmmaster import Checks, ConfigError, Workspace, robot_model
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]
#: (the option, the values it must refuse)
REFUSED: list[tuple[str, list[object]]] = [
    ("check_units", ["no", None, 0, 1, 1.0, [True]]),
    ("workspace", ["table", None, 0, {"floor_z_mm": 0}, (0, 0)]),
    ("model", ["tm13", "TM5-700 ", None, 0, robot_model]),  # a name: a built-in one's
]


@pytest.fixture
def tm_simulator_factory(memory_simulator_factory: Factory) -> Factory:
    return memory_simulator_factory


@pytest.mark.parametrize("profile", ["tmflow", "article"])
@pytest.mark.parametrize(("option", "values"), REFUSED, ids=[o for o, _ in REFUSED])
def test_a_setter_refuses_a_value_of_another_type_naming_the_option(
    tm_simulator_factory: Factory, profile: str, option: str, values: list[object]
) -> None:
    sim, robot = ready_robot(tm_simulator_factory, profile)
    try:
        before = getattr(robot, option)
        for value in values:
            with pytest.raises(ConfigError, match=option):
                setattr(robot, option, value)
            assert getattr(robot, option) is before, f"{value!r} was taken"
        assert list(sim.request_log) == []
        robot.move_to(TARGET, speed=100)  # planned with the settings the robot had
        assert sim.motion_log()[-1].target == TARGET
    finally:
        robot.close()


def test_the_setters_take_a_value_of_their_type(tm_simulator_factory: Factory) -> None:
    sim, robot = ready_robot(tm_simulator_factory, "tmflow")
    try:
        robot.check_units = False
        robot.workspace = Workspace(floor_z_mm=0)
        robot.model = "tm5-700"  # a name, as Robot(model=) takes it
        assert robot.model is robot_model("tm5-700")
        robot.model = robot_model("tm5-700")
        assert robot.check_units is False
        assert robot.workspace == Workspace(floor_z_mm=0)
        assert robot.checks.workspace == Workspace(floor_z_mm=0)
        assert robot.model is robot_model("tm5-700")
        robot.move_to(TARGET, speed=100)
        assert sim.motion_log()[-1].target == TARGET
    finally:
        robot.close()


@pytest.mark.parametrize("value", ["no", None, 0, 1, 1.0])
def test_checks_units_takes_only_a_bool_as_the_setter_does(value: object) -> None:
    # Checks(units=0) was pydantic's lax bool: False, the units check off without a word,
    # where robot.check_units = 0 is refused.
    with pytest.raises(ConfigError, match=r"checks\.units"):
        Checks(units=value)
