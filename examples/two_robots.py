"""Two robots, one program: robot A hands a part over to robot B.

Robot A picks the part at its pick position, puts it down on a handover table and moves
clear; robot B, waiting clear of the table, then picks it up from the handover table and
puts it down at its own place position. Each robot is driven from its own thread (the
library is synchronous: one thread per robot is the simple, measured choice, see
docs/architecture.md), and the threads coordinate with a :class:`threading.Barrier`
(both ready) and a :class:`threading.Event` (A has released the part and moved clear):
B's move to the handover table starts only after that event.

The two robots stand side by side, facing the same way: B's base is ``B_OFFSET_Y_MM``
(400 mm) along A's y axis. Each robot is given poses in its own base frame, so the
handover point is ``HANDOVER`` for A and ``HANDOVER_B``, the same point, for B. With
real robots, measure where B's base stands in A's frame (calibrate it) and set the
offset, and check that the waiting and clearing poses keep the two arms apart.

Run against two simulators it starts itself (the default)::

    python examples/two_robots.py --sim

or against two robots (or simulators) already listening::

    python -m tmmaster.sim --port 5020 &
    python -m tmmaster.sim --port 5030 &
    python examples/two_robots.py --host 127.0.0.1 --port-a 5020 --port-b 5030

Both speak the ``tmflow`` profile unless told otherwise (``--profile article`` on the
simulators and here for the article's map, which is only safe against its simulator).

Be aware of what the simulation does NOT do: the two simulators do not share a world.
A's part really travels in A's simulated world (it ends up on A's handover table), but
nothing carries it into B's: B's simulator has a part of its own at the handover point
from the start. The simulator puts its parts at ``PICK_A``'s coordinates unless told
otherwise, which is where A picks and, in B's frame, the handover point: so the two
simulators above need no options. Only the coordination between the two programs is
real here; the handover itself is modelled by giving both worlds a part.

When one robot fails, the cell stops: the other robot's move in progress is given up
(the arm stopped) and it sends nothing more (``Robot.interrupt()``), so neither arm moves
on toward a table the other may still stand over. Ctrl-C does the same for both and
exits with code 130; any failure exits with 1, naming what failed.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from tmmaster import (
    DEFAULT_PROFILE,
    Pose,
    Robot,
    StopRequestedError,
    TimeoutPolicy,
    TMMasterError,
)
from tmmaster.sim import Cell, ObjectState, Simulator, TableObject

HOST = "127.0.0.1"
#: Where B's base stands, along A's y axis (B faces the same way as A), mm.
B_OFFSET_Y_MM = 400.0
#: Where robot A's part lies (the article's pick position), in A's frame.
PICK_A = Pose(300.0, -200.0, 100.0, 180.0, 0.0, 90.0)
#: The handover table in A's frame (the article's place position, on the table)...
HANDOVER = Pose(300.0, 200.0, 100.0, 180.0, 0.0, 90.0)
#: ... and the same point in B's frame.
HANDOVER_B = HANDOVER.offset(dy=-B_OFFSET_Y_MM)
#: Where robot B puts the part down, in B's frame.
PLACE_B = Pose(300.0, 200.0, 100.0, 180.0, 0.0, 90.0)
#: Approach and retreat height above a pick or place pose, mm.
CLEARANCE_MM = 100.0
SPEED = 80
#: Longest B waits for A to release the part before giving up, wall seconds.
HANDOVER_TIMEOUT_S = 60.0


def above(pose: Pose) -> Pose:
    """The approach pose straight above ``pose``."""
    return Pose(pose.x, pose.y, pose.z + CLEARANCE_MM, pose.rx, pose.ry, pose.rz)


@dataclass
class Handover:
    """What the two robot threads share."""

    ready: threading.Barrier = field(default_factory=lambda: threading.Barrier(2))
    #: Set by A once the part is released and A's gripper has moved clear.
    released: threading.Event = field(default_factory=threading.Event)
    #: Set by either robot when it failed, so the other does not wait for nothing.
    failed: threading.Event = field(default_factory=threading.Event)
    #: (monotonic time, robot, step) of every step, for the report and the tests.
    steps: list[tuple[float, str, str]] = field(default_factory=list)
    errors: dict[str, BaseException] = field(default_factory=dict)
    #: The robots, by name: a failure or Ctrl-C interrupts them all.
    robots: dict[str, Robot] = field(default_factory=dict)
    #: True once Ctrl-C stopped the run.
    interrupted: bool = False
    #: The robots whose close() could not confirm that nothing they sent can still run.
    unconfirmed: list[str] = field(default_factory=list)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def log(self, robot: str, step: str) -> None:
        """Record a step (thread-safe) and print it."""
        with self._lock:
            self.steps.append((time.monotonic(), robot, step))
        print(f"[{robot}] {step}", flush=True)

    def fail(self, robot: str, error: BaseException) -> None:
        """Record ``robot``'s failure and stop the cell: every robot's move in progress is
        given up, and no robot sends another command (``Robot.interrupt()``)."""
        with self._lock:
            first = next(iter(self.errors), None)
            if isinstance(error, StopRequestedError) and first and not self.interrupted:
                # Stopped because the other robot failed (not by Ctrl-C): say so.
                stopped = RuntimeError(f"robot {first} failed: robot {robot} stopped")
                stopped.__cause__ = error
                error = stopped
            self.errors[robot] = error
        self.failed.set()
        self.stop_all()

    def interrupt(self) -> None:
        """Ctrl-C: every robot gives its command up and sends nothing more."""
        self.interrupted = True
        self.stop_all()

    def stop_all(self) -> None:
        """Interrupt every robot and wake every thread that waits for the other."""
        for robot in self.robots.values():
            robot.interrupt()  # the move in progress is given up; nothing new is sent
        self.released.set()  # wake B (it checks `failed` first)
        self.ready.abort()  # wake a partner still waiting to start

    def check(self, robot: str) -> None:
        """Raise unless the run goes on (no failure, no Ctrl-C)."""
        if self.interrupted:
            raise StopRequestedError(f"robot {robot}: interrupted")
        if self.failed.is_set():
            raise RuntimeError(f"robot {next(iter(self.errors), '?')} failed: no handover")

    def time_of(self, robot: str, step: str) -> float:
        """When ``robot`` did ``step`` (KeyError if it never did)."""
        for at, who, what in self.steps:
            if who == robot and what == step:
                return at
        raise KeyError(f"{robot} never did {step!r}")


def pick(robot: Robot, pose: Pose) -> None:
    """Approach from above, go down, grip (an empty grip raises), go back up."""
    robot.move_to(above(pose), speed=SPEED)
    robot.move_to(pose, speed=SPEED, motion="line")
    robot.gripper.grip()
    robot.move_to(above(pose), speed=SPEED, motion="line")


def place(robot: Robot, pose: Pose) -> None:
    """Approach from above, go down, open, go back up."""
    robot.move_to(above(pose), speed=SPEED)
    robot.move_to(pose, speed=SPEED, motion="line")
    robot.gripper.open()
    robot.move_to(above(pose), speed=SPEED, motion="line")


def robot_a(robot: Robot, shared: Handover) -> None:
    """A: pick the part, put it on the handover table, move clear, then tell B."""
    robot.wait_until_ready()
    shared.ready.wait(HANDOVER_TIMEOUT_S)
    pick(robot, PICK_A)
    shared.log("A", "picked")
    place(robot, HANDOVER)
    # Only now, with A's fingers open and A back over its own pick position, may B come.
    robot.move_to(above(PICK_A), speed=SPEED)
    shared.log("A", "released")
    shared.released.set()


def robot_b(robot: Robot, shared: Handover) -> None:
    """B: wait clear of the handover table until A has released, then take the part over."""
    robot.wait_until_ready()
    shared.ready.wait(HANDOVER_TIMEOUT_S)
    robot.move_to(above(PLACE_B), speed=SPEED)
    shared.log("B", "waiting clear of handover")
    if not shared.released.wait(HANDOVER_TIMEOUT_S):
        raise TimeoutError(f"A did not release the part within {HANDOVER_TIMEOUT_S:g} s")
    shared.check("B")
    shared.log("B", "going to handover")
    pick(robot, HANDOVER_B)
    shared.log("B", "picked")
    place(robot, PLACE_B)
    shared.log("B", "placed")


def run(
    port_a: int,
    port_b: int,
    *,
    host: str = HOST,
    profile: str = DEFAULT_PROFILE,
    settle_s: float = 0.5,
) -> Handover:
    """Drive both robots, one thread each; errors are collected in the result.

    A failure of either robot stops both (:meth:`Handover.fail`). Ctrl-C (KeyboardInterrupt
    in this, the main thread) interrupts both robots, waits until each has given its
    command up and closed, then is raised again.
    """
    shared = Handover()
    jobs: dict[str, Callable[[Robot, Handover], None]] = {"A": robot_a, "B": robot_b}
    for name, port in (("A", port_a), ("B", port_b)):
        # Made here, before any thread starts: a failure or Ctrl-C can interrupt both.
        shared.robots[name] = Robot(
            host,
            port,
            profile=profile,
            name=f"robot-{name}",
            timeouts=TimeoutPolicy(gripper_settle_s=settle_s),
            # The default Workspace() is the simulated cell (its table top at 85 mm): on
            # yours, checks=Checks(workspace=Workspace(floor_z_mm=your table top's height).
        )

    def worker(name: str) -> None:
        robot = shared.robots[name]
        try:
            robot.connect()
            jobs[name](robot, shared)
        except BaseException as exc:  # reported by main(); the other robot is stopped
            shared.fail(name, exc)
        finally:
            # close() says whether it could confirm that nothing the robot sent can run.
            if not robot.close():
                shared.unconfirmed.append(robot.name)

    threads = [threading.Thread(target=worker, args=(n,), name=f"robot-{n}") for n in jobs]
    for t in threads:
        t.start()
    try:
        for t in threads:
            # join() with a timeout in a loop: the main thread stays responsive to Ctrl-C.
            while t.is_alive():
                t.join(0.5)
    except KeyboardInterrupt:
        shared.interrupt()  # each move in progress is given up (the arm stopped)
        for t in threads:
            t.join()
        raise Interrupted(shared) from None
    return shared


class Interrupted(KeyboardInterrupt):
    """Ctrl-C ended the run once both robots had given their commands up and closed."""

    def __init__(self, handover: Handover) -> None:
        super().__init__("interrupted")
        #: What the run did until then (its ``unconfirmed`` robots included).
        self.handover = handover


@dataclass
class SimResult:
    """A run on two simulators, with each simulated world's objects at the end."""

    handover: Handover
    objects_a: list[ObjectState]
    objects_b: list[ObjectState]


