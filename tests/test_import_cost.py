"""What ``import tmmaster`` leaves for later: what only a rare path needs.

Every program, test worker and simulator process imports tmmaster: a module or a
validator that only a retry, a robot error or a command line needs is built there.
"""

from __future__ import annotations

import json
import subprocess
import sys

_PROBE = """
import json, sys
import tmmaster
from tmmaster._tm_errors import TMErrorCode, lookup_tm_error
loaded = [m for m in ("argparse", "tenacity", "tmmaster._robot_program") if m in sys.modules]
built = TMErrorCode.__pydantic_complete__
label = lookup_tm_error(0x22).label
print(json.dumps([loaded, built, label, TMErrorCode.__pydantic_complete__]))
"""


def test_import_leaves_the_rare_paths_for_later() -> None:
    out = subprocess.run(
        [sys.executable, "-c", _PROBE], capture_output=True, text=True, check=True, timeout=60
    ).stdout
    loaded, built, label, built_after = json.loads(out)
    # argparse: the command lines; tenacity: a retry after a transient failure; the robot
    # program's generator: `tmmaster robot-program` and the simulator.
    assert loaded == []
    # The error-code table's model is built by the first look-up, which still works.
    assert built is False
    assert label == "0x0022 Force or Torque Over Range"
    assert built_after is True
