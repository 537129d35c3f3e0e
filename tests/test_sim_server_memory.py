"""The memory each simulated TCP server hands pymodbus: pymodbus' own, one copy each."""

from __future__ import annotations

import pytest
from pymodbus.simulator import SimDevice

from tmmaster.sim import Simulator


@pytest.mark.parametrize("profile", ["tmflow", "article"])
def test_each_server_gets_its_own_copy_of_the_memory_pymodbus_builds(profile: str) -> None:
    first = Simulator(profile, listen=True)._servers[0]._sim_device()
    second = Simulator(profile, listen=True)._servers[0]._sim_device()
    built = first.build_device()
    assert built == SimDevice(id=0, simdata=first.simdata, action=first.action).build_device()
    assert isinstance(built, dict)
    again = second.build_device()
    assert again == built
    for table, (_, registers, flags) in built.items():
        assert registers is not again[table][1]
        assert flags is not again[table][2]
        registers[0] = 0xBEEF  # the runtime writes its registers: no other server sees it
    assert second.build_device() == again
