"""The runner examples (pick_and_place.py, palletizing.py, custom_sequence.py) when things
go wrong: Ctrl-C ends them with exit 130 and the arm at rest, saying so; a give-up the
link could not carry is said, never hidden behind a plain failure.

Found by hunt 29 ("the code users copy"); both tests fail without the fix:

- Ctrl-C left ``main()`` as a bare KeyboardInterrupt (a traceback; the library had
  stopped the arm, but the script never said so, and its caller got no exit code);
- with a command write held in the network and the link down behind it, the robot's
  ``close()`` could not confirm the withdraw or stop (the arm may still run toward the
  target given up), and the examples said only "failed in ...: <the link error>".

The simulator's motion log and pose are the judge of what the arm did.
"""

from __future__ import annotations

import functools
import logging
import signal
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType

import pytest

from examples_support import load_example
from fault_proxy import FaultProxy
from safety_invariant import wait_braked
from test_hunt29_many_robots import link_down_behind_the_second_move
from tmmaster import RetryPolicy, Robot
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

EXAMPLES = ["pick_and_place", "palletizing", "custom_sequence"]


@pytest.fixture(autouse=True)
def restore_logging() -> Iterator[None]:
    """The examples configure tmmaster's logging for a process of their own: undone after."""
    root, pymodbus = logging.getLogger("tmmaster"), logging.getLogger("pymodbus")
    saved = ([*root.handlers], root.level, root.propagate, pymodbus.level)
    yield
    root.handlers[:] = saved[0]
    root.setLevel(saved[1])
    root.propagate = saved[2]
    pymodbus.setLevel(saved[3])


@pytest.fixture
def ctrl_c_handler() -> Iterator[None]:
    """Python's own Ctrl-C handler, also where pytest was started with SIGINT ignored."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


#: A retry policy that gives up a lost link in 0.3 s, not 10 s per step.
SHORT_RETRY = RetryPolicy(attempts=3, total_time_s=0.3, initial_backoff_s=0.05)


def argv(name: str, port: int, tmp_path: Path) -> list[str]:
    """The example's arguments: the robot on ``port``, a fast gripper, short retries."""
    if name == "pick_and_place":
        config = tmp_path / "fast.toml"
        config.write_text(
            "[gripper]\nsettle_s = 0.05\n[run]\npoll_interval_s = 0.02\n"
            "[retry]\nattempts = 3\ntotal_time_s = 0.3\ninitial_backoff_s = 0.05\n"
        )
        return ["--port", str(port), "--cycles", "2", "--config", str(config)]
    return ["--port", str(port), "--settle", "0.05"]


def load(name: str) -> ModuleType:
    """The example, its robots made with ``SHORT_RETRY`` (its own command line has no
    option for it; ``pick_and_place`` takes it from its configuration file)."""
    example = load_example(name)
    if hasattr(example, "Robot"):
        setattr(example, "Robot", functools.partial(Robot, retry=SHORT_RETRY))  # noqa: B010
    return example


@pytest.mark.usefixtures("ctrl_c_handler")
@pytest.mark.parametrize("name", EXAMPLES)
def test_ctrl_c_exits_130_with_the_arm_at_rest(
    name: str,
    tm_simulator_factory: Factory,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    sim = tm_simulator_factory()
    main_thread = threading.main_thread().ident
    assert main_thread is not None

    def operator() -> None:
        # A real SIGINT to the main thread, as a terminal's Ctrl-C, once the 2nd move runs.
        sim.wait_for(lambda: len(sim.motion_log()) >= 2, timeout=10.0)
        signal.pthread_kill(main_thread, signal.SIGINT)

    thread = threading.Thread(target=operator)
    thread.start()
    try:
        code = load_example(name).main(argv(name, sim.port, tmp_path))
    except KeyboardInterrupt:
        pytest.fail("Ctrl-C left main() as a KeyboardInterrupt, not exit code 130")
    finally:
        thread.join(10.0)
    assert code == 130
    err = capsys.readouterr().err
    assert f"{name}: interrupted; nothing the robot was sent can still run" in err
    log = sim.motion_log()
    wait_braked(sim)  # a stopped arm brakes to rest
    assert sim.motion_log() == log  # nothing started after main() returned


@pytest.mark.parametrize("name", EXAMPLES)
def test_a_give_up_the_link_could_not_carry_is_said(
    name: str,
    tm_simulator_factory: Factory,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    sim = tm_simulator_factory()
    with FaultProxy(sim.port) as proxy:
        # The second command write held in the network, the link cut behind it.
        cutter = link_down_behind_the_second_move(proxy)
        try:
            code = load(name).main(argv(name, proxy.port, tmp_path))
        finally:
            cutter.join(35.0)
    assert code == 1
    err = capsys.readouterr().err
    assert (
        f"{name}: could NOT confirm that the robot gave its command up: the arm may still move"
        in err
    )
