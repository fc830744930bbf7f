"""Joints driven together (differential cable drives): the robot file's ``transmission``,
compliance with cross terms inside a coupled group, play behind each motor, and a
simulated truth found again by calibration."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
import yaml

from robocal_casadi.calibration import calibrate
from robocal_casadi.calibration.drive_hints import drive_lines
from robocal_casadi.cli import main
from robocal_casadi.common.table import read_table
from robocal_casadi.effects import EFFECTS
from robocal_casadi.effects.motion import motor_direction_column, with_directions
from robocal_casadi.errors import InputError
from robocal_casadi.instruments.simulate import TrueRobot, simulate, simulate_again
from robocal_casadi.model.pinocchio_model import gravity_torques
from robocal_casadi.model.robot import dump_yaml, load_robot, robot_from_dict, save_robot
from robocal_casadi.model.transmission import TransmissionGroup, motor_directions

DEG = math.pi / 180
NOISE = 1.5e-5  # [m] per tracker coordinate

# A small arm of our own: joints 2-3 share a differential, the rest are driven alone.
ARM = """\
name: pair-arm
convention: dh
units: {length: mm, angle: deg}
joints:
  - {type: revolute, theta: 0, d: 350, a: 0, alpha: -90, limits: [-150, 150],
     mass: 7.0, com: [0, 50, 0], drive: cable}
  - {type: revolute, theta: 0, d: 0, a: 450, alpha: 0, limits: [-100, 100],
     mass: 4.0, com: [-220, 0, 20], drive: cable}
  - {type: revolute, theta: 90, d: 0, a: 40, alpha: 90, limits: [-140, 140],
     mass: 3.0, com: [0, -40, 0], drive: cable}
  - {type: revolute, theta: 0, d: 380, a: 0, alpha: -90, limits: [-160, 160],
     mass: 1.5, com: [0, 0, -120], drive: cable}
  - {type: revolute, theta: 0, d: 0, a: 0, alpha: 90, limits: [-110, 110],
     mass: 0.8, com: [0, 20, 0], drive: cable}
  - {type: revolute, theta: 0, d: 80, a: 0, alpha: 0, limits: [-170, 170],
     mass: 0.3, com: [0, 0, 20], drive: cable}
transmission:
  - {joints: [2, 3], motors: [[20, 20], [20, -20]]}
