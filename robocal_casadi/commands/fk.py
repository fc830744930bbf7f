"""Tool poses from joint readings (forward kinematics) with a nominal or calibrated robot.

For each row of q1..qn in JOINTS.csv (in the robot file's units) writes the tool pose
x,y,z,qw,qx,qy,qz in the world frame (lengths in the robot file's unit, quaternion with
qw >= 0) to POSES.csv. Every input column (q1..qn and the others: time, payload,
temperature, ...) is copied through as written, in its order, before the pose columns, so
each output row holds the reading it came from. Readings outside the robot's joint limits
are refused.

With --calibrated DIR the geometry comes from DIR/robot_calibrated.yaml (a result of
`robocal calibrate`); the readings and the output keep ROBOT.yaml's units. Only the
calibrated geometry is used unless --with-effects: then the effects the calibration
identified (DIR/effects_calibrated.yaml: joint compliance, periodic joint errors, gear-ratio
errors, thermal drift, ...) are applied too, so the poses carry the accuracy result.json
reports for the model with effects. Effects that read a payload [kg] or a temperature [C]
take them from JOINTS.csv's payload/temperature columns, or from --payload/--temperature.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..common.output import atomic_file
from ..common.table import read_table, write_table
from ..errors import InputError
from ..instruments.datasets import joint_readings as checked_joint_readings
from ..model.calibrated import (
    CALIBRATED_ROBOT,
    POSE_COLUMNS,
    calibrated_robot,
    pose_rows,
    tool_pose_rows,
)
from ..model.robot import load_robot
from .arguments import input_file, output_file
from .console import summarise

# The calibrated robot and the pose rows are shared with track, compensate and the
# Python front door (``model.calibrated``); the names stay importable from here.
__all__ = ["CALIBRATED_ROBOT", "POSE_COLUMNS", "add_arguments", "add_effect_options",
           "calibrated_robot", "pose_rows", "run", "tool_pose_rows"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("robot", metavar="ROBOT.yaml", help="robot file (its units apply to the "
                        "joint readings and the poses)")
    parser.add_argument("joints", metavar="JOINTS.csv", help="table with columns q1..qn")
    parser.add_argument("--out", metavar="POSES.csv", required=True,
                        help="output table: the input columns as written, then x,y,z,qw,qx,qy,qz")
    parser.add_argument("--calibrated", metavar="DIR",
                        help="use DIR/robot_calibrated.yaml (geometry only unless "
                        "--with-effects)")
    parser.add_argument("--base-link", metavar="NAME", help="first link of a URDF robot's chain")
    parser.add_argument("--tip-link", metavar="NAME", help="last link of a URDF robot's chain")
    add_effect_options(parser)


def add_effect_options(parser: argparse.ArgumentParser) -> None:
    """``--with-effects``, ``--payload`` and ``--temperature`` (fk and compensate)."""
    parser.add_argument("--with-effects", action="store_true",
                        help="also apply the effects the calibration identified "
                        "(effects_calibrated.yaml of the calibration folder)")
    parser.add_argument("--payload", type=float, metavar="KG",
                        help="payload [kg] for every row, where the effects need one and the "
                        "table has no payload column")
    parser.add_argument("--temperature", type=float, metavar="C",
                        help="temperature [C] for every row, where the effects need one and "
                        "the table has no temperature column")


def run(args: argparse.Namespace) -> int:
    robot_path = input_file(args.robot, "robot file")
    calibrated = Path(args.calibrated) / CALIBRATED_ROBOT if args.calibrated else None
    output_file(args.out, inputs=[robot_path, args.joints, calibrated])
    robot = load_robot(robot_path, base_link=args.base_link, tip_link=args.tip_link)
    if args.calibrated is not None:
        robot = calibrated_robot(Path(args.calibrated), robot, robot_path)
    table = read_table(args.joints)
    used: set[str] = set()
    readings_robot = Path(args.calibrated) / CALIBRATED_ROBOT if args.calibrated else robot_path
    Q = checked_joint_readings(table, robot, robot.units, used, readings_robot)
    kept_columns = list(table.columns)  # the reading itself, then what it gives
    clashes = [c for c in kept_columns if c in POSE_COLUMNS]
    if clashes:
        raise InputError(f"column(s) {clashes} would clash with the pose columns "
                         f"{list(POSE_COLUMNS)} of the output; rename them", file=table.path)
    if args.with_effects:
        if args.calibrated is None:
            raise InputError("effects come from a calibration: give --calibrated DIR",
                             where="--with-effects")
        from ..effects.effect_model import load_effects, row_values

        model = load_effects(Path(args.calibrated), robot)
        values = row_values(model, table, payload=args.payload, temperature=args.temperature)
        poses = pose_rows(model.tool_poses(Q, values), robot)
    else:
        poses = tool_pose_rows(robot, Q)
    copied = [list(row) for row in table.rows]
    with atomic_file(args.out) as staging:
        write_table(staging, [*kept_columns, *POSE_COLUMNS],
                    [[*kept, *pose] for kept, pose in zip(copied, poses)])
    print(f"wrote {len(poses)} tool poses to {args.out}")
    summarise(args, rows=len(poses), out=str(args.out), unit=robot.units.length,
              calibrated=args.calibrated, with_effects=bool(args.with_effects))
    return 0
