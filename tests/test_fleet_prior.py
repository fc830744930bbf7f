"""The fleet prior: the population estimator against simulated truth, the prior file, and
its use by calibrate (a robot that belongs, one that does not)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal_casadi.calibration.population import Evidence, conflict, estimate
from robocal_casadi.calibration.prior import Prior, PriorProblem, tolerance_of
from robocal_casadi.cli import main
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model import examples
from robocal_casadi.model.parameters import ParameterRegistry, perturbed_stems


def _simulated_fleet(rng, mean, covariance, tolerance, robots, unseen=None, sharp=1.0,
                     prefix="robot"):
    """Robots drawn from ``N(mean, covariance)``, each looked at by a random linear
    instrument (information ``H``), its calibration the Gaussian posterior under the
    tolerance prior: (evidence, true deviations)."""
    p = len(mean)
    evidence, truths = [], []
    tolerance_cov = np.diag(tolerance**2)
    for i in range(robots):
        theta = rng.multivariate_normal(mean, covariance)
        design = sharp * rng.normal(size=(8, p)) * rng.uniform(0.5, 4.0, size=p) / tolerance
        if unseen is not None and unseen(i):
            design[:, unseen(i)] = 0.0
        information = design.T @ design
        noise = np.linalg.lstsq(design, rng.normal(size=8), rcond=None)[0]
        seen_estimate = theta + noise  # the data-alone estimate (noise std 1 per row)
        posterior = np.linalg.inv(np.linalg.inv(tolerance_cov) + information)
        estimate_ = posterior @ (information @ seen_estimate)
        evidence.append(Evidence.from_posterior(f"{prefix}-{i}", estimate_, posterior,
                                                np.zeros(p), tolerance_cov))
        truths.append(theta)
    return evidence, np.array(truths)


def test_the_estimator_recovers_a_known_population():
    rng = np.random.default_rng(11)
    tolerance = np.array([1e-3, 2e-3, 0.5 * math.pi / 180])
    mean = np.array([0.6e-3, -1.2e-3, 0.3 * math.pi / 180])
    correlation = np.array([[1.0, 0.6, -0.3], [0.6, 1.0, 0.2], [-0.3, 0.2, 1.0]])
    spread = 0.3 * tolerance
    covariance = correlation * np.outer(spread, spread)
    robots = 300
    evidence, _ = _simulated_fleet(rng, mean, covariance, tolerance, robots)
    population = estimate(evidence, ("a", "b", "c"), tolerance, pseudo_robots=1e-3)
    # the mean's standard error: the spread plus each robot's estimation noise, over N
    noise = np.mean([np.diag(np.linalg.pinv(e.information)) for e in evidence], axis=0)
    standard_error = np.sqrt((spread**2 + noise) / robots)
    assert np.all(np.abs(population.mean - mean) < 4 * standard_error)
    # a variance estimated from N draws: relative standard error ~ sqrt(2 / N), and more
    # for the part estimation noise hides
    relative = np.diag(population.covariance) / spread**2 - 1
    assert np.all(np.abs(relative) < 4 * math.sqrt(2 / robots) * (1 + noise / spread**2))
    estimated_correlation = population.covariance / np.outer(population.spread,
                                                             population.spread)
    assert np.all(np.abs(estimated_correlation - correlation) < 0.2)
    assert not population.odd


def test_a_parameter_a_robot_did_not_see_does_not_move_the_mean():
    rng = np.random.default_rng(3)
    tolerance = np.array([1e-3, 1e-3, 1e-3])
    mean = np.array([0.8e-3, -0.5e-3, 0.6e-3])
    covariance = np.diag((0.2 * tolerance) ** 2)
    evidence, _ = _simulated_fleet(rng, mean, covariance, tolerance, 12)
    before = estimate(evidence, ("a", "b", "c"), tolerance)
    # a robot whose data carry nothing on parameter c: its calibration left c at nominal
    # (0) with the tolerance as its uncertainty; a plain average would pull c's mean by
    # mean_c / 13 toward zero. Its data on a and b sit at the fleet's mean, so that
    # nothing but c could move c's mean.
    design = np.array([[3.0, 1.0, 0.0], [1.0, -2.0, 0.0], [0.5, 0.5, 0.0]]) / tolerance
    information = design.T @ design
    tolerance_cov = np.diag(tolerance**2)
    posterior = np.linalg.inv(np.linalg.inv(tolerance_cov) + information)
    seen = np.array([before.mean[0], before.mean[1], 0.0])
    blind = Evidence.from_posterior("blind", posterior @ (information @ seen), posterior,
                                    np.zeros(3), tolerance_cov)
    assert posterior[2, 2] == pytest.approx(tolerance[2] ** 2)
    after = estimate(evidence + [blind], ("a", "b", "c"), tolerance)
    naive_pull = abs(before.mean[2]) / 13
    # what is left is the population's own readjustment, at the per cent level (one more
    # robot narrows the spread of a and b and the correlations' shrinkage, and every
    # robot's posterior of c with them)
    assert abs(after.mean[2] - before.mean[2]) < 0.03 * naive_pull
    assert after.seen_by[2] == before.seen_by[2]
    assert after.seen_by[0] == before.seen_by[0] + 1
    # nor widen its spread by the blind robot's own uncertainty
    assert after.spread[2] < 1.05 * before.spread[2]


def test_an_odd_robot_is_named_and_down_weighted():
    rng = np.random.default_rng(5)
    tolerance = np.array([1e-3, 1e-3, 1e-3, 1e-3])
    mean = np.array([0.6e-3, -0.6e-3, 0.3e-3, 0.0])
    spread = 0.15 * tolerance
    covariance = np.diag(spread**2)
    evidence, _ = _simulated_fleet(rng, mean, covariance, tolerance, 20, sharp=4.0)
    # own errors five times the fleet's spread
    odd_covariance = np.diag((5 * spread) ** 2)
    odd, truth = _simulated_fleet(np.random.default_rng(8), mean, odd_covariance,
                                  tolerance, 1, sharp=4.0, prefix="odd")
    population = estimate(evidence + odd, tuple("abcd"), tolerance)
    named = [m.robot for m in population.odd]
    assert named == ["odd-0"]
    member = population.odd[0]
    assert member.weight < 0.5 and member.distance > member.threshold
    without = estimate(evidence, tuple("abcd"), tolerance)
    # down-weighted: it moves the mean by much less than one robot in 21 would
    full_pull = np.abs(truth[0] - without.mean) / 21
    assert np.all(np.abs(population.mean - without.mean) < 0.5 * full_pull + 1e-12)


def test_the_conflict_statistic_is_chi_square_under_the_model():
    """Robots drawn from the prior itself: d^2 averages to the directions seen."""
    rng = np.random.default_rng(21)
    p = 4
    prior_covariance = np.diag([1.0, 2.0, 0.5, 1.5]) ** 2
    values = []
    for _ in range(400):
        theta = rng.multivariate_normal(np.zeros(p), prior_covariance)
        design = rng.normal(size=(3, p))  # sees three directions of four
        y = design @ theta + rng.normal(size=3)
        posterior = np.linalg.inv(np.linalg.inv(prior_covariance) + design.T @ design)
        m = posterior @ design.T @ y
        member = conflict("r", m, prior_covariance, posterior)
        values.append((member.distance, member.seen))
    distance, seen = np.array(values).T
    assert np.all(seen <= 3)
    # mean of chi^2 variables with seen dof, within 4 standard errors
    assert abs(distance.mean() - seen.mean()) < 4 * math.sqrt(2 * seen.mean() / len(values))


def test_a_correlated_prior_gives_the_closed_form_posterior_mean():
    rng = np.random.default_rng(2)
    A = rng.normal(size=(6, 3))
    b = rng.normal(size=6)
    sigma = 0.3
    C = np.array([[1.0, 0.5, 0.2], [0.5, 2.0, -0.4], [0.2, -0.4, 0.8]])
    c = np.array([0.1, -0.2, 0.3])

    class Linear:
        unknowns = ParameterRegistry(("p0", "p1", "p2"), ("length",) * 3)

        def residual(self, x):
            return A @ x - b

        def jacobian(self, x, columns=None):
            return A.copy()

    prior = Prior.correlated(("p0", "p1", "p2"), np.arange(3), c, C, sigma)
    problem = PriorProblem(Linear(), prior)
    J = problem.jacobian(np.zeros(3))
    x = np.linalg.lstsq(J, -problem.residual(np.zeros(3)), rcond=None)[0]
    closed = np.linalg.solve(A.T @ A / sigma**2 + np.linalg.inv(C),
                             A.T @ b / sigma**2 + np.linalg.solve(C, c))
    assert np.allclose(x, closed, rtol=1e-10, atol=1e-12)
    assert np.allclose(prior.covariance, C, rtol=1e-12)


# ---------------------------------------------------------------- with calibrations


def _errors(robot, rng, shared, scale, off=False):
    """Shared errors plus the robot's own (normal, std ``scale`` tolerances; ``off``:
    exactly ``scale`` tolerances on every parameter, signs at random)."""
    registry = robot.parameters()
    names = [f"{s}{i}" for i, j in enumerate(robot.joints, 1) for s in perturbed_stems(robot, j)]
    tolerance = np.array([tolerance_of(n, registry.quantity(n), robot) for n in names])
    own = rng.choice([-1.0, 1.0], size=len(names)) if off else rng.normal(size=len(names))
    return {n: float(v) for n, v in zip(names, shared * tolerance + own * tolerance * scale)}


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """Five calibrated robots of one small model (shared errors 2/3 of the tolerance plus
    their own 1/5), and two more measured: one of the model, one whose own errors are
    five times the fleet's spread."""
    root = tmp_path_factory.mktemp("fleet")
    robot = examples.prismatic_rrp()
    rng = np.random.default_rng(4)
    shared = rng.normal(size=16) * 2 / 3
    folders = []
    for k in range(5):
        data = simulate(robot, "tracker_points", out_dir=root / f"data{k}", rows=25,
                        noise=0.02e-3, geometric_errors=_errors(robot, rng, shared, 0.2),
                        seed=40 + k, progress=False)
        out = root / f"robot{k}"
        assert main(["calibrate", str(data.dataset_path), "--no-diagnose", "--no-report",
                     "--quiet", "--out", str(out)]) == 0
        folders.append(out)
    others = {}
    for name, scale, seed in (("member", 0.2, 50), ("stranger", 1.0, 51)):
        others[name] = simulate(robot, "tracker_points", out_dir=root / name, rows=12,
                                noise=0.02e-3,
                                geometric_errors=_errors(robot, rng, shared, scale,
                                                         off=name == "stranger"),
                                seed=seed, progress=False).dataset_path
    # a member measured too briefly for least squares (12 residuals, ~19 unknowns), and
    # its check readings: the same robot, drawn again
    few = simulate(robot, "tracker_points", out_dir=root / "few", rows=4, noise=0.02e-3,
                   geometric_errors=_errors(robot, rng, shared, 0.2), seed=52, progress=False)
    others["few"] = few.dataset_path
    assert main(["simulate", "--truth", str(root / "few" / "truth.yaml"), "--rows", "40",
                 "--seed", "53", "--out", str(root / "few-check"), "--quiet"]) == 0
    others["few-check"] = root / "few-check" / "dataset.yaml"
    return root, folders, others


