"""Digital I/O (``robot.io``): TM addresses, one request per read, checked and gated writes."""

from __future__ import annotations

import logging
import re
import shutil
import subprocess
import threading
from collections.abc import Callable, Iterator

import pytest

from fault_proxy import FaultProxy, Rule
from tmmaster import (
    ConfigError,
    ResponseTimeoutError,
    RetryPolicy,
    Robot,
    StopRequestedError,
    TimeoutPolicy,
    connect,
)
from tmmaster._robot_program import END_MODULE_DO
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]


@pytest.fixture
def sim(memory_simulator_factory: Factory) -> Simulator:
    return memory_simulator_factory()


@pytest.fixture
def robot(sim: Simulator) -> Iterator[Robot]:
    with connect(sim.url) as r:
        yield r


def requests(sim: Simulator, function_code: int) -> list[tuple[int, int]]:
    """``(address, count)`` of every request with ``function_code`` the simulator got."""
    return [(r.address, r.count) for r in sim.request_log if r.function_code == function_code]


def test_a_do_written_reads_back_at_the_tm_coil(sim: Simulator, robot: Robot) -> None:
    sim.clear_request_log()
    robot.io.set_do(3, True)
    assert requests(sim, 5) == [(3, 1)]  # control box DO 3 = coil 3, FC 05
    assert sim.do(3) is True
    assert sim.field("cb_do_3") is True  # the TM table's own entry
    assert robot.io.do(3) is True
    assert robot.io.dos() == tuple(i == 3 for i in range(16))
    robot.io.set_do(3, False)
    assert robot.io.do(3) is False
    assert sim.do(3) is False


def test_end_module_do_is_coil_800_plus_n(sim: Simulator, robot: Robot) -> None:
    sim.clear_request_log()
    robot.io.set_do(2, True, module="end_module")
    assert requests(sim, 5) == [(802, 1)]
    assert sim.do(2, module="end_module") is True
    assert sim.do(2) is False  # control box DO 2 untouched
    assert robot.io.dos(module="end_module") == (False, False, True, False)


def test_inputs_follow_the_simulator_and_read_in_one_request(sim: Simulator, robot: Robot) -> None:
    sim.set_di(5, True)
    sim.set_di(15, True)
    sim.set_di(3, True, module="end_module")
    sim.clear_request_log()
    assert robot.io.di(5) is True
    assert robot.io.di(4) is False
    assert robot.io.dis() == tuple(i in (5, 15) for i in range(16))
    assert robot.io.di(3, module="end_module") is True
    assert robot.io.dis(module="end_module")[1:] == (False, False, True)
    assert requests(sim, 2) == [(5, 1), (4, 1), (0, 16), (803, 1), (800, 4)]
    sim.set_di(5, False)
    assert robot.io.di(5) is False


def test_io_set_is_logged_at_info(robot: Robot, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.INFO, logger="tmmaster.robot"):
        robot.io.set_do(3, True)
    [record] = [r for r in caplog.records if "robot.io_set" in r.getMessage()]
    assert record.levelno == logging.INFO
    assert "do=3" in record.getMessage()
    assert "value=True" in record.getMessage()
    assert "module=control_box" in record.getMessage()


def test_a_write_after_close_is_refused_unsent(sim: Simulator, robot: Robot) -> None:
    robot.close()
    sim.clear_request_log()
    # The command gate refuses it (a closed link alone would say TransportClosedError).
    with pytest.raises(StopRequestedError, match="control_box DO 3 not written"):
        robot.io.set_do(3, True)
    assert sim.request_log == []
    assert sim.do(3) is False


def test_a_write_while_a_stop_is_requested_is_refused_unsent(sim: Simulator, robot: Robot) -> None:
    robot.interrupt()
    sim.clear_request_log()
    before = robot.stats.requests
    with pytest.raises(StopRequestedError, match="stop was requested"):
        robot.io.set_do(3, True)
    assert robot.stats.requests == before
    assert sim.request_log == []
    robot.clear_stop_request()
    robot.io.set_do(3, True)
    assert sim.do(3) is True


