"""docs/measured.md (the measured figures, once README.md's Measured section) is what
benchmarks/readme_measured.py renders from the saved benchmark JSON (benchmarks/results),
and the renderer takes its figures from it."""

from __future__ import annotations

import copy
import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SPEC = importlib.util.spec_from_file_location("readme_measured",
                                              ROOT / "benchmarks" / "readme_measured.py")
assert SPEC is not None and SPEC.loader is not None
measured = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(measured)
PAGE_TEXT = (ROOT / "docs" / "measured.md").read_text()


def test_the_page_is_what_the_saved_json_renders():
    # A hand edit of the section, or a new JSON without rewriting the page, fails here:
    # run `python benchmarks/readme_measured.py`.
    assert measured.section(PAGE_TEXT) == measured.rendered()


@pytest.mark.parametrize("name", measured.ORDER)
def test_every_part_says_where_its_figures_come_from(name):
    record = measured.load(name)
    assert record["benchmark"] == name
    if record["provenance"] == "run":
        facts = record["measured"]
        assert facts["date"] and facts["commit"] and facts["machine"]["cores"]
        assert record["command"].startswith("OPENBLAS_NUM_THREADS=1 python benchmarks/")
        assert isinstance(record["output"], dict) and name in measured.RENDERERS
    elif record["provenance"] == "written":
        facts = record["measured"]
        assert facts["date"] and facts["commit"] and record["text"]
        assert record["source"].startswith("Written from")
    else:
        assert record["provenance"] == "transcribed"
        assert record["source"].startswith("Not measured again") and record["text"]


def _run_record(name: str) -> dict:
    record = measured.load(name)
    if record["provenance"] != "run":
        pytest.skip(f"{name} has no saved run")
    return record


def test_the_calibration_table_is_read_from_the_run():
    record = copy.deepcopy(_run_record("calibration"))
    case = record["output"]["cases"][-1]
    case["headline"]["speedup_same_answer"] = 123.0
    case["numpy_scipy_least_squares_fd_converged"]["max_relative_difference"] = 4.5e-11
    text = measured.render_calibration(record)
    assert "(123x), off by 4.5e-11" in text
    assert case["case"] in text


def test_the_jobs_table_is_read_from_the_run():
    record = copy.deepcopy(_run_record("jobs"))
    case = record["output"]["cases"][0]
    case["cpu_seconds"], case["peak_memory_mib"] = 98.7, 1000.0
    text = measured.render_jobs(record)
    assert "| 98.7 |" in text and "1000 MiB (1049 MB)" in text


def test_the_fleet_memory_table_is_read_from_the_run():
    record = copy.deepcopy(_run_record("fleet_memory"))
    output = record["output"]
    last = max(output["checkpoints"], key=int)
    output["checkpoints"][last]["largest_peak_mib"] = 654.0
    output["largest_peak_last_over_first"] = 3.21
    text = measured.render_fleet_memory(record)
    assert "| 654 MiB |" in text and "3.21x" in text and "over the target" in text


def test_the_last_json_object_is_taken_from_mixed_output():
    printed = 'progress\n{"a": 1}\nmore\n' + json.dumps({"b": [1, 2]}, indent=2) + "\n"
    assert measured.last_json(printed) == {"b": [1, 2]}
    with pytest.raises(ValueError):
        measured.last_json("no json here\n")