@pytest.mark.slow
def test_result_folders_carry_the_geometry_posterior(fleet):
    _, folders, _ = fleet
    content = json.loads((folders[0] / "geometry_posterior.json").read_text())
    result = json.loads((folders[0] / "result.json").read_text())
    fitted = content["fitted"]
    covariance = np.array(content["covariance"])
    std = {p["name"]: p["std"] for p in result["parameters_geometric"]}
    assert covariance.shape == (len(fitted), len(fitted))
    # the diagonal is the square of the standard errors result.json gives (file units)
    assert np.allclose(np.sqrt(np.diag(covariance)), [std[n] for n in fitted], rtol=1e-6)
    assert content["prior"]["source"] == "tolerance"
    assert result["prior"]["source"] == "tolerance" and result["prior"]["belongs"] is None


@pytest.mark.slow
def test_prior_verb_learns_and_calibrate_uses_it(fleet, capsys):
    root, folders, others = fleet
    prior_file = root / "fleet.yaml"
    assert main(["prior", *map(str, folders), "--out", str(prior_file)]) == 0
    content = yaml.safe_load(prior_file.read_text())
    assert content["count"] == 5 and content["model"] == "rrp-scara"
    assert content["robots"] == [str(f) for f in folders]
    row = {p["name"]: p for p in content["parameters"]}
    assert all(set(r) >= {"mean", "spread", "seen_by", "unit"} for r in row.values())
    assert max(r["seen_by"] for r in row.values()) == 5
    capsys.readouterr()
    out = root / "member-fit"
    assert main(["calibrate", str(others["member"]), "--no-diagnose", "--no-report",
                 "--loss", "linear", "--prior", str(prior_file), "--out", str(out)]) == 0
    used = json.loads((out / "result.json").read_text())["prior"]
    assert used["source"] == str(prior_file) and used["belongs"] is True
    assert "this robot belongs" in capsys.readouterr().out
    posterior = json.loads((out / "geometry_posterior.json").read_text())
    assert posterior["prior"]["source"] == str(prior_file)


