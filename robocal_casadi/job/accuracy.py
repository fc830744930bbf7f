"""The tool-position error the delivered model is predicted to have over the work cell.

The work cell is the box of joint ranges a fit dataset declares (``work_cell:``, joints it
does not name keep the range the fit data cover), sampled uniformly at ``SAMPLES`` poses
with a fixed seed; without a declaration, the poses the fit data were measured in (at
most ``SAMPLES`` of them): the region the robot works in, as far as the data show. Beside
that figure ``statement`` gives the one over the whole box of joint ranges the data span
(every joint combination within the measured ranges) and names the parameters that carry
the difference (``unseen``): those the data barely see, ranked by how much of the box
figure their remaining uncertainty makes. And the nominal robot's predicted error over the
same poses: its error is the calibration's correction plus the calibrated model's own
error, ``E|e_nominal|^2 = |p_delivered - p_nominal|^2 + E|e_delivered|^2`` per pose (rigid
motion removed), so "calibrated or not" is read on one region.

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
controller runs geometry alone, what they move that the geometry does not: the distance
between the model with effects and the delivered geometry at each pose of the region,
loaded as the data were (each pose takes the payload, temperature, ... of a fit reading
drawn with a fixed seed; the measured poses their own), its best rigid motion removed
like the rest. Gravity and payload change over the region, so this is counted pose by
pose rather than at the fit readings alone. ``rms``, ``p95`` and ``max`` are over the poses.

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

import re
from collections.abc import Sequence
from dataclasses import replace

import casadi as ca
import numpy as np

from ..calibration.prior import tolerance_of
from ..effects.effect_model import EffectModel
from ..effects.motion import is_derived_column
from ..instruments.registry import INSTRUMENTS
from ..model.kinematics import Kinematics
from ..model.parameters import perturbed_stems
from ..model.robot import Robot
from ..results import (  # noqa: F401 (the record and its region kinds, re-exported)
    BAND,
    BAND_DRAWS,
    BAND_SEED,
    BOX_RATIO,
    DATA_RANGES,
    DECLARED,
    MEASURED,
    PARTLY_DECLARED,
    SAMPLES,
    ErrorFigures,
    PredictedAccuracy,
    Unseen,
)

SEED = BAND_SEED  # fixed: a prediction is repeatable
DRAWS = BAND_DRAWS  # draws of the parameter error behind ``band`` (quantile error ~0.5%)
UNSEEN_SHARE = 0.1  # an unseen parameter is named when it carries this share of the box's
UNSEEN_SHOWN = 3  # mean square; at most this many are named


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
    names taking the range the fit data cover; without a declaration (or with
    ``measured``), the fit data's own poses (``MEASURED``, the box ``region_of`` spans
    them). ``(None, kind)`` when a joint is left to data that carry no joint readings."""
    cells = [d.work_cell for d in datasets if getattr(d, "work_cell", None) is not None]
    data = region_of(result)
    if not cells or any(isinstance(c, str) for c in cells):  # the fit data's own poses
        return data, MEASURED
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


def statement(result, delivered: Robot, point, point_names: Sequence[str] = (),
              structured: float = 0.0,
              region: tuple[tuple[float, float], ...] | None = None,
              region_kind: str = MEASURED, *, effects: EffectModel | None = None,
              effects_point=None, nominal: tuple[Robot, Sequence[float]] | None = None,
              instrument: str = "", held_out: float | None = None
              ) -> PredictedAccuracy | None:
    """What a customer reads: ``predict`` over the region, and, where the region is the
    measured poses, the prediction over the box of joint ranges they span with the
    parameters that carry the difference (``unseen``) when the two differ by more than
    ``BOX_RATIO``; else, when the figure is more than ``BOX_RATIO`` times the delivered
    file's ``held_out`` RMS [m], the parameters that carry it. ``instrument`` (a dataset
    kind) words what would see them."""
    predicted, carried = _predict_or_none(result, delivered, point, point_names, structured,
                                          region, region_kind, effects, effects_point,
                                          nominal)
    if predicted is None:
        return None
    predicted = replace(predicted, held_out=held_out)
    if predicted.region_kind == MEASURED:
        box, box_carried = _predict(result, delivered, point, point_names, structured,
                                    predicted.region, DATA_RANGES, effects, effects_point,
                                    nominal)
        predicted = replace(predicted, box=box)
        if predicted.box_differs:
            return replace(predicted, unseen=_unseen(result, box_carried, box.rms**2,
                                                     tuple(point_names), instrument))
    if predicted.held_out_differs:
        return replace(predicted, unseen=_unseen(result, carried, predicted.rms**2,
                                                 tuple(point_names), instrument,
                                                 weak_only=False))
    return predicted


