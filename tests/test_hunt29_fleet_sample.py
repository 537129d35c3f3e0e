"""The Fleet sample of docs/robot-api.md ("Driving many robots: Fleet"), run as a user
pastes it into a script: a robot that fails makes the script exit nonzero, naming it,
and Ctrl-C stops every arm.

The sample is marked skip for test_doc_samples.py (real robots' addresses); here its
two addresses are put on two simulators on loopback, and it runs as a script of its own
(``python -c``), since the exit code is the subject.

Found by hunt 29 ("the code users copy"); the first test fails without the fix: each
robot's thread let its error escape, which Python prints and forgets, so with cell-2
e-stopped the script exited 0.
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

from safety_invariant import wait_braked
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

PAGE = Path(__file__).resolve().parents[1] / "docs" / "robot-api.md"
_BLOCK = re.compile(r"^```python\n(.*?)^```", re.DOTALL | re.MULTILINE)


def fleet_sample(port_1: int, port_2: int) -> str:
    """The page's Fleet sample, its two robots on ``port_1`` and ``port_2`` of 127.0.0.1."""
    blocks: list[str] = _BLOCK.findall(PAGE.read_text("utf-8"))
    (code,) = [b for b in blocks if "with Fleet(" in b]
    for address, port in (("192.168.1.11", port_1), ("192.168.1.12", port_2)):
        assert f'Robot("{address}", ' in code
        code = code.replace(f'Robot("{address}", ', f'Robot("127.0.0.1", {port}, ')
    return code


def start(code: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def moving(sim: Simulator) -> None:
    sim.wait_for(lambda: len(sim.motion_log()) == 1, timeout=30.0)


def test_a_robot_that_fails_fails_the_script(tm_simulator_factory: Factory) -> None:
    sim_1 = tm_simulator_factory()
    sim_2 = tm_simulator_factory(faults=["estop:at_move=1"])
    process = start(fleet_sample(sim_1.port, sim_2.port))
    _, err = process.communicate(timeout=60)
    assert [m.done_wall_time is not None for m in sim_1.motion_log()] == [True]
    assert [m.done_wall_time is not None for m in sim_2.motion_log()] == [False]
    assert process.returncode == 1, err
    assert "'cell-2': EmergencyStopError(" in err
    assert "cell-1" not in err


def test_ctrl_c_stops_every_arm(tm_simulator_factory: Factory) -> None:
    # Real time: the move takes seconds, the script's start-up does not matter.
    sim_1 = tm_simulator_factory(time_scale=1.0)
    sim_2 = tm_simulator_factory(time_scale=1.0)
    process = start(fleet_sample(sim_1.port, sim_2.port))
    try:
        for sim in (sim_1, sim_2):
            moving(sim)
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=30)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == -signal.SIGINT, err  # Python's exit on a KeyboardInterrupt
    assert "KeyboardInterrupt" in err
    for sim in (sim_1, sim_2):
        (motion,) = sim.motion_log()
        assert motion.done_wall_time is None  # stopped, never reported done
        wait_braked(sim)  # the stopped arm braked to rest, short of the target
        assert motion.target is not None
        assert not sim.tcp_pose().is_close(motion.target, mm=1.0, deg=1.0)
        assert sim.motion_log() == (motion,)
