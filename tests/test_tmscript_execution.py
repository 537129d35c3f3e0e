"""Stepping, blocking on the host's clock, closestop/errorstop, host calls, bad input, CLI."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pytest

from tmmaster import TMScriptSyntaxError
from tmmaster._cli import main as tmmaster_main
from tmmaster.tmscript import ExecState, Execution, ModbusDevice, MotionCall, parse
from tmmaster.tmscript.__main__ import main as cli_main


class FakeHost:
    """A host with a hand-driven clock that records what the script asks for."""

    def __init__(self) -> None:
        self.t = 0.0
        self.shown: list[str] = []
        self.requests: list[tuple[int, int, int, list[int] | None]] = []
        self.devices: list[ModbusDevice] = []
        self.registers: dict[int, int] = {}
        self.motions: list[MotionCall] = []
        self.tags: dict[int, bool] = {}
        self.paused = 0
        #: Until this host time, a Modbus request waits (a slow link).
        self.link_busy_until = 0.0

    def now_s(self) -> float:
        return self.t

    def display(self, text: str) -> None:
        self.shown.append(text)

    def modbus_ready(self, device: ModbusDevice) -> bool:
        return self.t >= self.link_busy_until

    def modbus_request(
        self,
        device: ModbusDevice,
        function: int,
        address: int,
        count: int,
        values: Sequence[int] | None,
    ) -> list[int]:
        self.devices.append(device)
        self.requests.append((function, address, count, None if values is None else list(values)))
        if values is not None:
            for i, v in enumerate(values):
                self.registers[address + i] = v
            return []
        return [self.registers.get(address + i, 0) for i in range(count)]

    def motion(self, call: MotionCall) -> bool:
        self.motions.append(call)
        return True

    def queue_tag(self, tag: int, wait: int) -> None:
        self.tags[tag] = False

    def queue_tag_done(self, tag: int) -> bool | None:
        return self.tags.get(tag)

    def stop_and_clear_buffer(self) -> None:
        self.tags.clear()

    def change_base(self, value: str | Sequence[float]) -> None:
        pass

    def change_tcp(
        self,
        value: str | Sequence[float],
        mass: float | None = None,
        inertia: Sequence[float] | None = None,
    ) -> None:
        pass

    def inversekin(
        self, pose: Sequence[float], reference: Sequence[float] | None = None
    ) -> list[float]:
        return [0.0, 0.0, 90.0, 0.0, 90.0, 0.0]

    def forwardkin(self, joints: Sequence[float]) -> list[float]:
        return [663.9, -181.8, 666.35, 180.0, 0.0, 90.0]

    def pause(self) -> None:
        self.paused += 1


def start(text: str) -> tuple[Execution, FakeHost]:
    host = FakeHost()
    return Execution(parse(text), host), host


def test_while_true_yields_on_the_budget_and_resumes() -> None:
    ex, _ = start("main\n{\nint i = 0\nwhile (true)\n{\ni++\n}\n}\n")
    for _ in range(3):
        assert ex.step(100).state == ExecState.RUNNING
    assert ex.stop() == ExecState.ENDED


def test_sleep_blocks_on_the_host_clock() -> None:
    ex, host = start('main\n{\nDisplay("a")\nSleep(500)\nDisplay("b")\n}\n')
    assert ex.step(100).state == ExecState.BLOCKED
    assert host.shown == ["a"]
    host.t = 0.499
    assert ex.step(100).state == ExecState.BLOCKED
    host.t = 0.5
    assert ex.step(100).state == ExecState.ENDED
    assert host.shown == ["a", "b"]


def test_waitfor_in_an_expression_reevaluates_its_condition() -> None:
    # TMscript 2.24 §5.4, p. 158: bool flag = WaitFor(i++ > 100, 1000)
    ex, host = start("main\n{\nint i = 0\nbool flag = WaitFor(i++ > 3, 1000)\nDisplay(flag)\n"
                     "if (WaitFor(false, 200))\n{\nDisplay(1)\n}\nDisplay(i)\n}\n")  # fmt: skip
    while ex.step(100).state == ExecState.BLOCKED and not host.shown:
        pass
    assert host.shown == ["true"]
    assert ex.step(100).state == ExecState.BLOCKED
    host.t = 0.2
    assert ex.step(100).state == ExecState.ENDED
    assert host.shown == ["true", "5"]


def test_a_literal_is_converted_where_the_script_reaches_it() -> None:
    # A literal given where another type is wanted (an assignment, an argument, an index)
    # is converted as any value is; one that cannot be is an error only once reached.
    # (A constant out of a byte's range is refused (§2.2, p. 15); a calculation is not.)
    lines = ["main", "{", "int[] a = {5, 6, 7}", "byte b = 0 + 1000", "Display(b)",
             "Display(a[2])", 'Display(a["1"])', "Display(Byte_ToInt16({1, 2}, 1))",
             "int n = 0", "if (n > 0)", "{", 'Display(a["x"])', "}",
             "Display(n)", 'Display(a["x"])', "Display(n)", "}"]  # fmt: skip
    ex, host = start("\n".join(lines) + "\n")
    status = ex.step(100)
    assert host.shown == ["232", "7", "6", "258", "0"]
    assert status.state == ExecState.ERROR
    assert status.error is not None
    assert status.error.line == 15
    assert '"x"' in str(status.error)


def test_closestop_runs_on_stop_and_on_normal_end() -> None:
    text = (
        'main\n{\nSleep(1000)\n}\nclosestop\n{\nDisplay("closed")\n}\n'
        'errorstop\n{\nDisplay("e")\n}\n'
    )
    ex, host = start(text)
    ex.step(10)
    assert ex.stop() == ExecState.ENDED
    assert host.shown == ["closed"]
    ex, host = start(text.replace("Sleep(1000)", "int a = 1"))
    assert ex.step(100).state == ExecState.ENDED
    assert host.shown == ["closed"]


def test_errorstop_runs_on_an_error_and_an_error_in_it_ends_the_project() -> None:
    # TMscript 2.24 §3.4, p. 31.
    text = (
        'main\n{\nint zero = 0\nint k = 100 / zero\n}\nclosestop\n{\nDisplay("c")\n}\n'
        'errorstop\n{\nDisplay("errorstop")\nint k = 100 / (byte)"0.1"\nDisplay("never")\n}\n'
    )
    ex, host = start(text)
    status = ex.step(100)
    assert status.state == ExecState.ERROR
    assert status.error is not None
    assert (status.error.line, status.error.column) == (4, 13)
    assert host.shown == ["errorstop"]


def test_an_error_in_closestop_ends_the_project_directly() -> None:
    # TMscript 2.24 §3.3, p. 30.
    text = ('main\n{\nExit()\n}\nclosestop\n{\nint zero = 0\nint k = 100 / zero\n'
            'Display("closestop")\n}\nerrorstop\n{\nDisplay("e")\n}\n')  # fmt: skip
    ex, host = start(text)
    assert ex.step(100).state == ExecState.ERROR
    assert host.shown == []


def test_exit_codes() -> None:
    # TMscript 2.24 §5.1, p. 155: < 0 errorstop, > 0 closestop.
    text = 'main\n{\nExit(-1)\n}\nclosestop\n{\nDisplay("c")\n}\nerrorstop\n{\nDisplay("e")\n}\n'
    ex, host = start(text)
    ex.step(100)
    assert host.shown == ["e"]
    assert ex.exit_code == -1
    ex, host = start(text.replace("Exit(-1)", "Exit(false, 1)"))
    ex.step(100)
    assert host.shown == ["c"]


def test_fail_runs_errorstop() -> None:
    ex, host = start('main\n{\nSleep(1000)\n}\nerrorstop\n{\nDisplay("e")\n}\n')
    ex.step(10)
    assert ex.fail("emergency stop") == ExecState.ERROR
    assert host.shown == ["e"]


def test_pause_waits_for_resume() -> None:
    ex, host = start('main\n{\nPause()\nDisplay("after")\n}\n')
    assert ex.step(100).state == ExecState.PAUSED
    assert host.paused == 1
    assert ex.step(100).state == ExecState.PAUSED
    ex.resume()
    assert ex.step(100).state == ExecState.ENDED
    assert host.shown == ["after"]


MODBUS = 'define\n{\nModbusTCP dev = "127.0.0.1", 502\n}\nmain\n{\n%s\n}\n'


def test_modbus_reads_use_the_right_function_address_and_word_order() -> None:
    ex, host = start(
        MODBUS
        % (
            'int[] a = modbus_read_int16("dev", 1, "RI", 7001, 2)\n'
            'int[] b = modbus_read_int32("dev", 1, "RO", 9000, 2)\n'
            'int[] c = modbus_read_int32("dev", 1, "RO", 9000, 2, 0)\n'
            'float[] f = modbus_read_float("dev", 2, "RO", 9002, 2)\n'
            "Display(a)\nDisplay(b)\nDisplay(c)\nDisplay(f)"
        )
    )
    host.registers = {7001: 0x2930, 7002: 0x9F4C, 9000: 0x0001, 9001: 0x0002}
    host.registers.update({9002: 0xC39D, 9003: 0x1375})  # 0xC39D1375 read as AB CD: a float
    assert ex.step(100).state == ExecState.ENDED
    assert [r[:3] for r in host.requests] == [
        (4, 7001, 2),
        (3, 9000, 2),
        (3, 9000, 2),
        (3, 9002, 2),
    ]
    assert host.devices[0] == ModbusDevice("dev", "127.0.0.1", 502, 1, 10000)
    assert host.devices[3].unit == 2
    # §16.6 p. 427: {0x29,0x30,0x9F,0x4C} -> {10544,-24756}; §16.7: AB CD vs CD AB.
    assert host.shown == ["{10544,-24756}", "{65538}", "{131073}", "{-314.152}"]


def test_modbus_write_and_preset() -> None:
    ex, host = start(
        MODBUS
        % (
            'dev.Preset("preset_9000", 1, "RO", 9000, "int32")\n'
            'modbus_write("dev", 0, "RO", 9000, 10000)\n'
            'int v = modbus_read("dev", "preset_9000")\nDisplay(v)\n'
            'modbus_write("dev", 0, "DO", 800, true)\n'
            'byte[] bb = {10, 0, 30}\nmodbus_write("dev", 0, "DO", 800, bb)'
        )
    )
    assert ex.step(100).state == ExecState.ENDED
    assert host.requests[0] == (16, 9000, 2, [0x0000, 0x2710])  # Big Endian (§16.11 p. 438)
    assert host.shown == ["10000"]
    assert host.requests[2] == (5, 800, 1, [1])
    assert host.requests[3] == (15, 800, 3, [1, 0, 1])


def test_ptp_and_queue_tags() -> None:
    ex, host = start(
        "main\n{\nfloat[] t = {417.5, -122.3, 343.9, 180, 0, 90}\n"
        'PTP("CPP", t, 10, 200, 0, false)\n'
        'QueueTag(1)\nLine("CAR", t, 100, 200, 50, false)\nint r = WaitQueueTag(1)\nDisplay(r)\n}\n'
    )
    assert ex.step(100).state == ExecState.BLOCKED
    assert host.motions[0] == MotionCall(
        "PTP", "CPP", (417.5, -122.3, 343.9, 180.0, 0.0, 90.0),
        10, 200, 0, False,
    )  # fmt: skip
    assert host.motions[1].kind == "Line"
    assert host.motions[1].format == "CAR"
    assert ex.step(100).state == ExecState.BLOCKED
    host.tags[1] = True
    assert ex.step(100).state == ExecState.ENDED
    assert host.shown == ["1"]


def test_circle_queues_an_arc_through_its_via_point() -> None:
    # TMscript 2.24 §13.12, pp. 343-344: Syntax 1 (arc angle) and Syntax 2 (and rotation).
    ex, host = start(
        "main\n{\nfloat[] p = {417.5, -122.3, 343.9, 180, 0, 90}\n"
        "float[] e = {381.7, 208.74, 343.9, 180, 0, 135}\n"
        'Circle("CAP", p, e, 100, 200, 50, 0, false)\n'
        'Circle("CPP", p, e, 10, 200, 0, 270, 1, false)\n'
        'bool ok = Circle("JPP", p, e, 10, 200, 0, 0, false)\nDisplay(ok)\n}\n'
    )
    assert ex.step(100).state == ExecState.ENDED
    first, second = host.motions
    assert first == MotionCall(
        "Circle", "CAP", (381.7, 208.74, 343.9, 180.0, 0.0, 135.0), 100, 200, 50, False,
        via=(417.5, -122.3, 343.9, 180.0, 0.0, 90.0), arc_angle=0,
    )  # fmt: skip
    assert (second.arc_angle, second.rotation, second.speed) == (270, 1, 10)
    assert host.shown == ["false"]  # "JPP" is no Circle format: rejected, nothing queued


def test_motion_is_refused_in_closestop() -> None:
    with pytest.raises(TMScriptSyntaxError, match="no motion in closestop"):
        parse('closestop\n{\nPTP("JPP", {0,0,90,0,90,0}, 10, 200, 0, false)\n}\n')


@pytest.mark.parametrize(
    ("text", "line", "column"),
    [
        ("main\n{\n  int a = = 1\n}\n", 3, 11),
        ('main\n{\n  Display("x"\n}\n', 4, 1),
        ("main\n{\n  x = 1 @ 2\n}\n", 3, 9),
        ('main\n{\n  Display123("wrong")\n}\n', 3, 3),
        ("main\n{\n  ThreadExit(1)\n}\n", 3, 3),
        ('main\n{\n  int a = 1 + "x" * 2\n}\n', 3, 19),
    ],
)
def test_bad_scripts_name_line_and_column(text: str, line: int, column: int) -> None:
    with pytest.raises(TMScriptSyntaxError) as info:
        parse(text)
    assert (info.value.line, info.value.column) == (line, column)
    assert f"line {line}, column {column}" in str(info.value)


def test_unknown_function_is_named() -> None:
    with pytest.raises(TMScriptSyntaxError, match=r"unknown function Display123\(\)"):
        parse('main\n{\nDisplay123("wrong")\n}\n')
    with pytest.raises(TMScriptSyntaxError, match=r"ThreadExit\(\) is not supported"):
        parse("main\n{\nThreadExit(1)\n}\n")


def test_cli_check_eval_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    good = tmp_path / "good.tms"
    good.write_text('main\n{\nDisplay("Hello")\nDisplay(10 / 3.0)\n}\n', encoding="utf-8")
    bad = tmp_path / "bad.tms"
    bad.write_text("main\n{\n  Display123(1)\n}\n", encoding="utf-8")
    moves = tmp_path / "moves.tms"
    moves.write_text('main\n{\nPTP("JPP", {0,0,90,0,90,0}, 10, 200, 0, false)\n}\n', "utf-8")
    fails = tmp_path / "fails.tms"
    fails.write_text("main\n{\nint zero = 0\nint k = 100 / zero\n}\n", encoding="utf-8")
    assert cli_main(["check", str(good)]) == 0
    assert capsys.readouterr().out == f"{good}: OK\n"
    assert cli_main(["check", str(bad)]) == 2
    assert capsys.readouterr().err.startswith(f"{bad}:3:3: unknown function Display123()")
    assert cli_main(["eval", "{1.5, 2} "]) == 0
    assert capsys.readouterr().out == "{1.5,2}\n"
    assert cli_main(["eval", "(string)true + 10 / 3.0"]) == 0
    assert capsys.readouterr().out == "true3.333333\n"
    assert cli_main(["run", str(good)]) == 0
    assert capsys.readouterr().out == "Hello\n3.333333\n"
    assert cli_main(["run", str(moves)]) == 2
    assert "PTP" in capsys.readouterr().err
    assert cli_main(["run", str(fails)]) == 1
    assert capsys.readouterr().err.startswith(f"{fails}:4:13: division by zero")


def test_the_tmmaster_command_runs_a_script(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # ``tmmaster tmscript`` is the same main(); ``python -m tmmaster`` itself runs as a
    # process in test_public_api.py and test_bad_input.py (a process costs over a second
    # of CPU importing the whole command line).
    script = tmp_path / "s.tms"
    script.write_text('main\n{\nDisplay("hi")\n}\n', encoding="utf-8")
    assert tmmaster_main(["tmscript", "run", str(script)]) == 0
    assert capsys.readouterr().out == "hi\n"
