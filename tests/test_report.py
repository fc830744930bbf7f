"""The HTML report: self-contained, every section present, numbers equal to the result's.

Results are built directly (synthetic but plausible numbers: a 6R arm measured by a
tracker with a temperature column, a cross bar, a sphere with a point laser), so the
report is tested without the engine; the expected figures are recomputed here with
numpy from the same arrays, independently of the report's own statistics.
"""

from __future__ import annotations

import base64
import io
import re
from dataclasses import replace
from html.parser import HTMLParser
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from robocal_casadi.calibration.diagnosis import CandidateTest
from robocal_casadi.common.units import Units
from robocal_casadi.errors import InputError
from robocal_casadi.model import examples
from robocal_casadi.report import write_report
from robocal_casadi.results import (
    CalibrationResult,
    DatasetResiduals,
    Decision,
    EffectFinding,
    Identifiability,
    ParameterEstimate,
    RmsSummary,
)

HELD_AT_NOMINAL = {
    "base_x": "bar data carries no absolute position",
    "base_rz": "a rotation about the first axis moves every touched point rigidly",
    "theta1": "equivalent to base_rz",
    "beta1": "axes 1 and 2 are not parallel",
}


def _rms(errors: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(errors))))


def _tracker_residuals(label: str, robot, rng: np.random.Generator, rows: int,
                       temperature: bool) -> DatasetResiduals:
    """Tracker errors [m] (norms of 3-D errors) with a compliance-like pattern in q2, q3."""
    joints = rng.uniform(robot.lower_limits, robot.upper_limits, size=(rows, robot.dof))
    noise = rng.normal(0.0, 12e-6, size=(rows, 3))
    sag = 8e-5 * np.cos(joints[:, 1])[:, None] * np.array([0.6, 0.0, 0.8]) \
        + 4e-5 * np.sin(joints[:, 1] + joints[:, 2])[:, None] * np.array([0.0, 1.0, 0.0])
    geometry = 1.2e-3 * np.column_stack([np.sin(joints[:, 0]), np.cos(joints[:, 1]),
                                         np.sin(joints[:, 2] - 0.3)])
    extras = {}
    if temperature:
        extras["temperature"] = np.linspace(22.9, 23.7, rows) + rng.normal(0, 0.02, rows)
    return DatasetResiduals(
        label=label, kind="tracker_points",
        errors_nominal=np.linalg.norm(geometry + sag + noise, axis=1),
        errors_geometric=np.linalg.norm(sag + noise, axis=1),
        errors_final=np.linalg.norm(noise, axis=1),
        rows=np.arange(rows), joints=joints, extras=extras)


def _bar_residuals(robot, rng: np.random.Generator, poses: int) -> DatasetResiduals:
    """Signed bar errors [m]: four touches per pose, then |AC|-L, |BD|-L, AC.BD/L per pose."""
    rows = 4 * poses
    joints = rng.uniform(robot.lower_limits, robot.upper_limits, size=(rows, robot.dof))
    scale = np.concatenate([np.full(rows, 1.0), np.full(3 * poses, 1.5)])
    draw = lambda sigma: rng.normal(0.0, sigma, rows + 3 * poses) * scale  # noqa: E731
    return DatasetResiduals(
        label="bar.yaml", kind="cross_bar", errors_nominal=draw(0.9e-3),
        errors_geometric=draw(0.05e-3), errors_final=draw(0.05e-3),
        rows=np.concatenate([np.arange(rows), np.full(3 * poses, -1)]), joints=joints)


def _sphere_residuals(robot, rng: np.random.Generator, rows: int) -> DatasetResiduals:
    joints = rng.uniform(robot.lower_limits, robot.upper_limits, size=(rows, robot.dof))
    return DatasetResiduals(
        label="sphere.yaml", kind="sphere_laser",
        errors_nominal=rng.normal(0.0, 0.4e-3, rows), errors_geometric=rng.normal(0, 30e-6, rows),
        errors_final=rng.normal(0, 30e-6, rows), rows=np.arange(rows), joints=joints,
        extras={"distance": rng.uniform(0.08, 0.12, rows)})


