"""Effects the DH model lacks, each a small ``Effect`` subclass in its own module.

``EFFECTS`` is the registry: it maps the effect names of ``result.json`` to their classes, in
the order diagnosis tries them, and is what diagnosis, the simulator, the ``simulate``
command and the report read. Adding an effect means writing its module and adding its
class to ``REGISTERED`` below (an effect defined elsewhere calls ``register``).
``make_effect`` builds one for a robot and the fit data (lumped compliance without masses,
a thermal reference from the data's mean, the driving joints of a coupling).

``LEARNED`` registers the effects learned from the data rather than derived from a
physical law (``residual_map``): no candidate of diagnosis, nothing the simulator
injects, fitted last by ``calibration.learned``; result files and the effects file name
them like the others, and the terminal and report say they are learned.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..errors import InputError
from ..model.robot import Robot
from .backlash import Backlash
from .base import Contribution, Effect, Implausible, Plausible, RowContext, TrueWorld, joint_list
from .compliance import JointCompliance
from .coupled_compliance import CoupledCompliance
from .coupling import JointCoupling
from .cyclic import JointCyclic
from .deflection import LinkDeflection
from .gravity import GravityModel, gravity_torque
from .hysteresis import Hysteresis
from .motion import direction_column, directions_of_motion, with_directions
from .motor_play import MotorPlay
from .residual_map import ResidualMap
from .scale import JointScale
from .thermal import ThermalDrift
from .transmission import TransmissionCoupling

REGISTERED: tuple[type[Effect], ...] = (JointCompliance, JointCyclic, JointScale, ThermalDrift,
                                        JointCoupling, TransmissionCoupling, Backlash, Hysteresis,
                                        CoupledCompliance, MotorPlay, LinkDeflection)
EFFECTS: dict[str, type[Effect]] = {cls.name: cls for cls in REGISTERED}
LEARNED: dict[str, type[Effect]] = {ResidualMap.name: ResidualMap}


def is_learned(name: str) -> bool:
    """Whether effect ``name`` is learned from the data (not a physical law)."""
    return name in LEARNED


def register(cls: type[Effect]) -> type[Effect]:
    """Add ``cls`` to ``EFFECTS`` after the built-in ones (usable as a class decorator): an
    effect written outside this package is then tried by diagnosis, simulated, written and
    read back like the others. A name already taken by another class is refused."""
    if EFFECTS.get(cls.name, cls) is not cls:
        raise ValueError(f"effect name {cls.name!r} is taken by {EFFECTS[cls.name].__name__}")
    EFFECTS[cls.name] = cls
    return cls


def data_columns() -> tuple[str, ...]:
    """The data columns (besides ``payload``) the registered effects read, each once, in
    registry order (``Effect.data_columns``)."""
    return tuple(dict.fromkeys(c for cls in EFFECTS.values() for c in cls.data_columns))


def effect_class(name: str, where: str = "effects") -> type[Effect]:
    """The registered class of effect ``name``; an ``InputError`` listing the valid names."""
    if name not in EFFECTS:
        raise InputError(f"unknown effect {name!r}; valid names: {', '.join(EFFECTS)}",
                         where=where)
    return EFFECTS[name]


def effect_title(name: str) -> str:
    """The effect's name in words (``joint_cyclic`` -> ``Periodic joint error``)."""
    cls = EFFECTS.get(name) or LEARNED.get(name)
    return cls.title if cls is not None else name.replace("_", " ").capitalize()


def make_effect(name: str, joints=(), robot: Robot | None = None,
                extras: Mapping[str, Any] | None = None, **options) -> Effect:
    """The effect ``name`` on ``joints`` (1-based), set up for ``robot`` and the fit data.

    ``extras`` are the fit data's extra columns (one array per name, all datasets
    joined): ``payload`` switches on the payload term of lumped compliance; for
    ``thermal_drift`` the column is ``temperature`` if present, else ``time``, and its
    mean becomes the reference. ``options`` go to the class (``drivers`` of a
    ``joint_coupling``, one per joint).
    """
    return effect_class(name).create(tuple(int(j) for j in joints), robot, extras or {},
                                     **options)


__all__ = ["Backlash", "Contribution", "CoupledCompliance", "EFFECTS", "Effect", "GravityModel",
           "Hysteresis", "MotorPlay",
           "Implausible",
           "JointCompliance", "JointCoupling", "JointCyclic", "JointScale", "LEARNED",
           "LinkDeflection", "ResidualMap", "is_learned",
           "Plausible",
           "REGISTERED", "RowContext", "ThermalDrift", "TransmissionCoupling", "TrueWorld",
           "data_columns", "direction_column", "directions_of_motion", "effect_class",
           "effect_title", "gravity_torque", "joint_list", "make_effect", "register",
           "with_directions"]
