"""A late stop frame of a closed gripper driver must not end the next driver's move as done.

A stand-alone blog-2fg7's move the master gives up is stopped; when the stop's answer is
lost it is written again, and the first frame may still land later, halting a later move
mid-way, which on blog-2fg7 (no width) reads as one at its target. So a move that
follows such a stop first waits until the retry policy's ``total_time_s`` has passed
(``gripper.stop_in_doubt``, ``tests/test_hunt2_gripper_stop.py``). Here the later move
comes from a *new* driver on the same gripper, made after the first was disconnected
(a new ``Robot`` with its ``GripperDevice``: the next run, a reconnect). The stop frame
is held by a FaultProxy (the blog-2fg7 ``control`` register) and lands as soon as the
new driver either waits for it (``gripper.stop_in_doubt``) or has its open executed by
the simulator. The judge is the simulated fingers: an open reported done has them open.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Iterator

import pytest

from fault_proxy import FaultProxy, Rule
from sim_speeds import SUITE_TICK_HZ
from tmmaster import Blog2FG7Gripper, GripperLink, GripperTimeoutError, RetryPolicy, gripper_profile
from tmmaster.sim import RobotSetup, Simulator, Timing

#: blog-2fg7 at 100 mm/s, half speed on the wall clock: 50 mm/s.
TIME_SCALE = 0.5
#: The retry policy's total time bounds the new driver's wait for the old stop frame.
RETRY = RetryPolicy(attempts=5, total_time_s=0.6, initial_backoff_s=0.01, jitter_s=0.0)


@pytest.fixture
def sim() -> Iterator[Simulator]:
    timing = Timing(tick_hz=SUITE_TICK_HZ)
    simulator = Simulator(
        "tmflow", robot=RobotSetup(gripper="blog-2fg7"), time_scale=TIME_SCALE, timing=timing
    )
    simulator.start()
    try:
        yield simulator
    finally:
        simulator.close()


def fingers(sim: Simulator) -> tuple[bool, float]:
    """Whether the simulated fingers move, and their width, mm."""
    state = sim.call(lambda: sim.backend.gripper_state())
    return bool(state.moving), float(state.width_mm)


class _Seen(logging.Handler):
    """Sets ``event`` once a record naming ``name`` is logged."""

    def __init__(self, name: str, event: threading.Event) -> None:
        super().__init__(logging.DEBUG)
        self.name_seen, self.event = name, event

    def emit(self, record: logging.LogRecord) -> None:
        if self.name_seen in record.getMessage():
            self.event.set()


def moves_executed(sim: Simulator) -> int:
    """How many gripper moves (FC16 from force through control) the simulator executed."""
    return sum(
        1
        for r in sim.request_log
        if r.server == "gripper" and r.function_code == 16 and r.address == 0
    )


def test_a_new_drivers_open_is_not_halted_by_the_old_drivers_late_stop(sim: Simulator) -> None:
    assert sim.gripper_port is not None
    profile = gripper_profile("blog-2fg7")
    release, waited, done = threading.Event(), threading.Event(), threading.Event()
    logger = logging.getLogger("tmmaster")
    handler, level = _Seen("gripper.stop_in_doubt", waited), logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.DEBUG)
    watcher: threading.Thread | None = None
    try:
        with FaultProxy(sim.gripper_port) as proxy:

            def link() -> GripperLink:
                return GripperLink(
                    "127.0.0.1",
                    proxy.port,
                    poll_interval_s=0.01,
                    retry=RETRY,
                    request_timeout_s=0.1,
                )

            first = Blog2FG7Gripper(profile, link())
            first.connect()
            try:
                stop = profile.field("control").address
                proxy.add(Rule("hold", function_code=16, address=stop, release=release))
                with pytest.raises(GripperTimeoutError):
                    first.close(timeout_s=0.3)  # given up: its stop held, retried, answered
                assert proxy.played("hold")
            finally:
                first.disconnect()
            before = moves_executed(sim)

            def release_once_waited_or_moving() -> None:
                # The held stop lands once the new driver waits for it, or has its open
                # executed: whichever comes first.
                while not (waited.is_set() or moves_executed(sim) > before):
                    if done.wait(0.005):
                        return
                release.set()

            watcher = threading.Thread(target=release_once_waited_or_moving)
            watcher.start()
            second = Blog2FG7Gripper(profile, link())
            second.connect()
            try:
                opened = second.open(timeout_s=3.0)
                proxy.wait_held()
            finally:
                second.disconnect()
    finally:
        done.set()
        release.set()
        if watcher is not None:
            watcher.join(5)
        logger.removeHandler(handler)
        logger.setLevel(level)
    assert not opened.busy
    sim.wait_for(lambda: not fingers(sim)[0], timeout=3)
    width = fingers(sim)[1]
    # Reported open: the fingers must be open (the simulated stroke ends at 39 mm).
    assert width >= 38.5, f"open() reported done with the fingers at {width:.1f} mm"
