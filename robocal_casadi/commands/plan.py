"""Design measurement poses for the set-up a dataset file describes.

Chooses, from bar/artifact placements, laser poses or configurations the robot can
really run (joint limits, above the worktable, target facing the instrument), the ones
that make the identification Jacobian best conditioned for the chosen observability
index, and writes them as the dataset's data table with the measured columns empty
(and, for bars and artifacts, where to put each socket). Prints the index of the plan
and the median of random feasible plans of the same size.
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

from ..common.output import atomic_file
from ..common.table import Table, read_table, write_table
from ..errors import InputError
from ..formats import option_name, program_formats
from ..instruments import instrument
from ..instruments.datasets import load_dataset
from .arguments import add_allow_outside_data, output_file, seed
from .console import summarise

MAX_COUNT = 10_000  # placements or readings in one plan
INDEX_CHOICES = ("tool", "cond", "O1", "O2", "O3", "O4", "O5")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", metavar="DATASET.yaml",
                        help="dataset file: kind, robot, units, instrument geometry "
                             "(its data table need not exist)")
    size = parser.add_mutually_exclusive_group(required=True)
    size.add_argument("--count", type=int, metavar="N",
                      help="bar or artifact placements, or readings, to plan")
    size.add_argument("--target-accuracy", type=float, metavar="X",
                      help="plan the fewest placements or readings predicted to bring the "
                           "work-cell RMS to X (the dataset file's length unit) for nine "
                           "robots in ten; prints the count -> predicted RMS curve")
    parser.add_argument("--prior", metavar="PRIOR.yaml",
                        help="with --target-accuracy: predict with this fleet prior (as "
                             "`robocal prior` writes) in place of the tolerance prior")
    parser.add_argument("--out", required=True, metavar="PLAN.csv", help="plan table to write")
    parser.add_argument("--index", default="tool", choices=INDEX_CHOICES,
                        help="index to optimise: tool = predicted tool-position error over "
                             "the workspace (default), cond = O2 condition number, O1 "
                             "geometric mean of singular values, O3 smallest singular value, "
                             "O4 noise amplification, O5 inverse sum of inverses")
    parser.add_argument("--seed", type=seed, default=0, metavar="S",
                        help="random seed of the candidate search (default 0)")
    parser.add_argument("--no-refine", action="store_true",
                        help="skip the continuous refinement of the chosen joints")
    parser.add_argument("--sensor-only", action="store_true",
                        help="laser: plan the scan for the laser and sphere alone (the "
                             "robot taken as exact; PLAN.csv gets pendant pose columns); the "
                             "default when the dataset's table holds pendant poses")
    for fmt in program_formats():
        parser.add_argument(fmt.flag, metavar=fmt.metavar, dest=option_name(fmt),
                            help=fmt.help)
    add_allow_outside_data(parser)


# What a plan leaves empty for the operator is the measurement model's
# ``measured_columns``; a touch table keeps the plan's socket columns.
PLAN_SOCKET_COLUMNS = ("socket_x", "socket_y", "socket_z")


def holds_readings(table: Table, kind: str) -> bool:
    """True unless ``table`` is a plan not yet measured: for tracker and laser data every
    measured cell is empty; for touches the table still has the plan's socket columns."""
    measured = instrument(kind).model.measured_columns
    if measured:
        present = [c for c in measured if table.has(c)]
        return not present or any(cell for c in present for cell in table.text(c))
    return not all(table.has(c) for c in PLAN_SOCKET_COLUMNS)