@pytest.mark.slow
def test_a_robot_off_the_model_is_told_and_calibrated_with_the_tolerances(fleet, capsys):
    root, folders, others = fleet
    prior_file = root / "fleet-stranger.yaml"
    assert main(["prior", *map(str, folders), "--out", str(prior_file), "--quiet"]) == 0
    capsys.readouterr()
    out, plain = root / "stranger-fit", root / "stranger-plain"
    assert main(["calibrate", str(others["stranger"]), "--no-diagnose", "--no-report",
                 "--loss", "linear", "--prior", str(prior_file), "--out", str(out)]) == 0
    assert "THIS ROBOT DOES NOT BELONG" in capsys.readouterr().out
    used = json.loads((out / "result.json").read_text())
    assert used["prior"]["source"] == "tolerance" and used["prior"]["belongs"] is False
    assert used["prior"]["conflict"]["distance"] > used["prior"]["conflict"]["threshold"]
    assert main(["calibrate", str(others["stranger"]), "--no-diagnose", "--no-report",
                 "--loss", "linear", "--quiet", "--out", str(plain)]) == 0
    alone = json.loads((plain / "result.json").read_text())
    # calibrated as before: the same estimates as without the fleet prior
    for a, b in zip(used["parameters"], alone["parameters"]):
        assert a["estimate"] == pytest.approx(b["estimate"], rel=1e-6, abs=1e-9)


