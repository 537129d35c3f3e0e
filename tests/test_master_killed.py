"""A paused move whose master process was killed never moves again at Play.

The master is a separate process (a real one, killed with SIGKILL: no close(), no
clean-up of any kind); the simulated robot runs the generated robot program, whose
heartbeat check is the only thing between the paused move and the operator's Play.
The simulator's motion record and the arm's pose are the judge.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from collections.abc import Iterator

import pytest

from pendant import press_play_pause, runs_again_without_moving
from tmmaster.sim import Simulator

MASTER = textwrap.dedent(
    """
    import sys, time
    from tmmaster import Pose, Robot, TimeoutPolicy

    beat = TimeoutPolicy(heartbeat_s=0.05, heartbeat_ttl_s=0.5)
    robot = Robot("127.0.0.1", int(sys.argv[1]), gripper=None, timeouts=beat)
    robot.connect()
    robot.wait_until_ready()
    robot.move_to(Pose(300, -200, 200, 180, 0, 90), speed=50)
    robot.start_move(Pose(300, 200, 200, 180, 0, 90), speed=5)  # a long turn of J1
    print("moving", flush=True)
    time.sleep(60)
    """
)


@pytest.fixture
def sim() -> Iterator[Simulator]:
    with Simulator(time_scale=5) as simulator:
        yield simulator


def test_a_paused_move_of_a_killed_master_never_moves_again(sim: Simulator) -> None:
    master = subprocess.Popen(
        [sys.executable, "-c", MASTER, str(sim.port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert master.stdout is not None
        assert master.stdout.readline().strip() == "moving"
        sim.wait_for(lambda: len(sim.motion_log()) == 2, timeout=5.0)
        start = sim.motion_log()[0].target
        assert start is not None
        sim.wait_for(lambda: sim.tcp_pose().distance_to(start) > 20, timeout=5.0)
        press_play_pause(sim)  # the operator pauses the project mid-move
        sim.wait_for(lambda: bool(sim.field("paused")), timeout=2.0)
        master.kill()  # the master process dies: nothing closes, nothing beats
        master.wait(timeout=5.0)
        # The program sees the heartbeat stop and ends the project.
        sim.wait_for(lambda: not sim.field("project_running"), timeout=3.0)
        held = sim.tcp_pose()
        press_play_pause(sim)  # the operator presses Play
        runs_again_without_moving(sim, held, moves=2)
    finally:
        if master.poll() is None:
            master.kill()
        master.wait(timeout=5.0)
        for stream in (master.stdout, master.stderr):
            if stream is not None:
                stream.close()
