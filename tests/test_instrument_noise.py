"""The instrument's own noise: declared or default, and what remains beside it."""

from __future__ import annotations

import csv
import json
import math
from collections import Counter

import numpy as np
import pytest

from robocal_casadi import calibrate, load_dataset
from robocal_casadi.calibration.remainder import NOISE_CAP, noise_limit
from robocal_casadi.cli import main
from robocal_casadi.errors import InputError
from robocal_casadi.instruments import model_for
from robocal_casadi.instruments.noise import expected_rms
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import ROBOTS

NOISE = 2e-5  # [m] per coordinate


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """Tracker data with noise alone beyond a geometric error (the noise declared)."""
    root = tmp_path_factory.mktemp("noise")
    return simulate(ROBOTS["industrial_6r"](), "tracker_points", out_dir=root / "clean",
                    rows=200, noise=NOISE, seed=3, geometric_errors={"a2": 3e-4},
                    progress=False)


def _with_noise(simulated, tmp_path, value: str):
    """The simulated dataset file with ``instrument_noise: <value>`` in place of its own."""
    text = simulated.dataset_path.read_text().splitlines()
    text = [line for line in text if not line.startswith("instrument_noise")]
    out = simulated.dataset_path.parent / f"{tmp_path.name}.yaml"
    out.write_text("\n".join(text + [f"instrument_noise: {value}"]) + "\n")
    return out


def test_simulate_declares_its_noise_in_the_file_unit(clean):
    dataset = load_dataset(clean.dataset_path)
    assert dataset.instrument_noise is not None
    assert dataset.instrument_noise.source == "declared"
    assert dataset.instrument_noise.a == pytest.approx(NOISE, rel=1e-12)


def test_a_tracker_noise_grows_with_range_as_declared(clean, tmp_path):
    path = _with_noise(clean, tmp_path, "{a: 0.01, b_per_m: 0.004}")  # file unit: mm
    dataset = load_dataset(path)
    model = model_for(dataset, "d")
    distance = np.linalg.norm(dataset.measured, axis=1)  # [m] from the tracker's origin
    sigma = 1e-5 + 4e-6 * distance
    assert expected_rms([model]) == pytest.approx(math.sqrt(3 * np.mean(sigma ** 2)), rel=1e-12)


def test_without_a_declaration_each_instrument_says_its_default(tmp_path):
    data = simulate(ROBOTS["industrial_6r"](), "artifact_touches", out_dir=tmp_path / "t",
                    rows=4, noise=0.0, seed=1, progress=False).load()
    model = model_for(data, "d")
    assert data.instrument_noise is None and model.instrument_noise.source == "default"
    assert model.instrument_name == "touch probe"
    # three coordinates per touch, each the deviation from its socket fitted as the mean of
    # the socket's n touches (a sqrt(1 - 1/n)); none on the certified distances between
    # located sockets
    rows = list(csv.DictReader((tmp_path / "t" / "touches.csv").open()))
    counts = Counter((r["pose"], r["point"]) for r in rows)
    assert len(set(counts.values())) == 1
    n = next(iter(counts.values()))
    touches = ~model.certified_entries()
    assert touches.sum() == 3 * len(rows)
    expected = model.default_noise[0] * np.sqrt(1.0 - 1.0 / n)
    assert np.allclose(model.entry_noise()[touches], expected, rtol=1e-15, atol=0)
    assert np.all(model.entry_noise()[~touches] == 0.0)


@pytest.mark.parametrize("value,where", [
    ("-0.01", "instrument_noise"), ("0", "instrument_noise"), ("lots", "instrument_noise"),
    ("500", "instrument_noise"), ("{a: 0.01, c: 1}", "instrument_noise.c"),
    ("{b_per_m: 0.01}", "instrument_noise.a"), ("{a: 0.01, b_per_m: -1}",
                                                 "instrument_noise.b_per_m")])
