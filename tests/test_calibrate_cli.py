"""`robocal calibrate` end to end: outputs per docs/formats.md, refusals with exit 2."""

from __future__ import annotations

import json

import pytest

from robocal_casadi.cli import main
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import industrial_6r
from robocal_casadi.model.robot import load_robot


@pytest.fixture(scope="module")
def tracker(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tracker")
    robot = industrial_6r()
    errors = {"a2": 0.4e-3, "theta3": 0.3e-3, "alpha3": -0.2e-3, "d4": 0.3e-3}
    fit = simulate(robot, "tracker_points", out_dir=folder / "fit", rows=120, noise=1e-5,
                   geometric_errors=errors, seed=1, progress=False)
    val = simulate(robot, "tracker_points", out_dir=folder / "val", rows=60, noise=1e-5,
                   geometric_errors=errors, seed=2, progress=False)
    return fit, val


def test_writes_the_contract_files_in_the_robot_units(tracker, tmp_path, capsys):
    fit, val = tracker
    out = tmp_path / "out"
    code = main(["calibrate", str(fit.dataset_path), "--validate", str(val.dataset_path),
                 "--out", str(out), "--no-diagnose", "--no-report"])
    assert code == 0
    result = json.loads((out / "result.json").read_text())
    assert set(result) >= {"datasets", "convention", "parameters", "condition_number",
                           "effects", "fit", "validation"}
    assert result["fit"]["unit"] == "mm"  # the example robot's file units
    a2 = next(p for p in result["parameters"] if p["name"] == "a2")
    assert a2["unit"] == "mm" and a2["identifiable"]
    assert a2["estimate"] - a2["nominal"] == pytest.approx(0.4, abs=5 * a2["std"])
    calibrated = load_robot(out / "robot_calibrated.yaml")
    assert calibrated.joints[1].a == pytest.approx(a2["estimate"] * 1e-3, abs=1e-15)
    assert result["validation"]["rms_geometric"] < 0.1 * result["validation"]["rms_nominal"]
    assert "validation RMS [mm]" in capsys.readouterr().out
    # errors.csv beside it: every fitted and held-out reading, on its table line
    table = (out / "errors.csv").read_text().splitlines()
    assert table[0].startswith("dataset,role,line,")
    roles = [line.split(",")[1] for line in table[1:]]
    assert roles == ["fit"] * 120 + ["validation"] * 60


def test_too_few_rows_to_identify_is_refused(tracker, tmp_path, capsys):
    fit, _ = tracker
    lines = fit.table_path.read_text().splitlines()
    small = tmp_path / "small"
    small.mkdir()
    (small / "points.csv").write_text("\n".join(lines[:6]) + "\n")
    (small / "robot.yaml").write_text(fit.robot_path.read_text())
    (small / "dataset.yaml").write_text(fit.dataset_path.read_text())
    out = tmp_path / "out"
    code = main(["calibrate", str(small / "dataset.yaml"), "--out", str(out), "--no-report"])
    message = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(message) == 1
    assert "dataset.yaml" in message[0] and "cannot identify" in message[0]
    assert not out.exists()


def test_a_fit_that_does_not_converge_is_refused(tracker, tmp_path, capsys):
    fit, _ = tracker
    out = tmp_path / "out"
    code = main(["calibrate", str(fit.dataset_path), "--out", str(out), "--no-report",
                 "--no-diagnose", "--max-iterations", "1"])
    message = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(message) == 1
    assert "did not converge" in message[0] and "1 iterations" in message[0]
    assert not out.exists()


def test_datasets_of_different_robots_are_refused(tracker, tmp_path, capsys):
    fit, _ = tracker
    other = simulate(industrial_6r(), "tracker_points", out_dir=tmp_path / "other", rows=40,
                     seed=3, progress=False)
    robot_text = other.robot_path.read_text().replace("name: industrial-6r", "name: other")
    other.robot_path.write_text(robot_text.replace("d: 675.0", "d: 680.0"))
    code = main(["calibrate", str(fit.dataset_path), str(other.dataset_path), "--out",
                 str(tmp_path / "out"), "--no-report"])
    assert code == 2
    assert "share one robot" in capsys.readouterr().err
