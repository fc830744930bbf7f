"""What a newcomer waits for: the README's two first commands, timed in fresh processes.

* ``robocal demo --no-screenshot`` (two calibrations with diagnosis and their reports on
  the shipped UR10 series D and Panda data), written into a temporary folder;
* with ``--tests``, the README's test command ``python -m pytest -q``, run in the
  repository (tens of minutes on a loaded 2-core machine; slow tests are kept out of it
  by the project's pytest settings).

Each command runs in its own subprocess. Its CPU seconds are those of the finished
subprocess and everything it waited for (``resource.getrusage(RUSAGE_CHILDREN)``: user
plus system time, the C compiler and test subprocesses included), which other work on a
shared machine moves less than wall time; its wall seconds are given beside them. The
load average is recorded before and after each command, and the process's niceness (a
niced run waits longer for the processor, so its wall time says more about the machine's
other work than about the command). Prints JSON.

    python benchmarks/setup.py [--tests] [--tests-timeout SECONDS] [--demo-runs 1]
                               [--cold-cache] [--blas-default]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _children_cpu() -> float:
    """CPU seconds [s] of this process's finished children, user plus system."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _load() -> list[float]:
    return [round(v, 2) for v in os.getloadavg()]


def timed(command: list[str], cwd: Path, timeout: float | None = None,
          env: dict[str, str] | None = None) -> dict:
    """Run ``command`` once; its exit status, CPU and wall seconds, load before and after,
    and the last line it printed (a summary for pytest). Past ``timeout`` seconds of wall
    time the command and everything it started are stopped (``finished`` false, exit
    status None), and the figures are those up to then."""
    before, cpu, wall = _load(), _children_cpu(), time.perf_counter()
    with tempfile.TemporaryFile("w+") as printed:
        process = subprocess.Popen(command, cwd=cwd, stdout=printed,
                                   stderr=subprocess.STDOUT, text=True,
                                   start_new_session=True, env=env)
        try:
            status: int | None = process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)  # its own session: it and its children
            process.wait()
            status = None
        wall, cpu = time.perf_counter() - wall, _children_cpu() - cpu
        printed.seek(0)
        text = printed.read()
    lines = [line for line in text.splitlines() if line.strip()]
    return {"exit_status": status, "finished": status is not None,
            "cpu_seconds": round(cpu, 1), "wall_seconds": round(wall, 1),
            "load_average_before": before, "load_average_after": _load(),
            "last_line": lines[-1] if lines else "", "progress_percent": progress(text),
            "failed": [line.split()[1] for line in lines
                       if line.startswith(("FAILED ", "ERROR ")) and len(line.split()) > 1]}


def progress(printed: str) -> int | None:
    """The last progress figure pytest printed (``[ 42%]`` at the end of a line of dots),
    so that a stopped run says how far it came."""
    found = re.findall(r"\[\s*(\d+)%\]", printed)
    return int(found[-1]) if found else None


def robocal() -> list[str]:
    """The ``robocal`` command of this environment (the script pip installs beside the
    interpreter), or the one on the path."""
    beside = Path(sys.executable).with_name("robocal")
    found = str(beside) if beside.is_file() else shutil.which("robocal")
    if found is None:
        raise SystemExit("setup.py: no robocal command beside the interpreter or on the path")
    return [found]


def pytest_counts(summary: str) -> dict[str, int]:
    """pytest's closing counts (``1218 passed, 6 failed, 3 skipped in ...``)."""
    return {word: int(number) for number, word in
            re.findall(r"(\d+) (passed|failed|skipped|errors?|deselected|xfailed|xpassed)",
                       summary)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tests", action="store_true",
                        help="also time the README's test command (python -m pytest -q)")
    parser.add_argument("--tests-timeout", type=float, default=None, metavar="SECONDS",
                        help="stop the test command after this much wall time and report "
                             "how far it came")
    parser.add_argument("--demo-runs", type=int, default=1,
                        help="times to run the demo (the first may compile C code)")
    parser.add_argument("--blas-default", action="store_true",
                        help="run the demo without OPENBLAS_NUM_THREADS / OMP_NUM_THREADS in "
                             "its environment, so that BLAS picks its own thread count as in "
                             "a newcomer's shell")
    parser.add_argument("--cold-cache", action="store_true",
                        help="run the demo on an empty compiled-code cache (ROBOCAL_CACHE "
                             "in a new folder), as on a newcomer's machine; later demo runs "
                             "reuse what the first compiled")
    args = parser.parse_args()
    out: dict = {"benchmark": "setup", "cores": os.cpu_count(), "niceness": os.nice(0),
                 "demo": []}
    with tempfile.TemporaryDirectory(prefix="robocal-cache-") as cache:
        env = dict(os.environ, ROBOCAL_CACHE=cache) if args.cold_cache else dict(os.environ)
        if args.blas_default:
            for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
                env.pop(name, None)
        for run in range(args.demo_runs):
            with tempfile.TemporaryDirectory(prefix="robocal-setup-") as folder:
                figures = timed(robocal() + ["demo", "--no-screenshot", "--quiet", "--out",
                                             str(Path(folder) / "demo")], ROOT, env=env)
            figures["blas_threads"] = env.get("OPENBLAS_NUM_THREADS", "library default")
            figures["cache"] = ("the user's" if not args.cold_cache else
                                "empty" if run == 0 else "filled by the run before")
            out["demo"].append(figures)
    if args.tests:
        tests = timed([sys.executable, "-m", "pytest", "-q"], ROOT, args.tests_timeout)
        tests["counts"] = pytest_counts(tests["last_line"])
        out["tests"] = tests
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
