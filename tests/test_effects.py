"""Effects: each delta against a direct numpy computation of its definition, gravity
torques against pinocchio, exact derivatives against finite differences."""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from robocal_casadi.effects import (
    EFFECTS,
    JointCompliance,
    JointCyclic,
    JointScale,
    RowContext,
    ThermalDrift,
    make_effect,
)
from robocal_casadi.effects.compliance import independent_terms
from robocal_casadi.effects.gravity import GravityModel
from robocal_casadi.errors import InputError
from robocal_casadi.model.examples import ROBOTS
from robocal_casadi.model.transforms import rot_x, rot_y, rot_z, translation

RNG_SEED = 7


# ----------------------------------------------------------------------- references


def pinocchio_model(robot, payload=0.0, payload_com=(0.0, 0.0, 0.0)):
    """An independent pinocchio model of a DH robot: one RZ/PZ joint per DH row."""
    model = pin.Model()
    model.gravity.linear = np.array(robot.gravity, dtype=float)
    parent, before = 0, robot.base.matrix()
    for i, joint in enumerate(robot.joints, start=1):
        if robot.convention == "dh":
            pre = np.eye(4)
            post = (rot_z(joint.theta) @ translation(0, 0, joint.d) @ translation(joint.a, 0, 0)
                    @ rot_x(joint.alpha) @ rot_y(joint.beta))
        else:
            pre = rot_x(joint.alpha) @ translation(joint.a, 0, 0)
            post = rot_z(joint.theta) @ translation(0, 0, joint.d) @ rot_y(joint.beta)
        M = before @ pre
        kind = pin.JointModelRZ() if joint.revolute else pin.JointModelPZ()
        parent = model.addJoint(parent, kind, pin.SE3(M[:3, :3], M[:3, 3]), f"joint{i}")
        com = post[:3, :3] @ np.array(joint.com) + post[:3, 3]
        model.appendBodyToJoint(parent, pin.Inertia(joint.mass, com, 1e-3 * np.eye(3)),
                                pin.SE3.Identity())
        before = post
    if payload:
        com = before[:3, :3] @ np.asarray(payload_com, float) + before[:3, 3]
        model.appendBodyToJoint(parent, pin.Inertia(payload, com, np.zeros((3, 3))),
                                pin.SE3.Identity())
    return model


def pinocchio_gravity(robot, q, payload=0.0, payload_com=(0.0, 0.0, 0.0)) -> np.ndarray:
    model = pinocchio_model(robot, payload, payload_com)
    return pin.computeGeneralizedGravity(model, model.createData(), np.asarray(q, float))


def perturbed(robot, rng):
    """The robot with every geometric parameter nudged (betas and base too)."""
    p = robot.parameter_vector() + rng.normal(0, 0.01, len(robot.parameters()))
    return replace(robot.with_parameters(p), gravity=(0.3, -0.2, -9.81))


def readings(robot, rng, n):
    lower = np.where(np.isfinite(robot.lower_limits), robot.lower_limits, -np.pi)
    upper = np.where(np.isfinite(robot.upper_limits), robot.upper_limits, np.pi)
    return rng.uniform(lower, upper, size=(n, robot.dof))


def without_masses(robot):
    return replace(robot, joints=tuple(replace(j, mass=None, com=None) for j in robot.joints))


class Evaluator:
    """``(q, p, theta, temperature, time, payload, payload_com) -> (dq, dp)`` of one effect."""

    def __init__(self, effect, robot, columns=("temperature", "time", "payload")):
        registry = robot.parameters()
        self.q = ca.SX.sym("q", robot.dof)
        self.p = ca.SX.sym("p", len(registry))
        self.theta = ca.SX.sym("theta", len(effect.parameter_names()))
        self.extras = {c: ca.SX.sym(c) for c in columns}
        self.com = ca.SX.sym("payload_com", 3)
        row = RowContext(robot, registry, self.q, self.p, self.extras, self.com)
        dq, dp = effect.delta(row, self.theta)
        dp = ca.SX.zeros(len(registry)) if dp is None else dp
        self.inputs = [self.q, self.p, self.theta, *self.extras.values(), self.com]
        self.dq, self.dp = dq, dp
        self.f = ca.Function("delta", self.inputs, [dq, dp])
        self.jac = ca.Function("delta_jacobians", self.inputs, [ca.jacobian(dq, self.q),
                                                    ca.jacobian(dq, self.theta),
                                                    ca.jacobian(dp, self.theta)])
        self.nominal = registry.vector_of(robot)

    def __call__(self, q, theta, p=None, temperature=0.0, time=0.0, payload=0.0,
                 com=(0.0, 0.0, 0.0)):
        p = self.nominal if p is None else p
        dq, dp = self.f(q, p, theta, temperature, time, payload, com)
        return np.asarray(dq).ravel(), np.asarray(dp).ravel()

    def jacobians(self, q, theta, **kw):
        p = self.nominal
        out = self.jac(q, p, theta, kw.get("temperature", 0.0), kw.get("time", 0.0),
                       kw.get("payload", 0.0), kw.get("com", (0.0, 0.0, 0.0)))
        return [np.asarray(o) for o in out]


