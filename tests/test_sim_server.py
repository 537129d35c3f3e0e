"""The simulator over real loopback TCP: served map, request log, faults, robustness."""

from __future__ import annotations

import json
import os
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import pytest

from exit_hooks import PAUSE_AT_EXIT, PAUSED_AT_EXIT, ctrl_c_in_the_exit_hooks
from tmmaster import (
    DEFAULT_PROFILE,
    ConnectionState,
    ModbusExceptionError,
    ModbusTransport,
    ResponseTimeoutError,
    RetryPolicy,
    TransportError,
)
from tmmaster._pose import Pose
from tmmaster._profiles import robot_profile
from tmmaster._registers import Table
from tmmaster.sim import RobotSetup, Simulator
from tmmaster.sim.__main__ import main as sim_main
from tmmaster.sim._bank import RegisterBank
from tmmaster.sim._tm_table import tm_table_fields, user_area

Factory = Callable[..., Simulator]

#: Article move: target (300, -200, 200, 180, 0, 90) x100 as int16, speed 50 %, PTP.
TARGET = Pose(300.0, -200.0, 200.0, 180.0, 0.0, 90.0)
MOVE_WORDS = [30000, (-20000) & 0xFFFF, 20000, 18000, 0, 9000, 50, 1]


@pytest.fixture
def article_simulator(tm_simulator_factory: Factory) -> Simulator:
    """A started simulator on the article's map: the tests read its registers directly."""
    return tm_simulator_factory("article")


@contextmanager
def client(port: int, *, timeout: float = 1.0, device_id: int = 1) -> Iterator[ModbusTransport]:
    """tmmaster's transport without retries (each call is one request), closed afterwards."""
    c = ModbusTransport(
        "127.0.0.1",
        port,
        device_id=device_id,
        timeout=timeout,
        retry=RetryPolicy(attempts=1),
        name="test-client",
    )
    try:
        yield c
    finally:
        c.close()


def read(c: ModbusTransport, table: Table, address: int, count: int = 1) -> list[int]:
    """One read request of the right function code for ``table``."""
    return c.read_block(table, address, count, retry=False)


def hr(c: ModbusTransport, address: int) -> int:
    """One holding register (a failed read raises)."""
    return read(c, Table.HOLDING, address)[0]


def write(c: ModbusTransport, address: int, words: list[int]) -> None:
    """One FC16 write of holding registers, sent once."""
    c.write_block(Table.HOLDING, address, words, retry=False)


def exception_code(request: Callable[[], object]) -> int:
    """The Modbus exception code a request is answered with (fails if it is answered)."""
    try:
        request()
    except ModbusExceptionError as exc:
        return exc.code
    pytest.fail("the request was answered normally, not with an exception")


def fails(request: Callable[[], object]) -> bool:
    """True when a request gets no normal answer (exception response or broken connection)."""
    try:
        request()
    except TransportError:
        return True
    return False


def raw_request(port: int, pdu: bytes, *, unit: int = 1) -> bytes:
    """Send one raw Modbus TCP request and return the response PDU (function code first)."""
    with socket.create_connection(("127.0.0.1", port), timeout=1.0) as s:
        s.sendall(struct.pack(">HHHB", 1, 0, len(pdu) + 1, unit) + pdu)
        header = b""
        while len(header) < 7:
            header += s.recv(7 - len(header))
        length = struct.unpack(">H", header[4:6])[0] - 1
        body = b""
        while len(body) < length:
            body += s.recv(length - len(body))
    return body


def wait_ready(sim: Simulator) -> None:
    sim.wait_for(lambda: sim.field("robot_mode") == sim.profile.mode_auto, 2.0)


# -- the served map ---------------------------------------------------------------------


@pytest.mark.parametrize("name", ["article", "tmflow"])
def test_every_field_is_served_and_unserved_addresses_give_exception_2(
    tm_simulator_factory: Factory, name: str
) -> None:
    sim = tm_simulator_factory(name)
    profile = robot_profile(name)
    # A tmflow simulator also serves Techman's table and the user define area.
    bank = (
        RegisterBank(profile, extra_fields=tm_table_fields(profile), raw_areas=user_area())
        if name == "tmflow"
        else RegisterBank(profile)
    )
    with client(sim.port) as c:
        for field in profile.fields.values():
            words = read(c, field.table, field.address, field.width)  # raises if refused
            assert len(words) == field.width, field.name
        for table in Table:
            runs = bank.readable(table)
            # One past the last readable address of the table (or 0 for an empty table).
            unserved = runs[-1][0] + runs[-1][1] if runs else 0
            assert exception_code(lambda: read(c, table, unserved)) == 2, (table, unserved)  # noqa: B023