"""


@pytest.fixture
def arm_file(tmp_path):
    path = tmp_path / "arm.yaml"
    path.write_text(ARM)
    return path


# ----------------------------------------------------------------------------- robot file


def test_transmission_is_read_and_survives_a_round_trip(arm_file, tmp_path):
    robot = load_robot(arm_file)
    assert robot.transmission == (TransmissionGroup((2, 3), ((20.0, 20.0), (20.0, -20.0))),)
    save_robot(robot, tmp_path / "back.yaml")
    assert load_robot(tmp_path / "back.yaml") == robot
    # in other units too: the ratios carry no unit
    save_robot(robot.with_units(robot.units.__class__("m", "rad")), tmp_path / "si.yaml")
    assert load_robot(tmp_path / "si.yaml").transmission == robot.transmission


@pytest.mark.parametrize("group,key,words", [
    ("{joints: [2, 3], motors: [[1, 1], [1, 1]]}", "transmission[0].motors", "not invertible"),
    ("{joints: [2, 3], motors: [[1, 1, 0], [1, -1, 0]]}", "transmission[0].motors", "square"),
    ("{joints: [2, 9], motors: [[1, 1], [1, -1]]}", "transmission[0].joints", "does not exist"),
    ("{joints: [2], motors: [[1]]}", "transmission[0].joints", "two or more"),
    ("{joints: [2, 3], motors: [[1, 1], [1, -1]], ratio: 3}", "transmission[0]", "ratio"),
    ("{joints: [2, 3], motors: [[1, x], [1, -1]]}", "transmission[0].motors[0][1]", "number"),
])
def test_a_bad_transmission_is_refused_in_one_line_naming_file_and_key(
        tmp_path, capsys, group, key, words):
    robot = tmp_path / "arm.yaml"
    robot.write_text(ARM.replace("  - {joints: [2, 3], motors: [[20, 20], [20, -20]]}",
                                 f"  - {group}"))
    joints = tmp_path / "q.csv"
    joints.write_text("q1,q2,q3,q4,q5,q6\n0,0,0,0,0,0\n")
    out = tmp_path / "poses.csv"
    assert main(["fk", str(robot), str(joints), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "arm.yaml" in err[0] and key in err[0] and words in err[0], err[0]
    assert not out.exists()


def test_a_joint_in_two_groups_or_a_prismatic_joint_is_refused():
    content = {"convention": "dh", "units": {"length": "m", "angle": "rad"}, "joints": [
        {"theta": 0, "d": 0, "a": 0.3, "alpha": 0}, {"theta": 0, "d": 0, "a": 0.3, "alpha": 0},
        {"type": "prismatic", "theta": 0, "d": 0, "a": 0, "alpha": 0}]}
    twice = {**content, "transmission": [{"joints": [1, 2], "motors": [[1, 1], [1, -1]]},
                                         {"joints": [2, 1], "motors": [[1, 0], [0, 1]]}]}
    with pytest.raises(InputError, match=r"transmission\[1\]\.joints.*already in"):
        robot_from_dict(twice, file="r.yaml")
    prismatic = {**content, "transmission": [{"joints": [2, 3], "motors": [[1, 1], [1, -1]]}]}
    with pytest.raises(InputError, match="prismatic"):
        robot_from_dict(prismatic, file="r.yaml")


# ----------------------------------------------------------------------------- the laws


def test_coupled_compliance_is_the_matrix_times_pinocchios_gravity_torque(arm_file):
    """``dq_G = -C tau_G`` against pinocchio's gravity torque (not the estimator's CasADi
    gravity), with the row's payload."""
    robot = load_robot(arm_file)
    effect = EFFECTS["coupled_compliance"].create((2, 3), robot)
    assert effect.parameter_names() == ("cc2_2", "cc2_3", "cc3_3")
    C = np.array([[3e-4, -1e-4], [-1e-4, 5e-4]])
    theta = np.array([C[0, 0], C[0, 1], C[1, 1]])
    rng = np.random.default_rng(2)
    Q = rng.uniform(robot.lower_limits, robot.upper_limits, size=(9, robot.dof))
    payload = rng.uniform(0.0, 3.0, 9)
    com = np.array([0.0, 0.01, 0.05])
    dq = effect.contribution(robot, theta, Q, {"payload": payload}, com).dq
    tau = gravity_torques(robot, Q, payload, com)
    expected = np.zeros_like(Q)
    for i in range(len(Q)):
        expected[i, 1] = -(C[0, 0] * tau[i, 1] + C[0, 1] * tau[i, 2])
        expected[i, 2] = -(C[1, 0] * tau[i, 1] + C[1, 1] * tau[i, 2])
    scale = np.abs(expected).max()
    assert scale > 1e-4  # the arm holds real torques here
    np.testing.assert_allclose(dq, expected, rtol=0, atol=1e-10 * scale)


