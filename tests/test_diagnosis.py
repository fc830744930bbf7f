"""Diagnosis on simulated truths: it names the effect the data hold, and nothing on clean
data. The data come from ``robocal_casadi.simulate`` (pinocchio gravity, its own
kinematics of the true robot), never from the estimator's effect code."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from robocal_casadi.calibration import Problem, calibrate, diagnosis, models_for, solve
from robocal_casadi.effects import EFFECTS
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import ROBOTS
from robocal_casadi.results import Decision

NOISE = 1e-5  # [m] per tracker coordinate
FLOOR = NOISE * np.sqrt(3)  # expected RMS of the 3-D point error from noise alone


def geometric_errors(robot, seed: int) -> dict[str, float]:
    """Fixed true errors, so the fit and the validation data share one true robot."""
    rng = np.random.default_rng(1000 + seed)
    errors = {}
    for i in range(1, robot.dof + 1):
        for stem, std in (("theta", 5e-4), ("d", 5e-4), ("a", 5e-4), ("alpha", 5e-4)):
            errors[f"{stem}{i}"] = float(rng.normal(0.0, std))
    return errors


def tracker_pair(tmp_path, robot, *, effects=None, payload=None, seed=0, rows=300,
                 validation_rows=150, thermal=False):
    """Fit and validation tracker datasets of one true robot."""
    errors = geometric_errors(robot, seed)
    common = dict(noise=NOISE, geometric_errors=errors, effects=effects, payload=payload,
                  progress=False)
    if thermal:
        common["temperature"] = (18.0, 28.0)
    fit = simulate(robot, "tracker_points", out_dir=tmp_path / "fit", rows=rows, seed=seed,
                   **common)
    validation = simulate(robot, "tracker_points", out_dir=tmp_path / "validation",
                          rows=validation_rows, seed=seed + 500, **common)
    return fit.load(), validation.load()


def only_finding(result):
    assert len(result.effects) == 1, [(e.name, e.joints) for e in result.effects]
    return result.effects[0]


def check_close_to_noise(result):
    assert result.validation.rms_final <= 1.1 * FLOOR, result
    assert result.fit.rms_final <= 1.1 * FLOOR, result


# ----------------------------------------------------------------------------- tracker


def test_compliance_on_joints_2_and_3_with_payload(tmp_path):
    robot = ROBOTS["industrial_6r"]()
    truth = {2: 1.5e-6, 3: 2.5e-6}
    fit, validation = tracker_pair(tmp_path, robot, effects={"joint_compliance": truth},
                                   payload=(0.0, 10.0))
    result = calibrate([fit], [validation])
    finding = only_finding(result)
    assert finding.name == "joint_compliance" and finding.joints == (2, 3)
    for j, c in truth.items():
        assert finding.parameters[f"c{j}"] == pytest.approx(c, rel=0.05)
    assert finding.unit == "rad/Nm"
    assert finding.evidence["bic_drop"] > 10
    assert finding.evidence["cv_rms_after"] < finding.evidence["cv_rms_before"]
    assert "joints 2 and 3 deflect under gravity" in finding.summary
    check_close_to_noise(result)


def test_periodic_error_on_one_joint(tmp_path):
    robot = ROBOTS["industrial_6r"]()
    truth = (2e-4, 1e-4, 0.0, 8e-5)
    fit, validation = tracker_pair(tmp_path, robot, effects={"joint_cyclic": {4: truth}})
    result = calibrate([fit], [validation])
    finding = only_finding(result)
    assert finding.name == "joint_cyclic" and finding.joints == (4,)
    first = np.hypot(finding.parameters["a1_4"], finding.parameters["b1_4"])
    assert first == pytest.approx(np.hypot(truth[0], truth[1]), rel=0.1)
    check_close_to_noise(result)


def test_gear_ratio_error(tmp_path):
    robot = ROBOTS["industrial_6r"]()
    fit, validation = tracker_pair(tmp_path, robot, effects={"joint_scale": {3: 3e-4}})
    result = calibrate([fit], [validation])
    finding = only_finding(result)
    assert finding.name == "joint_scale" and finding.joints == (3,)
    assert finding.parameters["s3"] == pytest.approx(3e-4, rel=0.05)
    check_close_to_noise(result)


def test_thermal_growth_with_a_temperature_column(tmp_path):
    robot = ROBOTS["industrial_6r"]()
    fit, validation = tracker_pair(tmp_path, robot, effects={"thermal_drift": 1.2e-5},
                                   thermal=True)
    result = calibrate([fit], [validation])
    finding = only_finding(result)
    assert finding.name == "thermal_drift" and finding.joints == ()
    assert finding.parameters["k_T"] == pytest.approx(1.2e-5, rel=0.1)
    assert finding.unit == "1/K"
    check_close_to_noise(result)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_clean_data_add_nothing(tmp_path, seed):
    robot = ROBOTS["industrial_6r"]()
    fit, _ = tracker_pair(tmp_path, robot, seed=seed, payload=(0.0, 10.0), thermal=True,
                          validation_rows=1)
    result = calibrate([fit])
    assert result.effects == ()
    assert result.fit.rms_final == result.fit.rms_geometric
    # every candidate was tested and none was supported (each effect offered on this
    # robot's drives: hysteresis is looked for on joints without gears, this arm has none)
    decisions = {entry.decision for entry in result.diagnosis}
    assert "added" not in decisions
    offered = {name for name, cls in EFFECTS.items()
               if cls.candidates(robot, {"temperature": [20.0, 21.0], "payload": [0.0, 1.0]})}
    assert "hysteresis" not in offered
    assert {entry.effect for entry in result.diagnosis} == offered


@pytest.mark.slow
def test_compliance_without_masses_uses_lumped_terms(tmp_path):
    """The simulator knows the masses; the robot handed to calibration does not."""
    robot = ROBOTS["industrial_6r"]()
    fit, validation = tracker_pair(tmp_path, robot, rows=400,
                                   effects={"joint_compliance": {2: 1.5e-6, 3: 2.5e-6}},
                                   payload=(0.0, 10.0))
    bare = replace(robot, joints=tuple(replace(j, mass=None, com=None) for j in robot.joints))
    fit, validation = (replace(d, robot=bare) for d in (fit, validation))
    result = calibrate([fit], [validation])
    found = {e.name: e for e in result.effects}
    assert set(found) == {"joint_compliance"}
    assert set(found["joint_compliance"].joints) == {2, 3}
    # the payload term carries c_j itself
    assert found["joint_compliance"].parameters["c2"] == pytest.approx(1.5e-6, rel=0.15)
    check_close_to_noise(result)


# ----------------------------------------------------------------------------- artifact


@pytest.mark.slow
def test_compliance_on_artifact_touches_folds_whole_placements(tmp_path):
    robot = ROBOTS["industrial_6r"]()
    data = simulate(robot, "artifact_touches", out_dir=tmp_path / "touches", rows=12,
                    noise=1e-5, geometric_errors=geometric_errors(robot, 0), touches=6,
                    effects={"joint_compliance": {2: 2e-6, 3: 3e-6}}, payload=(0.0, 10.0),
                    seed=3, progress=False).load()
    problem = Problem(robot, models_for([data]))
    groups = diagnosis.residual_groups(problem.models[0])
    assert set(groups) == set(int(p) for p in data.pose)  # one group per placement
    result = calibrate([data])
    finding = only_finding(result)
    assert finding.name == "joint_compliance" and set(finding.joints) == {2, 3}
    assert finding.parameters["c3"] == pytest.approx(3e-6, rel=0.15)


# ----------------------------------------------------------------------------- the checks


def _geometric(problem):
    """Nominal fit, identifiability and geometric fit, as ``calibrate`` does them."""
    from robocal_casadi.calibration import analyse_identifiability

    x0 = problem.initial()
    nominal = solve(problem, x0, problem.mask("placement"))
    ident = analyse_identifiability(problem, nominal.x)
    free = problem.mask("placement")
    free[problem.unknowns.indices(ident.identifiable)] = True
    return solve(problem, nominal.x, free), ident


def test_effects_the_geometry_absorbs_are_no_finding(tmp_path):
    """Joint 5 held at one reading: a scale or periodic error of it is a theta5 offset."""
    robot = ROBOTS["industrial_6r"]()
    joints = list(robot.joints)
    joints[4] = replace(joints[4], limits=(0.7, 0.7 + 1e-9))
    robot = replace(robot, joints=tuple(joints))
    data = simulate(robot, "tracker_points", out_dir=tmp_path / "fixed5", rows=200,
                    noise=NOISE, geometric_errors=geometric_errors(robot, 0), seed=4,
                    progress=False).load()
    problem = Problem(robot, models_for([data]))
    geometric, ident = _geometric(problem)
    outcome = diagnosis.run(problem, geometric, ident, progress=False)
    assert outcome.added == ()
    by_candidate = {(t.effect, t.joints): t for t in outcome.tested if t.round == 1}
    assert by_candidate[("joint_scale", (5,))].decision == "absorbed by the geometry"
    assert by_candidate[("joint_cyclic", (5,))].decision == "absorbed by the geometry"
    assert by_candidate[("joint_cyclic", (5,))].held == ("a1_5", "b1_5", "a2_5", "b2_5")
    # joints whose axis is vertical carry no gravity torque: the data cannot see it
    assert by_candidate[("joint_compliance", (1,))].decision == "no effect on these data"


def test_candidate_rows_read_as_mappings_and_diagnosis_is_frozen(tmp_path):
    robot = ROBOTS["industrial_6r"]()
    fit, _ = tracker_pair(tmp_path, robot, rows=120, validation_rows=1,
                          effects={"joint_scale": {2: 5e-4}})
    problem = Problem(robot, models_for([fit]))
    geometric, ident = _geometric(problem)
    outcome = diagnosis.run(problem, geometric, ident, progress=False)
    assert [f.name for f in outcome.added] == ["joint_scale"]
    row = outcome.tested[0]
    numbers = row.as_dict()
    assert numbers["effect"] == row.effect and set(numbers) >= {"bic_drop", "decision"}
    # the decision is typed; what the report tabulates is the numbers and words
    assert "outcome" not in numbers
    added = [t for t in outcome.tested if t.outcome is Decision.ADDED]
    assert [(t.effect, t.joints) for t in added] == [("joint_scale", (2,))]
    assert all((t.outcome is Decision.ADDED) == (t.decision == "added") for t in outcome.tested)
    with pytest.raises(AttributeError):
        outcome.rounds = 0  # type: ignore[misc]
    assert "joint_scale" in repr(outcome)
    assert outcome.problem.effects[0].name == "joint_scale"
    assert outcome.x_final[outcome.problem.unknowns.index("s2")] == pytest.approx(5e-4, rel=0.1)
    # tracker residuals fold by data row
    groups = diagnosis.residual_groups(problem.models[0])
    np.testing.assert_array_equal(groups, np.repeat(np.arange(fit.rows), 3))


def test_two_effects_each_credited_with_its_own_share(tmp_path):
    robot = ROBOTS["industrial_6r"]()
    fit, validation = tracker_pair(
        tmp_path, robot, payload=(0.0, 10.0),
        effects={"joint_compliance": {2: 1.5e-6}, "joint_scale": {4: 4e-4}})
    result = calibrate([fit], [validation])
    found = {e.name: e for e in result.effects}
    assert set(found) == {"joint_compliance", "joint_scale"}
    assert found["joint_compliance"].joints == (2,) and found["joint_scale"].joints == (4,)
    for finding in found.values():
        # each left out of the final model in turn: the final model is the same "after"
        assert finding.evidence["cv_rms_after"] < finding.evidence["cv_rms_before"]
        assert finding.evidence["bic_drop"] > 10
    after = {f.evidence["cv_rms_after"] for f in found.values()}
    assert len(after) == 1
    check_close_to_noise(result)


# ----------------------------------------------------------------------------- bar


@pytest.mark.parametrize("effect,joint,truth", [
    ("joint_cyclic", 3, {"a1_3": 4e-4, "b1_3": 2e-4, "a2_3": 1e-4, "b2_3": 5e-5}),
    ("joint_scale", 2, {"s2": 1e-3}),
])
def test_undeclared_effect_in_cross_bar_data(tmp_path, effect, joint, truth):
    """Bar data carry no absolute position, yet a joint error still shows in the lengths."""
    from robocal_casadi.calibration import evaluate
    from robocal_casadi.effects import make_effect

    robot = ROBOTS["industrial_6r"]()
    values = tuple(truth.values())
    spec = {joint: values if len(values) > 1 else values[0]}
    common = dict(noise=NOISE, geometric_errors=geometric_errors(robot, 0),
                  effects={effect: spec}, mounted_error=0.0, progress=False)
    fit = simulate(robot, "cross_bar", out_dir=tmp_path / "fit", rows=60, seed=1, **common)
    held_out = simulate(robot, "cross_bar", out_dir=tmp_path / "val", rows=60, seed=2, **common)
    result = calibrate([fit.load()], [held_out.load()])
    finding = only_finding(result)
    assert finding.name == effect and finding.joints == (joint,)
    for name, value in truth.items():
        if abs(value) >= 1e-4:
            assert finding.parameters[name] == pytest.approx(value, rel=0.1, abs=2e-5)
    # The noise floor: the true robot with the true effect on the held-out data.
    validation = held_out.load()
    true_effect = make_effect(effect, (joint,), robot)
    floor_problem, x = evaluate(held_out.truth.robot, [validation], (true_effect,),
                                {**truth, "probe_x": 0.0, "probe_y": 0.0,
                                 "probe_z": float(validation.probe[2])})
    floor = floor_problem.rms(x)
    fitted = len(result.identifiability.identifiable) + len(finding.parameters)
    measured = sum(len(r.errors_final) for r in result.residuals)
    assert result.validation.rms_final <= floor * math.sqrt(
        1.0 + prediction_allowance(fitted, measured, floor_problem.size))
    assert result.validation.rms_geometric > 3 * floor


def prediction_allowance(p: int, m: int, n: int, k: float = 3.0) -> float:
    """How far a model fitted with ``p`` unknowns to ``m`` residuals may exceed the truth's
    mean square error on ``n`` held-out residuals, relative to that error, at ``k``
    standard deviations. The estimate's error adds sigma^2 p/m on average (the spread of
    a least-squares estimate, sqrt(1 + p/m) in RMS), itself a chi-square with p degrees
    of freedom (relative spread sqrt(2/p)); its product with the held-out noise averages
    zero with a spread of 2 sigma^2 sqrt(p/(m n)); and sigma^2 is known from the truth's
    own held-out RMS only to a relative sqrt(2/n)."""
    estimation = p / m * (1.0 + k * math.sqrt(2.0 / p))
    cross = k * 2.0 * math.sqrt(p / (m * n))
    return (estimation + cross) * (1.0 + k * math.sqrt(2.0 / n))


def test_no_thermal_finding_when_the_held_out_data_have_no_temperature(tmp_path):
    """A model with thermal drift could not be applied to validation data without the
    column: diagnosis does not offer it, and the run completes."""
    robot = ROBOTS["industrial_6r"]()
    fit, validation = tracker_pair(tmp_path, robot, effects={"thermal_drift": 2e-5},
                                   thermal=True)
    stripped = replace(validation, extras={})
    result = calibrate([fit], [stripped])
    assert all(e.name != "thermal_drift" for e in result.effects)
    assert result.validation is not None
