"""Shared fixtures: every test must leave no thread and no socket behind."""

from __future__ import annotations

import gc
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

import tmmaster
from sim_speeds import SUITE_TICK_HZ, SUITE_TIME_SCALE
from tmmaster import Robot
from tmmaster.sim import Simulator


def _open_sockets() -> set[str]:
    # Linux only: each open socket is a /proc/self/fd link to "socket:[inode]".
    fds = "/proc/self/fd"
    found = set()
    for fd in os.listdir(fds):
        try:
            target = os.readlink(f"{fds}/{fd}")
        except OSError:
            continue
        if target.startswith("socket:"):
            found.add(target)
    return found


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Fail a test that leaves a thread or a socket open (python-can style)."""
    if not os.path.isdir("/proc/self/fd"):
        yield
        return
    threads_before = set(threading.enumerate())
    sockets_before = _open_sockets()
    yield
    deadline = time.monotonic() + 2.0
    collect = False
    while True:
        # pymodbus's server can drop an accepted-but-unserved connection without
        # closing it; such a socket is unreachable garbage, closed by a collection.
        # A collection costs tens of milliseconds with this many objects, so it is
        # made only once something new is found (it can close sockets, never open one).
        if collect:
            gc.collect()
        new_threads = [t for t in threading.enumerate() if t not in threads_before and t.is_alive()]
        new_sockets = _open_sockets() - sockets_before
        if not new_threads and not new_sockets:
            return
        collect = True
        if time.monotonic() > deadline:
            break
        time.sleep(0.02)
    pytest.fail(
        f"test leaked {len(new_threads)} thread(s) {[t.name for t in new_threads]}"
        f" and {len(new_sockets)} socket(s)"
    )


@pytest.fixture
def tm_simulator_factory(
    tm_simulator_factory: Callable[..., Simulator],
) -> Callable[..., Simulator]:
    """The plugin's factory with the suite's faster defaults (``sim_speeds.SUITE_TIME_SCALE``).

    The tmflow profile, as everywhere, unless a test asks for another (``"article"``).
    40x real time with a 100 Hz tick (each tick still advances 0.4 simulated seconds, as
    the plugin's 20x at 50 Hz does). A test whose subject is a wall-clock delay passes
    its own time_scale.
    """

    def make(profile: Any = "tmflow", **options: Any) -> Simulator:
        options.setdefault("time_scale", SUITE_TIME_SCALE)
        options.setdefault("tick_hz", SUITE_TICK_HZ)
        return tm_simulator_factory(profile, **options)

    return make


@pytest.fixture
def memory_simulator_factory(
    tm_simulator_factory: Callable[..., Simulator],
) -> Callable[..., Simulator]:
    """Like ``tm_simulator_factory``, but the simulators open no socket: use ``sim.url``.

    A module whose subject is not TCP overrides ``tm_simulator_factory`` with this one.
    """

    def make(profile: Any = "tmflow", **options: Any) -> Simulator:
        return tm_simulator_factory(profile, listen=False, **options)

    return make


#: xdist workers for a run of several test files (``-n auto`` in pyproject's addopts). Most
#: tests wait on the wall clock (simulated moves, timeouts), which workers overlap: the
#: suite waits about 88 s for 31-33 s of CPU. A worker costs about 1 s of CPU to start now
#: that the test modules are rewritten once (above). On two cores (24 Nov 2026) six took
#: 19.7-21.3 s, five 20.6-21.0 s, four 23.5 s (docs/architecture.md); more than six only
#: adds CPU, and load, against the safety tests' timing margins.
SUITE_WORKERS = 6


def _warm_the_rewrite_cache(config: pytest.Config) -> None:
    """Rewrite the test modules' asserts once, here, before the xdist workers start.

    Otherwise each worker rewrites all of them at the same time on a clean checkout (CI):
    about 1.6 s of CPU each. This uses pytest's private helpers, so any surprise from a
    newer pytest only skips the warm-up (the workers then rewrite as usual).
    """
    try:
        from _pytest.assertion import rewrite

        state = config.stash[rewrite.assertstate_key]
        for source in sorted(Path(__file__).parent.glob("test_*.py")):
            pyc = rewrite.get_cache_dir(source) / (source.name[:-3] + rewrite.PYC_TAIL)
            if rewrite._read_pyc(source, pyc) is not None:
                continue
            source_hash, code = rewrite._rewrite_test(source, config)
            if rewrite.try_makedirs(pyc.parent):
                rewrite._write_pyc(state, code, source_hash, pyc)
    except Exception:  # an optimisation only: never fail the run for it
        return


def pytest_configure(config: pytest.Config) -> None:
    """Cache compiled test modules; in the xdist controller, warm that cache for the workers."""
    # Containers (and .ci/run) often set PYTHONDONTWRITEBYTECODE=1: then every worker
    # rewrote every test module's asserts on every run. The cache goes into the usual,
    # git-ignored __pycache__ folders, as Python does by default.
    sys.dont_write_bytecode = False
    if hasattr(config, "workerinput"):
        return
    _compile_the_package()
    if not config.getoption("numprocesses", None):
        return
    _warm_the_rewrite_cache(config)


def _compile_the_package() -> None:
    """Write the bytecode of tmmaster's modules that has none, or an outdated one.

    The plugin (``-p tmmaster.sim.pytest_plugin``) and this file import most of tmmaster
    before ``pytest_configure`` lets this process write bytecode: under
    PYTHONDONTWRITEBYTECODE=1 those modules (about half the package) were compiled from
    source again by every xdist worker and every subprocess a test starts (the CLI
    tests', the examples'), which can only read a cache. Up-to-date files are skipped.
    """
    import compileall

    package = Path(tmmaster.__file__).parent
    try:
        compileall.compile_dir(package, quiet=2)
    except OSError:  # a read-only install: an optimisation only
        return


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_auto_num_workers(config: pytest.Config) -> int | None:
    """``-n auto``: ``SUITE_WORKERS`` for the suite or several files, one process for one file."""
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return None  # xdist's own hook reads it
    if config.args_source is pytest.Config.ArgsSource.TESTPATHS:
        return SUITE_WORKERS
    files: set[Path] = set()
    for arg in config.args:
        path = config.invocation_params.dir / arg.split("::")[0]
        files.update(path.rglob("test_*.py") if path.is_dir() else [path])
    return min(SUITE_WORKERS, len(files)) if len(files) > 1 else 0


#: Modules whose tests wait longest on the wall clock (simulated moves, timeouts, CLI
#: subprocesses), longest first (measured with ``--durations``). They are started first, so
#: that under xdist the short tests fill the other workers meanwhile instead of a long test
#: starting last and the whole run waiting for it alone.
_LONGEST_FIRST = (
    "test_safety_stateful.py",
    "test_cli_ux.py",
    "test_safety_regressions.py",
    "test_sim_mujoco.py",
    "test_examples_docstrings.py",
    "test_examples.py",
    "test_pickplace.py",
    "test_examples_two_robots.py",
    "test_pickplace_options.py",
    "test_transport.py",
    "test_logging.py",
    "test_sim_server.py",
    "test_robot.py",
    "test_grippers.py",
    "test_pickplace_runner.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Run the modules that wait longest first (stable: their own order is kept)."""
    rank = {name: i for i, name in enumerate(_LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


@pytest.fixture
def robots() -> Iterator[Callable[..., Robot]]:
    """Open robots on a simulator, connected and ready; all closed after the test.

    Modules that need other defaults (ports, short timeouts) define their own ``robots``.
    """
    opened: list[Robot] = []

    def make(sim: Simulator, **options: Any) -> Robot:
        options.setdefault("profile", sim.profile)
        options.setdefault("poll_interval_s", 0.01)
        options.setdefault(
            "retry", tmmaster.RetryPolicy(attempts=8, total_time_s=5, initial_backoff_s=0.02)
        )
        robot = Robot(sim.url, **options)
        opened.append(robot)
        robot.connect()
        robot.wait_until_ready(timeout_s=5)
        return robot

    yield make
    for robot in opened:
        robot.close()