def test_a_bad_declaration_names_the_key(clean, tmp_path, value, where, capsys):
    path = _with_noise(clean, tmp_path, value)
    with pytest.raises(InputError) as error:
        load_dataset(path)
    assert error.value.where == where, error.value
    assert main(["calibrate", str(path), "--out", str(tmp_path / "out"), "--no-report"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and where in err[0] and path.name in err[0], err
    assert not (tmp_path / "out").exists()


def test_only_a_tracker_may_declare_growth_with_range(tmp_path):
    data = simulate(ROBOTS["industrial_6r"](), "sphere_laser", out_dir=tmp_path / "l",
                    rows=30, noise=1e-5, seed=1, progress=False)
    path = _with_noise(data, tmp_path, "{a: 0.01, b_per_m: 0.001}")
    with pytest.raises(InputError, match="only a tracker"):
        load_dataset(path)


def test_noise_alone_is_called_a_noise_floor(clean, capsys):
    result = calibrate([clean.load()])
    left = result.remainder
    assert left is not None and left.basis == "cross-validation"
    # the held-out RMS of noise alone is the noise's, inflated by the unknowns fitted
    assert 0.85 < left.ratio <= left.limit, left
    assert left.noise_rms == pytest.approx(NOISE * math.sqrt(3), rel=1e-12)
    written = result.to_json()["unexplained"]
    assert written["is_noise"] and written["instrument_noise"]["value"] == pytest.approx(
        NOISE / 1e-3) and written["instrument_noise"]["unit"] == "mm"
    assert "a noise floor" in left.sentence(result.units)


def test_a_remainder_beyond_the_noise_is_never_a_noise_floor(tmp_path, capsys):
    simulated = simulate(ROBOTS["industrial_6r"](), "tracker_points", out_dir=tmp_path / "c",
                         rows=200, noise=NOISE, seed=4,
                         effects={"joint_compliance": {2: 3e-6, 3: 3e-6}},
                         progress=False)
    assert main(["calibrate", str(simulated.dataset_path), "--out", str(tmp_path / "out"),
                 "--no-diagnose", "--no-report"]) == 0
    out = capsys.readouterr().out
    written = json.loads((tmp_path / "out" / "result.json").read_text())["unexplained"]
    assert not written["is_noise"] and written["ratio"] > NOISE_CAP, written
    assert written["instrument_noise"]["source"] == "declared"
    remains = [line for line in out.splitlines() if line.startswith("remains:")]
    assert len(remains) == 1 and "lacks" in remains[0] and "times the tracker's noise" in \
        remains[0], out
    assert "noise floor" not in out and "consistent with noise" not in out, out


def test_the_limit_follows_the_chi_square_spread():
    # many entries: only a few percent above the noise; few: more; never above the cap
    assert 1.0 < noise_limit(30000, 40) < 1.05
    assert 1.2 < noise_limit(30, 0) < NOISE_CAP
    assert noise_limit(5, 10) == NOISE_CAP


def test_the_estimates_uncertainty_on_held_out_data_agrees_with_monte_carlo(tmp_path):
    """``estimation_rms`` (linear, placements projected out) against perturbed robots whose
    held-out placements are fitted again (the nonlinear refit validation runs), on
    noise-free readings of the nominal robot."""
    from robocal_casadi.calibration.evaluation import evaluate
    from robocal_casadi.calibration.remainder import estimation_rms

    robot = ROBOTS["industrial_6r"]()
    data = simulate(robot, "tracker_points", out_dir=tmp_path / "held", rows=40, noise=0.0,
                    seed=5, progress=False)
    datasets = [load_dataset(data.dataset_path)]
    problem, x = evaluate(robot, datasets, (), {}, label_prefix="validation:")
    names = ("a2", "alpha3", "d4", "theta5")
    std = np.array([2e-4, 3e-4, 2e-4, 4e-4])  # [m, rad]
    free = np.zeros(len(x), dtype=bool)
    free[problem.unknowns.indices(names)] = True
    covariance = np.diag(std**2)
    predicted = estimation_rms(problem, x, free, covariance, problem, x)
    rng = np.random.default_rng(11)
    squares = []
    for _ in range(100):
        values = {n: float(problem.initial()[problem.unknowns.index(n)] + d)
                  for n, d in zip(names, rng.normal(size=4) * std)}
        moved, x_moved = evaluate(robot, datasets, (), values, label_prefix="validation:")
        squares.append(np.mean(moved.errors(x_moved)[0] ** 2))
    monte_carlo = math.sqrt(np.mean(squares))
    # 100 draws of a mean square over four parameters: about 3.5% standard error on the
    # RMS; four of them, plus the small nonlinearity of sub-millimetre errors
    assert predicted == pytest.approx(monte_carlo, rel=0.15)
