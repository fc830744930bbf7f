"""Joints that keep the tool facing a moving target, level with the worktable.

Reads a tracking job (kind: tracking; docs/formats.md#tracking-job): the robot, the
camera on the end frame, the standoff Z, the worktable normal `up`, and a table of
camera observations time,q1..qn,x,y,z,roll,pitch,yaw. For each row it solves one small
NLP (target at (0, 0, Z) in the end frame, end z axis on the target, end x axis level,
joint limits, smallest move from the previous answer) and writes JOINTS.csv:
time,q1..qn,status,solve_ms with the joints in the job's units. `status` is ok,
limited (a bounded step towards a reachable goal that needs more than this row may move:
--max-step, or the job's max_velocity times the time since the previous row),
unreachable or failed; an unreachable or failed row keeps the last safe joints (the first
row's capture joints before any answer). Rows are solved in order, as a controller would;
a row the previous joints cannot reach smoothly is seeded from inverse kinematics. Where
the goal's z axis is within 1e-3 rad of `up`, every turn about it is level to within
that angle and the turn nearest the previous joints is kept.

With --calibrated DIR the geometry comes from DIR/robot_calibrated.yaml.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ..common.output import atomic_file
from ..common.table import write_table
from ..errors import InputError
from ..model.calibrated import calibrated_robot
from ..tracking.job import load_tracking_job
from ..tracking.run import joint_scales, track_job
from ..tracking.tracker import STATUSES
from .arguments import add_allow_outside_data, output_file
from .console import summarise


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("job", metavar="JOB.yaml", help="tracking job file (kind: tracking)")
    parser.add_argument("--out", metavar="JOINTS.csv", required=True,
                        help="output table time,q1..qn,status,solve_ms (job's units)")
    parser.add_argument("--calibrated", metavar="DIR",
                        help="use DIR/robot_calibrated.yaml instead of the job's robot file")
    parser.add_argument("--max-step", type=float, metavar="STEP",
                        help="largest joint move per row, in the job's angle unit (length "
                        "unit for prismatic joints); a target needing more is approached "
                        "by steps of this size (status limited)")
    add_allow_outside_data(parser)


def run(args: argparse.Namespace) -> int:
    job_path = Path(args.job)
    output_file(args.out, inputs=[job_path])
    if args.max_step is not None and not (np.isfinite(args.max_step) and args.max_step > 0):
        raise InputError(f"expected a positive number, got {args.max_step}", where="--max-step")
    outside = args.allow_outside_data
    job = load_tracking_job(job_path, allow_outside_data=outside)
    output_file(args.out, inputs=[job.data_path, job.robot_path])
    if args.calibrated is not None:
        robot = calibrated_robot(Path(args.calibrated), job.robot, job.robot_path)
        output_file(args.out, inputs=[Path(args.calibrated) / "robot_calibrated.yaml"])
        job = load_tracking_job(job_path, robot=robot, allow_outside_data=outside)
    max_step = None
    if args.max_step is not None:
        max_step = joint_scales(job) * args.max_step
    tracked = track_job(job, max_step=max_step)
    with atomic_file(args.out) as staging:
        write_table(staging, tracked.columns(), tracked.rows())
    counts = tracked.counts()
    times = tracked.solve_ms
    tally = ", ".join(f"{counts[s]} {s}" for s in STATUSES)
    print(f"{job.rows} rows: {tally}; solve time median {np.median(times):.3f} ms, "
          f"max {times.max():.3f} ms -> {args.out}")
    summarise(args, rows=job.rows, statuses=counts, solve_ms_median=float(np.median(times)),
              solve_ms_max=float(times.max()), out=str(args.out))
    return 0
