"""Maximum a posteriori identification, repeated readings and the fuller result.json."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from robocal_casadi.calibration import calibrate, solve
from robocal_casadi.calibration.prior import Prior, PriorProblem, posterior, tolerance_of
from robocal_casadi.commands.demo import data_folder
from robocal_casadi.errors import InputError
from robocal_casadi.instruments.datasets import dataset_rows, load_dataset
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model import examples
from robocal_casadi.model.parameters import ParameterRegistry
from robocal_casadi.model.robot import load_robot, robot_to_dict
from robocal_casadi.results import EffectFinding


class LinearProblem:
    """``r(x) = A x - b``: the smallest thing the solvers accept."""

    def __init__(self, A, b):
        self.A, self.b = A, b
        n = A.shape[1]
        self.unknowns = ParameterRegistry(tuple(f"p{i}" for i in range(n)), ("length",) * n)

    def residual(self, x):
        return self.A @ x - self.b

    def jacobian(self, x, columns=None):
        if columns is None:
            return self.A.copy()
        columns = np.flatnonzero(columns) if np.asarray(columns).dtype == bool else columns
        return self.A[:, columns]


def test_map_estimate_matches_the_closed_form_on_a_linear_problem():
    rng = np.random.default_rng(0)
    m, n = 40, 5
    A = rng.normal(size=(m, n))
    A[:, 4] = A[:, 3] + 1e-4 * rng.normal(size=m)  # a nearly dependent pair
    b = rng.normal(size=m)
    centre = rng.normal(size=n)
    tolerance = np.array([0.5, 1.0, 2.0, 0.1, 0.3])
    sigma = 0.7
    prior = Prior(tuple(f"p{i}" for i in range(n)), np.arange(n), centre, tolerance, sigma)
    problem = LinearProblem(A, b)
    free = np.ones(n, bool)
    estimate = solve(PriorProblem(problem, prior), np.zeros(n), free, tolerance=1e-14).x
    # Closed form: (A^T A + sigma^2 P) x = A^T b + sigma^2 P x0, P = diag(1/t^2).
    P = np.diag(1.0 / tolerance**2)
    expected = np.linalg.solve(A.T @ A + sigma**2 * P, A.T @ b + sigma**2 * P @ centre)
    np.testing.assert_allclose(estimate, expected, rtol=1e-8, atol=1e-10)

    statistics = posterior(A, problem.residual(estimate), np.arange(n), prior)
    inverse = np.linalg.inv(A.T @ A + sigma**2 * P)
    np.testing.assert_allclose(statistics.covariance, statistics.sigma**2 * inverse, rtol=1e-8)
    # Data share: the diagonal of the resolution matrix (A^T A + sigma^2 P)^-1 A^T A.
    np.testing.assert_allclose(statistics.share, np.diag(inverse @ A.T @ A), rtol=1e-8)
    spent = np.trace(inverse @ A.T @ A)
    residual = problem.residual(estimate)
    assert statistics.sigma == pytest.approx(math.sqrt(residual @ residual / (m - spent)))
    # The nearly dependent pair: the data alone cannot split it, the prior does.
    assert statistics.share[3] < 0.5  # the tighter tolerance of the two takes the pair
    assert statistics.share[0] > 0.9


def test_ipopt_minimises_the_same_map_objective():
    rng = np.random.default_rng(1)
    A, b = rng.normal(size=(30, 3)), rng.normal(size=30)
    prior = Prior(("p0", "p1", "p2"), np.arange(3), np.zeros(3), np.array([0.1, 1.0, 1.0]), 0.5)

    class Symbolic(LinearProblem):
        def symbolic_residual(self, x):
            import casadi as ca

            return ca.mtimes(ca.DM(self.A), x) - ca.DM(self.b)

    wrapped = PriorProblem(Symbolic(A, b), prior)
    lm = solve(wrapped, np.zeros(3), np.ones(3, bool), tolerance=1e-14).x
    ipopt = solve(wrapped, np.zeros(3), np.ones(3, bool), method="ipopt").x
    np.testing.assert_allclose(ipopt, lm, atol=1e-8)


def test_ur10_target_offset_along_the_flange_axis_is_flagged_prior_dominated():
    folder = data_folder() / "ur10-ipa"
    fit = load_dataset(folder / "series_D_fit.yaml")
    held_out = load_dataset(folder / "series_D_validation.yaml")
    strict = calibrate([fit], [held_out], diagnose=False, rule="fraction")
    result = calibrate([fit], [held_out], diagnose=False, rule="prior")
    # The old rule holds it at nominal; the prior estimates it but says the prior decided.
    assert "target_z" not in strict.identifiability.identifiable
    assert "target_z" in result.identifiability.identifiable
    assert "target_z" in result.prior.dominated
    value, std = result.mounted["target_z"]
    nominal = fit.target[2]
    tolerance = tolerance_of("target_z", "length", fit.robot)
    assert abs(value - nominal) < 3 * tolerance  # millimetres, not the metres of noise
    assert std < tolerance  # the posterior is never wider than the prior
    content = result.to_json()
    assert content["mounted"]["target_z"]["prior_dominated"] is True
    assert content["mounted"]["target_x"]["prior_dominated"] is False
    assert "target_z" in content["prior"]["dominated"]
    entries = {p["name"]: p for p in content["parameters"]}
    assert entries["a2"]["prior_dominated"] is False and entries["a2"]["data_share"] > 0.99
    assert "prior_dominated" not in entries["theta1"]  # held: absorbed by the frame
    assert result.validation.rms_final < 1.02 * strict.validation.rms_final


def test_dependencies_of_the_symmetric_drawing_are_not_held(tmp_path):
    """The example arm's target sits on the flange axis: at the nominal geometry a5 and
    alpha5 act as a combination of other parameters; on a real robot, off its drawing,
    they do not. Judged at the generic point, they are estimated (the truth carries
    errors there), structural dependencies stay held, and every estimate lies within
    three posterior standard errors of the simulated truth."""
    from robocal_casadi.calibration import Problem, models_for
    from robocal_casadi.calibration.identification import (
        EXACT_TOLERANCE,
        analyse_identifiability,
        generic_point,
    )
    from robocal_casadi.calibration.prior import SETTLED_DECREASE, SIGMA_SETTLED

    robot = examples.industrial_6r()
    errors = {name: float(value) for name, value in zip(
        ("a1", "a2", "a3", "a4", "a5", "alpha1", "alpha2", "alpha3", "alpha4", "alpha5",
         "beta2", "d2", "d4", "d5", "theta2", "theta3", "theta4", "theta5"),
        np.random.default_rng(3).normal(0.0, 3e-4, 18))}
    sim = simulate(robot, "tracker_points", out_dir=tmp_path / "t", rows=150, noise=1e-6,
                   geometric_errors=errors, seed=10, mounted_error=0.0, progress=False)
    data = sim.load()
    problem = Problem(robot, models_for([data]))
    x = problem.initial()
    at_nominal = analyse_identifiability(problem, x, tolerance=EXACT_TOLERANCE)
    generic = analyse_identifiability(problem, generic_point(problem, x),
                                      tolerance=EXACT_TOLERANCE)
    assert {"a5", "alpha5"} - set(at_nominal.identifiable) == {"a5", "alpha5"}
    assert {"a5", "alpha5"} <= set(generic.identifiable)
    for name in ("theta1", "d1", "beta5"):  # tracker frame; a combination at any geometry
        assert name not in generic.identifiable
    # The move is the same every time (a calibration is repeatable).
    np.testing.assert_array_equal(generic_point(problem, x), generic_point(problem, x))

    result = calibrate([data], diagnose=False)
    truth = sim.truth.robot.parameter_vector()
    registry = robot.parameters()
    for entry in result.parameters:
        if entry.identifiable:
            error = entry.estimate - truth[registry.index(entry.name)]
            assert abs(error) <= 3 * entry.std, (entry.name, error, entry.std)
    held_at_nominal = calibrate([data], diagnose=False, rule="fraction")
    assert {"a5", "alpha5"} <= set(result.identifiability.identifiable)
    assert not {"a5", "alpha5"} & set(held_at_nominal.identifiability.identifiable)
    # Estimating a5 and alpha5 costs the fit nothing the prior does not account for. The
    # MAP estimate minimises |r|^2 + sum (sigma/t_i)^2 (x_i - x0_i)^2 over a superset of the
    # fraction rule's free parameters, so at its minimum
    #   |r_map|^2 <= |r_fraction|^2 + sum (sigma/t_i)^2 (x_fraction_i - x0_i)^2,
    # with sigma the prior's weight (within SIGMA_SETTLED of the reported noise) and a slack
    # for the MAP's stopping rule (a step lowering the cost by under SETTLED_DECREASE sigma^2;
    # ten such steps at most remain for a linear rate of 0.9). Here |r|^2 = N rms^2.
    penalty = _prior_cost_of(held_at_nominal, problem, x, result.prior)
    sigma = result.prior.noise * (1.0 + SIGMA_SETTLED)
    slack = 10 * 2.0 * SETTLED_DECREASE * sigma**2
    rows = problem.errors(x)[0].size
    assert float(np.sum(problem.residual(x) ** 2)) == pytest.approx(rows * problem.rms(x) ** 2,
                                                                    rel=1e-12)
    assert rows * result.fit.rms_geometric**2 <= rows * held_at_nominal.fit.rms_geometric**2 \
        + (1.0 + SIGMA_SETTLED) ** 2 * penalty + slack


def _prior_cost_of(fit, problem, start, prior) -> float:
    """sum (sigma/t_i)^2 (x_i - x0_i)^2 [m^2] at ``fit``'s estimates, over the prior's
    parameters (robot and mounted), ``x0`` the problem's start values."""
    total = 0.0
    for name, tolerance in prior.tolerance.items():
        centre = start[problem.unknowns.indices((name,))[0]]
        if name in fit.mounted:
            value = fit.mounted[name][0]
        else:
            value = fit.parameter(name).estimate
        total += (prior.noise / tolerance * (value - centre)) ** 2
    return total


