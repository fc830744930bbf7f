"""The report of each kind of data: the plots that show its error before and after, the
accuracy summary equal to numpy's statistics of the result's errors, the customer's
fields, templates an integrator can replace, and what the conclusion says first.

The signed bar lengths are checked against pinocchio's forward kinematics of the
nominal robot, independently of the engine's CasADi model.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_report import body_rows, read_page, synthetic_result

from robocal_casadi.errors import InputError
from robocal_casadi.model import examples
from robocal_casadi.report import build_document, write_report
from robocal_casadi.report.info import ReportInfo, info_from_mapping
from robocal_casadi.results import RmsSummary, Unexplained


def _figures(path: Path) -> set[str]:
    return {attrs.get("id") for tag, attrs in read_page(path).tags if tag == "figure"}


@pytest.fixture(scope="module")
def bar(tmp_path_factory):
    from robocal_casadi.calibration import calibrate
    from robocal_casadi.instruments.simulate import simulate

    folder = tmp_path_factory.mktemp("bar")
    data = simulate(examples.industrial_6r(), "cross_bar", out_dir=folder / "data", rows=14,
                    seed=5, noise=1e-5, geometric_errors=(3e-4, 3e-4), progress=False)
    dataset = data.load()
    result = calibrate([dataset], diagnose=False)
    return dataset, result, write_report(result, folder / "report.html")


def test_bar_report_shows_lengths_and_perpendicularity_per_placement(bar):
    _, result, path = bar
    assert {"figure-lengths-fit", "figure-error-histogram", "figure-error-distribution"} \
        <= _figures(path)
    assert "figure-axes-fit" not in _figures(path)  # a bar has no 3-D point errors


def test_signed_bar_errors_equal_pinocchio_kinematics_of_the_nominal_robot(bar):
    """Before calibration: |AC| - L from the nominal robot's flange poses (pinocchio) and
    the nominal probe, and the perpendicularity AC.BD / L, placement by placement."""
    from robocal_casadi.model.pinocchio_model import pinocchio_tool_pose

    dataset, result, _ = bar
    residuals = result.residuals[0]
    robot = result.robot_nominal
    length = dataset.distances[0][2]
    checked = 0
    for i, term in enumerate(residuals.terms):
        rows = {p: int(np.flatnonzero((np.asarray(dataset.pose) == term.pose)
                                      & (np.asarray(dataset.point) == p))[0])
                for p in "ABCD"}
        point = {}
        for name, row in rows.items():
            T = pinocchio_tool_pose(robot, dataset.joints[row])
            point[name] = T[:3, :3] @ dataset.probe + T[:3, 3]
        if term.kind == "distance":
            a, b = term.points
            expected = np.linalg.norm(point[b] - point[a]) - length
        else:
            expected = np.dot(point["C"] - point["A"], point["D"] - point["B"]) / length
        assert residuals.components["nominal"][i, 0] == pytest.approx(expected, abs=1e-9)
        assert abs(residuals.components["nominal"][i, 0]) == pytest.approx(
            residuals.errors_nominal[i], abs=1e-12)
        checked += 1
    assert checked == 3 * 14


def test_accuracy_summary_equals_numpy_of_the_errors(bar):
    _, result, path = bar
    rows = read_page(path).tables["accuracy"][1:]
    for row in rows:
        model = {"nominal robot": "nominal", "calibrated": "final"}[row[1]]
        magnitude = np.abs(getattr(result.residuals[0], f"errors_{model}")) * 1e3  # mm
        expected = [magnitude.mean(), np.sqrt(np.mean(magnitude**2)),
                    np.percentile(magnitude, 99), magnitude.max()]
        assert int(row[2]) == magnitude.size
        np.testing.assert_allclose([float(v) for v in row[3:]], expected, rtol=6e-4)
    # the RMS of the summary is result.json's fit RMS
    fit = result.to_json()["fit"]
    assert float(rows[0][4]) == pytest.approx(fit["rms_nominal"], rel=6e-4)
    assert float(rows[1][4]) == pytest.approx(fit["rms_final"], rel=6e-4)


@pytest.mark.parametrize("kind,expected", [
    ("tracker_points", {"figure-axes-fit", "figure-workspace-fit", "figure-joints-fit"}),
    ("sphere_laser", {"figure-scan-fit", "figure-joints-fit"}),
    ("artifact_touches", {"figure-axes-fit", "figure-workspace-fit", "figure-lengths-fit"}),
])
def test_each_kind_gets_its_plots(tmp_path, kind, expected):
    from robocal_casadi.calibration import calibrate
    from robocal_casadi.instruments.simulate import simulate

    rows = {"tracker_points": 60, "sphere_laser": 80, "artifact_touches": 8}[kind]
    data = simulate(examples.industrial_6r(), kind, out_dir=tmp_path / "data", rows=rows,
                    seed=2, noise=1e-5, geometric_errors=(3e-4, 3e-4), progress=False)
    result = calibrate([data.load()], diagnose=False)
    path = write_report(result, tmp_path / "report.html")
    assert expected <= _figures(path)
    if kind == "tracker_points":  # per-axis parts: measured minus predicted, norm = error
        parts = result.residuals[0].components["final"]
        np.testing.assert_allclose(np.linalg.norm(parts, axis=1),
                                   result.residuals[0].errors_final, rtol=1e-12)


# ----------------------------------------------------------------------------- fields


def test_customer_fields_and_logo_at_the_top(tmp_path):
    logo = tmp_path / "logo.png"
    import matplotlib.pyplot as plt

    plt.imsave(logo, np.tile(np.linspace(0, 1, 40), (20, 1)))
    info = info_from_mapping({"customer": "Acme Gearboxes", "robot_serial": "KR-4711",
                              "instrument": "tracker", "operator": "J. Smith",
                              "date": __import__("datetime").date(2024, 5, 14),
                              "logo": "logo.png"}, base=tmp_path)
    path = write_report(synthetic_result(validation=False, effects=False),
                        tmp_path / "report.html", info=info)
    facts = {row[0]: row for row in read_page(path).tables["facts"]}  # no header row
    assert facts["customer"][1] == "Acme Gearboxes"
    assert facts["robot serial number"][1] == "KR-4711"
    assert facts["date of measurement"][1] == "2024-05-14"
    logos = [a for t, a in read_page(path).tags if t == "img" and a.get("class") == "logo"]
    assert len(logos) == 1 and logos[0]["src"].startswith("data:image/png;base64,")


@pytest.mark.parametrize("block,message", [
    ({"customr": "x"}, "unknown key 'customr'"),
    ({"customer": ["a"]}, "expected a line of text"),
    ({"logo": "missing.png"}, "no such file"),
    ({"logo": "logo.gif"}, "expected a .png, .jpg or .svg file"),
    ("Acme", "expected a mapping"),
])
def test_bad_report_block_names_the_key(tmp_path, block, message):
    with pytest.raises(InputError, match=message):
        info_from_mapping(block, file=tmp_path / "data.yaml", base=tmp_path)


def test_command_line_fields_override_the_dataset_block():
    merged = ReportInfo(customer="from file", operator="A").merged(ReportInfo(customer="cli"))
    assert merged.customer == "cli" and merged.operator == "A"


def test_an_integrator_replaces_the_style_and_a_template(tmp_path):
    (tmp_path / "brand").mkdir()
    (tmp_path / "brand" / "report.css").write_text("body { color: #123456; }")
    (tmp_path / "brand" / "brand.html.j2").write_text('<div class="banner">Robots Inc.</div>')
    path = write_report(synthetic_result(validation=False, effects=False),
                        tmp_path / "report.html", templates=tmp_path / "brand")
    text = path.read_text(encoding="utf-8")
    assert "color: #123456" in text and '<div class="banner">Robots Inc.</div>' in text
    assert "<table class=\"parameters\">" in text  # the rest is the package's own
    with pytest.raises(InputError, match="not a folder of report templates"):
        write_report(synthetic_result(), tmp_path / "x.html", templates=tmp_path / "none")


# ----------------------------------------------------------------------------- conclusion


def test_solver_details_only_in_the_appendix(tmp_path):
    path = write_report(synthetic_result(validation=False), tmp_path / "report.html")
    text = path.read_text(encoding="utf-8")
    appendix = text.index('<section id="appendix"')
    assert "iterations" not in text[:appendix] and "iterations" in text[appendix:]


def test_geometric_recommendation_comes_first():
    base = synthetic_result()
    result = replace(base, validation=RmsSummary(1.9e-3, 0.10e-3, 0.13e-3),
                     recommended="geometric")
    document = build_document(result)
    first = document.sections[0].blocks[0].text
    assert first.startswith("Use the geometric calibration alone")
    assert "0.13 mm RMS with the effects against 0.1 mm without" in first
    assert not build_document(base).sections[0].blocks[0].text.startswith("Use the")


def test_unexplained_structure_in_words_and_against_its_variable(tmp_path):
    result = synthetic_result(validation=False, effects=False)
    result = replace(result, unexplained=Unexplained(
        rms=4e-6, share=0.42, variables=("q2", "temperature"), parameters=("a2", "d3"),
        noise_floor=1e-6))
    path = write_report(result, tmp_path / "report.html")
    texts = " ".join(t for _, t in read_page(path).paragraphs)
    assert "0.004 mm RMS, about 42 % of the error that remains and follows the angle of " \
           "joint 2" in texts
    assert "figure-unexplained" in _figures(path)


def test_numbers_equal_result_json_in_millimetres_for_a_metre_file(tmp_path):
    from robocal_casadi.common.units import Units

    result = synthetic_result(Units("m", "rad"), validation=True, effects=False)
    content = json.loads(json.dumps(result.to_json()))
    page = read_page(write_report(result, tmp_path / "report.html"))
    headline = body_rows(page, "headline")
    for role in ("fit", "validation"):
        shown = [float(v) for v in headline[role][1:4]]
        expected = [content[role][k] * 1e3 for k in ("rms_nominal", "rms_geometric",
                                                     "rms_final")]
        np.testing.assert_allclose(shown, expected, rtol=6e-4)
