"""Thermal drift: every DH length grows in proportion to a temperature (or time) change.

    dp[L] = k * (T - T_ref) * L        for every DH length L in {d_i, a_i}

``T`` is the row's ``temperature`` [C] (parameter ``k_T`` [1/K]) or ``time`` [s]
(parameter ``k_t`` [1/s]); ``T_ref`` is fixed from the fit data (their mean) when the
effect is created, so ``k`` does not trade against the lengths themselves. Base and
tool are left alone: they belong to the mounting, not to the arm's links. ``dq = 0``.

Plausible on real robots: the expansion coefficients of the metals arms are made of
(steel about 11.5e-6/K, aluminium about 23e-6/K), so ``k_T`` is positive and below about
3e-5/K. Against ``time``, the drift may be of either sign (a robot warming up or cooling
down); the joints next to the motors warm by up to about 2 K per minute just after a
start, so ``|k_t|`` stays below 3e-5/K x 2 K / 60 s = 1e-6/s.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from typing import Any

import casadi as ca
import numpy as np

from ..common.units import Units
from ..errors import InputError, RobocalError
from ..model.parameters import length_names
from ..model.robot import Robot
from .base import Effect, Plausible, RowContext, TrueWorld
from .checks import column

COLUMNS = {"temperature": ("k_T", "1/K"), "time": ("k_t", "1/s")}
PLAUSIBLE = {
    "k_T": Plausible(3e-5, sign=+1, basis="metals expand when warmed: steel 11.5e-6/K, "
                     "aluminium 23e-6/K"),
    "k_t": Plausible(1e-6, basis="3e-5/K at a warming or cooling of up to 2 K per minute"),
}


class ThermalDrift(Effect):
    """Uniform growth of the DH lengths with ``column`` (``temperature`` or ``time``).

    ``reference_value`` is ``T_ref`` [C or s]; when None it is fixed by the first call
    of ``reference(extras)`` (the mean of the fit data's column).
    """

    name = "thermal_drift"
    title = "Thermal drift"
    typical = 1e-5
    sentence = "link lengths grow by {value:.3g} per {per} ({key})"
    plot_variable = "column"
    per = "column"
    data_columns = tuple(COLUMNS)
    simulation_default = (1.2e-5,)
    formula = ("every d_i, a_i of the true robot becomes L (1 + k (T - T_ref)); a drifting\n"
               "      temperature column is written (see --temperature, --reference-temperature)")

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

    def plausible(self, parameter: str, drive: str = "gear") -> Plausible:
        """The same for every drive: thermal growth is the links'."""
        return PLAUSIBLE[parameter]

    def settings(self, columns: Collection[str] = ()) -> dict[str, Any]:
        """``column`` and its ``reference`` ``T_ref`` [C or s]."""
        return {"column": self.column, "reference": float(self.constants()[0])}

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any], robot: Robot) -> ThermalDrift:
        return cls(tuple(int(j) for j in entry["joints"]),
                   column=entry.get("column", "temperature"),
                   reference_value=float(entry["reference"]))

    @classmethod
    def column_of(cls, parameters: Collection[str]) -> str | None:
        """The column whose coefficient is among ``parameters`` (``k_T``, ``k_t``)."""
        return next((c for c, (name, _) in COLUMNS.items() if name in parameters), None)

    @classmethod
    def column_label(cls, column: str) -> str | None:
        return {"temperature": "temperature [C]", "time": "time [s]"}.get(column)

    def truth_settings(self) -> dict[str, Any]:
        return {"column": self.column}

    @classmethod
    def create(cls, joints=(), robot: Robot | None = None,
               extras: Mapping[str, Any] | None = None, **options) -> ThermalDrift:
        """Against ``temperature`` if ``extras`` has it, else ``time``; its mean the reference."""
        extras = extras or {}
        column = options.get("column") or ("temperature" if "temperature" in extras else "time")
        if column not in extras:
            raise InputError("thermal_drift needs a 'temperature' or 'time' column in the data",
                             where="effects")
        effect = cls(tuple(joints), column=column)
        effect.reference({column: np.asarray(extras[column], dtype=float)})
        return effect

    @classmethod
    def candidates(cls, robot: Robot, extras: Mapping[str, Any]) -> tuple[ThermalDrift, ...]:
        """One per ``temperature`` or ``time`` column the data carry."""
        return tuple(cls.create((), robot, {column: extras[column]}, column=column)
                     for column in COLUMNS if column in extras)

    @classmethod
    def merged(cls, units, robot: Robot, extras: Mapping[str, Any]) -> ThermalDrift:
        (unit,) = units  # one column per effect
        return unit

    @classmethod
    def for_simulation(cls, keys=()) -> ThermalDrift:
        """Against the ``temperature`` column; its reference is the simulator's ``T_ref``."""
        return cls((), column="temperature")

    def describe(self, values, units: Units) -> str:
        (key, value), = values.items()
        return self.sentence.format(value=value, per="K" if key == "k_T" else "s", key=key)

    def plot_values(self, robot: Robot, joint: int, Q, extras, payload_com=None) -> np.ndarray:
        """The ``temperature`` [C] or ``time`` [s] column."""
        return np.asarray(extras[self.column], dtype=float)

    def simulated_dp(self, world: TrueWorld, p: np.ndarray,
                     extras: Mapping[str, float | None],
                     values: Mapping[str, float]) -> np.ndarray | None:
        """Every ``d_i``, ``a_i`` of the true robot times ``k (T - T_ref)``, ``T_ref`` the
        simulator's reference temperature."""
        temperature = extras.get(self.column)
        if temperature is None:
            return None
        registry = world.robot.parameters()
        factor = values[self.parameter_names()[0]] * (float(temperature)
                                                      - world.reference_temperature)
        dp = np.zeros(len(registry))
        for name in length_names(world.robot):  # d_i, a_i in DH; x_i, y_i, z_i in URDF
            dp[registry.index(name)] = factor * p[registry.index(name)]
        return dp

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