def synthetic_result(units: Units = Units("mm", "deg"), *, validation: bool = True,
                     effects: bool = True, sphere: bool = False, bar: bool = False,
                     seed: int = 7) -> CalibrationResult:
    """A plausible calibration of the example 6R arm, built directly (no engine)."""
    rng = np.random.default_rng(seed)
    robot = examples.industrial_6r().with_units(units)
    registry = robot.parameters()
    nominal = robot.parameter_vector()
    change = np.where(np.array(registry.quantities) == "length",
                      rng.normal(0, 0.4e-3, len(nominal)), rng.normal(0, 0.02 * np.pi / 180,
                                                                      len(nominal)))
    parameters, estimate = [], nominal.copy()
    for i, (name, quantity) in enumerate(zip(registry.names, registry.quantities)):
        held = name in HELD_AT_NOMINAL
        if not held:
            estimate[i] = nominal[i] + change[i]
        std = None if held else abs(change[i]) * 0.03 + (2e-6 if quantity == "length" else 1e-6)
        parameters.append(ParameterEstimate(name, quantity, float(nominal[i]), float(estimate[i]),
                                            std, not held, HELD_AT_NOMINAL.get(name)))
    identifiable = tuple(n for n in registry.names if n not in HELD_AT_NOMINAL)
    singular = np.concatenate([np.logspace(1.2, -1.6, len(identifiable)),
                               [3e-9, 1e-12, 2e-15, 0.0]])
    ident = Identifiability(registry.names, identifiable, dict(HELD_AT_NOMINAL), singular,
                            float(singular[0] / singular[len(identifiable) - 1]),
                            ("theta1 + base_rz",))

    fit = [_tracker_residuals("series_A.yaml", robot, rng, 400, temperature=True)]
    if bar:
        fit.append(_bar_residuals(robot, rng, 30))
    if sphere:
        fit.append(_sphere_residuals(robot, rng, 120))
    held_out = [_tracker_residuals("series_A_validation.yaml", robot, rng, 150,
                                   temperature=True)] if validation else []

    def summary(residuals) -> RmsSummary:
        return RmsSummary(*(_rms(np.concatenate([getattr(r, f"errors_{m}") for r in residuals]))
                            for m in ("nominal", "geometric", "final")))

    findings = (EffectFinding("joint_compliance", (2, 3), {"c2": 1.1e-6, "c3": 2.0e-6}, "rad/Nm",
                              {"rms_drop": 0.31, "bic_drop": 412.0}, {"c2": 4e-8, "c3": 9e-8},
                              "deflection proportional to the gravity torque"),
                EffectFinding("thermal_drift", (), {"k_length": 1.2e-5}, "1/C",
                              {"rms_drop": 0.05, "bic_drop": 30.0}, {},
                              "lengths grow with temperature")) if effects else ()
    mounted = {"target_x": (0.0012, 3e-6), "target_y": (-0.0004, 3e-6), "target_z": (0.1093, 4e-6)}
    placement = {"series_A.yaml.tracker_x": 1.234, "series_A.yaml.tracker_rz": 0.5}
    if sphere:
        mounted.update({"laser_x": (0.061236, 2e-6), "laser_y": (-0.015643, 2e-6),
                        "laser_z": (0.139778, 3e-6), "laser_nx": (0.016, 1e-4),
                        "laser_ny": (0.020, 1e-4)})
        placement.update({"sphere.yaml.centre_x": -0.119193, "sphere.yaml.centre_y": -0.305573,
                          "sphere.yaml.centre_z": 0.106620})
    calibrated = robot.with_parameters(estimate)
    return CalibrationResult(
        datasets=tuple(r.label for r in fit), robot_nominal=robot, robot_calibrated=calibrated,
        parameters=tuple(parameters), identifiability=ident,
        condition_number=ident.condition_number, effects=findings, fit=summary(fit),
        validation=summary(held_out) if validation else None, residuals=tuple(fit),
        validation_residuals=tuple(held_out), mounted=mounted, placement=placement,
        solver={"method": "lm", "iterations": 9, "status": "converged", "cost": 1.5e-7})


# ----------------------------------------------------------------------------- reading HTML


class _Page(HTMLParser):
    """Every tag's attributes, section ids, tables (class -> rows of cell text, muted flags)."""

    def __init__(self):
        super().__init__()
        self.tags: list[tuple[str, dict]] = []
        self.tables: dict[str, list[list[str]]] = {}
        self.muted: dict[str, list[bool]] = {}
        self.paragraphs: list[tuple[str, str]] = []
        self._table = None
        self._below = False  # inside a row of columns set under the row before
        self._span: str | None = None
        self._cell: list[str] | None = None
        self._paragraph: tuple[str, list[str]] | None = None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.tags.append((tag, attrs))
        if tag == "table":
            self._table = attrs.get("class", "")
            self.tables[self._table] = []
            self.muted[self._table] = []
        elif tag == "tr" and self._table is not None:
            classes = (attrs.get("class") or "").split()
            self._below = "below" in classes
            if not self._below:  # a row's columns set under it belong to that row
                self.tables[self._table].append([])
                self.muted[self._table].append("muted" in classes)
        elif tag in ("td", "th") and not self._below:
            self._cell = []
        elif tag == "span" and attrs.get("class") in ("below-header", "below-value"):
            self._cell = []
            self._span = attrs["class"]
        elif tag == "p":
            self._paragraph = (attrs.get("class", ""), [])

    def handle_endtag(self, tag):
        if tag == "span" and self._span is not None and self._cell is not None:
            text, rows = "".join(self._cell), self.tables[self._table]
            if self._span == "below-value":
                rows[-1].append(text)
            elif text not in rows[0]:  # its title joins the header, after the side columns
                rows[0].append(text)
            self._cell = self._span = None
        elif tag in ("td", "th") and self._cell is not None:
            self.tables[self._table][-1].append("".join(self._cell))
            self._cell = None
        elif tag == "table":
            self._table = None
        elif tag == "p" and self._paragraph is not None:
            self.paragraphs.append((self._paragraph[0], "".join(self._paragraph[1])))
            self._paragraph = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)
        if self._paragraph is not None:
            self._paragraph[1].append(data)


