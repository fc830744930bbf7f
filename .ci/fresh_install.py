"""A new user's first hour, in a fresh virtual environment: the README's first command
alone, then every verb once, on shipped and simulated data.

    python3 .ci/fresh_install.py [--keep DIR]

Copies the working tree (the files git tracks or would add) into a temporary folder,
makes a virtual environment without the machine's site packages, and runs there, from
the copy's root, the first command of the README's "Set up" section exactly as written
(it installs the package with its core dependencies only, then runs the demo). Then
every verb runs once with --json: each must exit 0 (fleet, whose engine is an optional
extra, exits 2 with one line saying how to install it and writes nothing), print one
JSON object on standard output and no traceback anywhere; one run with --quiet prints
nothing. The copy must also be left as git would see it clean: nothing written outside
the folders git ignores. Exit status 0 when all of that holds, 1 otherwise, with the
failed step named.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT = 1800  # [s] for one step


def first_command(readme: Path) -> str:
    """The first line of the first bash block under the README's "## Set up"."""
    section = readme.read_text().split("## Set up", 1)[1]
    block = section.split("```bash", 1)[1].split("```", 1)[0]
    return next(line.strip() for line in block.splitlines() if line.strip())


def copy_tree(target: Path) -> None:
    """The working tree's files that git tracks or would add (none that it ignores)."""
    listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others",
                             "--exclude-standard"], cwd=ROOT, capture_output=True, check=True)
    for name in filter(None, listed.stdout.decode().split("\0")):
        source = ROOT / name
        if source.is_file():
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target / name)


