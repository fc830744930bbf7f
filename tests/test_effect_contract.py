"""The contract every registered effect fulfils, checked over the whole registry.

Each check is against something the effect's ``delta`` did not produce: central finite
differences of the numeric evaluation, the numpy truth the simulator uses (pinocchio
gravity for compliance), a calibration of simulated data, and hand-made values outside
the plausible ranges.
"""

from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest
import yaml

from robocal_casadi.calibration import calibrate, diagnosis
from robocal_casadi.common.units import Units
from robocal_casadi.effects import EFFECTS, Effect, Plausible, RowContext, TrueWorld, register
from robocal_casadi.effects.effect_model import EffectModel, load_effects, save_effects
from robocal_casadi.effects.motion import direction_column, motor_direction_column, travel_column
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import ROBOTS
from robocal_casadi.model.robot import dump_yaml
from robocal_casadi.model.transmission import TransmissionGroup

NAMES = sorted(EFFECTS)
# two coupled groups, for the effects of joints driven together: a differential of ratio
# 50 and a matrix whose rows scale differently
ROBOT = replace(ROBOTS["industrial_6r"](), transmission=(
    TransmissionGroup((2, 3), ((50.0, 50.0), (50.0, -50.0))),
    TransmissionGroup((5, 6), ((2.0, 1.0), (1.0, -3.0)))))
FIT_EXTRAS = {"temperature": np.array([18.0, 21.0, 24.0]), "payload": np.array([0.0, 2.0, 5.0])}


def robot_for(cls: type[Effect]):
    """``ROBOT``, its joints driven the way ``cls`` is looked for (gear where it may be)."""
    drive = "gear" if "gear" in cls.drives else cls.drives[0]
    return replace(ROBOT, joints=tuple(replace(j, drive=drive) for j in ROBOT.joints))


def example(cls: type[Effect]) -> Effect:
    """The effect on two of its candidate units (one for a column effect)."""
    units = cls.candidates(robot_for(cls), FIT_EXTRAS)
    assert units, f"{cls.name} offers no candidate on {ROBOT.name}"
    chosen = units[:1] if cls.per == "column" else (units[1], units[-1])
    return cls.merged(chosen, ROBOT, FIT_EXTRAS)


def rows(effect: Effect, n: int, seed: int = 3):
    """Random readings (n x dof) [rad] and per-row inputs for ``effect``."""
    rng = np.random.default_rng(seed)
    Q = rng.uniform(np.maximum(ROBOT.lower_limits, -np.pi), np.minimum(ROBOT.upper_limits, np.pi),
                    size=(n, ROBOT.dof))
    extras = {"temperature": rng.uniform(15.0, 30.0, n), "payload": rng.uniform(0.0, 8.0, n)}
    for j in range(1, ROBOT.dof + 1):
        extras[direction_column(j)] = rng.choice([-1.0, 0.0, 1.0], n)
        extras[travel_column(j)] = rng.uniform(0.0, 0.05, n)
        extras[motor_direction_column(j)] = rng.choice([-1.0, 0.0, 1.0], n)
    return Q, extras


def theta_of(effect: Effect, seed: int = 5) -> np.ndarray:
    """Parameters of about the effect's typical size, random signs."""
    rng = np.random.default_rng(seed)
    return effect.typical * rng.uniform(0.5, 2.0, len(effect.parameter_names())) \
        * rng.choice([-1.0, 1.0], len(effect.parameter_names()))


def symbolic(effect: Effect):
    """``(q, theta, extras) -> (dq, ddq/dq, ddq/dtheta, ddp/dtheta)`` from ``delta``."""
    registry = ROBOT.parameters()
    q = ca.SX.sym("q", ROBOT.dof)
    theta = ca.SX.sym("theta", len(effect.parameter_names()))
    columns = sorted(set(effect.required_columns()) | {"payload"})
    e = ca.SX.sym("e", len(columns))
    com = np.array([0.0, 0.02, 0.1])
    row = RowContext(ROBOT, registry, q, ca.DM(ROBOT.parameter_vector()),
                     {c: e[i] for i, c in enumerate(columns)}, ca.DM(com))
    dq, dp = effect.delta(row, theta)
    dp = ca.SX.zeros(len(registry)) if dp is None else dp
    f = ca.Function("j", [q, theta, e], [ca.jacobian(dq, q), ca.jacobian(dq, theta),
                                         ca.jacobian(dp, theta)])
    return f, columns, com


# ----------------------------------------------------------------------------- declarations


