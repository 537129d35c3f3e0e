"""The tmmaster simulator: a TM robot (and gripper) served over Modbus TCP, in-process.

Like python-can's virtual bus, the simulator is part of the library: the same master
code runs against it and against a real robot. Start one with
``with Simulator() as sim:`` (a free loopback port) or ``python -m tmmaster.sim``;
``Simulator(listen=False)`` opens no socket and is reached in-process at ``sim.url``
(``Robot(sim.url)``, or ``Robot(..., link=MemoryTransport(sim))``).
"""

from types import FunctionType as _FunctionType
from typing import Any as _Any

from .._address import register_scheme as _register_scheme
from .._pose import DEFAULT_HOME
from .._transport import Transport as _Transport
from ._backend import (
    BackendFault,
    GripperState,
    MotionRejectedError,
    ObjectState,
    PathBackend,
    PhysicsBackend,
    PhysicsUnavailableError,
)
from ._controller import MotionRecord
from ._faults import (
    FAULT_KINDS,
    DropConnectionsFault,
    EstopFault,
    Fault,
    GraspMissFault,
    LateAckFault,
    ModbusExceptionFault,
    RobotErrorFault,
    SlowResponsesFault,
    StallFault,
    StopListeningFault,
    is_network_fault,
    parse_fault,
)
from ._kinematic import KinematicBackend
from ._memory import MemoryTransport
from ._memory import open_endpoint as _open_endpoint
from ._options import Cell, Listen, RobotSetup, Timing
from ._scene import Scene, SceneTable, load_scene
from ._server import RequestRecord
from ._simulator import Simulator
from ._world import (
    DEFAULT_GRIPPER,
    DEFAULT_PART_POSE,
    Fixture,
    GraspFit,
    GraspMode,
    GripperGeometry,
    TableObject,
    World,
)


def _open_sim_url(url: str, **options: _Any) -> _Transport:
    """Open ``sim://name``: the running simulator of that name (ConnectError: none runs)."""
    return _open_endpoint(url, **options)


# The simulator is a plugin of the core: the core serves sim:// through this opener.
_register_scheme("sim", _open_sim_url)

__all__ = [
    "DEFAULT_GRIPPER",
    "DEFAULT_HOME",
    "DEFAULT_PART_POSE",
    "FAULT_KINDS",
    "BackendFault",
    "Cell",
    "DropConnectionsFault",
    "EstopFault",
    "Fault",
    "Fixture",
    "GraspFit",
    "GraspMissFault",
    "GraspMode",
    "GripperGeometry",
    "GripperState",
    "KinematicBackend",
    "LateAckFault",
    "Listen",
    "MemoryTransport",
    "ModbusExceptionFault",
    "MotionRecord",
    "MotionRejectedError",
    "ObjectState",
    "PathBackend",
    "PhysicsBackend",
    "PhysicsUnavailableError",
    "RequestRecord",
    "RobotErrorFault",
    "RobotSetup",
    "Scene",
    "SceneTable",
    "Simulator",
    "SlowResponsesFault",
    "StallFault",
    "StopListeningFault",
    "TableObject",
    "Timing",
    "World",
    "is_network_fault",
    "load_scene",
    "parse_fault",
]

# Shown as tmmaster.sim.Name where they are used (tracebacks, reprs, the docs), not as
# the private module that defines them.
for _name in __all__:
    _value = globals()[_name]
    if isinstance(_value, type | _FunctionType) and _value.__module__.startswith(f"{__name__}._"):
        _value.__module__ = __name__
del _name, _value
