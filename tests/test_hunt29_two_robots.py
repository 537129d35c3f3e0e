"""examples/two_robots.py when things go wrong: Ctrl-C stops both arms and exits 130, and a
failure of one robot stops the other from starting anything more.

Found by hunt 29 ("the code users copy"); both tests fail without the fix:

- Ctrl-C reached only the main thread, blocked in ``Thread.join()``: the
  KeyboardInterrupt left ``main()`` as a traceback while both robot threads drove on,
  the whole handover run to its end after the operator pressed Ctrl-C (measured: A's
  eight remaining moves and grips, all of B's, after the Ctrl-C).
- A robot that failed stopped nothing: robot A went on to pick and put its part on the
  handover table with robot B e-stopped, B's arm wherever its first move had left it.

The simulators' motion logs are the judge, never what the example reports.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator, Sequence
from types import ModuleType
from typing import Any

import pytest

from examples_support import load_example
from safety_invariant import wait_braked
from tmmaster import Motion, Robot, StopRequestedError
from tmmaster.sim import Cell, MotionRecord, Simulator, TableObject

Factory = Callable[..., Simulator]

#: Every action of robot A's job: pick (2 moves, grip, 1 move), place (2, open, 1), clear.
A_ACTIONS = 9


@pytest.fixture(scope="module")
def example() -> ModuleType:
    return load_example("two_robots")


@pytest.fixture
def sims(tm_simulator_factory: Factory, example: ModuleType) -> tuple[Simulator, Simulator]:
    sim_a = tm_simulator_factory(cell=Cell(scene=[TableObject(name="part", pose=example.PICK_A)]))
    sim_b = tm_simulator_factory(
        cell=Cell(scene=[TableObject(name="part", pose=example.HANDOVER_B)]),
        faults=["estop:at_move=1"],
    )
    return sim_a, sim_b


@pytest.fixture
def ctrl_c_handler() -> Iterator[None]:
    """Python's own Ctrl-C handler, also where pytest was started with SIGINT ignored."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


def keep_handovers(example: ModuleType, monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """Every Handover the example makes, kept for the test to look at."""
    made: list[Any] = []
    handover_class = example.Handover

    def handover() -> Any:
        made.append(handover_class())
        return made[-1]

    monkeypatch.setattr(example, "Handover", handover)
    return made


def argv(sim_a: Simulator, sim_b: Simulator) -> list[str]:
    return ["--port-a", str(sim_a.port), "--port-b", str(sim_b.port), "--settle", "0.05"]


def started(log: Sequence[MotionRecord]) -> list[tuple[int, str, int | None, object]]:
    """What a motion log says was started: each motion's number, kind, seq and target."""
    return [(m.number, m.kind, m.seq, m.target) for m in log]


@pytest.mark.usefixtures("ctrl_c_handler")
def test_ctrl_c_stops_both_arms_and_exits_130(
    tm_simulator_factory: Factory,
    example: ModuleType,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    made = keep_handovers(example, monkeypatch)
    sim_a = tm_simulator_factory(cell=Cell(scene=[TableObject(name="part", pose=example.PICK_A)]))
    sim_b = tm_simulator_factory(
        cell=Cell(scene=[TableObject(name="part", pose=example.HANDOVER_B)])
    )
    main_thread = threading.main_thread().ident
    assert main_thread is not None

    def operator() -> None:
        # A real SIGINT to the main thread, as a terminal's Ctrl-C, once A moves.
        sim_a.wait_for(lambda: len(sim_a.motion_log()) >= 1, timeout=10.0)
        signal.pthread_kill(main_thread, signal.SIGINT)

    thread = threading.Thread(target=operator)
    thread.start()
    try:
        code = example.main(argv(sim_a, sim_b))
    except KeyboardInterrupt:
        pytest.fail("Ctrl-C left main() as a KeyboardInterrupt, not exit code 130")
    finally:
        thread.join(10.0)
    assert code == 130
    assert "interrupted" in capsys.readouterr().err
    logs = sim_a.motion_log(), sim_b.motion_log()
    wait_braked(sim_a)  # a stopped arm brakes to rest
    wait_braked(sim_b)
    # Nothing started after main() returned (a stopped motion's record gets its end time
    # once it has braked to rest: the motions themselves are compared).
    assert started(sim_a.motion_log()) == started(logs[0])
    assert started(sim_b.motion_log()) == started(logs[1])
    # Each robot was stopped by the Ctrl-C, neither blamed on the other.
    assert made[0].interrupted
    assert all(type(e) is StopRequestedError for e in made[0].errors.values()), made[0].errors
    # The handover did not run on: A never finished its job, B never took the part.
    assert len(logs[0]) < A_ACTIONS, [m.kind for m in logs[0]]
    assert not [m for m in logs[1] if m.kind == "gripper_close"]


def test_a_starts_nothing_more_once_b_failed(
    sims: tuple[Simulator, Simulator],
    example: ModuleType,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    sim_a, sim_b = sims  # B's e-stop is pressed during B's first move
    made = keep_handovers(example, monkeypatch)

    class GatedRobot(Robot):
        """Robot A holds after its first move until B's failure is known (an event)."""

        def move_to(self, *args: Any, **kwargs: Any) -> Motion:
            motion = super().move_to(*args, **kwargs)
            if self.name == "robot-A":
                assert made[0].failed.wait(10.0), "B never failed"
            return motion

    monkeypatch.setattr(example, "Robot", GatedRobot)
    code = example.main(argv(sim_a, sim_b))
    # A's first move (sent before B failed) is all A ever did: no grip, no handover.
    assert [m.kind for m in sim_a.motion_log()] == ["ptp"]
    assert not sim_a.objects()[0].held
    assert code == 1
    err = capsys.readouterr().err
    assert "robot B failed (robot error): EmergencyStopError" in err
    assert "robot A failed (error): RuntimeError('robot B failed: robot A stopped')" in err