def test_without_masses_the_lumped_products_span_the_true_deflection(arm_file):
    """A robot file without masses: the lumped products (and a constant per joint, the
    joints' offsets) reproduce ``-C tau`` of the true links (pinocchio) by linear least
    squares, and read back by name from the effects file."""
    robot = load_robot(arm_file)
    bare = replace(robot, joints=tuple(replace(j, mass=None, com=None) for j in robot.joints))
    effect = EFFECTS["coupled_compliance"].create((2, 3), bare)
    assert effect.lumped and effect.parameter_names()
    assert any(n.startswith("cc2_3_") for n in effect.parameter_names())  # cross products
    rng = np.random.default_rng(8)
    Q = rng.uniform(robot.lower_limits, robot.upper_limits, size=(150, robot.dof))
    C = np.array([[3e-4, -1e-4], [-1e-4, 5e-4]])
    tau = gravity_torques(robot, Q)[:, 1:3]
    target = -(tau @ C.T).ravel()
    k = len(effect.parameter_names())
    columns = [effect.contribution(bare, np.eye(k)[i], Q).dq[:, 1:3].ravel() for i in range(k)]
    columns += [np.tile(np.eye(2)[i], len(Q)) for i in range(2)]
    A = np.column_stack(columns)
    w, *_ = np.linalg.lstsq(A, target, rcond=None)
    assert np.abs(A @ w - target).max() < 1e-8 * np.abs(target).max()
    # the effects file names the products: read back, the same corrections
    theta = w[:k]
    entry = yaml.safe_load(dump_yaml({"e": effect.to_dict(dict(zip(
        effect.parameter_names(), theta)))}))["e"]
    back = EFFECTS["coupled_compliance"].from_dict(entry, bare)
    assert back.parameter_names() == effect.parameter_names()
    np.testing.assert_allclose(back.contribution(bare, theta, Q).dq,
                               effect.contribution(bare, theta, Q).dq, rtol=0,
                               atol=1e-13 * np.abs(target).max())


def test_motor_play_follows_each_motors_direction_by_hand():
    """A 2-joint group with ``M = [[2, 1], [1, -3]]``: motor directions and joint lags
    computed by hand, including a step that turns one motor not at all."""
    group = TransmissionGroup((1, 2), ((2.0, 1.0), (1.0, -3.0)))
    robot = replace(robot_from_dict({"convention": "dh", "units": {"length": "m", "angle": "rad"},
                                     "joints": [
        {"theta": 0, "d": 0, "a": 0.3, "alpha": 0, "drive": "cable"},
        {"theta": 0, "d": 0, "a": 0.3, "alpha": 0, "drive": "cable"}]}),
        transmission=(group,))
    # steps (dq1, dq2): motor 1 = 2 dq1 + dq2, motor 2 = dq1 - 3 dq2
    Q = np.array([[0.0, 0.0],
                  [0.1, 0.0],    # m1 +0.2 -> +1, m2 +0.1 -> +1
                  [0.2, -0.2],   # m1 0 -> keeps +1, m2 +0.7 -> +1
                  [0.1, 0.1],    # m1 +0.1 -> +1, m2 -1.0 -> -1
                  [0.1, 0.0]])   # m1 -0.1 -> -1, m2 +0.3 -> +1
    directions = np.array([[0, 0], [1, 1], [1, 1], [1, -1], [-1, 1]], dtype=float)
    np.testing.assert_array_equal(motor_directions(Q, group), directions)
    b1, b2 = 0.01, 0.004
    # N = [[1, 1/2], [1/3, -1]] (rows over their largest magnitude), det = -7/6,
    # N^-1 = (6/7) [[1, 1/2], [1/3, -1]]; dq = -N^-1 (b o d) / 2
    inverse = (6.0 / 7.0) * np.array([[1.0, 0.5], [1.0 / 3.0, -1.0]])
    expected = np.array([-inverse @ (0.5 * np.array([b1, b2]) * d) for d in directions])
    effect = EFFECTS["motor_play"]((1, 2))
    extras = with_directions(Q, {}, robot)
    assert set(effect.required_columns()) <= set(extras)
    np.testing.assert_array_equal(extras[motor_direction_column(2)], directions[:, 1])
    dq = effect.contribution(robot, np.array([b1, b2]), Q, extras).dq
    np.testing.assert_allclose(dq, expected, rtol=1e-12, atol=1e-15)


