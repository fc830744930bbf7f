"""Joint commands that put the calibrated robot's tool on Cartesian targets, each on the
branch (shoulder, elbow, wrist configuration) the robot used before.

ROBOT.yaml is the robot file; with --calibrated DIR (a result of `robocal calibrate`) the
geometry comes from DIR/robot_calibrated.yaml, in ROBOT.yaml's units, as for fk and
track. A calibration folder given in ROBOT.yaml's place is read the same way, in its own
units. TARGETS.csv has columns x,y,z (tool position) and optionally qw,qx,qy,qz (tool
orientation), in ROBOT's length unit and world frame, and optionally q1..qn: the joints
that reached each target before (a taught program, ROBOT's units; a row may leave them
all empty); other columns are copied through. JOINTS.csv gets those columns, the given
joints as seed_q1..seed_qn, then q1..qn (ROBOT's units), status, position_error and, with
orientations, orientation_error (the residual of the solve, ROBOT's units). Status is ok;
branch (the target is reachable, but only on another branch than the seed's: the joint
cells are left empty rather than switching configuration); or unreachable (no solution
within the joint limits from the seed, the first start and --restarts random ones; joint
cells empty).

Each target is solved from its seed and kept on the seed's branch (no singularity between
the seed and the answer, see robocal_casadi.model.configuration). A row without seed joints is
seeded with the inverse kinematics of the nominal robot (the folder's result.json nominal
values; the robot file itself otherwise), solved in order from --start and then from the
previous solution, so a path of targets gives a smooth joint path. Position-only targets
keep the tool turned as at the seed. Only the calibrated geometry is used unless
--with-effects: then the joints are refined until the geometry with the effects the
calibration identified (the folder's effects_calibrated.yaml) reaches each target, so the
robot lands with the accuracy result.json reports for the model with effects. Effects that
read a payload [kg] or a temperature [C] take them from TARGETS.csv's payload/temperature
columns, or from --payload/--temperature.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from ..common.fields import MAX_LENGTH, check_magnitude
from ..common.output import atomic_file
from ..common.table import read_table, write_table
from ..errors import InputError
from ..instruments.datasets import check_unit_quaternions
from ..job.compensation import STATUS_BRANCH, STATUS_UNREACHABLE, compensate
from ..model.calibrated import nominal_of
from ..model.robot import Robot, load_robot
from .arguments import output_file, seed
from .console import summarise

CALIBRATED_ROBOT = "robot_calibrated.yaml"
POSITION = ("x", "y", "z")
QUATERNION = ("qw", "qx", "qy", "qz")
SEED_PREFIX = "seed_"  # the given joints, written back beside the answer


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("robot", metavar="ROBOT.yaml",
                        help="robot file (its units apply to the targets and the joints)")
    parser.add_argument("targets", metavar="TARGETS.csv",
                        help="table with x,y,z[,qw,qx,qy,qz] (robot length unit, world frame) "
                        "and optionally the seed joints q1..qn (robot units)")
    parser.add_argument("--out", metavar="JOINTS.csv", required=True,
                        help="output table: extra input columns, q1..qn, status, errors")
    parser.add_argument("--start", metavar="Q1,...,QN",
                        help="joints to start the nominal solve of the first row without "
                        "seed joints from (robot units; default the middle of the limits)")
    parser.add_argument("--restarts", type=int, default=10,
                        help="random starts per target before it is unreachable (default 10)")
    parser.add_argument("--seed", type=seed, default=0, help="seed of the random starts")
    parser.add_argument("--calibrated", metavar="DIR",
                        help="use DIR/robot_calibrated.yaml (geometry only unless "
                        "--with-effects)")
    from .fk import add_effect_options

    add_effect_options(parser)


def robot_of(argument: str) -> Robot:
    """The robot file, or a calibration folder's robot_calibrated.yaml."""
    path = Path(argument)
    if path.is_dir():
        calibrated = path / CALIBRATED_ROBOT
        if not calibrated.is_file():
            raise InputError(f"no {CALIBRATED_ROBOT} in the calibration folder", file=path)
        return load_robot(calibrated)
    if not path.exists():
        raise InputError("robot file or calibration folder not found", file=path)
    return load_robot(path)


