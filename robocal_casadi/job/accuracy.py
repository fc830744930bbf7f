"""The tool-position error the delivered model is predicted to have over the work cell.

The work cell is the box of joint ranges a fit dataset declares (``work_cell:``, joints it
does not name keep the range the fit data cover), else the box of joint ranges the fit
data cover (``region_of``); it is sampled uniformly at ``SAMPLES`` poses with a fixed
seed. The box, not the neighbourhood of the measured poses, is the default: the figure is
a statement about where the robot may be sent within what it was measured over, and
every joint combination inside the box is one it may be sent to.

The error is predicted at the point the instrument located on the flange (probe tip,
tracker reflector, laser origin: the first three mounted unknowns), which is what the
data can vouch for: a tool frame offset the instrument cannot tell from its own offset is
the user's declaration, not calibrated. At each pose ``k`` that point moves with the robot
and mounted parameters as ``G_k = d p_world / d theta`` (3 x n, CasADi's exact Jacobian of
the delivered geometry).
The parameter error after calibration has covariance ``Sigma``:

* for the parameters the calibration fitted (robot and instrument point), the posterior
  covariance of the geometric fit (data and tolerance prior together; an artifact's
  certified socket distances count as free of reading noise, ``prior.posterior``);
* for those it held at nominal because the data barely see them (the 1% rule), their
  tolerance squared (``calibration.prior``), counted only for the part of their effect
  that the fitted parameters cannot take up over the region; those held by an exact
  dependency move nothing the fit could not take up, but their own errors widen the
  spread of the fitted parameters that take them up (``_represented``).

A rigid motion of the whole robot (its base placement) is what registering the robot to
the cell fixes, and no calibration instrument but the cell's own registration sees it; so
the error field is taken after removing its best rigid motion, projected out of
``G = [G_1; ...; G_N]``. The predicted error at pose ``k`` is then

    e_k^2 = tr(P_k G Sigma G^T P_k^T) + s^2                                   [m^2]

with ``P`` the projection and ``s`` the part of the residual that is structured rather
than noise: what the diagnosis left unexplained, plus, when effects were identified but a
controller runs geometry alone, the RMS distance between the delivered geometry and the
model with effects at the fit readings. ``rms``, ``p95`` and ``max`` are over the poses.

``rms`` is an expectation over calibrations like this one: the root of the mean, over
robots, of the square of the RMS over the work cell. One robot's RMS is a random draw
about it. Writing the parameter error as ``L z`` (``L L^T = Sigma``, ``z`` standard
normal), the square of one robot's RMS over the ``N`` poses is

    |P G L z|^2 / N + s^2 = sum_i lambda_i z_i^2 + s^2                         [m^2]

with ``lambda_i`` the eigenvalues of ``(P G L)^T (P G L) / N``: a weighted sum of
chi-square variables with one degree of freedom. When many directions share the
uncertainty (a tracker) it stays close to ``rms``; when one direction carries most of it
(the robot's scale seen only through a bar's length) it scatters like ``|z|``, and a
robot may lie at a third or at twice ``rms``. ``band`` gives its ``BAND`` quantiles,
from ``DRAWS`` draws of ``z`` with a fixed seed.
"""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca
import numpy as np

from ..calibration.prior import tolerance_of
from ..model.kinematics import Kinematics
from ..model.parameters import perturbed_stems
from ..model.robot import Robot
from ..results import (  # noqa: F401 (the record and its region kinds, re-exported)
    BAND,
    DATA_RANGES,
    DECLARED,
    MEASURED,
    PARTLY_DECLARED,
    SAMPLES,
    PredictedAccuracy,
)

SEED = 9283  # fixed: a prediction is repeatable
DRAWS = 20000  # draws of the parameter error behind ``band`` (quantile error ~0.5%)


def region_of(result) -> tuple[tuple[float, float], ...] | None:
    """Joint ranges [rad or m] the fit data cover; None when no fit data carry joints."""
    blocks = [np.asarray(r.joints, float) for r in result.residuals
              if r.joints is not None and len(r.joints)]
    if not blocks:
        return None
    Q = np.vstack(blocks)
    Q = Q[np.all(np.isfinite(Q), axis=1)]
    if not len(Q):
        return None
    return tuple((float(lo), float(hi)) for lo, hi in zip(Q.min(axis=0), Q.max(axis=0)))


def work_cell(result, datasets: Sequence = ()
              ) -> tuple[tuple[tuple[float, float], ...] | None, str]:
    """The region [rad or m per joint] the prediction is stated over, and its kind: the
    union of the ``work_cell`` boxes the fit ``datasets`` declare, a joint none of them
    names taking the range the fit data cover; without a declaration, ``region_of``.
    ``(None, kind)`` when a joint is left to data that carry no joint readings."""
    cells = [d.work_cell for d in datasets if getattr(d, "work_cell", None) is not None]
    data = region_of(result)
    if any(isinstance(c, str) for c in cells):  # "measured": the fit data's own poses
        return data, MEASURED
    if not cells:
        return data, DATA_RANGES
    region: list[tuple[float, float]] = []
    partly = False
    for joint, declared in enumerate(zip(*cells)):
        given = [c for c in declared if c is not None]
        if given:
            region.append((min(c[0] for c in given), max(c[1] for c in given)))
        elif data is None:
            return None, PARTLY_DECLARED
        else:
            region.append(data[joint])
            partly = True
    return tuple(region), PARTLY_DECLARED if partly else DECLARED


