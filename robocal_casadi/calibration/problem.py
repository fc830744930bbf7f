"""The identification problem: one residual over all datasets, with exact Jacobian.

Unknown vector ``x`` (``Problem.unknowns``), in this order:

1. every geometric parameter of the robot (``ParameterRegistry`` names, SI),
2. the parameters of each effect (``Effect.parameter_names``),
3. the mounted instrument unknowns, shared by name across datasets (probe, target, laser),
4. the placement unknowns of each dataset (sockets, instrument frame, sphere centre);
   datasets of one instrument station (``station:`` in the dataset file) share theirs by
   name, as the mounted unknowns are shared.

Placement values fitted on other data of the same station (``StationFrames``) may be
given; they are then held (``free_placement`` leaves them out), so that held-out data are
measured in the frame the calibration fitted.

Which of them are free is decided by the caller (identifiability, nominal fit,
validation); the residual and Jacobian are built once per problem as CasADi functions.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property

import casadi as ca
import numpy as np

from ..common.codegen import BatchFunction
from ..effects.base import Effect, RowContext
from ..effects.motion import direction_values, is_derived_column
from ..errors import InputError
from ..instruments.model import STATION_PREFIX, MeasurementModel
from ..model.kinematics import Kinematics, mapped
from ..model.parameters import ParameterRegistry
from ..model.robot import Robot


def _row_function(kinematics: Kinematics, effects: Sequence[Effect], columns: Sequence[str]):
    """Per-row CasADi function of one flange-frame point after the effects act.

    ``(q, extras, p, theta, offset, payload_com, constants) -> (p_world, dp/dp, dp/dtheta,
    dp/doffset)`` with ``q`` the joint readings, ``extras`` the data columns the effects
    read, ``p`` the robot geometry, ``theta`` all effect parameters, ``offset`` [m] in the
    flange frame, ``constants`` the effects' numbers fixed from the data
    (``Effect.constants``, e.g. a reference temperature: an input, not a literal, so
    compiled code is shared between datasets); ``p_world`` [m] and its exact derivatives
    (SX, so a batch of rows is one cheap map).
    """
    robot, registry = kinematics.robot, kinematics.registry
    q = ca.SX.sym("q", robot.dof)
    extras = ca.SX.sym("extras", len(columns))
    p = ca.SX.sym("p", len(registry))
    sizes = [len(e.parameter_names()) for e in effects]
    theta = ca.SX.sym("theta", sum(sizes))
    offset = ca.SX.sym("offset", 3)
    payload_com = ca.SX.sym("payload_com", 3)
    constant_sizes = [len(e.constants()) for e in effects]
    constants = ca.SX.sym("constants", sum(constant_sizes))
    row = RowContext(robot, registry, q, p, {c: extras[i] for i, c in enumerate(columns)},
                     payload_com)
    dq = ca.SX.zeros(robot.dof)
    dp = ca.SX.zeros(len(registry))
    start = constant_start = 0
    for effect, size, constant_size in zip(effects, sizes, constant_sizes):
        own = replace(row, constants=constants[constant_start:constant_start + constant_size])
        delta_q, delta_p = effect.delta(own, theta[start:start + size])
        dq += delta_q
        if delta_p is not None:
            dp += delta_p
        start += size
        constant_start += constant_size
    position = kinematics.point(q + dq, p + dp, offset)
    inputs = [q, extras, p, theta, offset, payload_com, constants]
    names = ["q", "extras", "p", "theta", "offset", "payload_com", "constants"]
    point = ca.Function("row_point", inputs, [position], names, ["p_world"])
    derivatives = ca.Function("row_point_jacobians", inputs,
                              [position, ca.jacobian(position, p), ca.jacobian(position, theta),
                               ca.jacobian(position, offset)],
                              names, ["p_world", "J_p", "J_theta", "J_offset"])
    return point, derivatives


COMPILE_ROWS = 1000  # from this many rows on, the per-row derivatives are compiled to C
# Rows a batch function evaluates at once; a shorter last chunk is padded. Compiled
# functions take long chunks (each call crosses into C once); interpreted ones, used below
# COMPILE_ROWS, short ones, so that a model of a few dozen rows (one artifact placement)
# does not evaluate hundreds of padding rows.
COMPILED_CHUNK = 256
INTERPRETED_CHUNK = 32
JACOBIAN_BLOCK = 1024  # rows of a separable model's Jacobian evaluated at once


def _runs(source: np.ndarray, target: np.ndarray
          ) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """Pairs of half-open ranges ``((a, b), (c, d))`` covering ``source -> target``
    (equal-length index arrays) where both step by one: ``out[c:d] = in[a:b]``."""
    breaks = np.flatnonzero((np.diff(source) != 1) | (np.diff(target) != 1)) + 1
    starts = np.r_[0, breaks].astype(int) if len(source) else np.zeros(0, int)
    stops = np.r_[breaks, len(source)].astype(int) if len(source) else np.zeros(0, int)
    return [((int(source[i]), int(source[j - 1]) + 1), (int(target[i]), int(target[j - 1]) + 1))
            for i, j in zip(starts, stops)]


def _pattern(sparsity: ca.Sparsity) -> tuple[np.ndarray, np.ndarray]:
    """(rows, columns) of the nonzeros of ``sparsity``, in CasADi's nonzero order."""
    rows, columns = sparsity.get_triplet()
    return np.asarray(rows, dtype=int), np.asarray(columns, dtype=int)


