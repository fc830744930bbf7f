"""A camera turned on the end frame and markers as OpenCV/ArUco report them.

The scene is built by hand: a wanted end pose ``G``; the ArUco marker facing it at the
standoff (``G Tz(Z) Rx(180 deg)``: marker z towards the camera, x along the end's x);
the camera at ``T_end_camera = Trans(xyz) R_camera``; what the camera reports is
``T_camera_marker`` at the capture joints, written as OpenCV's tvec and rvec (scipy's
rotation vector, not the package's conversion) or as a quaternion. The joints solved
must put pinocchio's end frame on ``G`` (position, z axis) with x level.
"""

from __future__ import annotations

import csv

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from robocal_casadi.cli import main
from robocal_casadi.model.examples import industrial_6r
from robocal_casadi.model.kinematics import nominal_pose
from robocal_casadi.model.pinocchio_model import pinocchio_tool_pose
from robocal_casadi.model.robot import save_robot
from robocal_casadi.tracking import Tracker

STANDOFF = 0.3  # [m]
CAMERA_XYZ = np.array([0.05, -0.02, 0.04])  # [m]
CAMERA_RPY = np.array([0.2, -0.3, 0.5])  # [rad], R = Rz(y) Ry(p) Rx(r)
START = np.array([0.2, -0.4, 0.5, 0.3, 0.9, 0.2])


def camera_pose() -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", CAMERA_RPY).as_matrix()  # extrinsic x, y, z
    T[:3, 3] = CAMERA_XYZ
    return T


def marker_seen(robot, q_capture, goal) -> np.ndarray:
    """``T_camera_marker`` of the marker that faces ``goal`` from the standoff."""
    flip = np.diag([1.0, -1.0, -1.0, 1.0])  # Rx(180 deg)
    stand = np.eye(4)
    stand[2, 3] = STANDOFF
    T_world_marker = goal @ stand @ flip
    T_world_camera = nominal_pose(robot, q_capture) @ camera_pose()
    return np.linalg.solve(T_world_camera, T_world_marker)


def on_goal(robot, q, goal, tolerance=1e-8) -> None:
    T = pinocchio_tool_pose(robot, q)
    assert np.linalg.norm(T[:3, 3] - goal[:3, 3]) < tolerance
    assert T[:3, 2] @ goal[:3, 2] == pytest.approx(1.0, abs=tolerance)
    assert abs(T[2, 0]) < tolerance  # x level with the table (up = world z)


def scene(count=5):
    robot = industrial_6r()
    rng = np.random.default_rng(4)
    goals = [nominal_pose(robot, START + rng.uniform(-0.1, 0.1, 6)) for _ in range(count)]
    return robot, goals


def test_tracker_takes_opencv_marker_poses_from_a_turned_camera():
    robot, goals = scene()
    tracker = Tracker(robot, CAMERA_XYZ, STANDOFF, camera_rotation=camera_pose()[:3, :3],
                      marker_convention="opencv")
    tracker.reset(START)
    for goal in goals:
        seen = marker_seen(robot, START, goal)
        rvec = Rotation.from_matrix(seen[:3, :3]).as_rotvec()
        step = tracker.step(START, np.concatenate([seen[:3, 3], rvec]))
        assert step.ok, step
        on_goal(robot, step.q, goal)


def test_a_turned_camera_is_not_the_parallel_one():
    """The rotation matters: ignoring it misses the goal (the check above can fail)."""
    robot, goals = scene(1)
    tracker = Tracker(robot, CAMERA_XYZ, STANDOFF, marker_convention="opencv")
    tracker.reset(START)
    seen = marker_seen(robot, START, goals[0])
    step = tracker.step(START, np.concatenate(
        [seen[:3, 3], Rotation.from_matrix(seen[:3, :3]).as_rotvec()]))
    T = pinocchio_tool_pose(robot, step.q)
    assert np.linalg.norm(T[:3, 3] - goals[0][:3, 3]) > 1e-3


def write_job(folder, robot, goals, *, camera: dict, orientation: str, extra: dict):
    """A job in mm/deg whose rows report the marker facing each goal."""
    save_robot(robot, folder / "robot.yaml")
    columns = {"rvec": ["rx", "ry", "rz"], "quaternion": ["qw", "qx", "qy", "qz"]}[orientation]
    rows = []
    for k, goal in enumerate(goals):
        seen = marker_seen(robot, START, goal)
        rotation = Rotation.from_matrix(seen[:3, :3])
        if orientation == "rvec":
            values = list(np.degrees(rotation.as_rotvec()))
        else:
            x, y, z, w = rotation.as_quat()  # scipy writes the scalar last
            values = [w, x, y, z]
        rows.append([0.1 * k, *np.degrees(START), *(seen[:3, 3] * 1e3), *values])
    with open(folder / "observations.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time", *(f"q{i}" for i in range(1, 7)), "x", "y", "z", *columns])
        writer.writerows([[repr(float(v)) for v in row] for row in rows])
    job = {"kind": "tracking", "robot": "robot.yaml", "units": {"length": "mm", "angle": "deg"},
           "camera": {"xyz": [float(v) for v in CAMERA_XYZ * 1e3], **camera},
           "standoff": STANDOFF * 1e3, "data": "observations.csv", **extra}
    (folder / "job.yaml").write_text(yaml.safe_dump(job))
    return folder / "job.yaml"


@pytest.mark.parametrize("camera_form, orientation",
                         [("rpy", "rvec"), ("quaternion", "quaternion")])
