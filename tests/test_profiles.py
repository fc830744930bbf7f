"""Controller profiles: the calibration restricted to a controller's parameters, with the
accuracy that costs reported against the unrestricted calibration of the same data."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from urdf_robots import ur10_urdf, write

from robocal_casadi.cli import main
from robocal_casadi.formats import profile_parameters
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.robot import load_robot

UR10_DH = (Path(__file__).resolve().parents[1] / "robocal_casadi" / "data" / "ur10-ipa"
           / "robot.yaml")
# beta3 tilts joint 3's axis: plain DH cannot hold it (joints 2, 3, 4 are parallel)
ERRORS = {"a2": 4e-4, "d4": -3e-4, "theta5": -6e-4, "beta3": 4e-4}


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    folder = tmp_path_factory.mktemp("profiles")
    fit = simulate(UR10_DH, "tracker_points", out_dir=folder / "fit", rows=50, noise=2e-5,
                   geometric_errors=ERRORS, seed=1, progress=False)
    val = simulate(UR10_DH, "tracker_points", out_dir=folder / "val", rows=40, noise=2e-5,
                   geometric_errors=ERRORS, seed=2, progress=False)
    return fit.dataset_path, val.dataset_path


def _run(data, out: Path, profile: str, capsys, status: int = 0) -> tuple[dict, str]:
    fit, val = data
    assert main(["calibrate", str(fit), "--validate", str(val), "--out", str(out),
                 "--no-diagnose", "--no-report", "--profile", profile]) == status
    return json.loads((out / "result.json").read_text()), capsys.readouterr().out


def test_dh_only_holds_beta_and_reports_the_cost(data, tmp_path, capsys):
    result, terminal = _run(data, tmp_path / "out", "dh-only", capsys)
    block = result["profile"]
    assert block["name"] == "dh-only" and "beta3" in block["held"]
    assert not any(n.startswith("beta") for n in block["parameters"])
    # the truth has a beta: without it the fit is measurably worse, and says so
    assert block["fit"]["rms_geometric"] > 1.5 * block["fit"]["rms_geometric_unrestricted"]
    assert block["validation"]["rms_geometric"] > block["validation"]["rms_geometric_unrestricted"]
    assert block["fit"]["rms_geometric"] == pytest.approx(result["fit"]["rms_geometric"])
    assert "profile dh-only" in terminal and "unrestricted" in terminal
    calibrated = load_robot(tmp_path / "out" / "robot_calibrated.yaml")
    assert all(j.beta == 0.0 for j in calibrated.joints)
    assert calibrated.joints[1].a != pytest.approx(-0.612, abs=1e-6)  # a2 was fitted


def test_kuka_fits_only_zero_offsets_base_and_tool(data, tmp_path, capsys):
    # The truth's errors lie mostly in lengths and a tilt the KUKA set cannot hold: its fit
    # does not carry over to the held-out data, so the job refuses it (exit 3) and the
    # robot file stays nominal.
    result, terminal = _run(data, tmp_path / "out", "kuka", capsys, status=3)
    assert terminal.startswith("NOT BETTER THAN DOING NOTHING")
    assert result["recommended"] in ("nominal", "instrument_only")
    validation = result["validation"]
    assert validation["rms_geometric"] > validation["rms_nominal"]
    nominal = load_robot(UR10_DH)
    calibrated = load_robot(tmp_path / "out" / "robot_calibrated.yaml")
    assert np.array_equal(calibrated.parameter_vector(), nominal.parameter_vector())
    estimates = {p["name"]: p for p in result["parameters"]}
    assert estimates["theta5"]["estimate"] != 0.0  # theta5 was fitted
    for name in ("d2", "a2", "alpha2", "beta3", "d4"):
        assert estimates[name]["estimate"] == estimates[name]["nominal"]
    fitted = {p["name"] for p in result["parameters"] if p["identifiable"]}
    assert fitted <= set(profile_parameters("kuka", nominal))
    fit = result["profile"]["fit"]
    assert fit["rms_final"] > fit["rms_final_unrestricted"]


def test_ur_profile_of_a_urdf_robot_and_refusals(data, tmp_path, capsys):
    fit, _ = data
    write(fit.parent, "ur10.urdf", ur10_urdf())
    content = yaml.safe_load(fit.read_text())
    content.update(robot="ur10.urdf", tip_link="tool0")
    urdf_dataset = fit.parent / "urdf.yaml"
    urdf_dataset.write_text(yaml.safe_dump(content))
    assert main(["calibrate", str(urdf_dataset), "--out", str(tmp_path / "ur"), "--no-diagnose",
                 "--no-report", "--profile", "ur"]) == 0
    block = json.loads((tmp_path / "ur" / "result.json").read_text())["profile"]
    assert "x2" in block["parameters"] and "flange_x" not in block["parameters"]
    # the joint origins hold everything a full URDF calibration identifies here
    assert block["fit"]["rms_geometric"] == pytest.approx(
        block["fit"]["rms_geometric_unrestricted"], rel=1e-3)
    capsys.readouterr()
    assert main(["calibrate", str(urdf_dataset), "--out", str(tmp_path / "no"), "--no-diagnose",
                 "--no-report", "--profile", "dh-only"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "--profile" in error
    assert not (tmp_path / "no").exists()


def test_profile_sets():
    robot = load_robot(UR10_DH)
    assert set(profile_parameters("ur", robot)) == {f"{s}{i}" for i in range(1, 7)
                                                     for s in ("theta", "d", "a", "alpha")}
    kuka = profile_parameters("kuka", robot)
    assert [n for n in kuka if not n.startswith(("base_", "tool_"))] == [
        f"theta{i}" for i in range(1, 7)]
    assert np.isin(["base_x", "tool_rz"], kuka).all()
