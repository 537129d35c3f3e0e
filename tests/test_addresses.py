"""Hosts, ports and failed connections: refused before any I/O, said as what happened.

A host with a port or a URL is a ConfigError naming the field, before a socket is
opened (library and pick & place CLI); a name that does not resolve is "cannot resolve
host"; a first connection refused fails at once, while a refused reconnect (a server
restarting) is still retried. No test reaches past the loopback: name resolution is
replaced where a test needs it to fail.
"""

from __future__ import annotations

import socket
import time
from pathlib import Path
from typing import Any

import pytest

import tmmaster
import tmmaster.sim  # serves sim:// hosts (the simulator is a plugin of the core)
from modbus_test_server import TestServer, free_port
from tmmaster import (
    ConfigError,
    ConnectError,
    ConnectRefusedError,
    Fleet,
    GripperDevice,
    HostNotFoundError,
    ModbusTransport,
    RetryPolicy,
    Robot,
    Table,
)
from tmmaster._address import check_host, check_port
from tmmaster._retry import is_transient
from tmmaster.pickplace import load_config
from tmmaster.pickplace.__main__ import EXIT_CONFIG, EXIT_CONNECTION, main

#: The pick & place default policy (5 attempts in 10 s) would take seconds on an outage.
PATIENT = RetryPolicy(attempts=12, total_time_s=10.0)