@pytest.mark.slow
def test_prior_verb_refuses_robots_of_another_model(fleet, tmp_path, capsys):
    root, folders, _ = fleet
    robot = examples.prismatic_rrp()
    other = simulate(robot.with_parameters(robot.parameter_vector() + 1e-3), "tracker_points",
                     out_dir=tmp_path / "data", rows=25, noise=0.02e-3, seed=3,
                     geometric_errors=(0.5e-3, 0.005), progress=False)
    stranger = tmp_path / "other-model"
    assert main(["calibrate", str(other.dataset_path), "--no-diagnose", "--no-report",
                 "--quiet", "--out", str(stranger)]) == 0
    capsys.readouterr()
    out = tmp_path / "p.yaml"
    assert main(["prior", *map(str, folders), str(stranger), "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert str(stranger) in error and "nominal" in error
    assert not out.exists()
    assert main(["prior", str(folders[0]), str(tmp_path), "--out", str(out)]) == 2
    assert "not a calibration result folder" in capsys.readouterr().err


@pytest.mark.slow
def test_calibrate_refuses_a_prior_of_another_model(fleet, tmp_path, capsys):
    root, folders, _ = fleet
    prior_file = tmp_path / "p.yaml"
    assert main(["prior", *map(str, folders), "--out", str(prior_file), "--quiet"]) == 0
    data = simulate(examples.ur_type(), "tracker_points", out_dir=tmp_path / "ur", rows=30,
                    noise=0.02e-3, seed=1, progress=False)
    capsys.readouterr()
    assert main(["calibrate", str(data.dataset_path), "--no-report", "--prior", str(prior_file),
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    # one line: the file, both robots, the first differing value in the file's units
    assert len(err) == 1 and str(prior_file) in err[0]
    assert "does not fit robot 'ur-type'" in err[0]
    assert not (tmp_path / "out").exists()


def test_a_prior_of_another_drawing_names_the_value_in_the_files_units():
    """A robot with the prior's parameters but another nominal value is refused naming the
    parameter and both values in the file's units (mm), not SI."""
    from robocal_casadi.calibration.population_prior import PopulationPrior
    from robocal_casadi.errors import InputError
    robot = examples.industrial_6r()
    registry = robot.parameters()
    names = tuple(registry.names)
    prior = PopulationPrior(robot.name, robot.convention, robot.units, "2026-01-01", ("a",),
                            names, tuple(registry.quantity(n) for n in names),
                            robot.parameter_vector(), np.zeros(len(names)),
                            np.eye(len(names)) * 1e-6, tuple(1 for _ in names))
    values = robot.parameter_vector().copy()
    values[names.index("d1")] += 0.5e-3  # [m]
    other = robot.with_parameters(values)
    with pytest.raises(InputError) as refused:
        prior.check_robot(other, "prior.yaml")
    nominal_mm = 1e3 * robot.parameter_vector()[names.index("d1")]
    assert (f"d1 is {nominal_mm:.9g} mm in the prior, {nominal_mm + 0.5:.9g} mm in robot"
            in str(refused.value))


@pytest.mark.slow
def test_fleet_learns_a_leave_one_out_prior(fleet, capsys):
    pytest.importorskip("distributed")
    root, folders, _ = fleet
    names = [f"r{k}" for k in range(len(folders))]
    (root / "fleet.yaml").write_text("robots:\n" + "".join(
        f"  - {{name: {n}, datasets: [data{k}/dataset.yaml]}}\n" for k, n in enumerate(names))
        + "  - {name: brief, datasets: [few/dataset.yaml]}\n")
    out = root / "fleet-out"
    assert main(["fleet", str(root / "fleet.yaml"), "--out", str(out), "--learn-prior",
                 "--workers", "1", "--no-report", "--no-diagnose", "--loss", "linear"]) == 0
    # the robot measured too briefly for the tolerance prior: refused in the first pass,
    # calibrated with the prior of all the others in the second
    assert not (out / "tolerance-prior" / "brief" / "result.json").is_file()
    brief = json.loads((out / "brief" / "result.json").read_text())["prior"]
    assert brief["belongs"] is True and brief["source"].endswith("brief.yaml")
    everyone = yaml.safe_load((out / "prior.yaml").read_text())
    assert everyone["count"] == len(names)
    summary = json.loads((out / "fleet.json").read_text())
    rows = {row["robot"]: row for row in summary["fleet_prior"]["robots"]}
    assert set(rows) == set(names) | {"brief"}
    for name in names:
        own = yaml.safe_load((out / "priors" / f"{name}.yaml").read_text())
        # leave one out: the robot's own prior never holds the robot itself
        assert own["count"] == len(names) - 1
        assert not any(Path(r).name == name for r in own["robots"])
        used = json.loads((out / name / "result.json").read_text())["prior"]
        expected = str((out / "priors" / f"{name}.yaml").resolve())
        assert used["offered"] == expected
        assert used["source"] == (expected if used["belongs"] else "tolerance")
        assert rows[name]["belongs"] == used["belongs"]
        assert (out / "tolerance-prior" / name / "result.json").is_file()
    assert "What the fleet prior changed" in (out / "fleet.html").read_text()


def test_a_prior_of_other_parameters_names_where_they_part():
    from robocal_casadi.calibration.population_prior import _first_difference
    assert _first_difference(("a1", "d2", "a3"), ("a1", "beta2", "a3")) == \
        "; parameter 2 is 'd2' in the prior, 'beta2' in the robot"
    assert _first_difference(("a1",), ("a1", "a2")) == "; the robot goes on with 'a2'"
    assert _first_difference(("a1", "a2"), ("a1", "a2")) == ""


@pytest.mark.slow
def test_the_fleet_prior_calibrates_a_robot_measured_too_briefly_for_least_squares(
        fleet, capsys):
    root, folders, others = fleet
    prior_file = root / "fleet-few.yaml"
    assert main(["prior", *map(str, folders), "--out", str(prior_file), "--quiet"]) == 0
    capsys.readouterr()
    alone = ["calibrate", str(others["few"]), "--no-diagnose", "--no-report", "--loss",
             "linear", "--validate", str(others["few-check"])]
    assert main([*alone, "--out", str(root / "few-alone")]) == 2
    assert "cannot identify" in capsys.readouterr().err
    assert main([*alone, "--prior", str(prior_file), "--out", str(root / "few-fleet")]) == 0
    result = json.loads((root / "few-fleet" / "result.json").read_text())
    assert result["prior"]["belongs"] is True
    held_out = result["validation"]
    # the population makes up for the missing readings: the robot's own part (a fifth of
    # the tolerance) against the drawing's whole error (two thirds and a fifth) is about
    # 0.3 before the readings add anything; half of the drawing's error is a loose bound
    assert held_out["rms_geometric"] < 0.5 * held_out["rms_nominal"]
    # what remains is the few readings' estimation error, not a model that lacks something
    left = result["unexplained"]
    assert not left["is_noise"] and left["estimation"]["explains_the_rest"]


def test_what_the_fleet_prior_moved_is_none_when_nothing_moved():
    """A robot calibrated with the tolerance prior in both passes moved no estimate: none
    is named (not the first parameter at zero standard errors); otherwise the estimate
    that moved most, in the first pass's standard errors."""
    from robocal_casadi.fleet.learning import _largest_move
    before = {"parameters": [{"name": "a1", "estimate": 1.0, "std": 0.1},
                             {"name": "d2", "estimate": 2.0, "std": 0.5}]}
    assert _largest_move(before, before) == {"moved": None, "moved_by_std": None}
    after = {"parameters": [{"name": "a1", "estimate": 1.05, "std": 0.1},
                            {"name": "d2", "estimate": 3.0, "std": 0.5}]}
    moved = _largest_move(before, after)
    assert moved["moved"] == "d2" and math.isclose(moved["moved_by_std"], 2.0)


@pytest.mark.parametrize("change,key,words", [
    (lambda c: c["parameters"][3].update(unit="furlong"), "parameters[3].unit",
     "expected the file's units (mm or deg), got 'furlong'"),
    (lambda c: c["parameters"][3].update(mean=float("nan")), "parameters[3].mean",
     "expected a finite number"),
    (lambda c: c["parameters"][3].update(spread=float("inf")), "parameters[3].spread",
     "expected a finite number"),
    (lambda c: c["parameters"][3].update(seen_by=-1), "parameters[3].seen_by",
     "count of robots"),
    (lambda c: c["parameters"][3].update(fitted_by=-2), "parameters[3].fitted_by",
     "count of robots"),
    (lambda c: c["parameters"][2].update(name=c["parameters"][3]["name"]), "parameters",
     "listed twice"),
])
def test_a_broken_prior_file_is_refused_naming_the_key(tmp_path, change, key, words):
    """Every row of PRIOR.yaml is checked on reading: a unit not the file's, a number that
    is not finite, a negative count, a name given twice: InputError naming file and key
    (the calibration would otherwise diverge on a NaN or mistake degrees for radians)."""
    from robocal_casadi.calibration.population_prior import (
        PopulationPrior,
        load_prior,
        save_prior,
    )
    from robocal_casadi.errors import InputError
    robot = examples.industrial_6r()
    registry = robot.parameters()
    names = tuple(registry.names)
    path = tmp_path / "prior.yaml"
    save_prior(PopulationPrior(robot.name, robot.convention, robot.units, "2026-01-01",
                               ("a", "b"), names, tuple(registry.quantity(n) for n in names),
                               robot.parameter_vector(), np.zeros(len(names)),
                               np.eye(len(names)) * 1e-8, tuple(2 for _ in names),
                               fitted_by=tuple(2 for _ in names)), path)
    load_prior(path)  # as written: read back
    content = yaml.safe_load(path.read_text())
    change(content)
    path.write_text(yaml.safe_dump(content, sort_keys=False))
    with pytest.raises(InputError) as refused:
        load_prior(path)
    assert f"{path}: {key}: " in str(refused.value) and words in str(refused.value)


def test_a_robot_whose_data_see_nothing_of_the_population_is_not_said_to_belong():
    from robocal_casadi.calibration.population import Membership
    from robocal_casadi.calibration.population_prior import PriorUse
    unseen = PriorUse("p.yaml", "p.yaml", True, Membership("r", 0.0, 0, math.inf, 1.0))
    assert "cannot be judged" in unseen.sentence and "belongs (" not in unseen.sentence
    seen = PriorUse("p.yaml", "p.yaml", True, Membership("r", 3.0, 5, 20.5, 1.0))
    assert "this robot belongs (prior-data conflict 3 over 5 directions" in seen.sentence


@pytest.fixture(scope="module")
def posterior_file_content(tmp_path_factory):
    """A geometry_posterior.json's content from one quick tracker calibration."""
    from robocal_casadi.calibration import calibrate
    from robocal_casadi.calibration.population_prior import posterior_content
    data = simulate(examples.industrial_6r(), "tracker_points",
                    out_dir=tmp_path_factory.mktemp("posterior") / "sim", rows=30,
                    noise=0.02e-3, seed=5, progress=False)
    return json.loads(json.dumps(posterior_content(calibrate([data.load()], diagnose=False))))


@pytest.mark.parametrize("change,key,words", [
    (lambda c: c["estimate"].__setitem__(0, float("nan")), "estimate", "finite"),
    (lambda c: c.update(estimate=c["estimate"][:-1]), "estimate", "numbers, got"),
    (lambda c: c.update(covariance=c["covariance"][:-1]), "covariance", "numbers, got"),
    (lambda c: c["covariance"][0].__setitem__(0, -1.0), "covariance", "semi-definite"),
    (lambda c: c["fitted"].__setitem__(0, "zz9"), "fitted", "'zz9' is not among"),
    (lambda c: c["parameters"][0].update(unit="furlong"), "parameters[0].unit", "furlong"),
    (lambda c: c["prior"].update(centre=c["prior"]["centre"][:-1]), "prior.centre",
     "numbers, got"),
    (lambda c: c["prior"]["covariance"][0].__setitem__(0, 0.0), "prior.covariance",
     "positive definite"),
])
def test_a_broken_posterior_file_is_refused_naming_the_key(posterior_file_content, change,
                                                           key, words):
    """`robocal prior` reads every robot's geometry_posterior.json strictly: a NaN, a list
    of the wrong size, a matrix that is no covariance, an unknown name, a unit not the
    file's end in InputError naming file and key (not a traceback, not a prior with NaN)."""
    import copy

    from robocal_casadi.calibration.population_prior import calibration_from
    from robocal_casadi.errors import InputError
    calibration_from(posterior_file_content, Path("robot"))  # as written: read
    content = copy.deepcopy(posterior_file_content)
    change(content)
    with pytest.raises(InputError) as refused:
        calibration_from(content, Path("robot"))
    assert f"{Path('robot') / 'geometry_posterior.json'}: {key}: " in str(refused.value)
    assert words in str(refused.value)
