"""Whole calibration jobs per kind and size: CPU seconds, peak memory, where the time goes.

Each case runs ``robocal calibrate`` (with diagnosis, result.json and report.html) in a
fresh Python process on data simulated by ``robocal_casadi.simulate`` (the example 6R
arm, geometric errors, 0.01 mm noise), or on the shipped UR10 series A:

* ``bar``: cross-bar, 30 placements;
* ``artifact``: artifact touches (sockets), 60 placements;
* ``tracker``: tracker points, 1,000 rows, with a payload and joint compliance;
* ``series_a``: UR10 tracker series A (about 12,000 rows), with ``--series-a``;
* ``demo``: ``robocal demo --no-screenshot`` (two calibrations with diagnosis and their
  reports, on the shipped UR10 series D and Panda data), with ``--demo``.

CPU seconds are ``time.process_time`` of the job (all threads of the process, not the
simulation), so other work on the machine moves them less than wall time; the C
compiler's CPU time (spent once per function on a machine that has not compiled it
before) is given apart. Multi-threaded BLAS spins while it waits for a core: on a shared
machine set ``OPENBLAS_NUM_THREADS=1`` for figures that mean something. Peak memory is the
process's maximum resident set (``resource.getrusage``). The profile lists the functions
with the largest cumulative CPU time (cProfile timed by ``time.process_time``; the
profiler itself adds to the total, so the CPU seconds come from a separate, unprofiled
run). Run it with this copy of the package importable, e.g.
``PYTHONPATH=. python benchmarks/jobs.py``. Prints JSON.

    python benchmarks/jobs.py [--cases bar,artifact,tracker] [--series-a] [--demo]
                              [--no-profile]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import pstats
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CASES = {"bar": ("cross_bar", 30), "artifact": ("artifact_touches", 60),
         "tracker": ("tracker_points", 1000)}
# The tracker data also carry a payload column and joint compliance, so that diagnosis
# has an effect to find (rounds, refits and the evidence of what it adds).
TRACKER_EFFECTS = {"joint_compliance": {2: 1.5e-6, 3: 2.5e-6}}  # [rad/Nm]
SERIES_A = Path(__file__).resolve().parents[1] / "robocal_casadi" / "data" / "ur10-ipa" / \
    "series_A.yaml"
SHARED_SERIES_A = Path(__file__).resolve().parents[2] / "shared" / "data" / "ur10-ipa" / \
    "series_A.yaml"
# What each case should stay within on a 2-core machine: CPU seconds, and peak memory
# [MB, 10^6 bytes] where one is set.
TARGETS = {"bar": (3.0, None), "artifact": (10.0, None), "tracker": (8.0, None),
           "series_a": (30.0, 400.0), "demo": (20.0, None)}
NOISE = 1e-5  # [m] per coordinate
TOP = 25  # functions listed in the profile summary
# Stages named in the summary by the function that runs them.
STAGES = {"calibrate": "identification.py:calibrate", "identifiability":
          "identification.py:analyse_identifiability", "diagnosis": "diagnosis.py:run",
          "unexplained": "unexplained.py:find", "report": "html.py:write_report"}


def _dataset(case: str, folder: Path) -> Path:
    """The dataset file of ``case`` (simulated into ``folder`` unless shipped)."""
    if case == "series_a":
        return SERIES_A if SERIES_A.is_file() else SHARED_SERIES_A
    from robocal_casadi.instruments.simulate import simulate
    from robocal_casadi.model.examples import industrial_6r

    kind, rows = CASES[case]
    tracker = case == "tracker"
    sim = simulate(industrial_6r(), kind, out_dir=folder / case, rows=rows, noise=NOISE,
                   geometric_errors=(0.5e-3, 0.5e-3), seed=1, progress=False,
                   effects=TRACKER_EFFECTS if tracker else None,
                   payload=(0.0, 10.0) if tracker else None)
    return Path(sim.dataset_path)


def _job(dataset: Path | None, out: Path) -> int:
    from robocal_casadi.cli import main

    if dataset is None:  # the demo: its own data, two jobs under ``out``
        return main(["demo", "--out", str(out), "--no-screenshot", "--force"])
    return main(["calibrate", str(dataset), "--out", str(out), "--force"])


def _result(out: Path) -> dict:
    """The job's result.json (the demo's first job's)."""
    path = out / "result.json"
    if not path.is_file():
        path = next(iter(sorted(out.glob("*/result.json"))), path)
    return json.loads(path.read_text()) if path.is_file() else {}