def predict(result, delivered: Robot, point, point_names: Sequence[str] = (),
            structured: float = 0.0,
            region: tuple[tuple[float, float], ...] | None = None,
            region_kind: str = DATA_RANGES) -> PredictedAccuracy | None:
    """The ``PredictedAccuracy`` of the ``delivered`` geometry of a ``CalibrationResult`` at
    the instrument's ``point`` [m] (flange frame; its unknowns ``point_names``, x, y, z);
    ``structured`` [m] the model error beyond the unexplained residual (module docstring).
    ``region`` (per joint ``(low, high)`` [rad or m], of kind ``region_kind``) defaults to
    the joint ranges of the fit data. None when there is no region."""
    if region is None:
        region, region_kind = region_of(result), DATA_RANGES
    if region is None:
        return None
    Q = _poses(result, region, region_kind)
    kinematics = Kinematics(delivered)
    G, positions = _point_jacobians(kinematics, Q, np.asarray(point, dtype=float))
    names = tuple(kinematics.registry.names) + tuple(point_names)
    PG = _without_rigid_motion(_rigid_basis(positions), G[:, :len(names)])
    E = _error_field(result, kinematics, names, PG)
    per_pose = (E**2).sum(axis=1).reshape(len(Q), 3).sum(axis=1)
    unexplained = 0.0 if result.unexplained is None else float(result.unexplained.rms)
    s2 = unexplained**2 + structured**2
    errors = np.sqrt(per_pose + s2)
    return PredictedAccuracy(float(np.sqrt(np.mean(errors**2))),
                             float(np.percentile(errors, 95)), float(errors.max()),
                             float(np.sqrt(s2)), region, len(Q), errors, region_kind,
                             rms_band(E, len(Q), s2))


def rms_band(E: np.ndarray, count: int, s2: float,
             quantiles: tuple[float, float] = BAND) -> tuple[float, float]:
    """The ``quantiles`` [m] of one robot's RMS over ``count`` poses when its error field
    (3 ``count`` entries [m]) is ``E z`` with ``z`` standard normal, plus ``s2`` [m^2]
    everywhere (module docstring)."""
    if not E.size:
        return (float(np.sqrt(s2)), float(np.sqrt(s2)))
    weights = np.linalg.svd(E, compute_uv=False) ** 2 / count  # lambda_i [m^2]
    weights = weights[weights > weights[0] * 1e-12] if weights[0] > 0 else weights[:0]
    z = np.random.default_rng(SEED).standard_normal((DRAWS, len(weights)))
    rms = np.sqrt(z**2 @ weights + s2)
    low, high = np.quantile(rms, quantiles)
    return float(low), float(high)


def _poses(result, region: tuple[tuple[float, float], ...], region_kind: str) -> np.ndarray:
    """The joint readings (N x dof) [rad or m] the prediction is made at: ``SAMPLES``
    drawn uniformly in the box ``region``, or, for ``MEASURED``, the fit data's own
    readings (at most ``SAMPLES`` of them, evenly spread over the table)."""
    if region_kind == MEASURED:
        blocks = [np.asarray(r.joints, float) for r in result.residuals
                  if r.joints is not None and len(r.joints)]
        Q = np.vstack(blocks)
        Q = Q[np.all(np.isfinite(Q), axis=1)]
        return Q[np.unique(np.linspace(0, len(Q) - 1, min(SAMPLES, len(Q))).astype(int))]
    low, high = np.array(region).T
    return np.random.default_rng(SEED).uniform(low, high, size=(SAMPLES, len(low)))


