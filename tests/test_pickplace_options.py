"""Each command-line option of the pick & place command is applied once (issue 12 item 3).

Every option either sets one configuration key, says what to run, or only shapes the
output; the options are read once, by ``_command``, which applies the configuration
options to the file in one step (``load_config``) and validates the result. Downstream
(the robot, the runner, the simulator, the plan, the report) reads that one
``PickPlaceConfig``: these tests fail if an option is read from the arguments after
that step, or if the robot or the runner is built from another configuration.
"""

from __future__ import annotations

import argparse
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from sim_speeds import QUICK
from tmmaster.pickplace import PickPlaceConfig
from tmmaster.pickplace import __main__ as cli
from tmmaster.sim import Simulator

#: Quick runs: simulated time 40x, short polls and settle times.
FAST = """
[gripper]
settle_s = 0.05
[run]
poll_interval_s = 0.02
[timeouts]
ack_s = 0.5
motion_margin_s = 0.5
"""

#: A value for each configuration option, different from the default (None: a switch,
#: which sets its key to true).
SAMPLES: dict[str, str | None] = {
    "host": "10.1.2.3",
    "port": "1502",
    "profile": "article",
    "cycles": "7",
    "poll_interval": "0.25",
    "release_held_part": None,
}

SimFactory = Callable[..., Simulator]


def _dests(parser: argparse.ArgumentParser) -> set[str]:
    """Every option's namespace name (help and --version print and exit: not options)."""
    return {a.dest for a in parser._actions if a.dest not in ("help", "version")}


def test_every_option_sets_one_config_key_says_what_to_run_or_shapes_output() -> None:
    kinds = [set(cli._CONFIG_OPTIONS), set(cli._COMMAND_OPTIONS), set(cli._OUTPUT_OPTIONS)]
    dests = _dests(cli.build_parser())
    for dest in sorted(dests):
        assert sum(dest in kind for kind in kinds) == 1, f"--{dest}: declare it in one table"
    assert set().union(*kinds) == dests, "a declared option the parser does not have"
    # Each configuration option names a real key, and no two name the same key.
    keys = list(cli._CONFIG_OPTIONS.values())
    assert len(set(keys)) == len(keys)
    sections = PickPlaceConfig.model_fields
    for section, key in keys:
        model = sections[section].annotation
        assert isinstance(model, type)
        assert key in model.model_fields


def test_each_config_option_changes_exactly_its_key() -> None:
    assert set(SAMPLES) == set(cli._CONFIG_OPTIONS), "give every config option a sample"
    parser = cli.build_parser()

    def config(*argv: str) -> dict[str, Any]:
        command = cli._command(parser.parse_args(["--dry-run", *argv]), cli._Outcome())
        return command.config.model_dump()

    base = config()
    for option, value in SAMPLES.items():
        flag = f"--{option.replace('_', '-')}"
        changed = config(flag) if value is None else config(flag, value)
        section, key = cli._CONFIG_OPTIONS[option]
        assert str(changed[section][key]) == ("True" if value is None else value)
        changed[section][key] = base[section][key]
        assert changed == base, f"--{option} changed more than {section}.{key}"


class _RecordingArgs(argparse.Namespace):
    """Arguments that log the name of every option read."""

    def __init__(self, args: argparse.Namespace, reads: list[str]) -> None:
        super().__init__(**vars(args))
        object.__setattr__(self, "_reads", reads)

    def __getattribute__(self, name: str) -> Any:
        if not name.startswith("_"):
            object.__getattribute__(self, "_reads").append(name)
        return object.__getattribute__(self, name)


#: Marks, in the log of reads, where ``_command`` returned.
BUILT = "<command built>"


@pytest.fixture
def traced(monkeypatch: pytest.MonkeyPatch) -> dict[str, list[Any]]:
    """Run the command with its reads of the arguments and its configurations recorded."""
    seen: dict[str, list[Any]] = {
        "reads": [],
        "loaded": [],
        "robots": [],
        "built": [],
        "runners": [],
    }
    command, load, build = cli._command, cli.load_config, cli.robot_from_config
    runner_from_config = cli.Runner.from_config

    def recorded_command(args: argparse.Namespace, outcome: Any) -> Any:
        result = command(args, outcome)
        seen["reads"].append(BUILT)
        return result

    def recorded_load(*args: Any, **kwargs: Any) -> PickPlaceConfig:
        config = load(*args, **kwargs)
        seen["loaded"].append(config)
        return config

    def recorded_robot(config: PickPlaceConfig, *args: Any, **kwargs: Any) -> Any:
        seen["robots"].append(config)
        seen["built"].append(build(config, *args, **kwargs))
        return seen["built"][-1]

    def recorded_runner(robot: Any, config: PickPlaceConfig, **kwargs: Any) -> Any:
        seen["runners"].append(config)
        return runner_from_config(robot, config, **kwargs)

    monkeypatch.setattr(cli, "_command", recorded_command)
    monkeypatch.setattr(cli, "load_config", recorded_load)
    monkeypatch.setattr(cli, "robot_from_config", recorded_robot)
    monkeypatch.setattr(cli.Runner, "from_config", recorded_runner)
    return seen


def _run(argv: list[str], seen: dict[str, list[Any]]) -> int:
    args = _RecordingArgs(cli.build_parser().parse_args(argv), seen["reads"])
    return cli.run(args, output=cli._Output(quiet=True))


def _after_build(reads: list[str]) -> set[str]:
    assert reads.count(BUILT) == 1
    return set(reads[reads.index(BUILT) + 1 :])


@pytest.mark.parametrize("mode", ["sim", "robot", "dry-run"])
def test_after_the_command_is_built_only_output_options_are_read(
    mode: str,
    traced: dict[str, list[Any]],
    tmp_path: Path,
    memory_simulator_factory: SimFactory,
) -> None:
    config = tmp_path / "cell.toml"
    config.write_text(FAST)
    report = tmp_path / "run.json"
    argv = ["--config", str(config), "--report", str(report), "--profile", "article"]
    if mode == "sim":
        argv += ["--sim", "--sim-time-scale", "40", "--cycles", "2", "--poll-interval", "0.03"]
    elif mode == "robot":
        # 100x with a 250 Hz tick (0.4 simulated s a tick, as the suite's 40x at 100 Hz):
        # the subject is which options are read, not the pace of the run.
        sim = memory_simulator_factory("article", **QUICK)
        argv += ["--host", sim.url, "--poll-interval", "0.03"]
    else:
        argv += ["--dry-run", "--cycles", "3"]

    assert _run(argv, traced) == cli.EXIT_OK

    assert _after_build(traced["reads"]) <= cli._OUTPUT_OPTIONS
    # ... and every other option was read once.
    reads = Counter(name for name in traced["reads"] if name not in cli._OUTPUT_OPTIONS)
    assert {name for name, count in reads.items() if count > 1} == set()
    assert "report" in _after_build(traced["reads"])
    # One configuration, loaded once; the robots and the runner are built from it.
    (loaded,) = traced["loaded"]
    assert loaded.run.poll_interval_s == (0.02 if mode == "dry-run" else 0.03)
    assert traced["robots"], "no robot was built"
    assert all(config is loaded for config in traced["robots"] + traced["runners"])
    assert len(traced["runners"]) == (0 if mode == "dry-run" else 1)
    # The register map checked while loading is the one the robots speak (loaded once).
    assert all(robot.profile is loaded.robot_profile() for robot in traced["built"])
    # A real robot is checked and run as one Robot; --sim checks one, runs the simulator's.
    assert len(traced["robots"]) == {"sim": 2, "robot": 1, "dry-run": 1}[mode]
