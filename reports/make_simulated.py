"""Write the example reports of simulated data in reports/: bar, artifact and sphere.

Each case is a fixed true robot (the industrial_6r example with explicit geometric
errors and no error of the mounted instrument), simulated twice with different seeds:
once for fitting, once held out. Run from the repository root:

    python reports/make_simulated.py            # all cases
    python reports/make_simulated.py bar-simulated

Every step is a `robocal` command; the commands are printed as they run. A screenshot
(report.png) is taken when Chromium is installed.
"""

from __future__ import annotations

import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
TRUTH = ["--error", "a2=0.4", "--error", "d4=-0.3", "--error", "a3=0.25",
         "--error", "theta3=0.04", "--error", "alpha2=0.03", "--error", "theta5=-0.05",
         "--mounted-error", "0"]
CASES = {
    # kind, extra simulate options, fit rows (placements or readings), held-out rows
    "bar-simulated": ("cross_bar", ["--noise", "0.01"], 40, 15),
    "artifact-simulated": ("artifact_touches", ["--noise", "0.01", "--sockets", "4",
                                                "--touches", "3", "--units", "m,rad"], 14, 6),
    "sphere-simulated": ("sphere_laser", ["--noise", "0.01"], 300, 120),
}
REPORT = ["--customer", "Example customer", "--robot-serial", "SIM-0001",
          "--operator", "robocal simulate", "--date", "2024-01-01"]


def robocal(*arguments: str) -> None:
    command = [sys.executable, "-m", "robocal_casadi.cli", *arguments]
    print("robocal " + shlex.join(arguments), flush=True)
    subprocess.run(command, check=True)


def make(name: str) -> None:
    kind, options, fit_rows, held_rows = CASES[name]
    with tempfile.TemporaryDirectory() as scratch:
        data = Path(scratch)
        for role, rows, seed in (("fit", fit_rows, 1), ("validation", held_rows, 2)):
            robocal("simulate", "--example", "industrial_6r", "--kind", kind, "--rows",
                    str(rows), "--seed", str(seed), *TRUTH, *options, "--out",
                    str(data / role))
        instrument = {"cross_bar": "cross bar, touch probe", "sphere_laser":
                      "point laser and reference sphere", "artifact_touches":
                      "socket plate, touch probe"}[kind]
        # --force: the folder is this script's own, and its screenshot (added after the
        # calibration wrote the folder) is not among the files calibrate lists as its own.
        robocal("calibrate", str(data / "fit" / "dataset.yaml"), "--validate",
                str(data / "validation" / "dataset.yaml"), "--out", str(HERE / name),
                *REPORT, "--instrument", f"{instrument} (simulated)", "--force")
    from robocal_casadi.report import find_chromium, screenshot_report

    if find_chromium():
        screenshot_report(HERE / name / "report.html", HERE / name / "report.png")
    else:
        print("(no Chromium found: report.png not rendered)")


if __name__ == "__main__":
    for case in sys.argv[1:] or list(CASES):
        make(case)
