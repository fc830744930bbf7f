"""The calibration engine over many robots, kinds, set-ups and effects (simulated truth).

Every case simulates data from a known true robot (``robocal_casadi.simulate``, its own
forward pass), calibrates, and checks against that truth:

* the parameters the data identify are recovered within three standard errors (the
  truth perturbs only parameters a first calibration names identifiable, so it is
  exactly representable, as in ``test_calibration.py``);
* the held-out RMS, on data from another placement of the instrument, is within 10% of
  the noise floor (the true robot and instrument on the same held-out data);
* the reasons given for what is not identifiable read right for the kind of data;
* diagnosis names the effect the data hold and adds nothing on clean data.

A separate check compares the two ways the engine builds its Jacobian (row by row in
compiled code for separable data, the chain rule for the rest) with each other and
with finite differences, on a problem that carries effects and two kinds of data.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.special import ndtri

from robocal_casadi.calibration import Problem, calibrate, evaluate, models_for
from robocal_casadi.common.units import Units
from robocal_casadi.effects import make_effect
from robocal_casadi.instruments.model import MeasurementModel
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.instruments.tracker.model import TrackerModel
from robocal_casadi.model.examples import industrial_6r, panda_7dof, prismatic_rrp, ur_type
from robocal_casadi.model.robot import Frame

NOISE = 10e-6  # [m]
ERRORS = (0.3e-3, 0.3e-3)  # [m], [rad]
SCRATCH_ROWS = {"tracker_points": 150, "cross_bar": 60, "artifact_touches": 16,
                "sphere_laser": 300}


# ----------------------------------------------------------------------------- robots


def metre_radian_6r():
    """The 6R arm with its file in m/rad instead of mm/deg (same geometry in SI)."""
    return replace(industrial_6r(), units=Units("m", "rad"))


def turned_base_6r():
    """The 6R arm on a base turned 180 deg about z (as a real UR10 file declares it)."""
    return replace(industrial_6r(), base=Frame((0.0, 0.0, 0.0), (0.0, 0.0, np.pi)),
                   has_base=True)


def massless_6r():
    """The 6R arm with no masses in its file (compliance must use lumped terms)."""
    robot = industrial_6r()
    return replace(robot, joints=tuple(replace(j, mass=None, com=None) for j in robot.joints),
                   has_gravity=False)


def five_axis():
    """A 5-axis arm: the 6R arm without its last joint."""
    robot = industrial_6r()
    return replace(robot, name="five-axis", joints=robot.joints[:5])


# ----------------------------------------------------------------------------- helpers


def true_mounted(truth) -> dict[str, float]:
    """The true instrument on the flange by mounted parameter name [m, unit vector]."""
    out = {}
    for key, stem in (("target", "target"), ("probe", "probe"), ("laser_origin", "laser")):
        if key in truth.mounted:
            out.update({f"{stem}_{a}": float(v) for a, v in zip("xyz", truth.mounted[key])})
    if "laser_direction" in truth.mounted:
        out.update({f"laser_n{a}": float(v)
                    for a, v in zip("xyz", truth.mounted["laser_direction"])})
    return out


def identifiable_truth(robot, kinds, tmp_path, seed, **options) -> dict[str, float]:
    """Random true errors on the parameters data of ``kinds`` identify (together)."""
    scratch = [simulate(robot, kind, out_dir=tmp_path / f"scratch-{k}", rows=SCRATCH_ROWS[kind],
                        noise=NOISE, geometric_errors=ERRORS, seed=seed + 100 + k,
                        mounted_error=0.0, progress=False, **options).load()
               for k, kind in enumerate(kinds)]
    registry = robot.parameters()
    names = [n for n in calibrate(scratch, diagnose=False).identifiability.identifiable
             if n in registry]
    rng = np.random.default_rng(seed)
    return {n: float(rng.normal(0, ERRORS[0] if registry.quantity(n) == "length" else ERRORS[1]))
            for n in names}


def check_against_truth(result, truth_robot, robot) -> int:
    """Every identified parameter within ``z`` std of the truth; the rest left nominal.

    ``z`` holds the whole set of k identified parameters to a false-alarm rate of 1e-3
    (Bonferroni: each within its two-sided 1 - 1e-3 / k quantile, about 4 std for 20
    parameters): a fixed 3 std fails one data set in three or four by chance alone when
    twenty estimates are judged at once."""
    truth = truth_robot.parameter_vector()
    registry = robot.parameters()
    identified = [e for e in result.parameters if e.identifiable]
    z = float(ndtri(1.0 - 0.5e-3 / max(len(identified), 1)))
    checked = 0
    for entry in result.parameters:
        if not entry.identifiable:
            assert entry.estimate == entry.nominal, entry.name
            continue
        true_value = truth[registry.index(entry.name)]
        assert abs(entry.estimate - true_value) <= z * entry.std, (
            f"{entry.name}: estimate {entry.estimate!r}, truth {true_value!r}, "
            f"std {entry.std!r}")
        checked += 1
    return checked


def noise_floor(held_out) -> float:
    """RMS of the true robot and instrument on the held-out data, placement fitted [m]."""
    problem, x = evaluate(held_out.truth.robot, [held_out.load()], (),
                          true_mounted(held_out.truth))
    return problem.rms(x)


# ----------------------------------------------------------------------------- two paths


class ChainRuleTracker(TrackerModel):
    """The tracker model with its row-by-row form switched off: the chain-rule path."""

    row_residual = MeasurementModel.row_residual


def test_separable_and_chain_rule_jacobians_agree_with_finite_differences(tmp_path):
    robot = industrial_6r()
    sim = simulate(robot, "tracker_points", out_dir=tmp_path / "t", rows=25, noise=NOISE,
                   geometric_errors=ERRORS, seed=7, payload=(0.0, 15.0),
                   payload_com=(0.01, 0.02, 0.05), temperature=(18.0, 26.0), progress=False)
    bar = simulate(robot, "cross_bar", out_dir=tmp_path / "b", rows=4, noise=NOISE,
                   geometric_errors=ERRORS, seed=8, temperature=(20.0, 22.0),
                   progress=False).load()
    tracker = sim.load()
    extras = {k: np.asarray(v, float) for k, v in tracker.extras.items()}
    effects = [make_effect("joint_compliance", (2, 3), robot, extras),
               make_effect("joint_cyclic", (1,), robot, extras),
               make_effect("thermal_drift", (), robot, extras)]
    fast_models = models_for([tracker])
    assert type(fast_models[0]) is TrackerModel
    fast = Problem(robot, fast_models, effects)
    # the same placement frame as the fast problem's
    slow = Problem(robot, [ChainRuleTracker(tracker, fast_models[0].label,
                                            fast.models[0].R0)], effects)
    assert fast._separable(fast.models[0]) is not None
    assert slow._separable(slow.models[0]) is None

    rng = np.random.default_rng(0)
    x = fast.initial()
    x[fast.slices["effects"]] = rng.normal(0, 1e-5, fast.slices["effects"].stop
                                           - fast.slices["effects"].start)
    x[fast.slices["robot"]] += rng.normal(0, 1e-4, fast.slices["robot"].stop)
    assert np.allclose(fast.residual(x), slow.residual(x), atol=1e-13, rtol=0)
    J_fast, J_slow = fast.jacobian(x), slow.jacobian(x)
    assert np.allclose(J_fast, J_slow, atol=1e-11, rtol=1e-9)
    columns = np.array([0, 5, 17, fast.slices["effects"].start + 1,
                        fast.slices["effects"].stop - 1, fast.slices["mounted"].start,
                        len(x) - 1])
    assert np.allclose(fast.jacobian(x, columns), J_fast[:, columns], atol=1e-14, rtol=0)
    # Central differences (step 1e-6 in SI; the residual is smooth).
    for i in range(len(x)):
        step = np.zeros(len(x))
        step[i] = 1e-6
        fd = (fast.residual(x + step) - fast.residual(x - step)) / 2e-6
        assert np.allclose(J_fast[:, i], fd, atol=1e-7 * max(1.0, np.abs(fd).max())), \
            fast.unknowns.names[i]

    # A separable model beside a chain-rule one in one problem: blocks stay in place.
    mixed = Problem(robot, models_for([tracker, bar]), effects)
    x = mixed.initial()
    x[mixed.slices["effects"]] = 1e-5
    J = mixed.jacobian(x)
    for i in range(len(x)):
        step = np.zeros(len(x))
        step[i] = 1e-6
        fd = (mixed.residual(x + step) - mixed.residual(x - step)) / 2e-6
        assert np.allclose(J[:, i], fd, atol=1e-7 * max(1.0, np.abs(fd).max())), \
            mixed.unknowns.names[i]


def test_compiled_code_does_not_depend_on_the_data(tmp_path):
    """Numbers fixed from the data (the tracker's reference rotation, the thermal
    reference temperature) reach the row functions as inputs: two datasets of one robot
    and effect set generate the same code, so compiled code is built once for both."""
    from robocal_casadi.common.codegen import generated_source

    robot = industrial_6r()
    sources, rotations = [], []
    for k, (low, high) in enumerate(((15.0, 20.0), (24.0, 31.0))):
        data = simulate(robot, "tracker_points", out_dir=tmp_path / f"t{k}", rows=12,
                        noise=NOISE, geometric_errors=ERRORS, seed=40 + k,
                        temperature=(low, high), progress=False).load()
        extras = {"temperature": np.asarray(data.extras["temperature"], float)}
        problem = Problem(robot, models_for([data]),
                          [make_effect("thermal_drift", (), robot, extras)])
        separable = problem._separable(problem.models[0])
        assert separable is not None
        sources.append(generated_source(separable.jacobian.function))
        rotations.append(problem.models[0].R0)
        assert problem.effects[0].constants() == (float(np.mean(extras["temperature"])),)
    assert not np.allclose(rotations[0], rotations[1])  # the data did differ
    assert sources[0] == sources[1]


# ----------------------------------------------------------------------------- geometry

# (name, robot, [(kind, rows, options)] fitted together, held-out (kind, rows), noise [m]).
# Held-out data come from another placement of the instrument (another seed).
GEOMETRY = [
    ("ur-tracker", ur_type, [("tracker_points", 150, {})], ("tracker_points", 120), NOISE),
    ("scara-tracker", prismatic_rrp, [("tracker_points", 150, {})], ("tracker_points", 120),
     NOISE),
    ("turned-base-tracker", turned_base_6r, [("tracker_points", 150, {})],
     ("tracker_points", 120), NOISE),
    ("tracker-plus-bar", industrial_6r, [("tracker_points", 120, {}), ("cross_bar", 30, {})],
     ("tracker_points", 120), NOISE),
    ("two-tracker-placements", industrial_6r,
     [("tracker_points", 80, {}), ("tracker_points", 80, {})], ("tracker_points", 120), NOISE),
    pytest.param("five-axis-bar", five_axis, [("cross_bar", 80, {})], ("cross_bar", 40), NOISE,
                 marks=pytest.mark.slow),
    pytest.param("metre-radian-bar", metre_radian_6r, [("cross_bar", 160, {})],
                 ("cross_bar", 40), NOISE, marks=pytest.mark.slow),
    pytest.param("scara-sockets", prismatic_rrp, [("artifact_touches", 10, {})],
                 ("artifact_touches", 10), NOISE, marks=pytest.mark.slow),
    pytest.param("four-sockets", industrial_6r, [("artifact_touches", 24, {"sockets": 4})],
                 ("artifact_touches", 12), NOISE, marks=pytest.mark.slow),
    pytest.param("laser-plus-tracker", ur_type,
                 [("tracker_points", 100, {}), ("sphere_laser", 200, {})], ("sphere_laser", 200),
                 NOISE, marks=pytest.mark.slow),
    pytest.param("tracker-1um", industrial_6r, [("tracker_points", 150, {})],
                 ("tracker_points", 120), 1e-6, marks=pytest.mark.slow),
    pytest.param("bar-0.1mm", industrial_6r, [("cross_bar", 80, {})], ("cross_bar", 40), 1e-4,
                 marks=pytest.mark.slow),
    pytest.param("tracker-compiled", industrial_6r, [("tracker_points", 2500, {})],
                 ("tracker_points", 300), NOISE, marks=pytest.mark.slow),
]


def _id(case) -> str:
    return (case.values if hasattr(case, "values") else case)[0]


@pytest.mark.parametrize("name,make_robot,parts,held_out,noise", GEOMETRY,
                         ids=[_id(c) for c in GEOMETRY])
def test_geometry_recovered_and_held_out_at_the_noise_floor(name, make_robot, parts, held_out,
                                                             noise, tmp_path):
    robot = make_robot()
    kinds = sorted({kind for kind, _, _ in parts})
    errors = identifiable_truth(robot, kinds, tmp_path, seed=3)
    fits = [simulate(robot, kind, out_dir=tmp_path / f"fit{k}", rows=rows, noise=noise,
                     geometric_errors=errors, seed=10 + k, mounted_error=0.0, progress=False,
                     **options)
            for k, (kind, rows, options) in enumerate(parts)]
    kind, rows = held_out
    val = simulate(robot, kind, out_dir=tmp_path / "val", rows=rows, noise=noise,
                   geometric_errors=errors, seed=99, mounted_error=0.0, progress=False)
    result = calibrate([f.load() for f in fits], [val.load()], diagnose=False)

    checked = check_against_truth(result, fits[0].truth.robot, robot)
    assert checked == len([n for n in result.identifiability.identifiable
                           if n in robot.parameters()])
    assert checked >= 6
    floor = noise_floor(val)
    assert result.validation.rms_geometric <= 1.10 * floor, (result.validation, floor)
    assert result.validation.rms_nominal > 3 * floor  # the errors were worth calibrating


# ----------------------------------------------------------------------------- reasons


@pytest.mark.parametrize("kind,expected", [
    ("tracker_points", "instrument frame"),
    ("cross_bar", "no absolute position"),
    ("artifact_touches", "socket positions"),
    ("sphere_laser", "sphere centre"),
])
def test_reasons_read_right_for_the_kind(kind, expected, tmp_path):
    """The base is never identifiable without an absolute reference; the reason names
    what takes its place for this kind of data; the tool never enters point data."""
    robot = turned_base_6r()  # declares a base frame
    rows = {"tracker_points": 60, "cross_bar": 20, "artifact_touches": 8,
            "sphere_laser": 150}[kind]
    data = simulate(robot, kind, out_dir=tmp_path / kind, rows=rows, noise=NOISE,
                    geometric_errors=ERRORS, seed=5, progress=False).load()
    ident = calibrate([data], diagnose=False).identifiability
    for name in ("base_x", "base_y", "base_z", "base_rz"):
        assert name not in ident.identifiable
        assert expected in ident.unidentifiable[name], (name, ident.unidentifiable[name])
    assert "tool_x" not in ident.identifiable
    assert "changes no residual" in ident.unidentifiable["tool_x"]
    # Combinations name parameters that were identified.
    for relation in ident.combinations:
        named = [term.split("*")[1] for term in relation.split("~")[1].split()
                 if "*" in term]
        assert named and set(named) <= set(ident.identifiable), relation


# ----------------------------------------------------------------------------- diagnosis

DIAGNOSIS_NOISE = 10e-6  # [m] per tracker coordinate
FLOOR = DIAGNOSIS_NOISE * np.sqrt(3)  # RMS of the 3-D point error from noise alone


def _errors(robot, seed: int) -> dict[str, float]:
    """Fixed true errors on every DH parameter, shared by fit and held-out data."""
    rng = np.random.default_rng(1000 + seed)
    return {f"{stem}{i}": float(rng.normal(0.0, 5e-4)) for i in range(1, robot.dof + 1)
            for stem in ("theta", "d", "a", "alpha")}


# (name, robot, effects, expected (effect, joints) or None, simulation options)
DIAGNOSIS = [
    ("clean-ur", ur_type, None, None, {"payload": (0.0, 10.0), "temperature": (18.0, 26.0)}),
    ("clean-scara", prismatic_rrp, None, None, {}),
    ("compliance-payload-com", ur_type, {"joint_compliance": {2: 3e-6}},
     ("joint_compliance", (2,)), {"payload": (0.0, 10.0), "payload_com": (0.0, 0.05, 0.1)}),
    ("thermal-time-column", industrial_6r, {"thermal_drift": 1.2e-5}, ("thermal_drift", ()),
     {"temperature": (18.0, 28.0), "time_column": True}),
    pytest.param("scale-five-axis", five_axis, {"joint_scale": {2: 3e-4}},
                 ("joint_scale", (2,)), {}, marks=pytest.mark.slow),
    pytest.param("cyclic-7dof", panda_7dof, {"joint_cyclic": {4: (0.0, 0.0, 1.5e-4, 1e-4)}},
                 ("joint_cyclic", (4,)), {}, marks=pytest.mark.slow),
    pytest.param("compliance-turned-base", turned_base_6r, {"joint_compliance": {2: 2e-6}},
                 ("joint_compliance", (2,)), {}, marks=pytest.mark.slow),
    pytest.param("clean-7dof", panda_7dof, None, None, {"payload": (0.0, 3.0)},
                 marks=pytest.mark.slow),
]


@pytest.mark.parametrize("name,make_robot,effects,expected,options", DIAGNOSIS,
                         ids=[_id(c) for c in DIAGNOSIS])
def test_diagnosis_names_the_effect_and_nothing_else(name, make_robot, effects, expected,
                                                     options, tmp_path):
    robot = make_robot()
    options = dict(options)
    time_column = options.pop("time_column", False)
    common = dict(noise=DIAGNOSIS_NOISE, geometric_errors=_errors(robot, 0), effects=effects,
                  mounted_error=0.0, progress=False, **options)
    fit, val = (simulate(robot, "tracker_points", out_dir=tmp_path / folder, rows=rows,
                         seed=seed, **common).load()
                for folder, rows, seed in (("fit", 300, 0), ("val", 150, 500)))
    if time_column:  # the same drift logged against time [s] instead of temperature
        fit, val = (replace(d, extras={"time": 100.0 * d.extras["temperature"]})
                    for d in (fit, val))
    result = calibrate([fit], [val])
    found = [(e.name, tuple(e.joints)) for e in result.effects]
    if expected is None:
        assert found == []
        assert result.fit.rms_final == result.fit.rms_geometric
    else:
        assert found == [expected]
        if time_column:
            assert result.effects[0].parameters["k_t"] == pytest.approx(1.2e-7, rel=0.1)
    assert result.validation.rms_final <= 1.1 * FLOOR, result.validation


# ----------------------------------------------------------------------------- small data


@pytest.mark.parametrize("rows", [8, 10])
def test_barely_enough_bar_placements_are_refused_when_they_fix_nothing(rows, tmp_path):
    """More residuals than unknowns, yet a nearly flat valley: without the refusal the fit
    wandered off to a probe offset of metres (or did not converge) at the noise level."""
    from robocal_casadi.errors import InputError

    data = simulate(industrial_6r(), "cross_bar", out_dir=tmp_path / "bar", rows=rows,
                    noise=NOISE, geometric_errors=ERRORS, seed=1, progress=False).load()
    with pytest.raises(InputError, match="do not determine .*probe_z .*add data") as caught:
        calibrate([data], diagnose=False)
    assert "dataset.yaml" in str(caught.value)
