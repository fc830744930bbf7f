"""docs/measured.md's generated section (the measured figures), written from the benchmarks'
saved JSON.

Every part of the section comes from one file ``benchmarks/results/<name>.json``: the
JSON a benchmark script printed (``output``), saved by ``--run NAME`` with the command,
the date, the commit and the machine it ran on (its load average and the run's niceness
included); the part is rendered from those figures (tables and sentences), so it says what
the script measured and nothing else. A record may carry ``notes``: how that run was made
(``notes_source`` says so), never figures of another run.

    python benchmarks/readme_measured.py            # rewrite the section from the JSON
    python benchmarks/readme_measured.py --check    # exit 1 if docs/measured.md differs
    python benchmarks/readme_measured.py --run calibration --run jobs   # measure, save, rewrite

``--run fleet_memory`` calibrates a thousand small robots: about half an hour on a quiet
2-core machine; ``--run setup`` runs the test suite once (tens of minutes on a loaded one).

``--run`` runs the script with its recorded arguments in a fresh process
(``OPENBLAS_NUM_THREADS=1``, this copy of the package first on the path); the jobs case
takes about five minutes on a loaded 2-core machine. Its UR10 series A job is left out:
the package does not ship that series, so no recorded command could find it everywhere.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).resolve().with_name("results")
PAGE = ROOT / "docs" / "measured.md"  # the section lived in README.md before
BEGIN = ("<!-- Written by benchmarks/readme_measured.py from benchmarks/results/*.json: "
         "edit those, not this section. -->")
END = "<!-- End of the generated section. -->"
# The parts of the section, in order.
ORDER = ("setup", "first_run", "real_data", "identification", "kinematics", "calibration", "jobs",
         "sphere_laser", "diagnosis", "planning", "design_bound", "scan", "tracking", "ik",
         "robust", "fleet", "fleet_memory", "table_memory", "delivered", "third_harmonic",
         "cable", "fleet_prior")
# What --run executes for a part (arguments of ``python benchmarks/<script>``).
RUNS = {"setup": ("setup.py", "--tests", "--tests-timeout", "3900"),
        "first_run": ("setup.py", "--cold-cache", "--blas-default", "--demo-runs", "2"),
        "real_data": ("real_data.py",),
        "identification": ("identification.py", "--quick"),
        "kinematics": ("kinematics.py",),
        "calibration": ("calibration.py", "--rows", "1000,5000", "--no-growth", "--no-loop"),
        "jobs": ("jobs.py", "--demo"),
        "sphere_laser": ("sphere_laser.py",),
        "diagnosis": ("diagnosis.py", "--quick"),
        "planning": ("planning.py", "--quick"),
        "design_bound": ("design_bound.py",),
        "scan": ("scan.py",),
        "tracking": ("tracking.py",),
        "ik": ("ik.py",),
        "robust": ("robust.py", "--quick"),
        "fleet": ("fleet.py", "--robots", "20", "--rows", "200"),
        "fleet_memory": ("fleet_memory.py", "--robots", "1000"),
        "table_memory": ("table_memory.py",),
        "delivered": ("delivered.py", "--seeds", "5"),
        "third_harmonic": ("third_harmonic.py",),
        # the Pandas' data: the folder ROBOCAL_PANDA_DATA names (fleet_prior.py --help)
        "fleet_prior": ("fleet_prior.py", "--part", "tracker,bar,panda", "--robots", "40",
                        "--next", "5", "--own", "0.3333,0.03333"),
        "cable": ("cable.py",)}
INTRO = ("Figures from this repository's benchmark scripts on a 2-core machine (each prints "
         "JSON with the comparison run in the same process), written into this section by "
         "`benchmarks/readme_measured.py` from the JSON saved in `benchmarks/results/`. Each "
         "part names the command, and the date, commit and machine of its run with the "
         "machine's load average when it started (2 means both cores busy). Wall times grow "
         "with that load, so CPU seconds are given where the script measures them; where "
         "a script times a short call by the wall clock, read the figure with the load.")
MIB, MB = 2.0**20, 1e6


# ----------------------------------------------------------------------------- saving


def machine() -> dict:
    """Facts about this machine that move the figures."""
    model = ""
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        model = next((line.split(":", 1)[1].strip() for line in
                      cpuinfo.read_text().splitlines() if line.startswith("model name")), "")
    import numpy as np

    return {"cpu": model or platform.processor(), "cores": os.cpu_count(),
            "load_average": [round(v, 2) for v in os.getloadavg()],
            "system": platform.platform(), "python": platform.python_version(),
            "numpy": np.__version__, "niceness": os.nice(0)}


def commit() -> str:
    """The checked-out commit, with ``+changes`` when the working tree differs from it
    (outside ``benchmarks/results``, which saved runs change)."""
    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True,
                              check=False).stdout.strip()

    head = git("rev-parse", "--short=12", "HEAD") or "unknown"
    changed = git("status", "--porcelain", "--untracked-files=no", "--", ".",
                  ":(exclude)benchmarks/results")
    return head + ("+changes" if changed else "")


def last_json(text: str) -> dict:
    """The last JSON object printed in ``text`` (a line opening with ``{`` to the end)."""
    lines = text.splitlines()
    for start in range(len(lines) - 1, -1, -1):
        if lines[start].startswith("{"):
            try:
                return json.loads("\n".join(lines[start:]))
            except json.JSONDecodeError:
                continue
    raise ValueError("the benchmark printed no JSON object")


def facts() -> dict:
    """When, at which commit and on which machine a run starts."""
    return {"date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
            "commit": commit(), "machine": machine()}


def save(name: str, script: str, arguments, output: dict,
         measured: dict | None = None) -> dict:
    """Save the JSON ``output`` a benchmark ``script`` printed with ``arguments`` as
    ``benchmarks/results/<name>.json``, with the facts of the run (``measured``, taken now
    when not given); return the record."""
    record = {"benchmark": name, "script": f"benchmarks/{script}",
              "command": " ".join(["OPENBLAS_NUM_THREADS=1", "python",
                                   f"benchmarks/{script}", *arguments]),
              "provenance": "run", "measured": measured or facts(), "output": output}
    (RESULTS / f"{name}.json").write_text(json.dumps(record, indent=1, ensure_ascii=False)
                                          + "\n")
    return record


def run(name: str) -> dict:
    """Run part ``name``'s benchmark, save its JSON with the facts of the run, return it."""
    script, *arguments = RUNS[name]
    command = [sys.executable, str(ROOT / "benchmarks" / script), *arguments]
    environment = dict(os.environ, OPENBLAS_NUM_THREADS="1",
                       PYTHONPATH=os.pathsep.join(
                           [str(ROOT)] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
    measured = facts()
    done = subprocess.run(command, cwd=ROOT, env=environment, capture_output=True, text=True,
                          check=False)
    if done.returncode:
        raise SystemExit(f"{script} failed (exit {done.returncode}): "
                         f"{done.stderr.strip().splitlines()[-1:]}")
    return save(name, script, arguments, last_json(done.stdout), measured)


def load(name: str) -> dict:
    return json.loads((RESULTS / f"{name}.json").read_text())


# ----------------------------------------------------------------------------- rendering


def _seconds(value: float) -> str:
    return f"{value:.2g} s" if value < 10 else f"{value:.0f} s"


def _ratio(value: float) -> str:
    return f"{value:.2g}x" if value < 100 else f"{value:.0f}x"


def _run_line(record: dict) -> str:
    """Where and when a run was made."""
    measured = record["measured"]
    box = measured["machine"]
    load_now = box["load_average"][0]
    niced = f", niceness {box['niceness']}" if box.get("niceness") else ""
    return (f"Run on {measured['date']} at commit {measured['commit']} "
            f"({box['cpu'] or 'unknown CPU'}, {box['cores']} cores, load average "
            f"{load_now:.1f} at the start{niced}; Python {box['python']}, numpy "
            f"{box['numpy']}): `{record['command']}`.")


def _notes(record: dict) -> str:
    if "notes" not in record:
        return ""
    return f"\n\n*{record['notes']}.*"


def render_calibration(record: dict) -> str:
    """The solve against scipy on the same unknowns, from ``calibration.py``'s JSON."""
    cases = record["output"]["cases"]
    rows = ["| case | free unknowns | ours: solve / whole job | scipy, converged (the same "
            "answer) | scipy, default tolerances |", "| --- | --- | --- | --- | --- |"]
    for case in cases:
        ours, head = case["ours"], case["headline"]
        converged = case["numpy_scipy_least_squares_fd_converged"]
        default = case["numpy_scipy_least_squares_fd"]
        rows.append(
            f"| {case['case']} | {case['free_unknowns']} | "
            f"{_seconds(ours['cpu_seconds_solve'])} / {_seconds(ours['cpu_seconds_total'])} | "
            f"{_seconds(converged['cpu_seconds'])} ({_ratio(head['speedup_same_answer'])}), "
            f"off by {converged['max_relative_difference']:.1e} | "
            f"{_seconds(default['cpu_seconds'])} ({_ratio(head['speedup_default_tolerances'])})"
            f", off by {default['max_relative_difference']:.1e} |")
    tolerance = cases[0]["headline"]["same_answer_tolerance"]
    large = [c for c in cases if c["kind"] != "cross_bar" and c["rows"] >= 1000]
    same = all(c["headline"]["same_answer"] for c in large)
    least = min((c["headline"]["speedup_same_answer"] for c in large), default=float("nan"))
    lead = (f"**Calibration** (simulated 6R with 0.5 mm / 0.5 mrad errors and 10 um noise; "
            f"the same free unknowns for every solver; CPU seconds; scipy least squares on a "
            f"vectorised numpy residual with finite differences, once run to convergence "
            f"and once with its default tolerances, each with the largest relative "
            f"difference of a free unknown from our answer). {_run_line(record)}")
    summary = (f"From 1,000 tracker points on, our solve is {_ratio(least)} or more faster "
               f"than scipy reaching the same answer (within {tolerance:.0e} relative: "
               f"{'yes' if same else 'no'}). \"Whole job\" adds the nominal fit and "
               f"identifiability.")
    return "\n\n".join([lead, "\n".join(rows), summary]) + _notes(record)


JOB_LABELS = {"bar": "cross bar, 30 placements", "artifact": "artifact, 60 placements",
              "tracker": "tracker, 1,000 points, payload and joint compliance",
              "series_a": "UR10 series A (`--series-a`, the full public data set)",
              "demo": "`robocal demo --no-screenshot` (`--demo`)"}


def _job_row(case: dict) -> str:
    stages = (case.get("profile") or {}).get("stages_cumulative_s", {})
    where = " / ".join(f"{stages[k]:.1f}" if k in stages else "-"
                       for k in ("calibrate", "diagnosis", "unexplained", "report"))
    peak = case["peak_memory_mib"]
    target = _seconds(case["target_cpu_seconds"])
    if case.get("target_peak_mb"):
        target += f", {case['target_peak_mb']:.0f} MB"
    compiler = case["compiler_cpu_seconds"]
    return (f"| {JOB_LABELS.get(case['case'], case['case'])} | {case['cpu_seconds']:.1f} | "
            f"{compiler:.1f} | {peak:.0f} MiB ({peak * MIB / MB:.0f} MB) | {target} | "
            f"{where} |")


def render_jobs(record: dict) -> str:
    """Whole calibration jobs per kind and size, from ``jobs.py``'s JSON."""
    # A job that stopped (an error, or an exit status other than 0) measured no calibration.
    cases = [c for c in record["output"]["cases"] if "error" not in c and not c["exit_status"]]
    failed = [f"{JOB_LABELS.get(c['case'], c['case'])} (exit status {c['exit_status']})"
              if "exit_status" in c else JOB_LABELS.get(c["case"], c["case"])
              for c in record["output"]["cases"] if "error" in c or c["exit_status"]]
    lead = ("**Whole jobs** (`robocal calibrate` with diagnosis, `result.json` and "
            "`report.html`, each in a fresh process, on simulated data of the example 6R "
            "or the shipped data; CPU seconds of the job, and of the C compiler apart (spent "
            "once per function on a machine that has not compiled it before); peak resident "
            f"memory; the last column from a second, profiled run, whose profiler adds its "
            f"own time). {_run_line(record)}")
    rows = ["| job | CPU s | compiler CPU s | peak memory | target | profiled: calibrate / "
            "diagnosis / unexplained / report [s] |", "| --- | --- | --- | --- | --- | --- |"]
    rows += [_job_row(c) for c in cases]
    parts = [lead, "\n".join(rows), _against_targets(cases)]
    if failed:
        parts.append(f"Failed in this run: {'; '.join(failed)}.")
    changes = f"\n\n{record['changes']}" if "changes" in record else ""
    return "\n\n".join(parts) + _notes(record) + changes


def _against_targets(cases: list[dict]) -> str:
    """Which jobs stayed within their targets in this run, and which did not."""
    within: list[str] = []
    over: list[str] = []
    for case in cases:
        memory = case.get("target_peak_mb")
        ok = case["cpu_seconds"] <= case["target_cpu_seconds"] and (
            not memory or case["peak_memory_mib"] * MIB / MB <= memory)
        (within if ok else over).append(JOB_LABELS.get(case["case"], case["case"]))
    return (f"Within target in this run: {'; '.join(within) or 'none'}. Over target: "
            f"{'; '.join(over) or 'none'}.")


def render_fleet_memory(record: dict) -> str:
    """Fleet workers' memory over many robots, from ``fleet_memory.py``'s JSON."""
    out = record["output"]
    points = sorted(out["checkpoints"].items(), key=lambda item: int(item[0]))
    lead = (f"**Fleet workers' memory** (`robocal fleet --no-report` on {out['robots']:,} "
            f"simulated robots, tracker data of the example 6R, {out['rows']} rows a robot, "
            f"{out['workers']} worker processes, restarted between batches of robots; each "
            f"robot's record carries the resident size of the process that ran it). "
            f"{_run_line(record)} The fleet took {_seconds(out['fleet_wall_s'])} of wall "
            f"time ({out['task_cpu_s']:.0f} s of task CPU); {len(out['failed'])} robots "
            f"failed; exit status {out['exit_status']}.")
    rows = ["| robots finished | worker processes so far | largest peak of one | resident "
            "after its last robot, smallest / largest |", "| --- | --- | --- | --- |"]
    for count, figures in points:
        resident = figures["resident_mib_per_worker"].values()
        rows.append(f"| {int(count):,} | {len(resident)} | {figures['largest_peak_mib']:.0f} "
                    f"MiB | {min(resident):.0f} / {max(resident):.0f} MiB |")
    ratio = out["largest_peak_last_over_first"]
    verdict = "within" if ratio <= out["target_ratio"] else "over"
    tail = (f"The largest peak after the last robot is {ratio:.2f}x that after the first "
            f"{points[0][0]} ({verdict} the target of {out['target_ratio']:.1f}x).")
    return "\n\n".join([lead, "\n".join(rows), tail]) + _notes(record)


def _us(value: float) -> str:
    return f"{value:.2g}" if value < 10 else f"{value:.0f}"


def _ms(seconds: float) -> str:
    """Seconds as milliseconds, two significant digits below 100 ms."""
    value = seconds * 1e3
    return f"{value:.2g} ms" if value < 100 else f"{value:.0f} ms"


def render_kinematics(record: dict) -> str:
    """Kinematics against pinocchio and numpy, from ``kinematics.py``'s JSON."""
    out = record["output"]
    robots = out["robots"]
    names = list(robots)
    heads = {"industrial_6r": "6R", "panda_7dof": "7-DOF"}
    rows_of = [
        ("pose: CasADi compiled batch / pinocchio in a Python loop / numpy batch",
         "fk_us", ("casadi_compiled_batched", "pinocchio_python_loop", "numpy_batched")),
        ("pose and parameter Jacobian: CasADi compiled batch / numpy finite differences",
         "fk_parameter_jacobian_us",
         ("casadi_compiled_batched", "numpy_finite_differences_batched")),
        ("pose and joint Jacobian: CasADi compiled batch / pinocchio loop",
         "fk_joint_jacobian_us", ("casadi_compiled_batched", "pinocchio_python_loop"))]
    rows = ["| | " + " | ".join(heads.get(n, n) for n in names) + " |",
            "| --- |" + " --- |" * len(names)]
    for label, group, keys in rows_of:
        rows.append(f"| {label} | " + " | ".join(
            " / ".join(_us(robots[n][group][k]) for k in keys) for n in names) + " |")
    agreement = [robots[n]["agreement"] for n in names]
    pose = max(max(a["tool_pose_casadi_vs_pinocchio_max_abs"] for a in agreement),
               max(a["tool_pose_casadi_vs_numpy_max_abs"] for a in agreement))
    joint = max(a["joint_jacobian_casadi_vs_pinocchio_max_abs"] for a in agreement)
    parameter = max(a["parameter_jacobian_casadi_vs_numpy_fd_max_abs"] for a in agreement)
    lead = (f"**Kinematics** (microseconds per configuration, batches of {out['batch']:,}; "
            f"the best of several wall-clock repeats, so the least the machine's other work "
            f"left; pinocchio {out['machine']['pinocchio']}, CasADi "
            f"{out['machine']['casadi']}). {_run_line(record)}")
    tail = (f"The methods agree: tool poses of CasADi, pinocchio and numpy within "
            f"{pose:.0e} (m and rotation entries), joint Jacobians of CasADi and pinocchio "
            f"within {joint:.0e}, the exact parameter Jacobian and numpy's central "
            f"differences within {parameter:.0e}.")
    return "\n\n".join([lead, "\n".join(rows), tail]) + _notes(record)


IK_ROBOTS = {"industrial_6r": "6R", "panda_7dof": "7-DOF", "prismatic_rrp": "RRP"}


def render_ik(record: dict) -> str:
    """Levenberg-Marquardt IK against IPOPT, from ``ik.py``'s JSON."""
    cases = record["output"]["cases"]
    rows = ["| robot, target | targets | solved: LM / IPOPT | worst error of the solved: LM / "
            "IPOPT | mean time per target: LM / IPOPT |", "| --- | --- | --- | --- | --- |"]
    for case in cases:
        lm, ipopt = case["lm"], case["ipopt"]
        rows.append(
            f"| {IK_ROBOTS.get(case['robot'], case['robot'])}, {case['mode']} | "
            f"{case['targets']} | {lm['solved']:.0%} / {ipopt['solved']:.0%} | "
            f"{lm['worst_position_error_m']:.0e} / {ipopt['worst_position_error_m']:.0e} m | "
            f"{lm['mean_ms']:.2g} / {ipopt['mean_ms']:.2g} ms |")
    ratios = [c["ipopt_over_lm_mean_time"] for c in cases]
    lead = (f"**Inverse kinematics** (reachable targets made by forward kinematics of random "
            f"joints; both solvers from the same seed with the same "
            f"{cases[0]['restarts']} random restarts; wall time per target, restarts "
            f"included). {_run_line(record)}")
    tail = (f"IPOPT took {min(ratios):.2g}x to {max(ratios):.2g}x the time of our "
            f"Levenberg-Marquardt solver per target.")
    return "\n\n".join([lead, "\n".join(rows), tail]) + _notes(record)


TRACKING_METHODS = (("gauss_newton", "ours: Gauss-Newton SQP, compiled"),
                    ("gauss_newton_interpreted", "ours, interpreted CasADi"),
                    ("sqpmethod_qrqp", "CasADi `sqpmethod` (qrqp)"),
                    ("sqpmethod_qpoases", "CasADi `sqpmethod` (qpOASES)"),
                    ("ipopt", "IPOPT"),
                    ("damped_least_squares", "damped least squares, level condition ignored"))


def render_tracking(record: dict) -> str:
    """Per-cycle tracking solves, from ``tracking.py``'s JSON."""
    out = record["output"]
    robots = out["robots"]
    names = list(robots)
    rows = ["| method | " + " | ".join(
        f"{IK_ROBOTS.get(n, n)}: CPU median / 99th percentile, solved" for n in names) + " |",
        "| --- |" + " --- |" * len(names)]
    for key, label in TRACKING_METHODS:
        cells = []
        for name in names:
            m = robots[name]["methods"].get(key)
            cells.append("-" if m is None else
                         f"{m['cpu_median_ms']:.2g} / {m['cpu_p99_ms']:.2g} ms, "
                         f"{m['success_rate']:.0%} of {m['cycles']:,}")
        rows.append(f"| {label} | " + " | ".join(cells) + " |")
    ours = [robots[n]["methods"]["gauss_newton"] for n in names]
    constraint = max(m["max_constraint_error"] for m in ours)
    difference = max(m["max_difference_to_ipopt_rad"] for m in ours)
    tilt = max(robots[n]["methods"]["damped_least_squares"]["max_level_tilt_deg"]
               for n in names)
    ipopt_cycles = robots[names[0]]["methods"]["ipopt"]["cycles"]
    lead = (f"**Tracking** ({out['cycles']:,} cycles of a moving target per robot, IPOPT on "
            f"the first {ipopt_cycles:,}; "
            f"CPU milliseconds per cycle of the solving thread). {_run_line(record)}")
    tail = (f"Our solver's largest constraint error was {constraint:.0e}, its largest "
            f"difference from IPOPT's joints {difference:.0e} rad; the damped least-squares "
            f"IK, which ignores the level condition, tilted the tool's x axis by up to "
            f"{tilt:.0f} deg.")
    return "\n\n".join([lead, "\n".join(rows), tail]) + _notes(record)


def render_sphere_laser(record: dict) -> str:
    """The sphere-and-laser fit, from ``sphere_laser.py``'s JSON."""
    sensor, robot = record["output"]["sensor_only"], record["output"]["robot_plus_sensor"]
    lm = sensor["ours_lm_no_guess"]
    truth = sensor["truth"]
    solver = sensor["solver_only_from_closed_form_start"]
    scipy = sensor["scipy_2point_from_guesses"]
    ours = robot["ours_calibrate"]
    geometric = robot["geometric_solve_only"]
    lead = (f"**Sphere and laser** (the published example, {sensor['readings']} readings, "
            f"R = {sensor['radius_mm']:.0f} mm, {sensor['noise_mm']:.2g} mm noise, tilting "
            f"scan; median wall times of repeated solves). {_run_line(record)}")
    body = (f"Sensor alone: every value within {lm['max_abs_error_in_std']:.1f} standard "
            f"errors of the truth (x0 = {lm['estimate']['x0']:.4f} +- {lm['std']['x0']:.4f} "
            f"mm for {truth['x0']:.4f}); residual RMS {lm['residual_rms_mm']:.5f} mm against "
            f"a noise floor of {sensor['noise_floor_rms_mm']:.5f} mm. The whole fit without "
            f"guesses took {_ms(lm['seconds'])} ({_ms(solver['lm']['seconds'])} from the "
            f"closed-form start; IPOPT from there {_ms(solver['ipopt']['seconds'])}), scipy "
            f"least squares from a user's guesses {_ms(scipy['seconds'])} "
            f"({scipy['evaluations']} evaluations). Robot plus laser, {robot['readings']} "
            f"readings of the 6R: {ours['rms_nominal_mm']:.2f} mm nominal to "
            f"{ours['rms_geometric_mm']:.4f} mm (floor {ours['noise_floor_rms_mm']:.4f} mm), "
            f"robot parameters within {ours['max_abs_error_in_std_robot']:.1f} and the laser "
            f"within {ours['max_abs_error_in_std_laser']:.1f} standard errors of the truth; "
            f"the geometric solve on {geometric['free_unknowns']} unknowns "
            f"{_ms(geometric['ours_lm_seconds'])} against scipy's "
            f"{_ms(geometric['scipy_2point_seconds'])}, the two within "
            f"{geometric['max_difference_in_std']:.1e} standard errors.")
    return "\n\n".join([lead, body]) + _notes(record)


def render_scan(record: dict) -> str:
    """Designed laser scans of one sphere, from ``scan.py``'s JSON."""
    out = record["output"]
    rows = ["| scan | readings | OCP solve (wall) | predicted tool error | fit residual | "
            "laser origin error / predicted standard error (x, y, z) |",
            "| --- | --- | --- | --- | --- | --- |"]
    for case in out["cases"]:
        label = "sensor only" if case["sensor_only"] else \
            f"robot plus laser ({case['identifiable']} parameters)"
        z = ", ".join(f"{v:.2f}" for v in case["origin_error_in_predicted_std"])
        rows.append(f"| {label} | {case['samples']} ({case['duration_s']:.0f} s at the scan's "
                    f"rate) | {case['solve_seconds']:.1f} s ({case['status']}) | "
                    f"{case['predicted_tool_error_mm']:.2g} mm | "
                    f"{case['residual_rms_mm']:.4f} mm | {z} |")
    lead = (f"**Laser scans** (6R, a 25 mm sphere, {out['noise_mm']:.2g} mm noise, simulated "
            f"truth; the scan designed by an optimal control problem, then simulated and "
            f"fitted). {_run_line(record)}")
    robot = ", ".join(f"{c['predicted_tool_error_mm']:.2g}" for c in out["cases"]
                      if not c["sensor_only"])
    tail = ("" if not robot else
            f"\n\nA scan of one sphere leaves the robot poorly determined (predicted tool "
            f"error {robot} mm): combine it with poses of other kinds for the robot.")
    return "\n\n".join([lead, "\n".join(rows)]) + tail + _notes(record)


def render_table_memory(record: dict) -> str:
    """Memory of reading a large table, from ``table_memory.py``'s JSON."""
    out = record["output"]
    return (f"**Reading large tables** (a tracker table of 10 full-precision columns, read "
            f"and turned into numbers in a fresh process). {_run_line(record)} A "
            f"{out['file_mib']:.0f} MiB table of {out['rows']:,} rows raised the peak "
            f"resident memory by {out['peak_increase_mib']:.0f} MiB, "
            f"{out['peak_over_file']:.1f} times the file; reading took "
            f"{out['read_seconds']:.1f} s of wall time.") + _notes(record)


def _minutes(seconds: float) -> str:
    return f"{seconds / 60:.0f} min" if seconds >= 600 else f"{seconds / 60:.1f} min"


def render_setup(record: dict) -> str:
    """What the README's first two commands cost, from ``setup.py``'s JSON."""
    out = record["output"]
    demo = out["demo"]
    cpu = [d["cpu_seconds"] for d in demo]
    loads = [d["load_average_before"][0] for d in demo]
    spread = (f"{min(cpu):.0f}-{max(cpu):.0f} s" if len(cpu) > 1 else f"{cpu[0]:.0f} s")
    lines = [f"**Set-up** (each command in its own process, CPU seconds of the process and "
             f"what it started; the machine's load average, a measure of how many processes "
             f"wanted a core, beside each; the run at niceness {out['niceness']}). "
             f"{_run_line(record)}",
             f"`robocal demo --no-screenshot` (two calibrations with diagnosis, two reports) "
             f"took {spread} of CPU and {', '.join(_seconds(d['wall_seconds']) for d in demo)} "
             f"of wall time at load {', '.join(f'{v:.1f}' for v in loads)} on "
             f"{out['cores']} cores, with the compiled-code cache "
             f"{demo[0].get('cache', 'this machine held then')}; exit status "
             f"{', '.join(str(d['exit_status']) for d in demo)}."]
    tests = out.get("tests")
    if tests:
        load = (f"{tests['load_average_before'][0]:.1f} at the start and "
                f"{tests['load_average_after'][0]:.1f} at the end")
        if tests.get("finished", True):
            counts = ", ".join(f"{n:,} {word}" for word, n in tests["counts"].items())
            lines.append(
                f"The test command (`python -m pytest -q`, slow checks left out) took "
                f"{_minutes(tests['cpu_seconds'])} of CPU and "
                f"{_minutes(tests['wall_seconds'])} of wall time with the load average "
                f"{load}: {counts}.")
        else:
            share = tests["progress_percent"]
            whole = (f"; at that rate the whole command needs about "
                     f"{_minutes(tests['cpu_seconds'] * 100 / share)} of CPU (an "
                     f"extrapolation, not a measurement)" if share else "")
            lines.append(
                f"The test command (`python -m pytest -q`, slow checks left out) did not "
                f"finish within the run's limit: it was stopped after "
                f"{_minutes(tests['wall_seconds'])} of wall time with the load average "
                f"{load}, having used {_minutes(tests['cpu_seconds'])} of CPU and come "
                f"through {share if share is not None else 'an unknown share'}% of the "
                f"tests by pytest's own progress figure{whole}.")
        lines.append("The CPU time is what a command costs; the wall time adds the waiting "
                     "for a core that the machine's other work caused.")
    lines.append("`pip install -e \".[test]\"` was not timed: it depends on the network and "
                 "on what pip has cached.")
    return "\n\n".join(lines) + _notes(record)


def render_first_run(record: dict) -> str:
    """The demo on an empty compiled-code cache and again, from ``setup.py``'s JSON."""
    demo = record["output"]["demo"]
    runs = "; ".join(
        f"with the cache {d['cache']}: {_seconds(d['cpu_seconds'])} of CPU, "
        f"{_seconds(d['wall_seconds'])} of wall time at load {d['load_average_before'][0]:.1f}"
        + ("" if d["exit_status"] == 0 else f" (exit status {d['exit_status']})")
        for d in demo)
    threads = demo[0].get("blas_threads", "1")
    if threads == "library default":
        threads = "the library's default, as in a shell that sets none"
    return (f"**A newcomer's first demo** (`robocal demo --no-screenshot` run on an empty "
            f"compiled-code cache, `ROBOCAL_CACHE` pointing to a new folder, as on a machine "
            f"that has never run the toolkit, so whatever the demo compiles is compiled in "
            f"that run; then again on that cache; OpenBLAS threads: {threads}; "
            f"CPU seconds "
            f"of the process and what it started, the compiler included). "
            f"{_run_line(record)} Measured {runs}.") + _notes(record)


REAL_SETS = {"series_D": "UR10, tracker, series D", "series_A": "UR10, tracker, series A"}


def _effects(effects: list[dict]) -> str:
    """Effect names with their joints (the full sentences are in each run's result.json)."""
    return "; ".join(f"{e['name'].replace('_', ' ')}"
                     + (f", joint{'s' * (len(e['joints']) > 1)} "
                        f"{', '.join(str(j) for j in e['joints'])}" if e["joints"] else "")
                     for e in effects) or "none"


def render_real_data(record: dict) -> str:
    """Calibration on the shipped real data, from ``real_data.py``'s JSON."""
    results = record["output"]["results"]
    rows = ["| data | fit / held out | held out: nominal / geometric / final [mm] | "
            "identifiable | effects diagnosis added | wall time |",
            "| --- | --- | --- | --- | --- | --- |"]
    for r in results:
        held = r["validation_mm"]
        if r["set"] == "panda":
            label = f"Panda, sockets, hold out {' + '.join(r['held_out'])}"
            sizes = "7 / 2 placements"
        else:
            label = REAL_SETS.get(r["set"], r["set"])
            sizes = f"{r['rows_fit']:,} / {r['rows_validation']:,} poses"
        rows.append(f"| {label} | {sizes} | {held['rms_nominal']:.3f} / "
                    f"{held['rms_geometric']:.3f} / {held['rms_final']:.3f} | "
                    f"{r['identifiable']} | {_effects(r['effects'])} | "
                    f"{_seconds(r['seconds'])} |")
    spreads = [r["validation_touch_spread_mm"]["reduction"] for r in results
               if r["set"] == "panda"]
    lead = (f"**Real data** (the package's copies: UR10 series D, every fourth pose held out, "
            f"and the Panda's plate placements, two held out at a time; RMS over the "
            f"held-out readings kept; diagnosis on). {_run_line(record)}")
    tail = ("" if not spreads else
            f"\n\nThe spread of the Panda's held-out touches around their socket fell by "
            f"{', '.join(f'{v:.0%}' for v in spreads)} from the nominal model to the final "
            f"one.")
    return "\n\n".join([lead, "\n".join(rows)]) + tail + _notes(record)


def render_diagnosis(record: dict) -> str:
    """Diagnosis against one geometric calibration, from ``diagnosis.py``'s JSON."""
    cases = record["output"]["cases"]
    real = [c for c in cases if "held_out_mm" in c]
    simulated = [c for c in cases if "rows" in c]
    rows = ["| data | rows | found | fit RMS: geometric / final / floor [mm] | wall s: "
            "calibration / with diagnosis / diagnosis alone (ratio) |",
            "| --- | --- | --- | --- | --- |"]
    for c in simulated:
        truth = c["truth"]["joint_compliance"]
        label = ("compliance on joints " + " and ".join(truth) if truth else "clean")
        found = "; ".join(f"{e['name']} {e['joints']}: " + ", ".join(
            f"{k} = {v:.4g}" for k, v in e["parameters"].items()) for e in c["found"]) \
            or "nothing"
        rms = c["rms_mm"]
        rows.append(f"| simulated 6R tracker, {label} | {c['rows']:,} | {found} | "
                    f"{rms['geometric']:.5f} / {rms['final']:.5f} / {rms['noise_floor']:.5f} "
                    f"| {c['seconds_calibration']:.1f} / "
                    f"{c['seconds_calibration_with_diagnosis']:.1f} / "
                    f"{c['seconds_diagnosis_run']:.1f} "
                    f"({c['ratio_diagnosis_to_calibration']:.2g}x) |")
    truths = sorted({f"c{j} = {v:.2g}" for c in simulated
                     for j, v in c["truth"]["joint_compliance"].items()})
    lead = (f"**Diagnosis** (simulated 6R tracker data, 0.01 mm noise, geometric errors and a "
            f"payload, compliance {', '.join(truths)} rad/Nm where it is simulated; wall "
            f"seconds, which the machine's load moves). {_run_line(record)}")
    parts = [lead, "\n".join(rows)]
    for c in real:
        held = c["held_out_mm"]
        parts.append(f"On real data ({c['case']}, {c['fit_rows']} / {c['held_out_rows']} "
                     f"rows) the held-out RMS went from {held['geometric']:.4f} mm "
                     f"(geometric) to {held['final']:.4f} mm with the {len(c['effects'])} "
                     f"effect(s) diagnosis added; recommended: {c['recommended']}.")
    return "\n\n".join(parts) + _notes(record)


IDENTIFICATION_CASES = {"cross_bar": "cross bar", "artifact_touches": "artifact",
                        "tracker_points": "tracker",
                        "sphere_laser (joints)": "sphere, joint readings",
                        "sphere_laser (pendant)": "sphere, pendant poses"}


def render_identification(record: dict) -> str:
    """The 1% rule against the prior, from ``identification.py``'s JSON."""
    results = record["output"]["results"]
    simulated = [r for r in results if "seeds" in r]
    rows = ["| case | fit / held out | held-out / floor, 1% rule (median) | held-out / floor, "
            "prior (median) | expected |", "| --- | --- | --- | --- | --- |"]
    for r in simulated:
        fit, held = r["runs"][0]["units_fit_held_out"]
        noise = r["runs"][0]["noise_mm"]
        cells = []
        for rule in ("fraction", "prior"):
            values = " ".join(f"{v:.3f}" for v in r[rule]["held_out_over_floor"])
            cells.append(f"{values} ({r[rule]['median_held_out_over_floor']:.3f})")
        rows.append(f"| {IDENTIFICATION_CASES.get(r['case'], r['case'])}, {noise:.2g} mm | "
                    f"{fit} / {held} | {cells[0]} | {cells[1]} | "
                    f"{r['prior']['median_expected_over_floor']:.3f} |")
    seeds = " ".join(str(s) for s in simulated[0]["seeds"]) if simulated else ""
    lead = (f"**Identification rule** (the 1% rule and the tolerance prior on the same data "
            f"in one process; simulated 6R, 0.5 mm / 0.05 deg errors, three quarters of the "
            f"units fitted, the rest held out, seeds {seeds}; the floor is the held-out RMS "
            f"of the true model, placements fitted again; \"expected\" is what an efficient "
            f"estimator reaches on average with `p` unknowns and `m` residual entries, "
            f"`sqrt(1 + p/m)`, the median over the seeds). {_run_line(record)}")
    return "\n\n".join([lead, "\n".join(rows)]) + _notes(record)


def render_robust(record: dict) -> str:
    """Gross errors set aside, from ``robust.py``'s JSON."""
    out = record["output"]
    rows = ["| case | seed | readings | corrupted rows | of them set aside | clean units set "
            "aside | held out, corrupted / clean | robust / plain on clean data | effects "
            "(corrupted data) |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for c in out["simulated"]:
        bad = c["bad_robust"]
        rows.append(f"| {c['case'].replace('_', ' ')} | {c['seed']} | {c['readings']} | "
                    f"{bad['injected']} ({c['share_injected']:.0%}) | "
                    f"{bad['injected_flagged']:.0%} | {bad['clean_units_set_aside']} | "
                    f"{c['held_out_ratio_bad_to_clean']:.3f}x | "
                    f"{c['held_out_ratio_robust_to_linear_clean']:.3f}x | "
                    f"{', '.join(bad['effects']) or 'none'} |")
    clean_aside = sum(c["clean_robust"]["units_set_aside"] for c in out["simulated"])
    lead = ("**Gross errors** (example 6R arm, noise 0.05 mm, a 0.1% gear-ratio error on "
            "joint 2 where the data see joints; a share of the rows then moved by 2-10 mm; "
            "held-out RMS over every reading, the robust fit on corrupted data against plain "
            f"least squares on the clean data). {_run_line(record)}")
    parts = [lead, "\n".join(rows),
             f"On the clean data the robust fit set {clean_aside} units aside in all."]
    for r in out["real"]:
        parts.append(f"Real data, {r['set']}: robust over plain least squares "
                     f"{r['ratio_all']:.3f}x held out over every reading "
                     f"({r['robust']['rejected_count']} set aside; recommended "
                     f"{r['robust']['recommended']}, {r['ratio_recommended']:.3f}x).")
    return "\n\n".join(parts) + _notes(record)


DESIGN_SETUPS = {"industrial_6r/tracker_points": "6R tracker",
                 "industrial_6r/cross_bar": "6R cross bar",
                 "panda_7dof/tracker_points": "7-DOF tracker",
                 "panda_7dof/cross_bar": "7-DOF cross bar"}


def render_design_bound(record: dict) -> str:
    """The optimal approximate design's bound, from ``design_bound.py``'s JSON."""
    cases = record["output"]["cases"]
    rows = ["| set-up | candidates | bound over random plans, at each size | many poses |",
            "| --- | --- | --- | --- |"]
    for c in cases:
        for pool in c["pools"]:
            sizes = ", ".join(f"{n}: {v:.2f}" for n, v in pool["bound_over_random"].items())
            rows.append(f"| {DESIGN_SETUPS.get(c['set_up'], c['set_up'])} | "
                        f"{pool['candidates']:,} | {sizes} | "
                        f"{pool['asymptotic_optimal_over_uniform']:.2f} |")
    lead = ("**What any plan can reach** (the optimal approximate design's bound on a plan's "
            "predicted tool error over the median of 40 random plans from the same pool of "
            "feasible candidates, at four plan sizes, and the ratio of the optimal design to "
            "uniform weights when the plan is large; a plan can beat random plans by 30% only "
            f"where the bound is below 0.7). {_run_line(record)}")
    return "\n\n".join([lead, "\n".join(rows)]) + _notes(record)


DELIVERED_KINDS = {"tracker_points": "tracker", "cross_bar": "cross bar",
                   "artifact_touches": "artifact", "sphere_laser": "point laser",
                   "laser_readme": "point laser, 6R with four small errors"}


def render_delivered(record: dict) -> str:
    """Predicted against true accuracy of the delivered robot, from ``delivered.py``'s JSON."""
    out = record["output"]
    rows = ["| kind | predicted / true, per seed | true error: delivered / nominal [mm] | "
            "within 1.5x | delivered worse than nominal without exit 3 |",
            "| --- | --- | --- | --- | --- |"]
    for kind, cases in out["cases"].items():
        summary = out["summary"][kind]
        ratios = " ".join("(refused)" if "refused" in c else f"{c['predicted_over_true']:.2f}"
                          for c in cases)
        errors = ", ".join("-" if "refused" in c else
                          f"{c['true_error_delivered_mm']:.3f} / {c['true_error_nominal_mm']:.3f}"
                          for c in cases)
        worse = summary["seeds"] - summary["refused"] - summary["never_worse_without_exit_3"]
        rows.append(f"| {DELIVERED_KINDS.get(kind, kind)} | {ratios} | {errors} | "
                    f"{summary['predicted_within_1.5x']} of {summary['predictions']} | "
                    f"{worse} |")
    seeds = max(len(c) for c in out["cases"].values())
    lead = (f"**Predicted against true work-cell accuracy** (the example 6R arm with every "
            f"joint's DH parameters off its drawing by errors drawn at 1 mm / 0.5 deg, the "
            f"tolerances the calibration assumes; held-out data; the delivered file "
            f"compared with the simulated truth at 400 poses over the joint ranges of the "
            f"fit data after the best rigid motion; seeds 1-{seeds}). "
            f"{_run_line(record)}")
    tail = ("The prediction is an expectation: where one combination of parameters carries "
            "most of the uncertainty (touch data), one robot's true error scatters widely "
            "about it ([docs/delivery.md](delivery.md#how-close-to-the-truth)).")
    return "\n\n".join([lead, "\n".join(rows), tail]) + _notes(record)


def _relative(value: float) -> str:
    return "0" if value == 0 else f"{value:.1e}"


def _error_text(message: str) -> str:
    """A robot's one-line error without its temporary file path and list of allowed keys."""
    return message.split(": ", 1)[-1].split("; allowed")[0]


PLANNING_SETUPS = {("industrial-6r", "tracker_points"): "6R tracker",
                   ("industrial-6r", "cross_bar"): "6R cross bar",
                   ("panda-7dof", "tracker_points"): "7-DOF tracker",
                   ("panda-7dof", "cross_bar"): "7-DOF cross bar"}


def render_planning(record: dict) -> str:
    """Designed against random feasible plans, from ``planning.py``'s JSON."""
    cases = record["output"]["cases"]
    rows = ["| set-up | poses | model error, designed / random [mm] | ratio: model error | "
            "predicted | bound from the pool | cond (designed by `cond` / random) |",
            "| --- | --- | --- | --- | --- | --- | --- |"]
    for c in cases:
        label = PLANNING_SETUPS.get((c["robot"], c["kind"]), f"{c['robot']} {c['kind']}")
        for size in c["sizes"]:
            tool, random = size["designed_tool"], size["random_median"]
            rows.append(f"| {label} | {size['count']} | {tool['model_error_mm']:.4f} / "
                        f"{random['model_error_mm']:.4f} | "
                        f"{1 - size['model_error_margin']['tool']:.2f} | "
                        f"{1 - size['predicted_margin']:.2f} | "
                        f"{1 - size['attainable_margin']:.2f} | "
                        f"{size['condition_ratio']:.2f} |")
    first = cases[0]
    lead = (f"**Experiment design** (simulated truth, {first['noise_mm']:.2g} mm noise; every "
            f"plan runnable: joint ranges, capsules, line of sight, random plans drawn under "
            f"the same checks; {first['random_plans_per_size']} random plans and "
            f"{first['noise_realisations_per_design']} noise realisations per size, medians; "
            f"model error = calibrated against true measured point over 500 configurations "
            f"after the best rigid motion; the ratios are designed (`tool`, the default) over "
            f"random: simulated, as the planner predicts it, and the least any choice from "
            f"the candidate pool could reach). {_run_line(record)}")
    return "\n\n".join([lead, "\n".join(rows)]) + _notes(record)


def render_fleet(record: dict) -> str:
    """A small fleet through ``robocal fleet``, from ``fleet.py``'s JSON."""
    out = record["output"]
    two, one = out["run_2_workers"], out["run_1_workers"]
    single = out["single_calibrate_largest_relative_difference"]
    lead = (f"**Fleet** (`robocal fleet --no-report` on {out['robots']} simulated robots, "
            f"tracker data of the example 6R, {out['rows']} rows a robot, two broken robot "
            f"files among them; wall time, which on a loaded machine says little about the "
            f"speed-up two workers give on free cores). {_run_line(record)}")
    body = (f"Two workers took {_seconds(two['wall_s'])} and one {_seconds(one['wall_s'])} "
            f"({out['speedup_two_vs_one']:.2f}x). {out['good_robots']} robots were "
            f"calibrated; their parameters differ between the one- and two-worker runs by "
            f"{_relative(out['one_vs_two_workers_largest_relative_difference'])} relative at "
            f"most, and from single `robocal calibrate` runs of {len(single)} of them by "
            f"{_relative(max(single.values(), default=0.0))}. The broken robots were named "
            f"{'as simulated' if out['broken_as_simulated'] else 'otherwise than simulated'} "
            f"({'; '.join(f'{k}: {_error_text(v)}' for k, v in out['broken_named'].items())}"
            f"); flagged as "
            f"standing out: {', '.join(out['flagged']) or 'none'} (simulated with an "
            f"outlying compliance: {', '.join(out['outlying_simulated']) or 'none'}).")
    return "\n\n".join([lead, body]) + _notes(record)


def render_third_harmonic(record: dict) -> str:
    """A periodic error three times per turn, found or not, from ``third_harmonic.py``."""
    out = record["output"]
    lead = (f"**A periodic error three times per turn** ({out['case']}; the same data "
            f"calibrated with the harmonic orders diagnosis offers, and with the first two "
            f"only). {_run_line(record)}")
    rows = ["| orders offered | effects named | third harmonic found / true | held-out RMS "
            "geometric / final | final over the noise floor | gross errors found / injected "
            "(same lines) | s |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for name, run in ((k, v) for k, v in out.items() if isinstance(v, dict)):
        third, held, gross = run["third_harmonic_deg"], run["held_out_rms_mm"], \
            run["gross_errors"]
        found = "none" if third["found"] is None else f"{third['found']:.4f} deg"
        effects = "; ".join(e.split(";")[0] for e in run["effects"]) or "none"
        rows.append(f"| {name} (up to {run['max_order_offered']}) | {effects} | {found} / "
                    f"{third['true']:.4f} deg | {held['geometric']:.4f} / {held['final']:.4f} "
                    f"mm | {held['final_over_floor']:.2f}x | {gross['found']} / "
                    f"{gross['injected']} ({'yes' if gross['same_lines'] else 'no'}) | "
                    f"{run['seconds']:.0f} |")
    return "\n\n".join([lead, "\n".join(rows)]) + _notes(record)


def _mm(value: float | None) -> str:
    return "refused" if value is None else f"{value:.3f}"


def render_fleet_prior(record: dict) -> str:
    """The fleet prior against the tolerance prior, from ``fleet_prior.py``'s JSON."""
    out = record["output"]
    parts = []
    simulated = [k for k in ("tracker", "bar") if k in out]
    first = out[simulated[0]]
    lead = (f"**What the fleet already knows** (simulated fleets of the example 6R: each "
            f"robot's geometric errors a part the model shares, {first['shared']:.2f} of the "
            f"tolerance, plus its own, {first['own']:.2f} of it; the prior learned from "
            f"{first['fleet_robots']} calibrated robots; the next robots measured with fewer "
            f"and fewer poses and calibrated on the same data with the tolerance prior, with "
            f"the fleet prior, and with the population itself as the prior (its true mean "
            f"and spread: the most any learned prior could know); true work-cell RMS: "
            f"calibrated against simulated tool point over 400 configurations in the joint "
            f"limits, after the best rigid motion, median over the robots of the model, in "
            f"mm; then the real Pandas, each left out of its own prior). {_run_line(record)}")
    parts.append(lead)
    for kind in simulated:
        part = out[kind]
        summary = part["summary"]
        unit = _fleet_unit(kind)
        rows = [f"| {kind} ({part['noise_mm']:g} mm noise): {unit} | tolerance prior | "
                f"fleet prior | the population itself | robots that belong |",
                "| --- | --- | --- | --- | --- |"]
        for count in part["counts"]:
            c = summary["per_count"][str(count)]
            tolerance = (_mm(c["tolerance_median_mm"]) if c["tolerance_calibrated"]
                         else "refused (too few)")
            rows.append(f"| {count} | {tolerance} | {_mm(c['fleet_median_mm'])} | "
                        f"{_mm(c.get('population_median_mm'))} | "
                        f"{c['belongs']} of {c['robots']} |")
        parts.append("\n".join(rows))
        parts.append(_fleet_third(part, kind) + (
            f" The robot off the model (own "
            f"errors {part['off']:g} times the fleet's spread) told it does not belong: "
            f"{summary['off_model_refused']}, and then calibrated as with the tolerance "
            f"prior: {'yes' if summary['off_model_same_as_tolerance'] else 'no'}."))
    smaller = [k for k in out if " own=" in k]
    if smaller:
        parts.append("Robots of a model that differ far less from each other (the same "
                     "fleets with each robot's own part smaller; shared part and counts as "
                     "above): " + " ".join(
                         f"{k.split(' ')[0]}, own part {out[k]['own']:.3g} of the "
                         f"tolerance: " + _fleet_third(out[k], k.split(' ')[0])
                         for k in smaller))
    if "panda" in out:
        panda = out["panda"]
        rows = ["| Panda left out | held-out RMS, tolerance prior / fleet prior [mm] | ratio | "
                "belongs (conflict / limit) | all touches of the placement, tolerance [mm] |",
                "| --- | --- | --- | --- | --- |"]
        for e in panda["robots"]:
            rows.append(f"| {e['robot']} ({e['fit_touches']} touches; "
                        f"{len(e['held_out_placements'])} placement"
                        f"{'s' if len(e['held_out_placements']) != 1 else ''} held out) | "
                        f"{e['tolerance_held_out_mm']:.3f} / {e['fleet_held_out_mm']:.3f} | "
                        f"{e['ratio']:.2f} | {'yes' if e['belongs'] else 'no'} "
                        f"({e['conflict']:.1f} / {e['threshold']:.1f}) | "
                        f"{e['tolerance_full_placement_held_out_mm']:.3f} |")
        parts.append("\n".join(rows))
        parts.append(f"At most 0.85 of the tolerance prior's held-out RMS: "
                     f"{panda['at_most_0.85']} of {panda['count']} Pandas.")
    return "\n\n".join(parts) + _notes(record)


def _fleet_unit(kind: str) -> str:
    return "readings" if kind == "tracker" else "placements"


def _fleet_third(part: dict, kind: str) -> str:
    """The fleet-prior benchmark's target in words: a third of the poses with the fleet
    prior (and with the population itself) against all of them with the tolerance prior."""
    summary = part["summary"]
    unit = _fleet_unit(kind)
    population = summary.get("population_at_third_no_worse_than_tolerance_at_all")
    return (f"A third of the {unit} ({summary['third']}) with the fleet prior against all "
            f"{part['full']} with the tolerance prior: no worse on "
            f"{summary['fleet_at_third_no_worse_than_tolerance_at_all']} robots (medians "
            f"{_mm(summary['fleet_third_median_mm'])} against "
            f"{_mm(summary['tolerance_all_median_mm'])} mm)"
            + ("." if population is None else
               f"; with the population itself as the prior: {population} "
               f"({_mm(summary['population_third_median_mm'])} mm)."))


def _cable_run(name: str, run: dict, targets: dict) -> str:
    """One row of the cable table: the declared run against its targets, the undeclared
    one with what the terminal said of drives."""
    held = run["held_out_rms_mm"]
    ratio = f"{held['final_over_floor']:.2f}x"
    if "estimates" in run:
        worst = run["largest_relative_error"]
        target = 100 * targets["relative_error"]
        within = "an effect not found" if worst is None else \
            f"largest relative error {100 * worst:.1f}% (target {target:.0f}%)"
        ratio += f" (target {targets['final_over_floor']:g}x)"
    else:
        within = "; ".join(run["drive_lines"]) or "no drive named"
    effects = ", ".join(run["effect_names"]) or "none"
    return (f"| {name} | {effects} | {within} | {held['geometric']:.4f} / {held['final']:.4f} "
            f"mm | {ratio} | {run['seconds']:.0f} |")


def render_cable(record: dict) -> str:
    """A 7-DOF arm with differential cable pairs, from ``cable.py``'s JSON."""
    out = record["output"]
    lead = (f"**Differential cable drives** ({out['case']}; the same tables calibrated with a "
            f"robot file that declares neither drive nor transmission, with the drive "
            f"only, and with both declared). {_run_line(record)}")
    rows = ["| robot file | effects named | estimates against the truth, or what the terminal "
            "says of drives | held-out RMS geometric / final | final over the noise floor | "
            "s |", "| --- | --- | --- | --- | --- | --- |"]
    rows.append(_cable_run("no drive, no transmission", out["undeclared"], out["targets"]))
    if "drive_only" in out:
        rows.append(_cable_run("`drive: cable`, no transmission", out["drive_only"],
                               out["targets"]))
    rows.append(_cable_run("`drive: cable`, `transmission:` 2-3 and 5-6", out["declared"],
                           out["targets"]))
    found = out["declared"]["estimates"]
    table = ["| effect | parameter | true | found | relative error |",
             "| --- | --- | --- | --- | --- |"]
    for effect, parameters in found.items():
        for parameter, v in parameters.items():
            error = "-" if v["relative_error"] is None else f"{100 * v['relative_error']:.2f}%"
            value = "-" if v["found"] is None else f"{v['found']:.4g}"
            table.append(f"| {effect} | {parameter} | {v['true']:.4g} | {value} | {error} |")
    return "\n\n".join([lead, "\n".join(rows), "\n".join(table)]) + _notes(record)


RENDERERS: dict[str, Callable[[dict], str]] = {"calibration": render_calibration,
                                               "jobs": render_jobs,
                                               "fleet_memory": render_fleet_memory,
                                               "kinematics": render_kinematics,
                                               "ik": render_ik, "tracking": render_tracking,
                                               "sphere_laser": render_sphere_laser,
                                               "scan": render_scan,
                                               "table_memory": render_table_memory,
                                               "setup": render_setup,
                                               "first_run": render_first_run,
                                               "real_data": render_real_data,
                                               "diagnosis": render_diagnosis,
                                               "identification": render_identification,
                                               "robust": render_robust,
                                               "design_bound": render_design_bound,
                                               "delivered": render_delivered,
                                               "planning": render_planning,
                                               "fleet": render_fleet,
                                               "third_harmonic": render_third_harmonic,
                                               "fleet_prior": render_fleet_prior,
                                               "cable": render_cable}


def render(records: dict[str, dict]) -> str:
    """The section's body from the parts' records."""
    parts = [INTRO]
    for name in ORDER:
        record = records[name]
        if record["provenance"] != "run":
            raise ValueError(f"benchmarks/results/{name}.json: provenance "
                             f"{record['provenance']!r}; only saved runs are rendered")
        parts.append(RENDERERS[name](record))
    return "\n\n".join(parts)


def rendered() -> str:
    return render({name: load(name) for name in ORDER})


def section(text: str) -> str:
    """The generated body in the page's text ``text`` (between the markers)."""
    start, end = text.find(BEGIN), text.find(END)
    if start < 0 or end < start:
        raise ValueError("docs/measured.md has no generated section (markers missing)")
    return text[start + len(BEGIN):end].strip("\n")


def rewrite(text: str, body: str) -> str:
    start, end = text.index(BEGIN), text.index(END)
    return text[:start + len(BEGIN)] + "\n\n" + body + "\n\n" + text[end:]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--run", action="append", default=[], choices=sorted(RUNS),
                        help="measure this part again before writing (repeatable)")
    parser.add_argument("--check", action="store_true",
                        help="only compare: exit 1 when docs/measured.md is not what the "
                        "JSON gives")
    args = parser.parse_args()
    for name in args.run:
        run(name)
    text = PAGE.read_text()
    body = rendered()
    if args.check:
        if section(text) != body:
            print("docs/measured.md's generated section differs from benchmarks/results/*.json; "
                  "run python benchmarks/readme_measured.py", file=sys.stderr)
            raise SystemExit(1)
        return
    PAGE.write_text(rewrite(text, body))


if __name__ == "__main__":
    main()