# ----------------------------------------------------------------------- gravity


@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_gravity_torque_matches_pinocchio(name):
    rng = np.random.default_rng(RNG_SEED)
    robot = perturbed(ROBOTS[name](), rng)
    model = GravityModel(robot)
    Q = readings(robot, rng, 6)
    payload = rng.uniform(0, 5, 6)
    com = np.array([0.01, -0.02, 0.12])
    ours = model.torques(Q, robot.parameter_vector(), payload, com)
    theirs = np.array([pinocchio_gravity(robot, q, m, com) for q, m in zip(Q, payload)])
    assert np.abs(theirs).max() > 1.0  # a real load, not all zeros
    np.testing.assert_allclose(ours, theirs, atol=1e-9 * np.abs(theirs).max())


def test_gravity_torque_matches_project_pinocchio_model():
    module = pytest.importorskip("robocal_casadi.model.pinocchio_model")
    rng = np.random.default_rng(1)
    robot = perturbed(ROBOTS["panda_7dof"](), rng)
    Q = readings(robot, rng, 4)
    payload, com = rng.uniform(0, 3, 4), np.array([0.0, 0.02, 0.08])
    theirs = module.gravity_torques(robot, Q, payload, com)
    ours = GravityModel(robot).torques(Q, None, payload, com)
    np.testing.assert_allclose(ours, theirs, atol=1e-9 * np.abs(theirs).max())


# ----------------------------------------------------------------------- compliance


@pytest.mark.parametrize("name", ["industrial_6r", "panda_7dof", "prismatic_rrp"])
def test_compliance_is_minus_c_times_pinocchio_gravity(name):
    rng = np.random.default_rng(RNG_SEED)
    robot = ROBOTS[name]()
    joints = tuple(range(1, robot.dof + 1))
    effect = JointCompliance(joints, robot=robot)
    assert effect.parameter_names() == tuple(f"c{j}" for j in joints)
    evaluate = Evaluator(effect, robot)
    c = rng.uniform(1e-6, 5e-6, robot.dof)
    com = np.array([0.0, 0.03, 0.1])
    for q in readings(robot, rng, 4):
        dq, dp = evaluate(q, c, payload=3.0, com=com)
        expected = -c * pinocchio_gravity(robot, q, 3.0, com)
        np.testing.assert_allclose(dq, expected, atol=1e-15)
        assert not dp.any()


def test_compliance_on_some_joints_leaves_the_others():
    robot = ROBOTS["industrial_6r"]()
    evaluate = Evaluator(JointCompliance((2, 3)), robot)
    q = np.array([0.1, -0.4, 0.7, 0.2, 0.5, -0.3])
    dq, _ = evaluate(q, [2e-6, 3e-6])
    tau = pinocchio_gravity(robot, q)
    np.testing.assert_allclose(dq, [0, -2e-6 * tau[1], -3e-6 * tau[2], 0, 0, 0], atol=1e-16)