def _sphere(tmp_path, readings="joints", rows=120):
    return simulate(examples.industrial_6r(), "sphere_laser", out_dir=tmp_path / readings,
                    rows=rows, noise=8e-6, geometric_errors=(0.3e-3, math.radians(0.03)),
                    seed=5, readings=readings, progress=False)


def test_result_json_carries_sphere_percentiles_and_noise(tmp_path):
    sim = _sphere(tmp_path)
    dataset = sim.load()
    keep = np.arange(dataset.rows) % 4 != 3
    fit = replace(dataset_rows(dataset, keep), path=dataset.path.with_name("fit.yaml"))
    held = replace(dataset_rows(dataset, ~keep), path=dataset.path.with_name("held.yaml"))
    result = calibrate([fit], [held], diagnose=False, rule="prior")
    content = json.loads(json.dumps(result.to_json()))
    spheres = {s["role"]: s for s in content["spheres"]}
    true_centre = np.asarray(sim.truth.placement["sphere_centre"]) * 1e3  # mm
    for role in ("fit", "validation"):
        assert spheres[role]["radius"] == pytest.approx(25.0)
        assert spheres[role]["unit"] == "mm"
        # In the calibrated robot's base frame, which the sphere centre fixes up to the
        # base and joint-1 errors it absorbs (0.3 mm, 0.03 deg at most a few tenths).
        np.testing.assert_allclose(spheres[role]["centre"], true_centre, atol=1.0)
    # The same sphere seen by held-out readings through the calibrated robot.
    np.testing.assert_allclose(spheres["validation"]["centre"], spheres["fit"]["centre"],
                               atol=0.05)  # 30 held-out readings, 0.008 mm noise
    # Standard errors of the centre: tens of micrometres (it shares the robot's errors).
    assert all(0.001 < s < 0.2 for s in spheres["fit"]["centre_std"])
    for block, residuals in (("fit", result.residuals), ("validation",
                                                         result.validation_residuals)):
        (entry,) = content[block]["datasets"]
        errors = np.abs(residuals[0].errors_final) * 1e3
        assert entry["rms_final"] == pytest.approx(float(np.sqrt(np.mean(errors**2))))
        assert entry["final"]["p50"] == pytest.approx(float(np.median(errors)))
        assert entry["final"]["max"] == pytest.approx(float(errors.max()))
        assert entry["final"]["p50"] <= entry["final"]["p95"] <= entry["final"]["p99"] \
            <= entry["final"]["max"]
    assert content["prior"]["rule"] == "prior"
    assert content["prior"]["noise"] == pytest.approx(8e-3, rel=0.25)  # mm