def run_with_simulators(time_scale: float = 10.0, *, profile: str = DEFAULT_PROFILE) -> SimResult:
    """Start two simulators (A: part at PICK_A; B: part at HANDOVER_B) and run."""
    sim_a = Simulator(
        profile, time_scale=time_scale, cell=Cell(scene=[TableObject(name="part", pose=PICK_A)])
    )
    # B's world gets its own part at the handover point: the worlds are not linked.
    sim_b = Simulator(
        profile, time_scale=time_scale, cell=Cell(scene=[TableObject(name="part", pose=HANDOVER_B)])
    )
    with sim_a, sim_b:
        # The gripper's settle time is physical time: scale it with the simulation.
        shared = run(sim_a.port, sim_b.port, profile=profile, settle_s=1.0 / time_scale)
        return SimResult(shared, sim_a.objects(), sim_b.objects())


def check_worlds(result: SimResult) -> list[str]:
    """Problems with the final object positions (empty when both parts are where expected)."""
    problems = []
    for name, objects, expected in (
        ("A", result.objects_a, HANDOVER),
        ("B", result.objects_b, PLACE_B),
    ):
        part = next(o for o in objects if o.name == "part")
        if part.held or not part.pose.is_close(expected, mm=1.0, deg=1.0):
            problems.append(f"{name}'s part is at {part.pose} (held={part.held}), not {expected}")
    return problems


