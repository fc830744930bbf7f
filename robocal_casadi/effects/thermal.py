"""Thermal drift: every DH length grows in proportion to a temperature (or time) change.

    dp[L] = k * (T - T_ref) * L        for every DH length L in {d_i, a_i}

``T`` is the row's ``temperature`` [C] (parameter ``k_T`` [1/K]) or ``time`` [s]
(parameter ``k_t`` [1/s]); ``T_ref`` is fixed from the fit data (their mean) when the
effect is created, so ``k`` does not trade against the lengths themselves. Base and
tool are left alone: they belong to the mounting, not to the arm's links. ``dq = 0``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..errors import InputError, RobocalError
from ..parameters import length_names
from .base import Effect, RowContext
from .checks import column

COLUMNS = {"temperature": ("k_T", "1/K"), "time": ("k_t", "1/s")}


class ThermalDrift(Effect):
    """Uniform growth of the DH lengths with ``column`` (``temperature`` or ``time``).

    ``reference_value`` is ``T_ref`` [C or s]; when None it is fixed by the first call
    of ``reference(extras)`` (the mean of the fit data's column).
    """

    name = "thermal_drift"
    typical = 1e-5  # a typical parameter size, for judging whether the data see it

    def __init__(self, joints: tuple[int, ...] = (), column: str = "temperature",
                 reference_value: float | None = None):
        super().__init__(joints)
        if column not in COLUMNS:
            raise InputError(f"thermal_drift: unknown column {column!r}; expected one of "
                             f"{sorted(COLUMNS)}", where="effects")
        self.column = column
        self.reference_value = None if reference_value is None else float(reference_value)

    def __repr__(self) -> str:
        return f"ThermalDrift(column={self.column!r}, reference_value={self.reference_value})"

    @property
    def unit(self) -> str:  # type: ignore[override]
        return COLUMNS[self.column][1]

    @property
    def label(self) -> str:
        return f"{self.name}[{self.column}]"

    def parameter_names(self) -> tuple[str, ...]:
        return (COLUMNS[self.column][0],)

    def required_columns(self) -> tuple[str, ...]:
        return (self.column,)

    def reference(self, extras: dict) -> dict:
        """``{"reference": T_ref}``; fixes ``reference_value`` from ``extras`` if unset."""
        if self.reference_value is None:
            if self.column not in extras:
                raise InputError(f"thermal_drift needs a {self.column!r} column in the data",
                                 where=self.column)
            values = np.asarray(extras[self.column], dtype=float)
            if not np.all(np.isfinite(values)):
                raise InputError(f"thermal_drift: the {self.column!r} column has empty or "
                                 "non-numeric entries", where=self.column)
            self.reference_value = float(np.mean(values))
        return {"reference": self.reference_value}

    def constants(self) -> tuple[float, ...]:
        """``(T_ref,)`` [C or s]."""
        if self.reference_value is None:
            raise RobocalError("thermal_drift: reference value not fixed; call "
                               "reference(extras) with the fit data first")
        return (self.reference_value,)

    def delta(self, row: RowContext, theta: ca.SX) -> tuple[ca.SX, ca.SX]:
        reference = row.constants[0] if row.constants is not None else self.constants()[0]
        if self.column not in row.extras:
            raise InputError(f"thermal_drift needs a {self.column!r} column in the data",
                             where=self.column)
        change = theta[0] * (row.extras[self.column] - reference)
        entries = {}
        for name in length_names(row.robot):  # d_i, a_i in DH; x_i, y_i, z_i in URDF
            index = row.registry.index(name)
            entries[index] = change * row.p[index]
        return column({}, row.robot.dof), column(entries, len(row.registry))