def read_page(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text(encoding="utf-8"))
    return page


def body_rows(page: _Page, table: str) -> dict[str, list[str]]:
    """Rows of ``table`` below its header, keyed by their first cell."""
    return {row[0]: row for row in page.tables[table][1:]}


@pytest.fixture(scope="module")
def full_report(tmp_path_factory) -> tuple[CalibrationResult, Path]:
    result = synthetic_result(sphere=True, bar=True)
    path = tmp_path_factory.mktemp("report") / "report.html"
    assert write_report(result, path) == path
    return result, path


# ----------------------------------------------------------------------------- tests


def test_page_is_self_contained(full_report):
    _, path = full_report
    text = path.read_text(encoding="utf-8")
    page = read_page(path)
    for tag, attrs in page.tags:
        for key in ("src", "href", "srcset", "data", "action"):
            value = attrs.get(key) or ""
            assert not re.match(r"\s*(https?:)?//", value), f"<{tag} {key}={value[:60]!r}>"
            if tag == "img" and key == "src":
                assert value.startswith("data:image/png;base64,")
            if key == "href" and key in attrs:
                assert value.startswith("#"), f"link leaves the page: {value}"
    assert not any(tag == "link" for tag, _ in page.tags)
    assert not any(tag == "script" and "src" in attrs for tag, attrs in page.tags)
    assert "url(" not in text and "@import" not in text


def test_every_section_is_present(full_report):
    _, path = full_report
    ids = {attrs.get("id") for tag, attrs in read_page(path).tags if tag == "section"}
    assert ids == {"conclusion", "accuracy", "applying", "robot-data", "identifiability",
                   "parameters", "errors", "rejected", "effects", "sphere", "instrument",
                   "appendix"}


def test_every_image_is_a_png_with_content(full_report):
    _, path = full_report
    images = [attrs for tag, attrs in read_page(path).tags if tag == "img"]
    # singular values, histogram, distribution, joints + order for fit and for validation,
    # 2 effects
    assert len(images) == 1 + 2 + 2 * 2 + 2
    for attrs in images:
        data = base64.b64decode(attrs["src"].split(",", 1)[1], validate=True)
        assert data[:8] == b"\x89PNG\r\n\x1a\n"
        pixels = matplotlib.image.imread(io.BytesIO(data), format="png")
        assert pixels.shape[:2] == (int(attrs["height"]), int(attrs["width"]))
        assert float(pixels[..., :3].std()) > 0.02, "blank image"
        assert attrs.get("alt")


def test_headline_rms_are_the_results_in_millimetres(full_report):
    result, path = full_report
    rows = body_rows(read_page(path), "headline")
    for role, summary, residuals in (("fit", result.fit, result.residuals),
                                     ("validation", result.validation,
                                      result.validation_residuals)):
        shown = [float(v) for v in rows[role][1:]]
        expected = [summary.rms_nominal * 1e3, summary.rms_geometric * 1e3,
                    summary.rms_final * 1e3]
        for kind in ("nominal", "final"):
            magnitude = np.abs(np.concatenate([getattr(r, f"errors_{kind}") for r in residuals]))
            expected.append(np.percentile(magnitude, 99) * 1e3)
        np.testing.assert_allclose(shown, expected, rtol=6e-4)


def test_per_dataset_errors_match_numpy(full_report):
    result, path = full_report
    rows = body_rows(read_page(path), "errors")
    for residuals in result.residuals + result.validation_residuals:
        row = rows[residuals.label]
        assert int(row[2]) == len(residuals.errors_final)
        final = np.abs(residuals.errors_final)
        expected = [_rms(residuals.errors_nominal), _rms(residuals.errors_geometric),
                    _rms(residuals.errors_final), np.percentile(final, 95),
                    np.percentile(final, 99), final.max()]
        np.testing.assert_allclose([float(v) for v in row[3:]], np.array(expected) * 1e3,
                                   rtol=6e-4)
    pooled = np.concatenate([r.errors_final for r in result.residuals])
    assert float(rows["all fit data"][5]) == pytest.approx(_rms(pooled) * 1e3, rel=6e-4)


