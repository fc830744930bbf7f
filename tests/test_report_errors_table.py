"""``errors.csv``: one row per error, its CSV line, and RMS figures equal to result.json's."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from test_report import synthetic_result

from robocal_casadi.common.units import Units
from robocal_casadi.instruments.datasets import load_dataset
from robocal_casadi.model import examples
from robocal_casadi.report.errors_table import COLUMNS, write_errors_csv

STAGES = ("nominal", "geometric", "final")
OUTLIER = 5e-3  # [m] added to one reading's x: hundreds of times the simulated noise


def _read(path):
    with path.open(newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    return rows


def _rms_per_dataset(rows) -> dict[tuple[str, str], dict[str, float]]:
    out: dict[tuple[str, str], dict[str, float]] = {}
    for key in {(r["dataset"], r["role"]) for r in rows}:
        chosen = [r for r in rows if (r["dataset"], r["role"]) == key]
        out[key] = {m: float(np.sqrt(np.mean([float(r[f"error_{m}_mm"]) ** 2 for r in chosen])))
                    for m in STAGES}
    return out


def _corrupt(table, row: int) -> int:
    """Put a blank line before data row ``row`` and move its x by ``OUTLIER``; return the
    line (1-based) it now sits on."""
    lines = table.read_text().splitlines()
    header = lines[0].split(",")
    target = row + 1  # the header is line 1
    cells = lines[target].split(",")
    k = header.index("x")
    cells[k] = repr(float(cells[k]) + OUTLIER / 1e-3)  # the simulated table is in mm
    lines[target] = ",".join(cells)
    lines.insert(target, "")
    table.write_text("\n".join(lines) + "\n")
    return target + 2


def test_lines_point_at_the_corrupted_reading_and_rms_match_result_json(tmp_path):
    """A simulated tracker calibration (60 readings, 10 um noise) with one reading moved
    by 5 mm and a blank line before it: the largest error after calibration is on that
    reading's line, and every dataset's RMS over the file's rows is result.json's."""
    identification = pytest.importorskip("robocal_casadi.calibration")
    from robocal_casadi.instruments.simulate import simulate

    robot = examples.industrial_6r().with_units(Units("mm", "deg"))
    common = dict(noise=1e-5, geometric_errors=(3e-4, 3e-4), progress=False)
    fit = simulate(robot, "tracker_points", out_dir=tmp_path / "fit", rows=60, seed=3, **common)
    held = simulate(robot, "tracker_points", out_dir=tmp_path / "held", rows=25, seed=4,
                    **common)
    dataset = fit.load()
    line = _corrupt(dataset.data_path, 17)
    # plain least squares: the robust default would set the corrupted reading aside
    result = identification.calibrate([load_dataset(dataset.path)], [held.load()],
                                      diagnose=False, loss="linear")
    rows = _read(write_errors_csv(result, tmp_path))
    assert tuple(rows[0]) == COLUMNS
    fitted = [r for r in rows if r["role"] == "fit"]
    assert len(fitted) == 60 and sum(r["role"] == "validation" for r in rows) == 25
    worst = max(fitted, key=lambda r: float(r["error_final_mm"]))
    assert int(worst["line"]) == line
    text = dataset.data_path.read_text().splitlines()
    assert text[line - 2] == ""  # the blank line counted, the reading right after it
    assert float(worst["error_nominal_mm"]) > 0.5 * OUTLIER / 1e-3
    # every other reading keeps the line it had: data row i on line i + 2 before the blank
    others = [int(r["line"]) for r in fitted if r is not worst]
    assert others == [i + 2 for i in range(17)] + [i + 3 for i in range(18, 60)]

    saved = json.loads(json.dumps(result.to_json()))
    scale = result.units.length_scale / 1e-3  # file unit in mm
    ours = _rms_per_dataset(rows)
    for role in ("fit", "validation"):
        for entry in saved[role]["datasets"]:
            for m in STAGES:
                assert ours[(entry["dataset"], role)][m] == pytest.approx(
                    entry[f"rms_{m}"] * scale, rel=1e-9)


@pytest.mark.parametrize("units", [Units("mm", "deg"), Units("m", "rad")])
def test_errors_in_millimetres_whatever_the_file_unit(tmp_path, units):
    """Synthetic tracker and bar residuals: each row's value is the stored error [m] in mm,
    placement-wide errors (bar lengths) have no line, and validation rows are marked."""
    result = synthetic_result(units, bar=True)
    rows = _read(write_errors_csv(result, tmp_path))
    expected = [(role, r) for role, group in (("fit", result.residuals),
                                              ("validation", result.validation_residuals))
                for r in group]
    assert len(rows) == sum(len(r.errors_final) for _, r in expected)
    start = 0
    for role, r in expected:
        chunk = rows[start:start + len(r.errors_final)]
        start += len(r.errors_final)
        assert {c["dataset"] for c in chunk} == {r.label} and {c["role"] for c in chunk} == {role}
        for m in STAGES:
            np.testing.assert_allclose([float(c[f"error_{m}_mm"]) for c in chunk],
                                       np.abs(getattr(r, f"errors_{m}")) * 1e3, rtol=1e-15)
        mapped = np.asarray(r.rows) >= 0
        assert [c["line"] for c in chunk] == [str(k + 2) if k >= 0 else "" for k in r.rows]
        assert (~mapped).sum() == sum(c["line"] == "" for c in chunk)


def test_nothing_written_for_a_result_of_the_wrong_type(tmp_path):
    with pytest.raises(TypeError):
        write_errors_csv({"fit": {}}, tmp_path)  # type: ignore[arg-type]
    assert not (tmp_path / "errors.csv").exists()


def test_readings_set_aside_are_listed_too(tmp_path):
    """The robust default sets the corrupted reading aside; errors.csv still has a row for
    its line, with the error it showed (nothing dropped silently)."""
    identification = pytest.importorskip("robocal_casadi.calibration")
    from robocal_casadi.instruments.simulate import simulate

    robot = examples.industrial_6r().with_units(Units("mm", "deg"))
    fit = simulate(robot, "tracker_points", out_dir=tmp_path / "fit", rows=60, seed=3,
                   noise=1e-5, geometric_errors=(3e-4, 3e-4), progress=False)
    dataset = fit.load()
    line = _corrupt(dataset.data_path, 17)
    result = identification.calibrate([load_dataset(dataset.path)], diagnose=False)
    assert [r.line for r in result.rejected] == [line]
    rows = _read(write_errors_csv(result, tmp_path))
    aside = [r for r in rows if r["role"] == "fit, set aside"]
    assert [int(r["line"]) for r in aside] == [line]
    assert float(aside[0]["error_final_mm"]) == pytest.approx(result.rejected[0].residual / 1e-3)
    assert len(rows) == 60  # 59 kept readings and the one set aside