def test_job_file_with_hand_eye_camera_and_opencv_marker(tmp_path, camera_form, orientation):
    robot, goals = scene()
    if camera_form == "rpy":
        camera = {"rpy": [float(v) for v in np.degrees(CAMERA_RPY)]}
    else:
        x, y, z, w = Rotation.from_euler("xyz", CAMERA_RPY).as_quat()
        camera = {"quaternion": [float(w), float(x), float(y), float(z)]}
    job = write_job(tmp_path, robot, goals, camera=camera, orientation=orientation,
                    extra={"marker_convention": "opencv"})
    out = tmp_path / "joints.csv"
    assert main(["track", str(job), "--out", str(out)]) == 0
    with open(out, newline="") as handle:
        table = list(csv.DictReader(handle))
    assert [r["status"] for r in table] == ["ok"] * len(goals)
    for row, goal in zip(table, goals):
        q = np.radians([float(row[f"q{i}"]) for i in range(1, 7)])
        on_goal(robot, q, goal, tolerance=1e-7)


def test_method_convention_accepts_quaternion_columns(tmp_path):
    """The default convention with a quaternion of C instead of roll, pitch, yaw gives the
    same joints as the roll, pitch, yaw table."""
    robot, goals = scene(3)
    rpy_rows, quaternion_rows = [], []
    tracker = Tracker(robot, CAMERA_XYZ, STANDOFF, camera_rotation=camera_pose()[:3, :3],
                      marker_convention="opencv")
    for k, goal in enumerate(goals):
        seen = marker_seen(robot, START, goal)
        rvec = Rotation.from_matrix(seen[:3, :3]).as_rotvec()
        # The method's observation of the same scene, from the tracker's conversion's
        # definition: position and C = R_B^T R_end_target for a parallel camera.
        T_end_marker = camera_pose() @ seen
        R_B = np.array([[0, -1, 0], [0, 0, -1], [1, 0, 0.0]])
        flip = np.diag([1.0, -1.0, -1.0])
        C = R_B.T @ T_end_marker[:3, :3] @ flip @ R_B
        xyz = T_end_marker[:3, 3] - CAMERA_XYZ
        roll, pitch, yaw = Rotation.from_matrix(C).as_euler("xyz")
        x, y, z, w = Rotation.from_matrix(C).as_quat()
        rpy_rows.append([0.1 * k, *np.degrees(START), *(xyz * 1e3),
                         *np.degrees([roll, pitch, yaw])])
        quaternion_rows.append([0.1 * k, *np.degrees(START), *(xyz * 1e3), w, x, y, z])
        assert tracker.goal(START, np.concatenate([seen[:3, 3], rvec])) == pytest.approx(
            Tracker(robot, CAMERA_XYZ, STANDOFF).goal(START, np.concatenate(
                [xyz, [roll, pitch, yaw]])), abs=1e-12)
    answers = []
    for name, rows, columns in (("rpy", rpy_rows, ["roll", "pitch", "yaw"]),
                                ("quaternion", quaternion_rows, ["qw", "qx", "qy", "qz"])):
        folder = tmp_path / name
        folder.mkdir()
        save_robot(robot, folder / "robot.yaml")
        with open(folder / "observations.csv", "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(["time", *(f"q{i}" for i in range(1, 7)), "x", "y", "z", *columns])
            writer.writerows([[repr(float(v)) for v in row] for row in rows])
        (folder / "job.yaml").write_text(yaml.safe_dump({
            "kind": "tracking", "robot": "robot.yaml",
            "units": {"length": "mm", "angle": "deg"},
            "camera": {"xyz": [float(v) for v in CAMERA_XYZ * 1e3]},
            "standoff": STANDOFF * 1e3, "data": "observations.csv"}))
        assert main(["track", str(folder / "job.yaml"), "--out", str(folder / "j.csv")]) == 0
        with open(folder / "j.csv", newline="") as handle:
            table = list(csv.DictReader(handle))
        assert [r["status"] for r in table] == ["ok"] * 3
        answers.append(np.array([[float(r[f"q{i}"]) for i in range(1, 7)] for r in table]))
        for row, goal in zip(answers[-1], goals):
            on_goal(robot, np.radians(row), goal, tolerance=1e-7)
    assert answers[0] == pytest.approx(answers[1], abs=1e-9)


@pytest.mark.parametrize("change, fragment", [
    ({"marker_convention": "aruco"}, "marker_convention"),
    ({"camera": {"xyz": [0, 0, 0], "rpy": [0, 0, 0], "quaternion": [1, 0, 0, 0]}}, "camera"),
    ({"camera": {"xyz": [0, 0, 0], "quaternion": [2, 0, 0, 0]}}, "norm 1"),
    ({"camera": {"xyz": [0, 0, 0], "rotation": [0, 0, 0]}}, "camera"),
])
def test_bad_camera_or_convention_is_one_line(tmp_path, capsys, change, fragment):
    robot, goals = scene(2)
    job = write_job(tmp_path, robot, goals, camera={}, orientation="rvec",
                    extra={"marker_convention": "opencv"})
    content = yaml.safe_load(job.read_text())
    content.update(change)
    job.write_text(yaml.safe_dump(content))
    out = tmp_path / "joints.csv"
    assert main(["track", str(job), "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert "job.yaml" in error and fragment in error and len(error.strip().splitlines()) == 1
    assert not out.exists()


def test_opencv_job_without_its_orientation_columns_names_them(tmp_path, capsys):
    robot, goals = scene(2)
    job = write_job(tmp_path, robot, goals, camera={}, orientation="rvec", extra={})
    out = tmp_path / "joints.csv"
    assert main(["track", str(job), "--out", str(out)]) == 2  # rx.. without opencv
    error = capsys.readouterr().err
    assert "observations.csv" in error and "'roll'" in error and "qw,qx,qy,qz" in error
    assert not out.exists()
