"""What a reader sees of a calibration in metres: one length unit (mm) in the terminal block
and the report, held-out figures over every reading first, the cross-validation of the fit
data never called held-out, and which comparison decides where two disagree.

Data: the example 7-DOF arm (robot file in m/rad), tracker readings simulated with a
compliant joint, and held-out readings of the same true robot (``simulate --truth``) with
two of them corrupted into gross errors.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from robocal_casadi.cli import main
from robocal_casadi.instruments.simulate import inject_gross_errors, simulate, simulate_again
from robocal_casadi.model.examples import ROBOTS

METRES = re.compile(r"(?<![a-z])(\[m\]|\d m\b|\d m[,;.)])")  # a length printed in metres


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> tuple[Path, str, dict, tuple[int, ...]]:
    root = tmp_path_factory.mktemp("metres")
    robot = ROBOTS["panda_7dof"]()
    assert robot.units.length == "m"
    fit = simulate(robot, "tracker_points", out_dir=root / "fit", rows=120, noise=2e-5,
                   geometric_errors=(3e-4, 3e-4), effects={"joint_compliance": {2: 4e-5}},
                   payload=(0.0, 3.0), seed=1, progress=False)
    held = simulate_again(fit.truth_path, out_dir=root / "val", rows=40, seed=2,
                          payload=(0.0, 3.0), progress=False)
    lines = inject_gross_errors(held, 0.05, seed=3)
    out = root / "out"
    status = main(["calibrate", str(fit.dataset_path), "--validate", str(held.dataset_path),
                   "--out", str(out)])
    assert status == 0
    return out, (out / "report.html").read_text(encoding="utf-8"), \
        json.loads((out / "result.json").read_text()), lines


def test_the_terminal_block_of_a_metre_file_is_in_mm(run, capsys):
    out, _, result, _ = run
    from robocal_casadi.commands.calibrate import summary
    from robocal_casadi.instruments.datasets import load_dataset
    from robocal_casadi.job.run import calibrate_job

    assert result["fit"]["unit"] == "m"  # result.json keeps the file's unit
    fit = load_dataset(out.parent / "fit" / "dataset.yaml")
    val = load_dataset(out.parent / "val" / "dataset.yaml")
    text = summary(calibrate_job([fit], [val]))
    assert "fit RMS [mm]" in text and not METRES.search(text), METRES.findall(text)
    found = [line for line in text.splitlines() if line.startswith("effect (")]
    assert found and all(" mm" in line for line in found)
    # the fit data's cross-validation is never called held-out
    assert all("cross-validated RMS of the fit data" in line for line in found)


def test_held_out_figures_lead_with_every_reading(run):
    out, page, result, corrupted = run
    validation = result["validation"]
    assert validation["rejected"] >= 1 and len(corrupted) == 2
    every, kept = validation["all"], validation["kept"]
    assert every["rms_final"] > kept["rms_final"]  # the gross errors count in the headline
    from robocal_casadi.report.numbers import format_number

    conclusion = page[page.index("After calibration"):]
    headline = conclusion[:conclusion.index(".</p>") if ".</p>" in conclusion else 600]
    first = format_number(every["rms_final"] * 1e3, 3)
    second = format_number(kept["rms_final"] * 1e3, 3)
    assert "every held-out reading" in headline and first in headline and second in headline
    assert headline.index(first) < headline.index(second)
    assert "set aside as gross errors" in headline


def test_the_report_of_a_metre_file_has_no_length_in_metres(run):
    _, page, _, _ = run
    text = re.sub(r"<[^>]+>", " ", page)
    assert "Lengths in this report are in mm" in text
    assert not METRES.search(text), METRES.findall(text)[:5]


def test_a_disagreement_of_folds_and_held_out_data_says_which_decides():
    """A result whose effects passed the folds but lose on the held-out set: the warning
    and the conclusion name the held-out set as the judge and say why."""
    from dataclasses import replace

    from robocal_casadi.report.conclusion import conclusion_paragraphs
    from robocal_casadi.results import HELD_OUT_DECIDE, EffectFinding, RmsSummary

    result = _small_result()
    effect = EffectFinding("joint_scale", (2,), {"s2": 1e-4}, "1",
                           {"cv_rms_before": 4.2e-4, "cv_rms_after": 4.0e-4}, {"s2": 1e-5})
    worse = replace(result, recommended="geometric", effects=(effect,),
                    validation=RmsSummary(2e-3, 4e-4, 5e-4), validation_all=None)
    assert "WORSE" in worse.warning and HELD_OUT_DECIDE in worse.warning
    assert "0.5 vs 0.4 mm" in worse.warning and " m)" not in worse.warning
    opening = conclusion_paragraphs(worse)[0]
    assert opening.startswith("Use the geometric calibration alone") and HELD_OUT_DECIDE in opening


def test_a_lumped_compliance_term_carries_its_own_unit():
    """``c6_m7`` is a compliance times a link mass: [rad kg/Nm], in result.json and the
    report's table, not the compliance's [rad/Nm]."""
    from robocal_casadi.effects.compliance import JointCompliance
    from robocal_casadi.results import EffectFinding

    effect = JointCompliance((6,))
    finding = EffectFinding("joint_compliance", (6,), {"c6": 1e-5, "c6_m7": 2.17e-3},
                            effect.unit, {}, {}, "", {n: effect.parameter_unit(n)
                                                      for n in ("c6", "c6_m7")})
    entry = finding.to_json()
    assert entry["units"] == {"c6": "rad/Nm", "c6_m7": "rad kg/Nm"}
    assert finding.unit_of("c6_m7") == "rad kg/Nm" and finding.unit_of("c6") == "rad/Nm"


_cache: dict = {}


def _small_result():
    """A calibration of simulated tracker data (mm file) with diagnosis off."""
    if "result" not in _cache:
        import tempfile

        from robocal_casadi.calibration import calibrate

        folder = Path(tempfile.mkdtemp())
        data = simulate(ROBOTS["industrial_6r"](), "tracker_points", out_dir=folder / "d",
                        rows=40, noise=1e-5, seed=4, progress=False).load()
        _cache["result"] = calibrate([data], diagnose=False)
    result = _cache["result"]
    assert np.isfinite(result.fit.rms_final)
    return result