@pytest.mark.parametrize("name", NAMES)
def test_declarations(name):
    cls = EFFECTS[name]
    assert cls.name == name
    assert cls.title and cls.title[0].isupper()
    assert cls.plot_variable in Effect.PLOT_VARIABLES
    assert cls.per in ("joint", "pair", "column", "group")
    assert cls.formula and cls.sentence
    effect = example(cls)
    names = effect.parameter_names()
    assert names and len(set(names)) == len(names)
    assert isinstance(effect.unit, str) and effect.unit
    for parameter in names:
        limits = effect.plausible(parameter)
        assert isinstance(limits, Plausible)
        # a typical value is a plausible one
        assert limits.minimum <= effect.typical <= limits.maximum, parameter
    one = cls.for_simulation(() if cls.per == "column" else
                             ((4, 6),) if cls.per == "pair" else
                             ((2, 3),) if cls.per == "group" else (2,))
    values = one.simulation_values()
    assert len(values) == len(cls.simulation_default)
    assert one.check_plausible(values) == ()
    text = effect.describe(dict(zip(names, theta_of(effect))), Units("mm", "deg"))
    assert isinstance(text, str) and len(text) > 10


# ----------------------------------------------------------------------------- the maths


@pytest.mark.parametrize("name", NAMES)
def test_shapes_and_zero_at_zero_parameters(name):
    effect = example(EFFECTS[name])
    Q, extras = rows(effect, 7)
    zero = effect.contribution(ROBOT, np.zeros(len(effect.parameter_names())), Q, extras)
    assert zero.dq.shape == (7, ROBOT.dof)
    assert zero.dp.shape == (7, len(ROBOT.parameters()))
    assert not zero.dq.any() and not zero.dp.any()
    some = effect.contribution(ROBOT, theta_of(effect), Q, extras)
    assert np.abs(some.dq).max() + np.abs(some.dp).max() > 0
    # only the joints the effect names move (the geometry for thermal drift; a motor's
    # play moves the joints of its transmission group)
    moved = np.flatnonzero(np.abs(some.dq).max(axis=0) > 0) + 1
    assert set(moved) <= set(effect.moved_joints(ROBOT))


def _central(f, x, h):
    x = np.asarray(x, dtype=float)
    out = []
    for k in range(len(x)):
        step = np.zeros_like(x)
        step[k] = h
        out.append((f(x + step) - f(x - step)) / (2 * h))
    return np.stack(out, axis=-1)


@pytest.mark.parametrize("name", NAMES)
def test_jacobians_match_finite_differences(name):
    effect = example(EFFECTS[name])
    jacobians, columns, com = symbolic(effect)
    Q, extras = rows(effect, 3)
    theta = theta_of(effect)
    for i in range(len(Q)):
        row = {c: extras[c][i:i + 1] for c in extras}
        e = np.array([extras[c][i] for c in columns])
        J_q, J_theta, J_dp = (np.asarray(m) for m in jacobians(Q[i], theta, e))

        def dq_of_q(q, row=row):
            return effect.contribution(ROBOT, theta, q[None], row, com).dq[0]

        def of_theta(t, i=i, row=row):
            c = effect.contribution(ROBOT, t, Q[i:i + 1], row, com)
            return np.concatenate([c.dq[0], c.dp[0]])

        fd_q = _central(dq_of_q, Q[i], 1e-6)
        fd_theta = _central(of_theta, theta, 1e-3 * effect.typical)
        for exact, approx in ((J_q, fd_q), (np.vstack([J_theta, J_dp]), fd_theta)):
            scale = max(np.abs(approx).max(), 1e-12)
            np.testing.assert_allclose(exact, approx, atol=1e-6 * scale, rtol=1e-5)


@pytest.mark.parametrize("name", NAMES)
def test_simulator_truth_agrees_with_the_estimator(name):
    """The simulator's numpy truth (pinocchio gravity for compliance) and the estimator's
    CasADi ``delta`` are two codings of one definition: they agree row by row."""
    cls = EFFECTS[name]
    keys = () if cls.per == "column" else ((4, 6), (2, 3)) if cls.per == "pair" else \
        ((2, 3), (5, 6)) if cls.per == "group" else (2, 5)
    offered = {j for unit in cls.candidates(robot_for(cls), FIT_EXTRAS) for j in unit.joints}
    if cls.per == "joint" and not set(keys) <= offered:  # e.g. links without length
        keys = tuple(sorted(offered))[:2]
    truth = cls.for_simulation(keys)
    rng = np.random.default_rng(11)
    values = {n: v * rng.uniform(0.5, 1.5) for n, v in zip(
        truth.parameter_names(), np.tile(cls.simulation_default, max(len(keys), 1)))}
    world = TrueWorld(ROBOT, np.array([0.01, 0.0, 0.12]), 21.5)
    Q, extras = rows(truth, 6, seed=9)
    estimator = truth
    if cls.per == "column":  # the estimator's reference is the simulator's T_ref
        estimator = cls.create((), ROBOT, {"temperature": np.array([world.reference_temperature])})
    theta = np.array([values[n] for n in estimator.parameter_names()])
    ours = estimator.contribution(ROBOT, theta, Q, extras, world.payload_com)
    np.testing.assert_allclose(ours.dq, truth.simulated_dq(world, Q, extras, values),
                               atol=1e-12 * max(1.0, np.abs(ours.dq).max()), rtol=1e-9)
    p = ROBOT.parameter_vector()
    # a shift of the whole arm is the estimator's change of the base translation
    shift = truth.simulated_shift(world, Q, extras, values)
    base = ROBOT.parameters().indices(["base_x", "base_y", "base_z"])
    for i in range(len(Q)):
        dp = truth.simulated_dp(world, p, {c: extras[c][i] for c in extras}, values)
        expected = np.zeros_like(p) if dp is None else dp.copy()
        expected[base] += shift[i]
        np.testing.assert_allclose(ours.dp[i], expected, atol=1e-15 + 1e-12 * np.abs(shift).max())


