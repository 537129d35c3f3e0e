"""The simulator is a plugin of the core: the core never loads it, and it serves ``sim://``.

Importing the SDK, the command lines and the report loads no ``tmmaster.sim`` module
(a run against a real robot pays nothing for the simulator); ``tmmaster.sim`` registers
the ``sim`` scheme in the core's registry of in-process transports when it is imported,
and a ``sim://`` host used before that is a ConfigError that says how to start one.
Importing tmmaster loads neither rich nor matplotlib, nor do the commands load rich or
structlog (logging loads them once it is on). The checks of what a fresh process loads
run in one fresh process, one after the other, in one test (one interpreter start
instead of five; several tests sharing a fixture would each start one under xdist): each
reports what it found and the modules of ``tmmaster.sim`` loaded by then, so the first
check to load the simulator is the one named; the plugin's own scheme is registered last.
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

#: The checks run in one fresh interpreter, in this order: name -> Python source that
#: sets ``found`` (a JSON value). What ``import tmmaster`` loads comes first (nothing has
#: run before it but the driver's json, sys and traceback), then the sim:// host check
#: (it imports tmmaster.aio, as a fresh program would), the plugin's registration last.
FRESH_CHECKS: dict[str, str] = {
    # structlog imports rich when it is installed; tmmaster imports structlog only once
    # logging is on (the first enabled event, or configure_logging), so importing the
    # commands loads neither.
    "rich, matplotlib and structlog": (
        "import tmmaster\n"
        "first = sorted(m for m in ('rich', 'matplotlib') if m in sys.modules)\n"
        "import tmmaster.pickplace.__main__, tmmaster.report.__main__\n"
        "found = [first, 'matplotlib' in sys.modules,\n"
        "         sorted(m for m in ('rich', 'structlog') if m in sys.modules)]\n"
    ),
    "sim host before the simulator": (
        "import asyncio\n"
        "import tmmaster\n"
        "from tmmaster import aio\n"
        "found = []\n"
        "for attempt in (lambda: tmmaster.Robot('sim://cell-9'),\n"
        "                lambda: tmmaster.connect('sim://cell-9'),\n"
        "                lambda: aio.connect('sim://cell-9')):\n"
        "    try:\n"
        "        attempt()\n"
        "    except tmmaster.ConfigError as exc:\n"
        "        found.append(str(exc))\n"
    ),
    # A pick & place run for a real robot (--dry-run: checked, not connected) too.
    "sdk, commands, report and a real run": (
        "import contextlib, io\n"
        "import tmmaster, tmmaster.aio, tmmaster.report, tmmaster._cli, tmmaster._robot_cli\n"
        "from tmmaster import Fleet, Robot, StatusMonitor, connect\n"
        "from tmmaster.pickplace.__main__ import main\n"
        "before = sorted(m for m in sys.modules if m.startswith('tmmaster.sim'))\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    code = main(['--dry-run', '--quiet'])\n"
        "found = [before, code]\n"
    ),
    # Each command's options load only when it is chosen: the sim command's need the
    # simulator, the others' do not (the top-level help lists every command anyway).
    # The commands run one after the other; a module once loaded stays in sys.modules,
    # so the first command to load the simulator is the one named.
    "other commands": (
        "import contextlib, io\n"
        "from tmmaster._cli import main\n"
        "found = {}\n"
        "for argv in OTHER_COMMANDS:\n"
        "    with contextlib.redirect_stdout(io.StringIO()):\n"
        "        try:\n"
        "            main(argv)\n"
        "        except SystemExit:  # --help\n"
        "            pass\n"
        "    sim = sorted(m for m in sys.modules if m.startswith('tmmaster.sim'))\n"
        "    found[' '.join(argv)] = sim\n"
    ),
    # The core knows no scheme of its own: a plugin's opener gets the URL and the link's
    # options; a host of its scheme has no port.
    "a plugin's scheme": (
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
        "found = [check_host('bench://one'), *asked]\n"
    ),
}

#: The commands other than ``sim``, as ``tmmaster`` arguments.
OTHER_COMMANDS = [
    ["robot", "--help"],
    ["profile", "list"],
    ["pickplace", "--dry-run", "--quiet"],
    ["report", "--help"],
    ["tmscript", "--help"],
    ["--help"],
]

_DRIVER = (
    "import json, sys, traceback\n"
    "checks, OTHER_COMMANDS = json.loads(sys.argv[1]), json.loads(sys.argv[2])\n"
    "results = {}\n"
    "for name, code in checks.items():\n"
    "    space = {'sys': sys, 'OTHER_COMMANDS': OTHER_COMMANDS}\n"
    "    try:\n"
    "        exec(code, space)\n"
    "        found = space['found']\n"
    "    except BaseException:\n"
    "        found = {'error': traceback.format_exc()}\n"
    "    sim = sorted(m for m in sys.modules if m.startswith('tmmaster.sim'))\n"
    "    results[name] = [found, sim]\n"
    "print(json.dumps(results))\n"
)


def fresh_process() -> dict[str, Any]:
    """Run ``FRESH_CHECKS`` in one fresh interpreter: name -> [what it found, the
    ``tmmaster.sim`` modules loaded once it ran]."""
    done = subprocess.run(
        [sys.executable, "-c", _DRIVER, json.dumps(FRESH_CHECKS), json.dumps(OTHER_COMMANDS)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    results: dict[str, Any] = json.loads(done.stdout.splitlines()[-1])
    return results


def _found(fresh: dict[str, Any], name: str) -> tuple[Any, list[str]]:
    """What check ``name`` found, and the simulator's modules loaded by then."""
    found, sim = fresh[name]
    assert not (isinstance(found, dict) and "error" in found), found.get("error")
    return found, sim


