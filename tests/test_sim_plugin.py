"""The simulator is a plugin of the core: the core never loads it, and it serves ``sim://``.

Importing the SDK, the command lines and the report loads no ``tmmaster.sim`` module
(a run against a real robot pays nothing for the simulator); ``tmmaster.sim`` registers
the ``sim`` scheme in the core's registry of in-process transports when it is imported,
and a ``sim://`` host used before that is a ConfigError that says how to start one.
Each check of what a fresh process loads runs in a subprocess of its own.
"""

from __future__ import annotations

import json
import subprocess
import sys
from typing import Any

import pytest

import tmmaster.sim  # noqa: F401  serves sim:// (the simulator is a plugin of the core)
from tmmaster import ConfigError, ConnectError, Robot
from tmmaster._address import check_host, register_scheme


def _run(code: str) -> Any:
    """Run ``code`` in a fresh interpreter; what it prints last, as JSON."""
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.splitlines()[-1])


def test_the_sdk_the_commands_the_report_and_a_real_robot_run_load_no_simulator() -> None:
    # A pick & place run for a real robot (--dry-run: checked, not connected) too.
    loaded = _run(
        "import contextlib, io, json, sys\n"
        "import tmmaster, tmmaster.aio, tmmaster.report, tmmaster._cli, tmmaster._robot_cli\n"
        "from tmmaster import Fleet, Robot, StatusMonitor, connect\n"
        "from tmmaster.pickplace.__main__ import main\n"
        "before = sorted(m for m in sys.modules if m.startswith('tmmaster.sim'))\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    code = main(['--dry-run', '--quiet'])\n"
        "after = sorted(m for m in sys.modules if m.startswith('tmmaster.sim'))\n"
        "print(json.dumps([before, code, after]))\n"
    )
    assert loaded == [[], 0, []]


def test_a_sim_host_before_the_simulator_is_imported_says_how_to_start_one() -> None:
    said = _run(
        "import asyncio, json, sys\n"
        "import tmmaster\n"
        "from tmmaster import aio\n"
        "out = []\n"
        "for attempt in (lambda: tmmaster.Robot('sim://cell-9'),\n"
        "                lambda: tmmaster.connect('sim://cell-9'),\n"
        "                lambda: aio.connect('sim://cell-9')):\n"
        "    try:\n"
        "        attempt()\n"
        "    except tmmaster.ConfigError as exc:\n"
        "        out.append(str(exc))\n"
        "out.append(sorted(m for m in sys.modules if m.startswith('tmmaster.sim')))\n"
        "print(json.dumps(out))\n"
    )
    *messages, loaded = said
    assert len(messages) == 3
    for message in messages:
        assert message.startswith("host: ")
        assert "no in-process simulator named 'cell-9'" in message
        assert "tmmaster.sim.Simulator(" in message
    assert loaded == []  # said without loading the simulator


def test_the_simulator_serves_sim_once_imported_and_names_a_missing_one() -> None:
    assert check_host("sim://cell-9") == "sim://cell-9"
    with pytest.raises(ConnectError, match="no simulator named 'cell-9'"):
        Robot("sim://cell-9", profile="article")
    # The scheme is the simulator's: a second opener for it is refused.
    with pytest.raises(ConfigError, match="sim://"):
        register_scheme("sim", lambda url, **options: None)
    with pytest.raises(ConfigError, match="not a plain name"):
        register_scheme("a b", lambda url, **options: None)


def test_any_plugin_registers_a_scheme_the_core_opens_through_it() -> None:
    # The core knows no scheme of its own: a plugin's opener gets the URL and the link's
    # options; a host of its scheme has no port.
    asked = _run(
        "import json\n"
        "from tmmaster import ConnectError, Robot\n"
        "from tmmaster._address import check_host, register_scheme\n"
        "asked = []\n"
        "def opener(url, **options):\n"
        "    asked.append([url, options['role'], options['name']])\n"
        "    raise ConnectError(f'{url}: nothing runs')\n"
        "register_scheme('bench', opener)\n"
        "try:\n"
        "    Robot('bench://one', port=None, name='r1')\n"
        "except ConnectError as exc:\n"
        "    asked.append(str(exc))\n"
        "print(json.dumps([check_host('bench://one'), *asked]))\n"
    )
    assert asked == ["bench://one", ["bench://one", "robot", "r1"], "bench://one: nothing runs"]


#: The commands other than ``sim``, as ``tmmaster`` arguments.
OTHER_COMMANDS = [
    ["robot", "--help"],
    ["profile", "list"],
    ["pickplace", "--dry-run", "--quiet"],
    ["report", "--help"],
    ["tmscript", "--help"],
    ["--help"],
]


def test_a_tmmaster_command_other_than_sim_loads_no_simulator() -> None:
    # Each command's options load only when it is chosen: the sim command's need the
    # simulator, the others' do not (the top-level help lists every command anyway).
    # One fresh process runs them one after the other and lists what is loaded after
    # each: a module once loaded stays in sys.modules, so the first command to load the
    # simulator is the one named.
    loaded = _run(
        "import contextlib, io, json, sys\n"
        "from tmmaster._cli import main\n"
        "after = {}\n"
        f"for argv in {OTHER_COMMANDS!r}:\n"
        "    with contextlib.redirect_stdout(io.StringIO()):\n"
        "        try:\n"
        "            main(argv)\n"
        "        except SystemExit:  # --help\n"
        "            pass\n"
        "    sim = sorted(m for m in sys.modules if m.startswith('tmmaster.sim'))\n"
        "    after[' '.join(argv)] = sim\n"
        "print(json.dumps(after))\n"
    )
    assert loaded == {" ".join(argv): [] for argv in OTHER_COMMANDS}
