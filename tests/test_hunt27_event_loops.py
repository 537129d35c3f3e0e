"""Hunt 27: the driver's safety paths on asyncio's own loop too, not only on uvloop.

Every network ``Robot`` runs on a driver's loop: the process's default one or a
``Fleet``'s, made with ``event_loop="auto"``: uvloop when it is installed (the
``monitor`` extra, which the ``test`` extra brings), asyncio's own loop otherwise (a
plain ``pip install tmmaster``). So the suite, run with the test extra, drives every
network robot on uvloop, and the loop most users get is left to the tests that name it (the
monitor's). This module runs a chosen set of the give-up, stop and close tests again on
asyncio's loop: ``auto`` is steered by hiding uvloop (``import uvloop`` fails, as where
it is not installed), for the default driver and every ``Fleet()`` alike. On uvloop
they run in their own modules (measured by hunt 27: the same results on both loops,
the same times).

The tests are the other modules' own, imported (the same bodies and checks on what the
robot did); only the loop differs. The owed-Stop tests of two robots (test_hunt8_two_robots,
test_owed_stop_settled: 7 s of the suite's time) passed on both loops in hunt 27 and run
on uvloop only.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

import pytest

import tmmaster._fleet as fleet_module
from test_aio_cancel import (
    test_a_move_cancelled_while_its_write_is_held_in_the_network_never_runs,
    test_a_wait_cancelled_while_queued_stops_the_running_move,
)
from test_fleet import (
    fleet,
    robots,
    test_a_request_without_an_answer_times_out_on_its_own_timeout,
    test_an_interrupt_ends_a_wait_the_loop_polls_at_once_and_stops_the_arm,
    test_closing_a_fleet_with_a_dead_robot_stops_every_robot_at_once_within_its_budget,
    test_closing_the_fleet_while_a_thread_waits_ends_the_wait_and_stops_the_arm,
    test_ctrl_c_in_a_wait_the_loop_polls_withdraws_or_stops_before_returning,
)
from test_hunt3_fleet_close import (
    test_a_held_command_that_lands_right_after_fleet_close_never_runs,
)
from test_hunt22_cancel_threads import test_a_cancel_while_a_fleets_loop_polls_the_owners_wait
from tmmaster import Fleet, Robot
from tmmaster._loop import _loop_factory
from tmmaster.sim import Simulator

__all__ = [  # collected here again, on each loop
    "fleet",
    "robots",
    "test_a_cancel_while_a_fleets_loop_polls_the_owners_wait",
    "test_a_held_command_that_lands_right_after_fleet_close_never_runs",
    "test_a_move_cancelled_while_its_write_is_held_in_the_network_never_runs",
    "test_a_request_without_an_answer_times_out_on_its_own_timeout",
    "test_a_wait_cancelled_while_queued_stops_the_running_move",
    "test_an_interrupt_ends_a_wait_the_loop_polls_at_once_and_stops_the_arm",
    "test_closing_a_fleet_with_a_dead_robot_stops_every_robot_at_once_within_its_budget",
    "test_closing_the_fleet_while_a_thread_waits_ends_the_wait_and_stops_the_arm",
    "test_ctrl_c_in_a_wait_the_loop_polls_withdraws_or_stops_before_returning",
]

SimFactory = Callable[..., Simulator]


@pytest.fixture(autouse=True)
def event_loop(monkeypatch: pytest.MonkeyPatch) -> str:
    """The loop ``auto`` picks during the test: asyncio's own (uvloop hidden)."""
    monkeypatch.setitem(sys.modules, "uvloop", None)  # import uvloop -> ImportError
    # A default driver made before the test keeps its loop (another module's robot may
    # hold it across its tests): the test's links take a fresh one, made on this loop.
    monkeypatch.setattr(fleet_module, "_DEFAULT", fleet_module._DefaultDriver())
    assert _loop_factory("auto")[0] == "asyncio"
    return "asyncio"


def test_the_default_driver_and_a_fleet_run_on_the_loop_auto_picks(
    tm_simulator_factory: SimFactory, event_loop: str
) -> None:
    sim = tm_simulator_factory("article")
    with Fleet() as own:
        assert own.event_loop == event_loop
    robot = Robot("127.0.0.1", sim.port, profile="article", gripper=None)
    with robot:
        robot.wait_until_ready(timeout_s=5)
        assert fleet_module._DEFAULT.fleet is not None
        assert fleet_module._DEFAULT.fleet.event_loop == event_loop
