"""The TaskSequence sample of docs/pickplace.md, pasted into a script, fails the script
when the run fails: ``Runner.run()`` returns a failure, it never raises one.

test_doc_samples.py runs the sample on a healthy simulator; here the simulator's
e-stop is pressed during the second move, and the sample must end in SystemExit with
a nonzero code naming where and why, and command nothing after the failure.

Found by hunt 29 ("the code users copy"); the test fails without the fix: the sample
printed "ERROR [] Failure(...)" and the script went on to exit 0.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

PAGE = Path(__file__).resolve().parents[1] / "docs" / "pickplace.md"
_BLOCK = re.compile(r"^```python\n(.*?)^```", re.DOTALL | re.MULTILINE)


def sequence_sample(port: int) -> str:
    """The page's TaskSequence sample, its robot on ``port`` of 127.0.0.1."""
    blocks: list[str] = _BLOCK.findall(PAGE.read_text("utf-8"))
    (code,) = [b for b in blocks if 'TaskSequence("my-cell")' in b]
    assert 'Robot("127.0.0.1", 5020)' in code
    return code.replace('Robot("127.0.0.1", 5020)', f'Robot("127.0.0.1", {port})')


def test_a_failed_run_fails_the_script(
    tm_simulator_factory: Factory, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = tm_simulator_factory(faults=["estop:at_move=2"])
    namespace: dict[str, Any] = {}
    with pytest.raises(SystemExit) as exited:
        exec(compile(sequence_sample(sim.port), "pickplace.md", "exec"), namespace)
    assert exited.value.code == "failed in DOWN: " + namespace["result"].failure.message
    assert "emergency stop" in str(exited.value.code)
    assert capsys.readouterr().out.startswith("ERROR")
    # The e-stopped move was the last thing the robot started.
    assert [m.kind for m in sim.motion_log()] == ["ptp", "line"]
