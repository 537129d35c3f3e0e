"""Physics backends: how many times faster than real time the pick & place cycle runs.

Each backend runs the article's cycle (approach, pick, close, lift, place, open, home,
speeds 30 % / 10 %) driven directly, tick by tick (``dt`` = 20 ms of simulated time, the
controller's 50 Hz), with no Modbus and no master (MuJoCo twice: its default, arm
dynamics, whose moves end once the joints settled, and ``dynamics=False``, the ideal
servo setting the joints along the plan): the figure is
simulated seconds per wall second of the backend alone (and per CPU second of this
process, which a busy machine disturbs less), median of ``--rounds``. For MuJoCo it also
times a model rebuild (``reinitialize()``). Run::

    python benchmarks/bench_physics.py --rounds 5
"""

from __future__ import annotations

import argparse
import functools
import statistics
import time
from collections.abc import Callable

import tmmaster
from tmmaster import Pose
from tmmaster._pose import MotionType
from tmmaster.sim import KinematicBackend, PhysicsBackend

DT = 0.02
HOME = Pose(250, 0, 300, 180, 0, 90)
PICK = Pose(300, -200, 100, 180, 0, 90)
PLACE = Pose(300, 200, 200, 180, 0, 90)
PTP, LINE = MotionType.PTP, MotionType.LINE
CYCLE = [
    ("move", PICK.offset(dz=100), PTP, 30),
    ("move", PICK, LINE, 10),
    ("grip", 0.0),
    ("move", PICK.offset(dz=150), LINE, 10),
    ("move", PLACE, PTP, 30),
    ("grip", 39.0),
    ("move", HOME, PTP, 30),
]


def run_cycle(backend: PhysicsBackend) -> float:
    """Run one cycle; return the simulated seconds it took."""
    sim_s = 0.0

    def until(done: Callable[[], bool]) -> None:
        nonlocal sim_s
        while True:
            backend.step(DT)
            sim_s += DT
            if done():
                return

    for step in CYCLE:
        if step[0] == "move":
            _, target, motion, speed = step
            backend.start_motion(target, motion=motion, speed_percent=speed, accel_time_s=0.2)
            until(backend.is_settled)
        else:
            backend.drive_gripper(step[1], speed_mm_s=100, force_n=40)
            until(lambda: not backend.gripper_state().moving)
    return sim_s


def measure(make: Callable[[], PhysicsBackend], rounds: int) -> tuple[float, float, float]:
    """Median x real time (wall clock, and CPU time of this process), cycle length."""
    wall, cpu = [], []
    sim_s = 0.0
    for _ in range(rounds):
        backend = make()
        start, start_cpu = time.perf_counter(), time.process_time()
        sim_s = run_cycle(backend)
        wall.append(sim_s / (time.perf_counter() - start))
        cpu.append(sim_s / (time.process_time() - start_cpu))
    return statistics.median(wall), statistics.median(cpu), sim_s


def main() -> None:
    """Print the x-real-time figure of each backend."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    model = tmmaster.robot_model("tm5-700")
    wall, cpu, sim_s = measure(lambda: KinematicBackend(model, home=HOME), args.rounds)
    print(
        f"kinematic: cycle {sim_s:.2f} s simulated, {wall:,.0f}x real time ({cpu:,.0f}x per CPU s)"
    )
    try:
        from tmmaster.sim._mujoco import MuJoCoBackend
    except ImportError:
        print("mujoco: not installed (pip install 'tmmaster[mujoco]')")
        return

    for label, dynamics in (("default, dynamics on", None), ("dynamics=False", False)):
        make = functools.partial(MuJoCoBackend, model, home=HOME, dynamics=dynamics)
        wall, cpu, sim_s = measure(make, args.rounds)
        print(
            f"mujoco ({label}): cycle {sim_s:.2f} s simulated, {wall:.1f}x real time"
            f" ({cpu:.1f}x per CPU s)"
        )
    backend = MuJoCoBackend(model, home=HOME)
    rebuilds = []
    for _ in range(max(args.rounds, 5)):
        backend.invalidate()
        backend.reinitialize()
        rebuilds.append(backend.last_rebuild_s)
    print(f"mujoco:    model rebuild (reinitialize) {statistics.median(rebuilds) * 1000:.1f} ms")


if __name__ == "__main__":
    main()
