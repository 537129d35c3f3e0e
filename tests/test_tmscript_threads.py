"""Threads (ThreadRun), the project clock (GetNowStamp) and a refused Modbus write.

TMscript 2.24 §3.12 (p. 47): a thread runs a statement beside main; one started with
``ThreadRun(statement, true)`` goes on while the project is paused; motion functions
belong to main. §4.39 (p. 128): GetNowStamp is the project's run time in ms. §16.11
(p. 436): modbus_write returns false when the Modbus communication fails.
"""

from __future__ import annotations

from collections.abc import Sequence

import pytest

from test_tmscript_execution import FakeHost
from tmmaster.tmscript import ExecState, Execution, ModbusDevice, parse
from tmmaster.tmscript._host import ModbusCommunicationError

COUNTER = """
define
{
    int n = 0
}
main
{
    int id = ThreadRun(Count(), %s)
    Display("thread " + id)
    while (true)
    {
        Sleep(1000)
    }
}
void Count()
{
    while (true)
    {
        n = n + 1
        Display("n " + n)
        Sleep(100)
    }
}
"""


def step_for(execution: Execution, host: FakeHost, seconds: float, *, paused: bool = False) -> None:
    for _ in range(round(seconds / 0.05)):
        host.t += 0.05
        if paused:
            execution.step_threads(100)
        else:
            execution.step(100)


def test_a_thread_runs_beside_main() -> None:
    host = FakeHost()
    execution = Execution(parse(COUNTER % "false"), host)
    step_for(execution, host, 0.5)
    assert host.shown[0] == "thread 2"
    assert "n 4" in host.shown


@pytest.mark.parametrize("nonpause", [True, False])
def test_only_a_non_pause_thread_runs_while_the_project_is_paused(nonpause: bool) -> None:
    host = FakeHost()
    execution = Execution(parse(COUNTER % ("true" if nonpause else "false")), host)
    step_for(execution, host, 0.15)
    before = len(host.shown)
    step_for(execution, host, 0.5, paused=True)
    assert (len(host.shown) > before) is nonpause


def test_a_motion_function_in_a_thread_is_an_error_and_exit_in_a_thread_stops_the_project() -> None:
    host = FakeHost()
    moving = parse(
        "main\n{\n    ThreadRun(Go(), true)\n    Sleep(1000)\n}\n"
        'void Go()\n{\n    PTP("CPP", {1, 2, 3, 4, 5, 6}, 10, 200, 0, false)\n}\n'
    )
    execution = Execution(moving, host)
    step_for(execution, host, 0.1)
    assert execution.state is ExecState.ERROR
    assert "main thread" in str(execution.error)
    assert host.motions == []
    stopping = parse(
        "main\n{\n    ThreadRun(Quit(), true)\n"
        "    while (true)\n    {\n        Sleep(10)\n    }\n}\n"
        "void Quit()\n{\n    Sleep(200)\n    Exit(false, 1)\n}\n"
        'closestop\n{\n    Display("closestop")\n}\n'
    )
    host = FakeHost()
    execution = Execution(stopping, host)
    step_for(execution, host, 0.1)
    step_for(execution, host, 0.3, paused=True)
    assert execution.phase != "main"
    step_for(execution, host, 0.1)
    assert execution.state is ExecState.ENDED
    assert host.shown == ["closestop"]
    assert (execution.exit_code, execution.exit_waits) == (1, False)


def test_get_now_stamp_is_the_projects_run_time_in_ms() -> None:
    host = FakeHost()
    host.t = 100.0  # the host's clock is not the project's
    execution = Execution(
        parse('main\n{\n    Sleep(250)\n    Display("" + GetNowStamp())\n}\n'), host
    )
    step_for(execution, host, 0.5)
    # The project started at host time 100.0; the Sleep began at the first step (0.05 s
    # later) and ended at a step 0.25 s after that.
    assert 300 <= int(host.shown[0]) <= 350


class RefusingHost(FakeHost):
    """A slave that answers every write with an exception (no write permission)."""

    def modbus_request(
        self,
        device: ModbusDevice,
        function: int,
        address: int,
        count: int,
        values: Sequence[int] | None,
    ) -> list[int]:
        if values is not None:
            raise ModbusCommunicationError("exception 02")
        return super().modbus_request(device, function, address, count, values)


def test_modbus_write_returns_false_when_the_slave_refuses() -> None:
    host = RefusingHost()
    script = """
define
{
    ModbusTCP dev = "127.0.0.1", 502, 1000
}
main
{
    dev.Preset("p", 1, "RO", 9100, "int16")
    Display("preset " + modbus_write("dev", "p", 7))
    Display("address " + modbus_write("dev", 1, "RO", 9100, 7))
    Display("coil " + modbus_write("dev", 1, "DO", 800, 1))
}
"""
    Execution(parse(script), host).run_to_end(timeout_s=5)
    assert host.shown == ["preset false", "address false", "coil false"]