@pytest.fixture
def no_io(monkeypatch: pytest.MonkeyPatch) -> None:
    """Any name look-up or connection attempt fails the test."""

    def tripwire(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError(f"I/O attempted: {args!r}")

    monkeypatch.setattr(socket, "getaddrinfo", tripwire)
    monkeypatch.setattr(socket, "create_connection", tripwire)


@pytest.fixture
def unresolvable(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Names under ``.invalid`` fail to resolve at once, as a resolver says it (EAI_NONAME)."""
    asked: list[str] = []
    real = socket.getaddrinfo

    def getaddrinfo(host: Any, *args: Any, **kwargs: Any) -> Any:
        if isinstance(host, str) and host.endswith(".invalid"):
            asked.append(host)
            raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")
        return real(host, *args, **kwargs)

    monkeypatch.setattr(socket, "getaddrinfo", getaddrinfo)
    return asked


# -- the host, before any I/O ------------------------------------------------------


@pytest.mark.parametrize(
    ("host", "expected"),
    [
        ("192.168.1.100", "192.168.1.100"),
        ("robot-3.local", "robot-3.local"),
        ("robot_3", "robot_3"),
        ("localhost", "localhost"),
        ("::1", "::1"),
        ("[::1]", "::1"),  # as in a URL: taken without its brackets
        ("fe80::1%eth0", "fe80::1%eth0"),
        ("sim://cell-1", "sim://cell-1"),
    ],
)
def test_addresses_and_names_are_taken(host: str, expected: str) -> None:
    assert check_host(host) == expected


@pytest.mark.parametrize(
    ("host", "says"),
    [
        ("192.168.1.100:502", "'192.168.1.100:502' includes a port; put the port in port"),
        ("robot.local:5020", "includes a port; put the port in port"),
        ("[::1]:502", "'[::1]:502' includes a port"),
        ("http://192.168.1.100:502", "is a URL; give the address alone ('192.168.1.100')"),
        ("modbus://robot.local", "is a URL; give the address alone ('robot.local')"),
        ("tcp://[::1]:5020/", "('::1') and the port in port (5020)"),
        ("192.168.1", "'192.168.1' is not a valid IPv4 address"),  # would be 192.168.0.1
        ("192.168.1.300", "is not a valid IPv4 address"),
        ("192.168.1.100/24", "'/' is not allowed"),
        (" 192.168.1.100", "contains a space"),
        ("", "empty"),
        ("1::2::3", "is not a valid IPv6 address"),
        ("robot..local", "an empty part"),
        ("r" * 64 + ".local", "at most 63 characters"),
    ],
)
def test_what_is_no_address_is_refused_naming_field_and_value(host: str, says: str) -> None:
    with pytest.raises(ConfigError) as info:
        check_host(host)
    assert str(info.value).startswith("host: ")
    assert says in str(info.value)
    assert "sim://" not in str(info.value)


def test_a_host_that_is_not_text_and_bad_ports_are_refused() -> None:
    with pytest.raises(ConfigError, match=r"^host: not a string"):
        check_host(None)
    for port in (0, 65536, -1):
        with pytest.raises(ConfigError, match=r"^port: .* is not a TCP port"):
            check_port(port)
    for port in (True, "502", 502.0):
        with pytest.raises(ConfigError, match=r"^port: not an integer"):
            check_port(port)
    assert check_port(502) == 502


def test_robot_and_connect_refuse_a_port_in_the_host_before_any_io(no_io: None) -> None:
    with pytest.raises(ConfigError) as info:
        tmmaster.connect("192.168.1.100:502", profile="article")
    assert str(info.value) == "host: '192.168.1.100:502' includes a port; put the port in port"
    with pytest.raises(ConfigError, match=r"^host: 'http://192\.0\.2\.1:502' is a URL"):
        Robot("http://192.0.2.1:502")
    with pytest.raises(ConfigError, match=r"^gripper\.host: .* put the port in gripper\.port"):
        Robot("127.0.0.1", gripper=GripperDevice("blog-2fg7", host="127.0.0.1:5021"))
    with pytest.raises(ConfigError, match=r"^port: 70000 is not a TCP port"):
        Robot("127.0.0.1", 70000)
    with pytest.raises(ConfigError, match=r"^host: "):
        ModbusTransport("https://robot.local")
    with pytest.raises(ConfigError, match=r"^host: "):
        tmmaster.StatusMonitor().add("r1", "192.168.1.100:502")


def test_a_fleet_robot_refuses_a_port_in_the_host_before_any_io(no_io: None) -> None:
    fleet = Fleet()
    try:
        with pytest.raises(ConfigError, match=r"^host: .* includes a port"):
            Robot("10.0.0.7:502", profile="article", gripper=None, link=fleet)
    finally:
        fleet.close()


def test_an_ipv6_literal_in_brackets_connects_to_the_address() -> None:
    try:
        listener = socket.socket(socket.AF_INET6)
        listener.bind(("::1", 0))
    except OSError:
        pytest.skip("no IPv6 loopback here")
    with listener:
        listener.listen(1)
        port = listener.getsockname()[1]
        link = ModbusTransport("[::1]", port, retry=PATIENT)
        assert link.host == "::1"
        link.connect()  # a listener: the connection is accepted by the kernel
        link.close()


# -- what a failed connection says, and how long it takes -------------------------------


def test_a_refused_first_connection_fails_at_once() -> None:
    port = free_port()
    link = ModbusTransport("127.0.0.1", port, retry=PATIENT)
    started = time.monotonic()
    with pytest.raises(ConnectRefusedError) as info:
        link.connect()
    assert time.monotonic() - started < 3.0  # 12 attempts within 10 s otherwise
    assert link.stats.retries == 0
    assert isinstance(info.value, ConnectionRefusedError)  # the builtin, too
    assert info.value.retryable is False
    assert f"127.0.0.1:{port} refused the connection" in str(info.value)
    link.close()


def test_a_robot_to_a_port_nobody_listens_on_fails_at_once() -> None:
    started = time.monotonic()
    with pytest.raises(ConnectRefusedError):
        tmmaster.connect("127.0.0.1", free_port(), profile="article", retry=PATIENT)
    assert time.monotonic() - started < 3.0


def test_a_refused_reconnect_is_an_outage_and_is_retried() -> None:
    server = TestServer().start()
    policy = RetryPolicy(attempts=3, total_time_s=5.0, initial_backoff_s=0.01, max_backoff_s=0.02)
    link = ModbusTransport("127.0.0.1", server.port, timeout=0.5, retry=policy)
    try:
        link.connect()
        link.read_block(Table.HOLDING, 0, 1)
        server.stop()  # the server goes: the link is lost, then every reconnect refused
        with pytest.raises(ConnectError) as info:
            link.read_block(Table.HOLDING, 0, 1)
        assert link.stats.retries == 2  # every attempt the policy allows
        assert isinstance(info.value, ConnectRefusedError)
        assert info.value.retryable is True
    finally:
        link.close()
        server.stop()


def test_a_name_that_does_not_resolve_is_said_as_such_at_once(unresolvable: list[str]) -> None:
    link = ModbusTransport("robot.invalid", 502, retry=PATIENT)
    started = time.monotonic()
    with pytest.raises(HostNotFoundError) as info:
        link.connect()
    assert time.monotonic() - started < 3.0
    assert unresolvable == ["robot.invalid"]  # asked once: no retry
    assert str(info.value).startswith("cannot resolve host 'robot.invalid'")
    assert "Name or service not known" in str(info.value)
    assert isinstance(info.value, ConnectError)
    link.close()


def test_a_fleet_robot_says_the_same(unresolvable: list[str]) -> None:
    fleet = Fleet()
    try:
        robot = Robot("robot.invalid", profile="article", gripper=None, retry=PATIENT, link=fleet)
        with pytest.raises(HostNotFoundError, match=r"cannot resolve host 'robot\.invalid'"):
            robot.connect()
        assert robot.stats.retries == 0
        robot = Robot("127.0.0.1", free_port(), profile="article", gripper=None, link=fleet)
        with pytest.raises(ConnectRefusedError):
            robot.connect()
        assert robot.stats.retries == 0
    finally:
        fleet.close()


def test_the_retry_policy_never_retries_what_cannot_succeed() -> None:
    refused = ConnectRefusedError("refused")
    assert is_transient(refused)  # a reconnect's: an outage
    refused.retryable = False
    assert not is_transient(refused)
    assert not is_transient(tmmaster.TransportClosedError("closed"))
    calls: list[int] = []

    def fail() -> None:
        calls.append(1)
        raise refused

    with pytest.raises(ConnectRefusedError):
        PATIENT.call("connect", fail)
    assert calls == [1]


# -- the pick & place command and its configuration --------------------------------------


def _last_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines, "nothing on stderr"
    return lines[-1]


@pytest.mark.parametrize("quiet", [[], ["--quiet"]])
def test_pickplace_refuses_a_port_in_host_before_any_io(
    no_io: None, quiet: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["--host", "192.168.1.100:502", *quiet]) == EXIT_CONFIG
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert _last_line(err) == (
        "pickplace: config error: --host: '192.168.1.100:502' includes a port;"
        " put the port in --port [exit 2]"
    )


@pytest.mark.parametrize("quiet", [[], ["--quiet"]])
def test_pickplace_refuses_a_url_and_never_says_sim(
    no_io: None, quiet: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["--host", "http://192.168.1.100:502", *quiet]) == EXIT_CONFIG
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "--host: 'http://192.168.1.100:502' is a URL" in err
    assert "and the port in --port (502)" in err
    assert "sim" not in err
    assert "in-process" not in err


def test_a_config_files_host_is_checked_naming_the_key(no_io: None, tmp_path: Path) -> None:
    config = tmp_path / "cell.toml"
    config.write_text('[robot]\nhost = "192.168.1.100:502"\n')
    with pytest.raises(ConfigError) as info:
        load_config(config)
    assert str(info.value) == (
        f"{config}: robot.host: '192.168.1.100:502' includes a port; put the port in robot.port"
    )
    config.write_text('[gripper]\nhost = "http://10.0.0.9"\n')
    with pytest.raises(ConfigError, match=r"gripper\.host: 'http://10\.0\.0\.9' is a URL"):
        load_config(config)
    config.write_text('[robot]\nhost = "[::1]"\n')
    assert load_config(config).robot.host == "::1"


def test_pickplace_says_a_name_does_not_resolve(
    unresolvable: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report = tmp_path / "r.json"
    code = main(["--host", "robot.invalid", "--profile", "article", "--report", str(report)])
    assert code == EXIT_CONNECTION
    line = _last_line(capsys.readouterr().err)
    assert line.startswith("pickplace: cannot resolve host 'robot.invalid'")
    assert "unreachable" not in line
    assert unresolvable == ["robot.invalid"]


def test_pickplace_says_a_refused_connection_and_does_not_retry(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    port = free_port()
    report = tmp_path / "r.json"
    code = main(["--host", "127.0.0.1", "--port", str(port), "--report", str(report)])
    assert code == EXIT_CONNECTION
    line = _last_line(capsys.readouterr().err)
    assert f"robot at 127.0.0.1:{port} refused the connection" in line
    assert "unreachable" not in line
    assert json.loads(report.read_text())["transport"]["robot"]["retries"] == 0


def test_the_simulators_bind_address_is_checked_too(
    no_io: None, capsys: pytest.CaptureFixture[str]
) -> None:
    from tmmaster.sim.__main__ import main as sim_main

    assert sim_main(["--bind", "127.0.0.1:5020", "--port", "0"]) == 2
    assert _last_line(capsys.readouterr().err) == (
        "sim: --bind: '127.0.0.1:5020' includes a port; put the port in --port [exit 2]"
    )
