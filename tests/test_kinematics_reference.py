"""CasADi kinematics against independent references: pinocchio and finite differences.

Every example robot and every real robot file, nominal and with perturbed geometry
(non-zero beta, base and tool), on random and near-singular joint readings.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocal_casadi.model import examples
from robocal_casadi.model.kinematics import Kinematics
from robocal_casadi.model.pinocchio_model import (
    export_urdf,
    frame_placements,
    gravity_torques,
    pinocchio_model,
)

TOLERANCE = 1e-12  # [m] for positions, dimensionless for rotation matrix entries
STEP = 1e-6  # central-difference step [m] or [rad]
FD_TOLERANCE = 1e-8  # central differences carry ~h^2 truncation and ~eps/h rounding


def perturbed_parameters(kinematics: Kinematics, rng: np.random.Generator) -> np.ndarray:
    """Nominal geometry plus errors: 5 mm on lengths, 0.02 rad on angles, larger on base/tool."""
    registry = kinematics.registry
    scale = np.array([0.005 if quantity == "length" else 0.02 for quantity in registry.quantities])
    for name in registry.names:
        if name.startswith(("base_", "tool_")):
            scale[registry.index(name)] *= 20
    return kinematics.nominal + rng.uniform(-1, 1, len(registry)) * scale


def pinocchio_frames(kinematics: Kinematics, p: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """Per row of ``Q``: frame_0..frame_n, flange, tool from pinocchio (N x (n+3) x 4 x 4)."""
    model = pinocchio_model(kinematics.robot.with_parameters(p))
    names = [f"frame_{i}" for i in range(kinematics.dof + 1)] + ["flange", "tool"]
    return np.array([frame_placements(model, q, names) for q in Q])


def casadi_joint_frames(kinematics: Kinematics, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    return np.array([np.asarray(T) for T in kinematics.joint_frames(q, p)])


@pytest.mark.parametrize("perturb", [False, True], ids=["nominal", "perturbed"])
def test_frames_agree_with_pinocchio(any_robot, samples, perturb):
    kinematics = Kinematics(any_robot)
    p = kinematics.nominal
    if perturb:
        p = perturbed_parameters(kinematics, np.random.default_rng(1))
    Q = samples(any_robot)
    reference = pinocchio_frames(kinematics, p, Q)
    n = kinematics.dof
    np.testing.assert_allclose(kinematics.tool_poses(Q, p), reference[:, n + 2], rtol=0,
                               atol=TOLERANCE)
    np.testing.assert_allclose(kinematics.flange_poses(Q, p), reference[:, n + 1], rtol=0,
                               atol=TOLERANCE)
    for q, frames in zip(Q, reference):
        np.testing.assert_allclose(casadi_joint_frames(kinematics, p, q), frames[: n + 1],
                                   rtol=0, atol=TOLERANCE)


@st.composite
def configuration_and_geometry(draw, robot_name: str):
    robot = examples.ROBOTS[robot_name]()
    lower = np.where(np.isfinite(robot.lower_limits), robot.lower_limits, -np.pi)
    upper = np.where(np.isfinite(robot.upper_limits), robot.upper_limits, np.pi)
    q = [draw(st.floats(lo, hi, allow_nan=False)) for lo, hi in zip(lower, upper)]
    seed = draw(st.integers(0, 2**32 - 1))
    return robot, np.array(q), seed


@pytest.mark.parametrize("robot_name", list(examples.ROBOTS))
def test_tool_pose_agrees_with_pinocchio_property(robot_name):
    kinematics = Kinematics(examples.ROBOTS[robot_name]())

    @settings(max_examples=30, deadline=None)
    @given(configuration_and_geometry(robot_name))
    def check(case):
        _, q, seed = case
        p = perturbed_parameters(kinematics, np.random.default_rng(seed))
        reference = pinocchio_frames(kinematics, p, q[None])[0, -1]
        np.testing.assert_allclose(kinematics.tool_poses(q, p)[0], reference, rtol=0,
                                   atol=TOLERANCE)

    check()


def central_difference(function, x: np.ndarray, step: float = STEP) -> np.ndarray:
    """d function / d x by central differences; columns follow the entries of ``x``."""
    columns = []
    for k in range(len(x)):
        e = np.zeros_like(x)
        e[k] = step
        columns.append((np.ravel(function(x + e)) - np.ravel(function(x - e))) / (2 * step))
    return np.column_stack(columns)


def test_point_jacobians_agree_with_finite_differences(any_robot, samples):
    kinematics = Kinematics(any_robot)
    rng = np.random.default_rng(2)
    p = perturbed_parameters(kinematics, rng)
    offset = np.array([0.02, -0.03, 0.15])

    def point(q, p, o):
        return np.asarray(kinematics.point(q, p, o)).ravel()

    for q in samples(any_robot, count=6, seed=3):
        position, J_p, J_q, J_offset = (np.asarray(v)
                                        for v in kinematics.point_jacobians(q, p, offset))
        np.testing.assert_allclose(position.ravel(), point(q, p, offset), rtol=0, atol=1e-15)
        np.testing.assert_allclose(J_p, central_difference(lambda x, q=q: point(q, x, offset), p),
                                   rtol=0, atol=FD_TOLERANCE)
        np.testing.assert_allclose(J_q, central_difference(lambda x: point(x, p, offset), q),
                                   rtol=0, atol=FD_TOLERANCE)
        np.testing.assert_allclose(J_offset,
                                   central_difference(lambda x, q=q: point(q, p, x), offset),
                                   rtol=0, atol=FD_TOLERANCE)


def rotation_rate(R_plus: np.ndarray, R_minus: np.ndarray, R: np.ndarray,
                  step: float) -> np.ndarray:
    """World angular velocity from a central difference of a rotation: (dR/dq) R^T as a vector."""
    W = (R_plus - R_minus) / (2 * step) @ R.T
    return np.array([W[2, 1], W[0, 2], W[1, 0]])


def test_tool_jacobian_agrees_with_finite_differences_and_pinocchio(any_robot, samples):
    kinematics = Kinematics(any_robot)
    p = perturbed_parameters(kinematics, np.random.default_rng(4))
    model = pinocchio_model(any_robot.with_parameters(p))
    data = model.createData()
    tool = model.getFrameId("tool")
    for q in samples(any_robot, count=8, seed=5):
        J = np.asarray(kinematics.tool_jacobian(q, p))
        T = kinematics.tool_poses(q, p)[0]
        expected = np.zeros((6, kinematics.dof))
        for k in range(kinematics.dof):
            e = np.zeros(kinematics.dof)
            e[k] = STEP
            plus, minus = kinematics.tool_poses(np.vstack([q + e, q - e]), p)
            expected[:3, k] = (plus[:3, 3] - minus[:3, 3]) / (2 * STEP)
            expected[3:, k] = rotation_rate(plus[:3, :3], minus[:3, :3], T[:3, :3], STEP)
        np.testing.assert_allclose(J, expected, rtol=0, atol=FD_TOLERANCE)
        reference = pin.computeFrameJacobian(model, data, q, tool, pin.LOCAL_WORLD_ALIGNED)
        np.testing.assert_allclose(J, reference, rtol=0, atol=TOLERANCE)


def test_parallel_axes_stay_parallel_in_ur_type():
    """Joints 2, 3, 4 of the UR-type arm (axes z_1, z_2, z_3) are parallel everywhere."""
    kinematics = Kinematics(examples.ur_type())
    for q in np.random.default_rng(6).uniform(-np.pi, np.pi, size=(10, kinematics.dof)):
        axes = casadi_joint_frames(kinematics, kinematics.nominal, q)[1:4, :3, 2]
        np.testing.assert_allclose(np.cross(axes[0], axes[1]), 0, atol=1e-15)
        np.testing.assert_allclose(np.cross(axes[1], axes[2]), 0, atol=1e-15)


def test_urdf_export_reads_back_into_pinocchio(any_robot, samples, tmp_path):
    """The exported URDF, parsed by pinocchio, gives our frames and our gravity torques."""
    kinematics = Kinematics(any_robot)
    p = perturbed_parameters(kinematics, np.random.default_rng(10))
    robot = any_robot.with_parameters(p)
    path = tmp_path / "robot.urdf"
    export_urdf(robot, path)
    model = pin.buildModelFromUrdf(str(path))
    model.gravity = pin.Motion(np.asarray(robot.gravity), np.zeros(3))  # URDF has no gravity
    assert model.nq == robot.dof
    data = model.createData()
    names = [f"frame_{i}" for i in range(robot.dof + 1)] + ["tool"]
    Q = samples(robot, count=8, seed=11)
    for q in Q:
        frames = frame_placements(model, q, names)
        np.testing.assert_allclose(frames[:-1], casadi_joint_frames(kinematics, p, q), rtol=0,
                                   atol=TOLERANCE)
        np.testing.assert_allclose(frames[-1], kinematics.tool_poses(q, p)[0], rtol=0,
                                   atol=TOLERANCE)
    expected = gravity_torques(robot, Q)
    read_back = np.array([pin.computeGeneralizedGravity(model, data, q) for q in Q])
    np.testing.assert_allclose(read_back, expected, rtol=1e-12, atol=1e-10)
