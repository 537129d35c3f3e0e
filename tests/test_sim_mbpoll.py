"""A third-party Modbus master (mbpoll) against the simulator: status read, move, done."""

from __future__ import annotations

import re
import shutil
import subprocess
from collections.abc import Callable

import pytest

from tmmaster._pose import Pose
from tmmaster.sim import Simulator

MBPOLL = shutil.which("mbpoll")


def mbpoll(port: int, *options: str, values: tuple[int, ...] = ()) -> str:
    """Run mbpoll once against the simulator (0-based addresses, holding registers)."""
    if MBPOLL is None:
        pytest.skip("mbpoll not installed: apt-get install mbpoll")
    result = subprocess.run(
        [MBPOLL, "-m", "tcp", "-a", "1", "-0", "-t", "4", "-p", str(port), *options, "127.0.0.1"]
        + [str(v) for v in values],
        capture_output=True,
        text=True,
        timeout=10,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return result.stdout


def registers(output: str) -> dict[int, int]:
    """The ``[address]: value`` lines of an mbpoll read."""
    return {int(a): int(v) for a, v in re.findall(r"^\[(\d+)\]:\s+(\d+)", output, re.MULTILINE)}


def test_mbpoll_reads_status_writes_a_move_and_sees_it_complete(
    tm_simulator_factory: Callable[..., Simulator],
) -> None:
    sim = tm_simulator_factory("article")  # its registers are the ones written below
    port = sim.port
    sim.wait_for(lambda: registers(mbpoll(port, "-r", "0", "-c", "4", "-1"))[0] == 5, 5.0)
    # FC16 of target (int16 x100; -200 mm as its two's complement 45536), speed, command.
    out = mbpoll(port, "-r", "512", values=(30000, 45536, 20000, 18000, 0, 9000, 50, 1))
    assert "Written 8 references" in out
    writes = [r for r in sim.request_log if r.is_write]
    assert [(r.function_code, r.address, r.count) for r in writes] == [(16, 512, 8)]
    sim.wait_for(lambda: registers(mbpoll(port, "-r", "519", "-1"))[519] == 0, 5.0)  # taken
    sim.wait_for(lambda: registers(mbpoll(port, "-r", "1", "-1"))[1] == 0, 5.0)  # idle again
    pose = registers(mbpoll(port, "-r", "16", "-c", "6", "-1"))
    assert [pose[a] for a in range(16, 22)] == [30000, 45536, 20000, 18000, 0, 9000]
    assert sim.tcp_pose().is_close(Pose(300.0, -200.0, 200.0, 180.0, 0.0, 90.0))