# ----------------------------------------------------------------------------- plausibility


@pytest.mark.parametrize("name", NAMES)
def test_plausible_range_check_names_the_parameter_and_the_factor(name):
    effect = example(EFFECTS[name])
    names = effect.parameter_names()
    inside = {n: effect.typical for n in names}
    assert effect.check_plausible(inside) == ()
    target = names[-1]
    limits = effect.plausible(target)
    too_big = {**inside, target: 10 * limits.maximum}
    # (a sine and cosine pair is also too large as a whole: that is its own entry)
    (finding,) = [f for f in effect.check_plausible(too_big) if f.parameter == target]
    assert finding.parameter == target and finding.factor == pytest.approx(10.0)
    assert target in finding.message and "10 times" in finding.message
    if limits.sign:
        wrong = {**inside, target: -limits.sign * effect.typical}
        (finding,) = effect.check_plausible(wrong)
        assert finding.parameter == target and finding.factor == np.inf
        assert ("negative" if limits.sign > 0 else "positive") in finding.message
    if limits.minimum > 0:
        (finding,) = effect.check_plausible({**inside, target: limits.minimum / 4})
        assert finding.factor == pytest.approx(4.0) and "smallest" in finding.message


def test_harmonic_amplitudes_and_the_refusal_text():
    """A sine and cosine pair each within range but together too large is caught; a small
    compliance is weak, not absurd; a large one is refused in words."""
    deg = np.pi / 180
    cyclic = EFFECTS["joint_cyclic"]((2,))
    (finding,) = cyclic.check_plausible({"a1_2": 0.04 * deg, "b1_2": 0.04 * deg})
    assert finding.parameter == "a1_2/b1_2"
    assert finding.factor == pytest.approx(np.hypot(0.04, 0.04) / 0.05)
    coupling = EFFECTS["joint_coupling"]((4,), (6,))
    assert coupling.check_plausible({"sin4_q6": 0.03 * deg, "cos4_q6": 0.03 * deg}) == ()
    assert "amplitude" in coupling.implausibility({"sin4_q6": 0.04 * deg,
                                                   "cos4_q6": 0.04 * deg})
    compliance = EFFECTS["joint_compliance"]((2,))
    assert compliance.implausibility({"c2": 1e-8}) == ""
    assert len(compliance.check_plausible({"c2": 1e-8})) == 1
    assert "c2 = 0.001" in compliance.implausibility({"c2": 1e-3})
    assert "negative" in compliance.implausibility({"c2": -1e-6})


def test_the_stated_ranges_of_real_robots():
    deg = np.pi / 180
    cases = {
        ("joint_compliance", "c2"): (1e-4, 1e-7, +1),
        ("joint_cyclic", "a1_2"): (0.05 * deg, 0.0, 0),
        ("joint_scale", "s2"): (2e-3, 0.0, 0),
        ("thermal_drift", "k_T"): (3e-5, 0.0, +1),
        ("joint_coupling", "sin2_q3"): (0.05 * deg, 0.0, 0),
        ("backlash", "b2"): (0.1 * deg, 0.0, +1),
    }
    for (name, parameter), (maximum, minimum, sign) in cases.items():
        effect = example(EFFECTS[name])
        limits = effect.plausible(parameter)
        assert (limits.maximum, limits.minimum, limits.sign) == pytest.approx(
            (maximum, minimum, sign)), name
    # steel and aluminium are plausible thermal coefficients
    thermal = example(EFFECTS["thermal_drift"])
    assert thermal.check_plausible({"k_T": 11.5e-6}) == ()
    assert thermal.check_plausible({"k_T": 23e-6}) == ()


# ----------------------------------------------------------------------------- recovery


