"""Public entry points check their arguments before any work, scipy-style.

A wrong name lists the valid ones and suggests the closest; a wrong count, number or
shape names the argument, the expectation and what was given. Every refusal is an
``ArgumentError``: a ``ValueError`` (as scipy raises) and a ``RobocalError`` (so the
command line prints it as its one line). Before these checks ``calibrate(...,
loss="hubr")`` ran as plain least squares without a word.
"""

from __future__ import annotations

import numpy as np
import pytest

from planning import design_plan
from planning.indices import canonical
from robocal_casadi import Tracker, calibrate, compensate, load_dataset, simulate
from robocal_casadi.calibration import Problem, models_for
from robocal_casadi.calibration.solver import solve
from robocal_casadi.common.checks import choice, count, positive, rotation_matrix
from robocal_casadi.errors import ArgumentError, InputError, RobocalError
from robocal_casadi.model.examples import industrial_6r
from robocal_casadi.model.ik import InverseKinematics
from robocal_casadi.model.kinematics import Kinematics


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sim")
    simulate(industrial_6r(), "tracker_points", rows=12, seed=1, out_dir=folder / "d",
             progress=False)
    return load_dataset(folder / "d" / "dataset.yaml")


def refused(call, *fragments):
    with pytest.raises(ArgumentError) as caught:
        call()
    error = caught.value
    assert isinstance(error, ValueError) and isinstance(error, RobocalError)
    for fragment in fragments:
        assert fragment in str(error), str(error)
    return error


def test_calibrate_refuses_a_misspelt_loss_and_suggests_huber(dataset):
    error = refused(lambda: calibrate([dataset], loss="hubr"), "loss", "'hubr'", "'linear'",
                    "'huber'", "did you mean 'huber'")
    assert error.argument == "loss"


@pytest.mark.parametrize("options, fragments", [
    ({"method": "levenberg"}, ["method", "'lm'", "'ipopt'", "'linearised'", "'two_stage'"]),
    ({"method": "two-stage"}, ["did you mean 'two_stage'"]),
    ({"method": None}, ["method", "expected one of", "None"]),
    ({"max_iterations": 0}, ["max_iterations", ">= 1", "0"]),
    ({"max_iterations": 2.5}, ["max_iterations", "whole number"]),
    ({"select_growth": -0.1}, ["select_growth", ">= 0"]),
    ({"select_growth": float("nan")}, ["select_growth", "finite"]),
    ({"effects": ["joint_compliance"]}, ["effects", "Effect objects", "str"]),
])
def test_calibrate_checks_every_option(dataset, options, fragments):
    refused(lambda: calibrate([dataset], diagnose=False, **options), *fragments)


def test_calibrate_wants_a_list_of_datasets(dataset):
    refused(lambda: calibrate(str(dataset.path)), "datasets", "load_dataset", "a list")
    refused(lambda: calibrate(dataset), "datasets", "a list")
    refused(lambda: calibrate([dataset], validation=[42]), "validation", "int")
    with pytest.raises(InputError, match="missing.yaml: dataset file not found"):
        calibrate([dataset], validation=[dataset.path.parent / "missing.yaml"])


def test_solve_checks_shapes_and_names(dataset):
    problem = Problem(dataset.robot, models_for([dataset]), ())
    x0 = problem.initial()
    free = problem.mask("placement")
    refused(lambda: solve(problem, x0[:-1], free), "x0", f"({len(x0)},)")
    refused(lambda: solve(problem, x0, free[:-1]), "free", "booleans")
    refused(lambda: solve(problem, x0, free.astype(int)), "free", "booleans")
    refused(lambda: solve(problem, x0, free, loss="Huber"), "did you mean 'huber'")
    refused(lambda: solve(problem, x0, free, tolerance=0.0), "tolerance", "> 0")
    x_bad = x0.copy()
    x_bad[0] = np.nan
    refused(lambda: solve(problem, x_bad, free), "x0", "finite")


def test_tracker_checks_its_names_and_camera():
    robot = industrial_6r()
    refused(lambda: Tracker(robot, [0, 0, 0.05], 0.3, method="gauss-newton"),
            "method", "did you mean 'gauss_newton'", "'sqpmethod'", "'ipopt'")
    refused(lambda: Tracker(robot, [0, 0, 0.05], 0.3, method="sqpmethod", qpsol="qpOASES"),
            "qpsol", "did you mean 'qpoases'")
    refused(lambda: Tracker(robot, [0, 0, 0.05], 0.3, marker_convention="aruco"),
            "marker_convention", "'method'", "'opencv'")
    refused(lambda: Tracker(robot, [0, 0, 0.05], 0.3, camera_rotation=np.diag([1, 1, -1.0])),
            "camera_rotation", "rotation matrix")
    refused(lambda: Tracker(robot, [0, 0, 0.05], 0.3, camera_rotation=np.eye(2)),
            "camera_rotation", "(3, 3)")


def test_inverse_kinematics_checks_names_and_counts():
    kinematics = Kinematics(industrial_6r())
    refused(lambda: InverseKinematics(kinematics, "poses"), "mode", "did you mean 'pose'")
    refused(lambda: InverseKinematics(kinematics, "pose", "LM"), "method", "did you mean 'lm'")
    ik = InverseKinematics(kinematics, "pose")
    target = np.eye(4)
    refused(lambda: ik.solve(target, restarts=-1), "restarts", ">= 0")
    refused(lambda: ik.solve(target, seed=np.zeros(5)), "seed", "(6,)")
    refused(lambda: ik.solve(target, position_tolerance=-1e-9), "position_tolerance")


def test_simulate_plan_and_compensate_check_their_arguments(tmp_path, dataset):
    robot = industrial_6r()
    refused(lambda: simulate(robot, "crossbar", out_dir=tmp_path / "s"), "kind",
            "did you mean 'cross_bar'")
    refused(lambda: simulate(robot, "cross_bar", rows=0, out_dir=tmp_path / "s"), "rows")
    refused(lambda: simulate(robot, "cross_bar", noise=-1e-3, out_dir=tmp_path / "s"), "noise")
    refused(lambda: simulate(robot, "sphere_laser", readings="pendent",
                             out_dir=tmp_path / "s"), "did you mean 'pendant'")
    assert not (tmp_path / "s").exists()
    refused(lambda: canonical("O7"), "index", "'cond'", "'O1'")
    refused(lambda: design_plan(dataset, 0), "count", ">= 1")
    refused(lambda: compensate(robot, [[0.5, 0.0, 1.0]], restarts=-2), "restarts")


def test_the_checks_hand_back_canonical_values():
    assert choice("huber", ("linear", "huber"), "loss") == "huber"
    assert count(np.int64(3), "n") == 3 and count(4.0, "n") == 4
    assert positive("2.5", "x") == 2.5 and positive(0, "x", allow_zero=True) == 0.0
    refused(lambda: count(True, "n"), "n", "whole number")
    R = rotation_matrix(np.eye(3).tolist(), "R")
    assert R.dtype == float and R.shape == (3, 3)
