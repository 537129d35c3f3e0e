"""How fast the suite's simulators run: one place for the time scales and tick rates.

Every tick advances at most ``TICK_SIM_S`` simulated seconds, whatever the time scale,
so a faster simulator ticks more often instead of jumping further per tick.
"""

from __future__ import annotations

from typing import Any

from tmmaster.sim import Simulator, Timing

#: Simulated seconds one control tick may advance.
TICK_SIM_S = 0.4

#: The suite's default (``tm_simulator_factory`` in conftest): 40x real time, 100 Hz.
SUITE_TIME_SCALE = 40.0
SUITE_TICK_HZ = SUITE_TIME_SCALE / TICK_SIM_S

#: For runs whose subject is the outcome (the moves sent, where the parts end up, the
#: exit code), not a wall-clock delay nor a request count a fault is timed by: 100x at
#: 250 Hz, so a move ends by the master's first poll instead of a stretched later one.
QUICK: dict[str, Any] = {"time_scale": 100.0, "timing": Timing(tick_hz=100.0 / TICK_SIM_S)}


def ticking_simulator(*args: Any, time_scale: float, **options: Any) -> Simulator:
    """A ``Simulator`` whose tick rate keeps up with ``time_scale`` (``TICK_SIM_S`` a tick).

    For examples that build their own simulators at Simulator's default 50 Hz tick, which
    allows 20x at most: tests swap it in for the example's ``Simulator``.
    """
    return Simulator(
        *args, time_scale=time_scale, timing=Timing(tick_hz=time_scale / TICK_SIM_S), **options
    )