def test_parameter_table_in_file_units_with_held_parameters_folded(full_report):
    result, path = full_report
    page = read_page(path)
    rows = body_rows(page, "parameters")
    held = body_rows(page, "parameters-held")
    assert set(rows) == {p.name for p in result.parameters if p.identifiable}
    assert set(held) == set(HELD_AT_NOMINAL)
    for p in result.parameters:
        scale = 1e-3 if p.quantity == "length" else np.pi / 180
        resolution = 1e-4 if p.quantity == "length" else 1e-5
        row = rows[p.name] if p.identifiable else held[p.name]
        assert row[1] == ("mm" if p.quantity == "length" else "deg")
        assert float(row[2]) == pytest.approx(p.nominal / scale, abs=resolution)
        if p.identifiable:
            assert float(row[3]) == pytest.approx(p.estimate / scale, abs=resolution)
            assert float(row[4]) == pytest.approx((p.estimate - p.nominal) / scale,
                                                  abs=resolution)
            assert float(row[5]) == pytest.approx(p.std / scale, rel=5e-3)
        else:
            assert p.reason in row[3]
    assert all(page.muted["parameters-held"][1:])
    text = path.read_text(encoding="utf-8")
    block = text[text.index('<details id="parameters-held">'):]
    assert '<table class="parameters-held">' in block[:block.index("</details>")]


def test_identifiability_lists_what_was_not_identifiable(full_report):
    result, path = full_report
    page = read_page(path)
    assert {k: v[1] for k, v in body_rows(page, "not-identifiable").items()} == HELD_AT_NOMINAL
    assert [r[0] for r in page.tables["combinations"][1:]] == ["theta1 + base_rz"]


def test_effects_sphere_and_instrument_values(full_report):
    result, path = full_report
    page = read_page(path)
    compliance = body_rows(page, "effect-joint_compliance")
    assert float(compliance["c2"][1]) == pytest.approx(1.1e-6)
    assert float(compliance["c3"][2]) == pytest.approx(9e-8)
    assert compliance["c2"][3] == "rad/Nm"
    evidence = body_rows(page, "evidence-joint_compliance")
    assert float(evidence["BIC drop (positive favours the effect)"][1]) == 412.0
    assert evidence["fall of the RMS on the fit data"][1] == "31.0 %"
    laser = body_rows(page, "laser")
    assert float(laser["laser_x"][1]) == pytest.approx(61.236, abs=1e-4)
    assert float(laser["laser_nx"][1]) == pytest.approx(0.016) and laser["laser_nx"][3] == "-"
    centre = body_rows(page, "sphere-sphere.yaml")
    assert float(centre["sphere.yaml.centre_y"][1]) == pytest.approx(-305.573, abs=1e-4)
    placement = body_rows(page, "placement")
    assert float(placement["series_A.yaml.tracker_rz"][1]) == pytest.approx(
        np.degrees(0.5), abs=1e-5)
    assert placement["series_A.yaml.tracker_rz"][3] == "deg"


def test_conclusion_states_the_held_out_figures():
    result = replace(synthetic_result(), validation=RmsSummary(1.90e-3, 0.101e-3, 0.024e-3))
    from robocal_casadi.report import build_document

    headline = build_document(result).sections[0].blocks[0].text
    assert headline.startswith("After calibration the position error on held-out data fell "
                               "from 1.9 mm to 0.024 mm RMS (99th percentile from ")
    magnitude = np.abs(np.concatenate([r.errors_final for r in result.validation_residuals]))
    assert f"to {np.percentile(magnitude, 99) * 1e3:.3g} mm, over 150 measurements" in headline


def test_report_of_a_metre_file_shows_millimetres_and_states_the_file_unit(tmp_path):
    result = synthetic_result(Units("m", "rad"), validation=False, effects=False)
    path = write_report(result, tmp_path / "r.html", title="Cell 4 robot")
    page = read_page(path)
    text = path.read_text(encoding="utf-8")
    assert any(tag == "title" for tag, _ in page.tags) and "Cell 4 robot" in text
    headline = body_rows(page, "headline")
    assert list(headline) == ["fit"]
    assert float(headline["fit"][3]) == pytest.approx(result.fit.rms_final * 1e3, rel=6e-4)
    a2 = body_rows(page, "parameters")["a2"]
    assert a2[1] == "mm" and float(a2[3]) == pytest.approx(
        result.parameter("a2").estimate * 1e3, abs=1e-4)
    alpha1 = body_rows(page, "parameters")["alpha1"]
    assert alpha1[1] == "rad" and float(alpha1[2]) == pytest.approx(-np.pi / 2, abs=1e-7)
    units = next(t for kind, t in page.paragraphs if kind == "units")
    assert "in mm" in units and "robot file is in length m, angle rad" in units
    texts = " ".join(t for _, t in page.paragraphs)
    assert "No held-out data was given" in texts
    assert "Diagnosis added no effect" in texts
    ids = {attrs.get("id") for tag, attrs in page.tags if tag == "section"}
    assert "sphere" not in ids
    conclusion = next(t for kind, t in page.paragraphs if kind == "conclusion")
    assert f"to {result.fit.rms_final * 1e3:.3g} mm RMS" in conclusion
    assert " m RMS" not in conclusion


