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
def test_every_part_is_a_saved_run_that_says_where_it_ran(name):
    record = measured.load(name)
    assert record["benchmark"] == name
    assert record["provenance"] == "run"
    facts = record["measured"]
    assert facts["date"] and facts["commit"] and facts["machine"]["cores"]
    assert len(facts["machine"]["load_average"]) == 3
    assert isinstance(record["output"], dict) and name in measured.RENDERERS
    # A note may say how the run was made, never carry figures of another run.
    assert record.get("notes_source", "how this run was made").startswith(
        "how this run was made")


@pytest.mark.parametrize("name", measured.ORDER)
def test_every_part_is_measured_again_by_its_recorded_command(name):
    script, *arguments = measured.RUNS[name]
    assert (ROOT / "benchmarks" / script).is_file()
    assert measured.load(name)["command"] == " ".join(
        ["OPENBLAS_NUM_THREADS=1", "python", f"benchmarks/{script}", *arguments])


def test_a_part_that_is_no_saved_run_is_refused():
    records = {name: measured.load(name) for name in measured.ORDER}
    name = measured.ORDER[0]
    records[name] = dict(records[name], provenance="transcribed")
    with pytest.raises(ValueError, match=name):
        measured.render(records)


def _run_record(name: str) -> dict:
    record = measured.load(name)
    assert record["provenance"] == "run"
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


def test_the_setup_paragraph_is_read_from_the_run():
    record = copy.deepcopy(_run_record("setup"))
    output = record["output"]
    output["demo"][0]["cpu_seconds"] = 61.0
    output["tests"].update(cpu_seconds=1234.0, wall_seconds=4321.0, finished=True,
                           counts={"passed": 1111, "failed": 2})
    output["tests"]["load_average_before"][0] = 9.25
    text = measured.render_setup(record)
    assert "took 61 s of CPU" in text and "21 min of CPU and 72 min of wall time" in text
    assert "load average 9.2 at the start" in text or "load average 9.3 at the start" in text
    assert "1,111 passed, 2 failed" in text
    # A run stopped at its limit says how far it came, and marks the whole as extrapolated.
    output["tests"].update(finished=False, progress_percent=50, counts={})
    text = measured.render_setup(record)
    assert "did not finish" in text and "through 50% of the tests" in text
    assert "about 41 min of CPU (an extrapolation" in text


def test_the_kinematics_table_is_read_from_the_run():
    record = copy.deepcopy(_run_record("kinematics"))
    robot = record["output"]["robots"]["industrial_6r"]
    robot["fk_us"]["casadi_compiled_batched"] = 0.123
    robot["fk_parameter_jacobian_us"]["numpy_finite_differences_batched"] = 4567.0
    text = measured.render_kinematics(record)
    assert "| 0.12 / " in text and " / 4567 |" in text


def test_the_delivered_table_is_read_from_the_run():
    record = copy.deepcopy(_run_record("delivered"))
    kind, cases = next(iter(record["output"]["cases"].items()))
    case = next(c for c in cases if "predicted_over_true" in c)
    case["predicted_over_true"] = 7.77
    text = measured.render_delivered(record)
    assert " 7.77" in text


def test_a_job_that_stopped_is_listed_as_failed_not_timed():
    record = copy.deepcopy(_run_record("jobs"))
    case = record["output"]["cases"][0]
    case["exit_status"], case["cpu_seconds"] = 2, 0.77
    text = measured.render_jobs(record)
    assert "| 0.77 |" not in text and "(exit status 2)" in text


def test_the_first_demo_is_read_from_the_run():
    record = copy.deepcopy(_run_record("first_run"))
    first, again = record["output"]["demo"][:2]
    assert (first["cache"], again["cache"]) == ("empty", "filled by the run before")
    first["cpu_seconds"], again["exit_status"] = 87.0, 3
    text = measured.render_first_run(record)
    assert "with the cache empty: 87 s of CPU" in text and "(exit status 3)" in text


def test_the_fleet_paragraph_is_read_from_the_run():
    record = copy.deepcopy(_run_record("fleet"))
    output = record["output"]
    output["run_2_workers"]["wall_s"], output["run_1_workers"]["wall_s"] = 50.0, 95.0
    output["speedup_two_vs_one"] = 1.9
    output["flagged"] = ["r099"]
    text = measured.render_fleet(record)
    assert "Two workers took 50 s and one 95 s (1.90x)" in text
    assert "standing out: r099" in text


def test_the_setup_benchmark_reads_pytest_counts():
    spec = importlib.util.spec_from_file_location("setup_benchmark",
                                                  ROOT / "benchmarks" / "setup.py")
    assert spec is not None and spec.loader is not None
    setup = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(setup)
    assert setup.pytest_counts("6 failed, 1218 passed, 3 skipped, 41 deselected in 2940.12s") \
        == {"failed": 6, "passed": 1218, "skipped": 3, "deselected": 41}


def test_the_last_json_object_is_taken_from_mixed_output():
    printed = 'progress\n{"a": 1}\nmore\n' + json.dumps({"b": [1, 2]}, indent=2) + "\n"
    assert measured.last_json(printed) == {"b": [1, 2]}
    with pytest.raises(ValueError):
        measured.last_json("no json here\n")


def test_the_cable_table_is_read_from_the_run():
    record = copy.deepcopy(_run_record("cable"))
    declared = record["output"]["declared"]
    declared["held_out_rms_mm"]["final_over_floor"] = 9.87
    declared["largest_relative_error"] = 0.0432
    record["output"]["undeclared"]["drive_lines"] = ["joint 4: a line of the run"]
    text = measured.render_cable(record)
    assert "9.87x (target 1.1x)" in text and "largest relative error 4.3%" in text
    assert "joint 4: a line of the run" in text
    # every estimate against its truth, by name
    for effect, parameters in declared["estimates"].items():
        for parameter in parameters:
            assert f"| {effect} | {parameter} |" in text


def test_a_benchmark_saves_its_json_the_way_a_run_does(tmp_path, monkeypatch):
    monkeypatch.setattr(measured, "RESULTS", tmp_path)
    record = measured.save("example", "example.py", ["--seed", "3"], {"figure": 1.5})
    assert json.loads((tmp_path / "example.json").read_text()) == record
    assert record["command"] == "OPENBLAS_NUM_THREADS=1 python benchmarks/example.py --seed 3"
    assert record["provenance"] == "run" and {"date", "commit", "machine"} <= set(
        record["measured"])
