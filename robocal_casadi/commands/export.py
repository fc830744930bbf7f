"""Write a calibration result in the formats controllers and ROS read.

DIR is a result of `robocal calibrate`. --urdf OUT.urdf writes the calibrated chain over
the user's own URDF: the --like file, or the URDF the calibration read; link and joint
names, meshes, inertias, limits and comments are kept and only joint origins change. A
robot calibrated in DH (or modified DH) form is written into the --like file's link
frames: the fixed transforms between its DH frames and the file's link frames come from
the nominal robot, so the --like file must describe the arm the calibration started from,
with its root link as the robot file's world frame. Without --like a DH robot is written
as a plain description (links frame_0..frame_n, joints joint_1..joint_n).
--ur-calibration OUT.yaml writes UR's kinematics file (x, y, z, roll, pitch, yaw per joint,
as ur_description and the UR ROS drivers read it) for arms with UR's structure; another
arm is refused (``urdf.writer.ur_structure_problem``). --dh-table OUT.csv writes the
joints as a plain DH table (joint, type, theta, d, a, alpha in the robot file's units).
The formats and their flags come from ``robocal_casadi.formats``.

Only the geometry is exported: effects listed in DIR/result.json are not part of a URDF.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..common.output import atomic_file
from ..errors import InputError
from ..formats import ExportSource, model_formats, option_name
from ..model.calibrated import nominal_of
from ..model.robot import load_robot
from .arguments import output_file
from .console import summarise

CALIBRATED_ROBOT = "robot_calibrated.yaml"
RESULT = "result.json"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("folder", metavar="DIR", type=Path, help="a calibration result folder")
    for fmt in model_formats():
        parser.add_argument(fmt.flag, metavar=fmt.metavar, type=Path, dest=option_name(fmt),
                            help=fmt.help)
    parser.add_argument("--like", metavar="VENDOR.urdf", type=Path,
                        help="the URDF to write over (default: the one the calibration read)")
    parser.add_argument("--base-link", metavar="NAME", help="first link of the --like chain")
    parser.add_argument("--tip-link", metavar="NAME", help="last link of the --like chain")


def run(args: argparse.Namespace) -> int:
    folder: Path = args.folder
    if not folder.is_dir():
        raise InputError("calibration folder not found", file=folder)
    asked = [(fmt, path) for fmt in model_formats()
             if (path := getattr(args, option_name(fmt))) is not None]
    if not asked:
        raise InputError("nothing to write: give one or more of " + ", ".join(
            f"{fmt.flag} {fmt.metavar}" for fmt in model_formats()), where="export")
    robot_path = folder / CALIBRATED_ROBOT
    if not robot_path.is_file():
        raise InputError(f"no {CALIBRATED_ROBOT} in the calibration folder", file=folder)
    inputs = [robot_path, folder / RESULT, args.like]
    for fmt, path in asked:
        output_file(path, fmt.flag, inputs=inputs)
    calibrated = load_robot(robot_path)
    like = args.like
    if like is None and calibrated.urdf is not None:
        like = Path(calibrated.urdf.file)
        if not like.is_file():
            raise InputError(f"the URDF the calibration read ({like}) is gone; name it with "
                             "--like", file=robot_path, where="urdf.file")
    nominal = None if calibrated.convention == "urdf" else nominal_of(calibrated, folder)
    source = ExportSource(calibrated, nominal=nominal, like=args.like, urdf=like,
                          base_link=args.base_link, tip_link=args.tip_link)
    texts = {path: fmt.write(source) for fmt, path in asked}
    for path, text in texts.items():  # everything computed before anything is written
        with atomic_file(path) as staging:
            staging.write_text(text)
        print(f"wrote {path}")
    summarise(args, written=[str(p) for p in texts])
    return 0


__all__ = ["add_arguments", "nominal_of", "run"]
