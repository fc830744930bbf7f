"""Maximum a posteriori identification: what the data say, weighed against tolerances.

Each robot and mounted parameter has a tolerance ``t_i``: how far it may plausibly be off
its nominal value ``x0_i`` (one standard deviation of a Gaussian prior, SI). With noise
``sigma`` [m] on every residual entry, the estimate minimises

    0.5 |r(x)|^2 + 0.5 sum_i (sigma / t_i)^2 (x_i - x0_i)^2,

the least-squares problem with one extra residual row ``(sigma / t_i)(x_i - x0_i)`` per
parameter. A parameter the data determine well (standard error far below ``t_i``) is
estimated as by least squares; one they barely touch stays near nominal instead of
being fitted to noise (a reflector offset along the flange axis that the tracker frame
nearly absorbs). ``sigma`` is estimated from the fit itself:
``sigma^2 = RSS / (m - n_effective)`` with ``n_effective`` the degrees of freedom the fit
spends (placements plus the data's share of each parameter), iterated to a fixed point.

Posterior covariance: ``sigma^2 (J^T J + sigma^2 P)^-1``, ``P = diag(1 / t_i^2)``. The
data's share of parameter ``i`` is ``1 - Sigma_ii / t_i^2`` (1: the data alone, 0: the
prior alone); below one half the prior dominates and the estimate says more about the
tolerance than about the robot.

Default tolerances per kind of parameter (``DEFAULT_TOLERANCE``); a robot file's
``tolerance:`` entries override them (``robot.Robot.tolerance``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .solver import CONVERGED_DECREASE

DEGREE = math.pi / 180.0
DEFAULT_TOLERANCE = {
    "dh_length": 1e-3,           # [m] d, a of a joint
    "dh_angle": 0.5 * DEGREE,    # [rad] theta, alpha, beta of a joint
    "frame_length": 10e-3,       # [m] base and tool position
    "frame_angle": 1.0 * DEGREE,  # [rad] base and tool rpy
    "instrument_length": 5e-3,   # [m] probe, target, laser origin in the flange frame
    "instrument_direction": 3.0 * DEGREE,  # [rad ~ unit vector component] laser beam
}
SIGMA_ITERATIONS = 6  # fixed-point rounds for the noise estimate
SIGMA_SETTLED = 0.02  # relative change of sigma that ends the rounds
SETTLED_DECREASE = 1e-6  # [sigma^2] a MAP step lowering the cost by less: the fit has settled


def settled_decrease(problem) -> float:
    """The relative cost decrease of a step below which a maximum a posteriori fit of
    ``problem`` has settled: ``SETTLED_DECREASE`` sigma^2 against a cost near
    ``0.5 m sigma^2`` (``m`` residual entries), that is ``2 SETTLED_DECREASE / m``.

    Along directions the prior mostly decides, Gauss-Newton converges only linearly (the
    data's curvature nearly cancels there); past this point a step moves the estimate by a
    negligible part of its standard error, and demanding a decrease at rounding level
    would only crawl on."""
    return max(CONVERGED_DECREASE, 2.0 * SETTLED_DECREASE / max(problem.size, 1))


def kind_of(name: str, quantity: str) -> str | None:
    """The kind of parameter ``name`` (a key of ``DEFAULT_TOLERANCE``); None: no prior."""
    if name.startswith(("probe_", "target_", "laser_")):
        return "instrument_length" if quantity == "length" else "instrument_direction"
    if name.startswith(("base_", "tool_", "flange_")):
        return "frame_length" if quantity == "length" else "frame_angle"
    stem = name.rstrip("0123456789")
    if stem in ("d", "a", "x", "y", "z"):  # x, y, z: a URDF joint origin, like d and a
        return "dh_length"
    if stem in ("theta", "alpha", "beta", "roll", "pitch", "yaw"):
        return "dh_angle"
    return None


def tolerance_of(name: str, quantity: str, robot) -> float | None:
    """Tolerance [SI] of parameter ``name``: the robot file's, else the default of its kind."""
    given = getattr(robot, "tolerance", None) or {}
    if name in given:
        return float(given[name])
    kind = kind_of(name, quantity)
    if kind is None:
        return None
    return float(given.get(kind, DEFAULT_TOLERANCE[kind]))


@dataclass(frozen=True)
class Prior:
    """Gaussian prior on ``x[index]`` (parameters ``names``): centre [SI], tolerance [SI]
    (the square root of its covariance's diagonal), noise ``sigma`` [m].

    ``root`` (None: the parameters are independent, ``diag(1 / tolerance)``) is a matrix
    ``W`` with ``W^T W = C^-1`` for a full prior covariance ``C`` [SI^2] (a population
    prior learned from a fleet, ``population``); the prior's residual rows are then
    ``sigma W (x[index] - centre)``.
    """

    names: tuple[str, ...]
    index: np.ndarray
    centre: np.ndarray
    tolerance: np.ndarray
    sigma: float
    root: np.ndarray | None = None

    @property
    def weights(self) -> np.ndarray:
        """``sigma / t_i`` [1 / (SI of the parameter) * m]: the prior rows' weights (of the
        independent prior; see ``rows``)."""
        return self.sigma / self.tolerance

    @property
    def rows(self) -> np.ndarray:
        """``sigma W``: the prior rows' coefficients (k x k)."""
        if self.root is None:
            return np.diag(self.weights)
        return self.sigma * self.root

    @property
    def precision(self) -> np.ndarray:
        """``C^-1`` [1/SI^2]: the prior's precision matrix."""
        if self.root is None:
            return np.diag(1.0 / self.tolerance**2)
        return self.root.T @ self.root

    @property
    def covariance(self) -> np.ndarray:
        """``C`` [SI^2]: the prior's covariance matrix."""
        if self.root is None:
            return np.diag(self.tolerance**2)
        inverse_root = np.linalg.inv(self.root)
        return inverse_root @ inverse_root.T

    def with_sigma(self, sigma: float) -> Prior:
        return replace(self, sigma=float(sigma))

    def placed_in(self, problem) -> Prior:
        """The prior in ``problem``'s layout (same names; effects may shift the indices)."""
        return replace(self, index=problem.unknowns.indices(self.names))

    @classmethod
    def correlated(cls, names: tuple[str, ...], index: np.ndarray, centre: np.ndarray,
                   covariance: np.ndarray, sigma: float) -> Prior:
        """The prior ``N(centre, covariance)`` [SI, SI^2] with its full covariance."""
        covariance = 0.5 * (np.asarray(covariance, float) + np.asarray(covariance, float).T)
        lower = np.linalg.cholesky(covariance)
        root = np.linalg.solve(lower, np.eye(len(names)))  # L^-1: (L^-1)^T L^-1 = C^-1
        return cls(names, np.asarray(index, int), np.asarray(centre, float),
                   np.sqrt(np.diag(covariance)), float(sigma), root)

    def __repr__(self) -> str:
        kind = "independent" if self.root is None else "correlated"
        return f"Prior({len(self.index)} parameters, {kind}, sigma={self.sigma:.3g} m)"


class PriorProblem:
    """A ``Problem`` whose residual carries the prior's rows after the data's.

    Everything else (layout, masks, sizes, per-dataset errors) is the wrapped problem's,
    so the solvers run on it unchanged.
    """

    def __init__(self, problem, prior: Prior, row_weights: np.ndarray | None = None):
        self.problem = problem
        self.prior = prior
        # sqrt of each data entry's weight: a reading recorded k times counts 1/k per copy
        self.root_weights = None if row_weights is None else np.sqrt(row_weights)

    def __getattr__(self, name):
        return getattr(self.problem, name)

    def prior_rows(self, x: np.ndarray) -> np.ndarray:
        p = self.prior
        return p.rows @ (np.asarray(x, float)[p.index] - p.centre)

    def residual(self, x: np.ndarray) -> np.ndarray:
        r = self.problem.residual(x)
        if self.root_weights is not None:
            r = r * self.root_weights
        return np.concatenate([r, self.prior_rows(x)])

    def jacobian(self, x: np.ndarray, columns=None) -> np.ndarray:
        J = self.problem.jacobian(x, columns)
        if self.root_weights is not None:
            J = J * self.root_weights[:, None]
        n = len(self.problem.unknowns)
        if columns is None:
            columns = np.arange(n)
        elif np.asarray(columns).dtype == bool:
            columns = np.flatnonzero(columns)
        position = np.full(n, -1)
        position[np.asarray(columns, int)] = np.arange(len(columns))
        rows = np.zeros((len(self.prior.index), J.shape[1]))
        where = position[self.prior.index]
        present = where >= 0
        rows[:, where[present]] = self.prior.rows[:, present]
        return np.vstack([J, rows])

    def symbolic_residual(self, x):
        import casadi as ca

        p = self.prior
        offset = ca.vertcat(*[x[int(i)] - float(c) for i, c in zip(p.index, p.centre)])
        r = self.problem.symbolic_residual(x)
        if self.root_weights is not None:
            r = r * ca.DM(self.root_weights)
        if not len(p.index):
            return r
        return ca.vertcat(r, ca.mtimes(ca.DM(p.rows), offset))


@dataclass(frozen=True)
class Posterior:
    """Posterior statistics at an estimate, over the free unknowns.

    ``covariance`` over ``free`` (NaN rows/columns for unknowns the distinct data do not
    reach); ``share`` the data's share of each prior parameter (``prior.index`` order);
    ``sigma`` [m] the noise estimate (NaN when the distinct data leave no degree of
    freedom); ``dof`` the residual degrees of freedom it rests on.
    """

    covariance: np.ndarray
    share: np.ndarray
    sigma: float
    dof: float

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0, None))


