"""The start of a run with a part still in the gripper (a run that failed mid-carry).

A re-run must not open the gripper wherever the arm happens to be: the part would fall
there. The run refuses to start (exit 2, nothing written, nothing moved) unless the
operator asks for the release (``--release-held-part``, ``[gripper]
release_held_part_at_start``). Every check reads the simulator (its request and motion
logs, where the part is), not what the master says.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

import pytest

from sim_speeds import QUICK
from tmmaster import PollPolicy, Pose, Robot, TimeoutPolicy, load_profile
from tmmaster.pickplace import ARTICLE_PICK, ARTICLE_PLACE, Runner, TaskSequence
from tmmaster.pickplace.__main__ import EXIT_CONFIG, EXIT_OK, main
from tmmaster.sim import Cell, RequestRecord, Simulator, TableObject

PICK = Pose.from_sequence(ARTICLE_PICK)
PLACE = Pose.from_sequence(ARTICLE_PLACE)
#: Where the earlier run stopped: the part lifted 150 mm above the pick pose.
LIFT = PICK.offset(dz=150)
#: A part released at PLACE falls onto the table: its centre at PICK's height.
PLACED = Pose(PLACE.x, PLACE.y, PICK.z, PLACE.rx, PLACE.ry, PLACE.rz)
GRIPPER_REGISTER = 0x0210  # article: 0 open, 1 close
TARGET_BLOCK = 0x0200  # article: one FC16 per motion command

FAST = """
[gripper]
settle_s = 0.05

[run]
poll_interval_s = 0.02