def test_the_program_gripper_output_is_refused_unsent(sim: Simulator, robot: Robot) -> None:
    assert robot.io.gripper_output == 0  # the generated program's default wiring (io:do=0)
    sim.clear_request_log()
    with pytest.raises(ConfigError, match=r"end_module DO 0 \(coil 800\) drives the gripper"):
        robot.io.set_do(0, True, module="end_module")
    with pytest.raises(ConfigError, match="gripper"):
        robot.io.set_do(0, False, module="end_module")
    assert sim.request_log == []
    assert sim.do(0, module="end_module") is False
    # Control box DO 0 is another coil: allowed.
    robot.io.set_do(0, True)
    assert sim.do(0) is True


def test_the_gripper_output_follows_the_program_wiring(sim: Simulator, robot: Robot) -> None:
    robot.io.gripper_output = 2  # a program written with --gripper io:do=2
    robot.io.set_do(0, True, module="end_module")
    assert sim.do(0, module="end_module") is True
    with pytest.raises(ConfigError, match="io:do=2"):
        robot.io.set_do(2, True, module="end_module")
    robot.io.gripper_output = None  # no program drives a gripper output
    robot.io.set_do(2, True, module="end_module")
    assert sim.do(2, module="end_module") is True
    for bad in (4, -1, True, 1.0):
        with pytest.raises(ConfigError, match="end_module DO"):
            robot.io.gripper_output = bad  # type: ignore[assignment]
    assert robot.io.gripper_output is None


def test_a_profile_without_digital_io_refuses_unsent(memory_simulator_factory: Factory) -> None:
    sim = memory_simulator_factory("article")
    with connect(sim.url, profile="article") as robot:
        assert robot.io.modules == ()
        assert robot.io.gripper_output is None  # no robot program
        sim.clear_request_log()
        with pytest.raises(ConfigError, match="profile 'article' declares no digital I/O"):
            robot.io.set_do(0, True)
        with pytest.raises(ConfigError, match="no digital I/O"):
            robot.io.dis()
        assert sim.request_log == []
    with pytest.raises(ConfigError, match="no digital I/O"):
        sim.set_di(0, True)


def test_a_custom_module_is_served_by_the_simulator(memory_simulator_factory: Factory) -> None:
    from tmmaster._profiles import profile_from_data

    profile = profile_from_data(
        {
            "extends": "article",
            "name": "article-io",
            "digital_io": {"panel": {"do_address": 3000, "do_count": 2, "di_count": 0}},
        }
    )
    sim = memory_simulator_factory(profile)
    with connect(sim.url, profile=profile) as robot:
        robot.io.set_do(1, True, module="panel")
        assert robot.io.dos(module="panel") == (False, True)
        assert sim.do(1, module="panel") is True
        with pytest.raises(ConfigError, match="module panel has no DI"):
            robot.io.di(0, module="panel")


@pytest.fixture
def tcp_sim(tm_simulator_factory: Factory) -> Simulator:
    return tm_simulator_factory()


@pytest.mark.parametrize("retries", [True, False], ids=["retried", "not-retried"])
def test_a_lost_answer_leaves_the_coil_as_requested(tcp_sim: Simulator, retries: bool) -> None:
    retry = RetryPolicy(initial_backoff_s=0.01, jitter_s=0) if retries else RetryPolicy(attempts=1)
    with FaultProxy(tcp_sim.port) as proxy:
        robot = Robot("127.0.0.1", proxy.port, retry=retry, timeouts=TimeoutPolicy(request_s=0.3))
        with robot:
            tcp_sim.clear_request_log()
            proxy.add(Rule("drop_answer", function_code=5))
            if retries:
                # Setting a coil twice to the same value is harmless: resent, and done.
                robot.io.set_do(3, True)
                assert [(r.function_code, r.address) for r in tcp_sim.request_log] == [
                    (5, 3),
                    (5, 3),
                ]
            else:
                with pytest.raises(ResponseTimeoutError):
                    robot.io.set_do(3, True)
                assert requests(tcp_sim, 5) == [(3, 1)]
            assert tcp_sim.do(3) is True
            assert robot.io.do(3) is True


