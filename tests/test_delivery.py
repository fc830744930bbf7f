"""What the robot receives: the best geometry-only model, figures from the files as
written, a loud refusal when calibrating is worse than doing nothing, and the predicted
accuracy over the work cell, each checked against something the code under test did not
produce (robocal fk and a closed-form rigid fit, a nominal truth, Monte Carlo sampling
with the numpy reference kinematics)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from robocal_casadi.calibration import calibrate
from robocal_casadi.cli import main
from robocal_casadi.common.table import read_table
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.job.accuracy import BAND, MEASURED, SAMPLES, SEED, predict, region_of
from robocal_casadi.job.run import JobOptions, calibrate_job
from robocal_casadi.model.kinematics import nominal_pose
from robocal_casadi.model.robot import load_robot

UR10 = Path(__file__).resolve().parents[1] / "robocal_casadi" / "data" / "ur10-ipa" / "robot.yaml"
ERRORS = {"a2": 4e-4, "d4": -3e-4, "alpha3": 5e-4, "theta3": -4e-4, "theta2": 3e-4}
EFFECTS = {"joint_cyclic": {1: (2e-4, -1e-4, 0, 0)}}
NOISE = 2e-5  # [m] per coordinate


@pytest.fixture(scope="module")
def delivered(tmp_path_factory):
    folder = tmp_path_factory.mktemp("delivery")
    sims = [simulate(UR10, "tracker_points", out_dir=folder / part, rows=rows, noise=NOISE,
                     geometric_errors=ERRORS, effects=EFFECTS, seed=seed, progress=False)
            for part, seed, rows in (("fit", 3, 120), ("val", 4, 60))]
    out = folder / "out"
    # Plain least squares: the comparisons below are on the same held-out readings (the
    # robust default may keep other readings under other models).
    status = main(["calibrate", str(sims[0].dataset_path), "--validate",
                   str(sims[1].dataset_path), "--out", str(out), "--no-report",
                   "--loss", "linear"])
    return out, sims, status


def _kabsch_rms(points: np.ndarray, measured: np.ndarray) -> float:
    """RMS distance [same unit] after the best rigid motion of ``points`` onto ``measured``
    (closed form, Kabsch)."""
    a, b = points - points.mean(0), measured - measured.mean(0)
    U, _, Vt = np.linalg.svd(a.T @ b)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = (U @ D @ Vt).T
    moved = a @ R.T
    return float(np.sqrt(np.mean(np.sum((moved - b) ** 2, axis=1))))


def test_written_robot_file_delivers_what_result_json_says(delivered, tmp_path):
    out, sims, status = delivered
    assert status == 0
    result = json.loads((out / "result.json").read_text())
    block = result["delivered"]["robot_calibrated.yaml"]
    validation = sims[1]
    joints = tmp_path / "joints.csv"
    table = read_table(validation.table_path)
    names = [f"q{j}" for j in range(1, 7)]
    Q = np.column_stack([table.numbers(n) for n in names])
    np.savetxt(joints, Q, delimiter=",", header=",".join(names), comments="")
    poses = tmp_path / "poses.csv"
    assert main(["fk", str(out / "robot_calibrated.yaml"), str(joints), "--out",
                 str(poses)]) == 0
    fk = read_table(poses)
    T = np.zeros((len(Q), 4, 4))
    T[:, :3, 3] = np.column_stack([fk.numbers(c) for c in "xyz"])
    w, x, y, z = (np.asarray(fk.numbers(c)) for c in ("qw", "qx", "qy", "qz"))
    T[:, :3, :3] = np.stack([
        np.stack([1 - 2 * (y**2 + z**2), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x**2 + z**2), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x**2 + y**2)], -1)], 1)
    mounted = block["mounted"]
    target = np.array([mounted[k] for k in sorted(mounted)])  # target x, y, z [mm]
    points = T[:, :3, :3] @ target + T[:, :3, 3]
    measured = np.column_stack([table.numbers(c) for c in "xyz"])
    # The delivered file's held-out RMS, measured independently: robocal fk on the file
    # as written and a closed-form fit of the tracker frame.
    assert _kabsch_rms(points, measured) == pytest.approx(block["validation"], abs=1e-6)


def test_delivered_geometry_is_never_worse_than_a_geometric_fit(delivered):
    out, sims, _ = delivered
    result = json.loads((out / "result.json").read_text())
    assert result["effects"], "the simulated periodic error must be found for this check"
    block = result["delivered"]["robot_calibrated.yaml"]
    geometric = calibrate([load_dataset(sims[0].dataset_path)],
                          [load_dataset(sims[1].dataset_path)], diagnose=False, loss="linear")
    scale = geometric.units.length_scale
    assert block["validation"] <= 1.01 * geometric.validation.rms_geometric / scale
    candidates = result["delivered"]["candidates"]
    assert block["validation"] <= 1.01 * min(c["held_out"] for c in candidates.values()
                                             if c["held_out"] is not None
                                             and block["model"] in candidates)


def test_calibration_worse_than_doing_nothing_is_refused_loudly(tmp_path, capsys):
    # The fit data come from a robot off its drawing, the held-out data from one on it
    # (a robot repaired between the two sessions): calibrating makes it worse there.
    fit = simulate(UR10, "tracker_points", out_dir=tmp_path / "fit", rows=60, noise=NOISE,
                   geometric_errors={"a2": 2e-3, "theta3": 3e-3, "a3": -2e-3}, seed=5,
                   progress=False)
    held = simulate(UR10, "tracker_points", out_dir=tmp_path / "val", rows=40, noise=NOISE,
                    seed=6, progress=False)
    out = tmp_path / "out"
    status = main(["calibrate", str(fit.dataset_path), "--validate", str(held.dataset_path),
                   "--out", str(out), "--no-report", "--no-diagnose"])
    printed = capsys.readouterr().out.splitlines()
    assert status == 3
    assert printed[0].startswith("NOT BETTER THAN DOING NOTHING")
    result = json.loads((out / "result.json").read_text())
    assert result["recommended"] in ("nominal", "instrument_only")
    written = load_robot(out / "robot_calibrated.yaml")
    nominal = load_robot(UR10)
    assert np.allclose(written.parameter_vector(), nominal.parameter_vector(), atol=1e-12)


def _posterior_rms(result, robot, names, point, Q, draws, seed):
    """Per draw of the robot and instrument-point errors from ``result``'s posterior, the
    RMS over the poses ``Q`` of the point moved by the numpy reference kinematics, after
    the best rigid motion (closed form)."""
    registry = robot.parameters()
    in_robot = [k for k, n in enumerate(result.covariance_names) if n in registry]
    in_point = [k for k, n in enumerate(result.covariance_names) if n in names]
    index = registry.indices([result.covariance_names[k] for k in in_robot])
    point_index = [names.index(result.covariance_names[k]) for k in in_point]
    base = robot.parameter_vector()

    def located(geometry, offset):
        poses = [nominal_pose(geometry, q) for q in Q]
        return np.array([T[:3, :3] @ offset + T[:3, 3] for T in poses])

    reference = located(robot, point)
    out = []
    for delta in np.random.default_rng(seed).multivariate_normal(
            np.zeros(len(result.covariance_names)), result.covariance, draws):
        moved, offset = base.copy(), point.copy()
        moved[index] += delta[in_robot]
        offset[point_index] += delta[in_point]
        out.append(_kabsch_rms(located(robot.with_parameters(moved), offset), reference))
    return np.array(out)


def test_predicted_parameter_error_matches_monte_carlo(tmp_path):
    sim = simulate(UR10, "tracker_points", out_dir=tmp_path / "fit", rows=40, noise=1e-4,
                   geometric_errors=ERRORS, seed=7, progress=False)
    result = calibrate_job([load_dataset(sim.dataset_path)], (), JobOptions(diagnose=False))
    robot = result.robot_calibrated
    assert not robot.has_tool  # the tool pose is the flange pose: the reference below
    names = ("target_x", "target_y", "target_z")
    point = np.array([result.mounted_geometric[n] for n in names])
    prediction = predict(result, robot, point, names, structured=0.0)
    unexplained = 0.0 if result.unexplained is None else result.unexplained.rms
    parameter_part = np.sqrt(max(prediction.rms**2 - unexplained**2, 0.0))
    # Independent: sample the robot and reflector errors from the posterior, move the
    # numpy reference kinematics, remove the best rigid motion (closed form), average.
    low, high = np.array(region_of(result)).T
    Q = np.random.default_rng(SEED).uniform(low, high, size=(SAMPLES, len(low)))[::16]
    draws = 400
    squares = _posterior_rms(result, robot, names, point, Q, draws, seed=11) ** 2
    estimate = np.sqrt(np.mean(squares))
    # A mean of `draws` squared norms of a Gaussian field: relative spread of the mean
    # square at most sqrt(2/draws) (one degree of freedom), 3 sigma on the RMS.
    assert parameter_part == pytest.approx(estimate, rel=3 * np.sqrt(2 / draws))


def test_lumped_compliance_reads_back_at_another_geometry():
    """Which lumped compliance terms are independent is judged numerically on a geometry;
    an effects file written at the calibration's reads back by name at any other."""
    from robocal_casadi.effects import JointCompliance

    panda = load_robot(UR10.parents[1] / "panda-mukca" / "robot.yaml")
    assert not panda.has_inertia  # the lumped form
    written = JointCompliance((6,), robot=panda)
    names = written.parameter_names()
    rng = np.random.default_rng(3)
    for _ in range(5):
        moved = panda.with_parameters(panda.parameter_vector()
                                      + 1e-3 * rng.standard_normal(len(panda.parameters())))
        read = JointCompliance((6,), robot=moved).with_terms_named(names, moved)
        assert read.parameter_names() == names


