"""StatusMonitor behind a Modbus slave that accepts one client: share the Robot's link, yield.

Real controllers limit their Modbus TCP clients. :class:`OneClientSlave` is such a slave
on 127.0.0.1: a relay in front of a simulator that serves one client at a time and
either resets every other (``refuse``) or drops the older client for the newer
(``last_wins``). It counts the connections it accepted, so the tests count events, never
time them.
"""

from __future__ import annotations

import contextlib
import math
import select
import socket
import struct
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any, Literal

import pytest

import tmmaster
from tmmaster import (
    ConfigError,
    ConnectError,
    ConnectionLostError,
    Fleet,
    MonitoredStatus,
    PollPolicy,
    Pose,
    Robot,
    StatusMonitor,
)
from tmmaster.sim import Simulator

SimFactory = Callable[..., Simulator]

#: The monitor's rate: 10 ms slots, so a window of a few tenths of a second has dozens.
RATE_HZ = 100.0

TOUR = (
    Pose(300, -200, 150, 180, 0, 90),
    Pose(300, -200, 180, 180, 0, 90),
    Pose(250, 0, 160, 180, 0, 90),
)


class _Pipe:
    """One served client: its bytes relayed to and from its own upstream connection."""

    def __init__(self, client: socket.socket, upstream: socket.socket) -> None:
        self.client = client
        self.upstream = upstream
        self.ended = threading.Event()
        self.thread = threading.Thread(target=self._relay, name="one-client-pipe", daemon=True)
        self.thread.start()

    def _relay(self) -> None:
        peers = {self.client: self.upstream, self.upstream: self.client}
        try:
            while True:
                ready, _, _ = select.select(list(peers), [], [])
                for sock in ready:
                    data = sock.recv(65536)
                    if not data:
                        return
                    peers[sock].sendall(data)
        except OSError:
            return
        finally:
            self.ended.set()
            for sock in peers:
                with contextlib.suppress(OSError):
                    sock.shutdown(socket.SHUT_RDWR)

    def close(self) -> None:
        for sock in (self.client, self.upstream):
            with contextlib.suppress(OSError):
                sock.shutdown(socket.SHUT_RDWR)
        self.thread.join(5)
        self.client.close()
        self.upstream.close()


class OneClientSlave:
    """A Modbus TCP slave on 127.0.0.1 that serves one client at a time (a simulator behind).

    ``refuse``: while a client is served, a new one is accepted and reset at once.
    ``last_wins``: a new client is served and the older one is closed.
    """

    def __init__(self, target_port: int, mode: Literal["refuse", "last_wins"]) -> None:
        self.target_port = target_port
        self.mode = mode
        #: Client connections accepted (served or reset).
        self.accepted = 0
        #: Of those, reset because another client held the slot.
        self.refused = 0
        self._lock = threading.Lock()
        self._current: _Pipe | None = None
        self._pipes: list[_Pipe] = []
        self._stopping = threading.Event()
        self._listener = socket.socket()
        self._listener.bind(("127.0.0.1", 0))
        self._listener.listen(16)
        self.port: int = self._listener.getsockname()[1]
        self._acceptor = threading.Thread(target=self._accept, name="one-client", daemon=True)
        self._acceptor.start()

    @property
    def served(self) -> int:
        """Clients that were served (accepted and not reset)."""
        with self._lock:
            return self.accepted - self.refused

    def drop_current(self) -> None:
        """Close the served client's connection now (the link breaks mid-run)."""
        with self._lock:
            current = self._current
        if current is not None:
            for sock in (current.client, current.upstream):
                with contextlib.suppress(OSError):
                    sock.shutdown(socket.SHUT_RDWR)
            current.ended.wait(5)

    def _accept(self) -> None:
        while not self._stopping.is_set():
            ready, _, _ = select.select([self._listener], [], [], 0.02)
            if not ready:
                continue
            try:
                client, _ = self._listener.accept()
            except OSError:
                continue
            with self._lock:
                self.accepted += 1
                current = self._current
                busy = current is not None and not current.ended.is_set()
                if busy and self.mode == "refuse":
                    self.refused += 1
                    # A reset, as from a server that takes no more clients.
                    client.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
                    client.close()
                    continue
            if busy and current is not None:  # last_wins: the older client goes
                for sock in (current.client, current.upstream):
                    with contextlib.suppress(OSError):
                        sock.shutdown(socket.SHUT_RDWR)
            upstream = socket.create_connection(("127.0.0.1", self.target_port), timeout=2)
            upstream.settimeout(None)
            pipe = _Pipe(client, upstream)
            with self._lock:
                self._current = pipe
                self._pipes.append(pipe)

    def close(self) -> None:
        """Stop accepting, close every connection and join every thread."""
        self._stopping.set()
        self._acceptor.join(5)
        self._listener.close()
        with self._lock:
            pipes, self._pipes = self._pipes, []
        for pipe in pipes:
            pipe.close()