def test_effect_standard_errors_are_in_result_json():
    finding = EffectFinding("joint_compliance", (2,), {"c2": 1.5e-6}, "rad/Nm",
                            {"rms_drop": 0.3}, std={"c2": 2e-8})
    assert finding.to_json()["std"] == {"c2": 2e-8}


def test_repeated_placements_do_not_shrink_standard_errors(tmp_path, capsys):
    sim = simulate(examples.industrial_6r(), "cross_bar", out_dir=tmp_path / "bar", rows=40,
                   noise=10e-6, geometric_errors=(0.3e-3, math.radians(0.03)), seed=2,
                   progress=False)
    dataset = sim.load()
    once = calibrate([dataset], diagnose=False, rule="prior")
    assert "notes" not in once.to_json()
    capsys.readouterr()
    # Every placement recorded three times under new placement ids.
    copies = 3
    shift = int(dataset.pose.max()) + 1
    repeated = replace(
        dataset, joints=np.tile(dataset.joints, (copies, 1)),
        pose=np.concatenate([dataset.pose + k * shift for k in range(copies)]),
        point=dataset.point * copies,
        extras={k: np.tile(v, copies) for k, v in dataset.extras.items()})
    thrice = calibrate([repeated], diagnose=False, rule="prior")
    err = capsys.readouterr().err
    assert err.count("repeat an earlier one exactly") == 1
    assert "80 of 120 units" in err
    assert any("repeat" in note for note in thrice.to_json()["notes"])
    for name in ("a2", "theta3", "d4"):
        a, b = once.parameter(name), thrice.parameter(name)
        assert b.estimate == pytest.approx(a.estimate, abs=1e-9)
        assert b.std == pytest.approx(a.std, rel=0.02)


