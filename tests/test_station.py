"""One instrument station across datasets: datasets naming the same ``station`` share one
placement of the instrument, and held-out data of that station are measured in the frame
the calibration fitted, so that a wrong placement shows in their errors instead of being
refitted away. Checked on a simulated truth (one tracker placement for every reading)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal_casadi.calibration import calibrate
from robocal_casadi.calibration.evaluation import evaluate, models_for
from robocal_casadi.calibration.problem import Problem, StationFrames
from robocal_casadi.cli import main
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.instruments.simulate import simulate

UR10 = Path(__file__).resolve().parents[1] / "robocal_casadi" / "data" / "ur10-ipa" / "robot.yaml"
ERRORS = {"a2": 4e-4, "d4": -3e-4, "alpha3": 5e-4, "theta2": 3e-4}
NOISE = 2e-5  # [m] per coordinate
PARTS = {"first": (0, 60), "second": (60, 120), "held": (120, 180)}
STATION = "cell-A"
# The RMS of a 3-D point error with independent noise NOISE per coordinate is
# sqrt(3) NOISE; 60 points put the sample RMS within about 10% of it (chi-square with
# 180 degrees of freedom, 3 sigma), a fitted model adds its estimation error (a few
# parameters against 120 points): 1.5 sqrt(3) NOISE bounds both.
NOISE_RMS = np.sqrt(3) * NOISE
AT_NOISE = 1.5 * NOISE_RMS


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """One tracker placement seen in 180 readings, split into three tables."""
    folder = tmp_path_factory.mktemp("station")
    sim = simulate(UR10, "tracker_points", out_dir=folder / "sim", rows=180, noise=NOISE,
                   geometric_errors=ERRORS, seed=11, progress=False)
    return sim


def _split(sim, folder: Path, station: str | None) -> dict[str, Path]:
    """The simulated table cut into ``PARTS``, one dataset file each (``station`` given)."""
    lines = sim.table_path.read_text().splitlines()
    header, rows = lines[0], lines[1:]
    content = yaml.safe_load(sim.dataset_path.read_text())
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "robot.yaml").write_text(sim.robot_path.read_text())
    out = {}
    for name, (start, stop) in PARTS.items():
        (folder / f"{name}.csv").write_text("\n".join([header] + rows[start:stop]) + "\n")
        entry = dict(content, data=f"{name}.csv")
        if station is not None:
            entry["station"] = station
        (folder / f"{name}.yaml").write_text(yaml.safe_dump(entry, sort_keys=False))
        out[name] = folder / f"{name}.yaml"
    return out


def _rms(errors) -> float:
    flat = np.concatenate(errors)
    return float(np.sqrt(np.mean(flat**2)))


def test_datasets_of_one_station_share_one_placement(simulated, tmp_path):
    shared = _split(simulated, tmp_path / "shared", STATION)
    apart = _split(simulated, tmp_path / "apart", None)
    data = [load_dataset(shared[n]) for n in ("first", "second")]
    assert all(d.station == STATION for d in data)
    one = Problem(data[0].robot, models_for(data))
    two = Problem(data[0].robot, models_for([load_dataset(apart[n])
                                             for n in ("first", "second")]))
    assert one.mask("placement").sum() == 6
    assert two.mask("placement").sum() == 12
    assert all(n.startswith(f"station:{STATION}/") for n in np.asarray(one.unknowns.names)[
        one.mask("placement")])

    result = calibrate(data, loss="linear", diagnose=False)
    placement = [n for n in result.placement if "instrument" in n]
    assert len(placement) == 6
    # one frame for both tables: every reading is explained at the noise level
    assert result.fit.rms_geometric < AT_NOISE


def test_fixed_station_shows_a_wrong_placement_that_a_refit_hides(simulated, tmp_path):
    """With the true robot and target, the held-out error under the station's placement
    is the noise; that placement moved by ``shift`` makes every point err by the shift,
    while refitting the placement on the held-out points hides it."""
    paths = _split(simulated, tmp_path / "shared", STATION)
    truth = simulated.truth
    target = {f"target_{a}": float(v) for a, v in zip("xyz", truth.mounted["target"])}
    fit = [load_dataset(paths["first"])]
    held = [load_dataset(paths["held"])]
    problem, x = evaluate(truth.robot, fit, (), target)
    frames = StationFrames.of(problem, x)
    name = f"station:{STATION}/instrument_x"
    assert set(frames.values) >= {name}

    right, x_right = evaluate(truth.robot, held, (), target, label_prefix="validation:",
                              frames=frames)
    assert right.placement_frame(right.models[0]) == f"station {STATION} (fixed)"
    assert _rms(right.errors(x_right)) < AT_NOISE

    shift = 1e-3  # [m] along the tracker's x axis
    wrong = StationFrames({**frames.values, name: frames.values[name] + shift}, frames.leaders)
    moved, x_moved = evaluate(truth.robot, held, (), target, label_prefix="validation:",
                              frames=wrong)
    # every point errs by the shift plus its noise: RMS^2 = shift^2 + 3 NOISE^2 up to the
    # sample's spread (a few NOISE)
    assert _rms(moved.errors(x_moved)) == pytest.approx(np.hypot(shift, NOISE_RMS),
                                                        abs=4 * NOISE)
    refitted, x_refitted = evaluate(truth.robot, held, (), target, label_prefix="validation:")
    assert refitted.placement_frame(refitted.models[0]) == \
        f"station {STATION}, refitted on the validation data"
    assert _rms(refitted.errors(x_refitted)) < AT_NOISE


def test_validation_keeps_the_station_of_the_fit(simulated, tmp_path):
    """End to end: result.json and the report say which frame each held-out dataset
    was judged in, and the held frame of a right calibration leaves the noise."""
    outcomes = {}
    for station in (STATION, None):
        paths = _split(simulated, tmp_path / str(station), station)
        out = tmp_path / f"out-{station}"
        report = [] if station is not None else ["--no-report"]
        assert main(["calibrate", str(paths["first"]), str(paths["second"]), "--validate",
                     str(paths["held"]), "--out", str(out), "--loss", "linear",
                     "--no-diagnose", "--quiet", *report]) == 0
        outcomes[station] = json.loads((out / "result.json").read_text())
    fixed = outcomes[STATION]["validation"]
    refit = outcomes[None]["validation"]
    assert [d["validation_frame"] for d in fixed["datasets"]] == [f"station {STATION} (fixed)"]
    assert [d["validation_frame"] for d in refit["datasets"]] == [
        "refitted on the validation data"]
    assert "validation_frame" not in outcomes[STATION]["fit"]["datasets"][0]
    assert fixed["rms_final"] < AT_NOISE / 1e-3  # result.json lengths are in mm
    report = (tmp_path / f"out-{STATION}" / "report.html").read_text()
    assert f"station {STATION} (fixed)" in report and "measured in the robot" in report


def test_station_must_be_text(simulated, tmp_path, capsys):
    paths = _split(simulated, tmp_path / "bad", STATION)
    content = yaml.safe_load(paths["first"].read_text())
    content["station"] = ["cell-A", "cell-B"]
    paths["first"].write_text(yaml.safe_dump(content))
    out = tmp_path / "out"
    status = main(["calibrate", str(paths["first"]), "--out", str(out), "--no-report"])
    err = capsys.readouterr().err.strip()
    assert status == 2, err
    assert len(err.splitlines()) == 1
    assert "first.yaml" in err and "station" in err and "cell-B" in err
    assert not out.exists()
