"""Bad robot and data files end with one clear line and exit status 2, writing nothing.

Valid files come from the simulator; each case breaks one thing and runs a real verb
(``fk`` and ``simulate`` read robot files, ``calibrate`` reads datasets, ``compensate``
reads target tables). The line must name the file and the key or row, and say what is
wrong; the output the verb was asked for must not exist afterwards.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml

from robocal_casadi.cli import main
from robocal_casadi.errors import InputError
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import ROBOTS


@pytest.fixture(scope="module")
def templates(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("templates")
    return {
        "bar": simulate(ROBOTS["industrial_6r"](), "cross_bar", rows=2, seed=1,
                        out_dir=root / "bar").dataset_path.parent,
        "panda": simulate(ROBOTS["panda_7dof"](), "tracker_points", rows=6, seed=1,
                          out_dir=root / "panda").dataset_path.parent,
    }


@pytest.fixture
def bar(tmp_path, templates) -> Path:
    """A writable copy of a valid cross_bar dataset (industrial_6r, mm/deg)."""
    return Path(shutil.copytree(templates["bar"], tmp_path / "bar"))


@pytest.fixture
def panda(tmp_path, templates) -> Path:
    """A writable copy of a valid tracker dataset (panda_7dof, m/rad)."""
    return Path(shutil.copytree(templates["panda"], tmp_path / "panda"))


def run(args: list[str], capsys) -> tuple[int, str]:
    status = main(args)
    err = capsys.readouterr().err.strip()
    return status, err


def assert_one_clear_line(status: int, err: str, *fragments: str) -> None:
    assert status == 2, err
    assert len(err.splitlines()) == 1, err
    for fragment in fragments:
        assert fragment in err, f"{fragment!r} not in {err!r}"


def edit_yaml(path: Path, change) -> None:
    content = yaml.safe_load(path.read_text())
    change(content)
    path.write_text(yaml.safe_dump(content, sort_keys=False))


def edit_cell(path: Path, line: int, column: str, value: str) -> None:
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[line - 1].split(",")
    cells[header.index(column)] = value
    lines[line - 1] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


def fk_args(folder: Path, tmp_path: Path, robot: Path | None = None) -> list[str]:
    joints = tmp_path / "joints.csv"
    if not joints.exists():
        table = (folder / "touches.csv") if (folder / "touches.csv").exists() else (
            folder / "points.csv")
        joints.write_text(table.read_text())
    return ["fk", str(robot or folder / "robot.yaml"), str(joints), "--out",
            str(tmp_path / "poses.csv")]


# ----------------------------------------------------------------------------- robot files


def test_unknown_convention(bar, tmp_path, capsys):
    edit_yaml(bar / "robot.yaml", lambda c: c.update(convention="craig"))
    status, err = run(fk_args(bar, tmp_path), capsys)
    assert_one_clear_line(status, err, "robot.yaml", "convention", "'craig'", "dh")
    assert not (tmp_path / "poses.csv").exists()


def test_missing_joint_field(bar, tmp_path, capsys):
    edit_yaml(bar / "robot.yaml", lambda c: c["joints"][2].pop("d"))
    status, err = run(["simulate", "--robot", str(bar / "robot.yaml"), "--kind",
                       "tracker_points", "--rows", "3", "--out", str(tmp_path / "sim")], capsys)
    assert_one_clear_line(status, err, "robot.yaml", "joints[2] (joint 3).d", "missing")
    assert not (tmp_path / "sim").exists()


def test_wrong_unit_name(bar, tmp_path, capsys):
    edit_yaml(bar / "robot.yaml", lambda c: c["units"].update(length="inch"))
    status, err = run(fk_args(bar, tmp_path), capsys)
    assert_one_clear_line(status, err, "robot.yaml", "units.length", "'inch'", "mm")
    assert not (tmp_path / "poses.csv").exists()


def test_wrong_unit_name_in_a_dataset(bar, tmp_path, capsys):
    edit_yaml(bar / "dataset.yaml", lambda c: c["units"].update(angle="degrees"))
    status, err = run(["calibrate", str(bar / "dataset.yaml"), "--out", str(tmp_path / "cal")],
                      capsys)
    assert_one_clear_line(status, err, "dataset.yaml", "units.angle", "'degrees'")
    assert not (tmp_path / "cal").exists()


def test_non_numeric_value_in_the_robot_file(bar, tmp_path, capsys):
    edit_yaml(bar / "robot.yaml", lambda c: c["joints"][1].update(a="680 mm"))
    status, err = run(fk_args(bar, tmp_path), capsys)
    assert_one_clear_line(status, err, "robot.yaml", "joints[1] (joint 2).a",
                          "expected a number", "'680 mm'")


def test_nan_in_the_robot_file(bar, tmp_path, capsys):
    edit_yaml(bar / "robot.yaml", lambda c: c["joints"][0].update(alpha=float("nan")))
    status, err = run(fk_args(bar, tmp_path), capsys)
    assert_one_clear_line(status, err, "robot.yaml", "joints[0] (joint 1).alpha", "finite")


def test_non_numeric_cell_in_the_table(bar, tmp_path, capsys):
    edit_cell(bar / "touches.csv", 4, "q3", "12;5")
    status, err = run(["calibrate", str(bar / "dataset.yaml"), "--out", str(tmp_path / "cal")],
                      capsys)
    assert_one_clear_line(status, err, "touches.csv", "line 4", "'q3'", "'12;5'")
    assert not (tmp_path / "cal").exists()


def test_nan_cell_in_the_table(panda, tmp_path, capsys):
    edit_cell(panda / "points.csv", 3, "y", "nan")
    status, err = run(["calibrate", str(panda / "dataset.yaml"), "--out",
                       str(tmp_path / "cal")], capsys)
    assert_one_clear_line(status, err, "points.csv", "line 3", "'y'", "finite")
    assert not (tmp_path / "cal").exists()


def test_missing_robot_file(bar, tmp_path, capsys):
    status, err = run(fk_args(bar, tmp_path, robot=tmp_path / "nowhere.yaml"), capsys)
    assert_one_clear_line(status, err, "nowhere.yaml", "not found")
    assert not (tmp_path / "poses.csv").exists()


def test_dataset_naming_a_missing_robot_file(bar, tmp_path, capsys):
    (bar / "robot.yaml").unlink()
    status, err = run(["calibrate", str(bar / "dataset.yaml"), "--out", str(tmp_path / "cal")],
                      capsys)
    assert_one_clear_line(status, err, "dataset.yaml", "robot", "robot.yaml", "not found")
    assert not (tmp_path / "cal").exists()


# ----------------------------------------------------------------------------- data tables


def test_cross_bar_pose_with_fewer_than_four_touches(bar, tmp_path, capsys):
    lines = (bar / "touches.csv").read_text().splitlines()
    dropped = [line for line in lines if not line.startswith("1,C,")]
    assert len(dropped) == len(lines) - 1
    (bar / "touches.csv").write_text("\n".join(dropped) + "\n")
    status, err = run(["calibrate", str(bar / "dataset.yaml"), "--out", str(tmp_path / "cal")],
                      capsys)
    assert_one_clear_line(status, err, "touches.csv", "pose 1", "missing ['C']")
    assert not (tmp_path / "cal").exists()


def test_empty_table(bar, tmp_path, capsys):
    header = (bar / "touches.csv").read_text().splitlines()[0]
    (bar / "touches.csv").write_text(header + "\n")
    status, err = run(["calibrate", str(bar / "dataset.yaml"), "--out", str(tmp_path / "cal")],
                      capsys)
    assert_one_clear_line(status, err, "touches.csv", "empty table")
    assert not (tmp_path / "cal").exists()


def test_degrees_in_a_file_that_declares_radians(panda, tmp_path, capsys):
    edit_cell(panda / "points.csv", 5, "q2", "45.0")  # panda files are m/rad; 45 is degrees
    status, err = run(["calibrate", str(panda / "dataset.yaml"), "--out",
                       str(tmp_path / "cal")], capsys)
    assert_one_clear_line(status, err, "points.csv", "line 5", "q2", "outside the robot's limits",
                          "degrees in a file that declares rad")
    assert not (tmp_path / "cal").exists()
    # the same through the fk verb, whose readings are in the robot file's units
    status, err = run(fk_args(panda, tmp_path), capsys)
    assert_one_clear_line(status, err, "joints.csv", "line 5", "q2", "degrees")
    assert not (tmp_path / "poses.csv").exists()


def test_missing_joint_column(panda, tmp_path, capsys):
    text = (panda / "points.csv").read_text().replace("q7,", "q_seven,", 1)
    (panda / "points.csv").write_text(text)
    with pytest.raises(InputError, match=r"points\.csv.*missing joint column\(s\) \['q7'\]"):
        load_dataset(panda / "dataset.yaml")


def test_bad_targets_table_for_compensate(bar, tmp_path, capsys):
    (tmp_path / "targets.csv").write_text("x,y,z\n900,0,1200\n900,abc,1200\n")
    out = tmp_path / "joints.csv"
    status, err = run(["compensate", str(bar / "robot.yaml"), str(tmp_path / "targets.csv"),
                       "--out", str(out)], capsys)
    assert_one_clear_line(status, err, "targets.csv", "line 3", "'y'", "'abc'")
    assert not out.exists()


def test_bad_simulate_options_write_nothing(tmp_path, capsys):
    out = tmp_path / "sim"
    for options, fragment in ((["--effect", "joint_wobble:2"], "unknown effect"),
                              (["--errors", "0.5"], "expected 2 numbers"),
                              (["--error", "a9=1"], "unknown parameter 'a9'")):
        status, err = run(["simulate", "--example", "industrial_6r", "--kind", "cross_bar",
                           "--rows", "2", "--out", str(out), *options], capsys)
        assert_one_clear_line(status, err, fragment)
        assert not out.exists()