def test_the_fixtures_speak_the_default_profile(
    tm_simulator: Simulator, tm_simulator_factory: Factory
) -> None:
    # As every entry point does: the article's map only when a test asks for it.
    assert tm_simulator.profile.name == DEFAULT_PROFILE == "tmflow"
    assert tm_simulator_factory(listen=False).profile.name == DEFAULT_PROFILE
    assert tm_simulator_factory("article", listen=False).profile.name == "article"


def test_served_values_come_from_the_bank(article_simulator: Simulator) -> None:
    wait_ready(article_simulator)
    with client(article_simulator.port) as c:
        assert hr(c, 0x0000) == 5  # robot_mode auto, set by the controller
        pose = read(c, Table.HOLDING, 0x10, 6)
    assert pose == [25000, 0, 30000, 18000, 0, 9000]  # DEFAULT_HOME x100


def test_tmflow_bits_are_exact(tm_simulator_factory: Factory) -> None:
    sim = tm_simulator_factory("tmflow")
    sim.wait_for(lambda: sim.field("project_running") is True, 2.0)
    with client(sim.port) as c:
        bits = read(c, Table.DISCRETE_INPUT, 7201, 2)
        assert bits == [0, 1]  # error, project_running
        # 7211 is in no profile field and not in Techman's table.
        assert exception_code(lambda: read(c, Table.DISCRETE_INPUT, 7210, 2)) == 2


# -- request log ------------------------------------------------------------------------


def test_request_log_shows_one_fc16_per_move(article_simulator: Simulator) -> None:
    wait_ready(article_simulator)
    article_simulator.clear_request_log()
    with client(article_simulator.port, device_id=7) as c:
        write(c, 0x200, MOVE_WORDS)  # raises unless answered normally
        hr(c, 0x0001)
    log = article_simulator.request_log
    assert [(r.function_code, r.address, r.count) for r in log] == [(16, 0x200, 8), (3, 1, 1)]
    assert log[0].values == tuple(MOVE_WORDS)
    assert log[0].device_id == 7  # the TM controller answers any unit id
    assert log[0].server == "robot"
    assert log[1].values is None
    assert log[0].time <= log[1].time
    article_simulator.clear_request_log()
    assert article_simulator.request_log == []


def test_refused_write_changes_nothing(article_simulator: Simulator) -> None:
    wait_ready(article_simulator)
    # motion_status is written by the device only: refused by FC16 (the transport) and
    # by FC06 (a raw frame: the transport never sends FC06).
    with client(article_simulator.port) as c:
        assert exception_code(lambda: write(c, 0x0001, [1])) == 2
        assert hr(c, 0x0001) == 0
    assert raw_request(article_simulator.port, struct.pack(">BHH", 6, 0x0001, 1)) == bytes(
        [0x86, 2]
    )
    with client(article_simulator.port) as c:
        assert hr(c, 0x0001) == 0


# -- the article's race -----------------------------------------------------------------


def test_racy_article_master_sees_done_before_the_robot_moved(
    tm_simulator_factory: Factory,
) -> None:
    """The article's master: FC16 the move, then poll motion_status == 0 as "done"."""
    with ExitStack() as clients:
        for _attempt in range(20):
            # A fresh robot per attempt: after a missed attempt the move is already under
            # way, and writing it again would read "moving". Under CPU load (xdist workers)
            # a tick can fall between the write and the poll, hence a few attempts.
            sim = tm_simulator_factory("article", time_scale=5.0)
            wait_ready(sim)
            c = clients.enter_context(client(sim.port))
            # Start right after a tick, so the write and the first poll fit before the next.
            ticks = sim.ticks
            sim.wait_for(lambda: sim.ticks != ticks, 1.0, interval=0.0002)  # noqa: B023
            before = sim.ticks
            write(c, 0x200, MOVE_WORDS)
            racy_done = hr(c, 0x0001) == 0  # the article's completion check
            pose_at_done = sim.tcp_pose()
            if sim.ticks == before:
                break
        else:
            pytest.fail("could not fit write + poll between two ticks")
        assert racy_done, "the racy master reads idle and believes the move is done"
        assert not pose_at_done.is_close(TARGET), "but the robot had not moved at all"
        # Afterwards the robot does start the move the master thought was over.
        sim.wait_for(lambda: hr(c, 0x0001) == 1, 1.0)
        assert not sim.tcp_pose().is_close(TARGET)


def test_correct_handshake_ends_at_the_target(article_simulator: Simulator) -> None:
    wait_ready(article_simulator)
    with client(article_simulator.port) as c:
        write(c, 0x200, MOVE_WORDS)
        article_simulator.wait_for(lambda: hr(c, 0x0207) == 0, 2.0)  # acknowledged
        article_simulator.wait_for(lambda: hr(c, 0x0001) == 0, 5.0)  # then idle
        assert article_simulator.tcp_pose().is_close(TARGET)
        words = read(c, Table.HOLDING, 0x10, 6)
    assert words == MOVE_WORDS[:6]


