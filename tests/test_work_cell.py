"""The region the predicted accuracy is stated over (a declared work cell, else the joint
ranges of the fit data) and the posterior it propagates when some residual entries are
certified geometry rather than readings (an artifact's known socket distances)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal_casadi.calibration.prior import Prior, posterior
from robocal_casadi.cli import main
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.job.accuracy import (
    DATA_RANGES,
    MEASURED,
    PARTLY_DECLARED,
    SAMPLES,
    predict,
    region_of,
)
from robocal_casadi.job.run import JobOptions, calibrate_job, measured

UR10 = Path(__file__).resolve().parents[1] / "robocal_casadi" / "data" / "ur10-ipa" / "robot.yaml"
ERRORS = {"a2": 4e-4, "d4": -3e-4, "alpha3": 5e-4}
CELL_Q6 = [-20.0, 30.0]  # [deg], the file's angle unit


@pytest.fixture(scope="module")
def tracker(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cell")
    return simulate(UR10, "tracker_points", out_dir=folder / "sim", rows=40, noise=2e-5,
                    geometric_errors=ERRORS, seed=5, progress=False)


def _with(sim, folder: Path, **keys) -> Path:
    """A copy of the simulated dataset file in ``folder`` with ``keys`` added."""
    folder.mkdir(parents=True, exist_ok=True)
    content = yaml.safe_load(sim.dataset_path.read_text())
    content.update(keys, robot=str(sim.robot_path), data=sim.table_path.name)
    (folder / sim.table_path.name).write_text(sim.table_path.read_text())
    path = folder / "dataset.yaml"
    path.write_text(yaml.safe_dump(content, sort_keys=False))
    return path


def test_declared_work_cell_is_the_prediction_region(tracker, tmp_path):
    path = _with(tracker, tmp_path / "declared", work_cell={"q6": CELL_Q6})
    dataset = load_dataset(path, allow_outside_data=True)
    assert dataset.work_cell[5] == pytest.approx(tuple(np.radians(CELL_Q6)))
    assert all(c is None for c in dataset.work_cell[:5])
    result = calibrate_job([dataset], (), JobOptions(diagnose=False, loss="linear"))
    result = measured(result, [dataset])
    predicted = result.predicted_accuracy
    data = region_of(result)
    expected = list(data[:5]) + [tuple(np.radians(CELL_Q6))]
    assert predicted.region_kind == PARTLY_DECLARED
    assert np.allclose(predicted.region, expected, atol=1e-12)
    # the same prediction as asked for directly over that box, and another than over the
    # data's own ranges (q6 moves the reflector, so its range changes the figure)
    assert result.delivered is not None
    names = tuple(result.delivered.mounted)[:3]
    point = [result.delivered.mounted[n] for n in names]
    direct = predict(result, result.robot_calibrated, point, names,
                     region=tuple(expected), region_kind=PARTLY_DECLARED)
    assert predicted.rms == pytest.approx(direct.rms, rel=1e-12)
    default = predict(result, result.robot_calibrated, point, names)
    assert default.region_kind == DATA_RANGES
    assert default.rms != pytest.approx(predicted.rms, rel=1e-6)
    block = predicted.to_json(1e-3, "mm")["region"]
    assert block["kind"] == PARTLY_DECLARED


def test_measured_poses_as_the_work_cell(tracker, tmp_path):
    """``work_cell: measured``: the prediction is made at the fit data's own readings."""
    path = _with(tracker, tmp_path / "measured", work_cell="measured")
    dataset = load_dataset(path, allow_outside_data=True)
    result = calibrate_job([dataset], (), JobOptions(diagnose=False, loss="linear"))
    predicted = measured(result, [dataset]).predicted_accuracy
    assert predicted.region_kind == MEASURED
    assert predicted.samples == len(predicted.errors) == min(SAMPLES, dataset.rows)
    assert "the poses the data cover" in predicted.sentence(1e-3, "mm")


@pytest.mark.parametrize("cell, fragment", [
    ("everywhere", "'measured'"),
    ({"q6": [30, -20]}, "low below high"),
    ({"q6": [-20, 30, 40]}, "work_cell.q6"),
    ({"q9": [0, 1]}, "'q9'"),
    ({"q2": [-1000, 0]}, "beyond the robot's limits"),
    ([[-20, 30]], "expected a mapping"),
])
def test_bad_work_cell_is_refused_with_one_line(tracker, tmp_path, capsys, cell, fragment):
    path = _with(tracker, tmp_path / "bad", work_cell=cell)
    out = tmp_path / "out"
    status = main(["calibrate", str(path), "--out", str(out), "--no-report",
                   "--allow-outside-data"])
    err = capsys.readouterr().err.strip()
    assert status == 2, err
    assert len(err.splitlines()) == 1
    assert "dataset.yaml" in err and "work_cell" in err and fragment in err
    assert not out.exists()