def test_a_fresh_process_loads_no_simulator_nor_rich_and_opens_a_plugins_scheme() -> None:
    fresh = fresh_process()
    # Importing tmmaster loads neither rich nor matplotlib; the commands neither rich nor
    # structlog.
    (first, matplotlib, commands), loaded = _found(fresh, "rich, matplotlib and structlog")
    assert (first, matplotlib, commands) == ([], False, [])
    assert loaded == []  # nor the simulator
    # A sim:// host before the simulator is imported says how to start one.
    messages, loaded = _found(fresh, "sim host before the simulator")
    assert len(messages) == 3
    for message in messages:
        assert message.startswith("host: ")
        assert "no in-process simulator named 'cell-9'" in message
        assert "tmmaster.sim.Simulator(" in message
    assert loaded == []  # said without loading the simulator
    # The SDK, the command lines, the report and a real robot's run load no simulator.
    (before, code), after = _found(fresh, "sdk, commands, report and a real run")
    assert [before, code, after] == [[], 0, []]
    # Nor does any tmmaster command other than sim.
    loaded, _ = _found(fresh, "other commands")
    assert loaded == {" ".join(argv): [] for argv in OTHER_COMMANDS}
    # Any plugin registers a scheme the core opens through it.
    asked, _ = _found(fresh, "a plugin's scheme")
    assert asked == ["bench://one", ["bench://one", "robot", "r1"], "bench://one: nothing runs"]


def test_the_simulator_serves_sim_once_imported_and_names_a_missing_one() -> None:
    assert check_host("sim://cell-9") == "sim://cell-9"
    with pytest.raises(ConnectError, match="no simulator named 'cell-9'"):
        Robot("sim://cell-9", profile="article")
    # The scheme is the simulator's: a second opener for it is refused.
    with pytest.raises(ConfigError, match="sim://"):
        register_scheme("sim", lambda url, **options: None)
    with pytest.raises(ConfigError, match="not a plain name"):
        register_scheme("a b", lambda url, **options: None)


def test_the_plugin_forgets_what_robots_owe_to_the_simulators_it_closed(
    memory_simulator_factory: Any,
) -> None:
    # A debt kept per robot address outlives the Robot (docs/safety.md); once the
    # fixture's simulators are closed, a later test's simulator on the same port or name
    # is another robot: what was owed to these ends with them, another robot's stays.
    from tmmaster import _command, _gripper, _io
    from tmmaster.sim.pytest_plugin import _addresses, _forget_what_robots_owe

    sim = memory_simulator_factory("article")
    gone = set(_addresses(sim))
    other = ("127.0.0.1", 1, 1)
    owed: Any = object()
    _command._STOPS_OWED.update({(sim.url, 0, 1): owed, other: owed})
    _gripper._STOP_DOUBTS[(sim.url, 0, 65)] = [0.0]
    _io._WATCHED[(sim.url, 0, 1, "coil", 3)] = owed
    _forget_what_robots_owe(gone)
    assert list(_command._STOPS_OWED) == [other]
    assert (sim.url, 0, 65) not in _gripper._STOP_DOUBTS
    assert not [key for key in _io._WATCHED if key[0] == sim.url]