def posterior(J: np.ndarray, r: np.ndarray, free_index: np.ndarray, prior: Prior | None,
              sigma: float | None = None, rows: np.ndarray | None = None,
              certified: np.ndarray | None = None, noise_known: bool = False) -> Posterior:
    """Posterior at an estimate from the data Jacobian ``J`` (columns ``free_index``) and
    residual ``r`` [m].

    ``rows`` (boolean over ``r``) keeps only the entries that are independent information
    (duplicated readings left out). ``sigma`` [m] fixes the noise for the prior's weight;
    the returned ``sigma`` is re-estimated from the kept residual.

    ``certified`` (boolean over ``r``) marks entries that compare fitted unknowns with an
    instrument's certified geometry (an artifact's known socket distances): they weigh in
    the fit like readings but carry no reading noise. The covariance is then that of the
    estimate the fit computes, ``A^-1 (J_n^T J_n + s^2 P) A^-1 sigma^2`` with
    ``A = J^T J + s^2 P`` (``P`` the prior's precision, ``s`` the noise it was weighed
    with, ``J_n`` the rows with reading noise), instead of ``A^-1 sigma^2``, which would
    count every certified entry as one more noisy reading and overstate the uncertainty.
    """
    if rows is not None:
        J, r = J[rows], r[rows]
        certified = None if certified is None else np.asarray(certified, bool)[rows]
    free_index = np.asarray(free_index, int)
    n = len(free_index)
    precision_prior, variance_prior, prior_position = _prior_over(prior, free_index)
    reached = (np.abs(J).sum(axis=0) > 0) | (variance_prior > 0)
    Jr = J[:, reached]
    data = Jr.T @ Jr
    m = len(r)
    rss = float(r @ r)
    sigma_prior = sigma if sigma is not None else (prior.sigma if prior is not None else None)
    precision_reached = precision_prior[np.ix_(reached, reached)]

    def solve_for(s: float | None):
        if s is None or not np.isfinite(s):
            information = data
        else:
            information = data + s**2 * precision_reached
        inverse = np.linalg.pinv(information, rcond=1e-14, hermitian=True)
        spent = float(np.trace(inverse @ data))
        return inverse, spent

    inverse, spent = solve_for(sigma_prior)
    dof = m - spent
    sigma_new = math.sqrt(rss / dof) if dof > 0.5 else float("nan")
    covariance = np.full((n, n), np.nan)
    # Data too few to estimate their own noise (only a population prior lets a fit get
    # here): the uncertainty is that of the noise the prior was weighed against.
    if sigma_prior is not None and (noise_known or not math.isfinite(sigma_new)):
        scale = sigma_prior**2
    else:
        scale = sigma_new**2
    sub = np.ix_(np.flatnonzero(reached), np.flatnonzero(reached))
    covariance[sub] = scale * _sandwich(inverse, Jr, certified, precision_reached, sigma_prior)
    share = _data_share(inverse, reached, prior_position, variance_prior, sigma_prior)
    return Posterior(covariance, share, sigma_new, dof)


