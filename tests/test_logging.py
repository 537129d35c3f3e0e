"""The library is quiet unless the application configures logging."""

from __future__ import annotations

import io
import json
import subprocess
import sys
import textwrap
from typing import Any

import pytest

import tmmaster
from tmmaster._logging import get_logger


def test_the_readme_snippet_prints_only_what_the_user_prints() -> None:
    script = textwrap.dedent(
        """
        import tmmaster
        from tmmaster.sim import Simulator

        with Simulator("article", listen=False, time_scale=20) as sim:
            with tmmaster.connect(sim.url, profile="article") as robot:
                robot.wait_until_ready()
                robot.move_to(tmmaster.Pose(300, -200, 200, 180, 0, 90), speed=30)
                print("mine")
        """
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=True
    )
    assert done.stdout == "mine\n"
    assert done.stderr == ""


def test_configure_logging_prints_events_and_can_be_undone(
    capfd: pytest.CaptureFixture[str],
) -> None:
    # In-process: configure_logging writes to the stream it is given; what a fresh
    # interpreter prints without it is the test above.
    stream = io.StringIO()
    undo = tmmaster.configure_logging(json=True, level="info", stream=stream)
    get_logger("tmmaster.robot").info("robot.test_event", answer=42)
    get_logger("tmmaster.robot").debug("robot.too_detailed")
    undo()
    get_logger("tmmaster.robot").warning("robot.after_undo")
    (line,) = stream.getvalue().splitlines()
    event = json.loads(line)
    assert (event["event"], event["answer"]) == ("robot.test_event", 42), event
    assert (event["logger"], event["level"]) == ("tmmaster.robot", "info"), event
    assert capfd.readouterr() == ("", "")


def test_a_disabled_event_never_enters_the_processors(monkeypatch: pytest.MonkeyPatch) -> None:
    import logging

    import structlog

    from tmmaster import _structlog

    seen: list[str] = []

    def spy(_logger: object, _method: str, event: dict[str, object]) -> dict[str, object]:
        seen.append(str(event["event"]))
        raise structlog.DropEvent

    monkeypatch.setattr(_structlog, "_PROCESSORS", [spy])
    std = logging.getLogger("tmmaster.test_disabled_events")
    std.setLevel(logging.WARNING)
    log = get_logger("tmmaster.test_disabled_events").bind(a=1)
    log.debug("d")
    log.info("i")
    log.warning("w")
    log.error("e")
    log.exception("x")
    std.setLevel(logging.NOTSET)
    assert seen == ["w", "e", "x"]


def test_is_enabled_for_follows_the_standard_loggers_level() -> None:
    import logging

    std = logging.getLogger("tmmaster.test_is_enabled_for")
    log = get_logger("tmmaster.test_is_enabled_for").bind(robot="r1")
    std.setLevel(logging.WARNING)
    assert not log.is_enabled_for(logging.INFO)
    assert log.is_enabled_for(logging.WARNING)
    std.setLevel(logging.DEBUG)
    assert log.is_enabled_for(logging.INFO)
    std.setLevel(logging.NOTSET)


def test_a_robots_info_events_are_still_logged_when_enabled(
    tm_simulator_factory: Any, robots: Any, caplog: pytest.LogCaptureFixture
) -> None:
    # The move events' fields are built only when INFO is on: with it on, they go out.
    import logging

    from tmmaster import Pose

    robot = robots(tm_simulator_factory("article"))
    with caplog.at_level(logging.INFO, "tmmaster"):
        robot.move_to(Pose(300, -200, 150, 180, 0, 90), speed=50)
    for event in ("robot.command_sent", "robot.command_acknowledged", "robot.command_done"):
        assert event in caplog.text


def test_a_plain_logging_setup_prints_the_event_then_key_value() -> None:
    # What logging.basicConfig(level=logging.INFO) prints: its own format around the
    # message, and the message is the event and its fields, never a dict.
    import logging

    stream = io.StringIO()
    handler = logging.StreamHandler(stream)
    handler.setFormatter(logging.Formatter(logging.BASIC_FORMAT))
    std = logging.getLogger("tmmaster.test_plain")
    std.addHandler(handler)
    std.setLevel(logging.INFO)
    try:
        log = get_logger("tmmaster.test_plain").bind(robot="r1")
        log.info("robot.connected", host="127.0.0.1", port=5020, target=[1.0, 2.5], note="a b")
        try:
            raise ValueError("boom")
        except ValueError:
            log.exception("robot.failed", quote='say "hi"')
    finally:
        std.removeHandler(handler)
        std.setLevel(logging.NOTSET)
    lines = stream.getvalue().splitlines()
    assert lines[0] == (
        "INFO:tmmaster.test_plain:robot.connected robot=r1 host=127.0.0.1 port=5020"
        ' target=[1.0,2.5] note="a b"'
    )
    assert lines[1] == 'ERROR:tmmaster.test_plain:robot.failed robot=r1 quote="say \\"hi\\""'
    assert lines[2] == "Traceback (most recent call last):"
    assert lines[-1] == "ValueError: boom"
    assert "timestamp" not in stream.getvalue()


def test_json_and_key_value_are_still_there_when_asked() -> None:
    # configure_logging renders the same events as JSON (--log-json) or as key=value.
    for as_json in (True, False):
        stream = io.StringIO()
        undo = tmmaster.configure_logging(json=as_json, level="info", stream=stream)
        try:
            get_logger("tmmaster.robot").bind(robot="r1").info("robot.connected", port=5020)
        finally:
            undo()
        (line,) = stream.getvalue().splitlines()
        if as_json:
            assert json.loads(line)["event"] == "robot.connected"
        else:
            assert "robot.connected" in line
            assert "port=5020" in line
            assert not line.startswith("{")