def test_certified_entries_give_the_covariance_of_the_estimate():
    """A linear model whose last rows are exact constraints (no noise) fitted by plain
    least squares with a prior: the covariance ``posterior`` gives with those rows
    certified matches the spread of the estimate over Monte Carlo draws of the noise and
    of the parameters about the prior's centre, while counting them as noisy overstates it."""
    rng = np.random.default_rng(3)
    noisy, exact, n = 40, 6, 5
    J = rng.normal(size=(noisy + exact, n))
    J[noisy:] *= 3.0  # constraints that carry much of the information
    sigma, tolerance = 0.1, np.full(n, 0.5)
    certified = np.r_[np.zeros(noisy, bool), np.ones(exact, bool)]
    prior = Prior(tuple(f"p{i}" for i in range(n)), np.arange(n), np.zeros(n), tolerance,
                  sigma)
    A = J.T @ J + np.diag(sigma**2 / tolerance**2)
    draws = 4000
    errors = np.empty((draws, n))
    for k in range(draws):
        theta = rng.normal(0.0, tolerance)
        y = J @ theta + np.where(certified, 0.0, rng.normal(0.0, sigma, noisy + exact))
        errors[k] = np.linalg.solve(A, J.T @ y) - theta
    sampled = np.cov(errors.T)
    # the residual only sets the noise estimate: one at exactly sigma
    r = np.r_[np.full(noisy, sigma), np.zeros(exact)] * np.sqrt((noisy + exact - n) / noisy)
    stated = posterior(J, r, np.arange(n), prior, sigma=sigma, certified=certified)
    counted = posterior(J, r, np.arange(n), prior, sigma=sigma)
    scale = stated.sigma**2 / sigma**2  # the noise estimate's own deviation from sigma
    # a sample variance of `draws` Gaussian draws: relative spread sqrt(2/draws), 4 sigma
    bound = 4 * np.sqrt(2 / draws)
    assert np.diag(stated.covariance) / scale == pytest.approx(np.diag(sampled), rel=bound)
    assert np.all(np.diag(counted.covariance) > (1 + bound) * np.diag(sampled) * scale)


def test_a_figure_far_above_the_held_out_rms_names_what_carries_it(tmp_path):
    """A cross bar sees distances only: over the poses the data cover the predicted tool
    error stands several times above the held-out RMS of the bar's distances. The
    statement then names the parameters whose remaining uncertainty carries it, each a
    part of the figure, with what would let the data see them."""
    from robocal_casadi.model.examples import industrial_6r
    from robocal_casadi.model.robot import save_robot

    save_robot(industrial_6r(), tmp_path / "robot.yaml")
    errors = {"a2": 3e-4, "alpha3": 3.5e-4, "d4": -2e-4, "theta5": 5e-4}
    sims = [simulate(tmp_path / "robot.yaml", "cross_bar", out_dir=tmp_path / name, rows=rows,
                     noise=1e-5, geometric_errors=errors, mounted_error=0.0, seed=seed,
                     progress=False) for name, rows, seed in (("fit", 40, 1), ("held", 20, 2))]
    out = tmp_path / "out"
    assert main(["calibrate", str(sims[0].dataset_path), "--validate", str(sims[1].dataset_path),
                 "--out", str(out), "--no-report", "--quiet"]) == 0
    import json

    result = json.loads((out / "result.json").read_text())
    stated = result["predicted_accuracy"]
    held_out = result["delivered"]["robot_calibrated.yaml"]["validation"]
    assert stated["rms"] > 2 * held_out  # the premise: a bar's distances see little
    named = stated["unseen"]
    assert named, stated
    assert all(u["to_see_it"] for u in named)
    # each named parameter carries at least a tenth of the mean square and at most the
    # whole (what knowing it would take off; correlated ones share a direction)
    assert all(0.1 * (1 - 1e-9) <= (u["rms"] / stated["rms"]) ** 2 <= 1 + 1e-9 for u in named)