def robot_and_calibration(args: argparse.Namespace) -> tuple[Robot, Path | None]:
    """The robot to compensate, and the calibration folder it comes from (None for a
    robot file alone): ``ROBOT.yaml [--calibrated DIR]``, or a folder in ROBOT's place."""
    from ..model.calibrated import calibrated_robot

    path = Path(args.robot)
    if path.is_dir():
        if args.calibrated is not None:
            raise InputError(f"{path} is a folder; give the robot file, with the calibration "
                             "as --calibrated DIR", where="--calibrated")
        return robot_of(args.robot), path
    robot = robot_of(args.robot)
    if args.calibrated is None:
        return robot, None
    folder = Path(args.calibrated)
    return calibrated_robot(folder, robot, path), folder


def run(args: argparse.Namespace) -> int:
    robot_argument = Path(args.robot)
    calibrated = robot_argument if robot_argument.is_dir() else \
        None if args.calibrated is None else Path(args.calibrated)
    output_file(args.out, inputs=[args.targets, robot_argument, None if calibrated is None
                                  else calibrated / CALIBRATED_ROBOT])
    if args.restarts < 0:
        raise InputError(f"must not be negative, got {args.restarts}", where="--restarts")
    robot, folder = robot_and_calibration(args)
    table = read_table(args.targets, required=POSITION)
    columns, targets = _targets(table, robot)
    has_orientation = len(columns) > len(POSITION)
    joint_names = [f"q{i}" for i in range(1, robot.dof + 1)]
    seeds = seed_joints(table, robot, joint_names)
    extras = [c for c in table.columns if c not in columns and c not in joint_names]
    taken = [f"{SEED_PREFIX}{c}" for c in joint_names] if seeds is not None else []
    clashes = [c for c in extras if c in taken or c in ("status", "position_error",
                                                        "orientation_error")]
    if clashes:
        raise InputError(f"input column(s) {clashes} clash with output columns", file=table.path,
                         where="line 1")
    start = _start_joints(args.start, robot)
    model = extras_values = None
    if args.with_effects:
        if folder is None:
            raise InputError("effects come from a calibration: give --calibrated DIR",
                             where="--with-effects")
        from ..effects.effect_model import load_effects, row_values

        model = load_effects(folder, robot)
        extras_values = row_values(model, table, payload=args.payload,
                                   temperature=args.temperature)
    nominal = nominal_robot(folder if folder is not None else robot_argument, robot)
    result = compensate(robot, targets, start=start, seeds=seeds, nominal=nominal,
                        restarts=args.restarts, seed=args.seed, effects=model,
                        extras=extras_values)
    out_columns = extras + taken + joint_names + ["status", "position_error"]
    if has_orientation:
        out_columns.append("orientation_error")
    rows = _output_rows(result, table, robot, extras, joint_names if seeds is not None else [],
                        has_orientation)
    with atomic_file(args.out) as staging:
        write_table(staging, out_columns, rows)
    unreachable = sum(s == STATUS_UNREACHABLE for s in result.status)
    other = sum(s == STATUS_BRANCH for s in result.status)
    print(f"wrote {len(result)} rows to {args.out} ({unreachable} unreachable, {other} "
          f"reachable only on another branch than their seed's)")
    summarise(args, rows=len(result), unreachable=unreachable, other_branch=other,
              out=str(args.out), calibrated=None if folder is None else str(folder))
    return 0


