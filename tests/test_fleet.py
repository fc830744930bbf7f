"""Fleet calibration on the real engine: a local Dask cluster of two worker processes.

Five simulated robots (one with a compliance four times the others': five are the fewest
the fleet judges) and one whose table is broken go through ``robocal fleet``; results are
compared with ``calibrate`` run directly, reruns skip what is unchanged, an offset moved
between runs is flagged, a bad fleet file is refused before anything runs, and concurrent
processes never compile one library at the same time. Robots calibrated by the library
alone show what the outlier rule judges and what it leaves alone.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")

from robocal_casadi.calibration import calibrate  # noqa: E402
from robocal_casadi.cli import main  # noqa: E402
from robocal_casadi.common import codegen
from robocal_casadi.errors import InputError  # noqa: E402
from robocal_casadi.fleet import high_outliers, load_fleet, spread  # noqa: E402
from robocal_casadi.fleet.outliers import LIMIT, Move  # noqa: E402
from robocal_casadi.instruments.datasets import load_dataset  # noqa: E402
from robocal_casadi.instruments.simulate import simulate  # noqa: E402
from robocal_casadi.model import examples  # noqa: E402

ROWS = 100
COMPLIANT = "r2"  # simulated with four times the fleet's compliance at joint 3


def _simulate(folder: Path, seed: int, c3: float, theta2_error: float = 0.0) -> None:
    errors = {"a2": 3e-4, "d4": -2e-4, "alpha3": 2e-4, "theta2": 1e-3 + theta2_error}
    simulate(examples.ROBOTS["industrial_6r"](), "tracker_points", out_dir=folder, rows=ROWS,
             noise=1e-5, geometric_errors=errors, seed=seed, progress=False,
             effects={"joint_compliance": {2: 1.0e-6 * (1 + 0.05 * seed), 3: c3}})


@pytest.fixture(scope="module")
def fleet_files(tmp_path_factory):
    root = tmp_path_factory.mktemp("fleet")
    for k in range(5):
        _simulate(root / f"r{k}", seed=k, c3=(4.0 if f"r{k}" == COMPLIANT else 1.0 + 0.1 * k)
                  * 1e-6)
    _simulate(root / "broken", seed=9, c3=1e-6)
    table = root / "broken" / "points.csv"
    lines = table.read_text().splitlines()
    lines[5] = lines[5].replace(",", ",oops,", 1)  # one cell too many on line 6
    table.write_text("\n".join(lines) + "\n")
    (root / "fleet.yaml").write_text("robots:\n" + "".join(
        f"  - {{name: {n}, datasets: [{n}/dataset.yaml]}}\n"
        for n in ("r0", "r1", "r2", "r3", "r4", "broken")))
    return root


@pytest.fixture(scope="module")
def first_run(fleet_files):
    """The fleet run once on its own local cluster of two worker processes."""
    out = fleet_files / "out"
    status = main(["fleet", str(fleet_files / "fleet.yaml"), "--out", str(out),
                   "--workers", "2", "--no-report"])
    return status, out, json.loads((out / "fleet.json").read_text())


@pytest.fixture(scope="module")
def cluster():
    """An existing cluster, as an operator would run one, for the --scheduler runs."""
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address="127.0.0.1:0") as local:
        yield local.scheduler_address


def test_fleet_calibrates_each_robot_and_fails_the_broken_one_alone(first_run, fleet_files,
                                                                    capsys):
    status, out, summary = first_run
    assert status == 1  # a robot failed; the fleet file was fine
    statuses = {r["name"]: r["status"] for r in summary["robots"]}
    assert statuses == {"r0": "calibrated", "r1": "calibrated", "r2": "calibrated",
                        "r3": "calibrated", "r4": "calibrated", "broken": "failed"}
    [failure] = summary["failed"]
    assert failure["robot"] == "broken"
    assert "points.csv" in failure["error"] and "line 6" in failure["error"]
    assert "\n" not in failure["error"]
    assert not (out / "broken").exists()
    for name in ("r0", "r1", "r2", "r3", "r4"):
        assert {p.name for p in (out / name).iterdir()} >= {"result.json",
                                                           "robot_calibrated.yaml",
                                                           "fleet_robot.json"}
    workers = {r["worker"] for r in summary["robots"] if r["status"] == "calibrated"}
    assert all(str(os.getpid()) not in w.split(":")[-1] for w in workers)  # other processes


def test_fleet_result_equals_a_single_calibrate_run(first_run, fleet_files):
    _, out, _ = first_run
    dataset = load_dataset(fleet_files / "r1" / "dataset.yaml")
    direct = calibrate([dataset])
    written = json.loads((out / "r1" / "result.json").read_text())
    scale = {"length": dataset.units.length_scale, "angle": dataset.units.angle_scale}
    for row, estimate in zip(written["parameters"], direct.parameters):
        assert row["name"] == estimate.name
        expected = estimate.estimate / scale.get(estimate.quantity, 1.0)
        assert math.isclose(row["estimate"], expected, rel_tol=1e-9, abs_tol=1e-12)
    assert math.isclose(written["fit"]["rms_final"],
                        direct.fit.rms_final / dataset.units.length_scale, rel_tol=1e-9)


def _without_times(path: Path) -> list[str]:
    """The lines of ``path`` but those of wall-clock figures (``"seconds": ...``)."""
    return [line for line in path.read_text().splitlines()
            if not line.lstrip().startswith('"seconds":')]


def test_fleet_result_file_is_the_calibrate_verbs_byte_for_byte(first_run, fleet_files,
                                                                tmp_path):
    _, out, _ = first_run
    single = tmp_path / "single"
    assert main(["calibrate", str(fleet_files / "r1" / "dataset.yaml"), "--out", str(single),
                 "--no-report"]) == 0
    fleet = json.loads((out / "r1" / "result.json").read_text())
    assert {"delivered", "recommended", "predicted_accuracy"} <= set(fleet)
    # the solver's time is the one wall-clock figure in the file
    assert (out / "r1" / "result.json").read_text().count('"seconds":') == 1
    assert _without_times(out / "r1" / "result.json") == _without_times(single / "result.json")
    for name in ("robot_calibrated.yaml", "effects_calibrated.yaml", "errors.csv"):
        assert (out / "r1" / name).read_bytes() == (single / name).read_bytes(), name


def test_fleet_flags_the_robot_with_outlying_compliance(first_run):
    _, out, summary = first_run
    flagged = {r["robot"] for r in summary["standing_out"]}
    assert flagged == {COMPLIANT}
    reason = next(r for r in summary["standing_out"] if r["robot"] == COMPLIANT)
    assert reason["quantity"] == "compliance.c3" and reason["score"] > LIMIT
    compliance = next(q for q in summary["quantities"] if q["key"] == "compliance.c3")
    assert compliance["values"][COMPLIANT]["value"] == pytest.approx(4e-6, rel=0.1)
    page = (out / "fleet.html").read_text()
    assert page.count("src='data:image/png;base64,") == len(summary["quantities"])
    assert "http://" not in page and "https://" not in page  # self-contained
    assert COMPLIANT in page and "broken" in page


def test_rerun_skips_unchanged_robots_and_redoes_changed_ones(first_run, fleet_files, cluster,
                                                             capsys):
    _, out, _ = first_run
    fleet = str(fleet_files / "fleet.yaml")
    before = (out / "r0" / "result.json").stat().st_mtime_ns
    # A changed table (one reading's last digit) makes r3 stale; the others are untouched.
    table = fleet_files / "r3" / "points.csv"
    lines = table.read_text().splitlines()
    lines[-1] = lines[-1][:-1] + ("1" if lines[-1][-1] != "1" else "2")
    table.write_text("\n".join(lines) + "\n")
    status = main(["fleet", fleet, "--out", str(out), "--scheduler", cluster, "--no-report"])
    assert status == 1
    summary = json.loads((out / "fleet.json").read_text())
    statuses = {r["name"]: r["status"] for r in summary["robots"]}
    assert statuses == {"r0": "unchanged", "r1": "unchanged", "r2": "unchanged",
                        "r3": "calibrated", "r4": "unchanged", "broken": "failed"}
    assert (out / "r0" / "result.json").stat().st_mtime_ns == before
    # A result made incomplete (its file removed) is computed again.
    (out / "r1" / "robot_calibrated.yaml").unlink()
    main(["fleet", fleet, "--out", str(out), "--scheduler", cluster, "--no-report"])
    summary = json.loads((out / "fleet.json").read_text())
    assert {r["name"]: r["status"] for r in summary["robots"]}["r1"] == "calibrated"
    assert (out / "r1" / "robot_calibrated.yaml").is_file()
    printed = capsys.readouterr()
    assert "failed: broken:" in printed.out
    assert "\r" not in printed.err  # progress stays quiet when not on a terminal


def test_previous_run_flags_a_moved_joint_offset(first_run, fleet_files, cluster, tmp_path):
    _, previous, _ = first_run
    # r0 again from new data in which its joint 2 offset moved by 0.05 deg; r2 unchanged.
    _simulate(tmp_path / "r0", seed=20, c3=1e-6, theta2_error=math.radians(0.05))
    (tmp_path / "fleet.yaml").write_text(textwrap.dedent(f"""\
        robots:
          - name: r0
            datasets: [r0/dataset.yaml]
          - name: r2
            datasets: ['{fleet_files / "r2" / "dataset.yaml"}']
        """))
    out = tmp_path / "out"
    status = main(["fleet", str(tmp_path / "fleet.yaml"), "--out", str(out), "--scheduler",
                   cluster, "--previous", str(previous), "--no-report", "--no-diagnose"])
    assert status == 0
    summary = json.loads((out / "fleet.json").read_text())
    moved = [r for r in summary["standing_out"] if r["quantity"].startswith("offset_change")]
    assert [(r["robot"], r["quantity"]) for r in moved] == [("r0", "offset_change.theta2")]
    assert moved[0]["value"] == pytest.approx(0.05, abs=0.01)  # deg, the robot file's unit
    assert any(q["key"] == "offset_change.theta2" for q in summary["quantities"])


@pytest.mark.parametrize("content, where", [
    ("robots: []\n", "robots"),
    ("robot: []\n", "robot"),
    ("robots:\n  - {name: a, datasets: [x.yaml], valdate: [y.yaml]}\n", "robots[0].valdate"),
    ("robots:\n  - {name: a, datasets: [x.yaml]}\n  - {name: A, datasets: [y.yaml]}\n",
     "robots[1].name"),
    ("robots:\n  - {name: ../up, datasets: [x.yaml]}\n", "robots[0].name"),
    ("robots:\n  - {name: a}\n", "robots[0].datasets"),
    ("robots:\n  - {name: a, datasets: [x.yaml], validate: [x.yaml]}\n",
     "robots[0].validate[0]"),
])
def test_bad_fleet_file_is_refused_before_anything_runs(tmp_path, capsys, content, where):
    fleet = tmp_path / "fleet.yaml"
    fleet.write_text(content)
    status = main(["fleet", str(fleet), "--out", str(tmp_path / "out")])
    error = capsys.readouterr().err
    assert status == 2
    assert error.count("\n") == 1 and f"fleet.yaml: {where}:" in error
    assert not (tmp_path / "out").exists()


def test_fleet_file_paths_are_relative_to_it(tmp_path):
    (tmp_path / "f.yaml").write_text("robots:\n  - {name: a, datasets: sub/d.yaml}\n")
    fleet = load_fleet(tmp_path / "f.yaml")
    assert fleet.robots[0].datasets == (tmp_path / "sub" / "d.yaml",)
    with pytest.raises(InputError, match="expected a list of dataset files"):
        (tmp_path / "g.yaml").write_text("robots:\n  - {name: a, datasets: 3}\n")
        load_fleet(tmp_path / "g.yaml")


def test_robust_rule_against_closed_form():
    # Median 1.0; absolute deviations 0, 0.1, 0.1, 0.2, 0.2 and the outlier's: MAD 0.1.
    values = {"a": 1.0, "b": 1.1, "c": 0.9, "d": 1.2, "e": 0.8, "f": 3.0}
    fleet = spread(list(values.values()))
    assert fleet.median == pytest.approx(1.05)
    deviations = sorted(abs(v - 1.05) for v in values.values())
    assert fleet.robust_sd == pytest.approx(1.4826 * np.median(deviations))
    _, found = high_outliers("x", {k: (v, None) for k, v in values.items()})
    assert [f.robot for f in found] == ["f"]
    expected = (3.0 - 1.05) / math.hypot(fleet.robust_sd, 0.01 * 1.05)
    assert found[0].score == pytest.approx(expected)
    # The robot's own standard error widens the scale: a noisy estimate is not an outlier.
    _, found = high_outliers("x", {**{k: (v, None) for k, v in values.items()}, "f": (3.0, 1.0)})
    assert found == []
    # Far below the fleet is no fault.
    _, found = high_outliers("x", {**{k: (v, None) for k, v in values.items()}, "f": (-5.0, None)})
    assert found == []
    move = Move("r", 2, "theta2", "angle", before=0.0, before_std=3e-6, now=1e-4, now_std=4e-6)
    assert move.score == pytest.approx(20.0) and move.moved


WRAPPER = """#!/bin/sh
# Logs the start and end of each compilation and widens the window between them.
echo "start $$ $(date +%s.%N)" >> "{log}"
sleep 1
"{cc}" "$@"
status=$?
echo "end $$ $(date +%s.%N)" >> "{log}"
exit $status
"""

COMPILE_ONE = """
import casadi as ca, numpy as np
from robocal_casadi.common import codegen
x = ca.SX.sym("x", 3)
f = ca.Function("fleet_lock_probe", [x], [ca.sin(x) * 7.25 + ca.dot(x, x)])
g = codegen.compiled(f)
assert g.is_a("External"), "not compiled"
print(float(g(np.array([0.1, 0.2, 0.3]))[0]))
"""


@pytest.mark.skipif(codegen.compiler() is None, reason="no C compiler")
def test_concurrent_processes_compile_one_library_once(tmp_path):
    log = tmp_path / "compilations.log"
    wrapper = tmp_path / "cc"
    wrapper.write_text(WRAPPER.format(log=log, cc=codegen.compiler()))
    wrapper.chmod(0o755)
    env = {**os.environ, "ROBOCAL_CACHE": str(tmp_path / "cache"), "CC": str(wrapper),
           "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[1]),
                                          os.environ.get("PYTHONPATH", "")])}
    processes = [subprocess.Popen([sys.executable, "-c", COMPILE_ONE], env=env,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                 for _ in range(4)]
    outputs = [p.communicate(timeout=300) for p in processes]
    assert all(p.returncode == 0 for p in processes), [err for _, err in outputs]
    values = {out.strip() for out, _ in outputs}
    assert len(values) == 1  # every process evaluates the same compiled library
    events = log.read_text().split()
    assert events.count("start") == 1 and events.count("end") == 1  # compiled once only
    assert len(list((tmp_path / "cache").glob("*.so"))) == 1


def test_local_workers_are_restarted_between_batches(tmp_path):
    """With a restart every two robots on one worker, four robots run in two worker
    processes, two robots each; every robot still gets its outcome (here the failure
    of its missing dataset, which ends a task at once)."""
    from robocal_casadi.fleet import Settings
    from robocal_casadi.fleet.engine import run_tasks
    from robocal_casadi.fleet.spec import Fleet, FleetRobot

    robots = tuple(FleetRobot(name=f"m{k}", datasets=(tmp_path / f"m{k}.yaml",))
                   for k in range(4))
    outcomes = list(run_tasks(Fleet(path=tmp_path / "fleet.yaml", robots=robots),
                              tmp_path / "out", Settings(report=False), workers=1,
                              restart_every=2))
    assert sorted(o.name for o in outcomes) == ["m0", "m1", "m2", "m3"]
    assert all(o.status == "failed" and f"{o.name}.yaml" in (o.error or "") for o in outcomes)
    by_worker: dict[str, list[str]] = {}
    for outcome in outcomes:
        by_worker.setdefault(outcome.worker, []).append(outcome.name)
    assert sorted(sorted(names) for names in by_worker.values()) == [["m0", "m1"],
                                                                     ["m2", "m3"]]


def test_summary_of_an_effect_without_a_standard_error(tmp_path):
    """A learned map's gain has no standard error: the fleet's summary keeps it as null
    instead of failing the robot (a simulated fleet robot whose calibration kept a map)."""
    from dataclasses import replace

    from robocal_casadi.fleet.robot_task import robot_summary
    from robocal_casadi.results import EffectFinding

    data = simulate(examples.industrial_6r(), "tracker_points", out_dir=tmp_path / "d", rows=30,
                    noise=2e-5, seed=3, progress=False).load()
    result = calibrate([data], diagnose=False)
    learned = EffectFinding("residual_map", (2, 3), {"map_gain": 1.0}, "1", {},
                            {"map_gain": None})
    summary = robot_summary(replace(result, effects=(learned,)))
    assert summary["effects"][0]["std"] == {"map_gain": None}
    assert json.loads(json.dumps(summary))["effects"][0]["parameters"] == {"map_gain": 1.0}


@pytest.fixture(scope="module")
def alike(tmp_path_factory):
    """Robot outcomes from the library's own calibration (no cluster needed): seven robots
    simulated alike (tracker data, 0.02 mm noise per coordinate) and one with five times
    that noise, a genuinely worse fit."""
    from robocal_casadi.fleet.robot_task import RobotOutcome, robot_summary

    root = tmp_path_factory.mktemp("alike")
    outcomes = {}
    for k, noise in enumerate([2e-5] * 7 + [1e-4]):
        name = f"a{k}" if noise == 2e-5 else "worse"
        data = simulate(examples.industrial_6r(), "tracker_points", out_dir=root / name,
                        rows=60, noise=noise, geometric_errors={"a2": 3e-4, "d4": -2e-4},
                        seed=40 + k, progress=False).load()
        outcomes[name] = RobotOutcome(name, "calibrated",
                                      summary=robot_summary(calibrate([data], diagnose=False)))
    return root, outcomes


def _fleet_of(root: Path, names, outcomes):
    from robocal_casadi.fleet import summarise
    from robocal_casadi.fleet.spec import Fleet, FleetRobot

    fleet = Fleet(root / "fleet.yaml", tuple(FleetRobot(n, (root / n / "dataset.yaml",))
                                             for n in names))
    return summarise(fleet, [outcomes[n] for n in names])


def test_three_robots_simulated_alike_are_not_judged(alike):
    """Three robots give no spread to judge by: none is flagged, and the fleet says why."""
    from robocal_casadi.fleet.outliers import MIN_ROBOTS

    root, outcomes = alike
    summary = _fleet_of(root, ["a0", "a1", "a2"], outcomes)
    assert summary.standing_out == [] and not summary.judged
    data = summary.to_json()
    assert data["standing_out"] == [] and data["rule"]["judged"] is False
    assert f"at least {MIN_ROBOTS}" in data["rule"]["note"] and "3 robots" in data["rule"]["note"]
    assert all(not q["judged"] for q in data["quantities"])
    # Even a worse robot among three is not judged: there is no spread to judge it by.
    assert _fleet_of(root, ["a0", "a1", "worse"], outcomes).standing_out == []


def test_a_worse_fit_stands_out_of_a_bigger_fleet_and_noise_does_not(alike):
    """With eight robots the spread is estimated: the robot with five times the noise is
    flagged on its fit RMS; the seven alike, whatever their MADs, are not, since no
    difference between them exceeds what each fit's own noise explains."""
    root, outcomes = alike
    names = [f"a{k}" for k in range(7)]
    summary = _fleet_of(root, [*names, "worse"], outcomes)
    assert summary.judged and summary.standing_out == ["worse"]
    flagged = {r["quantity"] for r in summary.reasons()}
    assert "fit.rms_final" in flagged
    alike_only = _fleet_of(root, names, outcomes)
    assert alike_only.judged and alike_only.standing_out == []
    fit = next(q for q in alike_only.to_json()["quantities"] if q["key"] == "fit.rms_final")
    # every robot's RMS carries the standard error its own errors imply: about
    # RMS / sqrt(2 n) for n near-Gaussian errors (here 60 3-D errors, so less)
    for entry in fit["values"].values():
        assert 0 < entry["std"] < entry["value"] / np.sqrt(2 * 60) * 1.5
    assert fit["noise"] > 0


def test_rms_standard_error_against_the_sampling_spread():
    """The standard error of an RMS from one sample matches the spread of RMS values over
    many samples (Gaussian errors, 400 per sample), within the spread of the estimate."""
    from robocal_casadi.fleet.robot_task import rms_standard_error

    rng = np.random.default_rng(5)
    samples = rng.normal(0.0, 2e-5, size=(2000, 400))
    spread_of_rms = np.std(np.sqrt(np.mean(samples ** 2, axis=1)))
    estimates = [rms_standard_error(s) for s in samples[:200]]
    assert np.median(estimates) == pytest.approx(spread_of_rms, rel=0.1)
    assert rms_standard_error(np.array([1e-5])) is None