def _predict_or_none(result, delivered: Robot, point, point_names: Sequence[str],
                     structured: float, region, region_kind: str, effects, effects_point,
                     nominal) -> tuple[PredictedAccuracy | None, dict[str, float]]:
    """``_predict`` over ``region`` (the box of the fit data's joint ranges when None);
    ``(None, {})`` when there is no region."""
    if region is None:
        region, region_kind = region_of(result), DATA_RANGES
    if region is None:
        return None, {}
    return _predict(result, delivered, point, point_names, structured, region, region_kind,
                    effects, effects_point, nominal)


def predict(result, delivered: Robot, point, point_names: Sequence[str] = (),
            structured: float = 0.0,
            region: tuple[tuple[float, float], ...] | None = None,
            region_kind: str = DATA_RANGES, *, effects: EffectModel | None = None,
            effects_point=None, nominal: tuple[Robot, Sequence[float]] | None = None
            ) -> PredictedAccuracy | None:
    """The ``PredictedAccuracy`` of the ``delivered`` geometry of a ``CalibrationResult`` at
    the instrument's ``point`` [m] (flange frame; its unknowns ``point_names``, x, y, z);
    ``structured`` [m] the model error beyond the unexplained residual where ``effects``
    (the model with effects, its instrument at ``effects_point`` [m]) cannot be evaluated
    over the region (module docstring). ``region`` (per joint ``(low, high)`` [rad or m],
    of kind ``region_kind``) defaults to the box of joint ranges of the fit data.
    ``nominal``: the nominal robot and its instrument point [m], whose error over the same
    poses is stated beside. None when there is no region."""
    if region is None:
        region, region_kind = region_of(result), DATA_RANGES
    if region is None:
        return None
    return _predict(result, delivered, point, point_names, structured, region, region_kind,
                    effects, effects_point, nominal)[0]


def _predict(result, delivered: Robot, point, point_names: Sequence[str], structured: float,
             region: tuple[tuple[float, float], ...], region_kind: str,
             effects: EffectModel | None, effects_point, nominal
             ) -> tuple[PredictedAccuracy, dict[str, float]]:
    """``predict``, and per parameter the mean square [m^2] over the poses that knowing it
    exactly would take off (``_error_field``)."""
    Q, extras = _poses(result, region, region_kind)
    kinematics = Kinematics(delivered)
    point = np.asarray(point, dtype=float)
    G, positions = _point_jacobians(kinematics, Q, point)
    names = tuple(kinematics.registry.names) + tuple(point_names)
    basis = _rigid_basis(positions)
    PG = _without_rigid_motion(basis, G[:, :len(names)])
    left_out = _left_out(effects, effects_point, Q, extras, positions, basis)
    E, carried = _error_field(result, kinematics, names, PG,
                              _noise_ratio(result) if left_out is not None else 1.0)
    per_pose = (E**2).sum(axis=1).reshape(len(Q), 3).sum(axis=1)
    unexplained = 0.0 if result.unexplained is None else float(result.unexplained.rms)
    if left_out is None:
        left_out = np.full(len(Q), structured**2)
    s2 = unexplained**2 + left_out  # per pose [m^2]
    errors = np.sqrt(per_pose + s2)
    nominal_figures = None
    if nominal is not None:
        nominal_positions = Kinematics(nominal[0]).points(Q, np.asarray(nominal[1], float))
        correction = _without_rigid_motion(basis, (positions - nominal_positions).reshape(-1, 1))
        nominal_figures = ErrorFigures.of(
            np.sqrt(errors**2 + (correction.reshape(len(Q), 3) ** 2).sum(axis=1)))
    return PredictedAccuracy(float(np.sqrt(np.mean(errors**2))),
                             float(np.percentile(errors, 95)), float(errors.max()),
                             float(np.sqrt(np.mean(s2))), region, len(Q), errors, region_kind,
                             rms_band(E, len(Q), float(np.mean(s2))),
                             nominal_figures), carried


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


