"""The simulator: files that read back, data that fit the truth, effects as defined.

The checks recompute what was measured from the truth with the plain numpy forward
kinematics (``nominal_pose``) and, for compliance, gravity torques by finite differences
of the potential energy: nothing here goes through the simulator's own forward pass.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from robocal_casadi.cli import main
from robocal_casadi.errors import InputError
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.instruments.simulate import ray_sphere_distance, simulate
from robocal_casadi.model.examples import ROBOTS
from robocal_casadi.model.kinematics import dh_transform, nominal_pose
from robocal_casadi.model.transforms import invert, matrix_from_quaternion

KINDS = ("tracker_points", "cross_bar", "artifact_touches", "sphere_laser")
ROWS = {"tracker_points": 30, "cross_bar": 3, "artifact_touches": 2, "sphere_laser": 20}


def flange(robot, q) -> np.ndarray:
    return nominal_pose(robot, q) @ invert(robot.tool.matrix())


def flange_point(robot, q, offset) -> np.ndarray:
    T = flange(robot, q)
    return T[:3, :3] @ offset + T[:3, 3]


def potential_gradient(robot, q, payload, payload_com, h=1e-6) -> np.ndarray:
    """Gravity torque dV/dq by central differences of the potential energy [Nm]."""
    g = np.asarray(robot.gravity)

    def energy(q):
        T = robot.base.matrix()
        V = 0.0
        for joint, reading in zip(robot.joints, q):
            T = T @ dh_transform(robot.convention, joint.revolute, reading, joint.theta, joint.d,
                                 joint.a, joint.alpha, joint.beta)
            V -= joint.mass * g @ (T[:3, :3] @ np.asarray(joint.com) + T[:3, 3])
        return V - payload * g @ (T[:3, :3] @ payload_com + T[:3, 3])

    return np.array([(energy(q + h * e) - energy(q - h * e)) / (2 * h) for e in np.eye(len(q))])


@pytest.mark.parametrize("robot_name", ["industrial_6r", "panda_7dof"])
@pytest.mark.parametrize("kind", KINDS)
def test_every_kind_reads_back_with_the_same_values(tmp_path, robot_name, kind):
    robot = ROBOTS[robot_name]()
    sim = simulate(robot, kind, rows=ROWS[kind], noise=1e-5, geometric_errors=(3e-4, 3e-4),
                   seed=3, out_dir=tmp_path / "sim", payload=(0.0, 5.0),
                   temperature=(19.0, 23.0))
    dataset = load_dataset(sim.dataset_path)
    assert dataset.kind == kind and dataset.rows == sim.rows
    np.testing.assert_allclose(dataset.joints, sim.joints, rtol=1e-15, atol=0)
    for column in ("payload", "temperature"):
        np.testing.assert_allclose(dataset.extras[column], sim.extras[column], rtol=1e-15)
    if kind == "tracker_points":
        measured = np.column_stack([sim.measured[c] for c in "xyz"])
        np.testing.assert_allclose(dataset.measured, measured, rtol=1e-15, atol=1e-18)
    elif kind == "sphere_laser":
        np.testing.assert_allclose(dataset.distance, sim.measured["distance"], rtol=1e-15)
        assert dataset.radius == pytest.approx(0.025, rel=1e-15)
    else:
        np.testing.assert_array_equal(dataset.pose, sim.pose)
        assert dataset.point == sim.point
        assert len(set(dataset.pose)) == ROWS[kind]
    truth = yaml.safe_load(sim.truth_path.read_text())
    scale = robot.units.length_scale
    for name, error in sim.truth.parameter_errors.items():
        quantity = robot.parameters().quantity(name)
        assert truth["parameter_errors"][name] * robot.units.scale(quantity) == pytest.approx(
            error, rel=1e-12)
    assert truth["noise"] * scale == pytest.approx(1e-5)
    assert truth["reference_temperature"] == 20.0


def test_noise_free_tracker_data_fit_the_nominal_robot_exactly(tmp_path):
    robot = ROBOTS["industrial_6r"]()
    sim = simulate(robot, "tracker_points", rows=40, seed=5, out_dir=tmp_path / "sim")
    T_instrument_world = invert(sim.truth.placement["T_world_instrument"])
    target = sim.truth.mounted["target"]
    np.testing.assert_array_equal(target, [0.0, 0.0, 0.1])  # no errors: mounted as nominal
    dataset = sim.load()
    for q, measured in zip(dataset.joints, dataset.measured):
        world = flange_point(robot, q, target)
        expected = T_instrument_world[:3, :3] @ world + T_instrument_world[:3, 3]
        assert np.linalg.norm(measured - expected) < 1e-12


def test_tracker_data_follow_the_true_robot_not_the_nominal(tmp_path):
    robot = ROBOTS["panda_7dof"]()
    sim = simulate(robot, "tracker_points", rows=30, seed=6, out_dir=tmp_path / "sim",
                   geometric_errors=(5e-4, 5e-4))
    T = invert(sim.truth.placement["T_world_instrument"])
    target = sim.truth.mounted["target"]
    assert np.linalg.norm(target - [0, 0, 0.1]) > 0  # the target got its mounting error
    true_errors, nominal_errors = [], []
    for q, measured in zip(sim.joints, np.column_stack([sim.measured[c] for c in "xyz"])):
        for model, out in ((sim.truth.robot, true_errors), (robot, nominal_errors)):
            world = flange_point(model, q, target)
            out.append(np.linalg.norm(T[:3, :3] @ world + T[:3, 3] - measured))
    assert max(true_errors) < 1e-12
    assert np.mean(nominal_errors) > 1e-4


def test_noise_is_the_stated_size(tmp_path):
    robot = ROBOTS["industrial_6r"]()
    sim = simulate(robot, "tracker_points", rows=400, noise=1e-4, seed=7, out_dir=tmp_path / "s")
    T = invert(sim.truth.placement["T_world_instrument"])
    residuals = [T[:3, :3] @ flange_point(robot, q, [0, 0, 0.1]) + T[:3, 3] - m
                 for q, m in zip(sim.joints, np.column_stack([sim.measured[c] for c in "xyz"]))]
    assert np.std(residuals) == pytest.approx(1e-4, rel=0.1)


@pytest.mark.parametrize("robot_name", ["industrial_6r", "panda_7dof"])
def test_bar_touches_satisfy_the_bar_with_the_true_robot(tmp_path, robot_name):
    robot = ROBOTS[robot_name]()
    sim = simulate(robot, "cross_bar", rows=3, seed=8, out_dir=tmp_path / "sim",
                   geometric_errors=(5e-4, 5e-4), bar_length=0.3)
    probe = sim.truth.mounted["probe"]
    nominal_bar_errors = []
    for pose in np.unique(sim.pose):
        for model in (sim.truth.robot, robot):
            tip = {p: flange_point(model, q, probe)
                   for p, q, k in zip(sim.point, sim.joints, sim.pose) if k == pose}
            AC, BD = tip["C"] - tip["A"], tip["D"] - tip["B"]
            errors = [np.linalg.norm(AC) - 0.3, np.linalg.norm(BD) - 0.3, AC @ BD / 0.3]
            if model is sim.truth.robot:
                assert np.max(np.abs(errors)) < 1e-10
                sockets = sim.truth.placement["sockets"][pose]
                for name in "ABCD":
                    assert np.linalg.norm(tip[name] - sockets[name]) < 1e-10
            else:
                nominal_bar_errors.extend(errors)
    assert np.max(np.abs(nominal_bar_errors)) > 1e-5


def test_artifact_touches_repeat_each_socket_in_different_configurations(tmp_path):
    robot = ROBOTS["panda_7dof"]()
    sim = simulate(robot, "artifact_touches", rows=2, touches=4, sockets=3, seed=9,
                   socket_distance=0.05, out_dir=tmp_path / "sim")
    dataset = sim.load()
    distances = {(a, b): length for a, b, length in dataset.distances}
    assert distances == pytest.approx({("hole_0", "hole_1"): 0.05, ("hole_0", "hole_2"): 0.1,
                                       ("hole_1", "hole_2"): 0.05}, rel=1e-12)
    for pose in (0, 1):
        for socket in ("hole_0", "hole_1", "hole_2"):
            rows = [i for i in range(sim.rows) if sim.pose[i] == pose and sim.point[i] == socket]
            assert len(rows) == 4
            tips = np.array([flange_point(robot, sim.joints[i], sim.truth.mounted["probe"])
                             for i in rows])
            assert np.max(np.linalg.norm(tips - tips[0], axis=1)) < 1e-10  # same socket
            spread = np.max(np.ptp(sim.joints[rows], axis=0))
            assert spread > 0.05  # [rad] genuinely different configurations


@pytest.mark.parametrize("readings", ["joints", "pendant"])
def test_sphere_laser_distances_hit_the_sphere(tmp_path, readings):
    robot = ROBOTS["industrial_6r"]()
    sim = simulate(robot, "sphere_laser", rows=25, seed=10, readings=readings,
                   out_dir=tmp_path / "sim")
    dataset = sim.load()
    truth = sim.truth
    origin, direction = truth.mounted["laser_origin"], truth.mounted["laser_direction"]
    centre = truth.placement["sphere_centre"]
    if readings == "pendant":
        assert dataset.joints is None
        poses = dataset.flange_poses
        for F, q in zip(poses, sim.joints):
            np.testing.assert_allclose(F, flange(robot, q), atol=1e-12)
    else:
        poses = np.array([flange(robot, q) for q in dataset.joints])
    tilt = []
    for F, distance in zip(poses, dataset.distance):
        surface = F[:3, :3] @ (origin + distance * direction) + F[:3, 3]
        assert abs(np.linalg.norm(surface - centre) - 0.025) < 1e-12
        tilt.append(F[:3, :3] @ direction)
    angles = np.degrees(np.arccos(np.clip(np.array(tilt) @ np.mean(tilt, axis=0)
                                          / np.linalg.norm(np.mean(tilt, axis=0)), -1, 1)))
    assert np.max(angles) > 5.0  # tilted orientations: p0 along n is observable


def test_ray_sphere_distance_closed_form():
    assert ray_sphere_distance([0, 0, 0], [0, 0, 1], [0, 0, 1.0], 0.25) == pytest.approx(0.75)
    assert np.isnan(ray_sphere_distance([0, 0, 0], [1, 0, 0], [0, 0, 1.0], 0.25))
    assert np.isnan(ray_sphere_distance([0, 0, 0], [0, 0, -1], [0, 0, 1.0], 0.25))


# ----------------------------------------------------------------------------- effects


def _tracker_expected(sim, robot, joints_true, p_rows=None):
    T = invert(sim.truth.placement["T_world_instrument"])
    out = []
    for k, q in enumerate(joints_true):
        model = robot if p_rows is None else robot.with_parameters(p_rows[k])
        out.append(T[:3, :3] @ flange_point(model, q, sim.truth.mounted["target"]) + T[:3, 3])
    return np.array(out)


def _measured(sim):
    return np.column_stack([sim.measured[c] for c in "xyz"])


def test_joint_scale_and_cyclic_effects_as_defined(tmp_path):
    robot = ROBOTS["industrial_6r"]()
    a1, b1, a2, b2 = 3e-4, -2e-4, 1e-4, 5e-5
    sim = simulate(robot, "tracker_points", rows=30, seed=11, out_dir=tmp_path / "sim",
                   effects={"joint_scale": {3: 4e-4}, "joint_cyclic": {2: (a1, b1, a2, b2)}})
    Q = sim.joints.copy()
    q2 = Q[:, 1].copy()
    Q[:, 2] *= 1 + 4e-4
    Q[:, 1] += a1 * np.sin(q2) + b1 * np.cos(q2) + a2 * np.sin(2 * q2) + b2 * np.cos(2 * q2)
    np.testing.assert_allclose(_measured(sim), _tracker_expected(sim, robot, Q), atol=1e-12)
    plain = _tracker_expected(sim, robot, sim.joints)
    assert np.max(np.linalg.norm(_measured(sim) - plain, axis=1)) > 1e-4


def test_joint_compliance_as_defined_with_payload(tmp_path):
    robot = ROBOTS["industrial_6r"]()
    com = np.array([0.0, 0.02, 0.08])
    c = {2: 2e-6, 3: 3e-6}
    sim = simulate(robot, "tracker_points", rows=12, seed=12, out_dir=tmp_path / "sim",
                   effects={"joint_compliance": c}, payload=(0.0, 30.0), payload_com=com)
    dataset = sim.load()
    np.testing.assert_allclose(dataset.payload_com, com, atol=1e-15)
    Q = sim.joints.copy()
    for k, q in enumerate(sim.joints):
        torque = potential_gradient(robot, q, sim.extras["payload"][k], com)
        for j, cj in c.items():
            Q[k, j - 1] = q[j - 1] - cj * torque[j - 1]
    np.testing.assert_allclose(_measured(sim), _tracker_expected(sim, robot, Q), atol=1e-11)
    assert np.max(np.linalg.norm(_measured(sim) - _tracker_expected(sim, robot, sim.joints),
                                 axis=1)) > 1e-4


def test_thermal_drift_as_defined(tmp_path):
    robot = ROBOTS["industrial_6r"]()
    k = 2e-5
    sim = simulate(robot, "tracker_points", rows=20, seed=13, out_dir=tmp_path / "sim",
                   effects={"thermal_drift": k}, reference_temperature=21.0,
                   temperature=(15.0, 35.0))
    truth = yaml.safe_load(sim.truth_path.read_text())
    assert truth["reference_temperature"] == 21.0
    assert truth["effects"]["thermal_drift"]["parameters"]["k_T"] == k
    registry = robot.parameters()
    lengths = registry.indices([f"{s}{i}" for i in range(1, 7) for s in "da"])
    p_rows = []
    for T in sim.extras["temperature"]:
        p = registry.vector_of(robot)
        p[lengths] *= 1 + k * (T - 21.0)
        p_rows.append(p)
    np.testing.assert_allclose(_measured(sim), _tracker_expected(sim, robot, sim.joints, p_rows),
                               atol=1e-12)
    assert np.ptp(sim.extras["temperature"]) > 15.0


def test_effects_also_hold_for_touches(tmp_path):
    """Readings solved back from the true joints: the scaled readings seat the probe."""
    robot = ROBOTS["industrial_6r"]()
    sim = simulate(robot, "cross_bar", rows=2, seed=14, out_dir=tmp_path / "sim",
                   effects={"joint_scale": {2: 1e-3}})
    probe = sim.truth.mounted["probe"]
    misses = []
    for i, (pose, name) in enumerate(zip(sim.pose, sim.point)):
        q = sim.joints[i].copy()
        q[1] *= 1 + 1e-3
        socket = sim.truth.placement["sockets"][pose][name]
        assert np.linalg.norm(flange_point(robot, q, probe) - socket) < 1e-10
        misses.append(np.linalg.norm(flange_point(robot, sim.joints[i], probe) - socket))
    assert max(misses) > 1e-4  # the readings alone miss (by |q2| x 1e-3 x lever)


# ----------------------------------------------------------------------------- CLI and failures


def test_cli_writes_the_four_files(tmp_path, capsys):
    out = tmp_path / "sim"
    status = main(["simulate", "--example", "industrial_6r", "--kind", "tracker_points",
                   "--rows", "20", "--noise", "0.01", "--errors", "0.5,0.05",
                   "--effect", "joint_compliance:2,3", "--effect", "joint_cyclic:2=1e-4/0/0/0",
                   "--seed", "1", "--out", str(out)])
    assert status == 0
    assert sorted(p.name for p in out.iterdir()) == [".robocal-output", "dataset.yaml",
                                                     "points.csv", "robot.yaml", "truth.yaml"]
    truth = yaml.safe_load((out / "truth.yaml").read_text())
    assert truth["units"] == {"length": "mm", "angle": "deg"}
    assert truth["noise"] == 0.01
    assert truth["effects"]["joint_compliance"]["parameters"] == {"c2": 1e-6, "c3": 1e-6}
    assert truth["effects"]["joint_cyclic"]["parameters"]["a1_2"] == 1e-4
    # the true robot in the truth file differs from the nominal by the written errors
    assert truth["robot"]["a2"] == pytest.approx(680.0 + truth["parameter_errors"]["a2"])
    assert load_dataset(out / "dataset.yaml").rows == 20


def test_explicit_errors_by_name(tmp_path):
    out = tmp_path / "sim"
    assert main(["simulate", "--example", "industrial_6r", "--kind", "tracker_points",
                 "--rows", "5", "--error", "a2=0.3", "--error", "theta3=0.01",
                 "--out", str(out)]) == 0
    truth = yaml.safe_load((out / "truth.yaml").read_text())
    assert truth["parameter_errors"] == pytest.approx({"a2": 0.3, "theta3": 0.01})


def test_failure_writes_nothing(tmp_path):
    robot = ROBOTS["prismatic_rrp"]()
    out = tmp_path / "sim"
    with pytest.raises(InputError, match="could place only 0 of 1"):
        simulate(robot, "cross_bar", rows=1, bar_length=5.0, seed=1, out_dir=out)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_a_folder_with_other_files_is_not_replaced(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("keep me")
    status = main(["simulate", "--example", "industrial_6r", "--kind", "tracker_points",
                   "--rows", "5", "--out", str(tmp_path)])
    assert status == 2
    assert (tmp_path / "notes.txt").read_text() == "keep me"
    assert "not empty" in capsys.readouterr().err


def test_rerun_into_a_simulation_folder_replaces_it(tmp_path):
    out = tmp_path / "sim"
    first = simulate(ROBOTS["industrial_6r"](), "tracker_points", rows=5, seed=1, out_dir=out)
    second = simulate(ROBOTS["industrial_6r"](), "tracker_points", rows=7, seed=2, out_dir=out)
    assert first.dataset_path == second.dataset_path
    assert load_dataset(out / "dataset.yaml").rows == 7


def test_same_seed_same_data(tmp_path):
    a = simulate(ROBOTS["panda_7dof"](), "cross_bar", rows=2, seed=4, out_dir=tmp_path / "a",
                 geometric_errors=(1e-4, 1e-4), noise=1e-5)
    b = simulate(ROBOTS["panda_7dof"](), "cross_bar", rows=2, seed=4, out_dir=tmp_path / "b",
                 geometric_errors=(1e-4, 1e-4), noise=1e-5)
    assert a.table_path.read_text() == b.table_path.read_text()
    assert a.truth_path.read_text() == b.truth_path.read_text()


def test_quaternion_of_pendant_rows_is_unit(tmp_path):
    sim = simulate(ROBOTS["panda_7dof"](), "sphere_laser", rows=10, seed=2, readings="pendant",
                   out_dir=tmp_path / "sim")
    for row in sim.pendant:
        assert np.linalg.norm(row[3:]) == pytest.approx(1.0, abs=1e-15)
        R = matrix_from_quaternion(row[3:])
        assert np.allclose(R @ R.T, np.eye(3))


def test_cli_coupling_and_backlash_effects(tmp_path):
    """``--effect joint_coupling:J@K=s/c`` and ``--effect backlash:J=b`` reach the truth, and
    the backlash truth follows the order of the written rows."""
    from robocal_casadi.effects.motion import directions_of_motion
    from robocal_casadi.instruments.simulate import directions_in_order

    out = tmp_path / "sim"
    assert main(["simulate", "--example", "industrial_6r", "--kind", "tracker_points",
                 "--rows", "30", "--effect", "joint_coupling:5@6=2e-4/-1e-4",
                 "--effect", "backlash:2=5e-4,3", "--out", str(out)]) == 0
    truth = yaml.safe_load((out / "truth.yaml").read_text())
    assert truth["effects"]["joint_coupling"]["parameters"] == {"sin5_q6": 2e-4, "cos5_q6": -1e-4}
    assert truth["effects"]["joint_coupling"]["drivers"] == {5: 6}
    assert truth["effects"]["backlash"]["parameters"] == {"b2": 5e-4, "b3": 5e-4}
    dataset = load_dataset(out / "dataset.yaml")
    # the simulator's own directions and the estimator's agree on the table as read back
    np.testing.assert_array_equal(directions_in_order(dataset.joints),
                                  directions_of_motion(dataset.joints))


def test_backlash_holds_for_touches_in_the_order_written(tmp_path):
    """Touch readings solved back in order: each row's true joint is its reading minus half
    the play times the sign of its change from the row before (0 on the first row)."""
    robot = ROBOTS["industrial_6r"]()
    b = 8e-4
    sim = simulate(robot, "cross_bar", rows=3, seed=14, out_dir=tmp_path / "sim",
                   effects={"backlash": {2: b}}, progress=False)
    probe = sim.truth.mounted["probe"]
    direction, misses = 0.0, []
    for i, (pose, name) in enumerate(zip(sim.pose, sim.point)):
        if i:
            change = sim.joints[i, 1] - sim.joints[i - 1, 1]
            direction = np.sign(change) if change else direction
        q = sim.joints[i].copy()
        q[1] -= 0.5 * b * direction
        socket = sim.truth.placement["sockets"][pose][name]
        assert np.linalg.norm(flange_point(sim.truth.robot, q, probe) - socket) < 1e-9
        misses.append(np.linalg.norm(flange_point(sim.truth.robot, sim.joints[i], probe)
                                     - socket))
    assert max(misses) > 1e-4


# ----------------------------------------------------------------------------- held truths

HAND_ROBOT = """\
name: hand-6r
convention: dh
units: {length: mm, angle: deg}
joints:
  - {type: revolute, theta: 0, d: 400, a: 150, alpha: -90, limits: [-170, 170]}
  - {type: revolute, theta: -90, d: 0, a: 600, alpha: 0, limits: [-120, 60]}
  - {type: revolute, theta: 0, d: 0, a: 120, alpha: -90, limits: [-100, 150]}
  - {type: revolute, theta: 0, d: 620, a: 0, alpha: 90, limits: [-180, 180]}
  - {type: revolute, theta: 0, d: 0, a: 0, alpha: -90, limits: [-120, 120]}
  - {type: revolute, theta: 0, d: 100, a: 0, alpha: 0, limits: [-350, 350]}