def test_the_effects_are_offered_only_where_a_transmission_is_declared(arm_file):
    robot = load_robot(arm_file)
    plain = replace(robot, transmission=())
    for name in ("coupled_compliance", "motor_play"):
        assert EFFECTS[name].candidates(plain, {}) == ()
        assert EFFECTS[name].candidates(robot, {})
    # a cable's sizes are allowed on a cable, refused on a gear
    play = EFFECTS["motor_play"]((2,))
    assert play.implausibility({"bm2": 0.3 * DEG}, robot) == ""
    geared = replace(robot, joints=tuple(replace(j, drive="gear") for j in robot.joints))
    assert "bm2" in play.implausibility({"bm2": 0.3 * DEG}, geared)
    compliance = EFFECTS["coupled_compliance"]([(2, 3)])
    values = {"cc2_2": 3e-4, "cc2_3": -1e-4, "cc3_3": 5e-4}
    assert compliance.implausibility(values, robot) == ""
    assert "cc2_2" in compliance.implausibility(values, geared)


# ----------------------------------------------------------------------------- recovery


TRUTH = {"coupled_compliance": {(2, 3): (3e-4, -1e-4, 5e-4)},
         "motor_play": {2: 0.2 * DEG, 3: 0.3 * DEG}}
# identifiable geometry only, so that the calibrated world frame is the truth's
ERRORS = {"a2": 4e-4, "d4": -3e-4, "theta3": 2e-4}


def _simulated(folder, arm_file):
    fit = simulate(arm_file, "tracker_points", out_dir=folder / "fit", rows=150, noise=NOISE,
                   seed=3, geometric_errors=ERRORS, effects=TRUTH, progress=False)
    held = simulate_again(fit.truth_path, out_dir=folder / "held", rows=80, seed=4,
                          progress=False)
    return fit, held


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """The pair arm simulated with both effects, calibrated by ``robocal calibrate``; the
    held-out table cut to start where the arm was moving, as a table of its own."""
    folder = tmp_path_factory.mktemp("pair")
    (folder / "arm.yaml").write_text(ARM)
    fit, held = _simulated(folder, folder / "arm.yaml")
    lines = held.table_path.read_text().splitlines(keepends=True)
    held.table_path.write_text("".join([lines[0], *lines[4:]]))  # rows 1-3 left out
    out = folder / "out"
    assert main(["calibrate", str(fit.dataset_path), "--validate", str(held.dataset_path),
                 "--out", str(out), "--no-report"]) == 0
    return fit, out


def test_calibration_finds_the_simulated_coupled_effects(calibrated):
    """Both effects named, each parameter within 5 of its standard errors (and 10%) of the
    truth, the held-out RMS at the noise floor of the 3-D point error: on a held-out table
    that starts with the motors moving, the side each motor starts on is fitted (with
    direction 0 there, its first row would miss by half a motor's play, about 1 mm)."""
    fit, out = calibrated
    result = json.loads((out / "result.json").read_text())
    assert sorted(e["name"] for e in result["effects"]) == ["coupled_compliance", "motor_play"]
    truth = fit.truth.effects.as_dict()
    for finding in result["effects"]:
        for parameter, value in truth[finding["name"]]["parameters"].items():
            found, std = finding["parameters"][parameter], finding["std"][parameter]
            assert std is not None and abs(found - value) <= 5 * std + 1e-12, parameter
            assert found == pytest.approx(value, rel=0.1), parameter
    floor = NOISE * math.sqrt(3) / 1e-3  # [mm], the file's unit
    every = result["validation"]["all"]  # over all held-out readings: none set aside
    assert every["rms_final"] <= 1.15 * floor < every["rms_geometric"]
    assert result["rejected"] == []


