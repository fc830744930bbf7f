"""The example reports kept in reports/, and the check of a report page against its
result.json.

The repository keeps what `robocal demo --out reports` writes that is small (result.json,
errors.csv, the calibrated robot and effects, the folder's marker) and the one screenshot
the README shows; the pages themselves (report.html) and the simulated examples of
reports/make_simulated.py are generated, and git ignores them. A page written here is
checked against the result.json beside it, and tests/test_demo.py checks a page the demo
has just written the same way (``check_report_folder``).
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from robocal_casadi.common.output import read_marker
from robocal_casadi.common.units import LENGTH_SCALE
from robocal_casadi.model.robot import load_robot
from robocal_casadi.report import find_chromium, page_state
from robocal_casadi.report.numbers import format_number

ROOT = Path(__file__).resolve().parents[1]
REPORTS = ROOT / "reports"
CASES = sorted(p for p in REPORTS.iterdir() if (p / "result.json").is_file()) \
    if REPORTS.is_dir() else []
PAGES = [p for p in CASES if (p / "report.html").is_file()]  # written here, not tracked
SCREENSHOT = REPORTS / "ur10-tracker" / "report.png"  # the one the README shows
KINDS = {"ur10-tracker": "tracker_points", "panda-sockets": "artifact_touches",
         "bar-simulated": "cross_bar", "artifact-simulated": "artifact_touches",
         "sphere-simulated": "sphere_laser"}
KIND_FIGURES = {"tracker_points": ("axes-fit", "workspace-fit", "joints-fit"),
                "artifact_touches": ("axes-fit", "lengths-fit"),
                "cross_bar": ("lengths-fit",),
                "sphere_laser": ("scan-fit",)}
KEPT = ("result.json", "errors.csv", "robot_calibrated.yaml")
LARGEST_TRACKED = 4 * 2**20  # [bytes] all tracked files under reports/ together


def test_demo_reports_are_present():
    assert {p.name for p in CASES} >= {"ur10-tracker", "panda-sockets"}


@pytest.mark.parametrize("case", CASES, ids=[p.name for p in CASES])
def test_kept_files_are_those_the_demo_wrote(case):
    """Each kept file is listed in the folder's marker with the SHA-256 it has, so the
    folder is what the demo wrote (and the demo may replace it); the calibrated robot
    reads back in result.json's units."""
    marker = read_marker(case)
    assert marker is not None and marker.verb == "demo"
    for name in KEPT:
        assert name in marker.files and (case / name).is_file(), name
    for name, digest in marker.files.items():
        if (case / name).exists():
            assert hashlib.sha256((case / name).read_bytes()).hexdigest() == digest, name
    result = json.loads((case / "result.json").read_text())
    robot = load_robot(case / "robot_calibrated.yaml")
    assert robot.units.length == result["fit"]["unit"]


def test_the_readme_shows_the_kept_screenshot():
    readme = (ROOT / "README.md").read_text()
    assert re.search(r"!\[[^]]*\]\(reports/ur10-tracker/report\.png\)", readme)
    data = SCREENSHOT.read_bytes()
    assert data.startswith(b"\x89PNG\r\n\x1a\n") and len(data) > 10_000


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(),
                    reason="needs git and a checkout")
def test_generated_pages_are_not_tracked():
    listed = subprocess.run(["git", "ls-files", "reports"], cwd=ROOT, capture_output=True,
                            text=True, check=True).stdout.split()
    assert "reports/ur10-tracker/report.png" in listed
    assert not [n for n in listed if n.endswith((".html", ".pdf"))
                or (n.endswith(".png") and n != "reports/ur10-tracker/report.png")]
    assert not [n for n in listed if "-simulated/" in n]
    size = sum((ROOT / n).stat().st_size for n in listed if (ROOT / n).exists())
    assert size < LARGEST_TRACKED, size


@pytest.mark.parametrize("case", PAGES, ids=[p.name for p in PAGES])
def test_report_numbers_match_result_json(case):
    check_report_folder(case)


def check_report_folder(case: Path) -> None:
    """A demo case folder is complete and its report shows the numbers of result.json."""
    result = json.loads((case / "result.json").read_text())
    html = (case / "report.html").read_text()
    # the report shows lengths in mm; result.json is in the robot file's unit
    to_mm = LENGTH_SCALE[result["fit"]["unit"]] / 1e-3
    for block in ("fit", "validation"):
        if block not in result:
            continue
        for key in ("rms_nominal", "rms_geometric", "rms_final"):
            shown = format_number(result[block][key] * to_mm)
            assert f">{shown}<" in html, f"{block}.{key} = {result[block][key]} not shown"
    ident = result["identifiability"]
    candidates = len(ident["identifiable"]) + len(ident["not_identifiable"])
    assert f"{len(ident['identifiable'])} of {candidates} candidate parameters" in html
    robot_identified = {p["name"] for p in result["parameters"] if p["identifiable"]}
    assert robot_identified <= set(ident["identifiable"])
    for effect in result["effects"]:
        assert effect["name"] in html
    assert 'id="accuracy"' in html and 'id="applying"' in html
    kind = KINDS.get(case.name)
    for figure in KIND_FIGURES.get(kind, ()):
        assert f'id="figure-{figure}"' in html, figure
    # The calibrated robot file loads in the units of result.json.
    robot = load_robot(case / "robot_calibrated.yaml")
    assert robot.units.length == result["fit"]["unit"]
    screenshot = case / "report.png"
    if screenshot.exists():  # a demo run without Chromium leaves none
        assert screenshot.stat().st_size > 10_000


@pytest.mark.skipif(find_chromium() is None, reason="Chromium not installed")
@pytest.mark.parametrize("case", PAGES, ids=[p.name for p in PAGES])
def test_report_loads_in_chromium_with_every_figure_drawn(case):
    html = (case / "report.html").read_text()
    state = page_state(case / "report.html")
    assert state.get("report-ready") == "true", state
    assert int(state["images-loaded"]) == int(state["images-total"]) == html.count("<img ")
