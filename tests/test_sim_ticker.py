"""The simulator's control tick: a failure stops it, and closing still frees everything."""

from __future__ import annotations

import pytest

from tmmaster.sim import Simulator


def _fail(dt: float) -> None:
    raise ZeroDivisionError("a bug in a tick")


@pytest.mark.parametrize("listen", [True, False])
def test_a_failing_tick_is_reported_and_the_simulator_still_closes_cleanly(listen: bool) -> None:
    sim = Simulator("article", listen=listen)
    sim._controller.tick = _fail  # type: ignore[method-assign]  # a hidden bug in the tick
    with pytest.raises(RuntimeError, match="control tick failed") as caught:
        sim.start()
    assert isinstance(caught.value.__cause__, ZeroDivisionError)
    assert sim.ticks == 0
    # start() closed it: its listener, loop and thread are gone (the suite's no_leaks
    # fixture fails the test for a socket or thread left behind).
    assert not sim.running
