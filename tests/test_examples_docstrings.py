"""Every command an example's docstring documents runs as written and exits 0.

Each example's docstring is read for its command lines (``examples_support``): a block
of ``python -m tmmaster.sim ...`` lines and ``python examples/NAME.py ...`` lines is run
together. The simulators are started in this process from the documented options, parsed
by the simulator's own command line (at ``sim_speeds.QUICK``, on free loopback ports that
stand in for the documented ones); then each example command's ``main(argv)`` runs with
those arguments, only the port numbers replaced. An example that starts simulators
itself gets them at ``OWN_SIMULATORS`` pace. So a docstring that drifts from what the example and
the simulator accept, or from what works, fails here.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from examples_support import EXAMPLES, documented_commands, load_example
from sim_speeds import QUICK, SUITE_TICK_HZ, SUITE_TIME_SCALE
from tmmaster._cliparse import UsageError
from tmmaster.sim import DEFAULT_PART_POSE, Cell, RobotSetup, Simulator, TableObject, Timing
from tmmaster.sim.__main__ import build_parser

SimFactory = Callable[..., Simulator]

#: Every example script, by name.
EXAMPLE_NAMES = sorted(p.stem for p in EXAMPLES.glob("*.py"))

#: The simulator options these tests reproduce; any other must keep its default.
SIM_OPTIONS = {"profile", "port", "parts", "model", "fault"}

#: How fast an example's own simulators run: the suite's pace (40x, 100 Hz). Up to 8
#: tmflow simulators tick in one process (each tick runs the robot program): at QUICK's
#: 250 Hz they would fall behind.
OWN_SIMULATORS: dict[str, Any] = {
    "time_scale": SUITE_TIME_SCALE,
    "timing": Timing(tick_hz=SUITE_TICK_HZ),
}

#: Options of an example's command line whose values are ports.
PORT_OPTIONS = ("--port", "--port-a", "--port-b", "--ports")


def _blocks() -> list[Any]:
    return [
        pytest.param(name, block, id=f"{name}-{k}")
        for name in EXAMPLE_NAMES
        for k, block in enumerate(documented_commands(name), start=1)
    ]


def test_every_example_documents_how_to_run_it() -> None:
    assert EXAMPLE_NAMES
    for name in EXAMPLE_NAMES:
        blocks = documented_commands(name)
        assert blocks, f"examples/{name}.py documents no command"
        ran = [words[1] for block in blocks for words in block if words[1] != "-m"]
        assert f"examples/{name}.py" in ran, f"examples/{name}.py never runs itself"


def test_the_commands_are_read_from_the_docstring() -> None:
    # The reader itself: blocks split at prose, a background "&" dropped.
    (block,) = documented_commands("palletizing")
    assert block[0][:3] == ["python", "-m", "tmmaster.sim"]
    assert block[-1][:2] == ["python", "examples/palletizing.py"]
    assert [len(b) for b in documented_commands("two_robots")] == [1, 3]
    assert all(words[-1] != "&" for b in documented_commands("two_robots") for words in b)


def start_simulator(words: list[str], factory: SimFactory) -> tuple[str, Simulator]:
    """Start what ``python -m tmmaster.sim ARGS`` would; returns (documented port, sim)."""
    parser = build_parser()
    args = parser.parse_args(words[3:])
    for option, value in vars(args).items():
        assert option in SIM_OPTIONS or value == parser.get_default(option), (
            f"this test does not reproduce the simulator option {option}={value!r}: add it"
        )
    count = 1 if args.parts is None else args.parts  # the simulator's default: one part
    parts = [TableObject(name=f"part-{i}", pose=DEFAULT_PART_POSE) for i in range(count)]
    sim = factory(
        args.profile,
        robot=RobotSetup(model=args.model),
        cell=Cell(scene=parts),
        faults=args.fault,
        **QUICK,
    )
    return str(args.port), sim


def example_argv(words: list[str], ports: dict[str, str]) -> list[str]:
    """The example's arguments, each documented port replaced by its simulator's."""
    argv = words[2:]
    out: list[str] = []
    option = ""
    for word in argv:
        if word.startswith("--"):
            option = word
            out.append(word)
        elif option in PORT_OPTIONS:
            assert word in ports, f"{' '.join(words)}: no simulator was started on port {word}"
            out.append(ports[word])
        else:
            if option == "--host":
                assert word == "127.0.0.1", f"{' '.join(words)}: not a loopback host"
            out.append(word)
    return out


def own_simulator(*args: Any, time_scale: float = 1.0, **options: Any) -> Simulator:
    """An example's own simulator at ``OWN_SIMULATORS`` pace, whatever it asks for."""
    return Simulator(*args, **options, **OWN_SIMULATORS)


@pytest.fixture
def restore_logging() -> Iterator[None]:
    """The examples configure tmmaster's logging for a process of their own: undone after."""
    root, pymodbus = logging.getLogger("tmmaster"), logging.getLogger("pymodbus")
    saved = ([*root.handlers], root.level, root.propagate, pymodbus.level)
    yield
    root.handlers[:] = saved[0]
    root.setLevel(saved[1])
    root.propagate = saved[2]
    pymodbus.setLevel(saved[3])


@pytest.mark.usefixtures("restore_logging")
@pytest.mark.parametrize(("name", "block"), _blocks())
def test_documented_commands_run_as_written(
    name: str,
    block: list[list[str]],
    tm_simulator_factory: SimFactory,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    ports: dict[str, str] = {}
    ran = 0
    for words in block:
        command = " ".join(words)
        if words[:3] == ["python", "-m", "tmmaster.sim"]:
            documented, sim = start_simulator(words, tm_simulator_factory)
            assert documented not in ports, f"{command}: port {documented} taken twice"
            ports[documented] = str(sim.port)
            continue
        assert words[0] == "python", command
        assert words[1] == f"examples/{name}.py", f"{command}: another script in {name}'s docs"
        example = load_example(name)
        if hasattr(example, "Simulator"):
            monkeypatch.setattr(example, "Simulator", own_simulator)
        argv = example_argv(words, ports)
        try:
            code = example.main(argv)
        except SystemExit as exc:  # argparse refused the documented options
            code = exc.code
        assert code == 0, f"{command} exited {code}:\n{capsys.readouterr().err}"
        ran += 1
    assert ran, f"{name}: a block of simulators and no example command"


def test_a_drifted_docstring_fails(tm_simulator_factory: SimFactory) -> None:
    # What the check above stands on: a port no simulator listens on, an unknown
    # simulator option and a host that is not loopback are each refused.
    with pytest.raises(AssertionError, match="no simulator was started on port 5021"):
        example_argv(["python", "examples/x.py", "--port", "5021"], {"5020": "1"})
    with pytest.raises(AssertionError, match="not a loopback host"):
        example_argv(["python", "examples/x.py", "--host", "192.168.1.100"], {})
    with pytest.raises(AssertionError, match="does not reproduce the simulator option"):
        start_simulator(["python", "-m", "tmmaster.sim", "--time-scale", "3"], tm_simulator_factory)
    with pytest.raises(UsageError):
        start_simulator(["python", "-m", "tmmaster.sim", "--no-such-option"], tm_simulator_factory)
