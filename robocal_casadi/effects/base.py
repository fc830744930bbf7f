"""The contract every effect model fulfils.

An effect is something the DH model lacks (joint compliance, periodic gear errors, a
gear-ratio error, thermal growth). It owns a few named parameters and, for one row of
data, returns symbolic corrections to the joint readings and to the geometric
parameters:

    q_effective = q + dq(q, p, extras; theta)        [rad or m]
    p_effective = p + dp(q, p, extras; theta)        [SI, registry order]

Forward kinematics is then evaluated at ``(q_effective, p_effective)``. Everything is
CasADi SX, so identification gets exact derivatives. Adding an effect means writing one
small subclass.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import casadi as ca

from ..parameters import ParameterRegistry
from ..robot import Robot


@dataclass(frozen=True)
class RowContext:
    """What an effect may look at for one data row (all CasADi SX).

    ``q`` (dof,) joint readings; ``p`` geometric parameters (registry order, SI);
    ``extras`` maps column names (``temperature`` [C], ``time`` [s], ``payload`` [kg], ...)
    to scalar symbols; ``payload_com`` (3,) [m] in the flange frame; ``constants`` the
    effect's own ``Effect.constants`` as symbols (None where the caller gives none: the
    effect then uses its numbers directly).
    """

    robot: Robot
    registry: ParameterRegistry
    q: ca.SX
    p: ca.SX
    extras: dict
    payload_com: ca.SX
    constants: ca.SX | None = None


class Effect(ABC):
    """One effect with named parameters ``theta``; see the module docstring."""

    name: ClassVar[str]  # name in result.json, e.g. "joint_compliance"
    unit: ClassVar[str]  # unit of the parameters in result.json, e.g. "rad/Nm"

    def __init__(self, joints: tuple[int, ...]):
        self.joints = tuple(int(j) for j in joints)  # 1-based

    def __repr__(self) -> str:
        return f"{type(self).__name__}(joints={list(self.joints)})"

    @property
    def label(self) -> str:
        return f"{self.name}{list(self.joints)}"

    @abstractmethod
    def parameter_names(self) -> tuple[str, ...]:
        """Names of ``theta``, unique across effects (e.g. ``("c2", "c3")``)."""

    def registry(self) -> ParameterRegistry:
        names = self.parameter_names()
        return ParameterRegistry(names, ("none",) * len(names))

    def required_columns(self) -> tuple[str, ...]:
        """Extra data columns this effect needs (e.g. ``("temperature",)``)."""
        return ()

    def reference(self, extras: dict) -> dict:
        """Constants fixed from the data when the effect is created (e.g. mean temperature)."""
        return {}

    def constants(self) -> tuple[float, ...]:
        """Numbers fixed from the data that ``delta`` reads through ``row.constants``.

        They reach compiled code as inputs, so code built for one dataset serves the next.
        """
        return ()

    @abstractmethod
    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, ca.SX | None]:
        """``(dq, dp)`` for one row; ``dp`` may be ``None`` for no geometric change."""
