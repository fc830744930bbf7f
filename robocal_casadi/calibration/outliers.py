"""Gross errors: the readings no calibration of the robot explains, found and set aside.

A gross error (a tracker beam broken mid-reading, a probe slipped out of its socket, a
laser reading at grazing incidence, a mistyped row) is not noise: least squares spreads
it over every estimate. ``screen`` finds such readings:

1. a robust start: the Huber M-estimate (iteratively reweighted least squares, scale
   from the median absolute deviation) over the unknowns given as free;
2. the noise ``sigma`` of each kind of error of each dataset (position, surface,
   distance, perpendicularity), from the 80% quantile of the absolute residual entries
   over the units kept (1.28 sigma for normal noise), each entry divided by
   ``sqrt(1 - h)`` for its leverage ``h``; never below ``RESOLUTION``. The quantile,
   rather than the median, makes the scale follow errors the model does not yet explain
   (real data carry some until diagnosis has run): a reading in the tail of such a
   spread is the model's error, not a gross one. Gross errors on up to 20% of the
   units leave it nearly unchanged (5% raise it by about 10%). The touches of one
   socket are judged by the larger of that noise and their own spread, so that a
   socket the model misses for many of its touches is not mistaken for many gross
   errors;
3. per unit of data, the deletion statistic ``t = r^T V^-1 r`` with ``r`` the unit's
   residual entries divided by their ``sigma`` and ``V = I - H`` (``I + H`` for a unit set
   aside, whose residual is then a prediction), ``H`` the unit's block of the hat matrix
   of the noise-weighted Jacobian. For a unit holding only noise ``t`` follows chi^2 with
   as many degrees of freedom as the unit has entries; a unit above the
   ``1 - FALSE_ALARM`` quantile is set aside;
4. least squares on the units kept (those set aside weigh zero), then 2-3 again, until
   the set aside no longer changes (at most ``ROUNDS`` rounds).

The unit is what the instrument produces: a tracker point, a laser reading, a touch of
a socket touched several times; a bar (or artifact) placement with a socket touched
once, whose length or angle errors fail, is set aside whole (where every socket is
touched several times, each touch is judged on its own and the lengths between the
sockets' centres are not tested), with the touches that look wrong named (a bad touch
shows only in the errors of the sockets it touched: for a cross, touch A and touch C
show alike, so both are named). When more than ``MAX_SHARE`` of a dataset's readings
would go, the data are bad rather than the robot: ``InputError``.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg import qr, solve_triangular
from scipy.spatial import cKDTree
from scipy.special import gammaincinv, ndtri  # chi2.ppf, norm.ppf without scipy.stats' import

from ..errors import InputError
from ..instruments.datasets import dataset_rows
from ..results import RejectedReading
from .problem import Problem
from .solver import Method, solve

FALSE_ALARM = 1e-4  # probability that a unit holding only noise is set aside
MAX_SHARE = 0.2  # more of a dataset's readings than this set aside: the data are bad
ROUNDS = 6  # rounds of fit-and-test at most
RESOLUTION = 1e-8  # [m] noise floor: errors this small are rounding, never gross
SCALE_QUANTILE = 0.8  # the noise is read off this quantile of the absolute residuals ...
QUANTILE_SCALE = float(ndtri(0.5 + SCALE_QUANTILE / 2))  # ... which is this many sigma
MIN_ENTRIES = 12  # fewer residual entries of one kind: its noise is pooled with the dataset's
RANK_TOLERANCE = 1e-10  # relative size of a QR pivot below which a direction has no data
NEIGHBOURS = 3  # readings nearest in joint space that show whether an error repeats
UNTESTABLE = 1e-8  # V's smallest eigenvalue below this: the fit reproduces the unit whatever


@dataclass(frozen=True)
class Unit:
    """A unit of data that is kept or set aside whole.

    ``model`` indexes ``problem.models``; ``rows`` its data rows; ``entries`` indices
    into the stacked residual; ``errors`` indices into the model's ``errors``;
    ``reading`` what it is; ``suspect`` the touches that look wrong (placements).
    """

    model: int
    rows: tuple[int, ...]
    entries: np.ndarray
    errors: tuple[int, ...]
    reading: str
    kinds: tuple[str, ...]  # the error kind of each entry of ``entries``
    near: tuple = ()  # units with the same key share one placement unknown (a socket)


@dataclass(frozen=True)
class Screening:
    """What ``screen`` found: the units set aside and the estimate on the rest."""

    units: tuple[Unit, ...]
    rejected: tuple[int, ...]  # indices into ``units``
    statistic: np.ndarray  # per unit, t
    quantile: np.ndarray  # per unit, the chi^2 quantile it is compared with
    residual: np.ndarray  # per unit, |r| [m]
    weights: np.ndarray  # per residual entry: 0 set aside, 1 kept
    x: np.ndarray  # the least-squares estimate on the units kept
    sigma: np.ndarray  # per residual entry, the noise of its kind [m]

    def kept_rows(self, problem: Problem) -> list[np.ndarray]:
        """Per model, a mask over its readings: True where kept."""
        masks = [np.ones(readings(m.dataset), dtype=bool) for m in problem.models]
        for k in self.rejected:
            unit = self.units[k]
            masks[unit.model][list(unit.rows)] = False
        return masks

    def kept_errors(self, problem: Problem) -> list[np.ndarray]:
        """Per model, a mask over its ``errors``: True where kept."""
        masks = [np.ones(len(m.error_rows()), dtype=bool) for m in problem.models]
        for k in self.rejected:
            unit = self.units[k]
            masks[unit.model][list(unit.errors)] = False
        return masks


def readings(dataset) -> int:
    """How many readings (table rows) ``dataset`` holds (pendant scans have no joints)."""
    return dataset.readings


def units_of(problem: Problem) -> tuple[Unit, ...]:
    """Every unit of data of ``problem``, model by model (see the module docstring)."""
    out: list[Unit] = []
    start = 0
    for k, model in enumerate(problem.models):
        rows = model.error_rows()
        entries = model.error_entries()
        terms = model.error_terms()
        pose = getattr(model.dataset, "pose", None)
        placements: dict[int, list[int]] = {}
        for i, row in enumerate(rows):
            if row >= 0:
                near = (k, terms[i].pose, terms[i].points) if terms[i].points else ()
                out.append(Unit(k, (int(row),), start + entries[i], (i,), model.reading_name,
                                (terms[i].kind,) * len(entries[i]), near))
            elif i < len(terms) and terms[i].pose >= 0 and pose is not None:
                placements.setdefault(terms[i].pose, []).append(i)
        own = {int(r) for r in rows if r >= 0}
        for placement, errors in placements.items():
            members = tuple(int(r) for r in np.flatnonzero(np.asarray(pose) == placement))
            if own.issuperset(members):
                continue  # every touch is judged on its own: the sockets are averages
            index = np.concatenate([start + entries[i] for i in errors])
            kinds = tuple(terms[i].kind for i in errors for _ in entries[i])
            out.append(Unit(k, members, index, tuple(errors), "placement", kinds))
        start += model.residual_size()
    return tuple(out)


class _Weighted:
    """``problem`` with each residual entry multiplied by ``weights`` (0 or 1)."""

    def __init__(self, problem: Problem, weights: np.ndarray):
        self.problem = problem
        self.weights = weights

    def __getattr__(self, name):
        return getattr(self.problem, name)

    def residual(self, x: np.ndarray) -> np.ndarray:
        return self.problem.residual(x) * self.weights

    def jacobian(self, x: np.ndarray, columns=None) -> np.ndarray:
        return self.problem.jacobian(x, columns) * self.weights[:, None]

    def symbolic_residual(self, x):
        import casadi as ca

        return self.problem.symbolic_residual(x) * ca.DM(self.weights)


def screen(problem: Problem, x: np.ndarray, free: np.ndarray, *, method: Method = "lm",
           max_iterations: int = 200, robust_start: bool = True,
           rejected: tuple[int, ...] = ()) -> Screening:
    """Find the units of ``problem``'s data with gross errors; see the module docstring.

    ``x`` [SI] is the starting point, ``free`` the unknowns fitted (those the data
    determine, with the placements). ``robust_start=False`` starts the rounds from ``x``
    as it is: the least-squares fit of every unit but those ``rejected`` (indices into
    ``units_of(problem)``).
    """
    units = units_of(problem)
    if robust_start:
        x = solve(problem, x, free, method=method, loss="huber",
                  max_iterations=max_iterations).x
    rounds = functools.partial(_rounds, problem, units, free=free, method=method,
                               max_iterations=max_iterations)
    rejected, x, weights, tested = rounds(x, rejected, repeats=False)
    if rejected:  # then give back the errors that repeat where the configuration does
        rejected, x, weights, tested = rounds(x, rejected, repeats=True)
    statistic, quantile, residual, sigma = tested
    return Screening(units, rejected, statistic, quantile, residual, weights, x, sigma)


def _rounds(problem: Problem, units: Sequence[Unit], x: np.ndarray, rejected: tuple[int, ...],
            *, free: np.ndarray, method: Method, max_iterations: int, repeats: bool):
    """Test, set aside, refit, until the set aside no longer changes (step 4)."""
    weights = weights_of(problem, units, rejected)
    tested = _test(problem, units, x, free, weights, repeats)
    for _ in range(ROUNDS):
        found = tuple(int(k) for k in np.flatnonzero(tested[0] > tested[1]))
        if found == rejected:
            break
        rejected = found
        weights = weights_of(problem, units, rejected)
        x = refit(problem, x, free, weights, method=method, max_iterations=max_iterations)
        tested = _test(problem, units, x, free, weights, repeats)
    return rejected, x, weights, tested


def weights_of(problem: Problem, units: Sequence[Unit], rejected: Sequence[int]) -> np.ndarray:
    weights = np.ones(problem.size)
    for k in rejected:
        weights[units[k].entries] = 0.0
    return weights


def refit(problem: Problem, x: np.ndarray, free: np.ndarray, weights: np.ndarray, *,
          method: Method = "lm", max_iterations: int = 200) -> np.ndarray:
    """Least squares on the kept entries; unknowns only set-aside data reach stay put."""
    J = problem.jacobian(x, free) * weights[:, None]
    reached = free.copy()
    reached[np.flatnonzero(free)] = np.linalg.norm(J, axis=0) > 0
    return solve(_Weighted(problem, weights), x, reached, method=method,
                 max_iterations=max_iterations).x


def _test(problem: Problem, units: Sequence[Unit], x: np.ndarray, free: np.ndarray,
          weights: np.ndarray, repeats: bool = False
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per unit ``(t, chi^2 quantile, |r| [m])`` at ``x``, and the noise per entry [m];
    with ``repeats``, ``t`` of a reading is at most that of its error less its
    neighbours' (``_unrepeated``)."""
    r = problem.residual(x)
    J = problem.jacobian(x, free)
    kept = weights > 0
    W = _hat_factor(J, kept)
    leverage = np.where(kept, np.clip(np.sum(W * W, axis=1), 0.0, 1.0), 0.0)
    sigma = _noise(problem, units, r, leverage, kept)
    W = _hat_factor(J / sigma[:, None], kept)
    statistic = np.zeros(len(units))
    quantile = np.zeros(len(units))
    residual = np.zeros(len(units))
    sizes = np.array([len(unit.entries) for unit in units], dtype=int)
    for size in np.unique(sizes):
        members = np.flatnonzero(sizes == size)
        E = np.stack([units[int(k)].entries for k in members])  # (units, entries)
        t, ok = _statistics(r[E] / sigma[E], W[E], kept[E].all(axis=1))
        statistic[members] = np.where(ok, t, 0.0)
        quantile[members] = _quantile(int(size))
        residual[members] = np.sqrt(_dots(r[E], r[E]))
    if repeats:
        statistic = np.minimum(statistic, _unrepeated(problem, units, r / sigma))
    return statistic, quantile, residual, sigma