@dataclass(frozen=True)
class DirectResidual:
    """Compiled residual ``r = g(x)`` of a model that reads no robot points.

    Such a model carries its own flange poses (pendant poses), so ``residual`` and
    ``jacobian`` are functions of the unknown vector ``x`` alone.
    """

    model: MeasurementModel
    residual: ca.Function  # x -> r
    jacobian: ca.Function  # x -> dr/dx (sparse)


@dataclass(frozen=True)
class PointResidual:
    """Compiled residual ``r = g(P, x)`` of a model that reads the world points ``P``.

    ``P`` (3 x N, flattened column by column) [m] holds the robot's point of each data row
    at the flange-frame ``offsets`` the model asks for. ``derivatives`` returns the
    nonzeros of ``dg/dP`` and ``dg/dx``, whose (row, column) positions are fixed in
    ``g_P_rows``/``g_P_columns`` and ``g_x_rows``/``g_x_columns``; ``g_P_order`` sorts the
    ``dg/dP`` nonzeros by residual row (stable), so that they can be summed per row.
    """

    model: MeasurementModel
    offsets: ca.Function  # x -> (offsets 3 x 1 or 3 x N [m], d vec(offsets)/dx)
    residual: ca.Function  # (P, x) -> r
    derivatives: ca.Function  # (P, x) -> (nonzeros of dg/dP, nonzeros of dg/dx)
    g_P_rows: np.ndarray
    g_P_columns: np.ndarray
    g_P_order: np.ndarray
    g_x_rows: np.ndarray
    g_x_columns: np.ndarray


CompiledModel = DirectResidual | PointResidual


@dataclass(frozen=True)
class SeparableResidual:
    """Row-by-row residual and Jacobian of a separable model, compiled for batches.

    ``jacobian`` gives, per row, the derivatives with respect to the robot, effect,
    mounted and placement unknowns in that order; ``columns`` are their indices in ``x``.
    """

    residual: BatchFunction
    jacobian: BatchFunction
    columns: np.ndarray


def _compile(model: MeasurementModel, x: ca.MX, mounted_indices: np.ndarray,
             placement_indices: np.ndarray) -> CompiledModel:
    """The CasADi functions of ``model``'s residual over the unknown vector ``x``."""
    rows = model.dataset.rows
    P = ca.MX.sym("P", 3 * rows)
    recorded: dict[str, ca.MX] = {}

    def points(offsets: ca.MX) -> ca.MX:
        if "offsets" in recorded:
            raise RuntimeError("a measurement model may ask for its points once")
        recorded["offsets"] = offsets
        return ca.reshape(P, 3, rows)

    mounted = ca.vertcat(*[x[int(i)] for i in mounted_indices])
    placement = ca.vertcat(*[x[int(i)] for i in placement_indices]) \
        if len(model.placement) else ca.MX(0, 1)
    r = model.residual(points, mounted, placement)
    if "offsets" not in recorded:
        return DirectResidual(model=model, residual=ca.Function("residual", [x], [r]),
                              jacobian=ca.Function("jacobian", [x], [ca.jacobian(r, x)]))
    offsets = recorded["offsets"]
    # Sparse Jacobians of g: nonzeros as outputs, their (row, column) fixed.
    g_P, g_x = ca.jacobian(r, P), ca.jacobian(r, x)
    g_P_rows, g_P_columns = _pattern(g_P.sparsity())
    g_x_rows, g_x_columns = _pattern(g_x.sparsity())
    return PointResidual(
        model=model,
        offsets=ca.Function("offsets", [x], [offsets, ca.jacobian(ca.vec(offsets), x)]),
        residual=ca.Function("residual", [P, x], [r]),
        derivatives=ca.Function("g_derivatives", [P, x], [g_P.nz[:], g_x.nz[:]]),
        g_P_rows=g_P_rows, g_P_columns=g_P_columns,
        g_P_order=np.argsort(g_P_rows, kind="stable"),
        g_x_rows=g_x_rows, g_x_columns=g_x_columns)


