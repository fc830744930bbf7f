"""Point-laser sensor calibration on a sphere from known flange poses.

The method and its source: docs/methods.md#point-laser-and-sphere.

Unknowns: the laser reference point ``p0`` [m] (flange frame), the unit beam direction
``n`` (flange frame) and the sphere centre ``c`` [m] (base frame). Reading ``i`` has the
flange pose ``T_i = (R_i, t_i)`` (base frame) and the raw laser distance ``l_i`` [m]; its
residual [m] is the distance of the laser point from the sphere surface::

    r_i = || R_i (p0 + l_i n) + t_i - c || - R

Direction without poles or signs (``robocal_casadi.model.beam``): ``n`` moves on the unit
sphere as ``n <- beam_direction(n, (a, b))`` = ``normalise(n + a e1 + b e2)`` with
``e1, e2`` the tangent basis of the current ``n``; ``(a, b)`` are re-centred to zero
after every step, so any beam direction is reached with the same conditioning. The 8
local unknowns are ``[p0 (3), a, b, c (3)]``.

Two solvers: Levenberg-Marquardt on the closed-form Jacobian (``method="lm"``, the
default, a few milliseconds for 820 readings) and IPOPT through CasADi on
``[p0, w, c]``, ``n = beam_direction(w)`` with ``w.w = 1`` as a constraint, exact derivatives
(``method="ipopt"``, one solver built per reading count, data as parameters).

Identifiability: the Jacobian columns are scaled to unit length and their singular
values computed at the solution. A scan whose flange orientation does not vary (pure
translation), or varies only about the beam, leaves ``p0 + t n`` and ``c + t R n``
equally good; that is refused with ``InputError`` naming the numbers, not returned as an
estimate.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from ...common.least_squares import Tolerances, levenberg_marquardt
from ...errors import InputError, SolverError
from ...model.beam import beam_direction, tangent_basis
from ...model.kinematics import Kinematics

DEGENERACY_RATIO = 1e-6  # smallest / largest scaled singular value below which a scan is refused
PARAMETER_NAMES = ("x0", "y0", "z0", "a", "b", "xc", "yc", "zc")  # local unknowns, in order
FLANGE_AXES = np.vstack([np.eye(3), -np.eye(3)])  # fallback direction candidates
RETRY_RATIO = 0.01  # start RMS / radius above which the next round of starts is tried
EXACT_FIT = 1e-13  # [m] RMS residual at rounding level: the data are fitted exactly
START_ITERATIONS = 6  # LM steps given to each start before the best one is kept
IPOPT_ACCEPTED = ("Solve_Succeeded", "Solved_To_Acceptable_Level",
                  "Search_Direction_Becomes_Too_Small")  # the last: at the noise floor


@dataclass(frozen=True)
class SensorFit:
    """The calibrated laser and sphere centre, with their standard errors.

    ``origin`` ``p0`` [m] and ``direction`` ``n`` (unit) are in the flange frame,
    ``centre`` [m] in the base frame; ``*_std`` are one-sigma standard errors from the
    Gauss-Newton covariance ``s^2 (J^T J)^-1`` with ``s`` the residual standard deviation
    (``direction_std`` per component of ``n``). ``residual_rms`` [m] is the RMS distance of
    the laser points from the sphere surface. ``singular_values`` are those of the
    column-scaled Jacobian over ``[p0, a, b, c]`` (largest first). ``covariance`` (9 x 9)
    is over ``[p0, n, c]`` [m, 1, m].
    """

    origin: np.ndarray
    direction: np.ndarray
    centre: np.ndarray
    origin_std: np.ndarray
    direction_std: np.ndarray
    centre_std: np.ndarray
    residual_rms: float
    singular_values: np.ndarray
    iterations: int
    status: str
    method: str
    covariance: np.ndarray

    def patent_vector(self) -> np.ndarray:
        """``[x0, y0, z0, nx, ny, xc, yc, zc]`` (lengths [m]), the layout of the published
        example (docs/methods.md#point-laser-and-sphere)."""
        return np.concatenate([self.origin, self.direction[:2], self.centre])

    def __repr__(self) -> str:
        def mm(v, s):
            return "[" + ", ".join(f"{a * 1e3:.4f}+-{b * 1e3:.4f}" for a, b in zip(v, s)) + "] mm"

        n = "[" + ", ".join(f"{a:.6f}+-{b:.6f}" for a, b in zip(self.direction,
                                                              self.direction_std)) + "]"
        return (f"SensorFit(origin={mm(self.origin, self.origin_std)}, direction={n}, "
                f"centre={mm(self.centre, self.centre_std)}, "
                f"residual_rms={self.residual_rms * 1e3:.5f} mm, "
                f"condition={self.singular_values[0] / self.singular_values[-1]:.3g}, "
                f"iterations={self.iterations}, status={self.status!r}, method={self.method!r})")


# ----------------------------------------------------------------------------- geometry


@dataclass(frozen=True)
class Scan:
    """Readings laid out for fast evaluation: ``rotations`` (3 x 3 x N) and
    ``translations`` (3 x N) [m] of the flange poses (base frame), ``distance`` (N,) [m],
    ``radius`` [m]."""

    rotations: np.ndarray
    translations: np.ndarray
    distance: np.ndarray
    radius: float

    @staticmethod
    def from_poses(flange_poses: np.ndarray, distance: np.ndarray, radius: float) -> Scan:
        flange_poses = np.asarray(flange_poses, float)
        return Scan(np.ascontiguousarray(flange_poses[:, :3, :3].transpose(1, 2, 0)),
                    np.ascontiguousarray(flange_poses[:, :3, 3].T),
                    np.asarray(distance, float).ravel(), float(radius))

    def __len__(self) -> int:
        return len(self.distance)

    def points(self, origin, direction) -> np.ndarray:
        """Laser points ``T_i (p0 + l_i n)`` (3 x N) [m], base frame."""
        offsets = np.asarray(origin, float)[:, None] + np.asarray(direction, float)[:, None] \
            * self.distance[None, :]
        return np.einsum("ijn,jn->in", self.rotations, offsets) + self.translations

    def beams(self, direction) -> np.ndarray:
        """Beam directions ``R_i n`` (3 x N), base frame."""
        return np.einsum("ijn,j->in", self.rotations, np.asarray(direction, float))

    def residuals(self, origin, direction, centre) -> np.ndarray:
        """``||T_i (p0 + l_i n) - c|| - R`` (N,) [m]."""
        w = self.points(origin, direction) - np.asarray(centre, float)[:, None]
        return np.sqrt(np.sum(w * w, axis=0)) - self.radius

    def residual_and_jacobian(self, origin, direction, centre,
                              basis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residual (N,) [m] and Jacobian (N x 8) over ``[p0, a, b, c]`` at ``a = b = 0``.

        With ``u_i`` the unit vector from ``c`` to the laser point:
        ``dr/dp0 = u^T R_i``, ``dr/d(a, b) = l_i u^T R_i E``, ``dr/dc = -u^T``.
        """
        w = self.points(origin, direction) - centre[:, None]
        d = np.sqrt(np.sum(w * w, axis=0))
        u = w / d
        uR = np.einsum("in,ijn->jn", u, self.rotations)  # R_i^T u_i, 3 x N
        J = np.empty((8, len(d)))
        J[0:3] = uR
        J[3:5] = (basis.T @ uR) * self.distance
        J[5:8] = -u
        return d - self.radius, J.T


def laser_points(flange_poses: np.ndarray, distance: np.ndarray, origin, direction) -> np.ndarray:
    """Measured surface points ``T_i (p0 + l_i n)`` (N x 3) [m], base frame."""
    return Scan.from_poses(flange_poses, distance, 1.0).points(origin, direction).T


def surface_residuals(flange_poses: np.ndarray, distance: np.ndarray, radius: float, origin,
                      direction, centre) -> np.ndarray:
    """``||T_i (p0 + l_i n) - c|| - R`` (N,) [m] for unit ``direction``."""
    return Scan.from_poses(flange_poses, distance, radius).residuals(origin, direction, centre)


def sphere_centre(points: np.ndarray, radius: float, beam: np.ndarray | None = None) -> np.ndarray:
    """A starting centre [m] for surface ``points`` (N x 3) on a sphere of known ``radius``.

    Candidates: the algebraic (linear) sphere fit ``|P|^2 = 2 P.c + k``, the centroid and,
    when the beam directions ``beam`` (N x 3, base frame) are given, the points moved one
    radius along their beam (the centre lies behind the hit point). The candidate closest
    to radius ``R`` is refined by a few Gauss-Newton steps on ``|P - c| - R``.
    """
    points = np.asarray(points, float)
    candidates = []
    A = np.column_stack([2.0 * points, np.ones(len(points))])
    solution, *_ = np.linalg.lstsq(A, np.sum(points ** 2, axis=1), rcond=None)
    if np.all(np.isfinite(solution)):
        candidates.append(solution[:3])
    if beam is not None:
        candidates.append(np.mean(points + radius * beam, axis=0))
    candidates.append(points.mean(axis=0))

    def cost(c):
        return float(np.sum((np.sqrt(np.sum((points - c) ** 2, axis=1)) - radius) ** 2))

    c = min(candidates, key=cost).copy()
    for _ in range(5):  # Gauss-Newton on |P - c| - R, normal equations
        w = points - c
        d = np.sqrt(np.sum(w * w, axis=1))
        J = -w / np.maximum(d, 1e-300)[:, None]
        step = np.linalg.solve(J.T @ J, -(J.T @ (d - radius)))
        c += step
        if np.sqrt(step @ step) < 1e-9 * (radius + np.sqrt(c @ c)):
            break
    return c


# ----------------------------------------------------------------------------- Levenberg-Marquardt


def _step(origin, direction, centre, delta):
    n = beam_direction(direction, delta[3:5], tangent_basis(direction))
    return origin + delta[0:3], n, centre + delta[5:8]


def _levenberg_marquardt(scan: Scan, origin, direction, centre, *, max_iterations: int,
                         gradient_tolerance: float = 1e-8, step_tolerance: float = 1e-12):
    """The shared kernel on ``(origin, direction, centre)``; returns ``(origin, direction,
    centre, iterations, status)``.

    Steps are taken in ``[p0, a, b, c]`` with the direction moved in its tangent plane
    (``_step``). Converged when every column of ``J`` is orthogonal to ``r`` within
    ``gradient_tolerance`` (cosine, as MINPACK's ``gtol``), when the RMS residual is below
    ``EXACT_FIT`` (noise-free data), or when a step falls below ``step_tolerance`` of the
    scaled state.
    """
    def evaluate(state: tuple[np.ndarray, np.ndarray, np.ndarray], jacobian: bool):
        origin, direction, centre = state
        return scan.residual_and_jacobian(origin, direction, centre, tangent_basis(direction))

    def retract(state, delta):
        return _step(*state, delta)

    def coordinates(state):
        return np.concatenate([state[0], np.zeros(2), state[2]])

    tolerances = Tolerances(gtol=gradient_tolerance, xtol=step_tolerance,
                            residual_floor=np.sqrt(len(scan)) * EXACT_FIT)
    fit = levenberg_marquardt(evaluate, (origin, direction, centre),
                              max_iterations=max_iterations, tolerances=tolerances,
                              retract=retract, coordinates=coordinates)
    return (*fit.x, fit.iterations, fit.word)


# ----------------------------------------------------------------------------- IPOPT


@lru_cache(maxsize=8)
def _ipopt_solver(count: int) -> ca.Function:
    """IPOPT on ``[p0, w, c]`` (mm inside), ``n = beam_direction(w)`` and ``w.w = 1``, for
    ``count`` readings.

    Parameters: ``vec(R)`` (9 x count, column-major per reading), ``t`` [mm] (3 x count),
    ``l`` [mm] (count), radius [mm]. Built once per ``count`` and cached.
    """
    x = ca.SX.sym("x", 9)
    rotations = ca.SX.sym("R", 9, count)
    translations = ca.SX.sym("t", 3, count)
    distance = ca.SX.sym("l", 1, count)
    radius = ca.SX.sym("radius")
    p0, n, c = x[0:3], beam_direction(x[3:6]), x[6:9]
    offset = [p0[j] + distance * n[j] for j in range(3)]
    squared: ca.SX | float = 0
    for k in range(3):  # R_i[k, j] sits at row 3 j + k of vec(R_i)
        coordinate = translations[k, :] - c[k]
        for j in range(3):
            coordinate = coordinate + rotations[3 * j + k, :] * offset[j]
        squared = squared + coordinate ** 2
    residual = ca.sqrt(squared) - radius
    parameters = ca.vertcat(ca.vec(rotations), ca.vec(translations), ca.vec(distance), radius)
    nlp = {"x": x, "p": parameters, "f": 0.5 * ca.sumsqr(residual),
           "g": ca.dot(x[3:6], x[3:6]) - 1.0}  # the length of the free beam vector
    options: dict[str, Any] = {
        "print_time": False,
        "ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-10, "acceptable_tol": 1e-8,
                  "max_iter": 200}}
    return ca.nlpsol(f"sphere_fit_{count}", "ipopt", nlp, options)


def _ipopt(scan: Scan, origin, direction, centre):
    solver = _ipopt_solver(len(scan))
    parameters = np.concatenate([
        scan.rotations.transpose(2, 1, 0).reshape(-1),  # vec(R_i), column-major per reading
        1e3 * scan.translations.T.reshape(-1), 1e3 * scan.distance, [1e3 * scan.radius]])
    x0 = np.concatenate([1e3 * origin, direction, 1e3 * centre])
    solution = solver(x0=x0, p=parameters, lbg=0.0, ubg=0.0)
    stats = solver.stats()
    x = np.asarray(solution["x"]).ravel()
    if stats["return_status"] not in IPOPT_ACCEPTED:
        raise SolverError(f"IPOPT did not converge: {stats['return_status']}", stats=stats)
    n = x[3:6] / np.linalg.norm(x[3:6])
    return 1e-3 * x[0:3], n, 1e-3 * x[6:9], int(stats["iter_count"]), stats["return_status"]


# ----------------------------------------------------------------------------- the fit


def _check_inputs(flange_poses, distance, radius) -> Scan:
    flange_poses = np.asarray(flange_poses, float)
    distance = np.asarray(distance, float).ravel()
    if flange_poses.ndim != 3 or flange_poses.shape[1:] != (4, 4):
        raise InputError(f"flange_poses: expected N x 4 x 4, got shape {flange_poses.shape}")
    if len(distance) != len(flange_poses):
        raise InputError(f"distance: {len(distance)} readings for {len(flange_poses)} poses")
    if len(distance) < 8:
        raise InputError(f"{len(distance)} readings cannot determine the 8 unknowns "
                         "(p0, n, c); take at least 8, better hundreds")
    if not (np.all(np.isfinite(flange_poses)) and np.all(np.isfinite(distance))):
        raise InputError("flange_poses/distance: NaN or infinite values")
    if not radius > 0:
        raise InputError(f"radius must be positive, got {radius!r}")
    return Scan.from_poses(flange_poses, distance, radius)


def algebraic_start(scan: Scan) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed-form ``(p0, n, c)`` from the squared model, linear after lifting.

    Squaring ``||R_i (p0 + l_i n) + t_i - c|| = R`` and using ``|n| = 1`` gives, per reading,
    an equation linear in ``z = [k, g, c, p0, n, vec(M), vec(K)]`` (29 unknowns) with
    ``k = |p0|^2 + |c|^2``, ``g = p0.n``, ``M = c p0^T``, ``K = c n^T``::

        k + 2 l g - 2 t.c + 2 (R^T t).p0 + 2 l (R^T t).n - 2 <R, M> - 2 l <R, K>
            = R^2 - l^2 - |t|^2

    Solved by column-scaled least squares, ignoring the products' structure; ``p0``,
    ``n`` (normalised) and ``c`` are read from the linear part. Exact without noise when
    the orientations and distances vary enough; a start, not an estimate.
    """
    R, t, distance = scan.rotations, scan.translations, scan.distance
    count = len(distance)
    rotated = np.einsum("jin,jn->in", R, t)  # R_i^T t_i, 3 x N
    entries = R.reshape(9, count)  # R_i[j, k] at row 3 j + k, matching vec(M) row-major
    A = np.vstack([np.ones(count), 2 * distance, -2 * t, 2 * rotated, 2 * distance * rotated,
                   -2 * entries, -2 * distance * entries]).T
    b = scan.radius ** 2 - distance ** 2 - np.sum(t * t, axis=0)
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    z, *_ = np.linalg.lstsq(A / scale, b, rcond=None)
    z /= scale
    n = z[8:11]
    norm = np.linalg.norm(n)
    n = n / norm if norm > 1e-12 else np.array([0.0, 0.0, 1.0])
    return z[5:8], n, z[2:5]


def initial_values(scan: Scan, origin_guess=None, direction_guess=None, centre_guess=None):
    """A start ``(origin, direction, centre)`` without user help, and the LM steps spent.

    Starts, each given a few LM steps, tried in turn until one leaves an RMS below
    ``RETRY_RATIO`` times the radius (the lowest cost is kept in any case):
    ``algebraic_start``; the user's guesses where given (``p0`` at the flange origin and
    the centre from ``sphere_centre`` where not given); the six flange axes as directions.
    """
    guessed = origin_guess is not None or direction_guess is not None or centre_guess is not None
    rounds = [lambda: [algebraic_start(scan)],
              lambda: [_guessed(scan, origin_guess, direction_guess, centre_guess)] if guessed
              else [],
              lambda: [_guessed(scan, origin_guess, axis, centre_guess) for axis in FLANGE_AXES]]
    best: tuple = (np.inf, None, 0)
    for starts in rounds:
        best = min(best, _best_start(scan, starts()), key=lambda b: b[0])
        if np.sqrt(best[0] / len(scan)) <= RETRY_RATIO * scan.radius:
            break
    return best[1], best[2]


def _guessed(scan: Scan, origin_guess, direction_guess, centre_guess):
    origin = np.zeros(3) if origin_guess is None else np.asarray(origin_guess, float)
    n = np.array([0.0, 0.0, 1.0]) if direction_guess is None else \
        np.asarray(direction_guess, float) / np.linalg.norm(direction_guess)
    if centre_guess is not None:
        return origin, n, np.asarray(centre_guess, float)
    return origin, n, sphere_centre(scan.points(origin, n).T, scan.radius, beam=scan.beams(n).T)


def _best_start(scan: Scan, starts):
    """``(cost, (origin, direction, centre), steps)`` of the best start after a few LM steps."""
    best: tuple = (np.inf, None, 0)
    for origin, n, c in starts:
        if not (np.all(np.isfinite(origin)) and np.all(np.isfinite(c))):
            continue
        trial = _levenberg_marquardt(scan, origin, n, c, max_iterations=START_ITERATIONS)
        cost = float(np.sum(scan.residuals(*trial[:3]) ** 2))
        if np.isfinite(cost) and cost < best[0]:
            best = (cost, trial[:3], trial[3])
    return best


def fit_sensor(flange_poses: np.ndarray, distance: np.ndarray, radius: float, *,
               origin_guess=None, direction_guess=None, centre_guess=None,
               method: str = "lm", max_iterations: int = 100) -> SensorFit:
    """Calibrate the laser (``p0``, ``n``) and the sphere centre ``c`` from known flange poses.

    ``flange_poses`` (N x 4 x 4) [m], base frame; ``distance`` (N,) [m] raw laser readings;
    ``radius`` [m]. Guesses are optional (``origin_guess`` [m] and ``direction_guess`` in
    the flange frame, ``centre_guess`` [m] in the base frame); without them the start is
    closed-form (``initial_values``).
    ``method`` is ``"lm"`` (closed-form Jacobian, fastest) or ``"ipopt"`` (CasADi, exact
    derivatives, ``|n| = 1`` as a constraint); both continue from the same start, which
    has already taken a few LM steps (``initial_values``). ``iterations`` counts the LM
    steps from the start on, or IPOPT's own iterations.

    Raises ``InputError`` when the scan cannot separate ``p0`` from ``c`` (see
    ``check_identifiable``), ``SolverError`` when the solver fails.
    """
    scan = _check_inputs(flange_poses, distance, radius)
    if method not in ("lm", "ipopt"):
        raise InputError(f"method must be 'lm' or 'ipopt', got {method!r}")
    (origin, direction, centre), steps = initial_values(scan, origin_guess, direction_guess,
                                                        centre_guess)
    if method == "lm":
        origin, direction, centre, iterations, status = _levenberg_marquardt(
            scan, origin, direction, centre, max_iterations=max_iterations)
        iterations += steps  # the start's steps belong to the same descent
    else:
        origin, direction, centre, iterations, status = _ipopt(scan, origin, direction, centre)
    return summarise(scan, origin, direction, centre, iterations=iterations, status=status,
                     method=method)


def fit_dataset(dataset, *, method: str = "lm", robot=None) -> SensorFit:
    """``fit_sensor`` on a point-laser dataset, with the file's guesses.

    Pendant tables use their own flange poses; joint readings use the flange poses of
    ``robot`` (default: the dataset's robot, nominal), so the robot's own errors stay in
    the residual. A scan that cannot separate ``p0`` from ``c`` raises ``InputError``
    naming the table.
    """
    poses = dataset.flange_poses
    if poses is None:
        poses = Kinematics(robot or dataset.robot).flange_poses(dataset.joints)
    try:
        return fit_sensor(poses, dataset.distance, dataset.radius,
                          origin_guess=dataset.origin_guess,
                          direction_guess=dataset.direction_guess,
                          centre_guess=dataset.centre_guess, method=method)
    except InputError as error:
        if error.file is not None:
            raise
        raise InputError(error.what, file=dataset.data_path or dataset.path,
                         where="scan") from None


def summarise(scan: Scan, origin, direction, centre, *, iterations: int = 0,
              status: str = "given", method: str = "none") -> SensorFit:
    """``SensorFit`` at a given solution: covariance, singular values, identifiability check."""
    basis = tangent_basis(direction)
    r, J = scan.residual_and_jacobian(origin, direction, centre, basis)
    singular_values, vectors = scaled_singular_values(J)
    check_identifiable(singular_values, vectors, direction)
    dof = max(len(r) - 8, 1)
    variance = float(r @ r) / dof
    local = variance * np.linalg.inv(J.T @ J)
    M = np.zeros((9, 8))  # d[p0, n, c] / d[p0, a, b, c]
    M[0:3, 0:3] = np.eye(3)
    M[3:6, 3:5] = basis
    M[6:9, 5:8] = np.eye(3)
    covariance = M @ local @ M.T
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    return SensorFit(origin=origin, direction=direction, centre=centre, origin_std=std[0:3],
                     direction_std=std[3:6], centre_std=std[6:9],
                     residual_rms=float(np.sqrt(np.mean(r ** 2))),
                     singular_values=singular_values, iterations=iterations, status=status,
                     method=method, covariance=covariance)


# ----------------------------------------------------------------------------- identifiability


def scaled_singular_values(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Singular values (largest first) of ``J`` with unit columns, and the right singular
    vectors (columns, in the unscaled parameters, each of unit length) of the smallest."""
    norms = np.linalg.norm(J, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    _, s, Vt = np.linalg.svd(J / norms, full_matrices=False)
    null = (Vt.T / norms[:, None])
    return s, null / np.linalg.norm(null, axis=0)


def check_identifiable(singular_values: np.ndarray, vectors: np.ndarray,
                       direction: np.ndarray, *, ratio: float = DEGENERACY_RATIO) -> None:
    """Refuse a scan that leaves a combination of ``[p0, a, b, c]`` undetermined.

    ``vectors`` are the right singular vectors from ``scaled_singular_values``. The
    message gives the singular values and the undetermined direction: for a scan without
    enough tilt it is ``p0 + t d`` with ``c + t R d`` (``R`` the flange rotation).
    """
    s = np.asarray(singular_values)
    weak = np.flatnonzero(s < ratio * s[0])
    if weak.size == 0:
        return
    shown = ", ".join(f"{x:.3g}" for x in s)
    origin_part = vectors[0:3, weak]
    v = vectors[:, weak[-1]]
    d_origin, d_centre = v[0:3], v[5:8]
    if weak.size >= 3 and np.linalg.matrix_rank(origin_part, tol=1e-3) == 3:
        detail = ("p0 + d and c + R*d fit equally for every d (R the flange rotation, the "
                  "same in every reading: a pure translation scan)")
    elif np.linalg.norm(d_origin) > 1e-3:
        scale = np.linalg.norm(d_origin)
        d = d_origin / scale
        along = abs(float(d @ direction))
        what = "the beam direction n" if along > 0.999 else f"{along:.3f} along the beam"
        detail = (f"p0 + t*d and c + t*R*d fit equally (R the flange rotation) for "
                  f"d = [{d[0]:.4f}, {d[1]:.4f}, {d[2]:.4f}] (flange frame, {what}), "
                  f"the centre moving along [{', '.join(f'{x:.4f}' for x in d_centre / scale)}]")
    else:
        detail = "undetermined combination [" + ", ".join(
            f"{name} {x:.3f}" for name, x in zip(PARAMETER_NAMES, v)) + "]"
    raise InputError(
        f"the scan does not separate the laser origin from the sphere centre: "
        f"{weak.size} of {s.size} singular values of the column-scaled Jacobian below "
        f"{ratio:g} x the largest ([{shown}]); {detail}; tilt the sensor between readings")
