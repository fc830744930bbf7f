"""docs/measured.md's generated section (the measured figures), written from the benchmarks'
saved JSON.

Every part of the section comes from one file ``benchmarks/results/<name>.json``:

* ``"provenance": "run"``: the JSON a benchmark script printed (``output``), saved by
  ``--run NAME`` with the command, the date, the commit and the machine it ran on; the
  part is rendered from those figures (tables and sentences), so it says what the
  script measured and nothing else;
* ``"provenance": "transcribed"``: a part not measured again since the section was
  first generated; its ``text`` is the earlier wording (then in README.md) and ``source`` says
  which run it came from. The part is printed with that note.
* ``"provenance": "written"``: a part measured again whose printed JSON was not kept;
  its ``text`` was written from that output, ``measured`` names the date and commit and
  ``source`` the commands. The part is printed with that note.

    python benchmarks/readme_measured.py            # rewrite the section from the JSON
    python benchmarks/readme_measured.py --check    # exit 1 if docs/measured.md differs
    python benchmarks/readme_measured.py --run calibration --run jobs   # measure, save, rewrite

``--run fleet_memory`` calibrates a thousand small robots: about half an hour on a quiet
2-core machine.

``--run`` runs the script with its recorded arguments in a fresh process
(``OPENBLAS_NUM_THREADS=1``, this copy of the package first on the path); the jobs case
takes about ten minutes on a loaded 2-core machine.
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
ORDER = ("setup", "real_data", "identification", "kinematics", "calibration", "jobs",
         "sphere_laser", "diagnosis", "planning", "design_bound", "scan", "tracking", "ik",
         "robust", "fleet", "fleet_memory", "table_memory", "delivered")
# What --run executes for a part (arguments of ``python benchmarks/<script>``).
RUNS = {"calibration": ("calibration.py", "--rows", "1000,5000", "--no-growth", "--no-loop"),
        "jobs": ("jobs.py", "--series-a", "--demo"),
        "fleet_memory": ("fleet_memory.py", "--robots", "1000")}
INTRO = ("Figures from this repository's benchmark scripts on a 2-core machine (each prints "
         "JSON with the comparison run in the same process), written into this section by "
         "`benchmarks/readme_measured.py` from the JSON saved in `benchmarks/results/`. Each "
         "part names the command, and the date, commit and machine of its run, or says that "
         "it was not measured again. Times vary by a factor of about two with machine load.")
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
            "numpy": np.__version__}


def commit() -> str:
    """The checked-out commit, with ``+changes`` when the working tree differs from it."""
    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True,
                              check=False).stdout.strip()

    head = git("rev-parse", "--short=12", "HEAD") or "unknown"
    changed = git("status", "--porcelain", "--untracked-files=no")
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


def run(name: str) -> dict:
    """Run part ``name``'s benchmark, save its JSON with the facts of the run, return it."""
    script, *arguments = RUNS[name]
    command = [sys.executable, str(ROOT / "benchmarks" / script), *arguments]
    environment = dict(os.environ, OPENBLAS_NUM_THREADS="1",
                       PYTHONPATH=os.pathsep.join(
                           [str(ROOT)] + [p for p in [os.environ.get("PYTHONPATH")] if p]))
    measured = {"date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
                "commit": commit(), "machine": machine()}
    done = subprocess.run(command, cwd=ROOT, env=environment, capture_output=True, text=True,
                          check=False)
    if done.returncode:
        raise SystemExit(f"{script} failed (exit {done.returncode}): "
                         f"{done.stderr.strip().splitlines()[-1:]}")
    record = {"benchmark": name, "script": f"benchmarks/{script}",
              "command": " ".join(["OPENBLAS_NUM_THREADS=1", "python",
                                   f"benchmarks/{script}", *arguments]),
              "provenance": "run", "measured": measured, "output": last_json(done.stdout)}
    previous = load(name) if (RESULTS / f"{name}.json").is_file() else {}
    if "notes" in previous:
        record["notes"], record["notes_source"] = previous["notes"], previous["notes_source"]
    (RESULTS / f"{name}.json").write_text(json.dumps(record, indent=1, ensure_ascii=False)
                                          + "\n")
    return record


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
    return (f"Run on {measured['date']} at commit {measured['commit']} "
            f"({box['cpu'] or 'unknown CPU'}, {box['cores']} cores, load average "
            f"{load_now:.1f} at the start; Python {box['python']}, numpy {box['numpy']}): "
            f"`{record['command']}`.")


def _notes(record: dict) -> str:
    if "notes" not in record:
        return ""
    return f"\n\n{record['notes']} ({record['notes_source']})"


def render_transcribed(record: dict) -> str:
    return f"{record['text']}\n\n*{record['source']}.*"


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
              "series_a": "UR10 series A (shipped, `--series-a`)",
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
    cases = [c for c in record["output"]["cases"] if "error" not in c]
    failed = [c["case"] for c in record["output"]["cases"] if "error" in c]
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
        parts.append(f"Failed in this run: {', '.join(failed)}.")
    changes = f"\n\n{record['changes']}" if "changes" in record else ""
    return "\n\n".join(parts) + _notes(record) + changes


def _against_targets(cases: list[dict]) -> str:
    """Which jobs stayed within their targets in this run, and which did not."""
    within, over = [], []
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


RENDERERS: dict[str, Callable[[dict], str]] = {"calibration": render_calibration,
                                               "jobs": render_jobs,
                                               "fleet_memory": render_fleet_memory}


def render(records: dict[str, dict]) -> str:
    """The section's body from the parts' records."""
    parts = [INTRO]
    for name in ORDER:
        record = records[name]
        if record["provenance"] in ("transcribed", "written"):
            parts.append(render_transcribed(record))
        else:
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