@dataclass(frozen=True)
class StationFrames:
    """Placement unknowns of instrument stations, fitted on some data, to be held where
    other data of the same stations are evaluated.

    ``values`` maps placement names (``station:<name>/...``) to values [SI]; ``leaders``
    maps a station to the model whose reference those values are expressed in (a
    tracker's reference rotation), which the models of that station then follow.
    """

    values: Mapping[str, float] = field(default_factory=dict)
    leaders: Mapping[str, MeasurementModel] = field(default_factory=dict)

    @classmethod
    def of(cls, problem: Problem, x: np.ndarray) -> StationFrames:
        """The station placements of ``problem`` at ``x``."""
        names = problem.unknowns.names
        values = {names[i]: float(x[i]) for i in np.flatnonzero(problem.mask("placement"))
                  if names[i].startswith(STATION_PREFIX)}
        leaders: dict[str, MeasurementModel] = {}
        for model in problem.models:
            if model.station is not None:
                leaders.setdefault(model.station, model)
        return cls(values, leaders)

    def __repr__(self) -> str:
        return f"StationFrames(stations={sorted(self.leaders)}, values={len(self.values)})"



def _batch(function: ca.Function, per_row: tuple[str, ...], compile: bool) -> BatchFunction:
    """``function`` over rows: compiled in chunks of ``COMPILED_CHUNK`` rows, or
    interpreted in chunks of ``INTERPRETED_CHUNK``."""
    return BatchFunction(function, per_row=per_row, compile=compile,
                         chunk=COMPILED_CHUNK if compile else INTERPRETED_CHUNK)

