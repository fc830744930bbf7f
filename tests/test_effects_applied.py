"""fk and compensate with the identified effects: the accuracy a user gets is the one the
calibration reports for the model with effects, checked on a simulated truth (whose
effects the simulator computes with pinocchio's gravity torques, not the effect classes)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal_casadi.cli import main
from robocal_casadi.common.table import read_table
from robocal_casadi.effects.effect_model import load_effects
from robocal_casadi.instruments.simulate import TrueRobot, simulate
from robocal_casadi.job.compensation import compensate
from robocal_casadi.model.robot import load_robot

UR10 = Path(__file__).resolve().parents[1] / "robocal_casadi" / "data" / "ur10-ipa" / "robot.yaml"
# identifiable geometry only, so the calibrated world frame is the truth's
ERRORS = {"a2": 4e-4, "d4": -3e-4, "alpha3": 5e-4, "theta3": -4e-4}
EFFECTS = {"joint_compliance": {2: 3e-6, 3: 4e-6}, "joint_cyclic": {1: (1e-4, -5e-5, 0, 0)}}
NOISE = 1e-5  # [m] per coordinate
PAYLOAD = 8.0  # [kg]


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    folder = tmp_path_factory.mktemp("effects")
    sims = [simulate(UR10, "tracker_points", out_dir=folder / part, rows=rows, noise=NOISE,
                     geometric_errors=ERRORS, effects=EFFECTS, payload=(0.0, 10.0), seed=seed,
                     progress=False)
            for part, seed, rows in (("fit", 1, 150), ("val", 2, 60))]
    out = folder / "out"
    assert main(["calibrate", str(sims[0].dataset_path), "--validate", str(sims[1].dataset_path),
                 "--out", str(out), "--no-report"]) == 0
    truth = sims[0].truth
    world = TrueRobot(truth.robot, truth.effects, truth.reference_temperature, np.zeros(3))
    return out, world


def _true_flange(world: TrueRobot, Q: np.ndarray, payload: float) -> np.ndarray:
    return world.kinematics.flange_poses(world.true_joints(Q, np.full(len(Q), payload)))


def _readings(count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    Q = rng.uniform(-2.5, 2.5, (count, 6))
    Q[:, 1] = rng.uniform(-2.8, -0.4, count)  # the arm up, as in the simulated data
    return Q


def test_result_says_what_each_output_delivers(calibrated):
    out, _ = calibrated
    result = json.loads((out / "result.json").read_text())
    assert {e["name"] for e in result["effects"]} == {"joint_compliance", "joint_cyclic"}
    delivered = result["delivered"]
    geometry = delivered["robot_calibrated.yaml"]["validation"]
    with_effects = delivered["effects_calibrated.yaml"]["validation"]
    assert with_effects == pytest.approx(result["validation"]["rms_final"])
    assert geometry > 5 * with_effects  # the effects carry most of the accuracy here
    assert "--with-effects" in delivered["effects_calibrated.yaml"]["applies"]


def test_fk_with_effects_matches_the_truth(calibrated, tmp_path):
    out, world = calibrated
    Q = _readings(30, 11)
    table = tmp_path / "joints.csv"
    lines = ["q1,q2,q3,q4,q5,q6,payload"] + [
        ",".join(repr(float(v)) for v in np.degrees(q)) + f",{PAYLOAD}" for q in Q]
    table.write_text("\n".join(lines) + "\n")
    errors = {}
    for label, options in (("geometry", []), ("effects", ["--with-effects"])):
        poses = tmp_path / f"{label}.csv"
        assert main(["fk", str(UR10), str(table), "--out", str(poses), "--calibrated", str(out),
                     *options]) == 0
        read = read_table(poses)
        P = np.column_stack([read.numbers(c) for c in "xyz"]) * 1e-3
        errors[label] = np.linalg.norm(P - _true_flange(world, Q, PAYLOAD)[:, :3, 3], axis=1)
    assert np.sqrt(np.mean(errors["effects"] ** 2)) < 3 * np.sqrt(3) * NOISE
    assert np.sqrt(np.mean(errors["geometry"] ** 2)) > 5 * np.sqrt(np.mean(errors["effects"] ** 2))


def test_compensation_with_effects_lands_at_the_noise_floor(calibrated, tmp_path):
    out, world = calibrated
    Q_goal = _readings(12, 12)
    goal = _true_flange(world, Q_goal, PAYLOAD)
    targets = tmp_path / "targets.csv"
    targets.write_text("x,y,z\n" + "\n".join(",".join(repr(float(v)) for v in p * 1e3)
                                              for p in goal[:, :3, 3]) + "\n")
    start = ",".join(repr(float(v)) for v in np.degrees(Q_goal[0]))
    misses = {}
    for label, options in (("geometry", []), ("effects", ["--with-effects", "--payload",
                                                          str(PAYLOAD)])):
        joints = tmp_path / f"{label}.csv"
        assert main(["compensate", str(out), str(targets), "--out", str(joints),
                     f"--start={start}", *options]) == 0
        read = read_table(joints)
        assert set(read.text("status")) == {"ok"}
        Q = np.radians(np.column_stack([read.numbers(f"q{i}") for i in range(1, 7)]))
        misses[label] = np.linalg.norm(_true_flange(world, Q, PAYLOAD)[:, :3, 3]
                                       - goal[:, :3, 3], axis=1)
        if label == "effects":  # the solve itself reaches the target with the effects
            assert np.max(read.numbers("position_error")) < 1e-6  # [mm]
    assert np.sqrt(np.mean(misses["effects"] ** 2)) < 3 * np.sqrt(3) * NOISE
    assert np.sqrt(np.mean(misses["geometry"] ** 2)) > 5 * np.sqrt(np.mean(misses["effects"] ** 2))


def test_pose_targets_with_effects(calibrated):
    out, world = calibrated
    robot = load_robot(out / "robot_calibrated.yaml")
    model = load_effects(out, robot)
    Q_goal = _readings(5, 13)
    goal = _true_flange(world, Q_goal, PAYLOAD)
    from robocal_casadi.model.transforms import quaternion_from_matrix

    targets = np.column_stack([goal[:, :3, 3], [quaternion_from_matrix(T[:3, :3]) for T in goal]])
    result = compensate(robot, targets, start=Q_goal[0], effects=model,
                        extras={"payload": np.asarray(PAYLOAD)})
    assert result.status == ("ok",) * 5
    reached = model.tool_poses(result.joints, {"payload": np.asarray(PAYLOAD)})
    assert np.abs(reached - goal).max() < 1e-6  # onto the target, with the effects
    true = _true_flange(world, result.joints, PAYLOAD)
    assert np.sqrt(np.mean(np.sum((true[:, :3, 3] - goal[:, :3, 3]) ** 2, axis=1))) < \
        3 * np.sqrt(3) * NOISE


def test_effects_need_their_inputs(calibrated, tmp_path, capsys):
    out, _ = calibrated
    table = tmp_path / "joints.csv"
    table.write_text("q1,q2,q3,q4,q5,q6\n0,-90,0,0,0,0\n")
    poses = tmp_path / "poses.csv"
    assert main(["fk", str(UR10), str(table), "--out", str(poses), "--calibrated", str(out),
                 "--with-effects"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "'payload'" in error and not poses.exists()
    assert main(["fk", str(UR10), str(table), "--out", str(poses), "--with-effects"]) == 2
    assert "--calibrated" in capsys.readouterr().err


def test_fk_applies_coupling_and_backlash_in_row_order(tmp_path):
    """A driven joint and a joint with play: fk --with-effects follows the truth, the
    directions of motion taken from the order of the rows as in the data."""
    effects = {"joint_coupling": {"5@6": (3e-4, -2e-4)}, "backlash": {2: 4e-4}}
    sims = [simulate(UR10, "tracker_points", out_dir=tmp_path / part, rows=rows, noise=NOISE,
                     geometric_errors={"a2": 4e-4, "d4": -3e-4}, effects=effects, seed=seed,
                     progress=False)
            for part, seed, rows in (("fit", 1, 150), ("val", 2, 60))]
    out = tmp_path / "out"
    assert main(["calibrate", str(sims[0].dataset_path), "--validate",
                 str(sims[1].dataset_path), "--out", str(out), "--no-report"]) == 0
    found = yaml.safe_load((out / "effects_calibrated.yaml").read_text())["effects"]
    assert {e["name"] for e in found} == {"joint_coupling", "backlash"}
    truth = sims[0].truth
    world = TrueRobot(truth.robot, truth.effects, truth.reference_temperature, np.zeros(3))
    Q = _readings(40, 14)
    table = tmp_path / "joints.csv"
    table.write_text("q1,q2,q3,q4,q5,q6\n" + "\n".join(
        ",".join(repr(float(v)) for v in np.degrees(q)) for q in Q) + "\n")
    true = world.kinematics.flange_poses(world.true_joints(Q, np.zeros(len(Q))))[:, :3, 3]
    rms = {}
    for label, options in (("geometry", []), ("effects", ["--with-effects"])):
        poses = tmp_path / f"{label}.csv"
        assert main(["fk", str(UR10), str(table), "--out", str(poses), "--calibrated", str(out),
                     *options]) == 0
        read = read_table(poses)
        P = np.column_stack([read.numbers(c) for c in "xyz"]) * 1e-3
        rms[label] = float(np.sqrt(np.mean(np.sum((P - true) ** 2, axis=1))))
    assert rms["effects"] < 3 * np.sqrt(3) * NOISE
    assert rms["geometry"] > 5 * rms["effects"]