def test_robot_file_tolerances_are_read_checked_and_written_back(tmp_path):
    path = tmp_path / "robot.yaml"
    path.write_text(
        "convention: dh\nunits: {length: mm, angle: deg}\n"
        "joints:\n"
        "  - {theta: 0, d: 400, a: 25, alpha: -90, tolerance: {a: 0.5, theta: 0.1}}\n"
        "  - {theta: 0, d: 0, a: 455, alpha: 0}\n"
        "tolerance: {length: 2, angle: 0.3, tool_rpy: 2, instrument: 3}\n")
    robot = load_robot(path)
    assert tolerance_of("a1", "length", robot) == pytest.approx(0.5e-3)
    assert tolerance_of("theta1", "angle", robot) == pytest.approx(math.radians(0.1))
    assert tolerance_of("d1", "length", robot) == pytest.approx(2e-3)
    assert tolerance_of("alpha2", "angle", robot) == pytest.approx(math.radians(0.3))
    assert tolerance_of("tool_ry", "angle", robot) == pytest.approx(math.radians(2))
    assert tolerance_of("base_x", "length", robot) == pytest.approx(10e-3)  # default
    assert tolerance_of("probe_z", "length", robot) == pytest.approx(3e-3)
    content = robot_to_dict(robot)
    assert content["joints"][0]["tolerance"] == {"theta": 0.1, "a": 0.5}
    assert content["tolerance"] == {"length": 2.0, "angle": 0.3, "tool_rpy": 2.0,
                                    "instrument": 3.0}
    for bad, message in (("{a: 0.5, thetta: 1}", "thetta"), ("{a: -1}", "positive"),
                         ("{a: lots}", "tolerance.a")):
        path.write_text("convention: dh\nunits: {length: mm, angle: deg}\njoints:\n"
                        f"  - {{theta: 0, d: 0, a: 0, alpha: 0, tolerance: {bad}}}\n")
        with pytest.raises(InputError, match=message):
            load_robot(path)
    path.write_text("convention: dh\nunits: {length: mm, angle: deg}\njoints:\n"
                    "  - {theta: 0, d: 0, a: 0, alpha: 0}\ntolerance: {lenght: 1}\n")
    with pytest.raises(InputError, match="lenght"):
        load_robot(path)