[timeouts]
ack_s = 0.5
motion_margin_s = 0.5
"""

SimFactory = Callable[..., Simulator]


def holding_sim(factory: SimFactory, profile: str) -> Simulator:
    """A simulator whose gripper holds the part at LIFT, as a run that failed mid-carry
    leaves it; its request log cleared, so it holds only what the next run sends."""
    sim = factory(profile, cell=Cell(scene=[TableObject(name="part-1", pose=PICK)]), **QUICK)
    with Robot(
        "127.0.0.1",
        sim.port,
        profile=profile,
        polling=PollPolicy(interval_s=0.01),
        timeouts=TimeoutPolicy(gripper_settle_s=0.05),
    ) as robot:
        robot.gripper.open()
        robot.move_to(PICK.offset(dz=100), speed=30)
        robot.move_to(PICK, speed=10, motion="line")
        robot.gripper.grip()
        robot.move_to(LIFT, speed=10, motion="line")
    (part,) = sim.objects()
    assert part.held
    sim.clear_request_log()
    return sim


def run_cli(
    sim: Simulator, tmp_path: Path, *extra: str, gripper: str = "", config: str = ""
) -> int:
    """The command, in-process, against ``sim``: the fast settings, ``gripper`` keys in
    their section, then ``config``."""
    path = tmp_path / "cell.toml"
    path.write_text(FAST.replace("[gripper]\n", f"[gripper]\n{gripper}\n") + "\n" + config)
    return main(
        [
            "--host",
            "127.0.0.1",
            "--port",
            str(sim.port),
            "--profile",
            sim.profile.name,
            "--config",
            str(path),
            *extra,
        ]
    )


def writes(log: list[RequestRecord], address: int | None = None) -> list[RequestRecord]:
    """The writes of the log (at ``address`` only, when given)."""
    return [r for r in log if r.is_write and (address is None or r.address == address)]


def assert_untouched(sim: Simulator, motions_before: int) -> None:
    """Nothing written, nothing moved, nothing opened: the part is still held at LIFT."""
    assert writes(sim.request_log) == []
    assert len(sim.motion_log()) == motions_before  # no move, no gripper command
    (part,) = sim.objects()
    assert part.held
    assert sim.tcp_pose().is_close(LIFT, mm=0.5)


@pytest.mark.parametrize(
    ("profile", "reaction"), [("article", "stay"), ("article", "retreat"), ("tmflow", "stay")]
)
def test_a_part_held_at_the_start_refuses_the_run_and_nothing_moves_or_opens(
    tm_simulator_factory: SimFactory,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    profile: str,
    reaction: str,
) -> None:
    sim = holding_sim(tm_simulator_factory, profile)
    motions = len(sim.motion_log())

    code = run_cli(sim, tmp_path, config=f'[on_error]\nreaction = "{reaction}"\n')

    assert code == EXIT_CONFIG
    assert_untouched(sim, motions)  # the retreat does not move a run that never started
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert line.startswith("pickplace: ")
    assert line.endswith("[exit 2]")
    assert "the gripper holds a part at the start" in line
    assert "--release-held-part" in line
    assert "release_held_part_at_start" in line


def test_a_part_held_without_the_open_at_start_is_refused_too(
    tm_simulator_factory: SimFactory, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Not opened, the part would be carried down onto the next part at the pick pose.
    sim = holding_sim(tm_simulator_factory, "article")
    motions = len(sim.motion_log())

    code = run_cli(sim, tmp_path, gripper="open_at_start = false")

    assert code == EXIT_CONFIG
    assert_untouched(sim, motions)
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert "the gripper holds a part at the start" in line
    assert "starts with a pick" in line


@pytest.mark.parametrize(
    ("option", "gripper"),
    [("--release-held-part", ""), (None, "release_held_part_at_start = true")],
    ids=["option", "config-key"],
)
def test_the_opt_in_releases_the_held_part_where_the_arm_is_then_runs_the_cycle(
    tm_simulator_factory: SimFactory,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    option: str | None,
    gripper: str,
) -> None:
    sim = holding_sim(tm_simulator_factory, "article")

    code = run_cli(sim, tmp_path, *([option] if option else []), gripper=gripper)

    assert code == EXIT_OK
    sent = writes(sim.request_log)
    # The first thing written is the open, where the arm was (nothing moved before it).
    assert sent[0].address == GRIPPER_REGISTER
    assert sent[0].values == (0,)
    assert writes(sim.request_log, TARGET_BLOCK)[0] is sent[1]
    # The part fell at the pick pose's x-y, was picked again and placed.
    (part,) = sim.objects()
    assert not part.held
    assert part.pose.is_close(PLACED, mm=1.0)
    assert "pickplace.held_part_released" in capsys.readouterr().err  # a warning, by default


@pytest.mark.parametrize(
    ("option", "gripper"),
    [("--release-held-part", ""), (None, "release_held_part_at_start = false")],
    ids=["option", "config-key-default"],
)
def test_an_empty_gripper_still_opens_at_the_start(
    tm_simulator_factory: SimFactory,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    option: str | None,
    gripper: str,
) -> None:
    sim = tm_simulator_factory(
        "article", cell=Cell(scene=[TableObject(name="part-1", pose=PICK)]), **QUICK
    )

    code = run_cli(sim, tmp_path, *([option] if option else []), gripper=gripper)

    assert code == EXIT_OK
    sent = writes(sim.request_log)
    assert sent[0].address == GRIPPER_REGISTER
    assert sent[0].values == (0,)  # opened first
    assert writes(sim.request_log, TARGET_BLOCK)[0] is sent[1]
    (part,) = sim.objects()
    assert not part.held
    assert part.pose.is_close(PLACED, mm=1.0)
    assert "held_part" not in capsys.readouterr().err  # nothing held: nothing to say


def test_the_opt_in_without_the_open_at_start_is_refused_naming_the_key(
    tm_simulator_factory: SimFactory, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = tm_simulator_factory("article", **QUICK)

    code = run_cli(sim, tmp_path, "--release-held-part", gripper="open_at_start = false")

    assert code == EXIT_CONFIG
    assert sim.request_log == []  # refused before anything connected
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert "gripper.release_held_part_at_start: needs open_at_start = true" in line


def test_a_gripper_that_cannot_tell_is_opened_at_the_start_with_a_warning(
    tm_simulator_factory: SimFactory, caplog: pytest.LogCaptureFixture
) -> None:
    # A register gripper on a profile without a grasp flag cannot say it holds the part:
    # the start opens it as configured, and says that it could not look.
    sim = holding_sim(tm_simulator_factory, "article")
    data = load_profile("article").model_dump()
    del data["fields"]["grasp_status"]
    blind = type(load_profile("article")).model_validate({**data, "name": "no-grasp-flag"})
    with (
        caplog.at_level(logging.WARNING, "tmmaster"),
        Robot(
            "127.0.0.1",
            sim.port,
            profile=blind,
            polling=PollPolicy(interval_s=0.01),
            timeouts=TimeoutPolicy(gripper_settle_s=0.05),
        ) as robot,
    ):
        sequence = TaskSequence("open-only", prepare=lambda ctx: ctx.open_gripper())
        sequence.add("DWELL", lambda ctx: ctx.wait(0.01))
        result = Runner(robot).run(sequence)

    assert result.ok
    assert writes(sim.request_log, GRIPPER_REGISTER)[0].values == (0,)
    (part,) = sim.objects()
    assert not part.held  # released where the arm was: the gripper could not tell
    assert "pickplace.held_part_unknown" in caplog.text