def _targets(table, robot: Robot) -> tuple[tuple[str, ...], np.ndarray]:
    """The target columns read (x,y,z and, when present, all of qw,qx,qy,qz) and the
    targets, one row each: position [m] in the world frame, then the unit quaternion."""
    L = robot.units.length_scale
    has_orientation = [c for c in QUATERNION if table.has(c)]
    if has_orientation and len(has_orientation) != 4:
        missing = [c for c in QUATERNION if not table.has(c)]
        raise InputError(f"orientation columns need all of {list(QUATERNION)}; missing "
                         f"{missing}", file=table.path, where="line 1")
    columns = POSITION + (QUATERNION if has_orientation else ())
    targets = np.column_stack([table.numbers(c) for c in columns])
    for index, col in np.argwhere(np.abs(targets[:, :3] * L) > MAX_LENGTH)[:1]:
        check_magnitude(targets[index, col] * L, "length", file=table.path,
                        where=f"line {table.line(int(index))}, column {POSITION[col]!r}",
                        shown=targets[index, col], unit=robot.units.length)
    targets[:, :3] *= L
    if has_orientation:
        check_unit_quaternions(targets[:, 3:], table)
    return columns, targets


def _start_joints(text: str | None, robot: Robot) -> np.ndarray | None:
    """``--start`` (robot units) as joints [rad or m], checked against the limits."""
    if not text:
        return None
    try:
        start = np.array([float(v) for v in text.split(",")])
    except ValueError:
        raise InputError(f"expected comma-separated numbers, got {text!r}",
                         where="--start") from None
    if len(start) != robot.dof:
        raise InputError(f"expected {robot.dof} joint values, got {len(start)}",
                         where="--start")
    if not np.all(np.isfinite(start)):
        raise InputError(f"expected finite numbers, got {text!r}", where="--start")
    scales = robot.reading_scales()
    start = start * scales
    outside = np.flatnonzero((start < robot.lower_limits) | (start > robot.upper_limits))
    if outside.size:
        k = int(outside[0])
        raise InputError(f"q{k + 1} = {start[k] / scales[k]:g} is outside the robot's limits",
                         where="--start")
    return start


def _output_rows(result, table, robot: Robot, extras: list[str], seed_columns: list[str],
                 has_orientation: bool) -> list[list]:
    """The rows of JOINTS.csv: copied columns, the given seeds, then the answer in the
    robot's units."""
    L, A = robot.units.length_scale, robot.units.angle_scale
    scales = robot.reading_scales()
    rows = []
    text = {c: table.text(c) for c in extras}
    for i in range(len(result)):
        row: list = [text[c][i] for c in extras]
        row += [table.text(c)[i] for c in seed_columns]
        row += list(result.joints[i] / scales)
        row += [result.status[i], result.position_error[i] / L]
        if has_orientation:
            error = result.orientation_error[i]
            row.append(error / A if math.isfinite(error) else math.nan)
        rows.append(row)
    return rows


def seed_joints(table, robot: Robot, joint_names: list[str]) -> np.ndarray | None:
    """Per-row seed joints [rad or m] from columns q1..qn (robot units; a row left empty
    is seeded from the nominal inverse kinematics), or None without those columns."""
    present = [c for c in joint_names if table.has(c)]
    if not present:
        return None
    if len(present) != len(joint_names):
        missing = [c for c in joint_names if c not in present]
        raise InputError(f"seed joints need all of {joint_names}; missing {missing}",
                         file=table.path, where="line 1")
    values = np.column_stack([table.numbers(c, allow_empty=True) for c in joint_names])
    empty = np.isnan(values)
    partial = np.flatnonzero(empty.any(axis=1) & ~empty.all(axis=1))
    if partial.size:
        raise InputError("seed joints q1..qn must all be given or all be empty",
                         file=table.path, where=f"line {table.line(int(partial[0]))}")
    seeds = values * robot.reading_scales()
    lower, upper = robot.lower_limits, robot.upper_limits
    outside = np.argwhere((seeds < lower) | (seeds > upper))
    if outside.size:
        row, k = (int(v) for v in outside[0])
        raise InputError(f"seed {joint_names[k]} = {values[row, k]:g} is outside the robot's "
                         f"limits", file=table.path, where=f"line {table.line(row)}")
    return seeds


def nominal_robot(argument: Path, calibrated: Robot) -> Robot:
    """The robot the controller knows: for a calibration folder with result.json the
    calibrated robot at the nominal values listed there, else ``calibrated`` itself."""
    if argument.is_dir() and (argument / "result.json").is_file():
        return nominal_of(calibrated, argument)
    return calibrated