@pytest.mark.parametrize("name", ["industrial_6r", "ur_type", "panda_7dof"])
def test_lumped_compliance_spans_the_true_deflection(name):
    """Without masses, the lumped terms reproduce -c_j tau_j(q) up to a theta offset."""
    rng = np.random.default_rng(RNG_SEED)
    robot = ROBOTS[name]()
    bare = without_masses(robot)
    effect = make_effect("joint_compliance", range(2, robot.dof + 1), bare, {"payload": [0.0]})
    assert effect.lumped and effect.payload
    evaluate = Evaluator(effect, bare)
    Q = readings(robot, rng, 60)
    payload = rng.uniform(0, 4, len(Q))
    com = np.array([0.02, 0.0, 0.15])
    # the lumped model is linear in its parameters: its columns, row by row
    n = len(effect.parameter_names())
    columns = np.array([[evaluate(q, np.eye(n)[k], payload=m, com=com)[0] for k in range(n)]
                        for q, m in zip(Q, payload)])  # rows x parameters x dof
    c = rng.uniform(1e-6, 4e-6, robot.dof)
    truth = np.array([-c * pinocchio_gravity(robot, q, m, com) for q, m in zip(Q, payload)])
    names = effect.parameter_names()
    for j in range(2, robot.dof + 1):
        own = [k for k, name in enumerate(names) if name == f"c{j}" or name.startswith(f"c{j}_")]
        others = [k for k in range(n) if k not in own]
        assert not columns[:, others, j - 1].any()
        A = np.column_stack([columns[:, own, j - 1], np.ones(len(Q))])  # + theta offset
        x, *_ = np.linalg.lstsq(A, truth[:, j - 1], rcond=None)
        misfit = A @ x - truth[:, j - 1]
        assert np.abs(misfit).max() < 1e-9 * np.abs(truth[:, j - 1]).max()
        # the payload term carries c_j itself
        assert x[own.index(names.index(f"c{j}"))] == pytest.approx(c[j - 1], rel=1e-6)
        # and the kept columns are independent of each other and of a constant
        s = np.linalg.svd(A / np.linalg.norm(A, axis=0), compute_uv=False)
        assert s[-1] > 1e-7


def test_lumped_terms_skip_vertical_axes():
    bare = without_masses(ROBOTS["prismatic_rrp"]())
    assert [independent_terms(bare, j) for j in range(1, 5)] == [(), (), (), ()]
    assert independent_terms(without_masses(ROBOTS["industrial_6r"]()), 1) == ()


def test_compliance_with_known_masses_needs_them():
    bare = without_masses(ROBOTS["industrial_6r"]())
    with pytest.raises(InputError, match="mass"):
        Evaluator(JointCompliance((2,)), bare)


# ----------------------------------------------------------------------- the others


def test_cyclic_matches_its_definition():
    rng = np.random.default_rng(RNG_SEED)
    robot = ROBOTS["ur_type"]()
    effect = JointCyclic((1, 4))
    assert effect.parameter_names() == ("a1_1", "b1_1", "a2_1", "b2_1",
                                        "a1_4", "b1_4", "a2_4", "b2_4")
    evaluate = Evaluator(effect, robot)
    theta = rng.normal(0, 1e-4, 8)
    for q in readings(robot, rng, 5):
        dq, dp = evaluate(q, theta)
        expected = np.zeros(robot.dof)
        for k, j in enumerate((1, 4)):
            a1, b1, a2, b2 = theta[4 * k:4 * k + 4]
            x = q[j - 1]
            expected[j - 1] = (a1 * np.sin(x) + b1 * np.cos(x)
                               + a2 * np.sin(2 * x) + b2 * np.cos(2 * x))
        np.testing.assert_allclose(dq, expected, atol=1e-18)
        assert not dp.any()


def test_scale_matches_its_definition_on_revolute_and_prismatic_joints():
    robot = ROBOTS["prismatic_rrp"]()
    evaluate = Evaluator(JointScale((2, 3)), robot)
    q = np.array([0.3, -1.2, 0.17, 2.0])
    dq, dp = evaluate(q, [1e-3, -2e-4])
    np.testing.assert_allclose(dq, [0, 1e-3 * -1.2, -2e-4 * 0.17, 0], atol=1e-18)
    assert not dp.any()


@pytest.mark.parametrize("column", ["temperature", "time"])
def test_thermal_drift_matches_its_definition(column):
    robot = ROBOTS["industrial_6r"]()
    registry = robot.parameters()
    extras = {column: np.array([20.0, 22.0, 24.0])}
    effect = make_effect("thermal_drift", (), robot, extras)
    assert effect.reference_value == pytest.approx(22.0)
    assert effect.parameter_names() == ({"temperature": "k_T", "time": "k_t"}[column],)
    evaluate = Evaluator(effect, robot)
    p = robot.parameter_vector() + 0.01
    k, value = 1.2e-5, 25.5
    dq, dp = evaluate(np.zeros(robot.dof), [k], p=p, **{column: value})
    expected = np.zeros(len(registry))
    for i in range(1, robot.dof + 1):
        for stem in "da":
            index = registry.index(f"{stem}{i}")
            expected[index] = k * (value - 22.0) * p[index]
    np.testing.assert_allclose(dp, expected, atol=1e-18)
    assert not dq.any()


