"""The example reports in reports/ (written by `robocal demo` on real data) agree with
the result.json written beside them, and the demo's outputs are complete."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from robocal_casadi.report.numbers import format_number
from robocal_casadi.robot import load_robot

REPORTS = Path(__file__).resolve().parents[1] / "reports"
CASES = sorted(p for p in REPORTS.iterdir() if p.is_dir()) if REPORTS.is_dir() else []


def test_demo_reports_are_present():
    assert {p.name for p in CASES} >= {"ur10-tracker", "panda-sockets"}


@pytest.mark.parametrize("case", CASES, ids=[p.name for p in CASES])
def test_report_numbers_match_result_json(case):
    check_report_folder(case)


def check_report_folder(case: Path) -> None:
    """A demo case folder is complete and its report shows the numbers of result.json."""
    result = json.loads((case / "result.json").read_text())
    html = (case / "report.html").read_text()
    for block in ("fit", "validation"):
        for key in ("rms_nominal", "rms_geometric", "rms_final"):
            shown = format_number(result[block][key])
            assert f">{shown}<" in html, f"{block}.{key} = {result[block][key]} not shown"
    ident = result["identifiability"]
    candidates = len(ident["identifiable"]) + len(ident["not_identifiable"])
    assert f"{len(ident['identifiable'])} of {candidates} candidate parameters" in html
    robot_identified = {p["name"] for p in result["parameters"] if p["identifiable"]}
    assert robot_identified <= set(ident["identifiable"])
    for effect in result["effects"]:
        assert effect["name"] in html
    # The calibrated robot file loads and carries the estimates of result.json.
    robot = load_robot(case / "robot_calibrated.yaml")
    assert robot.units.length == result["fit"]["unit"]
    assert (case / "report.png").stat().st_size > 10_000  # the screenshot of the page
