"""The example reports in reports/ agree with the result.json written beside them.

Written by `robocal demo` (real data: ur10-tracker, panda-sockets) and by
reports/make_simulated.py (simulated bar, artifact and sphere data). The checks hold
whether or not the demo was run again since, and with or without Chromium: the page's
own numbers are always checked; the screenshot and the browser's view of the page only
where there is a screenshot or a Chromium.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from robocal_casadi.common.units import LENGTH_SCALE
from robocal_casadi.model.robot import load_robot
from robocal_casadi.report import find_chromium, page_state
from robocal_casadi.report.numbers import format_number

REPORTS = Path(__file__).resolve().parents[1] / "reports"
CASES = sorted(p for p in REPORTS.iterdir() if (p / "result.json").is_file()) \
    if REPORTS.is_dir() else []
KINDS = {"ur10-tracker": "tracker_points", "panda-sockets": "artifact_touches",
         "bar-simulated": "cross_bar", "artifact-simulated": "artifact_touches",
         "sphere-simulated": "sphere_laser"}
KIND_FIGURES = {"tracker_points": ("axes-fit", "workspace-fit", "joints-fit"),
                "artifact_touches": ("axes-fit", "lengths-fit"),
                "cross_bar": ("lengths-fit",),
                "sphere_laser": ("scan-fit",)}


def test_demo_reports_are_present():
    assert {p.name for p in CASES} >= {"ur10-tracker", "panda-sockets"}


@pytest.mark.parametrize("case", CASES, ids=[p.name for p in CASES])
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
@pytest.mark.parametrize("case", CASES, ids=[p.name for p in CASES])
def test_report_loads_in_chromium_with_every_figure_drawn(case):
    html = (case / "report.html").read_text()
    state = page_state(case / "report.html")
    assert state.get("report-ready") == "true", state
    assert int(state["images-loaded"]) == int(state["images-total"]) == html.count("<img ")
