"""A kind that lives only here: a draw-wire gauge from a fixed anchor to the flange.

The wire is hooked to a point on the flange (mounted: ``hook_x, hook_y, hook_z`` [m],
flange frame); its drum stands somewhere in the room (placement: ``<label>/anchor_x, _y,
_z`` [m], world frame). Each reading is the wire's length [m]. Residual per reading:
``|T_i hook - anchor| - length_i`` [m].

Dataset file keys: ``hook: {xyz}`` (flange frame) and ``anchor: {xyz}`` (a guess of the
drum's position, world frame); table columns ``q1..qn`` and ``length`` in the file's
length unit. Everything the toolkit asks of a kind is in this one module; importing it
registers the kind with the one line at the bottom.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import casadi as ca
import numpy as np

from robocal_casadi.errors import InputError
from robocal_casadi.instruments import Instrument, MeasurementModel, register
from robocal_casadi.instruments.dataset import (
    DatasetBase,
    extra_columns,
    length3,
    lengths,
    with_table,
)
from robocal_casadi.instruments.simulation import (
    Generated,
    Setup,
    in_units,
    run_extras,
)
from robocal_casadi.model.parameters import ParameterRegistry

KIND = "string_gauge"
DEFAULT_HOOK = (0.0, 0.02, 0.08)  # [m] flange frame
ANCHOR_DISTANCE = 1.8  # [m] from the robot base, in a random direction


@dataclass(frozen=True, repr=False)
class StringGauge(DatasetBase):
    """Wire lengths (N,) [m] from the anchor to the flange-frame ``hook`` [m]."""

    row_fields = ("length",)

    length: np.ndarray | None = None
    hook: np.ndarray = field(default_factory=lambda: np.zeros(3))
    anchor: np.ndarray = field(default_factory=lambda: np.zeros(3))  # [m] guess, world frame


def read(content: dict, table, common: dict) -> StringGauge:
    path, units = common["path"], common["units"]
    fields: dict[str, Any] = dict(hook=length3(content, "hook", "xyz", units, path),
                                  anchor=length3(content, "anchor", "xyz", units, path))
    if table is not None:
        used = {"length"}
        fields["length"] = lengths(table, ["length"], units)[:, 0]
        if np.any(fields["length"] <= 0):
            row = int(np.argmax(fields["length"] <= 0))
            raise InputError("a wire length must be positive", file=table.path,
                             where=f"line {table.line(row)}")
        common = with_table(common, table, common["robot"], used)
        fields["extras"] = extra_columns(table, used)
    return StringGauge(**common, **fields)


class StringGaugeModel(MeasurementModel):
    """Residuals of wire lengths; see the module docstring."""

    kind = KIND
    table = "lengths.csv"
    reach = "configuration"
    error_title = "wire length error"
    reading_name = "wire reading"
    measured_columns = ("length",)
    separable = True

    def __init__(self, dataset, label: str):
        super().__init__(dataset, label)
        self._placement = ParameterRegistry(
            tuple(f"{self.placement_prefix}/anchor_{axis}" for axis in "xyz"), ("length",) * 3)

    @property
    def mounted(self) -> ParameterRegistry:
        return ParameterRegistry(("hook_x", "hook_y", "hook_z"), ("length",) * 3)

    @property
    def placement(self) -> ParameterRegistry:
        return self._placement

    def initial_mounted(self) -> np.ndarray:
        return np.asarray(self.dataset.hook, dtype=float).copy()

    def initial_placement(self, points, mounted) -> np.ndarray:
        return np.asarray(self.dataset.anchor, dtype=float).copy()

    def residual_size(self) -> int:
        return self.dataset.rows

    def residual(self, points, mounted, placement) -> ca.MX:
        world = points(mounted)  # 3 x N
        apart = world - ca.repmat(placement[0:3], 1, self.dataset.rows)
        return (ca.sqrt(ca.sum1(apart * apart)) - ca.DM(self.dataset.length.reshape(1, -1))).T

    def row_residual(self, point, data, mounted, placement, constants):
        return ca.norm_2(point - placement[0:3]) - data[0]

    def row_data(self) -> np.ndarray:
        return np.asarray(self.dataset.length, dtype=float).reshape(-1, 1)

    def errors(self, residual: np.ndarray) -> np.ndarray:
        return np.abs(np.asarray(residual, float).ravel())

    def error_rows(self) -> np.ndarray:
        return np.arange(self.dataset.rows)

    def nominal_mounted(self) -> np.ndarray:
        return np.asarray(self.dataset.hook, dtype=float).copy()

    def nominal_placement(self, sockets=None) -> np.ndarray:
        return np.asarray(self.dataset.anchor, dtype=float).copy()

    @classmethod
    def planned_dataset(cls, dataset, joints, kinematics, *, pose=None, point=(), distance=None):
        """The nominal robot's wire lengths to the file's anchor."""
        joints = np.asarray(joints, dtype=float)
        hooks = kinematics.points(joints, dataset.hook)
        return replace(dataset, joints=joints, extras={},
                       length=np.linalg.norm(hooks - dataset.anchor, axis=1))


def simulate(setup: Setup) -> Generated:
    """Random configurations; the wire from a drum about ``ANCHOR_DISTANCE`` away."""
    rng = setup.rng
    hook = setup.mounted(DEFAULT_HOOK)
    heading = rng.uniform(-math.pi, math.pi)
    anchor = np.array([ANCHOR_DISTANCE * math.cos(heading), ANCHOR_DISTANCE * math.sin(heading),
                       rng.uniform(0.0, 0.5)])
    guess = anchor + rng.normal(0.0, 0.005, 3)
    run = setup.random_run()
    hooks = run.poses[:, :3, :3] @ hook + run.poses[:, :3, 3]
    wire = np.linalg.norm(hooks - anchor, axis=1) + rng.normal(0.0, setup.noise, setup.rows)
    return Generated(
        Q_read=run.Q_read, extras=run_extras(run.payloads, run.temperatures, setup),
        mounted={"hook": hook}, placement={"anchor": anchor},
        fields=lambda units: {"hook": {"xyz": in_units(units, DEFAULT_HOOK)},
                              "anchor": {"xyz": in_units(units, guess)}},
        measured={"length": wire})


INSTRUMENT = Instrument(kind=KIND, model=StringGaugeModel, blocks={"hook": ("xyz",),
                                                                  "anchor": ("xyz",)},
                        read=read, simulate=simulate)

register(INSTRUMENT)
