"""The tool-position error the delivered model is predicted to have over the work cell.

The work cell is the box of joint ranges the fit data cover (``region``), sampled
uniformly at ``SAMPLES`` poses with a fixed seed. At each pose ``k`` the tool-frame
origin moves with the robot parameters as ``G_k = d p_tool / d theta`` (3 x n, CasADi's
exact Jacobian of the delivered geometry). The parameter error after calibration has
covariance ``Sigma``:

* for the parameters the calibration fitted, the posterior covariance of the geometric
  fit (data and tolerance prior together);
* for those it held at nominal because the data barely see them (the 1% rule), their
  tolerance squared (``calibration.prior``), counted only for the part of their effect
  that the fitted parameters cannot take up over the region; those held by an exact
  dependency move nothing the fit could not take up.

A rigid motion of the whole robot (its base placement) is what registering the robot to
the cell fixes, and no calibration instrument but the cell's own registration sees it; so
the error field is taken after removing its best rigid motion, projected out of
``G = [G_1; ...; G_N]``. The predicted error at pose ``k`` is then

    e_k^2 = tr(P_k G Sigma G^T P_k^T) + s^2                                   [m^2]

with ``P`` the projection and ``s`` the part of the residual that is structured rather
than noise: what the diagnosis left unexplained, plus, when effects were identified but a
controller runs geometry alone, the RMS distance between the delivered geometry and the
model with effects at the fit readings. ``rms``, ``p95`` and ``max`` are over the poses.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..calibration.prior import tolerance_of
from ..kinematics import Kinematics
from ..robot import Robot

SAMPLES = 400
SEED = 9283  # fixed: a prediction is repeatable


@dataclass(frozen=True)
class PredictedAccuracy:
    """Predicted tool-position error over ``region`` [m]: ``rms``, ``p95``, ``max``;
    ``structured`` [m] the part from what the model does not describe (``s``);
    ``region`` the joint ranges (per joint ``[low, high]``, rad or m)."""

    rms: float
    p95: float
    max: float
    structured: float
    region: tuple[tuple[float, float], ...]
    samples: int = SAMPLES

    def to_json(self, length_scale: float, unit: str, angle_unit: str = "rad") -> dict:
        return {"rms": self.rms / length_scale, "p95": self.p95 / length_scale,
                "max": self.max / length_scale, "structured": self.structured / length_scale,
                "unit": unit,
                "region": {"kind": "joint ranges of the fit data", "samples": self.samples,
                           "joints_rad_or_m": [list(r) for r in self.region]}}

    def sentence(self, length_scale: float, unit: str) -> str:
        return (f"predicted tool-position error over the joint ranges the data cover: RMS "
                f"{self.rms / length_scale:.4g}, 95% {self.p95 / length_scale:.4g}, max "
                f"{self.max / length_scale:.4g} {unit}")

    def __repr__(self) -> str:
        return (f"PredictedAccuracy(rms={self.rms:.4g} m, p95={self.p95:.4g} m, "
                f"max={self.max:.4g} m)")


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


def predict(result, delivered: Robot, structured: float = 0.0,
            region: tuple[tuple[float, float], ...] | None = None) -> PredictedAccuracy | None:
    """The ``PredictedAccuracy`` of the ``delivered`` geometry of a ``CalibrationResult``;
    ``structured`` [m] the model error beyond the unexplained residual (see the module
    docstring). None when the data give no joint readings to define the region."""
    region = region if region is not None else region_of(result)
    if region is None:
        return None
    low, high = np.array(region).T
    Q = np.random.default_rng(SEED).uniform(low, high, size=(SAMPLES, len(low)))
    kinematics = Kinematics(delivered)
    G, positions = _tool_jacobians(kinematics, Q)
    P = _without_rigid_motion(positions)
    per_pose = _parameter_error(result, kinematics, G, P)
    unexplained = 0.0 if result.unexplained is None else float(result.unexplained.rms)
    s2 = unexplained**2 + structured**2
    errors = np.sqrt(np.clip(per_pose, 0.0, None) + s2)
    return PredictedAccuracy(float(np.sqrt(np.mean(errors**2))),
                             float(np.percentile(errors, 95)), float(errors.max()),
                             float(np.sqrt(s2)), region)


def _tool_jacobians(kinematics: Kinematics, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``G`` (3N x n) and the tool positions (N x 3) [m] at the rows of ``Q``."""
    q = ca.SX.sym("q", kinematics.dof)
    p = ca.SX.sym("p", len(kinematics.nominal))
    position = kinematics.tool_pose(q, p)[:3, 3]
    function = ca.Function("tool_position_jacobian", [q, p],
                           [position, ca.jacobian(position, p)])
    mapped = function.map(len(Q))
    positions, jacobians = mapped(Q.T, ca.repmat(ca.DM(kinematics.nominal), 1, len(Q)))
    positions = np.asarray(positions).T
    n = len(kinematics.nominal)
    G = np.asarray(jacobians).reshape(3, len(Q), n).transpose(1, 0, 2)  # block k: 3 x n
    return G.reshape(3 * len(Q), n), positions


def _without_rigid_motion(positions: np.ndarray) -> np.ndarray:
    """Projection (3N x 3N) removing every small rigid motion of the point set."""
    centred = positions - positions.mean(axis=0)
    blocks = []
    for point in centred:
        x, y, z = point
        skew = np.array([[0.0, z, -y], [-z, 0.0, x], [y, -x, 0.0]])  # -[p]x: d p / d rotation
        blocks.append(np.hstack([np.eye(3), skew]))
    R = np.vstack(blocks)
    Qr, _ = np.linalg.qr(R)
    return np.eye(len(R)) - Qr @ Qr.T


def _parameter_error(result, kinematics: Kinematics, G: np.ndarray,
                     P: np.ndarray) -> np.ndarray:
    """Expected squared tool-position error [m^2] per pose from the parameters' errors
    (module docstring), the rigid motion removed by ``P``."""
    registry = kinematics.registry
    count = len(G) // 3
    fitted = np.array(registry.indices(list(result.covariance_names)), dtype=int)
    PG = P @ G
    per_pose = np.zeros(count)
    if len(fitted) and result.covariance.shape == (len(fitted), len(fitted)):
        block = PG[:, fitted]
        per_pose += np.einsum("ij,jk,ik->i", block, result.covariance, block).reshape(
            count, 3).sum(axis=1)
    # Parameters held at nominal by an exact dependency moved nothing the fit could not
    # take up; those held because the data barely see them keep their tolerance.
    held = [n for n in result.identifiability.practical if n in registry]
    basis = np.linalg.qr(PG[:, fitted])[0] if len(fitted) else np.zeros((len(G), 0))
    for name in held:
        column = PG[:, registry.index(name)]
        left = column - basis @ (basis.T @ column)
        tolerance = tolerance_of(name, registry.quantity(name), result.robot_nominal)
        if tolerance is not None:
            per_pose += tolerance**2 * (left.reshape(count, 3) ** 2).sum(axis=1)
    return per_pose