def test_matplotlib_pdf_beside_the_page(tmp_path):
    result = synthetic_result(validation=False, effects=False)
    path = write_report(result, tmp_path / "report.html", pdf=True, printer="matplotlib")
    pdf = path.with_suffix(".pdf").read_bytes()
    assert pdf.startswith(b"%PDF") and pdf.rstrip().endswith(b"%%EOF")
    pages = len(re.findall(rb"/Type\s*/Page\b", pdf))
    plots = len(re.findall(r"<img\b", path.read_text(encoding="utf-8")))
    assert plots == 5 and 4 <= pages <= plots + 6
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.html", "report.pdf"]


def test_nothing_written_when_rendering_fails(tmp_path, monkeypatch):
    from robocal_casadi.report import figures

    def broken(*args, **kwargs):
        raise RuntimeError("plot failed")

    monkeypatch.setattr(figures, "singular_values", broken)
    with pytest.raises(RuntimeError, match="plot failed"):
        write_report(synthetic_result(), tmp_path / "report.html", pdf=True)
    assert list(tmp_path.iterdir()) == []


def test_bad_arguments(tmp_path):
    with pytest.raises(InputError, match="is a folder"):
        write_report(synthetic_result(), tmp_path)
    with pytest.raises(TypeError, match="CalibrationResult"):
        write_report({"fit": 1}, tmp_path / "report.html")


# ----------------------------------------------------------------------------- with the engine


def _engine():
    identification = pytest.importorskip("robocal_casadi.calibration")
    simulate = pytest.importorskip("robocal_casadi.simulate")
    return identification.calibrate, simulate.simulate


def test_report_of_a_simulated_tracker_calibration(tmp_path):
    """The engine on a simulated truth (6R arm, compliance on joints 2 and 3, tracker noise
    10 um per coordinate): the report's fit RMS after calibration is the noise floor
    sqrt(3) x 10 um, and the effect found is shown with its plot."""
    calibrate, simulate = _engine()
    robot = examples.industrial_6r()
    noise = 1e-5
    common = dict(noise=noise, geometric_errors=(3e-4, 3e-4), progress=False,
                  effects={"joint_compliance": {2: 2e-6, 3: 2e-6}})
    fit = simulate(robot, "tracker_points", out_dir=tmp_path / "fit", rows=150, seed=1, **common)
    result = calibrate([fit.load()])
    path = write_report(result, tmp_path / "report.html")
    page = read_page(path)
    final_fit = float(body_rows(page, "headline")["fit"][3])  # mm
    assert final_fit == pytest.approx(np.sqrt(3) * noise * 1e3, rel=0.15)
    assert float(body_rows(page, "headline")["fit"][1]) > 20 * final_fit
    assert [e.name for e in result.effects] == ["joint_compliance"]
    compliance = body_rows(page, "effect-joint_compliance")
    for j in (2, 3):
        assert float(compliance[f"c{j}"][1]) == pytest.approx(2e-6, rel=0.1)
    figures = {attrs.get("id") for tag, attrs in page.tags if tag == "figure"}
    assert {"figure-effect-joint_compliance", "figure-singular-values",
            "figure-joints-fit"} <= figures
    # the effect's plot: error against the gravity torque at each joint (pinocchio), with
    # the fitted deflection from the effect model (CasADi) equal to -c tau
    from robocal_casadi.model.pinocchio_model import gravity_torques
    from robocal_casadi.report.effect_views import effect_view

    view = effect_view(result, result.effects[0])
    assert view.variable == "torque" and "gravity torque" in view.caption
    residuals = result.residuals[0]
    tau = gravity_torques(result.robot_calibrated, residuals.joints,
                          payload_mass=residuals.extras.get("payload", 0.0))
    for panel, j in zip(view.panels, (2, 3)):
        assert panel.x_label == f"gravity torque at joint {j} [N m]"
        np.testing.assert_allclose(panel.x, tau[residuals.rows, j - 1], rtol=1e-9, atol=1e-9)
        c = result.effects[0].parameters[f"c{j}"]
        np.testing.assert_allclose(np.deg2rad(panel.fitted), -c * panel.x, rtol=1e-7,
                                   atol=1e-12)
    # without compliance the error grows with the torque: largest at the extreme torques
    panel = view.panels[0]
    extreme = np.abs(panel.x) > np.percentile(np.abs(panel.x), 80)
    assert _rms(panel.geometric[extreme]) > 1.5 * _rms(panel.geometric[~extreme])
    assert _rms(panel.final[extreme]) < 0.2 * _rms(panel.geometric[extreme])


