"""Fleet calibration through ``robocal fleet`` on a local Dask cluster: wall time with two
workers against one, memory per worker, agreement with single ``robocal calibrate`` runs,
the broken robots named, and the robots with outlying effects being the ones flagged.

The fleet is simulated here (tracker data of the example 6R arm): every robot has its own
geometric errors (their spread varies from robot to robot) and a gravity compliance at
joints 2 and 3 that varies by +-20 %; some robots also have periodic errors of joint 1 or
a gear-ratio error of joint 3 at typical magnitudes; one robot in fifty has a compliance
four times the fleet's (the outliers the summary must flag); two robots have broken
files (a table cell that is no number, a dataset file with a misspelt key).

    python benchmarks/fleet.py [--robots 200] [--rows 500] [--sample 6] [--reports]

Each configuration runs the fleet from scratch into its own folder. Prints JSON (also
written to WORK/benchmark.json, with the partial results as each step ends).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

OUTLIER_EVERY = 50  # one robot in this many has an outlying compliance
OUTLIER_FACTOR = 4.0
BROKEN = {5: "table", 11: "dataset key"}  # robot index -> what is broken


def robot_name(k: int) -> str:
    return f"r{k:03d}"


def outliers(count: int) -> set[int]:
    picked = {k for k in range(count) if k % OUTLIER_EVERY == 17}
    return picked or {min(2, count - 1)}


def simulate_one(job: tuple[int, int, str, bool]) -> str:
    from robocal_casadi.instruments.simulate import simulate
    from robocal_casadi.model import examples

    k, rows, folder, outlying = job
    rng = np.random.default_rng(1000 + k)
    length, angle = rng.uniform(0.2e-3, 0.8e-3), math.radians(rng.uniform(0.02, 0.08))
    c2, c3 = 1e-6 * rng.uniform(0.8, 1.2, size=2)
    if outlying:
        c2 *= OUTLIER_FACTOR
    effects: dict = {"joint_compliance": {2: c2, 3: c3}}
    if k % 4 == 1:
        effects["joint_cyclic"] = {1: tuple(rng.uniform(0.5, 1.5) * v
                                            for v in (2e-4, 1e-4, 1e-4, 5e-5))}
    if k % 5 == 2:
        effects["joint_scale"] = {3: 5e-4 * rng.uniform(0.5, 1.5)}
    simulate(examples.ROBOTS["industrial_6r"](), "tracker_points", out_dir=folder, rows=rows,
             noise=1e-5, geometric_errors=(length, angle), effects=effects, seed=k,
             progress=False)
    return folder


def break_files(folder: Path, how: str) -> None:
    if how == "table":
        table = folder / "points.csv"
        lines = table.read_text().splitlines()
        cells = lines[40].split(",")
        cells[2] = "12x"  # a cell that is no number
        lines[40] = ",".join(cells)
        table.write_text("\n".join(lines) + "\n")
    else:
        dataset = folder / "dataset.yaml"
        dataset.write_text(dataset.read_text().replace("target:", "traget:"))


def run_fleet(fleet: Path, out: Path, workers: int, reports: bool) -> dict:
    command = [sys.executable, "-m", "robocal_casadi.cli", "fleet", str(fleet), "--out", str(out),
               "--workers", str(workers)] + ([] if reports else ["--no-report"])
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    wall = time.perf_counter() - start
    summary = json.loads((out / "fleet.json").read_text())
    per_worker: dict[str, list] = defaultdict(list)
    for robot in summary["robots"]:
        if robot.get("worker"):
            per_worker[robot["worker"]].append(robot)
    cpu = sum(r["cpu_seconds"] for r in summary["robots"])
    return {
        "workers": workers, "wall_s": wall, "exit_status": done.returncode,
        "task_cpu_s": cpu,
        # How much of the workers' wall time they actually got a processor (the machine is
        # shared): 1.0 means every worker computed all the time.
        "cpu_share": cpu / (wall * workers),
        "robots_per_worker": {w: len(rs) for w, rs in per_worker.items()},
        "peak_memory_mib_per_worker": {w: max(r["peak_memory"] for r in rs) / 2**20
                                       for w, rs in per_worker.items()},
        "memory_mib_first_last_task_per_worker": {
            w: [rs[0]["memory"] / 2**20, rs[-1]["memory"] / 2**20]
            for w, rs in ((w, sorted(rs, key=lambda r: r["finished"])) for w, rs in
                          per_worker.items())},
        "summary": summary, "stdout_tail": done.stdout.splitlines()[-8:],
        "stderr_tail": done.stderr.splitlines()[-5:],
    }


def parameters(result: Path) -> dict[str, float]:
    content = json.loads(result.read_text())
    values = {f"p:{p['name']}": p["estimate"] for p in content["parameters"]}
    for effect in content.get("effects", []):
        values.update({f"e:{effect['name']}:{k}": v for k, v in effect["parameters"].items()})
    values.update(flatten("fit", content["fit"]))
    return values


def flatten(prefix: str, value) -> dict[str, float]:
    """Every number inside ``value`` (nested dicts and lists) by its path; text left out."""
    if isinstance(value, dict):
        return {k: v for key, item in value.items() for k, v in
                flatten(f"{prefix}:{key}", item).items()}
    if isinstance(value, list):
        return {k: v for i, item in enumerate(value) for k, v in
                flatten(f"{prefix}:{i}", item).items()}
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return {prefix: float(value)}
    return {}


def largest_relative_difference(a: dict, b: dict) -> float:
    if set(a) != set(b):
        return math.inf
    worst = 0.0
    for key in a:
        x, y = a[key], b[key]
        scale = max(abs(x), abs(y), 1e-300)
        worst = max(worst, abs(x - y) / scale if scale > 1e-12 else abs(x - y))
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=200)
    parser.add_argument("--rows", type=int, default=500)
    parser.add_argument("--sample", type=int, default=6,
                        help="robots also calibrated one by one with robocal calibrate")
    parser.add_argument("--reports", action="store_true", help="write each robot's report.html")
    parser.add_argument("--work", type=Path, help="working folder (default: a temporary one)")
    args = parser.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="robocal_fleet_bench_"))
    work.mkdir(parents=True, exist_ok=True)
    report: dict = {"robots": args.robots, "rows": args.rows, "reports": args.reports,
                    "cores": os.cpu_count(), "load_average_at_start": os.getloadavg()}

    def save() -> None:
        (work / "benchmark.json").write_text(json.dumps(report, indent=1, default=str) + "\n")

    flagged_truth = outliers(args.robots)
    start = time.perf_counter()
    jobs = [(k, args.rows, str(work / "robots" / robot_name(k)), k in flagged_truth)
            for k in range(args.robots)]
    with ProcessPoolExecutor(2) as pool:
        list(pool.map(simulate_one, jobs, chunksize=4))
    broken = {robot_name(k): how for k, how in BROKEN.items() if k < args.robots}
    for name, how in broken.items():
        break_files(work / "robots" / name, how)
    fleet = work / "fleet.yaml"
    fleet.write_text("robots:\n" + "".join(
        f"  - {{name: {robot_name(k)}, datasets: [robots/{robot_name(k)}/dataset.yaml]}}\n"
        for k in range(args.robots)))
    report["simulation_s"] = time.perf_counter() - start
    save()

    runs = {}
    for workers in (2, 1):
        result = run_fleet(fleet, work / f"out{workers}", workers, args.reports)
        runs[workers] = result
        report[f"run_{workers}_workers"] = {k: v for k, v in result.items() if k != "summary"}
        save()
    two, one = runs[2], runs[1]
    report["speedup_two_vs_one"] = one["wall_s"] / two["wall_s"]
    report["speedup_target"] = 1.8

    summary = two["summary"]
    failed = {f["robot"]: f["error"] for f in summary["failed"]}
    report["broken_named"] = failed
    report["broken_as_simulated"] = sorted(failed) == sorted(broken)
    flagged = sorted({r["robot"] for r in summary["standing_out"]})
    report["flagged"] = flagged
    report["outlying_simulated"] = sorted(robot_name(k) for k in flagged_truth)
    report["flagged_are_the_outliers"] = flagged == report["outlying_simulated"]
    report["flag_reasons"] = [r["reason"] for r in summary["standing_out"]]

    good = [r["name"] for r in summary["robots"] if r["status"] != "failed"]
    report["good_robots"] = len(good)
    report["one_vs_two_workers_largest_relative_difference"] = max(
        largest_relative_difference(parameters(work / "out2" / n / "result.json"),
                                    parameters(work / "out1" / n / "result.json")) for n in good)
    sample = [good[int(i)] for i in np.linspace(0, len(good) - 1, min(args.sample, len(good)))]
    sample = sorted(set(sample) | (set(robot_name(k) for k in flagged_truth) & set(good)))
    single = {}
    for name in sample:
        out = work / "single" / name
        subprocess.run([sys.executable, "-m", "robocal_casadi.cli", "calibrate",
                        str(work / "robots" / name / "dataset.yaml"), "--out", str(out),
                        "--no-report"], check=True, capture_output=True)
        single[name] = largest_relative_difference(parameters(out / "result.json"),
                                                   parameters(work / "out2" / name /
                                                              "result.json"))
    report["single_calibrate_largest_relative_difference"] = single
    report["single_calibrate_match_1e-9"] = all(v <= 1e-9 for v in single.values())
    report["work"] = str(work)
    save()
    print(json.dumps(report, indent=1, default=str))


if __name__ == "__main__":
    main()
