"""What the arm carries at its flange: the gripper and the part it holds, against its payload.

Techman's rated payload (:attr:`RobotModel.payload_kg`, the datasheets' figure) is what
the arm may carry at the flange, the tool included: TMflow asks for the tool's mass in
its tool settings and, for a part, a payload on each motion node; an over-payload error
(0x000F, TMflow SW 2.24 Software Manual, Appendix J, p. 407) tells the user to check
"whether the average center of mass of the tool and payload has been taken". So both
backends count the gripper's mass (:attr:`GripperGeometry.mass_kg`) with the part's.

Not modelled: the payload's derating with the distance of its centre of mass from the
flange. Techman publishes it as a payload chart in the arm's hardware manual, which is
not among the manuals this project has as text; TMflow 2.24 states no figure for it.
"""

from __future__ import annotations

from ._backend import BackendFault
from ._world import GripperGeometry, TableObject


def carried_kg(part: TableObject | None, gripper: GripperGeometry) -> float:
    """The mass the arm carries at its flange: the gripper and the part it holds, kg.

    Args:
        part: The part held, or None.
        gripper: The gripper.

    Returns:
        The gripper's mass plus the part's, kg.
    """
    return gripper.mass_kg + (0.0 if part is None else part.mass_kg)


def over_payload(
    part: TableObject | None, gripper: GripperGeometry, payload_kg: float | None
) -> BackendFault | None:
    """The over-payload fault when the gripper and ``part`` weigh more than ``payload_kg``.

    Args:
        part: The part held, or None (the gripper alone is checked).
        gripper: The gripper.
        payload_kg: The arm's rated payload, kg (None: not known, not checked).

    Returns:
        A ``"payload"`` fault naming the masses, or None.
    """
    if payload_kg is None:
        return None
    carried = carried_kg(part, gripper)
    if carried <= payload_kg + 1e-9:
        return None
    what = f"the {gripper.mass_kg:g} kg gripper"
    if part is not None:
        what = f"{part.name} ({part.mass_kg:g} kg) with {what}"
    return BackendFault(
        "payload",
        f"carrying {what} ({carried:g} kg) over the rated payload of {payload_kg:g} kg",
    )
