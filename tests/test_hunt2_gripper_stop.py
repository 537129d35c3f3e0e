"""A late stop frame of a stand-alone gripper must not end a later move as "done".

A move the master gives up is stopped (``tests/test_gripper_given_up.py``). When that
stop's answer is lost, the master writes it again on a new connection, but the first
frame may still reach the device later, in the middle of the NEXT move, and halt the
fingers there. The blog-2fg7 map reports no width, and a device halted reads like one
at its target (gOBJ 3): the master would report a width it never reached. The judge is
the simulated fingers: a move the master reports done must have reached its target.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from fault_proxy import FaultProxy
from fault_proxy import Rule as FaultRule
from sim_speeds import SUITE_TICK_HZ
from tmmaster import (
    Blog2FG7Gripper,
    GripperLink,
    GripperTimeoutError,
    RetryPolicy,
    gripper_profile,
)
from tmmaster.sim import RobotSetup, Simulator, Timing

#: blog-2fg7 at 100 mm/s, half speed on the wall clock: 50 mm/s.
TIME_SCALE = 0.5


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


def test_a_late_stop_frame_never_ends_a_later_blog_2fg7_move_as_done(sim: Simulator) -> None:
    assert sim.gripper_port is not None
    profile = gripper_profile("blog-2fg7")
    with FaultProxy(sim.gripper_port) as proxy:
        # Everything the master does waits for no frame of its own beyond 0.6 s.
        retry = RetryPolicy(attempts=5, total_time_s=0.6, initial_backoff_s=0.01, jitter_s=0.0)
        link = GripperLink(
            "127.0.0.1", proxy.port, poll_interval_s=0.01, retry=retry, request_timeout_s=0.1
        )
        gripper = Blog2FG7Gripper(profile, link)
        gripper.connect()
        try:
            # The stop written after a close given up is held in the network and lands
            # 0.25 s later, well inside the retry policy's 0.6 s: by then the master has
            # written it again (answered) and sent the open, whose fingers need about
            # 0.3 s to travel the 15 mm the close went.
            stop = profile.field("control").address
            proxy.add(FaultRule("hold", function_code=16, address=stop, delay_s=0.25))
            with pytest.raises(GripperTimeoutError):
                gripper.close(timeout_s=0.3)
            opened = gripper.open(timeout_s=2.0)
            proxy.wait_held()
        finally:
            gripper.disconnect()
    assert not opened.busy
    moving, width = fingers(sim)
    assert not moving
    # Reported open: the fingers must be open (the simulated stroke ends at 39 mm).
    assert width >= 38.5, f"open() reported done with the fingers at {width:.1f} mm"
