"""Which simulated robot program runs a handshake: one controller class per handshake.

Apart from ``_controller.py`` (the shared base) so that the base never imports the
classes derived from it: the import graph stays acyclic (``tests/test_import_graph.py``).
"""

from __future__ import annotations

from typing import Any

from .._registers import Handshake, RobotProfile
from .._robot_models import RobotModel
from ._backend import PhysicsBackend
from ._bank import RegisterBank
from ._clear_on_accept import ClearOnAcceptController
from ._controller import RobotController


def controller_class(handshake: Handshake) -> type[RobotController]:
    """The controller class running ``handshake`` (as the client's ``channel_for`` picks).

    The sequence handshake is a TMflow project: the robot program, interpreted
    (:class:`~._script_project.ScriptProjectController`).
    """
    if handshake is Handshake.CLEAR_ON_ACCEPT:
        return ClearOnAcceptController
    # Imported here: the interpreter (and lark) load only for a robot that runs a program.
    from ._script_project import ScriptProjectController

    return ScriptProjectController


def controller_for(
    profile: RobotProfile,
    bank: RegisterBank,
    backend: PhysicsBackend,
    model: RobotModel,
    **options: Any,
) -> RobotController:
    """The controller running ``profile``'s handshake on ``bank``."""
    return controller_class(profile.handshake)(profile, bank, backend, model, **options)