class Run:
    """Runs steps in the fresh environment and keeps the failures."""

    def __init__(self, venv: Path, cwd: Path):
        self.env = {**{k: v for k, v in os.environ.items()
                       if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")},
                    "PATH": f"{venv / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}",
                    "VIRTUAL_ENV": str(venv)}
        self.cwd = cwd
        self.failures: list[str] = []

    def shell(self, name: str, command: str, cwd: Path) -> subprocess.CompletedProcess:
        print(f"== {name}: {command}", flush=True)
        done = subprocess.run(["bash", "-c", command], cwd=cwd, env=self.env, text=True,
                              capture_output=True, timeout=TIMEOUT)
        if done.returncode != 0 or "Traceback" in done.stderr + done.stdout:
            self.failures.append(f"{name}: exit {done.returncode}\n{done.stdout[-3000:]}\n"
                                 f"{done.stderr[-3000:]}")
        return done

    def verb(self, arguments: list[str], expect: int = 0, says: str = "") -> dict | None:
        name = f"robocal {arguments[0]}"
        print(f"== {name}: robocal {' '.join(arguments)} --json", flush=True)
        done = subprocess.run(["robocal", *arguments, "--json"], cwd=self.cwd, env=self.env,
                              text=True, capture_output=True, timeout=TIMEOUT)
        problems = []
        if done.returncode != expect:
            problems.append(f"exit {done.returncode}, expected {expect}")
        if "Traceback" in done.stderr:
            problems.append("a traceback")
        if says and says not in done.stderr:
            problems.append(f"no {says!r} on standard error")
        try:
            summary = json.loads(done.stdout)
        except ValueError:
            problems.append("standard output is not one JSON object")
            summary = None
        if problems:
            self.failures.append(f"{name}: {'; '.join(problems)}\n{done.stdout[-2000:]}\n"
                                 f"{done.stderr[-3000:]}")
        return summary


def write_inputs(work: Path) -> None:
    """A tracking job and a fleet file for the verbs that read one."""
    rows = ["time,q1,q2,q3,q4,q5,q6,x,y,z,roll,pitch,yaw"]
    for k in range(5):
        rows.append(f"{0.01 * k:.2f},{5 * k},-20,30,0,45,{k},{2 * k},0,300,0,0,0")
    (work / "observations.csv").write_text("\n".join(rows) + "\n")
    (work / "job.yaml").write_text(textwrap.dedent("""\
        kind: tracking
        robot: sim/robot.yaml
        units: {length: mm, angle: deg}
        camera: {xyz: [0, 0, 50]}
        standoff: 300.0
        data: observations.csv
        """))
    (work / "fleet.yaml").write_text("robots:\n  - name: r1\n    datasets: [sim/dataset.yaml]\n")


def every_verb(run: Run) -> None:
    """Each verb once, in the order a user meets them."""
    sim = ["simulate", "--example", "industrial_6r", "--kind", "tracker_points", "--rows",
           "60", "--noise", "0.01", "--error", "a2=0.3", "--error", "theta3=0.05"]
    run.verb([*sim, "--seed", "1", "--out", "sim"])
    run.verb([*sim, "--seed", "2", "--out", "sim-check"])
    run.verb(["calibrate", "sim/dataset.yaml", "--validate", "sim-check/dataset.yaml",
              "--out", "cal"])
    run.verb(["plan", "sim/dataset.yaml", "--count", "12", "--out", "plan.csv"])
    table = (run.cwd / "sim" / "points.csv").read_text().splitlines()
    header = table[0].split(",")
    keep = [header.index(f"q{i}") for i in range(1, 7)]
    (run.cwd / "joints.csv").write_text("\n".join(
        ",".join(line.split(",")[i] for i in keep) for line in table[:6]) + "\n")
    run.verb(["fk", "sim/robot.yaml", "joints.csv", "--calibrated", "cal", "--out", "poses.csv"])
    run.verb(["compensate", "sim/robot.yaml", "poses.csv", "--calibrated", "cal", "--out",
              "commands.csv"])
    run.verb(["export", "cal", "--urdf", "cal.urdf"])
    write_inputs(run.cwd)
    run.verb(["track", "job.yaml", "--out", "tracked.csv", "--calibrated", "cal"])
    try:
        subprocess.run([str(Path(run.env["VIRTUAL_ENV"]) / "bin" / "python"), "-c",
                        "import distributed"], check=True, capture_output=True)
        run.verb(["fleet", "fleet.yaml", "--out", "fleet-out", "--workers", "1"])
    except subprocess.CalledProcessError:  # the core install has no Dask: a clear refusal
        run.verb(["fleet", "fleet.yaml", "--out", "fleet-out"], expect=2, says="pip install")
        if (run.cwd / "fleet-out").exists():
            run.failures.append("robocal fleet: refused, yet left its --out folder behind")
    run.verb(["demo", "--no-diagnose", "--no-screenshot", "--out", "demo-again"])
    quiet = subprocess.run(["robocal", *sim, "--seed", "3", "--out", "sim-quiet", "--quiet"],
                           cwd=run.cwd, env=run.env, text=True, capture_output=True,
                           timeout=TIMEOUT)
    if quiet.returncode != 0 or quiet.stdout or quiet.stderr:
        run.failures.append(f"robocal simulate --quiet: exit {quiet.returncode}, printed "
                            f"{quiet.stdout[-500:]!r} {quiet.stderr[-500:]!r}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", type=Path, help="work in DIR and leave it (default: a "
                        "temporary folder, removed)")
    args = parser.parse_args()
    base = Path(tempfile.mkdtemp(prefix="robocal-fresh-")) if args.keep is None else args.keep
    try:
        clone, venv, work = base / "clone", base / "venv", base / "work"
        clone.mkdir(parents=True)
        work.mkdir()
        copy_tree(clone)
        subprocess.run(["git", "init", "-q"], cwd=clone, check=True)
        subprocess.run(["git", "add", "-A"], cwd=clone, check=True)
        before = subprocess.run(["git", "status", "--porcelain"], cwd=clone, text=True,
                                capture_output=True, check=True).stdout
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        run = Run(venv, work)
        run.shell("README's first command", first_command(clone / "README.md"), clone)
        after = subprocess.run(["git", "status", "--porcelain"], cwd=clone, text=True,
                               capture_output=True, check=True).stdout
        if after != before:
            run.failures.append(f"the README's first command changed the clone:\n{after}")
        if not run.failures:
            every_verb(run)
    finally:
        if args.keep is None:
            shutil.rmtree(base, ignore_errors=True)
    for failure in run.failures:
        print(f"FAILED {failure}", file=sys.stderr)
    print(f"fresh install: {len(run.failures)} failure(s)")
    return 1 if run.failures else 0


if __name__ == "__main__":
    sys.exit(main())