def test_thermal_drift_needs_its_column_and_reference():
    with pytest.raises(InputError, match="temperature"):
        make_effect("thermal_drift", (), ROBOTS["industrial_6r"](), {"payload": [1.0]})
    with pytest.raises(InputError, match="column"):
        ThermalDrift(column="humidity")
    effect = ThermalDrift()
    with pytest.raises(InputError, match="non-numeric"):
        effect.reference({"temperature": np.array([20.0, np.nan])})


# ----------------------------------------------------------------------- derivatives


def _finite_difference(f, x, h):
    x = np.asarray(x, float)
    columns = []
    for k in range(len(x)):
        step = np.zeros_like(x)
        step[k] = h
        columns.append((f(x + step) - f(x - step)) / (2 * h))
    return np.column_stack(columns)


@pytest.mark.parametrize("effect_name,robot_name", [
    ("joint_compliance", "industrial_6r"), ("joint_compliance", "panda_7dof"),
    ("joint_compliance_lumped", "ur_type"), ("joint_cyclic", "industrial_6r"),
    ("joint_scale", "prismatic_rrp"), ("thermal_drift", "industrial_6r"),
])
def test_exact_derivatives_match_finite_differences(effect_name, robot_name):
    rng = np.random.default_rng(RNG_SEED)
    robot = ROBOTS[robot_name]()
    extras = {"temperature": np.array([18.0, 24.0]), "payload": np.array([0.0, 2.0])}
    if effect_name == "joint_compliance_lumped":
        robot = without_masses(robot)
        effect = make_effect("joint_compliance", (2, 3, 5), robot, extras)
    else:
        effect = make_effect(effect_name, (2, 3) if effect_name != "thermal_drift" else (),
                             robot, extras)
    evaluate = Evaluator(effect, robot)
    theta = rng.normal(0, 1e-3, len(effect.parameter_names()))
    q = readings(robot, rng, 1)[0]
    kw = dict(temperature=23.0, payload=1.5, com=(0.0, 0.01, 0.1))
    J_q, J_theta, J_dp_theta = evaluate.jacobians(q, theta, **kw)
    fd_q = _finite_difference(lambda x: evaluate(x, theta, **kw)[0], q, 1e-6)
    fd_theta = _finite_difference(lambda x: evaluate(q, x, **kw)[0], theta, 1e-6)
    fd_dp = _finite_difference(lambda x: evaluate(q, x, **kw)[1], theta, 1e-6)
    for exact, approx in ((J_q, fd_q), (J_theta, fd_theta), (J_dp_theta, fd_dp)):
        scale = max(np.abs(approx).max(), 1e-12)
        np.testing.assert_allclose(exact, approx, atol=1e-6 * scale)
    assert np.abs(J_theta).max() + np.abs(J_dp_theta).max() > 0


# ----------------------------------------------------------------------- registry, input


def test_registry_names_every_contract_effect():
    assert set(EFFECTS) == {"joint_compliance", "joint_cyclic", "joint_scale", "thermal_drift",
                            "joint_coupling", "transmission_coupling", "backlash",
                            "hysteresis", "coupled_compliance", "motor_play", "link_deflection"}
    for name, cls in EFFECTS.items():
        assert cls.name == name


def test_bad_joints_and_names_are_refused():
    robot = ROBOTS["prismatic_rrp"]()
    with pytest.raises(InputError, match="valid names"):
        make_effect("joint_backlash", (1,), robot)
    with pytest.raises(InputError, match="joint 7 does not exist"):
        Evaluator(JointScale((7,)), robot)
    with pytest.raises(InputError, match="prismatic"):
        Evaluator(JointCyclic((3,)), robot)
    with pytest.raises(InputError, match="twice"):
        Evaluator(JointScale((2, 2)), robot)


# ----------------------------------------------------------------------- coupling, backlash


