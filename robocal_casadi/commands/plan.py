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
import os
from pathlib import Path

from ..datasets import load_dataset
from ..errors import InputError
from ..table import Table, read_table
from .arguments import add_allow_outside_data, output_file, seed

MAX_COUNT = 10_000  # placements or readings in one plan
INDEX_CHOICES = ("tool", "cond", "O1", "O2", "O3", "O4", "O5")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", metavar="DATASET.yaml",
                        help="dataset file: kind, robot, units, instrument geometry "
                             "(its data table need not exist)")
    parser.add_argument("--count", type=int, required=True, metavar="N",
                        help="bar or artifact placements, or readings, to plan")
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
    add_allow_outside_data(parser)


# What a plan leaves empty for the operator; a touch table keeps the plan's socket columns.
MEASURED_COLUMNS = {"tracker_points": ("x", "y", "z"), "sphere_laser": ("distance",)}
PLAN_SOCKET_COLUMNS = ("socket_x", "socket_y", "socket_z")


def holds_readings(table: Table, kind: str) -> bool:
    """True unless ``table`` is a plan not yet measured: for tracker and laser data every
    measured cell is empty; for touches the table still has the plan's socket columns."""
    if kind in MEASURED_COLUMNS:
        present = [c for c in MEASURED_COLUMNS[kind] if table.has(c)]
        return not present or any(cell for c in present for cell in table.text(c))
    return not all(table.has(c) for c in PLAN_SOCKET_COLUMNS)


def run(args: argparse.Namespace) -> int:
    from planning.design import design_plan
    from planning.plan_table import write_plan

    if args.count < 1:
        raise InputError(f"expected a positive count, got {args.count}", where="--count")
    if args.count > MAX_COUNT:
        raise InputError(f"{args.count} is more than a plan of at most {MAX_COUNT} can hold; "
                         "plan in parts", where="--count")
    output_file(args.out, inputs=[args.dataset])
    dataset = load_dataset(args.dataset, require_data=False,
                           allow_outside_data=args.allow_outside_data)
    output_file(args.out, inputs=[dataset.robot_path])
    data = dataset.data_path
    if data is not None and data.exists() and Path(args.out).exists() \
            and os.path.samefile(args.out, data):
        if holds_readings(read_table(data), dataset.kind):
            raise InputError(f"{args.out} is the dataset's own data table and it holds "
                             "readings; write the plan to another file", where="--out")
    plan = design_plan(dataset, args.count, args.index, seed=args.seed,
                       refine=not args.no_refine)
    write_plan(plan, args.out)
    print(plan.summary())
    print(f"wrote {args.out}")
    return 0
