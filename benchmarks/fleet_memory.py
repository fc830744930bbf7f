"""Memory of fleet workers over many robots: does a worker process grow with each robot it
calibrates?

A fleet of small simulated robots (tracker data of the example 6R arm, 30 rows each by
default, every robot with its own geometric errors and joint compliances) goes through
``robocal fleet --no-report`` on a local cluster of two worker processes. Every robot's
record in fleet.json carries the resident size of the process that ran it, after the
task (``memory``) and the most it held so far (``peak_memory``). Ordered by when the
robots finished, this gives each worker's peak after the fleet's first 50, 200, 500,
1000 ... robots, side by side. A worker process that was replaced (a restart after some
tasks) shows up under its own process id; ``largest_peak_mib`` is the largest peak over
every worker process at each checkpoint, the figure compared with the one after 50.

    python benchmarks/fleet_memory.py [--robots 300] [--rows 30] [--workers 2]

Prints JSON.
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
from pathlib import Path

import numpy as np

CHECKPOINTS = (50, 100, 200, 300, 500, 1000, 2000)
MIB = 2.0**20


def simulate_fleet(folder: Path, robots: int, rows: int) -> Path:
    """``robots`` tracker datasets, each with its own errors; the fleet file naming them."""
    from robocal_casadi.instruments.simulate import simulate
    from robocal_casadi.model import examples

    nominal = examples.ROBOTS["industrial_6r"]()
    for k in range(robots):
        rng = np.random.default_rng(5000 + k)
        errors = (rng.uniform(0.2e-3, 0.8e-3), math.radians(rng.uniform(0.02, 0.08)))
        compliance = {2: 1e-6 * rng.uniform(0.8, 1.2), 3: 1e-6 * rng.uniform(0.8, 1.2)}
        simulate(nominal, "tracker_points", out_dir=folder / f"r{k:04d}", rows=rows,
                 noise=1e-5, geometric_errors=errors, seed=k, progress=False,
                 effects={"joint_compliance": compliance})
    fleet = folder / "fleet.yaml"
    fleet.write_text("robots:\n" + "".join(
        f"  - {{name: r{k:04d}, datasets: [r{k:04d}/dataset.yaml]}}\n" for k in range(robots)))
    return fleet


def checkpoints(records: list[dict]) -> dict:
    """Per checkpoint (robots finished, fleet-wide): each worker process's peak and current
    resident size [MiB] as of its last robot by then, and the largest peak of them all."""
    ordered = sorted((r for r in records if r.get("worker")), key=lambda r: r["finished"])
    out = {}
    for count in [c for c in CHECKPOINTS if c <= len(ordered)] + [len(ordered)]:
        last: dict[str, dict] = {}
        for record in ordered[:count]:
            last[record["worker"]] = record
        out[str(count)] = {
            "seconds_after_first": ordered[count - 1]["finished"] - ordered[0]["finished"],
            "largest_peak_mib": max(r["peak_memory"] for r in last.values()) / MIB,
            "peak_mib_per_worker": {w: r["peak_memory"] / MIB for w, r in last.items()},
            "resident_mib_per_worker": {w: r["memory"] / MIB for w, r in last.items()}}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=300)
    parser.add_argument("--rows", type=int, default=30)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--work", type=Path, help="working folder (default: a temporary one)")
    args = parser.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="robocal_fleet_memory_"))
    start = time.perf_counter()
    fleet = simulate_fleet(work / "robots", args.robots, args.rows)
    simulation = time.perf_counter() - start
    out = work / "out"
    command = [sys.executable, "-m", "robocal_casadi.cli", "fleet", str(fleet), "--out",
               str(out), "--workers", str(args.workers), "--no-report"]
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True)
    wall = time.perf_counter() - start
    records = json.loads((out / "fleet.json").read_text())["robots"]
    per_worker: dict[str, int] = defaultdict(int)
    for record in records:
        per_worker[record.get("worker") or "none"] += 1
    figures = checkpoints(records)
    first, last = figures[min(figures, key=int)], figures[max(figures, key=int)]
    report = {
        "robots": args.robots, "rows": args.rows, "workers": args.workers,
        "cores": os.cpu_count(), "load_average_at_start": os.getloadavg(),
        "simulation_s": simulation, "fleet_wall_s": wall, "exit_status": done.returncode,
        "task_cpu_s": sum(r.get("cpu_seconds", 0.0) for r in records),
        "failed": [r["name"] for r in records if r["status"] == "failed"],
        "robots_per_worker_process": dict(per_worker),
        "checkpoints": figures,
        "largest_peak_last_over_first": last["largest_peak_mib"] / first["largest_peak_mib"],
        "target_ratio": 1.2,
        "stderr_tail": done.stderr.splitlines()[-5:], "work": str(work)}
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
