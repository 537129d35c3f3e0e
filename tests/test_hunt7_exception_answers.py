"""A command write answered with a Modbus exception, as a gateway or a failing controller does.

A Modbus TCP gateway (or a controller in trouble) may answer the command block's FC16
with an exception instead of the device's answer: 4 "slave device failure", 5
"acknowledge" (accepted, done later), 6 "busy", 10 "gateway path unavailable", 11
"gateway target failed to respond". What the answer says about the write is not what
happened to it: the FaultProxy plays each of

- the exception *instead of* forwarding the frame (never executed);
- the exception *after* forwarding it (the robot took the write: code 4 after the
  device applied it, code 6 from a gateway whose device took the frame);
- the exception only once the arm runs the command (the answer held, then replaced);
- the exception at once while the frame is still on its way and lands only later (code
  11: the gateway gave up waiting, its frame to the device stuck behind it; code 5:
  the device accepted it and acts on it later).

What must hold (docs/safety.md): the command write is never resent (DeviceBusyError is
a transient error to the retry policy, but a command write is sent once); a call that
raised never leaves a move behind it: whatever the robot took is stopped before the
error reaches the caller, and nothing starts after it; nothing runs twice. Codes 5 and
11 are a timeout, not a refusal: a frame that lands later is handled as one whose
answer was lost (article: followed if it lands during the in-flight watch; tmflow: its
number is resent or cancelled, so it never runs again), and the same holds for a tmflow
Play press (Stop pressed before the error) and a digital output (watched for). The
judge is the simulator's motion log (tests/safety_invariant.py), its arm at rest, its
coils.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from fault_proxy import FaultProxy, Rule
from safety_invariant import Issued, at_rest, attempt, check
from test_hunt_project_press import PLAY_PAUSE, assert_never_run_on, robot_through, slow_move
from tmmaster import (
    ModbusExceptionError,
    PollPolicy,
    Pose,
    RetryPolicy,
    Robot,
    TimeoutPolicy,
    TransportError,
)
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

A = Pose(300, -200, 150, 180, 0, 90)
B = Pose(300, -200, 250, 180, 0, 90)
C = Pose(300, -150, 150, 180, 0, 90)
TIMEOUTS = TimeoutPolicy(request_s=1.0, ack_timeout_s=3.0, motion_margin_s=1.0, in_flight_s=3.0)
#: The command block's first register (its FC16's address), per profile.
COMMAND_BLOCK = {"article": 0x0200, "tmflow": 9000}


def options(profile: str) -> dict[str, Any]:
    return dict(
        profile=profile, gripper=None, polling=PollPolicy(interval_s=0.01), timeouts=TIMEOUTS
    )


@pytest.fixture(params=["article", "tmflow"])
def profile(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.fixture
def sim(tm_simulator_factory: Factory, profile: str) -> Simulator:
    return tm_simulator_factory(profile)


@pytest.fixture
def proxy(sim: Simulator) -> Iterator[FaultProxy]:
    with FaultProxy(sim.port) as p:
        yield p


@pytest.fixture
def robot(proxy: FaultProxy, profile: str) -> Iterator[Robot]:
    with Robot("127.0.0.1", proxy.port, **options(profile)) as r:
        r.wait_until_ready(timeout_s=5)
        yield r


def command_writes(sim: Simulator, profile: str) -> list[float]:
    """When each FC16 to the command block reached the robot (its wall times)."""
    address = COMMAND_BLOCK[profile]
    return [r.time for r in sim.request_log if r.function_code == 16 and r.address == address]


def judge(sim: Simulator, proxy: FaultProxy, profile: str, issued: list[Issued]) -> None:
    """Once the robot logged every command write the proxy forwarded, 5 ticks (a landed
    frame is taken and started within 2) for it to be taken; then at rest, and the
    invariant. Counted on the simulator's clock, from the frame's arrival: a loaded
    machine delays the look, never shortens the window."""
    block = COMMAND_BLOCK[profile]
    forwarded = [
        s
        for s in proxy.seen
        if s.function_code == 16 and s.address == block and s.action != "drop_request"
    ]
    sim.wait_for(lambda: len(command_writes(sim, profile)) >= len(forwarded), timeout=5.0)
    ticks = sim.ticks
    sim.wait_for(lambda: sim.ticks >= ticks + 5, timeout=5.0)
    sim.wait_for(at_rest(sim), timeout=5.0, interval=0.05)
    check(issued, sim.motion_log())


@pytest.mark.parametrize("code", [4, 6, 10])
def test_an_exception_instead_of_the_write_moves_nothing_and_resends_nothing(
    sim: Simulator, proxy: FaultProxy, robot: Robot, profile: str, code: int
) -> None:
    issued: list[Issued] = []
    assert attempt(robot, A, issued) == "done"
    proxy.add(
        Rule("drop_request", function_code=16, address=COMMAND_BLOCK[profile], exception=code)
    )
    before = len(command_writes(sim, profile))
    with pytest.raises(ModbusExceptionError) as refused:
        robot.move_to(B, speed=80)
    assert refused.value.code == code
    issued.append(Issued(B, time.monotonic(), time.monotonic(), type(refused.value).__name__))
    judge(sim, proxy, profile, issued)
    sent = [s for s in proxy.seen if s.function_code == 16 and s.address == COMMAND_BLOCK[profile]]
    assert len(sent) == before + 1, "the refused command write was sent again"
    assert sim.tcp_pose().is_close(A), f"the arm left A: {sim.tcp_pose()}"
    assert attempt(robot, C, issued) == "done"  # the robot is usable: the next move runs once
    judge(sim, proxy, profile, issued)


@pytest.mark.parametrize("code", [4, 6])
def test_an_exception_after_the_robot_took_the_write_leaves_no_move_behind(
    tm_simulator_factory: Factory, profile: str, code: int
) -> None:
    """The frame executed, the exception relayed in place of the robot's answer: the
    robot may take the command before the master reacts. Withdrawn or stopped, the arm
    never runs on to the target, and the write is not sent again."""
    sim = tm_simulator_factory(profile, time_scale=1.0)  # a move still runs when stopped
    issued: list[Issued] = []
    block = COMMAND_BLOCK[profile]
    with FaultProxy(sim.port) as proxy, Robot("127.0.0.1", proxy.port, **options(profile)) as r:
        r.wait_until_ready(timeout_s=5)
        far = r.pose().offset(dz=-120)
        proxy.add(Rule("drop_answer", function_code=16, address=block, exception=code))
        assert attempt(r, far, issued, speed=20) != "done"
        judge(sim, proxy, profile, issued)
        assert len(command_writes(sim, profile)) == 1  # taken once, never resent
        assert len(sim.motion_log()) <= 1, sim.motion_log()
        assert not sim.tcp_pose().is_close(far, mm=1.0), "the arm ran on to the target"


def release_when(proxy: FaultProxy, release: threading.Event, *, read_at: int | None) -> None:
    """Set ``release`` once the proxy saw a read (FC3) of ``read_at`` after the hold played,
    or once the test sets it itself (the call ended); on a thread of its own."""

    def watch() -> None:
        while not release.is_set():
            seen = proxy.seen
            held = [s.time for s in seen if s.action == "hold"]
            if (
                read_at is not None
                and held
                and any(
                    s.function_code == 3 and s.address == read_at and s.time > held[0] for s in seen
                )
            ):
                release.set()
            release.wait(0.002)

    threading.Thread(target=watch, daemon=True).start()


@pytest.mark.parametrize("code", [5, 11])
def test_a_gateway_timeout_whose_frame_lands_later_runs_once_or_never(
    sim: Simulator, proxy: FaultProxy, robot: Robot, profile: str, code: int
) -> None:
    """Code 11 (or 5) at once, the frame still on its way to the robot.

    The gateway's "no answer from the device" says nothing of the frame: it may still
    land, as after a request timeout; code 5, "acknowledge", says the device accepted
    the request and acts on it later. tmflow: the frame lands once the call ended (the
    master resent the number, or cancelled it): it never runs again. article: the frame
    lands while the master reads the registers back for it (the in-flight watch, the part
    of the contract it can keep, docs/safety.md): the master follows it, it runs once.
    Were the exception taken for a refusal, the article master would withdraw at once,
    the call end, and the frame, landing after, run a move the master had given up.
    """
    issued: list[Issued] = []
    release = threading.Event()
    assert attempt(robot, A, issued) == "done"
    block = COMMAND_BLOCK[profile]
    proxy.add(Rule("hold", function_code=16, address=block, exception=code, release=release))
    release_when(proxy, release, read_at=block if profile == "article" else None)
    outcome = attempt(robot, B, issued)
    release.set()  # the frame reaches the robot now, if it has not yet
    proxy.wait_held()
    judge(sim, proxy, profile, issued)
    ran = [m for m in sim.motion_log() if m.target is not None and m.target.is_close(B)]
    if outcome == "done":
        assert len(ran) == 1, ran
        assert sim.tcp_pose().is_close(B), sim.tcp_pose()
    else:
        assert not ran, (outcome, ran)
        assert sim.tcp_pose().is_close(A), (outcome, sim.tcp_pose())


def test_a_play_press_the_gateway_timed_out_never_resumes_the_paused_move(
    tm_simulator_factory: Factory,
) -> None:
    """tmflow's Play/Pause coil is a toggle, pressed once: a press answered with code 11
    may still land. The master must treat it as unanswered (press Stop before the error
    reaches the caller), not as refused: landing on the paused project, it is Play."""
    sim = tm_simulator_factory("tmflow", time_scale=1.0)  # the move runs while it is held
    release = threading.Event()
    with FaultProxy(sim.port) as proxy, robot_through(proxy) as robot:
        motion = slow_move(robot, sim)
        robot.pause()
        proxy.add(Rule("hold", function_code=5, address=PLAY_PAUSE, exception=11, release=release))
        try:
            with pytest.raises(TransportError):
                robot.play()
        finally:
            release.set()  # it lands now, after the master gave it up
        proxy.wait_held()
        assert_never_run_on(sim, motion)


@pytest.mark.parametrize("code", [4, 6])
def test_an_exception_answered_once_the_arm_moves_stops_it_and_never_resends(
    tm_simulator_factory: Factory, profile: str, code: int
) -> None:
    """The exception comes only once the robot runs the command (its answer held until the
    motion started, well inside the request timeout): the master must stop the arm
    before the error reaches the caller, and write the command nowhere again."""
    sim = tm_simulator_factory(profile, time_scale=1.0)  # the move lasts while it is answered
    release = threading.Event()
    issued: list[Issued] = []
    block = COMMAND_BLOCK[profile]
    with FaultProxy(sim.port) as proxy, Robot("127.0.0.1", proxy.port, **options(profile)) as r:
        r.wait_until_ready(timeout_s=5)
        start = r.pose()
        far = start.offset(dz=-120)
        proxy.add(
            Rule("delay_answer", function_code=16, address=block, exception=code, release=release)
        )

        def release_once_moving() -> None:
            sim.wait_for(lambda: bool(sim.motion_log()), timeout=5.0)
            release.set()

        threading.Thread(target=release_once_moving, daemon=True).start()
        try:
            outcome = attempt(r, far, issued, speed=20)
        finally:
            release.set()
        assert outcome in ("DeviceFailureError", "DeviceBusyError"), outcome
        judge(sim, proxy, profile, issued)
        ran = sim.motion_log()
        assert len(ran) == 1, ran
        assert not sim.tcp_pose().is_close(far, mm=1.0), "the arm ran on to the target"
        assert len([s for s in proxy.seen if s.function_code == 16 and s.address == block]) == 1


def test_an_output_write_the_gateway_timed_out_is_watched_for(
    tm_simulator_factory: Factory,
) -> None:
    """A digital output's write answered with code 11 while its frame is held: the next
    write of the other value must watch for that frame and undo it when it lands."""
    sim = tm_simulator_factory("tmflow")
    release = threading.Event()

    def do3_writes() -> list[bool]:
        log = sim.request_log
        return [
            bool(r.values[0]) for r in log if r.function_code == 5 and r.address == 3 and r.values
        ]

    def release_once_false_landed() -> None:
        sim.wait_for(lambda: False in do3_writes(), timeout=5)
        release.set()

    retry = RetryPolicy(attempts=1)  # the first write raises; its frame is still on its way
    with FaultProxy(sim.port) as proxy, Robot("127.0.0.1", proxy.port, retry=retry) as robot:
        proxy.add(Rule("hold", function_code=5, address=3, exception=11, release=release))
        try:
            with pytest.raises(TransportError):
                robot.io.set_do(3, True)
            threading.Thread(target=release_once_false_landed, daemon=True).start()
            robot.io.set_do(3, False)  # watches for the held True, undoes it once it lands
        finally:
            release.set()
        proxy.wait_held()
        assert do3_writes()[:2] == [False, True], do3_writes()  # the held True landed late
        assert sim.do(3) is False, do3_writes()