def _prior_over(prior: Prior | None, free_index: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The prior over the unknowns ``free_index``: its precision (n x n), each unknown's
    prior variance (0: none) and, per prior entry, its position among them (-1: not
    free). The unknowns not free are fixed: the prior on the rest is the conditional one,
    whose precision is the block of the full precision."""
    n = len(free_index)
    precision_prior = np.zeros((n, n))
    variance_prior = np.zeros(n)
    prior_position = np.zeros(0, int)
    if prior is not None and len(prior.index):
        position = {int(i): k for k, i in enumerate(free_index)}
        prior_position = np.array([position.get(int(i), -1) for i in prior.index])
        held = np.flatnonzero(prior_position >= 0)
        where = prior_position[held]
        precision_prior[np.ix_(where, where)] = prior.precision[np.ix_(held, held)]
        variance_prior[where] = prior.tolerance[held] ** 2
    return precision_prior, variance_prior, prior_position


def _data_share(inverse: np.ndarray, reached: np.ndarray, prior_position: np.ndarray,
                variance_prior: np.ndarray, sigma_prior: float | None) -> np.ndarray:
    """Per prior entry, the share of its estimate the data decide: one less the ratio of
    its posterior to its prior variance, 1 - s^2 (J^T J + s^2 P)^-1_ii / C_ii with the
    noise s the prior was weighed with (for independent priors the diagonal of the
    resolution matrix (J^T J + s^2 P)^-1 J^T J); NaN where no prior or no data reach."""
    share = np.full(len(prior_position), np.nan)
    if not len(prior_position) or sigma_prior is None:
        return share
    diagonal = np.full(len(reached), np.nan)
    diagonal[reached] = np.diag(inverse)
    for k, position in enumerate(prior_position):
        if position >= 0 and np.isfinite(diagonal[position]):
            share[k] = 1.0 - sigma_prior**2 * diagonal[position] / variance_prior[position]
    return share


def _sandwich(inverse: np.ndarray, J: np.ndarray, certified: np.ndarray | None,
              precision: np.ndarray, s: float | None) -> np.ndarray:
    """``A^-1 (J_n^T J_n + s^2 P) A^-1`` (see ``posterior``); ``A^-1`` itself when no entry
    is certified (the two are then equal)."""
    if certified is None or not np.any(certified):
        return inverse
    noisy = J[~np.asarray(certified, bool)]
    middle = noisy.T @ noisy
    if s is not None and np.isfinite(s):
        middle = middle + s**2 * precision
    out = inverse @ middle @ inverse
    return 0.5 * (out + out.T)


def duplicate_rows(problem) -> tuple[np.ndarray, int, int]:
    """Residual entries that carry independent information, and the duplicates found.

    A unit of data (a placement of a bar or artifact, a tracker or laser reading) that
    repeats an earlier unit's readings exactly (joints and measured values) adds no
    information: its residual entries are left out (False). Returns the mask over the
    stacked residual, the number of repeated units and the number of units.
    """
    copies = repeated_copies(problem)
    first = copies > 0
    units = repeated = 0
    for model, groups in _groups(problem):
        keys: dict[int, int] = {}
        for g, c in zip(groups, copies[_span(problem, model)]):
            if g >= 0:
                keys.setdefault(int(g), c)
        units += len(keys)
        repeated += sum(1 for c in keys.values() if c < 0)
    return first, repeated, units


def repeated_copies(problem) -> np.ndarray:
    """Per residual entry, how often its unit's readings occur (negative: a later copy)."""
    out = []
    count: dict[bytes, int] = {}
    keys = []
    for model, groups in _groups(problem):
        key_of = {int(g): model.dataset.kind.encode() + _unit_bytes(model.dataset, int(g))
                  for g in dict.fromkeys(groups.tolist()) if g >= 0}
        for key in key_of.values():
            count[key] = count.get(key, 0) + 1
        keys.append((groups, key_of))
    seen: set[bytes] = set()
    for groups, key_of in keys:
        sign = {}
        for g, key in key_of.items():
            sign[g] = -1 if key in seen else 1
            seen.add(key)
        out.append(np.array([sign[int(g)] * count[key_of[int(g)]] if g >= 0 else 1
                             for g in groups], dtype=int))
    return np.concatenate(out) if out else np.zeros(0, int)


def copy_weights(problem) -> np.ndarray:
    """Per residual entry ``1 / copies``: repeated readings count once in all."""
    return 1.0 / np.abs(repeated_copies(problem))


def _groups(problem):
    return [(model, np.asarray(model.residual_groups(), int)) for model in problem.models]


def _span(problem, model) -> slice:
    start = 0
    for other in problem.models:
        size = other.residual_size()
        if other is model:
            return slice(start, start + size)
        start += size
    raise KeyError(model)


def _unit_bytes(dataset, group: int) -> bytes:
    """The readings of one unit of data as bytes (its id left out)."""
    pose = getattr(dataset, "pose", None)
    rows = np.flatnonzero(np.asarray(pose) == group) if pose is not None else np.array([group])
    parts = []
    for name in ("joints", "measured", "distance", "flange_poses"):
        value = getattr(dataset, name, None)
        if value is not None:
            parts.append(np.ascontiguousarray(np.asarray(value, float)[rows]).tobytes())
    points = getattr(dataset, "point", None)
    if points:
        parts.append("|".join(str(points[i]) for i in rows).encode())
    return b"#".join(parts)