# -- network faults ---------------------------------------------------------------------


def test_drop_connections_after_n_requests(tm_simulator_factory: Factory) -> None:
    sim = tm_simulator_factory("article", faults=["drop_connections:after_requests=2"])
    with client(sim.port) as c:
        hr(c, 0)
        hr(c, 0)  # the second request is answered, then the connection is closed
        sim.wait_for(lambda: c.state is ConnectionState.DISCONNECTED, 2.0)
    with client(sim.port) as c:  # once=true: a new connection is served normally
        for _ in range(3):
            hr(c, 0)


def test_drop_connections_injected_at_run_time_repeats(article_simulator: Simulator) -> None:
    article_simulator.inject("drop_connections:after_requests=1,once=false")
    for _ in range(2):
        with client(article_simulator.port) as c:
            hr(c, 0)
            # Dropped after its request: the link sees the close (a next request would
            # open a fresh one).
            article_simulator.wait_for(lambda: c.state is ConnectionState.DISCONNECTED, 2.0)
    article_simulator.clear_faults()
    with client(article_simulator.port) as c:
        hr(c, 0)
        hr(c, 0)
        assert c.state is ConnectionState.CONNECTED
        assert c.stats.reconnects == 0


def _connect_refused(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) != 0


def test_stop_listening_then_listening_again_on_the_same_port(
    tm_simulator_factory: Factory,
) -> None:
    # 0.3 s of outage (wall time); seen refused within a few ms of its start, so it is
    # seen down for more than 0.15 s (half of it, as 0.2 s of the 0.4 s it was).
    sim = tm_simulator_factory("article", faults=["stop_listening:after_requests=1,duration_s=0.3"])
    port = sim.port
    with client(port) as c:
        hr(c, 0)
    sim.wait_for(lambda: _connect_refused(port), 1.0)
    started = time.monotonic()
    sim.wait_for(lambda: not _connect_refused(port), 2.0, interval=0.02)
    assert time.monotonic() - started > 0.15
    assert sim.port == port
    with client(port) as c:
        hr(c, 0)


def test_slow_responses(article_simulator: Simulator) -> None:
    with client(article_simulator.port) as c:
        # Answers 0.15 s late; once cleared, a read (a few ms) must take under 0.12 s,
        # which a still-delayed answer cannot.
        article_simulator.inject("slow_responses:delay_s=0.15")
        started = time.monotonic()
        hr(c, 0)
        assert time.monotonic() - started >= 0.15
        article_simulator.clear_faults()
        started = time.monotonic()
        hr(c, 0)
        assert time.monotonic() - started < 0.12


def test_modbus_exception_for_an_address_range(tm_simulator_factory: Factory) -> None:
    sim = tm_simulator_factory(
        "article", faults=["modbus_exception:table=holding,start=0x200,end=0x207,code=6"]
    )
    with client(sim.port) as c:
        assert exception_code(lambda: write(c, 0x200, MOVE_WORDS)) == 6
        assert exception_code(lambda: hr(c, 0x1FF + 8)) == 6
        hr(c, 0)  # outside the range
    assert sim.field("command") == "none" or sim.field("command") == 0  # nothing written
    assert [r.refused for r in sim.request_log][:2] == [6, 6]


# -- the gripper device -----------------------------------------------------------------


def test_onrobot_gripper_allows_one_connection_and_its_unit_id(
    tm_simulator_factory: Factory,
) -> None:
    sim = tm_simulator_factory("article", robot=RobotSetup(gripper="onrobot-2fg7"))
    assert sim.gripper_port is not None
    assert sim.gripper_port != sim.port
    with client(sim.gripper_port, device_id=65) as first:
        assert hr(first, 1536) == 0xC0  # answered normally: the 2FG7's product code
        with client(sim.gripper_port, timeout=0.5, device_id=65) as second:
            second.connect()  # the kernel completes the TCP connect
            assert fails(lambda: hr(second, 1536))
        # The first connection is unaffected; a wrong unit id gets a gateway exception
        # (same connection: the transport takes its unit id from device_id per request).
        hr(first, 256)
        first.device_id = 1
        with pytest.raises(ResponseTimeoutError, match="exception 11"):  # 0x0B: a timeout
            hr(first, 256)
    with client(sim.gripper_port, device_id=65) as again:  # the first has gone: served
        sim.wait_for(lambda: not fails(lambda: hr(again, 1536)), 2.0)
    assert {r.server for r in sim.request_log} == {"gripper"}


# -- robustness -------------------------------------------------------------------------


