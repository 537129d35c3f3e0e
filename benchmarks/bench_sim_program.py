"""CPU per control tick of the simulated tmflow robot, idle and commanded.

The simulated ``tmflow`` robot runs the robot program (``tmmaster robot-program``)
through the TMscript interpreter on each control tick. This measures what a tick costs,
without threads or sockets: controllers are ticked in a plain loop, so the figure is the
simulator's own CPU per robot per tick.

- ``idle``: the project runs, nobody commands (the program polls its command block).
- ``moving``: a master's writes are played into the register bank directly: a PTP to
  and fro, the next command as soon as the previous one is done.

Run it on the current code, and with ``PYTHONPATH`` pointing at another revision's
``src`` to compare (docs/performance.md shows both)::

    python benchmarks/bench_sim_program.py --robots 20 --ticks 500
    python benchmarks/bench_sim_program.py --profile article  # the article's slave
"""

from __future__ import annotations

import argparse
import time

from tmmaster import Pose
from tmmaster._profiles import robot_profile
from tmmaster._robot_models import robot_model
from tmmaster._transport import encode_writes, group_writes
from tmmaster.sim._kinematic import KinematicBackend
from tmmaster.sim._world import World


def make_controllers(n: int, profile_name: str = "tmflow") -> list[object]:
    """``n`` simulated robots, as ``Simulator`` builds them (tmflow: default program)."""
    from tmmaster.sim import _simulator
    from tmmaster.sim._clear_on_accept import ClearOnAcceptController

    profile = robot_profile(profile_name)
    model = robot_model("tm5-700")
    out = []
    for _ in range(n):
        backend = KinematicBackend(model, world=World(()))
        if profile_name == "article":
            cls, options = ClearOnAcceptController, {}
        else:
            cls, options = _simulator._script_project(profile, "generated", None)
        bank = cls.bank_for(profile)
        out.append((cls(profile, bank, backend, model, **options), bank))
    return out


def command(bank: object, seq: int, target: Pose, profile_name: str = "tmflow") -> None:
    """Write a PTP command block into ``bank`` as a master's FC16 would."""
    profile = robot_profile(profile_name)
    words = [
        (profile.field(f"target_{n}"), v)
        for n, v in zip(["x", "y", "z", "rx", "ry", "rz"], target.as_list(), strict=True)
    ]
    words += [(profile.field("speed"), 100), (profile.field("command"), 1)]
    if profile_name != "article":
        words += [(profile.field("accel_time"), 0), (profile.field("seq"), seq)]
    for block, values in group_writes(encode_writes(words)):
        bank.write(block.table, block.address, values)  # type: ignore[attr-defined]


def _done(bank: object, seq: int, profile_name: str) -> bool:
    """Whether the robot finished command ``seq`` (the article: it cleared the command)."""
    get = bank.get  # type: ignore[attr-defined]
    if profile_name == "article":
        return bool(get("command") == 0 and get("motion_status") == 0)
    return bool(int(get("done_seq")) == seq)


def run(n: int, ticks: int, moving: bool, profile_name: str = "tmflow") -> float:
    """Microseconds of CPU per robot per tick."""
    robots = make_controllers(n, profile_name)
    dt = 0.02  # 50 Hz, real time
    for _ in range(50):  # initialise, start the project
        for controller, _bank in robots:
            controller.tick(dt)  # type: ignore[attr-defined]
    targets = (Pose(300, -200, 150, 180, 0, 90), Pose(300, -200, 250, 180, 0, 90))
    seqs = [0] * n
    started = time.process_time()
    for _ in range(ticks):
        for i, (controller, bank) in enumerate(robots):
            if moving and _done(bank, seqs[i], profile_name):
                seqs[i] += 1
                command(bank, seqs[i], targets[seqs[i] % 2], profile_name)
            controller.tick(dt)  # type: ignore[attr-defined]
    return (time.process_time() - started) * 1e6 / (n * ticks)


def main() -> None:
    """Print idle and moving figures, several rounds each."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=20)
    parser.add_argument("--ticks", type=int, default=500)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--profile", choices=("tmflow", "article"), default="tmflow")
    args = parser.parse_args()
    for moving in (False, True):
        figures = [run(args.robots, args.ticks, moving, args.profile) for _ in range(args.rounds)]
        print(
            f"{args.profile} {'moving' if moving else 'idle':6}"
            f" {args.robots} robots x {args.ticks} ticks:"
            f" {min(figures):.0f} us per robot tick (least of {len(figures)} rounds)"
            f"; rounds: {', '.join(f'{f:.0f}' for f in figures)}"
        )


if __name__ == "__main__":
    main()