def test_report_of_a_simulated_sphere_laser_calibration(tmp_path):
    """Sphere and laser: the section shows the engine's fitted laser and sphere centre in
    the file's units, and the distance to the sphere after calibration is at the
    simulated laser noise (10 um)."""
    calibrate, simulate = _engine()
    robot = examples.industrial_6r()
    data = simulate(robot, "sphere_laser", out_dir=tmp_path / "sphere", rows=120, seed=3,
                    noise=1e-5, geometric_errors=(3e-4, 3e-4), progress=False)
    result = calibrate([data.load()], diagnose=False)
    path = write_report(result, tmp_path / "report.html")
    page = read_page(path)
    assert "sphere" in {attrs.get("id") for tag, attrs in page.tags if tag == "section"}
    laser = body_rows(page, "laser")
    for name, (value, _) in result.mounted.items():
        scale = 1.0 if name.startswith("laser_n") else 1e-3
        assert float(laser[name][1]) == pytest.approx(value / scale, abs=1e-4)
    centre = next(rows for name, rows in page.tables.items() if name.startswith("sphere-"))
    shown = {row[0]: float(row[1]) for row in centre[1:]}
    assert shown == pytest.approx({k: v * 1e3 for k, v in result.placement.items()}, abs=1e-4)
    # the truth's sphere centre, from the simulator, is where the report says (within 1 mm)
    truth = np.asarray(data.truth.placement["sphere_centre"]) * 1e3
    np.testing.assert_allclose(sorted(shown.values()), sorted(truth), atol=1.0)
    final = float(body_rows(page, "headline")["fit"][3])
    assert 0.5e-2 < final < 1.2e-2  # mm: the laser noise, less what the fit absorbs


def test_pendant_sphere_data_without_joint_readings(tmp_path):
    """Sphere readings taken from pendant poses carry no joint readings: no joint plot,
    the rest of the report as usual."""
    result = synthetic_result(validation=False, effects=False, sphere=True)
    residuals = tuple(replace(r, joints=None) if r.kind == "sphere_laser" else r
                      for r in result.residuals[1:])
    result = replace(result, residuals=residuals, datasets=("sphere.yaml",))
    page = read_page(write_report(result, tmp_path / "report.html"))
    figures = {attrs.get("id") for tag, attrs in page.tags if tag == "figure"}
    assert "figure-joints-fit" not in figures and "figure-order-fit" in figures
    assert body_rows(page, "datasets")["sphere.yaml"][3] == "120"


# ----------------------------------------------------------------------------- effect plots


def _with_effect_models(result: CalibrationResult, models: tuple, values) -> CalibrationResult:
    findings = []
    start = 0
    for model in models:
        size = len(model.parameter_names())
        theta = dict(zip(model.parameter_names(), values[start:start + size]))
        findings.append(EffectFinding(model.name, model.joints, theta, model.unit,
                                      {"rms_drop": 0.2, "bic_drop": 50.0}))
        start += size
    return replace(result, effects=tuple(findings), effect_models=tuple(models),
                   effect_values=np.asarray(values, dtype=float))


def test_cyclic_effect_plot_overlays_the_fitted_harmonics():
    """The periodic error is shown against the joint angle with the fitted harmonic
    curve; the curve equals the formula evaluated here with numpy, in degrees."""
    from robocal_casadi.effects.cyclic import JointCyclic
    from robocal_casadi.report.effect_views import effect_view

    theta = [1.5e-3, -2.4e-3, -8.9e-4, -3.8e-4]  # a1, b1, a2, b2 [rad]
    result = _with_effect_models(synthetic_result(validation=False, effects=False),
                                 (JointCyclic((2,)),), theta)
    view = effect_view(result, result.effects[0])
    assert view.variable == "joint" and len(view.panels) == 1
    panel = view.panels[0]
    assert panel.x_label == "q2 [deg]" and panel.fitted_is_curve
    q = np.deg2rad(panel.x)
    a1, b1, a2, b2 = theta
    expected = np.rad2deg(a1 * np.sin(q) + b1 * np.cos(q) + a2 * np.sin(2 * q) + b2 * np.cos(2 * q))
    np.testing.assert_allclose(panel.fitted, expected, atol=1e-12)
    residuals = result.residuals[0]
    np.testing.assert_allclose(panel.geometric, residuals.errors_geometric * 1e3)
    assert "a1 sin q + b1 cos q" in view.caption