def _summary(profile: cProfile.Profile) -> dict:
    """Top functions by cumulative time, and the cumulative time of each named stage."""
    stats = pstats.Stats(profile, stream=io.StringIO())
    rows = []
    for (path, line, name), (_, calls, own, cumulative, _) in stats.stats.items():  # type: ignore[attr-defined]
        where = f"{Path(path).name}:{name}" if path != "~" else name
        rows.append((cumulative, own, calls, where, line))
    rows.sort(reverse=True)
    top = [{"function": where, "line": line, "calls": calls, "cumulative_s": round(cum, 3),
            "own_s": round(own, 3)} for cum, own, calls, where, line in rows[:TOP]]
    stages: dict[str, float] = {}
    for key, where in STAGES.items():
        stages[key] = round(sum(cum for cum, _, _, w, _ in rows if w == where), 3)
    by_own = sorted(rows, key=lambda row: -row[1])[:10]
    own = [{"function": w, "line": line, "calls": c, "own_s": round(o, 3)}
           for _, o, c, w, line in by_own]
    return {"stages_cumulative_s": stages, "top_cumulative": top, "top_own": own}


def _children_cpu() -> float:
    """CPU seconds of this process's finished children (the C compiler, when functions
    are compiled for the first time)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def one(case: str, profile: bool, keep: Path | None = None) -> dict:
    """Run ``case`` in this process and return its figures (``keep``: a folder to write
    the job's outputs into, ``<keep>/<case>``, instead of a temporary one)."""
    folder = Path(tempfile.mkdtemp(prefix=f"robocal-jobs-{case}-"))
    dataset = None if case == "demo" else _dataset(case, folder)
    out = keep / case if keep is not None else folder / "out"
    profiler = cProfile.Profile(time.process_time) if profile else None
    children = _children_cpu()
    cpu, wall = time.process_time(), time.perf_counter()
    if profiler is not None:
        profiler.enable()
    status = _job(dataset, out)
    if profiler is not None:
        profiler.disable()
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    children = _children_cpu() - children
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB -> MiB (Linux)
    result = _result(out) if status == 0 else {}
    figures = {"case": case, "dataset": dataset.name if dataset else "demo", "exit_status": status,
               "cpu_seconds": round(cpu, 2), "compiler_cpu_seconds": round(children, 2),
               "wall_seconds": round(wall, 2),
               "peak_memory_mib": round(peak, 1), "profiled": profile,
               "target_cpu_seconds": TARGETS[case][0], "target_peak_mb": TARGETS[case][1],
               "fit_rms": result.get("fit"), "effects": [
                   f"{e['name']}{e['joints']}" for e in result.get("effects", [])]}
    if profiler is not None:
        figures["profile"] = _summary(profiler)
    return figures


def _child(case: str, profile: bool, keep: Path | None = None) -> dict:
    command = [sys.executable, __file__, "--one", case] + (["--profile"] if profile else []) \
        + (["--keep", str(keep)] if keep is not None else [])
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode or not lines:
        return {"case": case, "error": done.stderr.strip().splitlines()[-3:]}
    return json.loads(lines[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", default=",".join(CASES),
                        help="comma-separated cases (default: bar,artifact,tracker)")
    parser.add_argument("--series-a", action="store_true", help="also the UR10 series A")
    parser.add_argument("--demo", action="store_true", help="also robocal demo")
    parser.add_argument("--no-profile", action="store_true",
                        help="CPU seconds and memory only, no profiled run")
    parser.add_argument("--keep", type=Path, metavar="DIR",
                        help="write each job's outputs into DIR/<case> (default: a temporary "
                             "folder)")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    parser.add_argument("--profile", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(one(args.one, args.profile, args.keep)))
        return
    cases = [c for c in args.cases.split(",") if c] + (["series_a"] if args.series_a else []) \
        + (["demo"] if args.demo else [])
    unknown = sorted(set(cases) - set(CASES) - {"series_a", "demo"})
    if unknown:
        parser.error(f"unknown case(s) {', '.join(unknown)}; choose from {', '.join(CASES)}")
    out = []
    for case in cases:
        figures = _child(case, profile=False, keep=args.keep)
        if not args.no_profile and "error" not in figures:
            figures["profile"] = _child(case, profile=True).get("profile")
        out.append(figures)
    print(json.dumps({"benchmark": "jobs", "numpy": np.__version__, "cases": out}, indent=2))


if __name__ == "__main__":
    main()
