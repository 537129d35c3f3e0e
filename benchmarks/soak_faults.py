"""A long randomized soak: random operations under random faults, the invariant after each.

Not a test (the suite does not collect ``benchmarks/``): a hunt for rare races that the
suite's few hypothesis examples miss. Each *episode* draws, from its seed, a front (a
``Robot``, an ``AsyncRobot``, or a ``Fleet`` of two robots driven from two threads), a
profile (``tmflow`` or ``article``) and a simulator time scale, then runs ``--ops``
random operations: moves of each kind (``move_to`` PTP and Line, ``move_by``,
``move_joints``, ``move_arc``, ``start_move`` then ``cancel``), a stop request, a Stop,
an e-stop, a pause and Play, closing (also from another thread) and reopening, the
gripper, the operator's reset, and faults between master and robot (the fault proxy's
rules, aimed at the command block's write) and inside the robot (a stall, a robot error
at the next move, a late acknowledgement, lost connections on the command write).

After every operation, for each simulator: the invariant of docs/safety.md on the
robot's own motion log (``tests/safety_invariant.py``), a move reported done only once
the robot reported it finished and with the TCP at its target, a move given up not
finishing later. After each episode: every held frame delivered and the operator's
Play, the invariant again, and no thread or socket left. Failures (and each episode's
seed, so one can be replayed with ``--seed S --episodes 1``) go to ``--log`` as JSON
lines.

Known limits of the article profile are left out (docs/safety.md, "what it cannot
guarantee"): on ``article`` a held command frame stays inside the in-flight window and
never meets a stop request, and the gateway's own retries (``duplicate_request``) are
played on ``tmflow`` only.

Run (one process at a time on a shared machine)::

    nice -n 10 .venv/bin/python benchmarks/soak_faults.py --seed 1 --episodes 50 --ops 40
    nice -n 10 .venv/bin/python benchmarks/soak_faults.py --minutes 30 --log soak.jsonl
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import faulthandler
import json
import random
import sys
import threading
import time
import traceback
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from fault_proxy import FaultProxy, Rule
from leaks import left_open, open_sockets
from pendant import press_play_pause
from safety_invariant import Issued, check, wait_braked
from tmmaster import (
    Fleet,
    PollPolicy,
    Pose,
    RetryPolicy,
    Robot,
    TimeoutPolicy,
    TMMasterError,
    aio,
)
from tmmaster.sim import Simulator, Timing

COMMAND_BLOCK = {"article": 0x0200, "tmflow": 9000}
BASES = (
    Pose(300, -200, 150, 180, 0, 90),
    Pose(300, 200, 180, 180, 0, 90),
    Pose(250, 0, 160, 180, 0, 90),
)
READY = (0.0, 0.0, 90.0, 0.0, 90.0, 0.0)
REQUEST_TIMEOUT_S = 0.15
IN_FLIGHT_S = 0.4
#: A stop is taken at the robot's next tick; a move ending in that tick reports its end.
TICK_SLACK_S = 0.15
#: Wall seconds one operation may take before the process dumps its threads and exits.
HANG_S = 90.0
NETWORK_FAULTS = (
    "hold",
    "drop_request",
    "drop_answer",
    "close_after",
    "delay_answer",
    "duplicate_answer",
    "duplicate_request",
    "stale_answer",
)


class BrokenInvariantError(Exception):
    """An invariant the soak checks was broken."""


@dataclass
class Side:
    """One simulated robot, its fault proxy, its master and what was issued to it."""

    sim: Simulator
    proxy: FaultProxy
    issued: list[Issued] = field(default_factory=list)
    given_up: list[Issued] = field(default_factory=list)
    robot: Robot | None = None
    arobot: aio.AsyncRobot | None = None
    count: int = 0

    def target(self, rng: random.Random) -> Pose:
        self.count += 1
        base = BASES[rng.randrange(len(BASES))]
        return base.offset(dx=rng.uniform(-20, 20), dy=rng.uniform(-20, 20), dz=0.5 * self.count)


class Episode:
    """One front, one profile, ``ops`` random operations."""

    def __init__(self, seed: int, front: str | None = None, profile: str | None = None) -> None:
        self.rng = random.Random(seed)
        self.seed = seed
        self.front = front or self.rng.choice(["sync", "aio", "fleet"])
        self.profile = profile or self.rng.choice(["tmflow", "article"])
        self.time_scale = self.rng.choice([5.0, 10.0, 20.0])
        self.trace: list[str] = []
        self.kind = ""
        self.label = ""
        self.errors: list[str] = []
        self.loop = asyncio.new_event_loop() if self.front == "aio" else None
        self.fleet = Fleet(watch_hz=50) if self.front == "fleet" else None
        self.sides = [self._side() for _ in range(2 if self.front == "fleet" else 1)]
        self.max_hold_s = 1.5 if self.profile == "tmflow" else REQUEST_TIMEOUT_S + IN_FLIGHT_S * 0.6

    def _side(self) -> Side:
        sim = Simulator(self.profile, time_scale=self.time_scale, timing=Timing(tick_hz=50)).start()
        side = Side(sim, FaultProxy(sim.port))
        self._open(side)
        return side

    # -- masters ---------------------------------------------------------------------

    def _options(self) -> dict[str, Any]:
        return {
            "profile": self.profile,
            "timeouts": TimeoutPolicy(
                request_s=REQUEST_TIMEOUT_S,
                ack_timeout_s=0.4,
                in_flight_s=IN_FLIGHT_S,
                motion_factor=1.3,
                motion_margin_s=0.8,
            ),
            "retry": RetryPolicy(
                attempts=6, total_time_s=1.0, initial_backoff_s=0.02, max_backoff_s=0.2
            ),
            "polling": PollPolicy(interval_s=0.01),
        }

    def _run(self, coro: Coroutine[Any, Any, Any]) -> Any:
        assert self.loop is not None
        return self.loop.run_until_complete(asyncio.wait_for(coro, 30))

    def _open(self, side: Side) -> None:
        if self.front == "aio":
            arobot = aio.connect("127.0.0.1", side.proxy.port, **self._options())
            try:
                self._run(arobot.connect())
            except TMMasterError:
                return
            side.arobot, side.robot = arobot, arobot.robot
            return
        robot = Robot("127.0.0.1", side.proxy.port, link=self.fleet, **self._options())
        try:
            robot.connect()
        except TMMasterError:
            robot.close()
            return
        side.robot = robot

    def _close(self, side: Side) -> None:
        if side.arobot is not None:
            self._run(side.arobot.close())
        elif side.robot is not None:
            side.robot.close()
        side.robot = side.arobot = None

    # -- recording -------------------------------------------------------------------

    def _issue(self, side: Side, target: Pose, call: Callable[[], object]) -> Issued:
        command = Issued(target, time.monotonic())
        side.issued.append(command)
        try:
            result = call()
            if asyncio.iscoroutine(result):
                self._run(result)
            command.outcome = "done"
        except TMMasterError as exc:
            command.outcome = type(exc).__name__
            self.errors.append(f"{self.kind}: {exc}")
        except (asyncio.CancelledError, TimeoutError) as exc:
            command.outcome = type(exc).__name__
        finally:
            command.ended_at = time.monotonic()
        if command.outcome == "done":
            self._check_done(side, command)
        else:
            side.given_up.append(command)
        return command

    def _check_done(self, side: Side, command: Issued) -> None:
        assert command.ended_at is not None
        robot = side.robot
        tolerance = robot.position_tolerance_mm if robot is not None else 0.5
        records = [
            m
            for m in side.sim.motion_log()
            if m.target is not None and m.target.distance_to(command.target) <= 0.05
        ]
        if not records:
            log = [(m.number, m.kind, m.target) for m in side.sim.motion_log()[-3:]]
            raise BrokenInvariantError(
                f"{self.label}: {command.target} reported done, never started; last motions"
                f" {log}, TCP at {side.sim.tcp_pose()}"
            )
        done = records[-1].done_wall_time
        if done is None or done > command.ended_at:
            raise BrokenInvariantError(
                f"{command.target} reported done before the robot finished it ({done})"
            )
        away = side.sim.tcp_pose().distance_to(command.target)
        if away > tolerance + 0.01:
            raise BrokenInvariantError(
                f"{command.target} reported done with the TCP {away:.3f} mm away"
            )

    def check(self) -> None:
        for side in self.sides:
            try:
                check(side.issued, side.sim.motion_log())
            except AssertionError as exc:
                raise BrokenInvariantError(f"{self.label}: {exc}") from exc
            for command in side.given_up:
                assert command.ended_at is not None
                for motion in side.sim.motion_log():
                    if motion.target is None or command.target.distance_to(motion.target) > 0.05:
                        continue
                    done = motion.done_wall_time
                    if done is not None and done > command.ended_at + TICK_SLACK_S:
                        raise BrokenInvariantError(
                            f"{command.target} ({command.outcome}) finished"
                            f" {done - command.ended_at:.3f} s after its call gave it up"
                        )

    # -- operations ------------------------------------------------------------------

    def _move_call(self, side: Side, rng: random.Random) -> tuple[Pose, Callable[[], object]]:
        """A random move: its target (as the robot will log it) and the call that makes it."""
        front: Any = side.arobot if side.arobot is not None else side.robot
        assert side.robot is not None
        speed = rng.randint(20, 100)
        kinds = ["ptp", "line", "by"] + (["joints", "arc"] if self.profile == "tmflow" else [])
        kind = rng.choice(kinds)
        self.kind = kind
        if kind == "joints":
            side.count += 1
            joints = [a + rng.uniform(-8, 8) for a in READY]
            target = side.robot.model.forward(joints)
            return target, lambda: front.move_joints(joints, speed=speed)
        if kind == "arc":
            to = side.target(rng)
            via = to.offset(dx=rng.uniform(-40, 40), dy=rng.uniform(-40, 40), dz=10)
            return to, lambda: front.move_arc(via, to, speed=speed)
        if kind == "by":
            with contextlib.suppress(TimeoutError):
                wait_braked(side.sim, ticks=5, timeout=3.0)
            side.count += 1
            offset = [rng.uniform(-15, 15) for _ in range(3)]
            target = side.sim.tcp_pose().offset(dx=offset[0], dy=offset[1], dz=offset[2])
            return target, lambda: front.move_by(*offset, speed=speed)
        target = side.target(rng)
        return target, lambda: front.move_to(target, speed=speed, motion=kind)

    def _ready(self, side: Side) -> None:
        sim = side.sim
        sim.clear_error()
        if self.profile == "tmflow" and not (
            sim.field("project_running") and not sim.field("paused")
        ):
            sim.press_play()
        if side.robot is not None:
            side.robot.clear_stop_request()

    def _later(self, after_s: float, action: Callable[[], object]) -> threading.Timer:
        def act() -> None:
            with contextlib.suppress(TMMasterError):
                result = action()
                if asyncio.iscoroutine(result):
                    result.close()

        timer = threading.Timer(after_s, act)
        timer.start()
        return timer

    def op(self, side: Side, rng: random.Random) -> str:
        """One random operation on ``side``; returns its name."""
        if side.robot is None:
            self._open(side)
            return "reopen"
        if rng.random() < 0.7:
            self._ready(side)
        robot = side.robot
        name = rng.choice(
            [
                "move",
                "move",
                "move_net_fault",
                "move_net_fault",
                "move_outage",
                "move_sim_fault",
                "interrupt",
                "stop",
                "estop",
                "pause_play",
                "cancel",
                "close_during",
                "close_reopen",
                "gripper",
                "operator",
            ]
        )
        if name == "operator":
            self._ready(side)
            return name
        if name == "close_reopen":
            self._close(side)
            self._open(side)
            return name
        if name == "gripper":
            self._gripper(side, rng)
            return name
        target, call = self._move_call(side, rng)
        self.label = f"{name}/{self.kind}"
        timer: threading.Timer | None = None
        after = rng.uniform(0.0, 0.1)
        label = name
        if name == "move_net_fault":
            action = rng.choice(NETWORK_FAULTS)
            if self.profile == "article" and action == "duplicate_request":
                action = "drop_answer"
            delay = rng.uniform(0.0, self.max_hold_s)
            rule = Rule(
                action,  # type: ignore[arg-type]
                function_code=16,
                address=COMMAND_BLOCK[self.profile],
                delay_s=delay,
            )
            side.proxy.add(rule)
            label = f"{name}:{action}:{delay:.3f}"
        elif name == "move_outage":
            side.proxy.outage(rng.uniform(0.05, 0.6))
        elif name == "move_sim_fault":
            spec = rng.choice(
                [
                    "stall:at_move=1",
                    "robot_error:at_move=1",
                    f"late_ack:delay_s={rng.uniform(0.05, 1.0):.3f},at_move=1",
                    f"drop_connections:on_write_to={COMMAND_BLOCK[self.profile]},"
                    f"after_requests=1,{rng.choice(['lose=request', 'lose=answer', 'once=true'])}",
                    "estop:at_move=1",
                ]
            )
            side.sim.inject(spec)
            label = f"{name}:{spec}"
        elif name == "interrupt":
            timer = self._later(after, robot.interrupt)
        elif name == "stop":
            timer = self._later(after, robot.stop)
        elif name == "estop":
            timer = self._later(after, side.sim.press_estop)
        elif name == "pause_play":
            pause = (
                (lambda: press_play_pause(side.sim))
                if self.profile == "tmflow" and rng.random() < 0.5
                else robot.pause
            )
            timer = self._later(after, pause)
        elif name == "close_during":
            closer: Callable[[], object] = robot.close
            if side.arobot is not None:
                arobot, loop = side.arobot, self.loop
                assert loop is not None

                def closer() -> None:
                    loop.call_soon_threadsafe(lambda: asyncio.ensure_future(arobot.close()))

            timer = self._later(after, closer)
        if name == "cancel":
            self._cancelled(side, target, call, after)
        else:
            self._issue(side, target, call)
        if timer is not None:
            timer.join()
        side.proxy.clear()
        side.sim.clear_faults()
        if name == "pause_play":
            self._ready(side)
            if side.robot is not None:
                with contextlib.suppress(TMMasterError):
                    self._call(side, "play")
        if name == "close_during":
            self._close(side)
            self._open(side)
        if name == "interrupt" and side.robot is not None:
            side.robot.clear_stop_request()
        return f"{label}/{self.kind}"

    def _call(self, side: Side, method: str) -> object:
        front: Any = side.arobot if side.arobot is not None else side.robot
        result = getattr(front, method)()
        if asyncio.iscoroutine(result):
            return self._run(result)
        return result

    def _gripper(self, side: Side, rng: random.Random) -> None:
        front: Any = side.arobot if side.arobot is not None else side.robot
        gripper = getattr(front, "gripper", None)
        if gripper is None:
            return
        with contextlib.suppress(TMMasterError, asyncio.CancelledError, TimeoutError):
            result = gripper.open() if rng.random() < 0.5 else gripper.close()
            if asyncio.iscoroutine(result):
                self._run(result)

    def _cancelled(
        self, side: Side, target: Pose, call: Callable[[], object], after_s: float
    ) -> None:
        """``start_move`` then ``cancel`` (awaited: the wait's task cancelled) after ``after_s``."""
        command = Issued(target, time.monotonic())
        side.issued.append(command)
        if side.arobot is not None:
            arobot = side.arobot

            async def scenario() -> str:
                handle = await arobot.start_move(target, speed=40)
                waiting = asyncio.ensure_future(handle.wait())
                await asyncio.sleep(after_s)
                waiting.cancel()
                try:
                    await waiting
                except asyncio.CancelledError:
                    return "CancelledError"
                return "done"

            try:
                command.outcome = self._run(scenario())
            except TMMasterError as exc:
                command.outcome = type(exc).__name__
        else:
            assert side.robot is not None
            try:
                motion = side.robot.start_move(target, speed=40)
                time.sleep(after_s)
                cancelled = motion.cancel()
                command.outcome = "Cancelled" if cancelled else "done"
                if not cancelled:
                    motion.wait()
            except TMMasterError as exc:
                command.outcome = type(exc).__name__
        command.ended_at = time.monotonic()
        if command.outcome == "done":
            self._check_done(side, command)
        else:
            side.given_up.append(command)

    # -- the episode -----------------------------------------------------------------

    def step(self, index: int) -> None:
        faulthandler.dump_traceback_later(HANG_S, exit=True)
        if len(self.sides) == 1:
            name = self.op(self.sides[0], self.rng)
            self.trace.append(f"{index}:{name}={self._outcome(self.sides[0])}")
        else:
            names: list[str] = ["?", "?"]
            errors: list[BaseException] = []
            rngs = [random.Random(self.rng.random()) for _ in self.sides]

            def run(i: int) -> None:
                try:
                    name = self.op(self.sides[i], rngs[i])
                    names[i] = f"{name}={self._outcome(self.sides[i])}"
                except BaseException as exc:  # reported on the main thread
                    errors.append(exc)

            threads = [threading.Thread(target=run, args=(i,)) for i in range(2)]
            for thread in threads:
                thread.start()
            for thread in threads:
                thread.join()
            self.trace.append(f"{index}:{names[0]}|{names[1]}")
            if errors:
                raise errors[0]
        faulthandler.cancel_dump_traceback_later()
        self.check()

    @staticmethod
    def _outcome(side: Side) -> str:
        return side.issued[-1].outcome if side.issued else "-"

    def finish(self) -> None:
        """Close everything, deliver every held frame, press Play: nothing more may run."""
        for side in self.sides:
            self._close(side)
        for side in self.sides:
            side.proxy.wait_held()
            side.sim.clear_error()
            side.sim.press_play()
        time.sleep(3.0 / self.time_scale + 0.1)
        try:
            self.check()
        finally:
            if self.fleet is not None:
                self.fleet.close()
            for side in self.sides:
                side.proxy.close()
                side.sim.close()
            if self.loop is not None:
                self.loop.close()


def episode(
    seed: int, ops: int, log: Any, front: str | None, profile: str | None, verbose: bool = False
) -> bool:
    """Run one episode; write a line for a failure. True when it passed."""
    threads_before, sockets_before = set(threading.enumerate()), open_sockets()
    run = Episode(seed, front, profile)
    head = {"seed": seed, "front": run.front, "profile": run.profile, "scale": run.time_scale}
    log.write(json.dumps({"event": "start", **head}) + "\n")
    log.flush()
    failure: str | None = None
    try:
        for index in range(ops):
            run.step(index)
    except BrokenInvariantError as exc:
        failure = f"finding: {exc}"
    except Exception:  # an SDK call raising what it should not
        failure = "unexpected: " + traceback.format_exc(limit=8)
    try:
        run.finish()
    except BrokenInvariantError as exc:
        failure = failure or f"finding at the end: {exc}"
    threads, sockets = left_open(sockets_before, threads_before, collect=True)
    if not failure and (threads or sockets):
        failure = f"left open: threads {[t.name for t in threads]}, {len(sockets)} sockets"
    record = {"event": "fail" if failure else "pass", **head, "ops": len(run.trace)}
    if failure or verbose:
        record |= {"failure": failure, "trace": run.trace}
    log.write(json.dumps(record) + "\n")
    log.flush()
    return failure is None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--seed", type=int, default=1, help="first episode's seed")
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--ops", type=int, default=40, help="operations per episode")
    parser.add_argument("--minutes", type=float, help="stop starting episodes after this")
    parser.add_argument("--front", choices=["sync", "aio", "fleet"])
    parser.add_argument("--profile", choices=["tmflow", "article"])
    parser.add_argument("--log", default="-", help="JSON lines file (default: stdout)")
    parser.add_argument("--verbose", action="store_true", help="log every episode's trace")
    args = parser.parse_args(argv)
    log = sys.stdout if args.log == "-" else open(args.log, "a", encoding="utf-8")  # noqa: SIM115
    deadline = time.monotonic() + 60 * args.minutes if args.minutes else None
    failed = passed = 0
    seed = args.seed
    while (deadline is None and passed + failed < args.episodes) or (
        deadline is not None and time.monotonic() < deadline
    ):
        if episode(seed, args.ops, log, args.front, args.profile, args.verbose):
            passed += 1
        else:
            failed += 1
        seed += 1
    print(f"episodes {passed + failed}, failed {failed}, last seed {seed - 1}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
