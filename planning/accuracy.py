"""How accurately a plan will place the tool: the predicted standard error of the
measured point over the workspace, from the plan's covariance at the instrument's noise.

For identifiable parameters ``theta`` (placement unknowns projected out) a plan with
Jacobian ``J`` [m per unit] and readings of standard deviation ``sigma`` [m] has the
covariance ``C = sigma^2 (J^T J)^-1``. Moving the robot to a configuration ``q``, the
measured point (probe centre, reflector, laser spot at mid-range) [m, world frame] has the
covariance ``J_t(q) C J_t(q)^T`` with ``J_t = d point / d theta``. Averaged over random
configurations of the workspace (within the joint limits, above the table)::

    e^2 = mean_q trace(J_t C J_t^T) = sigma^2 trace(W (J^T J)^-1),   W = mean_q J_t^T J_t

with the rows of ``J_t`` over the configurations stripped of the infinitesimal rigid
motions of the points they move (``without_rigid_motion``): no kind of data sees where
the robot stands against the instrument (tracker frame, bar and artifact placements,
sphere centre are all unknowns), so a parameter error that moves every point alike is
neither determined by the data nor an error of the calibrated robot, which the user
registers to the work frame separately. ``e`` [m] is the root-mean-square standard
error of the tool position over the workspace after the best rigid motion: what the
calibration's parameter noise costs where it matters. With
``W = L L^T`` (Cholesky), ``e / sigma = sqrt(sum 1 / s_i^2)`` where ``s_i`` are the
singular values of ``J L^-T``: the index ``tool`` is that number, so the planner's
search and its report share one route (``information.Information.spectra``).

Parameters held at their nominal value (not identifiable) add a bias, not a variance;
they do not enter ``e``.
"""

from __future__ import annotations

import numpy as np

from robocal_casadi.common import exact
from robocal_casadi.instruments import instrument

from .reach import Workspace
from .setup import PlanSetup

SAMPLES = 300  # workspace configurations the weight matrix averages over
DEFAULT_NOISE = 10e-6  # [m] reading noise when the dataset file gives none


def measured_point(setup: PlanSetup) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(offset, t1, t2)``: the flange-frame point whose accuracy is predicted [m] and,
    for a laser, the two beam directions normal to its nominal beam (times the mid-range
    reading, [m]) that the row model varies; zero vectors otherwise. The kind's planner
    says which (``Planner.measured_point``)."""
    planner = instrument(setup.kind).planner
    if planner is None or planner.measured_point is None:
        return np.asarray(setup.offset, float), np.zeros(3), np.zeros(3)
    offset, t1, t2 = planner.measured_point(setup)
    return np.asarray(offset, float), np.asarray(t1, float), np.asarray(t2, float)


def workspace_samples(setup: PlanSetup, workspace: Workspace, rng: np.random.Generator,
                      count: int = SAMPLES) -> np.ndarray:
    """``count`` random joint readings (N x dof) within the limits whose links and
    measured point are clear of the table."""
    offset, _, _ = measured_point(setup)
    found: list[np.ndarray] = []
    for _ in range(50):
        Q = workspace.random_joints(rng, 4 * count)
        points = workspace.kinematics.points(Q, offset, workspace.p)
        found += list(Q[workspace.clear_of_table(Q, points)])
        if len(found) >= count:
            break
    if not found:  # nothing clear of the table: judge over the limits alone
        return workspace.random_joints(rng, count)
    return np.array(found[:count])


def tool_weights(setup: PlanSetup, workspace: Workspace, parameters: tuple[str, ...],
                 rng: np.random.Generator, count: int = SAMPLES, *,
                 rigid_motion: bool = False) -> np.ndarray:
    """``W = mean_q J_t^T J_t`` over ``parameters`` (robot names, then mounted ones in the
    row model's order) [m^2 per unit^2], rigid motions of the workspace's points
    projected out of ``J_t`` unless ``rigid_motion`` (counted: a laser calibrated on
    pendant poses, where the robot's place is given and only the sensor is unknown)."""
    kin = workspace.kinematics
    Q = workspace_samples(setup, workspace, rng, count)
    offset, t1, t2 = measured_point(setup)
    _, J_p, _, J_offset = kin.batch("point_jacobians")(Q, workspace.p, offset)
    n_robot = len(kin.registry)
    columns = [J_p]
    mounted = parameters[n_robot:]
    if mounted:
        columns.append(J_offset)  # probe, reflector or laser origin x, y, z
    if len(mounted) == 5:  # the laser's two beam directions: the spot moves by R t_k
        rotations = kin.flange_poses(Q, workspace.p)[:, :3, :3]
        columns.append(np.stack([exact.matmul(rotations, t1), exact.matmul(rotations, t2)],
                                axis=2))
    J = np.concatenate(columns, axis=2)  # N x 3 x parameters
    if J.shape[2] != len(parameters):
        raise ValueError(f"tool Jacobian has {J.shape[2]} columns for {len(parameters)} "
                         f"parameters")
    J = J.reshape(-1, J.shape[2])
    if not rigid_motion:
        J = without_rigid_motion(J, kin.points(Q, offset, workspace.p))
    # common.exact: the planner's search and refinement start from these weights, and
    # must not start from processor-dependent last bits
    return exact.gram(J) / len(Q)


def without_rigid_motion(J: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Point Jacobian rows ``J`` (3N x n, the 3 rows of each point in turn) with the
    infinitesimal rigid motions of the ``points`` (N x 3) [m] projected out: what is left
    of each parameter's effect after the best rigid motion of all points (the placement
    of the robot against the instrument, which no kind of data observes)."""
    centred = points - points.mean(axis=0)
    rigid = np.zeros((len(points), 3, 6))
    rigid[:, :, :3] = np.eye(3)
    x, y, z = centred.T
    # omega x p = -[p]x omega
    rigid[:, 0, 4], rigid[:, 0, 5] = z, -y
    rigid[:, 1, 3], rigid[:, 1, 5] = -z, x
    rigid[:, 2, 3], rigid[:, 2, 4] = y, -x
    return exact.project_out(J, rigid.reshape(-1, 6), 1e-12)


def tool_transform(weights: np.ndarray) -> np.ndarray:
    """``L^-1`` with ``L L^T = W`` (a tiny ridge keeps a column the tool never feels
    invertible: its error then counts as nothing, not as infinite)."""
    W = np.asarray(weights, float)
    ridge = 1e-12 * max(np.trace(W) / len(W), 1e-300)
    return exact.lower_inverse(exact.cholesky(W + ridge * np.eye(len(W))))


def tool_error(spectrum_tool: np.ndarray, noise: float) -> float:
    """RMS standard error [m] of the tool position over the workspace from the singular
    values of ``J L^-T`` (``spectrum_tool``) and the reading noise ``noise`` [m]."""
    s = np.asarray(spectrum_tool, float)
    if s.size == 0 or s.min() <= 0:
        return float("inf")
    return float(noise * np.sqrt(np.sum(1.0 / s**2)))