def run(args: argparse.Namespace) -> int:
    from planning.designed import design, scans, table
    from planning.trajectory import Scan

    if args.prior is not None and args.target_accuracy is None:
        raise InputError("is for --target-accuracy", where="--prior")
    if args.target_accuracy is not None and not (args.target_accuracy > 0
                                                 and math.isfinite(args.target_accuracy)):
        raise InputError(f"expected a positive length, got {args.target_accuracy}",
                         where="--target-accuracy")
    if args.count is not None and args.count < 1:
        raise InputError(f"expected a positive count, got {args.count}", where="--count")
    if args.count is not None and args.count > MAX_COUNT:
        raise InputError(f"{args.count} is more than a plan of at most {MAX_COUNT} can hold; "
                         "plan in parts", where="--count")
    output_file(args.out, inputs=[args.dataset] + ([args.prior] if args.prior else []))
    for fmt in program_formats():
        path = getattr(args, option_name(fmt))
        if path is not None:
            output_file(path, fmt.flag, inputs=[args.dataset])
    dataset = load_dataset(args.dataset, require_data=False,
                           allow_outside_data=args.allow_outside_data)
    output_file(args.out, inputs=[dataset.robot_path])
    data = dataset.data_path
    if data is not None and data.exists() and Path(args.out).exists() \
            and os.path.samefile(args.out, data):
        if holds_readings(read_table(data), dataset.kind):
            raise InputError(f"{args.out} is the dataset's own data table and it holds "
                             "readings; write the plan to another file", where="--out")
    if args.sensor_only and not scans(dataset):
        raise InputError(f"--sensor-only is for laser scans, not {dataset.kind} data",
                         where="--sensor-only")
    searched = None
    if args.target_accuracy is not None:
        designed, searched = _targeted(dataset, args)
    else:
        designed = design(dataset, args.count, args.index, seed=args.seed,
                          refine=not args.no_refine, sensor_only=args.sensor_only)
    times = designed.times if isinstance(designed, Scan) else None
    programs = _programs(designed.setup.robot, designed.joints, times, args)
    columns, rows = table(designed)
    with atomic_file(args.out) as staging:
        write_table(staging, columns, rows)
    _write_programs(programs)
    print(designed.summary())
    print(f"wrote {args.out}")
    _summarise(args, designed, programs, searched)
    return 0


def _targeted(dataset, args):
    """``(plan, search)`` for ``--target-accuracy``; ``InputError`` (exit 2) when no count
    up to the limit reaches it (nothing written)."""
    from planning.designed import scans
    from planning.target import search

    from ..calibration.population_prior import load_prior

    if scans(dataset):
        raise InputError(f"is for pose plans, not {dataset.kind} scans; use --count",
                         where="--target-accuracy")
    if args.index != "tool":
        raise InputError("plans for the index 'tool' (predicted accuracy)",
                         where="--target-accuracy")
    fleet = None
    if args.prior is not None:
        fleet = load_prior(Path(args.prior))
        fleet.check_robot(dataset.robot, args.prior)
    target = args.target_accuracy * dataset.units.scale("length")  # [m]
    found = search(dataset, target, fleet=fleet, seed=args.seed, refine=not args.no_refine)
    print(found.curve(1e-3, "mm"))  # lengths people read are in mm
    if found.plan is None:
        best = found.best
        if not math.isfinite(best.rms):
            raise InputError(f"no plan of up to {found.limit} placements or readings "
                             "identifies the parameters", where="--target-accuracy")
        raise InputError(
            f"no plan of up to {found.limit} {dataset.kind} placements or readings is "
            f"predicted to reach {1e3 * target:.4g} mm for nine robots in ten: the best, "
            f"{best.count}, gives {1e3 * best.rms:.4g} mm", where="--target-accuracy")
    return found.plan, found


def _summarise(args: argparse.Namespace, plan, programs, searched=None) -> None:
    """The plan's figures for --json (the tool-position errors in metres; with
    --target-accuracy the curve, each count's 90% figure in metres)."""
    figures = {"index": "index", "value": "index_value", "random_median": "random_median",
               "tool_error": "tool_error_m", "random_tool_median": "random_tool_error_m",
               "condition_all": "condition_number"}
    summarise(args, rows=len(plan.joints), out=str(args.out),
              programs=[path for _, path in programs],
              **({} if searched is None else
                 {"target_m": searched.target,
                  "curve": [{"count": t.count, "rms_m": t.rms if math.isfinite(t.rms) else None,
                             "mean_rms_m": t.mean_rms if math.isfinite(t.mean_rms) else None,
                             "tolerance_rms_m": t.tolerance_rms
                             if t.tolerance_rms is None or math.isfinite(t.tolerance_rms)
                             else None}
                            for t in searched.trials]}),
              **{name: getattr(plan, key) for key, name in figures.items()
                 if hasattr(plan, key)})


def _programs(robot, joints, times, args) -> list[tuple[str, str]]:
    """The controller programs asked for, as (text, path); made before anything is written
    so that a refusal (e.g. not 6 axes) leaves no file behind."""
    return [(fmt.write(robot, joints, times), path) for fmt in program_formats()
            if (path := getattr(args, option_name(fmt))) is not None]


def _write_programs(programs) -> None:
    from planning.export import write_text

    for text, path in programs:
        write_text(text, path)
        print(f"wrote {path}")