def test_fk_with_effects_follows_the_motors_in_row_order(calibrated, tmp_path):
    """``robocal fk --with-effects`` on new readings: the motors' directions from the order
    of the rows, as the simulator's truth takes them (its own code, pinocchio's gravity)."""
    fit, out = calibrated
    truth = fit.truth
    world = TrueRobot(truth.robot, truth.effects, truth.reference_temperature, np.zeros(3))
    robot = truth.robot
    Q = np.random.default_rng(21).uniform(robot.lower_limits, robot.upper_limits, (40, 6))
    table = tmp_path / "joints.csv"
    table.write_text("q1,q2,q3,q4,q5,q6\n" + "\n".join(
        ",".join(repr(float(v)) for v in np.degrees(q)) for q in Q) + "\n")
    true = world.kinematics.flange_poses(world.true_joints(Q, np.zeros(len(Q))))[:, :3, 3]
    rms = {}
    for label, options in (("geometry", []), ("effects", ["--with-effects"])):
        poses = tmp_path / f"{label}.csv"
        assert main(["fk", str(fit.robot_path), str(table), "--out", str(poses),
                     "--calibrated", str(out), *options]) == 0
        read = read_table(poses)
        P = np.column_stack([read.numbers(c) for c in "xyz"]) * 1e-3
        rms[label] = float(np.sqrt(np.mean(np.sum((P - true) ** 2, axis=1))))
    assert rms["effects"] < 3 * np.sqrt(3) * NOISE
    assert rms["geometry"] > 5 * rms["effects"]


def test_without_the_drive_the_terminal_points_to_other_drives(tmp_path, arm_file):
    """The same data with a robot file that declares neither drive nor transmission: what
    is refused for its size on a gear is pointed to the drives that show it."""
    fit, _ = _simulated(tmp_path, arm_file)
    plain = replace(load_robot(fit.robot_path), transmission=())
    plain = replace(plain, joints=tuple(replace(j, drive="gear") for j in plain.joints))
    save_robot(plain, fit.robot_path)
    result = calibrate([fit.load()])
    lines = drive_lines(result)
    # the nearest drive that allows the sizes first, the cable among those named
    # and, the joint being in no declared group, how to declare its coupling
    assert any(line.startswith("joint 2:") and "`drive: " in line and "cable" in line
               and "`transmission:`" in line for line in lines), lines
    assert not {"coupled_compliance", "motor_play"} & {e.name for e in result.effects}


def test_without_masses_the_lumped_form_reaches_the_noise_floor(tmp_path, arm_file):
    """The same simulated arm with a robot file that gives no masses: the coupled
    compliance is found in its lumped form, the motors' play at its true size, the
    held-out RMS at the noise floor."""
    fit, held = _simulated(tmp_path, arm_file)
    for simulated in (fit, held):
        robot = load_robot(simulated.robot_path)
        save_robot(replace(robot, joints=tuple(replace(j, mass=None, com=None)
                                               for j in robot.joints)), simulated.robot_path)
    result = calibrate([fit.load()], [held.load()])
    assert sorted(e.name for e in result.effects) == ["coupled_compliance", "motor_play"]
    play = next(e for e in result.effects if e.name == "motor_play")
    for parameter, value in fit.truth.effects.as_dict()["motor_play"]["parameters"].items():
        assert play.parameters[parameter] == pytest.approx(value, rel=0.1), parameter
    floor = NOISE * math.sqrt(3)
    assert result.validation.rms_final <= 1.15 * floor < result.validation.rms_geometric


def test_what_remains_names_the_motor_whose_play_it_follows(tmp_path, arm_file):
    """Play behind motor 2 of the differential, left out of the model (no diagnosis): the
    search for unexplained structure names that motor's direction alone and explains most
    of the residual (with only the joints' directions it named direction_q3, direction_q2,
    q2, ... for 37% of it)."""
    fit = simulate(arm_file, "tracker_points", out_dir=tmp_path / "fit", rows=150,
                   noise=NOISE, seed=3, geometric_errors=ERRORS,
                   effects={"motor_play": {2: 0.3 * DEG}}, progress=False)
    left = calibrate([fit.load()], diagnose=False).unexplained
    assert left is not None
    assert left.variables[0] == motor_direction_column(2)
    assert left.share > 0.8