def main(argv: Sequence[str] | None = None) -> int:
    """Parse options, run the handover, report; exit code 0 on success."""
    parser = argparse.ArgumentParser(description="Robot A hands a part over to robot B.")
    parser.add_argument("--sim", action="store_true", help="start two simulators (default)")
    parser.add_argument("--host", default=HOST, help="robots' host (default 127.0.0.1)")
    parser.add_argument("--port-a", type=int, help="robot A's Modbus TCP port")
    parser.add_argument("--port-b", type=int, help="robot B's Modbus TCP port")
    parser.add_argument(
        "--profile",
        default=DEFAULT_PROFILE,
        help=f"both robots' profile (default: {DEFAULT_PROFILE})",
    )
    parser.add_argument("--time-scale", type=float, default=10.0, help="with --sim")
    parser.add_argument(
        "--settle",
        type=float,
        default=0.5,
        help="gripper settle time, s (the article map's gripper has no busy flag)",
    )
    args = parser.parse_args(argv)
    try:
        return handover(parser, args)
    except Interrupted as exc:
        unconfirmed = exc.handover.unconfirmed
        if unconfirmed:
            names = ", ".join(unconfirmed)
            print(f"interrupted: could NOT confirm that {names} stopped: check", file=sys.stderr)
        else:
            print("interrupted: both robots gave their commands up", file=sys.stderr)
        return 130
    except KeyboardInterrupt:  # again, while the robots gave their commands up
        print("interrupted: each robot gives its command up as it closes", file=sys.stderr)
        return 130
    except TMMasterError as exc:  # a robot's option refused before anything was sent
        print(f"two_robots: {exc}", file=sys.stderr)
        return 1


def handover(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    """Run the handover the options ask for and report it; the exit code."""
    given = (args.port_a, args.port_b)
    checked = ""
    if args.sim or given == (None, None):
        if given != (None, None):
            parser.error("--sim starts its own simulators: do not give --port-a/--port-b")
        result = run_with_simulators(args.time_scale, profile=args.profile)
        shared = result.handover
        problems = [] if shared.errors else check_worlds(result)
        for problem in problems:
            print(f"FAILED check: {problem}", file=sys.stderr)
        checked = ", both simulated parts where expected"
    elif None in given:
        parser.error("give both --port-a and --port-b (or --sim)")
    else:
        shared = run(
            args.port_a, args.port_b, host=args.host, profile=args.profile, settle_s=args.settle
        )
        problems = []
    for name, error in sorted(shared.errors.items()):
        kind = "robot error" if isinstance(error, TMMasterError) else "error"
        print(f"robot {name} failed ({kind}): {error!r}", file=sys.stderr)
    for name in shared.unconfirmed:
        print(f"{name}: could NOT confirm that it gave its command up: check", file=sys.stderr)
    if shared.errors or problems or shared.unconfirmed:
        return 1
    print(f"handover done: A released and moved clear before B came{checked}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