def test_close_waits_for_a_do_write_in_flight_then_refuses_the_next(tcp_sim: Simulator) -> None:
    """close() from another thread never cuts a DO write short, and no write follows it."""
    with FaultProxy(tcp_sim.port) as proxy:
        robot = Robot("127.0.0.1", proxy.port, timeouts=TimeoutPolicy(request_s=2.0))
        robot.connect()
        proxy.add(Rule("delay", function_code=5, delay_s=0.3))
        outcome: list[BaseException | None] = []

        def write() -> None:
            try:
                robot.io.set_do(3, True)
                outcome.append(None)
            except BaseException as exc:  # reported below
                outcome.append(exc)

        writer = threading.Thread(target=write)
        writer.start()
        tcp_sim.wait_for(lambda: any(s.function_code == 5 for s in proxy.seen), 5.0)
        assert robot.close(timeout_s=3.0) is True  # waits for the write on the wire
        writer.join(5.0)
        assert outcome == [None]
        with pytest.raises(StopRequestedError):
            robot.io.set_do(4, True)
        assert tcp_sim.do(3) is True
        assert tcp_sim.do(4) is False
        assert [s.function_code for s in proxy.seen].count(5) == 1


MBPOLL = shutil.which("mbpoll")


def mbpoll_bits(port: int, table: str, first: int, *values: int, count: int = 1) -> dict[int, int]:
    """One mbpoll request: read ``count`` bits, or write ``values`` (table "0" coils, "1" DIs)."""
    if MBPOLL is None:
        pytest.skip("mbpoll not installed: apt-get install mbpoll")
    args = [MBPOLL, "-m", "tcp", "-a", "1", "-0", "-t", table, "-r", str(first), "-p", str(port)]
    args += ["-1", "-c", str(count), "127.0.0.1"] if not values else ["127.0.0.1"]
    result = subprocess.run(
        args + [str(v) for v in values], capture_output=True, text=True, timeout=10, check=False
    )
    assert result.returncode == 0, result.stdout + result.stderr
    found = re.findall(r"^\[(\d+)\]:\s+(\d+)", result.stdout, re.MULTILINE)
    return {int(a): int(v) for a, v in found}


def test_another_modbus_master_sees_the_same_io(tcp_sim: Simulator) -> None:
    """mbpoll (not tmmaster's client) at the TM addresses: coils 0-15 / 800-803, DIs 0-15."""
    port = tcp_sim.port
    tcp_sim.set_di(7, True)
    assert mbpoll_bits(port, "1", 0, count=16) == {i: int(i == 7) for i in range(16)}
    mbpoll_bits(port, "0", 5, 1)  # FC 05: control box DO 5 high
    with connect("127.0.0.1", port) as robot:
        assert robot.io.do(5) is True
        assert robot.io.di(7) is True
        robot.io.set_do(1, True, module="end_module")
    assert mbpoll_bits(port, "0", 800, count=4) == {800: 0, 801: 1, 802: 0, 803: 0}
    # The master's heartbeat (FC16 at 9050) is no I/O write: it may come at any time.
    io_writes = [r for r in tcp_sim.request_log if r.is_write and r.address != 9050]
    assert [r.function_code for r in io_writes] == [5, 5]


def test_the_register_maps_page_shows_the_tmflow_modules() -> None:
    """The ``[digital_io]`` example of docs/register-maps.md is the tmflow profile's."""
    import tomllib
    from pathlib import Path

    from tmmaster import DigitalIOModule, robot_profile

    doc = (Path(__file__).parent.parent / "docs" / "register-maps.md").read_text("utf-8")
    [block] = [b for b in re.findall(r"```toml\n(.*?)```", doc, flags=re.S) if "digital_io" in b]
    shown = {name: DigitalIOModule(**m) for name, m in tomllib.loads(block)["digital_io"].items()}
    assert shown == robot_profile("tmflow").digital_io
    # The coil the robot program drives its gripper with is the end module's DO 0.
    assert shown["end_module"].do_address == END_MODULE_DO
