"""A sequence of your own in Python: register states and actions, the runner does the rest.

This one inspects a part: it picks it, shows it to a camera, and puts it back where it
was. Polling, timeouts, retries, stop requests, logging and timing per state come from
the runner, exactly as for the built-in pick & place. Start the simulator in one
terminal, then the example in another::

    python -m tmmaster.sim --port 5020
    python examples/custom_sequence.py --port 5020

Both speak the ``tmflow`` profile unless told otherwise (``--profile article`` on both
for the article's map).
"""

from __future__ import annotations

import argparse
import sys

from tmmaster import DEFAULT_PROFILE, Pose, Robot, TimeoutPolicy, TMMasterError, configure_logging
from tmmaster.pickplace import RetryRule, Runner, StepContext, TaskSequence, mermaid

PART = Pose(300, -200, 100, 180, 0, 90)
ABOVE_PART = PART.offset(dz=100)
CAMERA = Pose(200, 0, 250, 180, 0, 90)


def build_sequence() -> TaskSequence:
    """Pick the part, hold it under the camera, put it back."""
    seq = TaskSequence("inspect", retreat=None)

    @seq.step("MOVE_ABOVE_PART")
    def above(ctx: StepContext) -> None:
        ctx.move(ABOVE_PART, speed=30)

    @seq.step("MOVE_TO_PART")
    def down(ctx: StepContext) -> None:
        ctx.move(PART, speed=10, motion="line")

    def reopen(ctx: StepContext) -> None:
        ctx.open_gripper()

    # A failed grasp: open, go back above the part, try twice more.
    @seq.step("GRIP", retry=RetryRule("MOVE_ABOVE_PART", attempts=2, recover=reopen))
    def grip(ctx: StepContext) -> None:
        ctx.grip()

    @seq.step("SHOW_TO_CAMERA")
    def show(ctx: StepContext) -> None:
        ctx.move(ABOVE_PART, speed=10, motion="line")
        ctx.move(CAMERA, speed=30)
        ctx.data["inspected"] = ctx.data.get("inspected", 0) + 1

    @seq.step("PUT_BACK")
    def put_back(ctx: StepContext) -> None:
        ctx.move(ABOVE_PART, speed=30)
        ctx.move(PART, speed=10, motion="line")
        ctx.open_gripper()
        ctx.move(ABOVE_PART, speed=10, motion="line")

    return seq


def given_up(robot: Robot | None) -> str:
    """What became of the robot's last command, as ``robot.close()`` says (safe twice)."""
    if robot is None or robot.close():
        return "nothing the robot was sent can still run"
    return "could NOT confirm that the robot gave its command up: the arm may still move"


def main(argv: list[str] | None = None) -> int:
    """Run the inspection sequence; returns 0 when done."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=5020)
    parser.add_argument("--profile", default=DEFAULT_PROFILE, help=f"default: {DEFAULT_PROFILE}")
    parser.add_argument(
        "--settle",
        type=float,
        default=0.5,
        help="gripper settle time, s (the article map's gripper has no busy flag)",
    )
    parser.add_argument("--diagram", action="store_true", help="print the mermaid diagram")
    args = parser.parse_args(argv)
    configure_logging(level="warning")
    sequence = build_sequence()
    if args.diagram:
        print(mermaid(sequence))
        return 0
    robot: Robot | None = None
    try:
        with Robot(
            args.host,
            args.port,
            profile=args.profile,
            timeouts=TimeoutPolicy(gripper_settle_s=args.settle),
            # The default Workspace() is the simulated cell (its table top at 85 mm): on
            # yours, checks=Checks(workspace=Workspace(floor_z_mm=your table top's height).
        ) as robot:
            result = Runner(robot).run(sequence)
    except TMMasterError as exc:
        print(f"custom_sequence: {exc}", file=sys.stderr)
        if robot is not None:
            print(f"custom_sequence: {given_up(robot)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # Ctrl-C: the move in progress was given up before this
        print(f"custom_sequence: interrupted; {given_up(robot)}", file=sys.stderr)
        return 130
    print(f"{sequence.name}: {result.state} after {result.duration_s:.2f} s")
    if result.failure is not None:
        print(
            f"custom_sequence: failed in {result.failure.state}: {result.failure.message}",
            file=sys.stderr,
        )
        print(f"custom_sequence: {given_up(robot)}", file=sys.stderr)
    return 0 if result.ok else 1


if __name__ == "__main__":
    sys.exit(main())