class Problem:
    """Residuals of ``models`` for ``robot`` with ``effects``; see the module docstring.

    ``start`` optionally gives starting values by name (robot, effect or mounted
    parameters, SI); placement unknowns are initialised from the data, except those
    ``frames`` holds (see ``StationFrames``), which take its values and stay fixed.
    """

    def __init__(self, robot: Robot, models: Sequence[MeasurementModel],
                 effects: Sequence[Effect] = (), start: dict[str, float] | None = None,
                 kinematics: Kinematics | None = None, frames: StationFrames | None = None):
        self.robot = robot
        self.models = tuple(models)
        self.effects = tuple(effects)
        self.kinematics = kinematics or Kinematics(robot)
        robot_registry = self.kinematics.registry
        effect_registry = ParameterRegistry((), ())
        for effect in self.effects:
            effect_registry = effect_registry.concat(effect.registry())
        mounted_names: list[str] = []
        mounted_quantities: list[str] = []
        for model in self.models:
            for name in model.mounted.names:
                if name not in mounted_names:
                    mounted_names.append(name)
                    mounted_quantities.append(model.mounted.quantity(name))
        mounted_registry = ParameterRegistry(tuple(mounted_names), tuple(mounted_quantities))
        placement_names: list[str] = []
        placement_quantities: list[str] = []
        for model in self.models:  # one station's unknowns are shared by name
            for name in model.placement.names:
                if name not in placement_names:
                    placement_names.append(name)
                    placement_quantities.append(model.placement.quantity(name))
        placement_registry = ParameterRegistry(tuple(placement_names),
                                               tuple(placement_quantities))
        self.unknowns = (robot_registry.concat(effect_registry).concat(mounted_registry)
                         .concat(placement_registry))
        sizes = [len(robot_registry), len(effect_registry), len(mounted_registry),
                 len(placement_registry)]
        bounds = np.cumsum([0] + sizes)
        self.slices = {key: slice(int(bounds[i]), int(bounds[i + 1]))
                       for i, key in enumerate(("robot", "effects", "mounted", "placement"))}
        self.columns = tuple(sorted({c for e in self.effects for c in e.required_columns()}
                                    | ({"payload"} if self.effects else set())))
        self._row = _row_function(self.kinematics, self.effects, self.columns)
        self._maps: dict[tuple[int, int], ca.Function] = {}
        self._separable_functions: dict[int, SeparableResidual | None] = {}
        self._data_cache: dict[int, tuple] = {}
        self.frames = frames or StationFrames()
        self._x0 = self._initial(start or {})
        self.held = np.isin(np.asarray(self.unknowns.names, dtype=object),
                            list(self.frames.values)) & self.mask("placement")

    def __repr__(self) -> str:
        counts = {k: s.stop - s.start for k, s in self.slices.items()}
        return (f"Problem({self.robot.name!r}, datasets={[m.label for m in self.models]}, "
                f"effects={[e.label for e in self.effects]}, unknowns={counts})")

    # ------------------------------------------------------------------ layout helpers

    def mounted_indices(self, model: MeasurementModel) -> np.ndarray:
        return self.unknowns.indices(model.mounted.names)

    def placement_indices(self, model: MeasurementModel) -> np.ndarray:
        return self.unknowns.indices(model.placement.names)

    def free_placement(self) -> np.ndarray:
        """Mask over ``x`` of the placement unknowns that are fitted (not held)."""
        return self.mask("placement") & ~self.held

    def placement_frame(self, model: MeasurementModel) -> str:
        """How held-out ``model``'s placement is obtained: held as the calibration fitted
        its station, or refitted on the held-out data themselves."""
        held = bool(self.held[self.placement_indices(model)].any())
        if model.station is not None and held:
            return f"station {model.station} (fixed)"
        if model.station is not None:
            return f"station {model.station}, refitted on the validation data"
        return "refitted on the validation data"

    def mask(self, *keys: str) -> np.ndarray:
        """Boolean mask over ``x`` selecting whole blocks ('robot', 'placement', ...)."""
        mask = np.zeros(len(self.unknowns), dtype=bool)
        for key in keys:
            mask[self.slices[key]] = True
        return mask

    # ------------------------------------------------------------------ data per model

    def _effect_constants(self) -> np.ndarray:
        """The effects' constants (``Effect.constants``), in effect order."""
        parts = [np.asarray(e.constants(), dtype=float).ravel() for e in self.effects]
        return np.concatenate(parts) if parts else np.zeros(0)

    def _data(self, model: MeasurementModel):
        """``(Q dof x N, extras columns x N, payload_com 3)`` of ``model``'s rows, built once
        per dataset (read-only: every residual and Jacobian evaluation reads them)."""
        cached = self._data_cache.get(id(model.dataset))
        if cached is not None and cached[0] is model.dataset:
            return cached[1]
        data = self._build_data(model)
        for array in data:
            array.flags.writeable = False
        self._data_cache[id(model.dataset)] = (model.dataset, data)
        return data

    def _build_data(self, model: MeasurementModel):
        dataset = model.dataset
        n = dataset.rows
        extras = np.zeros((len(self.columns), n))
        for i, column in enumerate(self.columns):
            if column in dataset.extras:
                extras[i] = np.asarray(dataset.extras[column], dtype=float)
            elif is_derived_column(column):  # derived from the full table's row order
                extras[i] = direction_values(dataset, column)
            elif column != "payload":
                raise InputError(f"effect needs a {column!r} column", file=dataset.data_path)
        payload_com = np.array(dataset.payload_com if dataset.payload_com is not None
                               else np.zeros(3), dtype=float)
        return np.array(dataset.joints.T, dtype=float), extras, payload_com

    def _mapped(self, which: int, rows: int) -> ca.Function:
        """The row function ``which`` mapped over ``rows`` rows. Below ``COMPILE_ROWS`` it
        evaluates every residual, on two threads; from there on the compiled batches do
        that and this map serves a few calls (the initial placement), in series: a
        threaded map holds work memory that grows with the rows (tens of MB at 10,000),
        for the same numbers."""
        key = (which, rows)
        if key not in self._maps:
            self._maps[key] = mapped(self._row[which], rows)
        return self._maps[key]

    def points_numeric(self, model: MeasurementModel, x: np.ndarray):
        """``offsets -> world positions (3 x N)`` [m] for the robot/effects in ``x``."""
        p, theta = x[self.slices["robot"]], x[self.slices["effects"]]
        Q, extras, payload_com = self._data(model)
        mapped = self._mapped(0, model.dataset.rows)

        def points(offsets):
            return np.asarray(mapped(Q, extras, p, theta, np.asarray(offsets, float),
                                     payload_com, self._effect_constants()))

        return points

    def _initial(self, start: dict[str, float]) -> np.ndarray:
        x = np.zeros(len(self.unknowns))
        x[self.slices["robot"]] = self.kinematics.registry.vector_of(self.robot)
        for model in self.models:
            x[self.mounted_indices(model)] = model.initial_mounted()
        for name, value in start.items():
            if name in self.unknowns:
                x[self.unknowns.index(name)] = value
        leaders = dict(self.frames.leaders)
        assigned = np.zeros(len(x), dtype=bool)
        placed = []
        for model in self.models:
            mounted = x[self.mounted_indices(model)]
            # Pendant-pose data carry their own flange poses: no robot points to offer.
            points = self.points_numeric(model, x) if model.uses_robot else None
            model, values = model.placed(points, mounted)
            if model.station is not None:  # the station's first model sets its reference
                leader = leaders.setdefault(model.station, model)
                if leader is not model:
                    model = model.follow(leader)
            placed.append(model)
            for index, name, value in zip(self.placement_indices(model), model.placement.names,
                                          values):
                if name in self.frames.values:
                    x[index] = self.frames.values[name]
                elif not assigned[index]:
                    x[index] = value
                assigned[index] = True
        self.models = tuple(placed)
        return x

    def initial(self) -> np.ndarray:
        """Starting point: given/nominal robot, zero effects, nominal mounted, placement fitted."""
        return self._x0.copy()

    # ------------------------------------------------------------------ residual functions
    #
    # The residual of a model is r = g(P, x) with P (3 x N) the world points of its rows.
    # P comes from the per-row SX function (cheap, mapped); g is the model's MX expression
    # with P as an input. The Jacobian is assembled by the chain rule
    #     dr/dx = dg/dx + dg/dP M,   M = dP/dp E_p + dP/dtheta E_theta + dP/doffset doffset/dx
    # where dg/dP M is one forward derivative of g with the columns of M as directions.

    @cached_property
    def _compiled(self) -> tuple[CompiledModel, ...]:
        nx = len(self.unknowns)
        x = ca.MX.sym("x", nx)
        return tuple(_compile(model, x, self.mounted_indices(model),
                              self.placement_indices(model)) for model in self.models)

    @cached_property
    def _point_batch(self):
        return _batch(self._row[0], ("q", "extras", "offset"), True)

    @cached_property
    def _row_batch(self):
        rows = max((m.dataset.rows for m in self.models), default=0)
        return _batch(self._row[1], ("q", "extras", "offset"), rows >= COMPILE_ROWS)

    def _separable(self, model: MeasurementModel) -> SeparableResidual | None:
        """Compiled row-by-row residual and Jacobian of a separable model, or None."""
        key = id(model)
        if key not in self._separable_functions:
            separable = model.separable and model.per_row
            self._separable_functions[key] = \
                self._compile_separable(model) if separable else None
        return self._separable_functions[key]

    def _compile_separable(self, model: MeasurementModel) -> SeparableResidual:
        row = self._row[0]
        q, extras, p, theta, _, payload_com, effect_constants = (row.sx_in(i) for i in range(7))
        data = ca.SX.sym("data", model.row_data().shape[1])
        mounted = ca.SX.sym("mounted", len(model.mounted))
        placement = ca.SX.sym("placement", len(model.placement))
        constants = ca.SX.sym("constants", len(model.row_constants()))
        point = row(q, extras, p, theta, model.row_offset(data, mounted), payload_com,
                    effect_constants)
        r = model.row_residual(point, data, mounted, placement, constants)
        unknowns = ca.vertcat(p, theta, mounted, placement)
        inputs = [q, extras, data, p, theta, mounted, placement, payload_com, constants,
                  effect_constants]
        names = ["q", "extras", "data", "p", "theta", "mounted", "placement", "payload_com",
                 "constants", "effect_constants"]
        compile = model.dataset.rows >= COMPILE_ROWS
        per_row = ("q", "extras", "data")
        residual = ca.Function("row_residual", inputs, [r], names, ["r"])
        jacobian = ca.Function("row_residual_jacobian", inputs, [r, ca.jacobian(r, unknowns)],
                               names, ["r", "J"])
        columns = np.concatenate([np.arange(self.slices["robot"].start, self.slices["robot"].stop),
                                  np.arange(self.slices["effects"].start,
                                            self.slices["effects"].stop),
                                  self.mounted_indices(model), self.placement_indices(model)])
        return SeparableResidual(_batch(residual, per_row, compile),
                                 _batch(jacobian, per_row, compile), columns)

    def _separable_arguments(self, model: MeasurementModel, x: np.ndarray) -> tuple:
        """The inputs of a separable model's row functions at ``x``."""
        Q, extras, payload_com = self._data(model)
        return (Q.T, extras.T, model.row_data(), x[self.slices["robot"]],
                x[self.slices["effects"]], x[self.mounted_indices(model)],
                x[self.placement_indices(model)], payload_com, model.row_constants(),
                self._effect_constants())

    def _separable_jacobian(self, model: MeasurementModel, functions: SeparableResidual,
                            x: np.ndarray, columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residual and Jacobian ``columns`` of a separable model, row by row.

        Evaluated in blocks of ``JACOBIAN_BLOCK`` rows, each copied into place: the
        function's own output (every unknown it sees, in its layout) never exists for all
        rows at once. Rows are independent, so the numbers are those of one call."""
        arguments = self._separable_arguments(model, x)
        varying = functions.jacobian.per_row
        rows = model.dataset.rows
        position = np.full(len(self.unknowns), -1)
        position[columns] = np.arange(len(columns))
        source = np.flatnonzero(position[functions.columns] >= 0)
        runs = _runs(source, position[functions.columns[source]])
        r_parts, J = [], None
        for start in range(0, max(rows, 1), JACOBIAN_BLOCK):
            block = [a[start:start + JACOBIAN_BLOCK] if v else a
                     for a, v in zip(arguments, varying)]
            r, J_rows = functions.jacobian(*block)
            J_rows = J_rows.reshape(r.shape[0], r.shape[1], len(functions.columns))
            if J is None:
                J = np.zeros((rows, J_rows.shape[1], len(columns)))
            # Copied run by run of consecutive columns: no full-size temporary.
            for (a, b), (c, d) in runs:
                J[start:start + len(r), :, c:d] = J_rows[:, :, a:b]
            r_parts.append(r.ravel())
        r_all = np.concatenate(r_parts)
        assert J is not None
        return r_all, J.reshape(r_all.size, len(columns))

    def _model_values(self, compiled: CompiledModel, x: np.ndarray) -> np.ndarray:
        """Residual of one model at ``x``."""
        if isinstance(compiled, DirectResidual):
            return np.asarray(compiled.residual(x)).ravel()
        separable = self._separable(compiled.model)
        if separable is not None:
            (r,) = separable.residual(*self._separable_arguments(compiled.model, x))
            return r.ravel()
        return self._point_residual(compiled, x)

    def _model_jacobian(self, compiled: CompiledModel, x: np.ndarray,
                        columns: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Residual of one model and its Jacobian's ``columns`` (default all)."""
        columns = np.arange(len(self.unknowns)) if columns is None else np.asarray(columns)
        if isinstance(compiled, DirectResidual):
            return (np.asarray(compiled.residual(x)).ravel(),
                    np.asarray(compiled.jacobian(x).full())[:, columns])
        separable = self._separable(compiled.model)
        if separable is not None:
            return self._separable_jacobian(compiled.model, separable, x, columns)
        return self._chain_rule(compiled, x, columns)

    def _point_residual(self, compiled: PointResidual, x: np.ndarray) -> np.ndarray:
        """Residual of a non-separable model that reads world points, at ``x``."""
        P_flat = self._points(compiled, x).ravel()
        return np.asarray(compiled.residual(P_flat, x)).ravel()

    def _points(self, compiled: PointResidual, x: np.ndarray) -> np.ndarray:
        """World points (rows x 3) [m] of a non-separable point model's rows at ``x``."""
        model = compiled.model
        rows = model.dataset.rows
        offsets = np.asarray(compiled.offsets(x)[0])
        Q, extras, payload_com = self._data(model)
        p, theta = x[self.slices["robot"]], x[self.slices["effects"]]
        if rows >= COMPILE_ROWS:
            per_row_offsets = np.broadcast_to(offsets.T, (rows, 3)) if offsets.shape[1] == 1 \
                else offsets.T
            (P,) = self._point_batch(Q.T, extras.T, p, theta, per_row_offsets, payload_com,
                                     self._effect_constants())
            return P
        return np.asarray(self._mapped(0, rows)(
            Q, extras, p, theta, offsets, payload_com, self._effect_constants())).T

    def _point_motion(self, compiled: PointResidual, x: np.ndarray, columns: np.ndarray,
                      position: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """World points (rows x 3) [m] and ``M = dP/dx`` for the requested ``columns``
        (3 rows x k; ``position``: each unknown's place among them, -1 if not asked for).

        ``M`` is None when no requested unknown moves a point (only the model's own, its
        frame or its sockets): then the points alone are evaluated, not their derivatives
        with respect to every robot and effect parameter."""
        model = compiled.model
        rows = model.dataset.rows
        offsets, d_offsets = compiled.offsets(x)
        d_offsets = np.asarray(d_offsets.full())[:, columns]
        moved = [key for key in ("robot", "effects")
                 if (position[self.slices[key].start:self.slices[key].stop] >= 0).any()]
        if not moved and not d_offsets.any():
            return self._points(compiled, x), None
        offsets = np.asarray(offsets)
        Q, extras, payload_com = self._data(model)
        p, theta = x[self.slices["robot"]], x[self.slices["effects"]]
        per_row_offsets = np.broadcast_to(offsets.T, (rows, 3)) if offsets.shape[1] == 1 \
            else offsets.T
        P, J_p, J_theta, J_offset = self._row_batch(Q.T, extras.T, p, theta, per_row_offsets,
                                                    payload_com, self._effect_constants())
        M = np.zeros((rows, 3, len(columns)))
        for key, block in (("robot", J_p), ("effects", J_theta)):
            block = block.reshape(rows, 3, -1)  # a one-column block comes back as rows x 3
            index = np.arange(self.slices[key].start, self.slices[key].stop)
            keep = position[index] >= 0
            if keep.any():
                M[:, :, position[index[keep]]] = block[:, :, keep]
        if d_offsets.shape[0] == 3:  # one offset for every row
            M += np.einsum("nij,jk->nik", J_offset, d_offsets)
        else:
            M += np.einsum("nij,njk->nik", J_offset, d_offsets.reshape(rows, 3, len(columns)))
        return P, M.reshape(3 * rows, len(columns))

    def _chain_rule(self, compiled: PointResidual, x: np.ndarray,
                    columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residual and Jacobian ``columns`` of a non-separable point model, by the chain rule."""
        position = np.full(len(self.unknowns), -1)
        position[columns] = np.arange(len(columns))
        P, M = self._point_motion(compiled, x, columns, position)
        P_flat = P.ravel()
        r = np.asarray(compiled.residual(P_flat, x)).ravel()
        g_P, g_x = (np.array(v.nonzeros()) for v in compiled.derivatives(P_flat, x))
        J = np.zeros((len(r), len(columns)))
        rows_x, cols_x = compiled.g_x_rows, compiled.g_x_columns
        wanted = position[cols_x] >= 0
        np.add.at(J, (rows_x[wanted], position[cols_x[wanted]]), g_x[wanted])
        if len(g_P) and M is not None:
            order = compiled.g_P_order
            sorted_rows = compiled.g_P_rows[order]
            starts = np.flatnonzero(np.r_[True, sorted_rows[1:] != sorted_rows[:-1]])
            contributions = g_P[order, None] * M[compiled.g_P_columns[order]]
            J[sorted_rows[starts]] += np.add.reduceat(contributions, starts, axis=0)
        return r, J

    def residual(self, x: np.ndarray) -> np.ndarray:
        """Stacked residual [m] at ``x``."""
        x = np.asarray(x, float)
        parts = [self._model_values(compiled, x) for compiled in self._compiled]
        return np.concatenate(parts) if parts else np.zeros(0)

    def jacobian(self, x: np.ndarray, columns: np.ndarray | None = None) -> np.ndarray:
        """Dense Jacobian d residual / d x at ``x`` (exact, by the chain rule above).

        ``columns`` (indices or a boolean mask over ``x``) restricts it to those unknowns.
        """
        if columns is not None and np.asarray(columns).dtype == bool:
            columns = np.flatnonzero(columns)
        x = np.asarray(x, float)
        parts = [self._model_jacobian(compiled, x, columns)[1] for compiled in self._compiled]
        return parts[0] if len(parts) == 1 else np.vstack(parts)

    def row_sensitivities(self, x: np.ndarray, parameters: Sequence[int] | np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """How each residual entry moves when a geometric parameter changes in one row only.

        For a parameter ``p_c`` (indices into the robot slice of ``x``) that took another
        value in data row ``k`` alone, residual entry ``i`` moves by
        ``S_c[i, k] = dr_i/dP_k . dP_k/dp_c`` [m per unit of p_c], with ``P_k`` the row's
        world point. Returned sparse as ``(entries, rows, values)``: entry indices into the
        stacked residual, row indices into the stacked data rows of all models (in model
        order), and one value per parameter (nnz x len(parameters)). Rows of models that
        carry their own flange poses have no such sensitivity.
        """
        x = np.asarray(x, float)
        chosen = np.asarray(parameters, dtype=int)
        robot_columns = np.arange(self.slices["robot"].start, self.slices["robot"].stop)
        entries, rows, values = [], [], []
        entry_offset = row_offset = 0
        for compiled in self._compiled:
            model = compiled.model
            size, n_rows = model.residual_size(), model.dataset.rows
            if isinstance(compiled, PointResidual) and model.uses_robot:
                separable = self._separable(model)
                if separable is not None:
                    J = self._separable_jacobian(model, separable, x, robot_columns[chosen])[1]
                    per_row = size // max(n_rows, 1)
                    index = np.arange(per_row * n_rows)
                    entries.append(entry_offset + index)
                    rows.append(row_offset + index // per_row)
                    values.append(J[index])
                else:
                    i, k, v = self._point_sensitivities(compiled, x, chosen)
                    entries.append(entry_offset + i)
                    rows.append(row_offset + k)
                    values.append(v)
            entry_offset += size
            row_offset += n_rows
        if not entries:
            return np.zeros(0, int), np.zeros(0, int), np.zeros((0, len(chosen)))
        return np.concatenate(entries), np.concatenate(rows), np.vstack(values)

    def _point_sensitivities(self, compiled: PointResidual, x: np.ndarray,
                             parameters: np.ndarray
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``row_sensitivities`` of one non-separable model, by the chain rule."""
        model = compiled.model
        n_rows = model.dataset.rows
        offsets = np.asarray(compiled.offsets(x)[0])
        Q, extras, payload_com = self._data(model)
        p, theta = x[self.slices["robot"]], x[self.slices["effects"]]
        per_row_offsets = np.broadcast_to(offsets.T, (n_rows, 3)) if offsets.shape[1] == 1 \
            else offsets.T
        P, J_p, _, _ = self._row_batch(Q.T, extras.T, p, theta, per_row_offsets, payload_com,
                                       self._effect_constants())
        J_p = J_p.reshape(n_rows, 3, -1)[:, :, parameters]
        g_P = np.array(compiled.derivatives(P.ravel(), x)[0].nonzeros())
        rows_P, cols_P = compiled.g_P_rows, compiled.g_P_columns
        row, axis = cols_P // 3, cols_P % 3
        contributions = g_P[:, None] * J_p[row, axis]
        key = rows_P.astype(np.int64) * n_rows + row
        unique, inverse = np.unique(key, return_inverse=True)
        summed = np.zeros((len(unique), len(parameters)))
        np.add.at(summed, inverse, contributions)
        return unique // n_rows, unique % n_rows, summed

    def symbolic_residual(self, x: ca.MX) -> ca.MX:
        """The residual as one CasADi MX expression of ``x`` (for IPOPT)."""
        p, theta = x[self.slices["robot"]], x[self.slices["effects"]]
        parts = []
        for compiled in self._compiled:
            model = compiled.model
            if isinstance(compiled, DirectResidual):
                parts.append(compiled.residual(x))
                continue
            Q, extras, payload_com = self._data(model)
            offsets = compiled.offsets(x)[0]
            P = self._mapped(0, model.dataset.rows)(Q, extras, p, theta, offsets, payload_com,
                                                    self._effect_constants())
            parts.append(compiled.residual(ca.vec(P), x))
        return ca.vertcat(*parts)

    @property
    def size(self) -> int:
        return sum(model.residual_size() for model in self.models)

    def split(self, r: np.ndarray) -> list[np.ndarray]:
        """Split a stacked residual into per-model pieces."""
        out, start = [], 0
        for model in self.models:
            size = model.residual_size()
            out.append(r[start:start + size])
            start += size
        return out

    def certified_entries(self) -> np.ndarray:
        """Mask over the stacked residual of the entries that compare fitted unknowns with
        an instrument's certified geometry (``MeasurementModel.certified_entries``)."""
        parts = [np.asarray(m.certified_entries(), bool) for m in self.models]
        return np.concatenate(parts) if parts else np.zeros(0, bool)

    def errors(self, x: np.ndarray) -> list[np.ndarray]:
        """Per-dataset per-measurement error lengths [m] at ``x``."""
        return [model.errors(r) for model, r in zip(self.models, self.split(self.residual(x)))]

    def rms(self, x: np.ndarray) -> float:
        """RMS over all datasets' per-measurement errors [m]."""
        errors = np.concatenate(self.errors(x))
        return float(np.sqrt(np.mean(errors**2))) if errors.size else float("nan")