"""
HAND_ERRORS = {"a2": 0.4, "d4": -0.3, "theta3": 0.02, "alpha2": -0.015}  # mm, deg
HAND_TARGET = [1.5, -2.0, 80.0]  # mm, flange frame


def _hand_truth(folder) -> None:
    """A robot file and a truth file written here by hand (not by the simulator): the
    nominal 6R above with the errors ``HAND_ERRORS``, a target at ``HAND_TARGET``."""
    from robocal_casadi.model.robot import load_robot

    folder.mkdir(parents=True)
    (folder / "robot.yaml").write_text(HAND_ROBOT)
    nominal = load_robot(folder / "robot.yaml")
    registry = nominal.parameters()
    vector = registry.vector_of(nominal)
    true = {}
    for name, value in zip(registry.names, vector):
        scale = nominal.units.scale(registry.quantity(name))
        true[name] = float(round(value / scale, 9) + HAND_ERRORS.get(name, 0.0))
    content = {"kind": "tracker_points", "seed": 0, "units": {"length": "mm", "angle": "deg"},
               "noise": 0.0, "reference_temperature": 20.0, "robot": true,
               "parameter_errors": HAND_ERRORS, "mounted": {"target": HAND_TARGET},
               "placement": {}, "effects": {}}
    (folder / "truth.yaml").write_text(yaml.safe_dump(content, sort_keys=False))


def _dh_tool(joints_deg_mm: list[dict], q_deg) -> np.ndarray:
    """Standard DH flange pose [mm] from the table (deg, mm), written out here."""
    T = np.eye(4)
    for joint, q in zip(joints_deg_mm, q_deg):
        th, al = np.radians(joint["theta"] + q), np.radians(joint["alpha"])
        ct, st, ca, sa = np.cos(th), np.sin(th), np.cos(al), np.sin(al)
        T = T @ np.array([[ct, -st * ca, st * sa, joint["a"] * ct],
                          [st, ct * ca, -ct * sa, joint["a"] * st],
                          [0, sa, ca, joint["d"]], [0, 0, 0, 1]])
    return T


def test_a_hand_written_truth_gets_new_readings_of_its_robot(tmp_path):
    """``simulate --truth`` on a truth the simulator did not write: the tracker points of the
    new run are those of the hand-written true robot (its DH table, target and the tracker
    pose the new truth file states), computed here from the plain DH formula."""
    _hand_truth(tmp_path / "hand")
    out = tmp_path / "new"
    assert main(["simulate", "--truth", str(tmp_path / "hand" / "truth.yaml"), "--rows", "25",
                 "--seed", "3", "--out", str(out)]) == 0
    truth = yaml.safe_load((out / "truth.yaml").read_text())
    written = yaml.safe_load((tmp_path / "hand" / "truth.yaml").read_text())
    assert truth["robot"] == pytest.approx(written["robot"], rel=1e-15, abs=1e-12)
    assert truth["mounted"]["target"] == pytest.approx(HAND_TARGET, rel=1e-15)
    assert truth["seed"] == 3 and truth["kind"] == "tracker_points"
    joints = [{"theta": truth["robot"][f"theta{i}"], "d": truth["robot"][f"d{i}"],
               "a": truth["robot"][f"a{i}"], "alpha": truth["robot"][f"alpha{i}"]}
              for i in range(1, 7)]
    instrument = truth["placement"]["instrument"]
    r, p, y = np.radians(instrument["rpy"])
    Rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    R, t = Rz @ Ry @ Rx, np.array(instrument["xyz"])
    table = np.loadtxt(out / "points.csv", delimiter=",", skiprows=1)
    for row in table:
        T = _dh_tool(joints, row[:6])
        world = T[:3, :3] @ HAND_TARGET + T[:3, 3]
        np.testing.assert_allclose(row[6:9], R.T @ (world - t), rtol=0, atol=1e-8)  # mm
    # ... and not those of the nominal robot (the errors move the target by about 1 mm)
    nominal = [dict(j, **{k: j[k] - HAND_ERRORS.get(f"{k}{i}", 0.0) for k in j})
               for i, j in enumerate(joints, start=1)]
    T = _dh_tool(nominal, table[0, :6])
    assert np.linalg.norm(R.T @ (T[:3, :3] @ HAND_TARGET + T[:3, 3] - t) - table[0, 6:9]) > 0.1


@pytest.mark.parametrize("kind, options", [
    ("tracker_points", ["--errors", "0.5,0.05", "--effect", "joint_compliance:2,3",
                        "--payload", "0,5", "--payload-com", "0,0,50", "--noise", "0.01"]),
    ("artifact_touches", ["--error", "a2=0.3", "--noise", "0.005"]),
    ("sphere_laser", ["--errors", "0.2,0.02", "--noise", "0.002"]),
])
def test_the_truths_own_seed_writes_the_truth_again(tmp_path, kind, options):
    rows = ["--rows", str(ROWS[kind])]
    first = tmp_path / "first"
    assert main(["simulate", "--example", "industrial_6r", "--kind", kind, *rows, *options,
                 "--seed", "4", "--out", str(first)]) == 0
    run = [o for o in ("--payload", "0,5") if "--payload" in options]
    again = tmp_path / "again"
    assert main(["simulate", "--truth", str(first / "truth.yaml"), *rows, *run, "--seed", "4",
                 "--out", str(again)]) == 0
    assert (again / "truth.yaml").read_bytes() == (first / "truth.yaml").read_bytes()
    other = tmp_path / "other"
    assert main(["simulate", "--truth", str(first / "truth.yaml"), *rows, *run, "--seed", "5",
                 "--out", str(other)]) == 0
    old, new = (yaml.safe_load((f / "truth.yaml").read_text()) for f in (first, other))
    assert new["seed"] == 5 and new["placement"] != old["placement"]
    for key in ("robot", "parameter_errors", "mounted", "effects", "noise", "kind", "units"):
        assert new[key] == old[key], key
    assert (other / "points.csv").exists() or kind != "tracker_points"


def test_every_effect_reads_back_from_the_truth_file(tmp_path):
    """Each registered effect (its simulator's defaults) survives truth.yaml: the effects
    rebuilt from the file write the same entries."""
    from dataclasses import replace

    from robocal_casadi.effects import EFFECTS
    from robocal_casadi.instruments.held_truth import read_truth, true_effects_of
    from robocal_casadi.instruments.simulate import TrueEffects
    from robocal_casadi.model.transmission import TransmissionGroup

    # joints 3 and 4 driven together, for the effects of coupled groups (key 3: its group)
    robot = replace(ROBOTS["industrial_6r"](), transmission=(
        TransmissionGroup((3, 4), ((1.0, 1.0), (1.0, -1.0))),))
    for name, cls in EFFECTS.items():
        if cls.per == "column" and not cls.simulation_default:
            continue  # learned: nothing to simulate
        default = cls.simulation_default
        values = default[0] if len(default) == 1 else default
        spec = values if cls.per == "column" else (
            {"5@6": values} if cls.per == "pair" else {3: values})
        sim = simulate(robot, "tracker_points", rows=6, seed=1, out_dir=tmp_path / name,
                       effects={name: spec}, progress=False)
        held = read_truth(sim.truth_path)
        rebuilt = TrueEffects(true_effects_of(held, held.nominal()))
        assert rebuilt.as_dict() == sim.truth.effects.as_dict(), name


def test_simulate_truth_refuses_what_would_change_the_robot(tmp_path, capsys):
    _hand_truth(tmp_path / "hand")
    truth = str(tmp_path / "hand" / "truth.yaml")
    for extra in (["--errors", "0.1,0.01"], ["--effect", "joint_compliance:2"],
                  ["--noise", "0.1"], ["--kind", "cross_bar"]):
        assert main(["simulate", "--truth", truth, *extra, "--out", str(tmp_path / "x")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and ("--truth" in err[0] or "--kind" in err[0]), err
    assert not (tmp_path / "x").exists()
    (tmp_path / "hand" / "robot.yaml").unlink()
    assert main(["simulate", "--truth", truth, "--out", str(tmp_path / "x")]) == 2
    assert "robot.yaml" in capsys.readouterr().err


def test_validation_from_another_simulated_robot_is_said(tmp_path, capsys):
    """Held-out data of the same truth (``--truth``) pass silently; held-out data simulated
    with another seed (another robot) get one line, and a note in result.json."""
    import json

    base = ["simulate", "--example", "industrial_6r", "--kind", "tracker_points", "--rows", "40",
            "--noise", "0.01", "--errors", "0.3,0.03"]
    assert main([*base, "--seed", "1", "--out", str(tmp_path / "fit")]) == 0
    assert main([*base, "--seed", "2", "--out", str(tmp_path / "other")]) == 0
    assert main(["simulate", "--truth", str(tmp_path / "fit" / "truth.yaml"), "--rows", "40",
                 "--seed", "2", "--out", str(tmp_path / "same")]) == 0
    capsys.readouterr()
    runs = {}
    for name in ("same", "other"):
        out = tmp_path / f"result-{name}"
        assert main(["calibrate", str(tmp_path / "fit" / "dataset.yaml"), "--validate",
                     str(tmp_path / name / "dataset.yaml"), "--out", str(out), "--no-report",
                     "--no-diagnose"]) == 0
        lines = [line for line in capsys.readouterr().out.splitlines()
                 if "another robot" in line]
        runs[name] = (lines, json.loads((out / "result.json").read_text()).get("notes", []))
    assert runs["same"] == ([], [])
    lines, notes = runs["other"]
    assert len(lines) == 1 and lines[0].startswith("NOTE: the held-out data")
    assert "--truth" in lines[0] and any("another robot" in n for n in notes)
