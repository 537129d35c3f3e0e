"""``tmmaster robot``: bad options refused before the first byte; ``stop`` says done at rest."""

from __future__ import annotations

from collections.abc import Callable

import pytest

from tmmaster import Pose, Robot
from tmmaster._cli import main
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]
FAR = Pose(300, 200, 200, 180, 0, 90)
#: The article's field that is 1 while the arm moves.
MOVING = {"article": "motion_status"}


@pytest.fixture(params=["article", "tmflow"])
def sim(tm_simulator_factory: SimFactory, request: pytest.FixtureRequest) -> Simulator:
    return tm_simulator_factory(request.param)


@pytest.mark.parametrize("action", ["play", "stop"])
@pytest.mark.parametrize("timeout", ["-1", "nan"])
def test_a_bad_timeout_is_refused_before_anything_is_sent(
    sim: Simulator, action: str, timeout: str, capsys: pytest.CaptureFixture[str]
) -> None:
    where = ["--host", sim.host, "--port", str(sim.port), "--profile", sim.profile.name]
    assert main(["robot", action, *where, "--timeout", timeout]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1
    assert "--timeout" in err[0]
    assert list(sim.request_log) == []


@pytest.mark.parametrize("name", ["article", "tmflow"])
def test_stop_says_done_only_once_the_arm_is_at_rest(
    tm_simulator_factory: SimFactory, name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    # Real time: the arm brakes for about 0.3 s, longer than the command's own reads.
    sim = tm_simulator_factory(name, time_scale=1.0)
    with Robot(sim.host, sim.port, profile=name) as robot:
        robot.wait_until_ready()
        start = sim.tcp_pose()
        robot.start_move(FAR, speed=30)
        sim.wait_for(lambda: sim.tcp_pose().distance_to(start) > 5, timeout=5.0)
        where = ["--host", sim.host, "--port", str(sim.port), "--profile", name]
        assert main(["robot", "stop", *where]) == 0
        # Braked to rest before the answer: the arm no longer moves (the article's motion
        # flag says so; tmflow's robot program state does not, after a stop).
        answered = sim.tcp_pose()
        if name == "article":
            assert sim.field(MOVING[name]) == 0
        ticks = sim.ticks
        sim.wait_for(lambda: sim.ticks >= ticks + 10, timeout=5.0)
        assert sim.tcp_pose().is_close(answered, mm=0.05, deg=0.05)
        assert "at rest" in capsys.readouterr().out
        robot.interrupt()
