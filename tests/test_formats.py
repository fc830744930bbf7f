"""Controller formats: one registry that ``export``, ``plan`` and ``calibrate --profile``
ask; a format written under tests/ registers in one line and ``robocal export`` writes it;
the DH table's content rebuilt into tool poses by a DH product written here, against
``robocal fk`` on the calibrated robot file."""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from robocal_casadi.cli import main
from robocal_casadi.common.table import read_table, write_table
from robocal_casadi.formats import (
    FORMATS,
    ModelFormat,
    model_formats,
    profile_parameters,
    profiles,
    program_formats,
    register,
)
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import ur_type
from robocal_casadi.model.robot import save_robot

MODULE = "joint_offsets_format"


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """A UR-type arm (standard DH, beta on joints 2 and 3) calibrated twice from simulated
    tracker data: unrestricted (its betas fitted) and with ``--profile dh-only``."""
    folder = tmp_path_factory.mktemp("formats")
    save_robot(ur_type(), folder / "ur.yaml")
    sim = simulate(folder / "ur.yaml", "tracker_points", out_dir=folder / "sim", rows=60,
                   noise=1e-5, geometric_errors=(4e-4, 4e-4), seed=3, progress=False)
    out = {}
    for name, extra in (("free", []), ("dh_only", ["--profile", "dh-only"])):
        out[name] = folder / name
        assert main(["calibrate", str(sim.dataset_path), "--out", str(out[name]),
                     "--no-diagnose", "--no-report", "--quiet", *extra]) == 0
    return out


@pytest.fixture
def offsets_format():
    """The format under tests/, registered for one test and taken out after."""
    sys.path.insert(0, str(Path(__file__).parent))
    try:
        yield importlib.import_module(MODULE)
    finally:
        sys.path.remove(str(Path(__file__).parent))
        FORMATS.pop("joint-offsets", None)
        sys.modules.pop(MODULE, None)


def test_the_built_in_formats_and_profiles_in_command_line_order():
    assert [f.flag for f in model_formats()] == ["--urdf", "--dh-table", "--ur-calibration"]
    assert [f.flag for f in program_formats()] == ["--urscript", "--krl", "--rapid"]
    assert [p.name for p in profiles()] == ["dh-only", "ur", "kuka"]
    assert all(f.expresses and f.help for f in FORMATS.values())


def test_a_format_from_tests_registers_in_one_line_and_export_writes_it(
        offsets_format, results, tmp_path, capsys):
    assert Path(offsets_format.__file__).read_text().count("register(") == 1
    assert list(FORMATS)[-1] == "joint-offsets"
    with pytest.raises(SystemExit):
        main(["export", "--help"])
    assert "--joint-offsets OUT.csv" in capsys.readouterr().out
    out = tmp_path / "offsets.csv"
    assert main(["export", str(results["free"]), "--joint-offsets", str(out)]) == 0
    # the expected offsets from the written files, read here with yaml and json alone
    calibrated = yaml.safe_load((results["free"] / "robot_calibrated.yaml").read_text())
    nominal = {row["name"]: row["nominal"]
               for row in json.loads((results["free"] / "result.json").read_text())["parameters"]}
    expected = [joint["theta"] - nominal[f"theta{i}"]
                for i, joint in enumerate(calibrated["joints"], start=1)]
    table = read_table(out)
    assert list(table.text("axis")) == [f"A{i}" for i in range(1, 7)]
    np.testing.assert_allclose(table.numbers("offset"), expected, rtol=0, atol=1e-12)
    assert np.max(np.abs(expected)) > 1e-4  # the calibration moved the zeros [deg]


def test_without_a_format_flag_export_names_every_registered_flag(offsets_format, results,
                                                                  capsys):
    assert main(["export", str(results["free"])]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1
    assert all(f.flag in error for f in model_formats()) and "--joint-offsets" in error


def test_a_taken_flag_or_profile_is_refused():
    with pytest.raises(ValueError, match="clashes with 'urdf'"):
        register(ModelFormat(name="other", flag="--urdf", metavar="X", help="h",
                             expresses="e", write=lambda source: ""))
    assert [f for f in FORMATS.values() if f.name == "other"] == []


def test_an_unknown_profile_lists_the_registered_ones():
    with pytest.raises(Exception, match=r"expected one of \['dh-only', 'ur', 'kuka'\]"):
        profile_parameters("fanuc", ur_type())


def _dh_poses(table_path: Path, robot_file: dict, Q_deg: np.ndarray) -> np.ndarray:
    """Tool positions [mm] from the DH table (T = Rz(theta + q) Tz(d) Tx(a) Rx(alpha)) and
    the base and tool frames of the robot file (R = Rz(y) Ry(p) Rx(r))."""
    table = read_table(table_path)
    theta, d, a, alpha = (np.radians(table.numbers("theta")), table.numbers("d"),
                          table.numbers("a"), np.radians(table.numbers("alpha")))

    def frame(entry) -> np.ndarray:
        r, p, y = np.radians(entry.get("rpy", [0, 0, 0]))
        cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
        T = np.eye(4)
        T[:3, :3] = [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]]
        T[:3, 3] = entry.get("xyz", [0, 0, 0])
        return T

    out = []
    for q in np.radians(Q_deg):
        T = frame(robot_file.get("base", {}))
        for i in range(len(q)):
            ct, st = np.cos(theta[i] + q[i]), np.sin(theta[i] + q[i])
            ca, sa = np.cos(alpha[i]), np.sin(alpha[i])
            T = T @ np.array([[ct, -st * ca, st * sa, a[i] * ct],
                              [st, ct * ca, -ct * sa, a[i] * st],
                              [0, sa, ca, d[i]], [0, 0, 0, 1]])
        out.append((T @ frame(robot_file.get("tool", {})))[:3, 3])
    return np.array(out)


def test_the_dh_table_gives_the_tool_poses_robocal_fk_gives(results, tmp_path):
    folder = results["dh_only"]
    out = tmp_path / "dh.csv"
    assert main(["export", str(folder), "--dh-table", str(out)]) == 0
    table = read_table(out)
    assert table.columns == ("joint", "type", "theta", "d", "a", "alpha")
    robot_file = yaml.safe_load((folder / "robot_calibrated.yaml").read_text())
    assert robot_file["units"] == {"length": "mm", "angle": "deg"}
    Q = np.random.default_rng(5).uniform(-170, 170, (12, 6))
    write_table(tmp_path / "q.csv", [f"q{i}" for i in range(1, 7)], Q)
    assert main(["fk", str(folder / "robot_calibrated.yaml"), str(tmp_path / "q.csv"),
                 "--out", str(tmp_path / "poses.csv")]) == 0
    poses = read_table(tmp_path / "poses.csv")
    expected = np.column_stack([poses.numbers(c) for c in ("x", "y", "z")])
    # both sides full precision: only the products' rounding apart [mm]
    np.testing.assert_allclose(_dh_poses(out, robot_file, Q), expected, rtol=0, atol=1e-9)


def test_a_fitted_beta_is_refused_by_the_dh_table_in_one_line(results, tmp_path, capsys):
    robot_file = yaml.safe_load((results["free"] / "robot_calibrated.yaml").read_text())
    assert any(joint.get("beta", 0.0) != 0.0 for joint in robot_file["joints"])
    out = tmp_path / "dh.csv"
    assert main(["export", str(results["free"]), "--dh-table", str(out)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "--dh-table" in error and "--profile dh-only" in error
    assert not out.exists()