def _unrepeated(problem: Problem, units: Sequence[Unit], z: np.ndarray) -> np.ndarray:
    """Per unit of one reading, ``t`` of its residual ``z`` (in noise units) less the mean
    of those of the ``NEIGHBOURS`` readings nearest in joint space (same dataset, same
    socket, same size; kept or set aside); ``inf`` where there are too few or the
    dataset has no joint readings.

    A gross error does not repeat: where the readings taken in nearly the same
    configuration show the same error, the error is the model's, which the diagnosis
    is there to find, not a bad reading. (A run of more than ``NEIGHBOURS`` alike errors
    at neighbouring configurations is taken as the model's too.) The difference of one
    unit-noise residual and the mean of ``NEIGHBOURS`` others has variance
    ``1 + 1 / NEIGHBOURS``.
    """
    out = np.full(len(units), np.inf)
    groups: dict[tuple, list[int]] = {}
    for index, unit in enumerate(units):
        joints = getattr(problem.models[unit.model].dataset, "joints", None)
        if len(unit.rows) == 1 and unit.reading != "placement" and joints is not None:
            groups.setdefault((unit.model, unit.near, len(unit.entries)), []).append(index)
    for (model, _, _), members in groups.items():
        if len(members) <= NEIGHBOURS:
            continue
        joints = np.asarray(problem.models[model].dataset.joints)
        configurations = joints[[units[k].rows[0] for k in members]]
        _, near = cKDTree(configurations).query(configurations, k=NEIGHBOURS + 1)
        itself = near == np.arange(len(members))[:, None]
        order = np.argsort(itself, axis=1, kind="stable")[:, :NEIGHBOURS]  # itself last
        E = np.stack([units[k].entries for k in members])
        local = z[E[np.take_along_axis(near, order, axis=1)]].mean(axis=1)
        difference = z[E] - local
        out[members] = _dots(difference, difference) / (1.0 + 1.0 / NEIGHBOURS)
    return out