def test_band_of_one_robots_rms_matches_monte_carlo(tmp_path):
    """The band holds one robot's RMS over the work cell for 80% of posterior draws: the
    errors drawn from the posterior, the numpy reference kinematics moved, the best rigid
    motion removed in closed form, at the prediction's own poses (the fit readings)."""
    sim = simulate(UR10, "tracker_points", out_dir=tmp_path / "fit", rows=30, noise=2e-4,
                   geometric_errors=ERRORS, seed=8, progress=False)
    result = calibrate_job([load_dataset(sim.dataset_path)], (), JobOptions(diagnose=False))
    robot = result.robot_calibrated
    assert not robot.has_tool  # the tool pose is the flange pose: the reference below
    names = ("target_x", "target_y", "target_z")
    point = np.array([result.mounted_geometric[n] for n in names])
    prediction = predict(result, robot, point, names, structured=0.0, region=region_of(result),
                         region_kind=MEASURED)
    unexplained = 0.0 if result.unexplained is None else result.unexplained.rms
    Q = np.asarray(result.residuals[0].joints, dtype=float)
    assert prediction.samples == len(Q)
    draws = 400
    rms = np.sqrt(_posterior_rms(result, robot, names, point, Q, draws, seed=12) ** 2
                  + unexplained**2)
    low, high = prediction.band
    assert low < prediction.rms < high
    # Each tail holds BAND[0] = 10% of the draws; a share of `draws` Bernoulli trials has
    # standard deviation sqrt(p (1 - p) / draws): 3 of them.
    for share, expected in ((np.mean(rms < low), BAND[0]), (np.mean(rms > high), 1 - BAND[1])):
        assert share == pytest.approx(expected, abs=3 * np.sqrt(expected * (1 - expected) / draws))
    # The expected mean square is the prediction's (relative spread of a mean of squares
    # at most sqrt(2 / draws), 3 of them).
    assert np.sqrt(np.mean(rms**2)) == pytest.approx(prediction.rms, rel=3 * np.sqrt(2 / draws))