def _poses(result, region: tuple[tuple[float, float], ...], region_kind: str
           ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The joint readings (N x dof) [rad or m] the prediction is made at: ``SAMPLES``
    drawn uniformly in the box ``region``, or, for ``MEASURED``, the fit data's own
    readings (at most ``SAMPLES`` of them, evenly spread over the table); and the loads
    they are taken under: each extra column of the fit data (payload, temperature, ...),
    per pose that of its own reading, or for a box pose of a fit reading drawn at random
    (fixed seed). A dataset without a column the others have counts it as 0."""
    blocks = [r for r in result.residuals if r.joints is not None and len(r.joints)]
    Q_data = np.vstack([np.asarray(r.joints, float) for r in blocks])
    columns = sorted({c for r in blocks for c in r.extras if not is_derived_column(c)})
    extras_data = {c: np.concatenate([np.asarray(r.extras[c], float) if c in r.extras else
                                      np.zeros(len(r.joints)) for r in blocks])
                   for c in columns}
    finite = np.all(np.isfinite(Q_data), axis=1)
    Q_data = Q_data[finite]
    extras_data = {c: v[finite] for c, v in extras_data.items()}
    rng = np.random.default_rng(SEED)
    if region_kind == MEASURED:
        rows = np.unique(np.linspace(0, len(Q_data) - 1, min(SAMPLES, len(Q_data))).astype(int))
        Q = Q_data[rows]
    else:
        low, high = np.array(region).T
        Q = rng.uniform(low, high, size=(SAMPLES, len(low)))
        rows = rng.integers(0, len(Q_data), size=SAMPLES)
    return Q, {c: v[rows] for c, v in extras_data.items()}


def _left_out(effects: EffectModel | None, effects_point, Q: np.ndarray,
              extras: dict[str, np.ndarray], positions: np.ndarray,
              basis: np.ndarray) -> np.ndarray | None:
    """Per pose the squared distance [m^2] between the instrument point under the model
    with ``effects`` (at ``effects_point`` [m], flange frame) and the delivered geometry's
    ``positions`` (N x 3), the best rigid motion of the whole field removed (``basis``);
    None without effects or when they read a value the data do not give."""
    if effects is None or effects_point is None:
        return None
    needed: dict[str, np.ndarray] = {}
    for column in effects.columns():
        if is_derived_column(column):
            continue  # direction and travel follow from the order of the poses
        if column in extras:
            needed[column] = extras[column]
        elif column == "payload":  # data without the column carry none
            needed[column] = np.zeros(len(Q))
        else:
            return None
    T_tool = effects.tool_poses(Q, needed)
    flange_tool = effects.robot.tool.matrix()
    offset = np.linalg.solve(flange_tool, np.r_[np.asarray(effects_point, float), 1.0])
    with_effects = (T_tool @ offset)[:, :3]
    field = _without_rigid_motion(basis, (with_effects - positions).reshape(-1, 1))
    return (field.reshape(len(Q), 3) ** 2).sum(axis=1)


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


def _noise_ratio(result) -> float:
    """How much of the geometric fit's residual [RMS ratio, >= 1] was structure the effects
    took up: ``rms_geometric / rms_final`` of the fit; 1 where the covariance does not
    have the plain posterior form (an artifact's certified distances) or nothing was
    taken up."""
    if any(kind in INSTRUMENTS and not INSTRUMENTS[kind].plain_posterior
           for kind in (r.kind for r in result.residuals)):
        return 1.0
    geometric, final = float(result.fit.rms_geometric), float(result.fit.rms_final)
    if not (np.isfinite(geometric) and np.isfinite(final)) or final <= 0:
        return 1.0
    return max(1.0, geometric / final)


def _sharpened(covariance: np.ndarray, names: Sequence[str], result, ratio: float
               ) -> np.ndarray:
    """The geometric fit's posterior covariance [SI] with its noise taken as the model
    with effects leaves it rather than as the geometric residual. That residual holds what
    the effects describe, which ``_left_out`` counts already: counted again through the
    noise scale it would inflate every data-determined direction by ``ratio``. With
    ``C = sigma^2 (J^T J + sigma^2 P)^-1`` (the prior weighed with the same noise ``sigma``)
    the data's information is ``C^-1 - P``; at the noise ``sigma / ratio`` the posterior is
    ``(ratio^2 (C^-1 - P) + P)^-1``: the prior's directions keep their tolerance."""
    if ratio <= 1.0 or result.prior is None:
        return covariance
    P = _prior_precision(result, names)
    values, vectors = np.linalg.eigh(0.5 * (covariance + covariance.T))
    if values.min() <= 0:
        return covariance
    information = (vectors / values) @ vectors.T - P  # the data's part [1 / SI^2]
    values, vectors = np.linalg.eigh(0.5 * (information + information.T))
    information = (vectors * np.clip(values, 0.0, None)) @ vectors.T
    return np.linalg.inv(ratio**2 * information + P)


def _prior_precision(result, names: Sequence[str]) -> np.ndarray:
    """The precision [1 / SI^2] of the prior the geometric fit used over ``names``: the
    tolerances', or a fleet prior's full one where it was used (``prior.use``)."""
    tolerance = dict(result.prior.tolerance)
    P = np.diag([1.0 / tolerance[n] ** 2 if tolerance.get(n) else 0.0 for n in names])
    use = getattr(result.prior, "use", None)
    if use is None or use.source == "tolerance" or not len(use.names):
        return P
    held = [k for k, n in enumerate(names) if n in use.names]
    where = [use.names.index(names[k]) for k in held]
    P[np.ix_(held, held)] = np.linalg.inv(use.covariance[np.ix_(where, where)])
    return P


def _error_field(result, kinematics: Kinematics, names: Sequence[str],
                 PG: np.ndarray, noise_ratio: float = 1.0) -> tuple[np.ndarray, dict[str, float]]:
    """``E`` (3N x m) [m]: the error field at the poses (rigid motion removed) is ``E z``
    with ``z`` standard normal (module docstring); ``PG``'s columns (3N rows) are
    ``names``. Its squared row norms summed per pose are the expected squared errors.
    And per parameter the mean square over the poses [m^2] knowing it exactly would take
    off: for a fitted one, the variance of the field explained by it,
    ``|PG Sigma e_i|^2 / Sigma_ii / N``; for one held at nominal, its tolerance's share."""
    registry = kinematics.registry
    count = len(PG) // 3
    column = {name: k for k, name in enumerate(names)}
    kept = [k for k, n in enumerate(result.covariance_names) if n in column]
    fitted = [column[result.covariance_names[k]] for k in kept]
    blocks = [np.zeros((len(PG), 0))]
    carried: dict[str, float] = {}
    if fitted:
        covariance = np.asarray(result.covariance, dtype=float)[np.ix_(kept, kept)]
        covariance = _sharpened(covariance, [result.covariance_names[k] for k in kept], result,
                                noise_ratio)
        covariance = covariance + _represented(result, registry, names, PG, fitted, covariance)
        covariance = 0.5 * (covariance + covariance.T)
        values, vectors = np.linalg.eigh(covariance)
        blocks.append(PG[:, fitted] @ (vectors * np.sqrt(np.clip(values, 0.0, None))))
        moved = PG[:, fitted] @ covariance  # the field's covariance with each parameter
        for j, k in enumerate(fitted):
            if covariance[j, j] > 0:
                carried[names[k]] = float(moved[:, j] @ moved[:, j] / covariance[j, j] / count)
    # Parameters held at nominal by an exact dependency moved nothing the fit could not
    # take up; those held because the data barely see them keep their tolerance.
    held = [n for n in result.identifiability.practical if n in registry]
    basis = np.linalg.qr(PG[:, fitted])[0] if fitted else np.zeros((len(PG), 0))
    for name in held:
        left = PG[:, column[name]] - basis @ (basis.T @ PG[:, column[name]])
        tolerance = tolerance_of(name, registry.quantity(name), result.robot_nominal)
        if tolerance is not None:
            blocks.append(tolerance * left[:, None])
            carried[name] = float(tolerance**2 * (left @ left) / count)
    return np.hstack(blocks), carried


_JOINT_PARAMETER = re.compile(r"^(theta|d|a|alpha|beta)(\d+)$")



def _unseen(result, carried: dict[str, float], box_square: float,
            point_names: tuple[str, ...], instrument: str, *, weak_only: bool = True
            ) -> tuple[Unseen, ...]:
    """The parameters the data barely see (their estimate owes more to the tolerance than
    to the data, or they were held at nominal for it; any parameter unless ``weak_only``)
    that each carry at least ``UNSEEN_SHARE`` of the mean square ``box_square`` [m^2],
    largest first."""
    weak = set(result.identifiability.practical)
    if result.prior is not None:
        weak |= set(result.prior.dominated)
    ranked = sorted(((n, v) for n, v in carried.items() if n in weak or not weak_only),
                    key=lambda item: item[1], reverse=True)
    named = [(n, v) for n, v in ranked if v >= UNSEEN_SHARE * box_square][:UNSEEN_SHOWN]
    return tuple(Unseen(n, float(np.sqrt(v)), remedy(n, point_names, instrument))
                 for n, v in named)


def remedy(name: str, point_names: tuple[str, ...], instrument: str) -> str:
    """What would let the data see parameter ``name`` (words), for data of kind
    ``instrument`` (a dataset kind)."""
    record = INSTRUMENTS.get(instrument)
    thing, turned = (record.noun, record.turned) if record is not None else (
        "instrument", "readings with the flange in other orientations")
    if name in point_names:
        return turned
    if name.startswith("base_"):
        return "registering the robot to the cell"
    if name.startswith("tool_"):
        return "a measurement of the tool itself"
    joint = _JOINT_PARAMETER.match(name)
    which = f"joint {joint.group(2)} and the joints after it" if joint else "the joints"
    return (f"readings that move {which} over more of their ranges, or another placement of "
            f"the {thing}")


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