def _statistics(z: np.ndarray, W: np.ndarray, kept: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``t = z^T V^-1 z`` for a stack of units of one size (``z`` (units, m) residual
    entries over their noise, ``W`` (units, m, rank) their rows of the hat factor,
    ``kept`` per unit), and whether ``V`` lets the unit be tested at all."""
    H = W @ np.swapaxes(W, 1, 2)
    V = np.eye(z.shape[1]) + np.where(kept[:, None, None], -H, H)
    ok = np.linalg.eigvalsh(V).min(axis=1) >= UNTESTABLE
    V[~ok] = np.eye(z.shape[1])  # untestable: not solved (its t stays 0)
    y = np.linalg.solve(V, z[:, :, None])[:, :, 0]
    return _dots(z, y), ok


def _dots(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of two stacks of vectors, each as ``a[k] @ b[k]`` rounds."""
    return np.matmul(a[:, None, :], b[:, :, None])[:, 0, 0]


@functools.cache
def _quantile(entries: int) -> float:
    """The ``1 - FALSE_ALARM`` quantile of chi^2 with ``entries`` degrees of freedom."""
    return float(2.0 * gammaincinv(entries / 2, 1.0 - FALSE_ALARM))


def _hat_factor(J: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """``W`` with ``W W^T`` the hat matrix of the ``kept`` rows of ``J`` extended to every
    row (``J (J_k^T J_k)^+ J^T``), from a pivoted QR of the column-scaled kept rows."""
    norms = np.linalg.norm(J[kept], axis=0)
    used = np.flatnonzero(norms > 0)
    Js = J[:, used] / norms[used]
    if not len(used):
        return np.zeros((len(J), 0))
    _, R, pivot = qr(Js[kept], mode="economic", pivoting=True)
    diagonal = np.abs(np.diag(R))
    rank = int(np.sum(diagonal > RANK_TOLERANCE * diagonal[0])) if diagonal.size else 0
    R = R[:rank, :rank]
    return solve_triangular(R, Js[:, pivot[:rank]].T, trans="T").T


def _noise(problem: Problem, units: Sequence[Unit], r: np.ndarray, leverage: np.ndarray,
           kept: np.ndarray) -> np.ndarray:
    """Per residual entry, the noise of its kind in its dataset [m] (module docstring)."""
    kind = np.full(problem.size, "", dtype=object)
    model = np.full(problem.size, -1)
    for unit in units:
        kind[unit.entries] = unit.kinds
        model[unit.entries] = unit.model
    scaled = np.abs(r) / np.sqrt(np.clip(1.0 - leverage, 1e-6, None))
    sigma = np.full(problem.size, RESOLUTION)
    for k in range(len(problem.models)):
        mine = (model == k) & kept
        pooled = _mad(scaled[mine])
        for name in set(kind[model == k]):
            group = mine & (kind == name)
            value = _mad(scaled[group]) if group.sum() >= MIN_ENTRIES else pooled
            sigma[(model == k) & (kind == name)] = max(value, RESOLUTION)
    # Readings of one socket spread more than the dataset's when the model errs there
    # alike for many of them: their own spread is then the noise they are judged by.
    near: dict[tuple, list[np.ndarray]] = {}
    for unit in units:
        if unit.near:
            near.setdefault(unit.near, []).append(unit.entries)
    for parts in near.values():
        entries = np.concatenate(parts)  # those set aside too: a cluster is no gross error
        if len(entries) >= MIN_ENTRIES:
            sigma[entries] = np.maximum(sigma[entries], _mad(scaled[entries]))
    return sigma


def _mad(values: np.ndarray) -> float:
    """Standard deviation of zero-mean normal values from the ``SCALE_QUANTILE`` quantile
    of their absolute values (robust to that share of gross errors less a margin)."""
    return float(np.quantile(values, SCALE_QUANTILE)) / QUANTILE_SCALE if values.size else 0.0


def suspects(problem: Problem, unit: Unit, r: np.ndarray, sigma: np.ndarray) -> str:
    """The touches of a placement whose errors alone explain what failed, e.g.
    ``"touch A or C"`` (a bad touch moves only the errors of the sockets it touched)."""
    model = problem.models[unit.model]
    terms = model.error_terms()
    entries = model.error_entries()
    start = sum(m.residual_size() for m in problem.models[:unit.model])
    misfit: dict[str, float] = {}
    sockets = sorted({s for i in unit.errors for s in terms[i].points})
    for socket in sockets:
        left = [i for i in unit.errors if socket not in terms[i].points]
        misfit[socket] = sum(float(np.sum((r[start + entries[i]]
                                           / sigma[start + entries[i]]) ** 2)) for i in left)
    if not misfit:
        return ""
    best = min(misfit.values())
    named = [s for s in sockets if misfit[s] <= best + 1e-9 * max(best, 1.0) + 1e-12]
    return "touch " + " or ".join(named)


def rejected_readings(problem: Problem, screening: Screening, role: str = "fit"
                      ) -> tuple[RejectedReading, ...]:
    """The units ``screening`` set aside, as ``RejectedReading`` rows (table order)."""
    r = problem.residual(screening.x)
    out = []
    for k in screening.rejected:
        unit = screening.units[k]
        dataset = problem.models[unit.model].dataset
        lines = tuple(dataset.line(row) for row in unit.rows)
        suspect = ""
        line = lines[0] if lines else -1
        if unit.reading == "placement":
            suspect = suspects(problem, unit, r, screening.sigma)
            named = suspect.removeprefix("touch ").split(" or ")
            points = getattr(dataset, "point", ())
            for row in unit.rows:
                if row < len(points) and points[row] in named:
                    line = dataset.line(row)
                    break
        t, q = screening.statistic[k], screening.quantile[k]
        residual = float(screening.residual[k])
        threshold = residual * float(np.sqrt(q / t)) if t > 0 else float("inf")
        table = dataset.data_path.name if dataset.data_path is not None else dataset.path.name
        out.append(RejectedReading(dataset.path.name, table, line, lines, unit.rows, residual,
                                   threshold, unit.reading, suspect, role,
                                   _position(problem, unit, screening.x), str(dataset.path)))
    return tuple(sorted(out, key=lambda e: (e.dataset, e.line)))


def _position(problem: Problem, unit: Unit, x: np.ndarray) -> tuple[float, float, float]:
    """Where the unit's point lay [m], base frame (mean over its rows)."""
    model = problem.models[unit.model]
    rows = list(unit.rows)
    if model.uses_robot:
        offset = x[problem.mounted_indices(model)][:3].reshape(3, 1)
        world = np.asarray(problem.points_numeric(model, x)(offset))[:, rows]
    else:
        world = np.asarray(model.dataset.flange_poses)[rows, :3, 3].T
    centre = world.mean(axis=1)
    return float(centre[0]), float(centre[1]), float(centre[2])


def exceeds_share(problem: Problem, screening: Screening) -> bool:
    """Whether more than ``MAX_SHARE`` of some dataset's readings would be set aside."""
    return any(kept.size and (~kept).sum() > MAX_SHARE * kept.size
               for kept in screening.kept_rows(problem))


def check_share(problem: Problem, screening: Screening) -> None:
    """Refuse data of which more than ``MAX_SHARE`` would be set aside (``InputError``)."""
    for model, kept in zip(problem.models, screening.kept_rows(problem)):
        if kept.size and (~kept).sum() > MAX_SHARE * kept.size:
            dataset = model.dataset
            raise InputError(
                f"{int((~kept).sum())} of {kept.size} readings are gross errors (more than "
                f"{MAX_SHARE:.0%}): the data are bad, not the robot; check the instrument "
                f"and the table", file=dataset.data_path or dataset.path)


SHOWN = 5  # set-aside readings named on the terminal


def rejected_lines(rejected: Sequence[RejectedReading], units) -> list[str]:
    """Terminal lines: how many units were set aside as gross errors, the first few named."""
    if not rejected:
        return ["gross errors: none found (no reading set aside)"]
    out = []
    for role in ("fit", "validation"):
        mine = [e for e in rejected if e.role == role]
        if not mine:
            continue
        more = f" (the first {SHOWN} below; all in result.json)" if len(mine) > SHOWN else ""
        out.append(f"gross errors: {len(mine)} unit(s) of the {role} data set aside{more}")
        out += ["  " + e.sentence(units) for e in mine[:SHOWN]]
    return out


def kept_datasets(datasets: Sequence, rejected: Sequence[RejectedReading], role: str) -> list:
    """``datasets`` without the rows ``rejected`` set aside in ``role`` (``"fit"`` or
    ``"validation"``), e.g. to evaluate another model on the same readings kept."""
    out = []
    for dataset in datasets:
        keep = np.ones(readings(dataset), dtype=bool)
        mine = [entry for entry in rejected
                if entry.role == role and entry.path == str(dataset.path)]
        if mine:
            table_lines = [dataset.line(i) for i in range(len(keep))]
            keep &= ~np.isin(table_lines, [line for entry in mine for line in entry.lines])
        out.append(dataset if keep.all() else dataset_rows(dataset, keep))
    return out
