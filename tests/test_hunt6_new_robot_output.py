"""A level output's late frame outlives the Robot that sent it: the next Robot must watch it.

The article's gripper register and a digital output hold the last value written
(``LevelOutput``): a write whose answer was lost is retried, and its first frame may
still land later; a later write of the other value watches for that frame and undoes it
(``tests/test_hunt_gripper.py``, ``tests/test_io_stale.py``). Here the later write comes
from a *new* ``Robot`` of the same process on the same robot: the first was closed (the
end of a pick & place run; docs/safety.md: "close() it and connect again"), and a
fresh ``Robot`` closes the gripper on a part, or sets the output back. The held frame
(FaultProxy ``hold`` on the register's address) lands once the simulator executed the
new write, inside the retry policy's ``total_time_s``: the output must still end at the
value the new Robot asked for, the fingers closed on the part. The judge is the
simulator's own register and coil.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from fault_proxy import FaultProxy, Rule
from tmmaster import PollPolicy, RegisterGripper, RetryPolicy, Robot, TimeoutPolicy
from tmmaster.sim import Simulator

Factory = Callable[..., Simulator]

#: The article map's gripper register (0 open, 1 close).
GRIPPER_REGISTER = 0x0210
DO = 3
#: The held first write times out at once; its retry lands.
TIMEOUTS = TimeoutPolicy(request_s=0.2)
#: Its total time bounds the watch for a late frame (never reached: the frame lands as
#: soon as the new Robot's write was executed).
RETRY = RetryPolicy(attempts=4, total_time_s=3.0, initial_backoff_s=0.01, jitter_s=0)


def executed(sim: Simulator, function_codes: tuple[int, ...], address: int) -> list[int]:
    """Every value the simulator executed into ``address`` by those function codes, in order."""
    return [
        int(r.values[0])
        for r in sim.request_log
        if r.function_code in function_codes and r.address == address and r.values
    ]


Release = Callable[[Callable[[], bool], threading.Event], None]


@pytest.fixture
def released() -> Iterator[Release]:
    """Set ``release`` (the held frame lands) once ``condition`` holds: a thread, joined
    at the test's end."""
    threads: list[threading.Thread] = []
    done = threading.Event()

    def arm(condition: Callable[[], bool], release: threading.Event) -> None:
        def watch() -> None:
            while not condition() and not done.wait(0.005):
                pass
            release.set()

        thread = threading.Thread(target=watch, name="release-held-frame")
        threads.append(thread)
        thread.start()

    yield arm
    done.set()
    for thread in threads:
        thread.join(5)


#: How the second Robot names the robot: as the first did, or otherwise (the process's
#: debts are keyed by the address the name resolves to, tests/test_hunt8_host_names.py).
SECOND_HOST = ["127.0.0.1", "localhost"]


@pytest.mark.parametrize("second_host", SECOND_HOST)
def test_a_new_robots_gripper_close_is_not_undone_by_the_old_robots_late_open(
    tm_simulator_factory: Factory, released: Release, second_host: str
) -> None:
    sim = tm_simulator_factory("article")
    options: dict[str, Any] = dict(
        profile="article",
        retry=RETRY,
        timeouts=TIMEOUTS,
        polling=PollPolicy(interval_s=0.01),
    )
    with FaultProxy(sim.port) as proxy:
        release = threading.Event()
        held = proxy.add(Rule("hold", address=GRIPPER_REGISTER, release=release))
        sim.clear_request_log()
        try:
            with Robot(
                "127.0.0.1", proxy.port, gripper=RegisterGripper(settle_s=0.1), **options
            ) as first:
                first.wait_until_ready(timeout_s=5)
                first.gripper.open()  # the first frame held; retried, answered: open
                assert held.times == 0
            # The held open lands once the simulator executed the new Robot's close.
            released(lambda: 1 in executed(sim, (6, 16), GRIPPER_REGISTER), release)
            with Robot(
                second_host, proxy.port, gripper=RegisterGripper(settle_s=0.1), **options
            ) as second:
                second.wait_until_ready(timeout_s=5)
                second.gripper.close()
                proxy.wait_held()
                sim.wait_for(lambda: executed(sim, (6, 16), GRIPPER_REGISTER).count(0) >= 2, 3)
                writes = executed(sim, (6, 16), GRIPPER_REGISTER)
                assert writes[-1] == 1, f"the fingers were left open under the part: {writes}"
                assert sim.field("gripper_command") == 1
        finally:
            release.set()


def test_a_new_robots_output_is_not_undone_by_the_old_robots_late_write(
    tm_simulator_factory: Factory, released: Release
) -> None:
    sim = tm_simulator_factory("tmflow")
    with FaultProxy(sim.port) as proxy:
        release = threading.Event()
        held = proxy.add(Rule("hold", function_code=5, address=DO, release=release))
        sim.clear_request_log()
        try:
            with Robot("127.0.0.1", proxy.port, retry=RETRY, timeouts=TIMEOUTS) as first:
                first.io.set_do(DO, True)  # the first frame held; retried, answered: True
                assert held.times == 0
            released(lambda: 0 in executed(sim, (5,), DO), release)
            with Robot("127.0.0.1", proxy.port, retry=RETRY, timeouts=TIMEOUTS) as second:
                second.io.set_do(DO, False)
                proxy.wait_held()
                sim.wait_for(lambda: executed(sim, (5,), DO).count(1) >= 2, 3)
                writes = executed(sim, (5,), DO)
                assert writes[-1] == 0, f"DO {DO} was left at the old value: {writes}"
                assert sim.do(DO) is False
        finally:
            release.set()
