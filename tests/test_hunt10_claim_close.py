"""Robot.close() on another thread while the first command's claim beat is in flight.

A tmflow master's first command claims the robot before its write (one read of 9052,
one beat with its own session: ``Heartbeat.claim``), then starts the heartbeat. That
beat is no command: it does not pass the command gate. ``close()`` on another thread
(a supervisor, an exit hook) while the beat is on its way must still leave nothing
behind: the command is never written, no motion runs, and the heartbeat the claim
starts once its beat is answered writes nothing after ``close()`` returned (a beat
that goes on would keep a later master's command of this session alive). The beat is
held at its write, by function code and address: over TCP by a FaultProxy, in process
(``sim://``, whose heartbeat is a thread of its own) by a link that waits on an Event.
The simulator's request log and motion log judge.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import pytest

from fault_proxy import FaultProxy, Rule
from tmmaster import PollPolicy, Pose, Robot, TimeoutPolicy, TMMasterError
from tmmaster.sim import MemoryTransport, Simulator

TARGET = Pose(300, -200, 150, 180, 0, 90)


def moving(robot: Robot, outcome: list[str]) -> threading.Thread:
    """``robot.move_to(TARGET)`` started on a thread of its own; its end goes to ``outcome``
    ("done", or the name of the error)."""

    def move() -> None:
        try:
            robot.move_to(TARGET, speed=50)
            outcome.append("done")
        except TMMasterError as exc:
            outcome.append(type(exc).__name__)

    mover = threading.Thread(target=move)
    mover.start()
    return mover


BEAT, COMMAND = 9050, 9000
TIMEOUTS = TimeoutPolicy(request_s=0.5, heartbeat_s=0.1, heartbeat_ttl_s=2.0)


class _HeldBeat(MemoryTransport):
    """An in-process link whose first beat (FC16 to 9050) waits for ``release``."""

    def __init__(self, sim: Simulator, held: threading.Event, release: threading.Event) -> None:
        super().__init__(sim, timeout=TIMEOUTS.request_s)
        self.held, self.release = held, release

    def _exchange(
        self, what: str, function_code: int, address: int, count: int, values: list[int] | None
    ) -> list[int]:
        if function_code == 16 and address == BEAT and not self.held.is_set():
            self.held.set()
            self.release.wait(5)
        return super()._exchange(what, function_code, address, count, values)


@contextmanager
def _robot(how: str, sim: Simulator) -> Iterator[tuple[Robot, threading.Event, threading.Event]]:
    held, release = threading.Event(), threading.Event()
    options: dict[str, Any] = dict(
        profile="tmflow", gripper=None, polling=PollPolicy(interval_s=0.01), timeouts=TIMEOUTS
    )
    if how == "sim://":
        with _robot_on(Robot(sim.url, link=_HeldBeat(sim, held, release), **options)) as robot:
            yield robot, held, release
        return
    with FaultProxy(sim.port) as proxy:
        proxy.add(Rule("hold", function_code=16, address=BEAT, release=release))
        proxy_held = threading.Thread(
            target=lambda: sim.wait_for(lambda: proxy.played("hold"), 5) or held.set()
        )
        proxy_held.start()
        with _robot_on(Robot("127.0.0.1", proxy.port, **options)) as robot:
            yield robot, held, release
        release.set()
        proxy_held.join(5)
        proxy.wait_held()


@contextmanager
def _robot_on(robot: Robot) -> Iterator[Robot]:
    try:
        robot.connect()
        robot.wait_until_ready(timeout_s=5)
        yield robot
    finally:
        robot.close()


@pytest.mark.parametrize("how", ["sim://", "tcp"])
def test_close_during_the_claim_beat_leaves_no_command_and_no_heartbeat(how: str) -> None:
    with (
        Simulator("tmflow", time_scale=20.0, listen=how == "tcp") as sim,
        _robot(how, sim) as (robot, held, release),
    ):
        outcome: list[str] = []
        mover = moving(robot, outcome)
        assert held.wait(5)  # the claim's beat is on its way
        closer = threading.Thread(target=robot.close)
        closer.start()
        sim.wait_for(lambda: robot._gate.closed, timeout=5)  # no command from now on
        if how == "sim://":
            release.set()  # in process the beat holds the link: close() waits for it
        closer.join(10)
        closed_at = time.time()  # the simulator's request log is on the wall clock
        release.set()  # over TCP the held beat lands now, after close() returned
        mover.join(10)
        assert not closer.is_alive()
        assert not mover.is_alive()
        assert outcome in (["StopRequestedError"], ["TransportClosedError"])
        # Several heartbeat periods (0.1 s): a heartbeat left running would beat in them.
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 20, timeout=5)
        log = sim.request_log
        assert not [r for r in log if r.function_code == 16 and r.address == COMMAND]
        assert not sim.motion_log()
        late = [r for r in log if (r.function_code, r.address) == (16, BEAT) and r.time > closed_at]
        assert len(late) == (1 if how == "tcp" else 0), late  # only the held one


def test_a_close_between_clear_stop_requests_check_and_its_clear_keeps_its_request(
    memory_simulator_factory: Callable[..., Simulator],
) -> None:
    # clear_stop_request() checks that the robot is open, then clears the stop event; a
    # close() on another thread in between (an AsyncRobot worker clears after a cancelled
    # call) had its stop request wiped: a wait in progress then ended on the closed link
    # instead of on the stop request.
    sim = memory_simulator_factory("tmflow")
    robot = Robot(sim.url)
    gate = robot._gate
    checks = 0

    class ClosingMeanwhile:
        @property
        def closed(self) -> bool:
            nonlocal checks
            checks += 1
            if checks == 1:
                robot._stop_event.set()  # close() on another thread, right after the check
                gate.close()
                return False
            return gate.closed

    robot._gate = ClosingMeanwhile()  # type: ignore[assignment]
    try:
        robot.clear_stop_request()
        assert robot._stop_event.is_set()
    finally:
        robot._gate = gate
        robot.close()