def test_effect_parameters_in_the_file_angle_unit(tmp_path):
    from robocal_casadi.effects.cyclic import JointCyclic

    theta = [1.5e-3, -2.4e-3, -8.9e-4, -3.8e-4]
    result = _with_effect_models(synthetic_result(validation=False, effects=False),
                                 (JointCyclic((2,)),), theta)
    page = read_page(write_report(result, tmp_path / "report.html"))
    rows = body_rows(page, "effect-joint_cyclic")
    assert list(rows) == ["a1_2", "b1_2", "a2_2", "b2_2"]  # the model's order
    for name, value in zip(rows, theta):
        assert rows[name][3] == "deg"
        assert float(rows[name][1]) == pytest.approx(np.rad2deg(value), rel=1e-3)
    assert "figure-effect-joint_cyclic" in {a.get("id") for t, a in page.tags if t == "figure"}


def test_compliance_without_link_masses_is_shown_against_the_joint_angle():
    """A robot file without masses has no gravity torque: the lumped compliance is
    plotted against the joint angle, and the caption says why."""
    from robocal_casadi.effects.compliance import JointCompliance
    from robocal_casadi.report.effect_views import effect_view

    result = synthetic_result(validation=False, effects=False)
    bare = replace(result.robot_calibrated,
                   joints=tuple(replace(j, mass=None, com=None)
                                for j in result.robot_calibrated.joints))
    model = JointCompliance((3,), bare)
    values = np.full(len(model.parameter_names()), 2e-6)
    result = _with_effect_models(replace(result, robot_calibrated=bare,
                                         robot_nominal=replace(result.robot_nominal,
                                                               joints=bare.joints)),
                                 (model,), values)
    view = effect_view(result, result.effects[0])
    assert view.variable == "joint" and view.panels[0].x_label == "q3 [deg]"
    assert "no link masses" in view.caption
    panel = view.panels[0]
    assert panel.fitted is not None and not panel.fitted_is_curve
    assert np.ptp(panel.fitted) > 0


def test_thermal_drift_is_shown_against_temperature_with_the_fitted_growth():
    from robocal_casadi.effects.thermal import ThermalDrift
    from robocal_casadi.report.effect_views import effect_view

    result = synthetic_result(validation=False, effects=False)
    model = ThermalDrift(column="temperature", reference_value=23.3)
    result = _with_effect_models(result, (model,), [1.2e-5])
    view = effect_view(result, result.effects[0])
    panel = view.panels[0]
    assert view.variable == "temperature" and panel.x_label == "temperature [C]"
    np.testing.assert_allclose(panel.x, result.residuals[0].extras["temperature"])
    np.testing.assert_allclose(panel.fitted, 1.2e-5 * (panel.x - 23.3) * 1e6)


def _diagnosis(rounds: int = 3) -> tuple[CandidateTest, ...]:
    """60 candidate tests as diagnosis records them; joint 2 compliance added in round 1."""
    entries = []
    rng = np.random.default_rng(4)
    for r in range(1, rounds + 1):
        for effect in ("joint_compliance", "joint_cyclic", "joint_scale"):
            for j in range(1, 7):
                added = (r, effect, j) == (1, "joint_compliance", 2)
                entries.append({"round": r, "effect": effect, "joints": (j,),
                                "parameters": 0 if j == 6 else 1, "held": ("c6",) if j == 6 else (),
                                "remaining_norm": float(rng.uniform()),
                                "rss_drop": float(rng.uniform(0, 0.3)),
                                "bic_drop": 900.0 if added else float(rng.normal(20, 60)),
                                "cv_rms_before": 4e-4, "cv_rms_after": 3.6e-4,
                                "decision": "added" if added else "not supported"})
        entries.append({"round": r, "effect": "thermal_drift", "joints": (), "parameters": 1,
                        "held": (), "remaining_norm": 0.93, "rss_drop": 1e-4, "bic_drop": -7.1,
                        "cv_rms_before": 4e-4, "cv_rms_after": 4.01e-4,
                        "decision": "not supported"})
        entries.append({"round": r, "effect": "joint_cyclic", "joints": (6,), "parameters": 1,
                        "held": ("a1_6", "b1_6"), "remaining_norm": 0.002, "rss_drop": 1e-3,
                        "bic_drop": float("nan"), "cv_rms_before": 4e-4,
                        "cv_rms_after": float("nan"), "decision": "not supported"})
    return tuple(CandidateTest(**e, outcome=Decision.ADDED if e["decision"] == "added"
                               else Decision.NOT_PAYING) for e in entries)


