"""The learned residual map: its regression, its file, its fade, and when it is kept.

References from outside the code under test: scipy's ``RBFInterpolator`` for the kernel
ridge regression, plain forward kinematics plus the map's numpy form for the CasADi form
read back from the effects file, and tracker data computed here through pinocchio.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import RBFInterpolator

from robocal_casadi import load_dataset
from robocal_casadi.calibration import Problem, calibrate, models_for
from robocal_casadi.calibration.evaluation import refit_placement
from robocal_casadi.calibration.learned import fit_map, joints_named, learn
from robocal_casadi.cli import main
from robocal_casadi.effects import ResidualMap, is_learned
from robocal_casadi.effects.effect_model import EFFECTS_FILE, load_effects
from robocal_casadi.instruments.datasets import dataset_rows
from robocal_casadi.model.examples import ROBOTS
from robocal_casadi.model.kinematics import Kinematics
from robocal_casadi.model.pinocchio_model import frame_placements, pinocchio_model
from robocal_casadi.model.robot import dump_yaml, load_robot, save_robot

NOISE = 1e-5  # [m] per tracker coordinate
TARGET = np.array([0.0, 0.0, 0.1])  # [m] reflector in the flange frame


def a_map(seed: int = 0) -> tuple[ResidualMap, np.ndarray, np.ndarray]:
    """A map over joints 2 and 3 fitted to a smooth field; the rows it was fitted on."""
    rng = np.random.default_rng(seed)
    X = rng.uniform([-1.0, -2.0], [1.5, 0.5], (60, 2))
    T = 2e-4 * np.column_stack([np.sin(2 * X[:, 0]), np.cos(X[:, 1]), X[:, 0] * X[:, 1]])
    effect = fit_map((2, 3), X, T, length_scale=0.3, smoothing=0.05)
    assert effect is not None
    return effect, X, T


def test_the_map_is_the_kernel_ridge_regression_scipy_solves():
    effect, X, T = a_map()
    U = (X - effect.lower) / (effect.upper - effect.lower)
    reference = RBFInterpolator(U, T, kernel="gaussian", degree=-1, smoothing=0.05,
                                epsilon=1.0 / (0.3 * math.sqrt(2.0)))
    probe = np.random.default_rng(1).uniform(effect.lower, effect.upper, (25, 2))
    scaled = (probe - effect.lower) / (effect.upper - effect.lower)
    expected = reference(scaled)
    # Both solve the same 60 x 60 system: agreement to its conditioning times rounding.
    np.testing.assert_allclose(effect.kernel_part(probe), expected,
                               atol=1e-9 * np.abs(T).max())


def test_the_map_fades_to_zero_outside_its_region():
    effect, X, _ = a_map()
    span = effect.upper - effect.lower
    inside = X[:5]
    np.testing.assert_array_equal(effect.weight(inside), np.ones(5))
    beyond = np.array([[effect.upper[0] + 1.01 * effect.fade[0], 0.0],
                       [0.0, effect.lower[1] - 1.5 * effect.fade[1]],
                       [effect.lower[0] - 3 * span[0], effect.upper[1] + 3 * span[1]]])
    Q = np.zeros((3, 6))
    Q[:, 1:3] = beyond
    np.testing.assert_array_equal(effect.shift(Q), np.zeros((3, 3)))
    # Between the region and the end of the fade the weight falls monotonically.
    steps = effect.upper[0] + np.linspace(0.0, 1.0, 11) * effect.fade[0]
    weights = effect.weight(np.column_stack([steps, np.full(11, 0.0)]))
    assert weights[0] == 1.0 and weights[-1] == 0.0
    assert np.all(np.diff(weights) <= 0) and 0 < weights[5] < 1


def test_the_map_reads_back_from_the_effects_file_and_evaluates_identically(tmp_path):
    robot = ROBOTS["industrial_6r"]()
    effect, _, _ = a_map(2)
    entry = {"name": effect.name, "joints": list(effect.joints),
             "parameters": {"map_gain": 1.0}, **effect.to_entry()}
    content = {"units": {"length": "m", "angle": "rad"}, "effects": [entry],
               "payload_com": [0.0, 0.0, 0.0]}
    (tmp_path / EFFECTS_FILE).write_text(dump_yaml(content))
    model = load_effects(tmp_path, robot)
    (loaded,) = model.effects
    assert isinstance(loaded, ResidualMap) and is_learned(loaded.name)
    for name in ("centres", "coefficients", "lower", "upper", "fade"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(effect, name))
    rng = np.random.default_rng(3)
    Q = rng.uniform(-1.0, 1.0, (40, robot.dof))
    Q[:, 1:3] = rng.uniform(effect.lower - 2 * effect.fade, effect.upper + 2 * effect.fade,
                            (40, 2))  # inside, in the fade and beyond
    moved = model.tool_poses(Q)[:, :3, 3] - Kinematics(robot).tool_poses(Q)[:, :3, 3]
    # CasADi form from the file against the numpy form of the map fitted in memory.
    np.testing.assert_allclose(moved, effect.shift(Q), rtol=0, atol=1e-13)
    assert np.abs(effect.shift(Q)).max() > 1e-5  # the points probe a map that moves them


def test_a_broken_map_entry_names_what_is_wrong(tmp_path):
    effect, _, _ = a_map()
    entry = {"name": effect.name, "joints": [2, 3], "parameters": {"map_gain": 1.0},
             **effect.to_entry()}
    entry["coefficients"] = entry["coefficients"][:-1]
    (tmp_path / EFFECTS_FILE).write_text(dump_yaml({"effects": [entry]}))
    with pytest.raises(Exception, match="coefficients") as caught:
        load_effects(tmp_path, ROBOTS["industrial_6r"]())
    assert "effects[0]" in str(caught.value)


def tracker_data(folder: Path, rows: int, seed: int, error, robot=None,
                 geometry_error: float = 0.0) -> object:
    """Tracker data of ``robot`` (default the 6R arm) computed through pinocchio (tracker
    frame = world), its DH parameters off the drawing by ``geometry_error`` [m, rad]
    (random, fixed), plus ``error(Q)`` (N x 3) [m] in the world frame."""
    robot = ROBOTS["industrial_6r"]() if robot is None else robot
    folder.mkdir(parents=True, exist_ok=True)
    Q = np.random.default_rng(seed).uniform(np.maximum(robot.lower_limits, -math.pi) * 0.9,
                                            np.minimum(robot.upper_limits, math.pi) * 0.9,
                                            (rows, robot.dof))
    kinematics = Kinematics(robot)
    p = kinematics.nominal.copy()
    drawing = np.random.default_rng(700)
    for i in range(1, robot.dof + 1):
        for stem in ("theta", "d", "a", "alpha"):
            p[kinematics.registry.index(f"{stem}{i}")] += drawing.normal(0.0, geometry_error)
    model = pinocchio_model(robot.with_parameters(p), with_links=False)
    points = np.array([(lambda T: T[:3, :3] @ TARGET + T[:3, 3])(
        frame_placements(model, q, ["flange"])[0]) for q in Q])
    points += np.random.default_rng(seed).normal(0.0, NOISE, points.shape) + error(Q)
    save_robot(robot, folder / "robot.yaml")
    (folder / "dataset.yaml").write_text(
        "kind: tracker_points\nrobot: robot.yaml\nunits: {length: m, angle: rad}\n"
        "target: {xyz: [0.0, 0.0, 0.1]}\ndata: points.csv\n")
    header = ",".join([f"q{j + 1}" for j in range(robot.dof)] + ["x", "y", "z"])
    lines = [header] + [",".join(repr(float(v)) for v in row)
                        for row in np.column_stack([Q, points])]
    (folder / "points.csv").write_text("\n".join(lines) + "\n")
    return load_dataset(folder / "dataset.yaml")


def sines(Q: np.ndarray) -> np.ndarray:
    """An error no effect of the library describes: sines of joints 2 and 3 [m]."""
    return 2e-4 * np.column_stack([np.sin(2 * Q[:, 1]) * np.cos(Q[:, 2]),
                                   np.sin(Q[:, 1] + 2 * Q[:, 2]), np.cos(3 * Q[:, 2])])


@pytest.mark.parametrize("seed", [1, 2])
def test_not_kept_on_clean_data_kept_on_an_unnamed_smooth_error(tmp_path, seed):
    """At the true geometry the residual is the noise (clean) or the noise plus ``sines``;
    the map is offered over q2 and q3 either way and must pay only in the second case."""
    robot = ROBOTS["industrial_6r"]()
    for name, error in (("clean", lambda Q: np.zeros((len(Q), 3))), ("sines", sines)):
        data = tracker_data(tmp_path / name, 150, seed, error)
        problem = Problem(robot, models_for([data]))
        x = refit_placement(problem, problem.initial())
        outcome = learn(problem, x, ("q2", "q3*q2", "direction_q1"))
        assert outcome is not None
        if name == "clean":
            assert outcome.effect is None, outcome
            assert outcome.reason
        else:
            assert outcome.effect is not None, outcome
            assert outcome.effect.joints == (2, 3)
            # the held-out error falls towards the noise floor (3-D: sqrt(3) sigma)
            assert outcome.cv_after < 0.5 * outcome.cv_before, outcome


def test_the_map_follows_only_joint_readings():
    assert joints_named(("q3", "direction_q1", "temperature", "q2*q3", "q5*q1"), 6) == (3, 2, 5)
    assert joints_named(("direction_q2", "payload"), 6) == ()


def test_shares_of_the_mean_square_add_up():
    from robocal_casadi.results import EffectFinding, mean_square_shares

    mapped = EffectFinding(name="residual_map", joints=(2, 3), parameters={"map_gain": 1.0},
                           unit="1", evidence={"fit_rms_without": 0.3})
    parts = mean_square_shares(1.0, 0.5, 0.1, [mapped])
    assert parts is not None
    assert sum(parts.values()) == pytest.approx(1.0)
    assert parts["learned map"] == pytest.approx(0.09 - 0.01)
    assert parts["physical effects"] == pytest.approx(0.25 - 0.09)
    assert mean_square_shares(1.0, 0.5, 0.5, []) is None


def sines_of_two_joints(Q: np.ndarray) -> np.ndarray:
    """Another unnamed error: 0.1 mm sines of joints 2 and 3 [m], world frame."""
    q2, q3 = Q[:, 1], Q[:, 2]
    return 1e-4 * np.column_stack([np.sin(2 * q2 + 0.4) * np.cos(q3),
                                   np.cos(3 * q3 - 0.2) * np.sin(q2),
                                   0.7 * np.sin(q2 + 2 * q3)])


@pytest.mark.slow
def test_fitted_on_half_of_joint_1_the_other_half_is_not_made_worse(tmp_path):
    """A UR10 whose truth is its geometry plus an error no effect names, fitted on the
    lower half of joint 1's range and judged on the upper half: what the calibration adds
    must not make the held-out half worse than the geometry alone. (Judged on quarters of
    each joint's range only, a joint-3 periodic error and a transmission coupling were
    added that made it worse.)"""
    robot = load_robot(Path(__file__).resolve().parents[1] / "robocal_casadi" / "data"
                       / "ur10-ipa" / "robot.yaml")
    data = tracker_data(tmp_path / "d", 400, 1, sines_of_two_joints, robot, 5e-4)
    low = data.joints[:, 0] < np.median(data.joints[:, 0])
    result = calibrate([dataset_rows(data, low)], [dataset_rows(data, ~low)])
    held_out = result.validation_all
    assert held_out.rms_final <= held_out.rms_geometric, [e.summary for e in result.effects]


@pytest.mark.slow
def test_the_job_delivers_the_map_and_reads_it_back(tmp_path):
    """On an error no effect names, the calibration keeps the map, says it is learned,
    writes it into effects_calibrated.yaml, and what the file delivers when read back is
    what the final model scored on the held-out data."""
    fit = tracker_data(tmp_path / "fit", 300, 1, sines, geometry_error=5e-4)
    held = tracker_data(tmp_path / "held", 150, 2, sines, geometry_error=5e-4)
    out = tmp_path / "out"
    assert main(["calibrate", str(fit.path), "--validate", str(held.path), "--out", str(out),
                 "--no-report"]) == 0
    result = json.loads((out / "result.json").read_text())
    assert "residual_map" in {e["name"] for e in result["effects"]}
    validation = result["validation"]["all"]
    assert validation["rms_final"] < 0.7 * validation["rms_geometric"], validation
    delivered = result["delivered"]["effects_calibrated.yaml"]["validation"]
    assert delivered == pytest.approx(result["validation"]["rms_final"], rel=1e-6)
    written = load_effects(out, ROBOTS["industrial_6r"]())
    assert any(isinstance(e, ResidualMap) for e in written.effects)


def test_kernel_matrix_against_scipy_distances_across_row_blocks():
    # More rows than one block of the in-place sum: every entry exp(-d^2 / (2 l^2)) with
    # d the Euclidean distance scipy computes on its own.
    from scipy.spatial.distance import cdist

    from robocal_casadi.effects.residual_map import KERNEL_BLOCK, gaussian

    rng = np.random.default_rng(4)
    U = rng.uniform(-0.1, 1.1, (KERNEL_BLOCK + 37, 3))
    centres = rng.uniform(0.0, 1.0, (50, 3))
    expected = np.exp(-cdist(U, centres, "sqeuclidean") / (2.0 * 0.2**2))
    np.testing.assert_allclose(gaussian(U, centres, 0.2), expected, rtol=1e-13, atol=0)


def test_the_geometry_refitted_with_the_map_is_the_maximum_a_posteriori_fit(tmp_path):
    """With the map in, the geometry is refitted under the prior it was fitted with: the
    refit ends at the minimum of the same objective (data plus prior rows) that scipy's
    least_squares reaches from the same start, within the fit's settling slack, and no
    parameter leaves the prior's reach (3 tolerances from where the prior centres it)."""
    from scipy.optimize import least_squares

    from robocal_casadi.calibration.diagnosis import embed
    from robocal_casadi.calibration.identification import _map_geometric
    from robocal_casadi.calibration.learned import with_map
    from robocal_casadi.calibration.prior import SETTLED_DECREASE, PriorProblem, copy_weights
    from robocal_casadi.calibration.solver import solve

    robot = ROBOTS["industrial_6r"]()
    data = tracker_data(tmp_path, 150, 1, sines, geometry_error=2e-4)
    problem = Problem(robot, models_for([data]))
    x0 = refit_placement(problem, problem.initial())
    start = solve(problem, x0, problem.mask("placement"))
    _, geometric, prior, _ = _map_geometric(problem, x0, start.x, 1e-5, None, method="lm",
                                            loss="linear", max_iterations=100)
    outcome = learn(problem, geometric.x, ("q2", "q3"))
    assert outcome is not None and outcome.effect is not None, outcome
    mapped, refit = with_map(problem, geometric, outcome.effect, prior=prior)
    assert refit.status == "converged", refit
    placed = prior.placed_in(mapped)
    objective = PriorProblem(mapped, placed, copy_weights(mapped))
    free = refit.free

    x_start = embed(problem, geometric.x, mapped)
    x_start[mapped.unknowns.index("map_gain")] = 1.0

    def full(z):
        x = x_start.copy()
        x[free] = z
        return x

    reference = least_squares(lambda z: objective.residual(full(z)), x_start[free],
                              jac=lambda z: objective.jacobian(full(z), free), method="lm",
                              xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=2000)
    ours = 0.5 * float(np.sum(objective.residual(refit.x) ** 2))
    # The fit settles when a step lowers the cost by under SETTLED_DECREASE sigma^2; ten
    # such steps at most remain for a linear rate of 0.9.
    slack = 10 * SETTLED_DECREASE * prior.sigma ** 2
    assert reference.cost - 1e-12 * reference.cost <= ours <= reference.cost + slack
    index = placed.index
    assert np.all(np.abs(refit.x[index] - placed.centre) <= 3 * placed.tolerance
                  + np.abs(geometric.x[prior.index] - placed.centre))