@pytest.fixture
def slave_factory() -> Iterator[Callable[..., OneClientSlave]]:
    """One-client slaves in front of simulators; closed after the test."""
    made: list[OneClientSlave] = []

    def make(sim: Simulator, mode: Literal["refuse", "last_wins"] = "refuse") -> OneClientSlave:
        slave = OneClientSlave(sim.port, mode)
        made.append(slave)
        return slave

    yield make
    for slave in made:
        slave.close()


@pytest.fixture
def robots() -> Iterator[Callable[..., Robot]]:
    """Robots over Modbus TCP to a port (not yet connected); closed after the test."""
    opened: list[Robot] = []

    def make(port: int, **options: Any) -> Robot:
        options.setdefault("profile", "article")
        options.setdefault("gripper", None)
        options.setdefault("polling", PollPolicy(interval_s=0.01))
        robot = Robot("127.0.0.1", port, **options)
        opened.append(robot)
        return robot

    yield make
    for robot in opened:
        robot.close()


def wait_for(
    monitor: StatusMonitor, name: str, check: Callable[[MonitoredStatus], bool]
) -> MonitoredStatus:
    """Wait (5 s at most: a generous bound, not a timing) until ``check`` holds."""
    deadline = time.monotonic() + 5.0
    while True:
        seen = monitor.latest(name)
        if check(seen):
            return seen
        if time.monotonic() > deadline:
            pytest.fail(f"{name}: condition not met; last seen {seen}")
        time.sleep(0.005)


def tour(robot: Robot, moves: int, *, lost_writes: bool = False) -> int:
    """Drive ``moves`` moves of the tour; the number done.

    ``lost_writes``: a command write that a lost link swallowed (the robot withdraws it
    and raises :class:`CommandStateUnknownError`) is counted as not done, not raised.
    """
    done = 0
    for i in range(moves):
        try:
            robot.move_to(TOUR[i % len(TOUR)], speed=80)
        except tmmaster.CommandStateUnknownError:
            if not lost_writes:
                raise
            continue
        done += 1
    return done


def backed_off_connects(elapsed_s: float, period_s: float = 1.0 / RATE_HZ) -> float:
    """How many connects a monitor backing off from one period may make in ``elapsed_s``.

    Waits of 1, 2, 4, ... periods add up to elapsed_s after about log2(elapsed_s /
    period) + 1 of them; two more for the connect at start and rounding.
    """
    return math.log2(max(elapsed_s / period_s, 1.0)) + 3


# -- (a) sharing the robot's link -----------------------------------------------------


@pytest.mark.parametrize("event_loop", ["asyncio", "uvloop"])
def test_a_shared_robot_is_watched_over_its_one_connection(
    tm_simulator_factory: SimFactory,
    slave_factory: Callable[..., OneClientSlave],
    robots: Callable[..., Robot],
    event_loop: Literal["asyncio", "uvloop"],
) -> None:
    if event_loop == "uvloop":
        pytest.importorskip("uvloop", reason="uvloop is the monitor extra")
    sim = tm_simulator_factory("article")
    slave = slave_factory(sim, "refuse")
    robot = robots(slave.port, name="arm")
    monitor = StatusMonitor(rate_hz=RATE_HZ, event_loop=event_loop)
    assert monitor.add_robot(robot) == "arm"
    with monitor:
        # Started before the robot connects: the monitor opens nothing, it waits.
        before = wait_for(monitor, "arm", lambda s: s.failures >= 3)
        assert isinstance(before.error, ConnectionLostError)
        assert slave.accepted == 0
        robot.connect()
        robot.wait_until_ready(timeout_s=5)
        assert tour(robot, 6) == 6
        toured = monitor.latest("arm")
        assert toured.polls >= 1  # it watched the tour
        seen = wait_for(monitor, "arm", lambda s: s.polls >= toured.polls + 2)
        assert seen.error is None
        assert seen.status is not None
        assert seen.status.pose.is_close(robot.status().pose, mm=0.01)
    assert slave.accepted == 1  # the robot's, and nothing else
    assert slave.refused == 0
    assert robot.stats.reconnects == 0


