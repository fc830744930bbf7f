"""An output folder is replaced as a whole only when the same verb wrote it and it holds
nothing else: never a folder with a dataset in it, never a file the run reads."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from robocal_casadi.cli import main
from robocal_casadi.common.output import MARKER, read_marker

SIMULATE = ["simulate", "--example", "industrial_6r", "--kind", "tracker_points", "--rows", "40",
            "--noise", "0.01", "--error", "a2=0.3"]
FAST = ["--no-diagnose", "--no-report"]
LOGO = '<svg xmlns="http://www.w3.org/2000/svg" width="4" height="4"><rect width="4" ' \
       'height="4"/></svg>\n'


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def simulated(tmp_path_factory) -> Path:
    """A simulated dataset folder, written once by `robocal simulate`."""
    folder = tmp_path_factory.mktemp("sim") / "sim"
    assert main([*SIMULATE, "--seed", "1", "--out", str(folder)]) == 0
    return folder


@pytest.fixture
def result(simulated, tmp_path) -> Path:
    """A calibration result folder, written by `robocal calibrate`."""
    out = tmp_path / "result"
    assert main(["calibrate", str(simulated / "dataset.yaml"), "--out", str(out), *FAST]) == 0
    return out


def refused(capsys, *words: str) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for word in words:
        assert word in err[0]
    return err[0]


def test_calibrate_refuses_a_simulated_dataset_folder(simulated, tmp_path, capsys):
    other = tmp_path / "bar-check"
    assert main([*SIMULATE, "--seed", "2", "--out", str(other)]) == 0
    before = snapshot(other)
    code = main(["calibrate", str(simulated / "dataset.yaml"), "--out", str(other), *FAST])
    assert code == 2
    refused(capsys, "dataset.yaml", "--out")
    assert snapshot(other) == before


def test_force_never_replaces_a_folder_holding_a_dataset(simulated, tmp_path, capsys):
    other = tmp_path / "bar-check"
    assert main([*SIMULATE, "--seed", "2", "--out", str(other)]) == 0
    before = snapshot(other)
    code = main(["calibrate", str(simulated / "dataset.yaml"), "--out", str(other), *FAST,
                 "--force"])
    assert code == 2
    refused(capsys, "dataset")
    assert snapshot(other) == before


def test_simulate_refuses_a_calibration_result(result, capsys):
    before = snapshot(result)
    assert main([*SIMULATE, "--seed", "3", "--out", str(result)]) == 2
    refused(capsys, "robocal calibrate", "--force")
    assert snapshot(result) == before


def test_simulate_replaces_its_own_output(simulated, tmp_path, capsys):
    folder = tmp_path / "again"
    assert main([*SIMULATE, "--seed", "1", "--out", str(folder)]) == 0
    assert main([*SIMULATE, "--seed", "4", "--out", str(folder)]) == 0
    marker = read_marker(folder)
    assert marker is not None and marker.verb == "simulate"
    assert set(marker.files) == {"dataset.yaml", "points.csv", "robot.yaml", "truth.yaml"}


def test_calibrate_replaces_its_own_unchanged_result(simulated, result, capsys):
    assert main(["calibrate", str(simulated / "dataset.yaml"), "--out", str(result),
                 *FAST]) == 0
    assert sorted(read_marker(result).files) == ["errors.csv", "geometry_posterior.json",
                                                 "result.json", "robot_calibrated.yaml"]


@pytest.mark.parametrize("change", ["added", "edited", "subfolder"])
def test_a_result_the_user_touched_is_not_replaced(simulated, result, capsys, change):
    if change == "added":
        (result / "notes.md").write_text("the robot was warm\n")
    elif change == "edited":
        path = result / "robot_calibrated.yaml"
        path.write_text(path.read_text() + "# checked by hand\n")
    else:
        (result / "mine").mkdir()
        (result / "mine" / "plot.png").write_bytes(b"\x89PNG")
    before = snapshot(result)
    code = main(["calibrate", str(simulated / "dataset.yaml"), "--out", str(result), *FAST])
    assert code == 2
    refused(capsys, "--force")
    assert snapshot(result) == before
    assert main(["calibrate", str(simulated / "dataset.yaml"), "--out", str(result), *FAST,
                 "--force"]) == 0


@pytest.mark.parametrize("option", ["--logo", "--report-templates"])
def test_calibrate_keeps_a_logo_or_templates_read_from_the_out_folder(simulated, result,
                                                                      capsys, option):
    if option == "--logo":
        given = result / "logo.svg"
        given.write_text(LOGO)
    else:
        given = result / "templates"
        shutil.copytree(Path(__import__("robocal_casadi.report", fromlist=["x"]).__file__)
                        .parent / "templates", given)
    for extra in ([], ["--force"]):
        code = main(["calibrate", str(simulated / "dataset.yaml"), "--out", str(result),
                     "--no-diagnose", option, str(given), *extra])
        assert code == 2
        refused(capsys, str(given))
        assert given.exists()


def test_demo_replaces_only_what_demo_wrote(simulated, result, tmp_path, capsys, monkeypatch):
    from robocal_casadi.commands import demo

    monkeypatch.setattr(demo, "cases", lambda: {"case": ([simulated / "dataset.yaml"], [])})
    reports = tmp_path / "reports"
    shutil.copytree(result, reports / "case")  # a calibrate result, not the demo's
    before = snapshot(reports)
    assert main(["demo", "--out", str(reports), "--no-diagnose", "--no-screenshot"]) == 2
    refused(capsys, "robocal calibrate")
    assert snapshot(reports) == before


def test_marker_lists_every_file_with_its_digest(result):
    import hashlib

    marker = read_marker(result)
    assert marker.verb == "calibrate"
    for name, digest in marker.files.items():
        assert hashlib.sha256((result / name).read_bytes()).hexdigest() == digest
    assert {p.name for p in result.iterdir()} == {*marker.files, MARKER}


def test_fleet_refuses_to_write_over_the_results_it_compares_with(simulated, tmp_path,
                                                                  capsys):
    fleet = tmp_path / "fleet.yaml"
    fleet.write_text(f"robots:\n  - name: r1\n    datasets: [{simulated / 'dataset.yaml'}]\n")
    earlier = tmp_path / "earlier"
    (earlier / "r1").mkdir(parents=True)
    (earlier / "r1" / "result.json").write_text("{}\n")
    before = snapshot(earlier)
    for out in (earlier, earlier / "inside"):
        code = main(["fleet", str(fleet), "--out", str(out), "--previous", str(earlier),
                     "--allow-outside-data"])
        assert code == 2
        refused(capsys, "--previous")
        assert snapshot(earlier) == before
