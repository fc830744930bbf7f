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

from robocal_casadi import examples
from robocal_casadi.errors import InputError
from robocal_casadi.report import write_report
from robocal_casadi.results import (
    CalibrationResult,
    DatasetResiduals,
    EffectFinding,
    Identifiability,
    ParameterEstimate,
    RmsSummary,
)
from robocal_casadi.units import Units

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
            self.tables[self._table].append([])
            self.muted[self._table].append(attrs.get("class") == "muted")
        elif tag in ("td", "th"):
            self._cell = []
        elif tag == "p":
            self._paragraph = (attrs.get("class", ""), [])

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
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
    assert ids == {"conclusion", "robot-data", "identifiability", "parameters", "errors",
                   "effects", "sphere", "instrument"}


def test_every_image_is_a_png_with_content(full_report):
    _, path = full_report
    images = [attrs for tag, attrs in read_page(path).tags if tag == "img"]
    # singular values, distribution, joints + order for fit and for validation, 2 effects
    assert len(images) == 1 + 1 + 2 * 2 + 2
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


def test_parameter_table_in_file_units_with_held_parameters_greyed(full_report):
    result, path = full_report
    page = read_page(path)
    rows = body_rows(page, "parameters")
    assert len(rows) == len(result.parameters)
    for p in result.parameters:
        row = rows[p.name]
        scale = 1e-3 if p.quantity == "length" else np.pi / 180
        resolution = 1e-4 if p.quantity == "length" else 1e-5
        assert row[1] == ("mm" if p.quantity == "length" else "deg")
        assert float(row[2]) == pytest.approx(p.nominal / scale, abs=resolution)
        assert float(row[3]) == pytest.approx(p.estimate / scale, abs=resolution)
        assert float(row[4]) == pytest.approx((p.estimate - p.nominal) / scale, abs=resolution)
        if p.identifiable:
            assert float(row[5]) == pytest.approx(p.std / scale, rel=5e-3)
        else:
            assert row[5] == "-" and p.reason in row[6]
    greyed = {r[0] for r, muted in zip(page.tables["parameters"], page.muted["parameters"])
              if muted}
    assert greyed == set(HELD_AT_NOMINAL)


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
    assert float(body_rows(page, "evidence-joint_compliance")["bic_drop"][1]) == 412.0
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


def test_report_in_metres_and_radians_without_validation_or_effects(tmp_path):
    result = synthetic_result(Units("m", "rad"), validation=False, effects=False)
    path = write_report(result, tmp_path / "r.html", title="Cell 4 robot")
    page = read_page(path)
    assert any(tag == "title" for tag, _ in page.tags) and "Cell 4 robot" in path.read_text()
    headline = body_rows(page, "headline")
    assert list(headline) == ["fit"]
    assert float(headline["fit"][3]) == pytest.approx(result.fit.rms_final, rel=6e-4)
    a2 = body_rows(page, "parameters")["a2"]
    assert a2[1] == "m" and float(a2[3]) == pytest.approx(result.parameter("a2").estimate,
                                                          abs=1e-7)
    alpha1 = body_rows(page, "parameters")["alpha1"]
    assert alpha1[1] == "rad" and float(alpha1[2]) == pytest.approx(-np.pi / 2, abs=1e-7)
    texts = " ".join(t for _, t in page.paragraphs)
    assert "No held-out data was given" in texts
    assert "Diagnosis added no effect" in texts
    ids = {attrs.get("id") for tag, attrs in page.tags if tag == "section"}
    assert "sphere" not in ids


def test_pdf_beside_the_page(tmp_path):
    result = synthetic_result(validation=False, effects=False)
    path = write_report(result, tmp_path / "report.html", pdf=True)
    pdf = path.with_suffix(".pdf").read_bytes()
    assert pdf.startswith(b"%PDF") and pdf.rstrip().endswith(b"%%EOF")
    pages = len(re.findall(rb"/Type\s*/Page\b", pdf))
    plots = len(re.findall(r"<img\b", path.read_text(encoding="utf-8")))
    assert plots == 4 and pages >= plots + 2  # every plot on its own page, and the text
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
    identification = pytest.importorskip("robocal_casadi.identification")
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