def test_a_busy_link_skips_the_slot_and_never_waits(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("article")
    robot = robots(sim.port)
    robot.connect()
    monitor = StatusMonitor(rate_hz=RATE_HZ)
    monitor.add_robot(robot, name="busy")
    with monitor:
        wait_for(monitor, "busy", lambda s: s.polls >= 2)
        with robot._transport._lock:  # type: ignore[attr-defined]  # the robot's request
            held = monitor.latest("busy")
            seen = wait_for(monitor, "busy", lambda s: s.skipped >= held.skipped + 5)
            assert seen.polls <= held.polls + 1  # a read already past the lock may end
        wait_for(monitor, "busy", lambda s: s.polls >= seen.polls + 2)


def test_a_lost_robot_link_is_never_reopened_by_the_monitor(
    tm_simulator_factory: SimFactory,
    slave_factory: Callable[..., OneClientSlave],
    robots: Callable[..., Robot],
) -> None:
    sim = tm_simulator_factory("article")
    slave = slave_factory(sim, "refuse")
    robot = robots(slave.port)
    robot.connect()
    monitor = StatusMonitor(rate_hz=RATE_HZ)
    monitor.add_robot(robot, name="r")
    with monitor:
        wait_for(monitor, "r", lambda s: s.polls >= 2)
        slave.drop_current()  # the robot's link breaks
        broken = wait_for(monitor, "r", lambda s: s.failures >= 1)
        # Many slots later, still nobody reconnected: only the robot's requests may.
        wait_for(monitor, "r", lambda s: s.failures >= broken.failures + 10)
        assert slave.accepted == 1
        assert robot.state is tmmaster.ConnectionState.DISCONNECTED
        robot.status()  # the robot's own request reconnects its link
        assert slave.accepted == 2
        seen = wait_for(monitor, "r", lambda s: s.error is None and s.polls > broken.polls)
    assert seen.status is not None


def test_robots_that_cannot_be_shared_are_refused(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("article")
    robot = robots(sim.port, name="one")
    monitor = StatusMonitor()
    monitor.add_robot(robot)
    with pytest.raises(ConfigError, match="already watched by this monitor as 'one'"):
        monitor.add_robot(robot, name="again")
    with pytest.raises(ConfigError, match="name 'one'"):
        monitor.add_robot(robots(sim.port, name="one"))
    with pytest.raises(ConfigError, match=r"tmmaster\.Robot"):
        monitor.add_robot("127.0.0.1")  # type: ignore[arg-type]
    closed = robots(sim.port, name="closed")
    closed.close()
    with pytest.raises(ConfigError, match="closed"):
        monitor.add_robot(closed)
    with Fleet() as fleet:
        member = Robot("127.0.0.1", sim.port, profile="article", gripper=None, link=fleet)
        with pytest.raises(ConfigError, match=r"Fleet\.latest"):
            monitor.add_robot(member, name="member")
    monitor.close()
    with pytest.raises(ConfigError, match=r"before StatusMonitor\.start"):
        monitor.add_robot(robots(sim.port, name="late"))


def test_an_own_link_to_a_commanded_robot_is_refused_naming_it(
    tm_simulator_factory: SimFactory,
    slave_factory: Callable[..., OneClientSlave],
    robots: Callable[..., Robot],
) -> None:
    sim = tm_simulator_factory("article")
    slave = slave_factory(sim, "refuse")
    robot = robots(slave.port, name="arm")
    robot.connect()
    monitor = StatusMonitor(rate_hz=RATE_HZ)
    with pytest.raises(ConfigError, match=r"Robot 'arm' .* monitor\.add_robot\(robot"):
        monitor.add("watch", "127.0.0.1", slave.port, profile="article")
    # The way it names: the robot's own link, and the slave sees one client.
    monitor.add_robot(robot, name="watch")
    with monitor:
        assert wait_for(monitor, "watch", lambda s: s.polls >= 2).error is None
        robot.move_to(TOUR[0], speed=80)
    assert slave.accepted == 1
    assert slave.refused == 0
    # Once the robot is closed, the address is nobody's: a link of the monitor's own.
    robot.close()
    StatusMonitor().add("watch", "127.0.0.1", slave.port, profile="article")


def test_a_robot_made_after_add_is_refused_at_start(
    tm_simulator_factory: SimFactory, robots: Callable[..., Robot]
) -> None:
    sim = tm_simulator_factory("article")
    monitor = StatusMonitor(rate_hz=RATE_HZ)
    monitor.add("watch", "127.0.0.1", sim.port, profile="article")
    robots(sim.port, name="late")
    with pytest.raises(ConfigError, match="Robot 'late'"):
        monitor.start()
    monitor.close()


# -- (b) a monitor with its own connection backs off ----------------------------------


def test_a_refused_connect_backs_off(tm_simulator_factory: SimFactory) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])  # nobody listens there once released
    monitor = StatusMonitor(rate_hz=RATE_HZ, timeout_s=0.2)
    monitor.add("nobody", "127.0.0.1", port)
    with monitor:
        started = time.monotonic()
        seen = wait_for(monitor, "nobody", lambda s: s.skipped >= 40)
        elapsed = time.monotonic() - started
    assert isinstance(seen.error, ConnectError)
    # Every connect failed and was counted: far fewer than one per slot.
    assert 2 <= seen.failures <= backed_off_connects(elapsed)
    assert seen.failures * 4 < seen.failures + seen.skipped


