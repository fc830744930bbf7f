"""Effects the DH model lacks, each a small ``Effect`` subclass.

``EFFECTS`` maps the effect names of ``result.json`` to their classes; ``make_effect`` builds one
for a robot and the fit data (lumped compliance without masses, a thermal reference
from the data's mean).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..robot import Robot
from .base import Effect, RowContext
from .compliance import JointCompliance
from .cyclic import JointCyclic
from .gravity import GravityModel, gravity_torque
from .scale import JointScale
from .thermal import ThermalDrift

EFFECTS: dict[str, type[Effect]] = {
    "joint_compliance": JointCompliance,
    "joint_cyclic": JointCyclic,
    "joint_scale": JointScale,
    "thermal_drift": ThermalDrift,
}


def make_effect(name: str, joints=(), robot: Robot | None = None,
                extras: dict | None = None) -> Effect:
    """The effect ``name`` on ``joints`` (1-based), set up for ``robot`` and the fit data.

    ``extras`` are the fit data's extra columns (one array per name, all datasets
    joined): ``payload`` switches on the payload term of lumped compliance; for
    ``thermal_drift`` the column is ``temperature`` if present, else ``time``, and its
    mean becomes the reference.
    """
    extras = extras or {}
    if name not in EFFECTS:
        raise InputError(f"unknown effect {name!r}; valid names: {', '.join(EFFECTS)}",
                         where="effects")
    joints = tuple(int(j) for j in joints)
    if name == "joint_compliance":
        return JointCompliance(joints, robot=robot, payload="payload" in extras)
    if name == "thermal_drift":
        column = "temperature" if "temperature" in extras else "time"
        if column not in extras:
            raise InputError("thermal_drift needs a 'temperature' or 'time' column in the data",
                             where="effects")
        effect = ThermalDrift(joints, column=column)
        effect.reference({column: np.asarray(extras[column], dtype=float)})
        return effect
    return EFFECTS[name](joints)


__all__ = ["EFFECTS", "Effect", "GravityModel", "JointCompliance", "JointCyclic", "JointScale",
           "RowContext", "ThermalDrift", "gravity_torque", "make_effect"]