def test_diagnosis_shows_the_added_and_strongest_rejected_and_folds_the_rest(tmp_path):
    diagnosis = _diagnosis()
    assert len(diagnosis) == 60
    result = replace(synthetic_result(validation=False), diagnosis=diagnosis)
    path = write_report(result, tmp_path / "report.html")
    page = read_page(path)
    summary = page.tables["diagnosis-summary"][1:]
    rejected = sorted((e for e in diagnosis if e.outcome is not Decision.ADDED
                       and e.parameters > 0 and np.isfinite(e.bic_drop)),
                      key=lambda e: -e.bic_drop)[:5]
    assert len(summary) == 1 + 5
    decision = page.tables["diagnosis-summary"][0].index("decision")
    assert summary[0][1] == "joint compliance" and summary[0][decision] == "added"
    assert [float(row[7]) for row in summary[1:]] == pytest.approx(
        [round(e.bic_drop, 1) for e in rejected], abs=0.051)
    assert [row[6] for row in summary[:1]] == [f"{100 * diagnosis[1].rss_drop:.1f} %"]
    # every candidate, in a folded block that opens for printing
    assert len(page.tables["diagnosis"]) == 1 + 60
    text = path.read_text(encoding="utf-8")
    block = text[text.index('<details id="diagnosis-all">'):]
    assert '<table class="diagnosis">' in block[:block.index("</details>")]
    assert "<summary>All 60 candidates tested</summary>" in block
    assert "details::details-content { content-visibility: visible" in text
    assert 'addEventListener("beforeprint"' in text
    # the folds' RMS in mm, not metres, not called held-out (the held-out set is another
    # figure); a NaN shows as a dash
    header = page.tables["diagnosis"][0]
    assert "fold RMS before [mm]" in header and not any("held-out" in h for h in header)
    assert float(page.tables["diagnosis"][1][header.index("fold RMS before [mm]")]) == 0.4
    assert page.tables["diagnosis"][-1][header.index("BIC drop")] == "-"


def test_pdf_prints_the_folded_diagnosis_table(tmp_path):
    result = replace(synthetic_result(validation=False, effects=False), diagnosis=_diagnosis(1))
    from robocal_casadi.report.pdf import write_pdf
    from robocal_casadi.report.sections import build_document

    document = build_document(result)
    effects = next(s for s in document.sections if s.anchor == "effects")
    details = [b for b in effects.blocks if type(b).__name__ == "Details"]
    assert len(details) == 1 and details[0].blocks[0].name == "diagnosis"
    assert len(details[0].blocks[0].rows) == 20
    write_pdf(document, tmp_path / "report.pdf")
    assert (tmp_path / "report.pdf").read_bytes().startswith(b"%PDF")


def test_dataset_names_read_as_names_and_derived_columns_as_derived(tmp_path):
    """Held-out data are named by their file, not by the calibration's key
    (``validation:NAME``), in a sentence that agrees in number; the columns derived from
    the row order are listed apart from the user's own."""
    base = synthetic_result()
    held = replace(base.validation_residuals[0], label="validation:series_D_validation",
                   placement_frame="fitted on these data")
    fit = replace(base.residuals[0], extras={
        **base.residuals[0].extras, "direction_q2": np.zeros(len(base.residuals[0].rows)),
        "travel_q2": np.zeros(len(base.residuals[0].rows))})
    result = replace(base, residuals=(fit, *base.residuals[1:]), validation_residuals=(held,))
    path = write_report(result, tmp_path / "report.html")
    text = path.read_text(encoding="utf-8")
    assert "validation:series_D" not in text
    assert ("The held-out data set series_D_validation has the instrument placement refitted "
            "on itself") in text
    page = read_page(path)
    rows = body_rows(page, "datasets")
    assert rows["series_D_validation"][1] == "validation"
    extra = rows["series_A.yaml"][-1]
    assert extra == "temperature; derived from the row order: direction_q2, travel_q2"


def test_workspace_before_and_after_share_one_colour_scale():
    """A colour means one error in both rows: every panel's scale runs from zero to the
    99th percentile of the before and after errors together."""
    from robocal_casadi.report.kind_figures import workspace

    residuals = synthetic_result().residuals[0]
    positions = np.random.default_rng(2).uniform(-1, 1, size=(len(residuals.rows), 3))
    figure = workspace((residuals,), (positions,), Units("mm", "deg"), "series_A")
    assert len(figure.axes) == 5  # four panels and one colour bar
    scales = [(c.norm.vmin, c.norm.vmax) for axes in figure.axes[:4] for c in axes.collections]
    both = np.abs(np.concatenate([residuals.errors_nominal, residuals.errors_final])) / 1e-3
    assert len(scales) == 4
    assert all(low == 0.0 and high == pytest.approx(np.percentile(both, 99), rel=1e-12)
               for low, high in scales)
