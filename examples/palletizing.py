"""Palletizing: pick parts from one spot and place them into a rows x cols grid.

Start the simulator in one terminal (six parts waiting at the pick position, one for
each slot of a 2 x 3 pallet), then the example in another::

    python -m tmmaster.sim --port 5020 --parts 6
    python examples/palletizing.py --port 5020 --rows 2 --cols 3

Both speak the ``tmflow`` profile unless told otherwise (``--profile article`` on both
for the article's map). Every move is checked before anything is sent: against the
profile's registers and by the TM5-700's inverse kinematics. Pallets of up to 3 x 3
slots and 3 layers at the default pitch stay within +/-327.67 mm, the range of the
article profile's int16 x100 registers, and well above the table; a slot out of range
or out of reach is refused with its number before the first move.
"""

from __future__ import annotations

import argparse
import sys

from tmmaster import (
    DEFAULT_HOME,
    DEFAULT_PROFILE,
    Pose,
    Robot,
    TimeoutPolicy,
    TMMasterError,
    configure_logging,
)
from tmmaster.pickplace import Pallet, Runner, palletizing

PICK = Pose(300, -200, 100, 180, 0, 90)
HOME = DEFAULT_HOME  # tool down, 250 mm in front of J1: reachable by a TM5-700
#: Slot 1; columns go along +x, rows along +y, layers up (a part's centre, 100 mm up).
PALLET_ORIGIN = Pose(240, 140, 100, 180, 0, 90)


def given_up(robot: Robot | None) -> str:
    """What became of the robot's last command, as ``robot.close()`` says (safe twice)."""
    if robot is None or robot.close():
        return "nothing the robot was sent can still run"
    return "could NOT confirm that the robot gave its command up: the arm may still move"


def main(argv: list[str] | None = None) -> int:
    """Fill the pallet; returns 0 when every slot got its part."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=5020)
    parser.add_argument("--profile", default=DEFAULT_PROFILE, help=f"default: {DEFAULT_PROFILE}")
    parser.add_argument("--rows", type=int, default=2)
    parser.add_argument("--cols", type=int, default=2)
    parser.add_argument("--layers", type=int, default=1)
    parser.add_argument("--pitch", type=float, default=40.0, help="dx = dy, mm")
    parser.add_argument("--layer-height", type=float, default=30.0, help="dz, mm")
    parser.add_argument(
        "--settle",
        type=float,
        default=0.5,
        help="gripper settle time, s (the article map's gripper has no busy flag)",
    )
    args = parser.parse_args(argv)
    configure_logging(level="warning")

    robot: Robot | None = None
    try:
        pallet = Pallet(
            origin=PALLET_ORIGIN,
            rows=args.rows,
            cols=args.cols,
            dx=args.pitch,
            dy=args.pitch,
            layers=args.layers,
            dz=args.layer_height,
        )
        sequence = palletizing(pick=PICK, pallet=pallet, home=HOME)
        with Robot(
            args.host,
            args.port,
            profile=args.profile,
            timeouts=TimeoutPolicy(gripper_settle_s=args.settle),
            # The default Workspace() is the simulated cell (its table top at 85 mm): on
            # yours, checks=Checks(workspace=Workspace(floor_z_mm=your table top's height).
        ) as robot:
            # Every slot is checked against the profile and the arm before the first move
            # (the runner's check: a slot it cannot take fails the run in IDLE).
            result = Runner(robot).run(sequence, source=f"{args.rows}x{args.cols} pallet")
    except TMMasterError as exc:
        print(f"palletizing: {exc}", file=sys.stderr)
        if robot is not None:
            print(f"palletizing: {given_up(robot)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # Ctrl-C: the move in progress was given up before this
        print(f"palletizing: interrupted; {given_up(robot)}", file=sys.stderr)
        return 130
    if result.failure is not None:
        print(
            f"palletizing: failed in {result.failure.state}: {result.failure.message}",
            file=sys.stderr,
        )
        print(f"palletizing: {given_up(robot)}", file=sys.stderr)
    print(
        f"palletizing: {result.cycles_completed}/{pallet.size} slots filled,"
        f" {result.state}, cycle times {result.cycle_times_s}"
    )
    return 0 if result.ok else 1


if __name__ == "__main__":
    sys.exit(main())