def _point_jacobians(kinematics: Kinematics, Q: np.ndarray,
                     point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``G`` (3N x (n + 3)): d p_world / d [robot parameters, point], and the world
    positions (N x 3) [m] of the flange-frame ``point`` at the rows of ``Q``."""
    q = ca.SX.sym("q", kinematics.dof)
    p = ca.SX.sym("p", len(kinematics.nominal))
    offset = ca.SX.sym("offset", 3)
    position = kinematics.point(q, p, offset)
    function = ca.Function("point_jacobian", [q, p, offset],
                           [position, ca.jacobian(position, ca.vertcat(p, offset))])
    count = len(Q)
    mapped = function.map(count)
    positions, jacobians = mapped(Q.T, ca.repmat(ca.DM(kinematics.nominal), 1, count),
                                  ca.repmat(ca.DM(point), 1, count))
    width = len(kinematics.nominal) + 3
    G = np.asarray(jacobians).reshape(3, count, width).transpose(1, 0, 2)  # block k: 3 x width
    return G.reshape(3 * count, width), np.asarray(positions).T


def _rigid_basis(positions: np.ndarray) -> np.ndarray:
    """Orthonormal basis (3N x 6) of the small rigid motions of the point set: three
    translations and three rotations about its centroid."""
    centred = positions - positions.mean(axis=0)
    blocks = []
    for point in centred:
        x, y, z = point
        skew = np.array([[0.0, z, -y], [-z, 0.0, x], [y, -x, 0.0]])  # -[p]x: d p / d rotation
        blocks.append(np.hstack([np.eye(3), skew]))
    return np.linalg.qr(np.vstack(blocks))[0]


def _without_rigid_motion(basis: np.ndarray, G: np.ndarray) -> np.ndarray:
    """``G`` with its rigid-motion part (``basis``, orthonormal) removed."""
    return G - basis @ (basis.T @ G)


def _error_field(result, kinematics: Kinematics, names: Sequence[str],
                 PG: np.ndarray) -> np.ndarray:
    """``E`` (3N x m) [m]: the error field at the poses (rigid motion removed) is ``E z``
    with ``z`` standard normal (module docstring); ``PG``'s columns (3N rows) are
    ``names``. Its squared row norms summed per pose are the expected squared errors."""
    registry = kinematics.registry
    column = {name: k for k, name in enumerate(names)}
    kept = [k for k, n in enumerate(result.covariance_names) if n in column]
    fitted = [column[result.covariance_names[k]] for k in kept]
    blocks = [np.zeros((len(PG), 0))]
    if fitted:
        covariance = np.asarray(result.covariance, dtype=float)[np.ix_(kept, kept)]
        covariance = covariance + _represented(result, registry, names, PG, fitted, covariance)
        values, vectors = np.linalg.eigh(0.5 * (covariance + covariance.T))
        blocks.append(PG[:, fitted] @ (vectors * np.sqrt(np.clip(values, 0.0, None))))
    # Parameters held at nominal by an exact dependency moved nothing the fit could not
    # take up; those held because the data barely see them keep their tolerance.
    held = [n for n in result.identifiability.practical if n in registry]
    basis = np.linalg.qr(PG[:, fitted])[0] if fitted else np.zeros((len(PG), 0))
    for name in held:
        left = PG[:, column[name]] - basis @ (basis.T @ PG[:, column[name]])
        tolerance = tolerance_of(name, registry.quantity(name), result.robot_nominal)
        if tolerance is not None:
            blocks.append(tolerance * left[:, None])
    return np.hstack(blocks)


def _represented(result, registry, names: Sequence[str], PG: np.ndarray, fitted: list[int],
                 covariance: np.ndarray) -> np.ndarray:
    """The error covariance [SI] the fitted parameters gain from the parameters they
    represent: one held at nominal by an exact dependency (``d3`` acting like ``d2`` on
    parallel axes) has its own error, which the fitted one takes up, so the combination it
    estimates spreads by ``C' = C + A C_h A^T`` (``A`` the dependency over the work cell,
    ``C_h`` the held tolerances squared), not by the fitted one's tolerance alone. The
    estimate was weighed with the narrower prior ``P``; its error covariance under the
    wider spread is ``K (H + P C' P) K = Sigma + K P A C_h A^T P K`` with ``K`` the
    posterior covariance (``Sigma`` itself unless certified distances entered the fit,
    where ``Sigma`` stands in for ``K``)."""
    prior = result.prior
    tolerance = {} if prior is None else dict(prior.tolerance)
    fitted_names = [names[k] for k in fitted]
    if not tolerance or not all(n in tolerance for n in fitted_names):
        return np.zeros_like(covariance)
    known = set(result.covariance_names) | set(result.identifiability.practical)
    robot = result.robot_nominal
    # Only the joint parameters that stand for a physical error of their own (``beta``
    # only where the file gives one); another name for a freedom the fitted parameters
    # already describe (``beta5`` of non-parallel axes) adds no spread.
    physical = {f"{stem}{i}" for i, joint in enumerate(robot.joints, start=1)
                for stem in perturbed_stems(robot, joint)}
    held = [(names.index(n), tolerance_of(n, registry.quantity(n), robot))
            for n in registry.names if n not in known and n in names and n in physical]
    held = [(k, t) for k, t in held if t is not None and np.any(PG[:, k])]
    if not held:
        return np.zeros_like(covariance)
    B = PG[:, fitted]
    A = np.linalg.lstsq(B, PG[:, [k for k, _ in held]], rcond=1e-10)[0]  # fitted x held
    spread = (A * np.array([t for _, t in held]) ** 2) @ A.T
    P = np.diag([1.0 / tolerance[n] ** 2 for n in fitted_names])
    gain = covariance @ P
    return gain @ spread @ gain.T
