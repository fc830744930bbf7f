"""Compensation on a simulated truth: commands from the true model land the true robot.

The truth comes from the simulator's random geometric errors; landing is checked with the
plain numpy forward kinematics of the true robot.
"""

from __future__ import annotations

import csv

import numpy as np
import pytest

from robocal_casadi.cli import main
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.job.compensation import compensate
from robocal_casadi.model.examples import ROBOTS
from robocal_casadi.model.ik import orientation_angle, random_joints
from robocal_casadi.model.kinematics import nominal_pose
from robocal_casadi.model.robot import save_robot
from robocal_casadi.model.transforms import matrix_from_quaternion, quaternion_from_matrix


@pytest.fixture(scope="module")
def truth(tmp_path_factory):
    out = tmp_path_factory.mktemp("truth") / "sim"
    # 0.5 mm and 0.05 deg per parameter, as a real arm's kinematic errors
    return simulate(ROBOTS["industrial_6r"](), "tracker_points", rows=5, seed=21,
                    geometric_errors=(5e-4, np.radians(0.05)), out_dir=out).truth


def _targets(robot, count, seed, with_orientation):
    joints = random_joints(robot, count, np.random.default_rng(seed), margin=0.05)
    rows = []
    for q in joints:
        T = nominal_pose(robot, q)
        row = list(T[:3, 3])
        if with_orientation:
            row += list(quaternion_from_matrix(T[:3, :3]))
        rows.append(row)
    return np.array(rows)


@pytest.mark.parametrize("with_orientation", [False, True])
def test_true_model_lands_the_true_robot_nominal_misses(truth, with_orientation):
    targets = _targets(truth.robot, 8, 1, with_orientation)
    calibrated = compensate(truth.robot, targets)
    nominal = compensate(truth.nominal, targets)
    assert calibrated.status == ("ok",) * 8 and nominal.status == ("ok",) * 8
    misses_true, misses_nominal = [], []
    for i, target in enumerate(targets):
        for result, misses in ((calibrated, misses_true), (nominal, misses_nominal)):
            T = nominal_pose(truth.robot, result.joints[i])  # the real robot moves
            misses.append(np.linalg.norm(T[:3, 3] - target[:3]))
            if with_orientation and result is calibrated:
                assert orientation_angle(T[:3, :3], matrix_from_quaternion(target[3:])) < 1e-9
    assert max(misses_true) < 1e-9
    # the nominal commands miss by the size of the kinematic errors: about a millimetre
    assert 2e-4 < np.mean(misses_nominal) < 2e-2


def test_unreachable_targets_are_marked(truth):
    targets = _targets(truth.robot, 3, 2, False)
    targets[1] = [4.0, 0.0, 0.5]  # [m] beyond reach
    result = compensate(truth.robot, targets, restarts=3)
    assert result.status == ("ok", "unreachable", "ok")
    assert np.all(np.isnan(result.joints[1])) and np.all(np.isfinite(result.joints[[0, 2]]))
    assert result.position_error[1] > 1.0
    assert "1 unreachable" in repr(result)


def _read(path):
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def test_cli_with_a_calibrated_folder(tmp_path, truth, capsys):
    folder = tmp_path / "calibration"
    folder.mkdir()
    save_robot(truth.robot, folder / "robot_calibrated.yaml")  # mm, deg like the nominal file
    targets = _targets(truth.robot, 4, 3, True)
    targets[2, :3] = [4.0, 0.0, 0.5]
    with open(tmp_path / "targets.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["name", "x", "y", "z", "qw", "qx", "qy", "qz"])
        for i, row in enumerate(targets):
            writer.writerow([f"p{i}"] + [repr(float(v) * 1000.0) for v in row[:3]] +
                            [repr(float(v)) for v in row[3:]])
    out = tmp_path / "joints.csv"
    assert main(["compensate", str(folder), str(tmp_path / "targets.csv"), "--out",
                 str(out)]) == 0
    rows = _read(out)
    assert list(rows[0]) == ["name", "q1", "q2", "q3", "q4", "q5", "q6", "status",
                             "position_error", "orientation_error"]
    assert [r["status"] for r in rows] == ["ok", "ok", "unreachable", "ok"]
    assert [r["name"] for r in rows] == ["p0", "p1", "p2", "p3"]
    assert rows[2]["q1"] == ""
    for i in (0, 1, 3):
        q = np.radians([float(rows[i][f"q{k}"]) for k in range(1, 7)])
        T = nominal_pose(truth.robot, q)
        assert np.linalg.norm(T[:3, 3] - targets[i, :3]) < 1e-9
        assert float(rows[i]["position_error"]) < 1e-6  # mm


def test_cli_refuses_a_bad_quaternion_and_writes_nothing(tmp_path, capsys):
    robot_path = tmp_path / "robot.yaml"
    save_robot(ROBOTS["industrial_6r"](), robot_path)
    (tmp_path / "targets.csv").write_text("x,y,z,qw,qx,qy,qz\n900,0,1200,1,0,0,0\n"
                                          "900,0,1200,0.9,0,0,0\n")
    out = tmp_path / "joints.csv"
    assert main(["compensate", str(robot_path), str(tmp_path / "targets.csv"), "--out",
                 str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "targets.csv" in err and "line 3" in err and "quaternion" in err
    assert len(err.splitlines()) == 1
    assert not out.exists()


def test_cli_missing_calibrated_robot(tmp_path, capsys):
    (tmp_path / "targets.csv").write_text("x,y,z\n1,2,3\n")
    assert main(["compensate", str(tmp_path), str(tmp_path / "targets.csv"), "--out",
                 str(tmp_path / "j.csv")]) == 2
    assert "robot_calibrated.yaml" in capsys.readouterr().err
