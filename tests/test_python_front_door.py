"""The Python front door runs what the command line runs, in the files' units.

Each of ``robocal_casadi.fk``, ``calibrate``, ``plan``, ``track`` and ``compensate`` is run
beside its ``robocal`` verb on the same files, and their outputs are compared: the tables
the verbs write hold full-precision numbers, so the same computation gives the same
numbers. The units are checked against an independent statement of the same robot in
other units, and the compensated joints against the forward kinematics they must invert.
"""

from __future__ import annotations

import contextlib
import csv
import doctest
import io
import json
import pydoc
from pathlib import Path

import numpy as np
import pytest
from test_tracking import lissajous_joints, write_job

import robocal_casadi as rc
from robocal_casadi.cli import main
from robocal_casadi.common.units import Units
from robocal_casadi.model.examples import industrial_6r
from robocal_casadi.model.robot import save_robot

FRONT_DOOR = ("load_robot", "load_dataset", "fk", "calibrate", "plan", "track", "compensate")


def run(*words) -> str:
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        status = main([str(w) for w in words])
    assert status == 0, buffer.getvalue()
    return buffer.getvalue()


def read(path: Path) -> tuple[list[str], np.ndarray]:
    """Header and numbers (NaN for empty or text cells) of a CSV table."""
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))

    def number(cell: str) -> float:
        try:
            return float(cell)
        except ValueError:
            return np.nan

    return rows[0], np.array([[number(c) for c in row] for row in rows[1:]])


def write(path: Path, columns: list[str], rows) -> Path:
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(columns)
        writer.writerows([[repr(float(v)) for v in row] for row in rows])
    return path


@pytest.fixture(scope="module")
def cell(tmp_path_factory) -> dict[str, Path]:
    """Simulated tracker data of the example 6R (mm/deg) with errors given by name (so both
    tables come from one true robot) and joint compliance under a payload, calibrated
    once by ``robocal calibrate`` and once by ``rc.calibrate``."""
    folder = tmp_path_factory.mktemp("front-door")
    common = ["--example", "industrial_6r", "--kind", "tracker_points", "--noise", "0.01",
              "--error", "a2=0.3", "--error", "d4=-0.2", "--error", "alpha3=0.02",
              "--effect", "joint_compliance:2,3=5e-6", "--payload", "0,20"]
    run("simulate", *common, "--rows", "150", "--seed", "1", "--out", folder / "fit")
    run("simulate", *common, "--rows", "60", "--seed", "2", "--out", folder / "check")
    run("calibrate", folder / "fit" / "dataset.yaml", "--validate",
        folder / "check" / "dataset.yaml", "--no-report", "--out", folder / "cli")
    rc.calibrate([folder / "fit" / "dataset.yaml"], [rc.load_dataset(
        folder / "check" / "dataset.yaml")], report=False, out=folder / "py")
    return {"folder": folder, "robot": folder / "fit" / "robot.yaml",
            "dataset": folder / "fit" / "dataset.yaml", "cli": folder / "cli",
            "py": folder / "py"}


def readings(cell, rows: int = 20) -> np.ndarray:
    """Joint readings of the fit table, robot file units (deg)."""
    header, values = read(rc.load_dataset(cell["dataset"]).data_path)
    return values[:rows, [header.index(f"q{i}") for i in range(1, 7)]]


def test_the_seven_are_exported_with_our_help():
    for name in FRONT_DOOR:
        function = getattr(rc, name)
        assert name in rc.__all__ and function.__module__ == "robocal_casadi.api", name
        text = pydoc.render_doc(function)
        assert "units" in text and ">>> " in text, name
    text = pydoc.render_doc(rc.fk)
    assert "Tool poses (N x 7)" in text and "world frame" in text


def test_fk_gives_the_poses_robocal_fk_writes(cell, tmp_path):
    q = readings(cell)
    joints = write(tmp_path / "joints.csv", [f"q{i}" for i in range(1, 7)], q)
    run("fk", cell["robot"], joints, "--out", tmp_path / "poses.csv")
    header, written = read(tmp_path / "poses.csv")
    # every input column is copied through, the readings included, then the pose
    assert header == [*(f"q{i}" for i in range(1, 7)), "x", "y", "z", "qw", "qx", "qy", "qz"]
    assert np.array_equal(written[:, :6], q)
    assert np.array_equal(rc.fk(cell["robot"], q), written[:, 6:])
    run("fk", cell["robot"], joints, "--calibrated", cell["cli"], "--out",
        tmp_path / "calibrated.csv")
    assert np.array_equal(rc.fk(rc.load_robot(cell["robot"]), q, calibrated=cell["cli"]),
                          read(tmp_path / "calibrated.csv")[1][:, 6:])


def test_fk_with_effects_gives_what_robocal_fk_writes(cell, tmp_path):
    assert (cell["cli"] / "effects_calibrated.yaml").is_file()  # the effects are exercised
    q = readings(cell)
    payload = np.linspace(0.0, 20.0, len(q))
    joints = write(tmp_path / "joints.csv", [*(f"q{i}" for i in range(1, 7)), "payload"],
                   np.column_stack([q, payload]))
    run("fk", cell["robot"], joints, "--calibrated", cell["cli"], "--with-effects", "--out",
        tmp_path / "poses.csv")
    _, written = read(tmp_path / "poses.csv")
    poses = rc.fk(cell["robot"], q, calibrated=cell["cli"], with_effects=True, payload=payload)
    assert np.array_equal(poses, written[:, 7:])  # q1..q6 and payload copied through first
    geometric = rc.fk(cell["robot"], q, calibrated=cell["cli"])
    # The payload bends the arm: the effects move the tool by far more than rounding.
    assert np.abs(poses[-1, :3] - geometric[-1, :3]).max() > 1e-3  # mm