def test_garbage_half_open_and_abrupt_clients_do_not_stop_service(
    article_simulator: Simulator,
) -> None:
    port = article_simulator.port
    garbage = socket.create_connection(("127.0.0.1", port))
    half_open = socket.create_connection(("127.0.0.1", port))
    abrupt = socket.create_connection(("127.0.0.1", port))
    try:
        garbage.sendall(os.urandom(64) + b"\xff" * 600)
        half_open.sendall(b"\x00\x01\x00\x00\x00\x06")  # an MBAP header and nothing more
        # A full FC3 request, then RST without waiting for the answer.
        abrupt.sendall(struct.pack(">HHHBBHH", 1, 0, 6, 1, 3, 0, 1))
        abrupt.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        abrupt.close()
        with client(port) as c:
            for _ in range(5):
                hr(c, 0)
    finally:
        garbage.close()
        half_open.close()
        abrupt.close()
    with client(port) as c:
        hr(c, 0)


# -- lifecycle --------------------------------------------------------------------------


def test_close_twice_leaves_no_thread_or_listener() -> None:
    before = set(threading.enumerate())
    sim = Simulator(time_scale=20.0)
    with sim:
        port = sim.port
        assert sim.running
    sim.close()
    sim.close()
    assert not sim.running
    assert set(threading.enumerate()) <= before
    assert _connect_refused(port)
    with pytest.raises(RuntimeError):
        sim.start()


def test_unknown_options_fail_before_anything_starts() -> None:
    with pytest.raises(ValueError, match="time_scale"):
        Simulator(time_scale=0)
    with pytest.raises(ValueError, match="unknown robot model"):
        Simulator(robot=RobotSetup(model="tm99"))


def test_objects_and_pose_are_visible(article_simulator: Simulator) -> None:
    names = [o.name for o in article_simulator.objects()]
    assert names == ["part"]
    assert article_simulator.tcp_pose().z == pytest.approx(300.0)


# -- the command line -------------------------------------------------------------------


def test_the_cli_banner_lists_faults_sigusr1_resets_an_error_and_sigint_exits_0() -> None:
    # One process for the command line's whole life: its banner (the armed fault), the
    # operator's reset (SIGUSR1), --trace-requests on stdout, --log-json on stderr, the
    # stop on SIGINT with exit 0 (SIGTERM, the other stop signal: test_hostile_programs
    # ends a simulator process with it), and two Ctrl-Cs while Python runs the exit hooks
    # (the test hook pauses there; for the commands without a process test of their own,
    # after --help: test_sigint_exit), which change nothing.
    src = Path(__file__).resolve().parents[1] / "src"
    env = {**os.environ, "PYTHONPATH": f"{src}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    env.update(PAUSE_AT_EXIT)
    proc = subprocess.Popen(
        [
            *(sys.executable, "-m", "tmmaster.sim", "--port", "0", "--time-scale", "10"),
            *("--profile", "article", "--fault", "estop:after_s=0.5"),
            *("--trace-requests", "--log-json"),
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        assert proc.stdout is not None
        banner = [proc.stdout.readline() for _ in range(5)]
        assert "modbus tcp 127.0.0.1:" in banner[0], banner
        port = int(banner[0].split()[3].rsplit(":", 1)[1])
        assert banner[2].startswith("physics kinematic")
        assert banner[3].strip() == "fault   armed: estop:after_s=0.5"
        assert f"kill -USR1 {proc.pid}" in banner[4]
        with ModbusTransport("127.0.0.1", port) as link:
            deadline = time.monotonic() + 10
            while link.read_block(Table.HOLDING, 3, 1) != [0x0200]:  # e-stop fired
                assert time.monotonic() < deadline
                time.sleep(0.05)
            proc.send_signal(signal.SIGUSR1)
            while link.read_block(Table.HOLDING, 3, 1) != [0]:  # the operator's reset
                assert time.monotonic() < deadline
                time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        err, out, after_the_pause = ctrl_c_in_the_exit_hooks(proc, timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert err.endswith(PAUSED_AT_EXIT), err + after_the_pause
    assert after_the_pause == ""  # no "Exception ignored in atexit callback", no traceback
    assert proc.returncode == 0
    assert '"function_code":3' in out  # --trace-requests: the requests on stdout
    assert "robot error reset (SIGUSR1)" in out
    assert "simulator stopped" in out
    # --log-json: the simulator's events, one JSON object per line on stderr.
    events = [
        json.loads(line) for line in err.removesuffix(PAUSED_AT_EXIT).splitlines() if line.strip()
    ]
    assert any(e["event"] == "sim.initialised" for e in events), err


def test_a_taken_port_is_one_line_and_exit_1(capsys: pytest.CaptureFixture[str]) -> None:
    # main() in-process: the entry point itself runs as a process in the tests around.
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        code = sim_main(["--port", str(port)])
    assert code == 1
    assert capsys.readouterr().err.strip().splitlines() == [
        f"sim: cannot listen on 127.0.0.1:{port} (port in use, or not an address of this"
        " machine) [exit 1]"
    ]
