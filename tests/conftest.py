"""Shared fixtures: every test must leave no thread and no socket behind, and no give-up
owed to its robot reaches the next test's."""

from __future__ import annotations

import gc
import importlib
import os
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings

import tmmaster
from leaks import left_open, open_sockets
from sim_speeds import SUITE_TICK_HZ, SUITE_TIME_SCALE
from tmmaster import Fleet, PollPolicy, Robot, _fleet
from tmmaster.sim import Simulator, Timing
from tmmaster.sim.pytest_plugin import _forget_what_robots_owe

# The property and stateful tests draw the same examples on every run, so a run's result
# depends on the code alone; TMMASTER_HYPOTHESIS=explore draws new ones (a longer hunt,
# with TMMASTER_STATEFUL_EXAMPLES). Loaded before any test module makes its settings.
# No deadline: an example's wall time says how busy the machine is, not whether the code
# is right (a 0.3 ms codec example took 433 ms once in a full run beside CPU hogs).
settings.register_profile("deterministic", derandomize=True, deadline=None)
settings.register_profile("explore", derandomize=False, deadline=None)
settings.load_profile(os.environ.get("TMMASTER_HYPOTHESIS", "deterministic"))


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Fail a test that leaves a thread or a socket open (python-can style)."""
    if not os.path.isdir("/proc/self/fd"):
        yield
        return
    threads_before = set(threading.enumerate())
    sockets_before = open_sockets()
    yield
    # pymodbus's server can drop an accepted-but-unserved connection without closing
    # it; such a socket is unreachable garbage, closed by a collection.
    new_threads, new_sockets = left_open(sockets_before, threads_before, collect=True)
    if not new_threads and not new_sockets:
        return
    pytest.fail(
        f"test leaked {len(new_threads)} thread(s) {[t.name for t in new_threads]}"
        f" and {len(new_sockets)} socket(s){where_they_are(new_threads)}"
    )


def where_they_are(threads: list[threading.Thread]) -> str:
    """What a leaked thread is doing (its stack) and what holds the default driver, for a
    leak seen only under load (a driver's loop thread alive 2 s after its test)."""
    frames = sys._current_frames()
    stacks = [
        f"\n--- {t.name}:\n" + "".join(traceback.format_stack(frames[t.ident]))
        for t in threads
        if t.ident in frames
    ]
    driver = _fleet._DEFAULT
    return f"\ndefault driver: {driver._users} user(s), fleet {driver.fleet!r}" + "".join(stacks)


@pytest.fixture(autouse=True)
def no_debt_outlives_its_robot() -> Iterator[None]:
    """What a test's Robots left owed to its robot (a Stop the link could not carry, a
    late output frame, a gripper's Stop: kept per process and robot address) ends with the
    test: its simulators are gone, and the next test's on a reused port is another robot,
    whose first call would deliver it."""
    yield
    _forget_what_robots_owe(None)  # every address: also simulators made by hand, proxies


@pytest.fixture
def tm_simulator_factory(
    tm_simulator_factory: Callable[..., Simulator],
) -> Callable[..., Simulator]:
    """The plugin's factory with the suite's faster defaults (``sim_speeds.SUITE_TIME_SCALE``).

    The tmflow profile, as everywhere, unless a test asks for another (``"article"``).
    40x real time with a 100 Hz tick (each tick still advances 0.4 simulated seconds, as
    the plugin's 20x at 50 Hz does). A test whose subject is a wall-clock delay passes
    its own time_scale. The robot's start-up (which ``start()`` waits for) takes the wall
    time it takes at 40x, whatever the time_scale: 0.2 s at 1x, 0.8 s at 0.25x, would
    delay only the test's start. A test whose subject is the start-up passes its own
    ``timing``.
    """

    def make(profile: Any = "tmflow", **options: Any) -> Simulator:
        options.setdefault("time_scale", SUITE_TIME_SCALE)
        start_up_s = Timing().init_time_s * options["time_scale"] / SUITE_TIME_SCALE
        options.setdefault("timing", Timing(tick_hz=SUITE_TICK_HZ, init_time_s=start_up_s))
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


#: xdist workers per CPU for ``-n auto`` (measured in docs/architecture.md, "The
#: transport seam"): most of a test's time is waiting on the wall clock (simulated moves,
#: timeouts), which more workers overlap; each worker also costs its start-up (about 3 s
#: of CPU: imports and collecting every test) and adds load against the safety tests'
#: timing margins. Six a CPU: 87-91 s on two cores in five runs, against 108-117 s with
#: four (2026-11-30, about 4,440 tests).
WORKERS_PER_CPU = 6


def _cpus() -> int:
    """How many CPUs this process may run on."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


#: The garbage collector's thresholds in a test process (Python's: 700, 10, 10).
GC_THRESHOLDS = (10_000, 10, 10)


def pytest_configure(config: pytest.Config) -> None:
    """Keep the bytecode of the suite's processes (the workers, the CLI tests' subprocesses),
    and collect the garbage of a test process less often.

    Containers and CI (``.ci/run``) often set PYTHONDONTWRITEBYTECODE=1: then every xdist
    worker compiled tmmaster and rewrote every test module's asserts again, and every
    subprocess a test starts compiled the package again (about 1 s of CPU each). Python
    and pytest write their caches into the usual, git-ignored ``__pycache__`` folders.

    A test process holds a large heap (every test module, the simulators' code,
    hypothesis), which each full collection traverses: at Python's thresholds, about
    0.1 s each, every few dozen tests. ``GC_THRESHOLDS`` cut the process's collection
    time by more than half (measured: 1.20 -> 0.54 s over five files, 492 tests). Garbage
    in cycles lives a little longer: ``no_leaks`` collects before it counts a socket or a
    thread as leaked, as it did.
    """
    del config
    sys.dont_write_bytecode = False
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
    gc.set_threshold(*GC_THRESHOLDS)
    # Python's own Ctrl-C handler, also where pytest was started with SIGINT ignored (a
    # command run with `&` in a script, nohup): the Ctrl-C tests need it, and the
    # workers and commands the suite starts then begin with SIGINT at its default.
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_collection_finish(session: pytest.Session) -> None:
    """Leave what collection made out of the full collections of the tests that follow.

    Once collected, a test process holds about 140,000 objects that live to its end (every
    test module, tmmaster, hypothesis, pydantic, the test items); each full collection
    traversed them again: in ``no_leaks``, at the thresholds, twice in pytest's own
    collections at the end of the session (those two: 140-170 ms after collecting the
    whole suite, under 1 ms frozen). Frozen (``gc.freeze``), they are skipped: measured on
    five files (539 tests, one process), full collections 0.70-0.75 -> 0.42 s of CPU.
    What the tests allocate is collected as before, so what a test leaves behind (an
    unclosed socket, a thread, an unraisable exception in a finaliser) is found as it was.
    """
    del session
    gc.freeze()


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config: pytest.Config) -> None:
    """Leave the objects still alive out of Python's last collections when a run ends.

    A test process ends holding a large heap (every test module, the simulators' code,
    hypothesis): Python's finalization traversed it again in its garbage collections,
    about 0.5 s of CPU per process (each xdist worker and the controller) after the
    session was over. Frozen (``gc.freeze``), they are left to the operating system.
    What closes or flushes at exit runs as before, ahead of that: pytest's own clean-up,
    threads joined, atexit handlers (logging.shutdown among them).
    """
    del config
    gc.freeze()


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_auto_num_workers(config: pytest.Config) -> int | None:
    """``-n auto``: ``WORKERS_PER_CPU`` workers a CPU, one process for a single test file.

    The suite (or a folder) gets the number of CPUs this process may use, times
    ``WORKERS_PER_CPU``; a few files no more workers than files; a single file runs in
    this process (no worker start-up to pay). PYTEST_XDIST_AUTO_NUM_WORKERS overrides it.
    """
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return None  # xdist's own hook reads it
    workers = WORKERS_PER_CPU * _cpus()
    if config.args_source is pytest.Config.ArgsSource.TESTPATHS:
        return workers
    files = _files_named(config)
    return min(workers, len(files)) if len(files) > 1 else 0


def _files_named(config: pytest.Config) -> set[Path]:
    """The test files the command line names: each file, and every one in a folder."""
    files: set[Path] = set()
    for arg in config.args:
        path = config.invocation_params.dir / arg.split("::")[0]
        files.update(path.rglob("test_*.py") if path.is_dir() else [path])
    return files


def _rewrite_cached(source: Path) -> bool:
    """Whether ``__pycache__`` holds pytest's rewrite of ``source``, written after its change."""
    changed = source.stat().st_mtime
    cached = (source.parent / "__pycache__").glob(f"{source.stem}.*-pytest-*.pyc")
    return any(pyc.stat().st_mtime >= changed for pyc in cached)