def test_coupling_matches_its_definition():
    from robocal_casadi.effects import JointCoupling

    robot = ROBOTS["industrial_6r"]()
    effect = JointCoupling((4, 5, 4), drivers=(6, 6, 1))
    assert effect.parameter_names() == ("sin4_q6", "cos4_q6", "sin5_q6", "cos5_q6",
                                        "sin4_q1", "cos4_q1")
    evaluate = Evaluator(effect, robot)
    theta = np.array([3e-4, -1e-4, 2e-4, 5e-5, -4e-4, 1e-4])
    q = np.array([0.3, -0.5, 0.8, 1.1, -0.7, 2.5])
    dq, dp = evaluate(q, theta)
    expected = np.zeros(6)
    expected[3] = 3e-4 * np.sin(2.5) - 1e-4 * np.cos(2.5) - 4e-4 * np.sin(0.3) + 1e-4 * np.cos(0.3)
    expected[4] = 2e-4 * np.sin(2.5) + 5e-5 * np.cos(2.5)
    np.testing.assert_allclose(dq, expected, atol=1e-18)
    assert not dp.any()
    with pytest.raises(InputError, match="cannot drive itself"):
        JointCoupling((4,), drivers=(4,))
    with pytest.raises(InputError, match="one driver per joint"):
        JointCoupling((4, 5), drivers=(6,))
    with pytest.raises(InputError, match="prismatic"):
        Evaluator(JointCoupling((1,), drivers=(3,)), ROBOTS["prismatic_rrp"]())


def test_coupling_candidates_are_the_ordered_pairs_of_revolute_joints():
    from robocal_casadi.effects import JointCoupling

    pairs = [u.pairs[0] for u in JointCoupling.candidates(ROBOTS["industrial_6r"](), {})]
    assert len(pairs) == 30 and len(set(pairs)) == 30 and all(j != k for j, k in pairs)
    rrp = [u.pairs[0] for u in JointCoupling.candidates(ROBOTS["prismatic_rrp"](), {})]
    revolute = [j for j, joint in enumerate(ROBOTS["prismatic_rrp"]().joints, 1) if joint.revolute]
    assert sorted(rrp) == sorted((j, k) for j in revolute for k in revolute if j != k)


def test_backlash_is_half_the_play_against_the_direction_of_motion():
    from robocal_casadi.effects import Backlash

    robot = ROBOTS["industrial_6r"]()
    effect = Backlash((2, 5))
    assert effect.required_columns() == ("direction_q2", "direction_q5")
    evaluate = Evaluator(effect, robot, columns=("direction_q2", "direction_q5", "payload"))
    q = np.array([0.3, -0.5, 0.8, 1.1, -0.7, 2.5])
    for d2, d5 in ((1.0, -1.0), (0.0, 1.0), (-1.0, 0.0)):
        dq, dp = evaluate.f(q, evaluate.nominal, [4e-4, 1e-3], d2, d5, 0.0, np.zeros(3))
        np.testing.assert_allclose(np.asarray(dq).ravel(),
                                   [0, -2e-4 * d2, 0, 0, -5e-4 * d5, 0], atol=1e-18)


def test_directions_of_motion_follow_the_row_order():
    from robocal_casadi.effects.motion import directions_of_motion

    Q = np.array([[0.0, 1.0], [0.2, 1.0], [0.2, 0.5], [0.1, 0.5], [0.1, 0.7], [0.1, 0.7]])
    np.testing.assert_array_equal(directions_of_motion(Q), [[0, 0], [1, 0], [1, -1], [-1, -1],
                                                            [-1, 1], [-1, 1]])
    assert directions_of_motion(Q[:1]).tolist() == [[0.0, 0.0]]


def test_data_selection_keeps_the_directions_of_the_full_table():
    """Rows cut out of a table keep the directions they had in it, so a selected subset
    is fitted with the same per-row inputs as the whole."""
    from dataclasses import dataclass

    from robocal_casadi.effects.motion import direction_values, directions_of_motion
    from robocal_casadi.instruments.datasets import dataset_rows

    rng = np.random.default_rng(2)
    Q = rng.normal(size=(12, 3))

    @dataclass(frozen=True)
    class Table:  # what dataset_rows needs of a dataset
        joints: np.ndarray
        extras: dict

    full = Table(Q, {"temperature": np.arange(12.0)})
    mask = np.zeros(12, dtype=bool)
    mask[[0, 3, 4, 9, 10]] = True
    part = dataset_rows(full, mask)
    for j in (1, 2, 3):
        np.testing.assert_array_equal(direction_values(part, f"direction_q{j}"),
                                      directions_of_motion(Q)[mask, j - 1])
    # recomputing on the subset would differ: the test distinguishes the two
    assert not np.array_equal(directions_of_motion(Q[mask]), directions_of_motion(Q)[mask])
