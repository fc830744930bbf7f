"""Degenerate data end in one line naming the table and what is degenerate, not a traceback.

Each case starts from a simulated dataset (valid: it calibrates) and breaks its rows so
that they carry no information: the robot never moved, two sockets of a placement
touched at one joint reading, a tracker that read one point throughout. Before the check
these crashed inside the engine (the length of a zero vector has no derivative: NaN in
the Jacobian, then "SVD did not converge" or "min() arg is an empty sequence").
"""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

import numpy as np
import pytest

from robocal_casadi.calibration.degeneracy import check_finite
from robocal_casadi.calibration.identifiability import analyse
from robocal_casadi.cli import main
from robocal_casadi.errors import RobocalError, SolverError
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import ROBOTS


@pytest.fixture(scope="module")
def valid(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("valid")
    six = ROBOTS["industrial_6r"]()
    simulate(six, "cross_bar", rows=10, seed=1, noise=1e-5, out_dir=root / "bar", progress=False)
    simulate(six, "artifact_touches", rows=3, sockets=3, touches=3, seed=1, noise=1e-5,
             out_dir=root / "art", progress=False)
    simulate(six, "tracker_points", rows=30, seed=1, noise=1e-5, out_dir=root / "tracker",
             progress=False)
    return root


def _edit(folder: Path, change) -> None:
    table = next(folder.glob("*.csv"))
    with open(table, newline="") as handle:
        rows = list(csv.reader(handle))
    header, body = rows[0], rows[1:]
    change(header, body)
    with open(table, "w", newline="") as handle:
        csv.writer(handle).writerows([header, *body])


def same_joints(header, body):
    """Every row at the first row's joints."""
    columns = [i for i, h in enumerate(header) if h[0] == "q" and h[1:].isdigit()]
    for row in body:
        for i in columns:
            row[i] = body[0][i]


def same_joints_per_pose(header, body):
    """Within each placement, every touch at that placement's first joints."""
    columns = [i for i, h in enumerate(header) if h[0] == "q" and h[1:].isdigit()]
    first = {}
    for row in body:
        first.setdefault(row[0], [row[i] for i in columns])
        for i, value in zip(columns, first[row[0]]):
            row[i] = value


def same_point(header, body):
    """The tracker read the first row's point in every row."""
    for name in ("x", "y", "z"):
        i = header.index(name)
        for row in body:
            row[i] = body[0][i]


@pytest.mark.parametrize("template, change, fragments", [
    ("bar", same_joints, ["touches.csv", "all 40 readings", "same joints", "never moved"]),
    ("art", same_joints, ["touches.csv", "all 27 readings", "same joints"]),
    ("tracker", same_joints, ["points.csv", "all 30 readings", "same joints"]),
    ("bar", same_joints_per_pose, ["touches.csv", "pose 0", "sockets A and C", "coincide"]),
    ("art", same_joints_per_pose, ["touches.csv", "pose 0", "hole_0 and hole_1", "coincide"]),
    ("tracker", same_point, ["points.csv", "measured points is the same"]),
], ids=["bar-same-joints", "artifact-same-joints", "tracker-same-joints",
        "bar-coinciding-sockets", "artifact-coinciding-sockets", "tracker-same-point"])
def test_degenerate_table_is_one_line(valid, tmp_path, capsys, template, change, fragments):
    folder = tmp_path / template
    shutil.copytree(valid / template, folder)
    _edit(folder, change)
    out = tmp_path / "result"
    code = main(["calibrate", str(folder / "dataset.yaml"), "--out", str(out), "--no-diagnose",
                 "--no-report"])
    error = capsys.readouterr().err
    assert code == 2, error
    assert len(error.strip().splitlines()) == 1, error
    assert error.startswith("robocal calibrate: error: ")
    for fragment in fragments:
        assert fragment in error
    assert not out.exists()


def test_degenerate_validation_table_is_refused_too(valid, tmp_path, capsys):
    shutil.copytree(valid / "bar", tmp_path / "bar")
    shutil.copytree(valid / "bar", tmp_path / "held")
    _edit(tmp_path / "held", same_joints)
    out = tmp_path / "result"
    code = main(["calibrate", str(tmp_path / "bar" / "dataset.yaml"), "--validate",
                 str(tmp_path / "held" / "dataset.yaml"), "--out", str(out), "--no-diagnose",
                 "--no-report"])
    error = capsys.readouterr().err
    assert code == 2 and "held" in error and "same joints" in error
    assert not out.exists()


def test_the_unmodified_templates_calibrate(valid, tmp_path, capsys):
    """The breakage above, not the templates, causes the refusals. The templates' robot
    is on its drawing, so the job may rightly find calibrating no better than doing
    nothing (status 3, written and said); what it must not do is refuse the data (2)."""
    for template in ("bar", "art", "tracker"):
        out = tmp_path / template
        status = main(["calibrate", str(valid / template / "dataset.yaml"), "--out", str(out),
                       "--no-diagnose", "--no-report"])
        assert status in (0, 3), capsys.readouterr().err
        assert (out / "result.json").is_file()


def test_non_finite_jacobian_is_a_solver_error_not_a_crash():
    rng = np.random.default_rng(0)
    J = rng.normal(size=(12, 5))
    J[3, 2] = np.nan
    with pytest.raises(SolverError, match="non-finite"):
        analyse(J, [f"a{i}" for i in range(5)], [0, 1, 2], [3, 4], invisible_reason="-",
                absorbed_reason="-")


class _Model:
    def __init__(self, size, name):
        self.size = size
        self.dataset = type("D", (), {"data_path": Path(name), "path": Path(name)})()

    def residual_size(self):
        return self.size


def test_check_finite_names_the_dataset_the_bad_rows_come_from():
    models = [_Model(4, "first.csv"), _Model(3, "second.csv")]
    r, J = np.zeros(7), np.ones((7, 2))
    check_finite(models, r, J, "the fit")  # all finite: nothing to say
    J[5, 1] = np.inf
    with pytest.raises(RobocalError, match=r"second\.csv.*1 of 3 residuals.*the fit"):
        check_finite(models, r, J, "the fit")
