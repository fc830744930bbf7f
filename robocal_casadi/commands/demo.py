"""Run the whole job on real data shipped with the package and write reports.

Two cases, each calibrated on part of the data and validated on the rest:

* a UR10 measured with a laser tracker (absolute target positions): three quarters of
  series D fit, every fourth pose held out;
* a Franka Panda seated in the sockets of a plate (touches of an artifact): seven plate
  placements fit, two whole placements held out.

Each case writes result.json, robot_calibrated.yaml and report.html (plus a screenshot
report.png when Chromium is installed) into OUT/<case>/, replacing that folder as a
whole. OUT defaults to ./robocal-demo, a folder the repository's .gitignore lists, so a
fresh clone stays clean; the repository's own example reports are written with
--out reports. Without Chromium (or with --no-screenshot) a report.png already in the
folder is kept: the data and the results are the same on every run, so the screenshot
still shows the report (only its time stamp and solver times differ).
"""

from __future__ import annotations

import argparse
import sys
from importlib import resources
from pathlib import Path

from ..instruments.datasets import load_dataset
from ..job.run import JobOptions, ReportOptions, run_job
from .arguments import add_force, output_folder
from .calibrate import summary, summary_fields
from .console import summarise

PANDA_FIT = ("back_left", "back_right", "front_center", "front_left", "front_right", "high",
             "mid_left")
PANDA_VALIDATION = ("mid-high", "mid_right")
SCREENSHOT = "report.png"
DEFAULT_OUT = Path("robocal-demo")  # untracked (.gitignore): the demo never dirties a clone


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help=f"folder for the reports (default: ./{DEFAULT_OUT}; the "
                        "repository's example reports: --out reports)")
    parser.add_argument("--no-diagnose", action="store_true",
                        help="stop after the geometric model")
    parser.add_argument("--no-screenshot", action="store_true",
                        help="do not render report.png with Chromium (an existing one is "
                        "kept)")
    add_force(parser)


def data_folder() -> Path:
    """The folder of the shipped data sets."""
    return Path(str(resources.files("robocal_casadi") / "data"))


def cases() -> dict[str, tuple[list[Path], list[Path]]]:
    """Case name -> (fit dataset files, validation dataset files)."""
    data = data_folder()
    return {
        "ur10-tracker": ([data / "ur10-ipa" / "series_D_fit.yaml"],
                         [data / "ur10-ipa" / "series_D_validation.yaml"]),
        "panda-sockets": ([data / "panda-mukca" / f"{n}.yaml" for n in PANDA_FIT],
                          [data / "panda-mukca" / f"{n}.yaml" for n in PANDA_VALIDATION]),
    }


def run(args: argparse.Namespace) -> int:
    chosen = cases()
    for name, (fit_files, validation_files) in chosen.items():
        output_folder(args.out / name, verb="demo", force=args.force,
                      inputs=[*fit_files, *validation_files], keeps=(SCREENSHOT,))
    done = {}
    for name, (fit_files, validation_files) in chosen.items():
        print(f"== {name}")
        fit = [load_dataset(p) for p in fit_files]
        validation = [load_dataset(p) for p in validation_files]
        out = args.out / name
        render = False
        if not args.no_screenshot:
            from ..report import find_chromium

            render = find_chromium() is not None
        outcome = run_job(fit, validation,
                          JobOptions(diagnose=not args.no_diagnose, progress=sys.stderr.isatty()),
                          out, ReportOptions(keep=() if render else (SCREENSHOT,)), verb="demo",
                          progress=sys.stderr.isatty())
        result = outcome.result
        print(summary(result, diagnosed=not args.no_diagnose))
        done[name] = {**summary_fields(result, diagnosed=not args.no_diagnose),
                      "out": str(out)}
        if render:
            from ..report import screenshot_report

            screenshot_report(out / "report.html", out / SCREENSHOT)
        elif not args.no_screenshot:
            kept = "kept from the previous run" if (out / SCREENSHOT).exists() else "not rendered"
            print(f"(no Chromium found: {SCREENSHOT} {kept})")
        print(f"wrote {out}/report.html")
    summarise(args, cases=done)
    return 0
