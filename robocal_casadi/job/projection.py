"""The geometry that best reproduces a model with effects, for controllers that run
geometry alone.

At the fit data's joint readings (with each row's payload, temperature and direction of
motion, as the effects read them) the model with effects puts the tool frame at
``T_target``. The projected geometry ``p`` minimises, over the robot parameters the
geometric calibration fitted,

    sum_k  sum_m | T_world_tool(q_k, p) m - T_target_k m |^2                 [m^2]

for the tool frame's origin and the points ``LEVER`` [m] along its three axes, so that
position and orientation both count, in lengths. Gauss-Newton from the geometric fit;
CasADi gives the exact Jacobian (one row's, mapped over the rows).
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as ca
import numpy as np

from ..effects.effect_model import EffectModel
from ..effects.motion import is_direction_column
from ..model.kinematics import Kinematics
from ..model.robot import Robot

LEVER = 0.1  # [m] points on the tool axes: an orientation error of 1 mrad counts 0.1 mm
MAX_ROWS = 400  # readings the projection is fitted on (spread evenly over the data)
ITERATIONS = 20
STEP_TOLERANCE = 1e-12  # [SI] a Gauss-Newton step below this ends the fit


def projected_geometry(result, final_robot: Robot, start_robot: Robot) -> Robot | None:
    """The geometry-only robot closest to ``result``'s model with effects (geometry
    ``final_robot``) over the fit readings, started from ``start_robot``; None when the
    data carry no joint readings (sensor-only scans) or no robot parameter was fitted."""
    targets = model_targets(result, final_robot)
    kinematics = Kinematics(start_robot)
    registry = kinematics.registry
    fitted = [n for n in result.covariance_names if n in registry]
    if targets is None or not fitted:
        return None
    Q, T_target = targets
    free = np.array(registry.indices(fitted), dtype=int)
    p = np.array(kinematics.nominal, dtype=float)
    evaluate = _functions(kinematics, Q, T_target, free)
    for _ in range(ITERATIONS):
        r, J = evaluate(p)
        step = np.linalg.lstsq(J, -r, rcond=1e-12)[0]
        p[free] += step
        if np.max(np.abs(step)) < STEP_TOLERANCE:
            break
    return start_robot.with_parameters(p)


def model_targets(result, final_robot: Robot) -> tuple[np.ndarray, np.ndarray] | None:
    """Fit readings (N x dof) and the tool poses (N x 4 x 4) [m] the model with effects
    gives there, at most ``MAX_ROWS`` rows evenly spread."""
    model = effect_model(result, final_robot)
    readings, poses = [], []
    for residuals in result.residuals:
        if residuals.joints is None or not len(residuals.joints):
            continue
        Q = np.asarray(residuals.joints, dtype=float)
        extras = {}
        for name in model.columns():
            if is_direction_column(name):
                continue  # from the order of the rows
            if name in residuals.extras:
                extras[name] = np.asarray(residuals.extras[name], dtype=float)
            elif name == "payload":
                extras[name] = np.zeros(len(Q))
            else:
                return None  # a value the effects need that the data do not give
        readings.append(Q)
        poses.append(model.tool_poses(Q, extras))
    if not readings:
        return None
    Q_all, T_all = np.vstack(readings), np.concatenate(poses)
    keep = np.unique(np.linspace(0, len(Q_all) - 1, min(MAX_ROWS, len(Q_all))).astype(int))
    return Q_all[keep], T_all[keep]


def effect_model(result, final_robot: Robot) -> EffectModel:
    """``result``'s model with effects on the geometry ``final_robot``, the payload's
    centre of mass [m] as the fit data give it."""
    com = next((r.payload_com for r in result.residuals if r.payload_com is not None), None)
    payload = any("payload" in r.extras for r in result.residuals)
    x, y, z = (0.0, 0.0, 0.0) if com is None else (float(v) for v in com)
    return EffectModel(final_robot, tuple(result.effect_models),
                       np.asarray(result.effect_values, dtype=float), (x, y, z), payload)


def _functions(kinematics: Kinematics, Q: np.ndarray, T_target: np.ndarray, free: np.ndarray
               ) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """``p -> (residual, d residual / d p[free])`` over the rows of ``Q``.

    One row's lever points and their derivatives are an SX function of ``(q, p)``,
    mapped over the rows; the rows' residuals are stacked in order, each the four points'
    coordinates one point after the other."""
    q = ca.SX.sym("q", kinematics.dof)
    p = ca.SX.sym("p", len(kinematics.nominal))
    points = np.array([[0, 0, 0, 1], [LEVER, 0, 0, 1], [0, LEVER, 0, 1], [0, 0, LEVER, 1]],
                      dtype=float).T  # 4 x 4, one point a column
    world = ca.vec((kinematics.tool_pose(q, p) @ ca.DM(points))[:3, :])  # 12: point by point
    fitted = ca.vertcat(*[p[int(i)] for i in free])
    row = ca.Function("lever_points", [q, p], [world, ca.jacobian(world, fitted)])
    count = len(Q)
    rows = kinematics.mapped(row, count)
    target = np.stack([(T @ points)[:3, :].T.ravel() for T in T_target])  # N x 12
    columns = len(free)

    def evaluate(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        P, J = (np.asarray(out) for out in rows(Q.T, x))  # 12 x N, 12 x (N k) row by row
        J = J.reshape(12, count, columns).transpose(1, 0, 2).reshape(12 * count, columns)
        return (P.T - target).ravel(), J

    return evaluate