TRUTH_KEYS = {"joint": 2, "pair": (5, 6), "group": (2, 3)}


@pytest.mark.parametrize("name", NAMES)
def test_calibration_recovers_the_simulated_effect(tmp_path, monkeypatch, name):
    """Simulated tracker data with one effect; diagnosis offered only that effect finds it
    and estimates its true values."""
    cls = EFFECTS[name]
    key = TRUTH_KEYS.get(cls.per)
    default = cls.simulation_default
    spec = default[0] if key is None else {key: default if len(default) > 1 else default[0]}
    sim = simulate(robot_for(cls), "tracker_points", out_dir=tmp_path / "fit", rows=200,
                   noise=1e-5,
                   seed=4, geometric_errors=(5e-4, 5e-4), effects={name: spec},
                   payload=(0.0, 20.0), progress=False)
    monkeypatch.setattr(diagnosis, "EFFECTS", {name: cls})
    result = calibrate([sim.load()])
    assert [e.name for e in result.effects] == [name], result.effects
    (finding,) = result.effects
    truth = sim.truth.effects.as_dict()[name]["parameters"]
    checked = 0
    for parameter, value in truth.items():
        if parameter in finding.parameters and abs(value) >= 1e-4 * (cls.typical / 1e-4):
            assert finding.parameters[parameter] == pytest.approx(value, rel=0.1), parameter
            checked += 1
    assert checked
    # down to the noise floor (3-D error of 1e-5 m per coordinate), from above it
    floor = 1e-5 * np.sqrt(3)
    assert result.fit.rms_final <= 1.1 * floor < result.fit.rms_geometric


# ----------------------------------------------------------------------------- description


@pytest.mark.parametrize("name", NAMES)
def test_description_round_trip_evaluates_identically(name):
    """An effect written by ``to_dict`` (through YAML text) and rebuilt by ``from_dict``
    has the same parameters and the same corrections at random rows: the same expression
    evaluated twice, so equal to round-off."""
    effect = example(EFFECTS[name])
    names = effect.parameter_names()
    theta = theta_of(effect)
    entry = effect.to_dict(dict(zip(names, theta)), FIT_EXTRAS.keys())
    text = dump_yaml({"effects": [entry]})
    (loaded,) = yaml.safe_load(text)["effects"]
    back = EFFECTS[loaded["name"]].from_dict(loaded, ROBOT)
    assert type(back) is type(effect)
    assert back.parameter_names() == names
    values = np.array([loaded["parameters"][n] for n in names])
    np.testing.assert_array_equal(values, theta)  # YAML keeps every digit
    Q, extras = rows(effect, 7)
    com = np.array([0.0, 0.02, 0.1])
    before = effect.contribution(ROBOT, theta, Q, extras, com)
    after = back.contribution(ROBOT, values, Q, extras, com)
    scale = max(np.abs(before.dq).max(), np.abs(before.dp).max(), 1e-300)
    np.testing.assert_allclose(after.dq, before.dq, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(after.dp, before.dp, rtol=0, atol=1e-13 * scale)


@pytest.fixture
def quadratic_effect():
    """The effect defined under tests/, registered for one test and taken out after."""
    from quadratic_effect import QuadraticReading

    register(QuadraticReading)
    yield QuadraticReading
    EFFECTS.pop(QuadraticReading.name)


def test_an_effect_defined_outside_the_library(tmp_path, monkeypatch, quadratic_effect):
    """Registered with one line, a new effect is simulated, found by diagnosis with its
    true value, written to the effects file and read back to the same tool poses."""
    cls = quadratic_effect
    truth = 1e-4
    sim = simulate(robot_for(cls), "tracker_points", out_dir=tmp_path / "fit", rows=200,
                   noise=1e-5, seed=4, geometric_errors=(5e-4, 5e-4),
                   effects={cls.name: {2: truth}}, progress=False)
    assert sim.truth.effects.as_dict()[cls.name]["parameters"] == {"e2_sq": truth}
    monkeypatch.setattr(diagnosis, "EFFECTS", {cls.name: cls})
    result = calibrate([sim.load()])
    assert [e.name for e in result.effects] == [cls.name], result.effects
    assert result.effects[0].parameters["e2_sq"] == pytest.approx(truth, rel=0.1)
    assert save_effects(result, tmp_path)
    model = load_effects(tmp_path, result.robot_calibrated)
    assert [type(e) for e in model.effects] == [cls]
    Q, _ = rows(model.effects[0], 5)
    direct = EffectModel(model.robot, tuple(result.effect_models),
                         np.asarray(result.effect_values, dtype=float)).tool_poses(Q)
    np.testing.assert_allclose(model.tool_poses(Q), direct, rtol=0, atol=1e-12)