def test_an_own_link_behind_a_taken_slot_backs_off(
    tm_simulator_factory: SimFactory,
    slave_factory: Callable[..., OneClientSlave],
    robots: Callable[..., Robot],
) -> None:
    sim = tm_simulator_factory("article")
    slave = slave_factory(sim, "refuse")
    robot = robots(slave.port)
    robot.connect()
    robot.wait_until_ready(timeout_s=5)
    monitor = StatusMonitor(rate_hz=RATE_HZ)
    # The robot stands for another program's client: the monitor reaches the slave by
    # another name than the robot's address, so it is not refused as the robot's own.
    monitor.add("own", "localhost", slave.port, profile="article")
    with monitor:
        started = time.monotonic()
        assert tour(robot, 3) == 3
        seen = wait_for(monitor, "own", lambda s: s.skipped >= 40)
        elapsed = time.monotonic() - started
    assert seen.polls == 0  # the slot was the robot's all along
    attempts = slave.refused  # every connect of the monitor's was reset
    assert 1 <= attempts <= backed_off_connects(elapsed) + 1  # + the one start() made
    assert attempts * 4 < seen.skipped
    assert robot.stats.reconnects == 0


# -- (c) last connection wins ---------------------------------------------------------


def test_last_connection_wins_reconnects_are_bounded_by_the_back_off(
    tm_simulator_factory: SimFactory,
    slave_factory: Callable[..., OneClientSlave],
    robots: Callable[..., Robot],
) -> None:
    sim = tm_simulator_factory("article")
    slave = slave_factory(sim, "last_wins")
    # The robot's own retries: quick, so a tour with a few lost links stays short.
    retry = tmmaster.RetryPolicy(attempts=8, total_time_s=5, initial_backoff_s=0.02)
    robot = robots(slave.port, retry=retry)
    robot.connect()
    robot.wait_until_ready(timeout_s=5)
    monitor = StatusMonitor(rate_hz=RATE_HZ)
    # The robot stands for another program's client: the monitor reaches the slave by
    # another name than the robot's address, so it is not refused as the robot's own.
    monitor.add("own", "localhost", slave.port, profile="article")
    with monitor:
        started = time.monotonic()
        # A monitor's connect that lands between the robot's last read and its command
        # write loses that write (the robot then withdraws it): the risk of two clients
        # on a last-connection-wins slave, which the back-off makes rare, not impossible.
        done = tour(robot, 9, lost_writes=True)
        # Counted now: once the robot is idle, the monitor's link keeps the slot.
        elapsed = time.monotonic() - started
        robot_connects = 1 + robot.stats.reconnects
        monitor_connects = slave.accepted - robot_connects
    allowed = backed_off_connects(elapsed) + 1  # + the one start() made
    assert 1 <= monitor_connects <= allowed
    assert done >= 9 - monitor_connects  # each connect cost the robot one move at most
    # Each time the monitor took the slot the robot took it back once, at most.
    assert robot.stats.reconnects <= monitor_connects


# -- (d) rates and timeouts a link cannot serve -----------------------------------------


@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("rate_hz", 1e9),
        ("rate_hz", 100.5),
        ("rate_hz", float("inf")),
        ("rate_hz", float("nan")),
        ("rate_hz", 0),
        ("rate_hz", -5),
        ("rate_hz", True),
        ("rate_hz", "20"),
        ("timeout_s", 1e-6),
        ("timeout_s", 1e6),
        ("timeout_s", float("inf")),
        ("timeout_s", float("nan")),
        ("backoff_max_s", 0),
        ("backoff_max_s", float("inf")),
        ("backoff_max_s", 1e9),
    ],
)
def test_rates_and_timeouts_a_link_cannot_serve_are_refused(option: str, value: Any) -> None:
    with pytest.raises(ConfigError, match=option):
        StatusMonitor(**{option: value})


def test_the_limits_are_named_and_the_bounds_accepted() -> None:
    with pytest.raises(ConfigError, match=r"rate_hz must be a number in \[0\.01, 100\] Hz"):
        StatusMonitor(rate_hz=1e9)
    assert StatusMonitor.MAX_RATE_HZ == 100.0
    assert StatusMonitor(rate_hz=100).rate_hz == 100.0
    assert StatusMonitor(rate_hz=0.01, timeout_s=60, backoff_max_s=3600).backoff_max_s == 3600
