"""Compensation keeps each pose's configuration: the answer lies on the seed's branch
(shoulder, elbow, wrist), and a target only another branch reaches is reported.

Targets are the nominal UR10's tool poses at known joints; the branch is read
independently of the code under test from UR's own flags (the signs of sin q3, the
elbow, and sin q5, the wrist) and from the joint distance to the known joints.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal_casadi.cli import main
from robocal_casadi.job.compensation import compensate
from robocal_casadi.model.kinematics import nominal_pose
from robocal_casadi.model.robot import load_robot
from robocal_casadi.model.transforms import quaternion_from_matrix

UR10 = Path(__file__).resolve().parents[1] / "robocal_casadi" / "data" / "ur10-ipa" / "robot.yaml"
# A calibration-sized change: a millimetre and a tenth of a degree
CHANGES = {"a2": 1.2e-3, "a3": -0.8e-3, "d4": 0.6e-3, "alpha3": np.radians(0.08),
           "theta5": np.radians(-0.1), "d6": 0.5e-3}


def _known_joints(count: int, seed: int) -> np.ndarray:
    """Joints [rad] away from the elbow and wrist singularities (|sin| > 0.3)."""
    rng = np.random.default_rng(seed)
    rows = []
    while len(rows) < count:
        q = rng.uniform(-np.pi, np.pi, 6)
        if abs(np.sin(q[2])) > 0.3 and abs(np.sin(q[4])) > 0.3:
            rows.append(q)
    return np.array(rows)


def _poses(robot, Q) -> np.ndarray:
    rows = []
    for q in Q:
        T = nominal_pose(robot, q)
        rows.append(list(T[:3, 3]) + list(quaternion_from_matrix(T[:3, :3])))
    return np.array(rows)


def _changed(robot):
    values = robot.parameter_vector()
    names = robot.parameters().names
    for name, change in CHANGES.items():
        values[names.index(name)] += change
    return robot.with_parameters(values)


def _flags(Q) -> np.ndarray:
    return np.sign(np.sin(np.asarray(Q)[:, [2, 4]]))


def test_seeded_targets_come_back_at_their_joints_on_the_nominal_model():
    robot = load_robot(UR10)
    Q = _known_joints(12, 1)
    result = compensate(robot, _poses(robot, Q), seeds=Q)
    assert result.status == ("ok",) * 12
    # the seeds solve the targets to rounding: the answer is the seed itself
    assert np.max(np.abs(result.joints - Q)) < 1e-8


@pytest.mark.parametrize("with_orientation", [True, False])
def test_a_changed_model_keeps_each_seeds_branch(with_orientation):
    nominal = load_robot(UR10)
    calibrated = _changed(nominal)
    Q = _known_joints(12, 2)
    targets = _poses(nominal, Q)[:, :7 if with_orientation else 3]
    result = compensate(calibrated, targets, seeds=Q, nominal=nominal)
    assert result.status == ("ok",) * 12
    assert np.array_equal(_flags(result.joints), _flags(Q))
    # millimetres of geometry move the joints by well under a degree, a branch by tens
    assert np.max(np.abs(result.joints - Q)) < np.radians(2.0)
    for q, target in zip(result.joints, targets):
        T = nominal_pose(calibrated, q)
        assert np.linalg.norm(T[:3, 3] - target[:3]) < 1e-9


def test_unseeded_targets_keep_the_nominal_solutions_branch():
    """Without seeds the nominal robot's own inverse kinematics picks the branch and the
    calibrated answer stays on it."""
    from robocal_casadi.job.compensation import target_poses
    from robocal_casadi.model.ik import inverse_kinematics
    from robocal_casadi.model.kinematics import Kinematics

    nominal = load_robot(UR10)
    calibrated = _changed(nominal)
    targets = _poses(nominal, _known_joints(8, 3))
    first = inverse_kinematics(Kinematics(nominal), "pose").solve_batch(
        target_poses(targets), restarts=10, rng=np.random.default_rng(0))
    assert first.success.all()
    result = compensate(calibrated, targets, nominal=nominal, restarts=10, seed=0)
    assert result.status == ("ok",) * 8
    assert np.max(np.abs(result.joints - first.q)) < np.radians(2.0)


def test_a_target_only_another_branch_reaches_is_reported():
    """With joint 4 held within +-90 deg, a pose reached with the wrist flipped (q5 < 0)
    cannot be reached on a seed's unflipped wrist (q4 would need about 180 deg)."""
    content = yaml.safe_load(UR10.read_text())
    content["joints"][3]["limits"] = [-90, 90]
    from robocal_casadi.model.robot import robot_from_dict

    robot = robot_from_dict(content)
    flipped = np.radians([20.0, -80.0, 70.0, 0.0, -60.0, 30.0])
    seed = flipped * np.array([1, 1, 1, 1, -1, 1])
    assert np.all((flipped >= robot.lower_limits) & (flipped <= robot.upper_limits))
    result = compensate(robot, _poses(robot, [flipped, seed]), seeds=[seed, seed], restarts=20)
    assert result.status == ("branch", "ok")
    assert np.isnan(result.joints[0]).all()
    assert np.max(np.abs(result.joints[1] - seed)) < 1e-8


def _write(path: Path, header: list[str], rows: list[list]) -> Path:
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(rows)
    return path


def test_cli_takes_a_taught_programs_joints(tmp_path, capsys):
    robot = load_robot(UR10)
    Q = _known_joints(5, 4)
    poses = _poses(robot, Q)
    header = ["name", "x", "y", "z", "qw", "qx", "qy", "qz"] + [f"q{k}" for k in range(1, 7)]
    text = lambda values: [repr(float(v)) for v in values]  # noqa: E731
    rows = [[f"p{i}", *text(pose[:3] * 1e3), *text(pose[3:]), *text(np.degrees(q))]
            for i, (pose, q) in enumerate(zip(poses, Q))]
    rows[3][8:] = [""] * 6  # no taught joints for this one: seeded from the nominal IK
    targets = _write(tmp_path / "targets.csv", header, rows)
    out = tmp_path / "joints.csv"
    assert main(["compensate", str(UR10), str(targets), "--out", str(out)]) == 0
    with open(out, newline="") as handle:
        written = list(csv.DictReader(handle))
    assert list(written[0])[:8] == ["name"] + [f"seed_q{k}" for k in range(1, 7)] + ["q1"]
    assert [r["status"] for r in written] == ["ok"] * 5
    for i in (0, 1, 2, 4):
        q = np.radians([float(written[i][f"q{k}"]) for k in range(1, 7)])
        assert np.max(np.abs(q - Q[i])) < 1e-7
    assert written[3]["seed_q1"] == ""

    rows[1][10] = ""  # one joint of a row missing
    _write(targets, header, rows)
    out.unlink()
    assert main(["compensate", str(UR10), str(targets), "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "line 3" in error and "all be given" in error
    assert not out.exists()


def test_seeds_of_the_wrong_shape_are_refused():
    from robocal_casadi.errors import InputError

    robot = load_robot(UR10)
    with pytest.raises(InputError, match="one row of 6 joints"):
        compensate(robot, [[0.5, 0.0, 1.0]], seeds=np.zeros((1, 5)))