@pytest.hookimpl(tryfirst=True)
def pytest_sessionstart(session: pytest.Session) -> None:
    """An xdist controller imports the test modules pytest has no rewrite cached for, once.

    Pytest rewrites a test module's asserts when it first imports it and caches the result
    in ``__pycache__``; every xdist worker imports every test module to collect it. From a
    fresh clone (as in CI) all the workers rewrote all the modules at the same time: about
    4.5 s of CPU each for this suite, before any test ran. Imported here first, before the
    workers start, the modules are rewritten once and the workers load pytest's cache. A
    module whose cache is newer than its source is not imported here; one that fails to
    import is left to the workers to report.
    """
    config = session.config
    here = Path(__file__).resolve().parent
    if not config.pluginmanager.has_plugin("dsession") or str(here) not in sys.path:
        return  # no xdist workers to start, or not the folder pytest imports tests from
    for source in sorted(path.resolve() for path in _files_named(config)):
        if source.parent != here or not source.is_file() or _rewrite_cached(source):
            continue
        try:
            importlib.import_module(source.stem)
        except (Exception, pytest.skip.Exception):
            continue


@pytest.fixture(params=["driver", "fleet"])
def driver_or_fleet(request: pytest.FixtureRequest) -> Iterator[Fleet | None]:
    """A Robot's ``link=``: None (the process's default driver), or a Fleet of the test's
    own; the same command path runs on either."""
    if request.param == "driver":
        yield None
        return
    with Fleet() as fleet:
        yield fleet


@pytest.fixture
def robots() -> Iterator[Callable[..., Robot]]:
    """Open robots on a simulator, connected and ready; all closed after the test.

    Modules that need other defaults (ports, short timeouts) define their own ``robots``.
    """
    opened: list[Robot] = []

    def make(sim: Simulator, **options: Any) -> Robot:
        options.setdefault("profile", sim.profile)
        options.setdefault("polling", PollPolicy(interval_s=0.01))
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
