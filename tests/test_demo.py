"""`robocal demo` on a machine without Chromium: the README's two commands in order.

The demo rewrites its case folders; where it cannot render the screenshot it must keep
the one already there (a repository's shipped reports carry one), so the shipped-report
checks pass whether or not the demo was re-run, with or without Chromium.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from test_shipped_reports import REPORTS, check_report_folder

import robocal_casadi.report as report_package
from robocal_casadi.cli import main
from robocal_casadi.commands import demo
from robocal_casadi.common.output import MARKER
from robocal_casadi.instruments.simulate import simulate
from robocal_casadi.model.examples import ROBOTS

REPOSITORY = Path(__file__).resolve().parents[1]
PNG = b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 64  # stands in for a rendered screenshot


@pytest.fixture
def small_case(tmp_path, monkeypatch):
    """The demo's cases replaced by one small simulated bar case (same code path)."""
    robot = ROBOTS["industrial_6r"]()
    for name, seed in (("fit", 1), ("check", 2)):
        simulate(robot, "cross_bar", rows=12, noise=1e-5, geometric_errors={"a2": 3e-4},
                 seed=seed, out_dir=tmp_path / name, progress=False)
    monkeypatch.setattr(demo, "cases", lambda: {
        "small-bar": ([tmp_path / "fit" / "dataset.yaml"], [tmp_path / "check" / "dataset.yaml"])})
    monkeypatch.setattr(report_package, "find_chromium", lambda: None)
    return tmp_path


def test_demo_without_chromium_keeps_the_screenshot(small_case, capsys):
    reports = small_case / "reports"
    assert main(["demo", "--out", str(reports), "--no-diagnose"]) == 0
    case = reports / "small-bar"
    check_report_folder(case)  # the page shows the numbers of result.json
    assert not (case / "report.png").exists()  # nothing to keep on a first run
    (case / "report.png").write_bytes(PNG)  # as rendered where Chromium was installed
    first = (case / "result.json").read_text()
    assert main(["demo", "--out", str(reports), "--no-diagnose"]) == 0
    out = capsys.readouterr().out
    assert "report.png kept" in out
    assert (case / "report.png").read_bytes() == PNG
    assert (case / "result.json").read_text().splitlines()[:20] == first.splitlines()[:20]
    assert (case / MARKER).is_file()
    assert sorted(p.name for p in case.iterdir() if not p.name.startswith(".")) == [
        "errors.csv", "geometry_posterior.json", "report.html", "report.png", "result.json",
        "robot_calibrated.yaml"]


def test_demo_does_not_replace_a_folder_it_did_not_write(small_case, capsys):
    case = small_case / "reports" / "small-bar"
    case.mkdir(parents=True)
    (case / "notes.md").write_text("mine\n")
    assert main(["demo", "--out", str(small_case / "reports"), "--no-diagnose"]) == 2
    assert "--force" in capsys.readouterr().err
    assert (case / "notes.md").read_text() == "mine\n"


@pytest.mark.slow
def test_readme_order_on_the_shipped_reports_without_chromium(tmp_path, monkeypatch, capsys):
    """`robocal demo` over a copy of the shipped reports, without Chromium, leaves
    folders that pass the shipped-report checks (the README's second command)."""
    monkeypatch.setattr(report_package, "find_chromium", lambda: None)
    reports = Path(shutil.copytree(REPORTS, tmp_path / "reports"))
    screenshots = {p.parent.name: p.read_bytes() for p in reports.glob("*/report.png")}
    assert main(["demo", "--out", str(reports)]) == 0
    capsys.readouterr()
    for case in sorted(p for p in reports.iterdir() if p.is_dir()):
        check_report_folder(case)
        if case.name in screenshots:  # the repository keeps one screenshot
            assert (case / "report.png").read_bytes() == screenshots[case.name]


def _git(*arguments: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(["git", *arguments], cwd=cwd, capture_output=True, text=True,
                          timeout=120)


def _in_git_checkout() -> bool:
    return shutil.which("git") is not None and (REPOSITORY / ".git").exists()


@pytest.mark.skipif(not _in_git_checkout(), reason="needs git and a checkout")
def test_default_output_is_ignored_by_git():
    """What `robocal demo` writes by default is no tracked file and git ignores it."""
    default = demo.DEFAULT_OUT
    assert not default.is_absolute()
    for case in demo.cases():
        path = default / case / "result.json"
        assert _git("check-ignore", "-q", str(path), cwd=REPOSITORY).returncode == 0, path
        assert _git("ls-files", "--error-unmatch", str(path),
                    cwd=REPOSITORY).returncode != 0, path


def test_demo_writes_nothing_outside_its_folder(small_case, monkeypatch, capsys):
    """Run with the default --out from a folder: only that folder appears."""
    work = small_case / "clone"
    work.mkdir()
    monkeypatch.chdir(work)
    assert main(["demo", "--no-diagnose"]) == 0
    capsys.readouterr()
    assert sorted(p.name for p in work.iterdir()) == [str(demo.DEFAULT_OUT)]


@pytest.mark.slow
@pytest.mark.skipif(not _in_git_checkout(), reason="needs git and a checkout")
def test_demo_leaves_a_fresh_clone_clean(tmp_path):
    """The README's first command, `robocal demo`, in a fresh clone of the committed
    repository (its own code): `git status` stays empty."""
    clone = tmp_path / "clone"
    assert _git("clone", "--quiet", str(REPOSITORY), str(clone), cwd=tmp_path).returncode == 0
    env = {**os.environ, "PYTHONPATH": str(clone)}
    run = subprocess.run([sys.executable, "-m", "robocal_casadi.cli", "demo",
                          "--no-screenshot"], cwd=clone, env=env, capture_output=True,
                         text=True, timeout=1800)
    assert run.returncode == 0, run.stderr
    assert "Traceback" not in run.stderr
    assert (clone / demo.DEFAULT_OUT / "ur10-tracker" / "report.html").is_file()
    assert _git("status", "--porcelain", "--ignore-submodules", cwd=clone).stdout == ""