def test_fk_takes_and_gives_the_files_units(cell, tmp_path):
    """The same robot written in m/rad: readings in rad give the same poses in m."""
    robot = rc.load_robot(cell["robot"])
    save_robot(robot.with_units(Units("m", "rad")), tmp_path / "robot_m.yaml")
    q = readings(cell, 5)
    in_mm = rc.fk(cell["robot"], q)
    in_m = rc.fk(tmp_path / "robot_m.yaml", np.radians(q))
    assert np.allclose(in_m[:, :3] * 1000.0, in_mm[:, :3], rtol=0, atol=1e-9)
    assert np.allclose(in_m[:, 3:], in_mm[:, 3:], rtol=0, atol=1e-12)
    with pytest.raises(rc.InputError, match="q2"):
        rc.fk(cell["robot"], np.radians(q) * 0 + [0, 400, 0, 0, 0, 0])  # beyond the limits


def test_calibrate_writes_what_robocal_calibrate_writes(cell):
    by_cli = json.loads((cell["cli"] / "result.json").read_text())
    by_python = json.loads((cell["py"] / "result.json").read_text())
    assert by_python["recommended"] == by_cli["recommended"]
    assert [e["name"] for e in by_python["effects"]] == [e["name"] for e in by_cli["effects"]]
    for mine, theirs in zip(by_python["parameters"], by_cli["parameters"], strict=True):
        assert mine["name"] == theirs["name"]
        assert mine["estimate"] == pytest.approx(theirs["estimate"], rel=1e-9, abs=1e-12)
    assert (cell["py"] / "robot_calibrated.yaml").read_text() == \
        (cell["cli"] / "robot_calibrated.yaml").read_text()


def test_compensate_gives_the_joints_robocal_compensate_writes(cell, tmp_path):
    q = readings(cell, 6)
    targets = rc.fk(cell["robot"], q, calibrated=cell["cli"])
    table = write(tmp_path / "targets.csv", ["x", "y", "z", "qw", "qx", "qy", "qz"], targets)
    run("compensate", cell["robot"], table, "--calibrated", cell["cli"], "--out",
        tmp_path / "joints.csv")
    header, written = read(tmp_path / "joints.csv")
    commands = rc.compensate(cell["robot"], targets, calibrated=cell["cli"])
    assert commands.status == ("ok",) * len(q)
    columns = [header.index(f"q{i}") for i in range(1, 7)]
    assert np.array_equal(commands.joints, written[:, columns])
    # Independent of how they were found: the joints put the calibrated tool on the target.
    reached = rc.fk(cell["robot"], commands.joints, calibrated=cell["cli"])
    assert np.abs(reached[:, :3] - targets[:, :3]).max() < 1e-6  # mm
    assert np.abs(np.abs(np.sum(reached[:, 3:] * targets[:, 3:], axis=1)) - 1).max() < 1e-9


def test_plan_designs_what_robocal_plan_designs(cell, tmp_path):
    run("plan", cell["dataset"], "--count", "12", "--seed", "3", "--no-refine", "--out",
        tmp_path / "plan.csv")
    header, written = read(tmp_path / "plan.csv")
    planned = rc.plan(cell["dataset"], 12, seed=3, refine=False)
    assert list(planned.columns) == header
    mine = np.array([[np.nan if c in ("", None) else float(c) for c in row]
                     for row in planned.rows])
    assert np.array_equal(mine, written, equal_nan=True)
    assert np.isnan(planned.column("x")).all()  # the operator measures these
    q2 = planned.column("q2")
    assert np.abs(q2).max() > 2 * np.pi  # degrees, as the dataset's units say


def test_track_solves_what_robocal_track_solves(tmp_path):
    robot = industrial_6r()
    job, _ = write_job(tmp_path, robot, lissajous_joints("industrial_6r", 12)[:12])
    run("track", job, "--out", tmp_path / "joints.csv")
    header, written = read(tmp_path / "joints.csv")
    tracked = rc.track(job)
    assert tracked.columns() == header
    assert tracked.status == ("ok",) * 12
    assert np.array_equal(tracked.joints, written[:, 1:7])
    assert np.array_equal(tracked.time, written[:, 0])


@pytest.mark.parametrize("name", ["load_robot", "load_dataset", "fk"])
def test_the_docstring_examples_on_the_shipped_data_run(name, monkeypatch):
    """The examples that use the data shipped with the package print what they show (the
    others name the user's own files)."""
    monkeypatch.chdir(Path(__file__).resolve().parents[1])
    test = doctest.DocTestFinder().find(getattr(rc, name), name, globs=vars(rc).copy())[0]
    test.examples = [e for e in test.examples  # a user's own file cannot be run here
                     if ".yaml" not in e.source or "robocal_casadi/data/" in e.source]
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    assert test.examples and runner.run(test, out=lambda text: None).failed == 0
