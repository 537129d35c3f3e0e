"""Pick & place from your own script: the article's cycle through the Python API.

Start the simulator in one terminal, then the example in another::

    python -m tmmaster.sim --port 5020
    python examples/pick_and_place.py --port 5020 --cycles 1

Both speak the ``tmflow`` profile unless told otherwise (``--profile article`` on both
for the article's map). Against a robot running the robot program
(docs/tmflow-program.md): ``--host 192.168.1.100 --port 502``.
"""

from __future__ import annotations

import argparse
import sys

from tmmaster import DEFAULT_PROFILE, Robot, TMMasterError, configure_logging
from tmmaster.pickplace import Runner, load_config, pick_and_place, robot_from_config


def given_up(robot: Robot | None) -> str:
    """What became of the robot's last command, as ``robot.close()`` says (safe twice)."""
    if robot is None or robot.close():
        return "nothing the robot was sent can still run"
    return "could NOT confirm that the robot gave its command up: the arm may still move"


def main(argv: list[str] | None = None) -> int:
    """Run the article's pick & place; returns 0 when every cycle is done."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=5020)
    parser.add_argument("--profile", default=DEFAULT_PROFILE, help=f"default: {DEFAULT_PROFILE}")
    parser.add_argument("--config", default=None, help="a pick & place TOML file")
    parser.add_argument("--cycles", type=int, default=1)
    args = parser.parse_args(argv)
    configure_logging(level="warning")

    robot: Robot | None = None
    try:
        # Everything is validated here, before a single byte goes out: the options are
        # applied to the file once, and the rest reads only the configuration.
        robot_options = {"host": args.host, "port": args.port, "profile": args.profile}
        config = load_config(
            args.config, overrides={"robot": robot_options, "run": {"cycles": args.cycles}}
        )
        sequence = pick_and_place(config)
        with robot_from_config(config) as robot:
            # The runner checks every move of every cycle from where the arm is before
            # its first command: a move it cannot take fails the run in IDLE, nothing sent.
            runner = Runner.from_config(robot, config)
            result = runner.run(sequence, source=args.config or "defaults")
    except TMMasterError as exc:  # config error or no connection
        print(f"pick_and_place: {exc}", file=sys.stderr)
        if robot is not None:
            print(f"pick_and_place: {given_up(robot)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # Ctrl-C: the move in progress was given up before this
        print(f"pick_and_place: interrupted; {given_up(robot)}", file=sys.stderr)
        return 130

    for state, timing in result.state_timings().items():
        print(f"{state:<18} {timing['count']:>3} x  mean {timing['mean_s']:.3f} s")
    if not result.ok:
        assert result.failure is not None
        print(f"failed in {result.failure.state}: {result.failure.message}", file=sys.stderr)
        print(f"pick_and_place: {given_up(robot)}", file=sys.stderr)
        return 1
    print(f"done: {result.cycles_completed} cycle(s), cycle times {result.cycle_times_s}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
