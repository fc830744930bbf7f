"""`robocal fk` against a plain numpy implementation of docs/conventions.md."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from robocal_casadi.cli import main

# ------------------------------------------------------------------ independent reference
# Written from docs/conventions.md alone: DH / modified DH with beta, rpy = Rz(y) Ry(p) Rx(r),
# world_T_tool = base * T(0,1) ... T(n-1,n) * tool, readings add to theta (revolute) or d.


def Rx(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def Ry(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def Rz(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def Tr(x, y, z):
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def reference_tool_pose(spec: dict, q_file_units) -> np.ndarray:
    """Tool pose with lengths in the spec's length unit, from readings in its units."""
    to_rad = math.pi / 180 if spec["angle"] == "deg" else 1.0
    base_xyz, base_rpy = spec["base"]
    tool_xyz, tool_rpy = spec["tool"]

    def frame(xyz, rpy):
        r, p, y = (v * to_rad for v in rpy)
        return Tr(*xyz) @ Rz(y) @ Ry(p) @ Rx(r)

    T = frame(base_xyz, base_rpy)
    for (kind, theta, d, a, alpha, beta), q in zip(spec["joints"], q_file_units):
        if kind == "revolute":
            theta = theta + q
        else:
            d = d + q
        theta, alpha, beta = theta * to_rad, alpha * to_rad, beta * to_rad
        if spec["convention"] == "dh":
            T = T @ Rz(theta) @ Tr(0, 0, d) @ Tr(a, 0, 0) @ Rx(alpha) @ Ry(beta)
        else:
            T = T @ Rx(alpha) @ Tr(a, 0, 0) @ Rz(theta) @ Tr(0, 0, d) @ Ry(beta)
    return T @ frame(tool_xyz, tool_rpy)


def rotation_of_quaternion(w, x, y, z) -> np.ndarray:
    return np.array([[w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z]])


# ------------------------------------------------------------------ robots under test

SCARA_MM_DEG = {
    "convention": "dh", "length": "mm", "angle": "deg",
    "joints": [("revolute", 10.0, 400.0, 350.0, 0.0, 0.0),
               ("revolute", -5.0, 12.0, 300.0, 180.0, 0.3),
               ("prismatic", 3.0, 50.0, 1.5, 0.0, 0.0),
               ("revolute", 0.0, 80.0, 0.0, -0.2, 0.0)],
    "limits": [(-150, 150), (-145, 145), (0, 300), (-360, 360)],
    "base": ((100.0, -200.0, 15.0), (1.0, -2.0, 17.0)),
    "tool": ((5.0, -3.0, 120.0), (0.0, 30.0, 90.0)),
}

PANDA_M_RAD = {
    "convention": "mdh", "length": "m", "angle": "rad",
    "joints": [("revolute", 0.0, 0.333, 0.0, 0.0, 0.0),
               ("revolute", 0.01, 0.0, 0.0, -math.pi / 2, 0.002),
               ("revolute", 0.0, 0.316, 0.0, math.pi / 2, -0.003),
               ("revolute", 0.0, 0.0, 0.0825, math.pi / 2, 0.0),
               ("revolute", 0.0, 0.384, -0.0825, -math.pi / 2, 0.001),
               ("revolute", 0.0, 0.0, 0.0, math.pi / 2, 0.0)],
    "limits": [(-2.9, 2.9), (-1.76, 1.76), (-2.9, 2.9), (-3.07, -0.07), (-2.9, 2.9), (-0.02, 3.75)],
    "base": ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
    "tool": ((0.0, 0.0, 0.107), (0.0, 0.0, -math.pi / 4)),
}


def robot_yaml(spec: dict) -> str:
    lines = [f"convention: {spec['convention']}",
             f"units: {{length: {spec['length']}, angle: {spec['angle']}}}", "joints:"]
    for (kind, theta, d, a, alpha, beta), (lo, hi) in zip(spec["joints"], spec["limits"]):
        lines.append(f"  - {{type: {kind}, theta: {theta!r}, d: {d!r}, a: {a!r}, "
                     f"alpha: {alpha!r}, beta: {beta!r}, limits: [{lo}, {hi}]}}")
    for key in ("base", "tool"):
        xyz, rpy = spec[key]
        lines.append(f"{key}: {{xyz: {list(xyz)}, rpy: {list(rpy)}}}")
    return "\n".join(lines) + "\n"


def readings(spec: dict, count: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    lower, upper = np.array(spec["limits"], dtype=float).T
    Q = rng.uniform(lower, upper, size=(count, len(lower)))
    Q[0] = np.clip(0.0, lower, upper)  # a configuration with the wrist aligned
    return Q


def write_joints(path: Path, Q: np.ndarray, extra=True) -> None:
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        names = [f"q{i}" for i in range(1, Q.shape[1] + 1)]
        writer.writerow((["time"] if extra else []) + names + (["note"] if extra else []))
        for k, q in enumerate(Q):
            row = [repr(float(v)) for v in q]
            writer.writerow(([f"{0.5 * k:.3f}"] if extra else []) + row
                            + ([f"row {k}"] if extra else []))


def read_rows(path: Path) -> tuple[list[str], list[list[str]]]:
    with path.open(newline="") as handle:
        rows = list(csv.reader(handle))
    return rows[0], rows[1:]


def check_poses(out: Path, spec: dict, Q: np.ndarray, length_tolerance: float) -> None:
    header, rows = read_rows(out)
    names = [f"q{i}" for i in range(1, Q.shape[1] + 1)]
    assert header == ["time", *names, "note", "x", "y", "z", "qw", "qx", "qy", "qz"]
    assert len(rows) == len(Q)
    for k, (row, q) in enumerate(zip(rows, Q)):
        assert row[0] == f"{0.5 * k:.3f}" and row[len(q) + 1] == f"row {k}"
        assert row[1:len(q) + 1] == [repr(float(v)) for v in q]  # the reading, as written
        x, y, z, w, qx, qy, qz = map(float, row[len(q) + 2:])
        expected = reference_tool_pose(spec, q)
        np.testing.assert_allclose([x, y, z], expected[:3, 3], rtol=0, atol=length_tolerance)
        assert abs(w * w + qx * qx + qy * qy + qz * qz - 1) < 1e-14
        np.testing.assert_allclose(rotation_of_quaternion(w, qx, qy, qz), expected[:3, :3],
                                   rtol=0, atol=1e-13)


@pytest.mark.parametrize("spec, tolerance", [(SCARA_MM_DEG, 1e-9), (PANDA_M_RAD, 1e-13)],
                         ids=["dh_mm_deg_prismatic", "mdh_m_rad_beta"])
def test_fk_matches_reference(tmp_path, spec, tolerance):
    robot = tmp_path / "robot.yaml"
    robot.write_text(robot_yaml(spec))
    Q = readings(spec, 25, seed=11)
    write_joints(tmp_path / "joints.csv", Q)
    out = tmp_path / "poses.csv"
    assert main(["fk", str(robot), str(tmp_path / "joints.csv"), "--out", str(out)]) == 0
    check_poses(out, spec, Q, tolerance)


def test_fk_with_calibrated_robot(tmp_path):
    (tmp_path / "robot.yaml").write_text(robot_yaml(SCARA_MM_DEG))
    calibrated = dict(SCARA_MM_DEG)
    joints = list(calibrated["joints"])
    joints[1] = ("revolute", -4.9, 12.4, 300.6, 179.8, 0.25)
    calibrated["joints"] = joints
    calibrated["tool"] = ((5.2, -3.1, 121.0), (0.1, 30.0, 90.0))
    result = tmp_path / "result"
    result.mkdir()
    (result / "robot_calibrated.yaml").write_text(robot_yaml(calibrated))
    Q = readings(SCARA_MM_DEG, 10, seed=12)
    write_joints(tmp_path / "joints.csv", Q)
    out = tmp_path / "poses.csv"
    argv = ["fk", str(tmp_path / "robot.yaml"), str(tmp_path / "joints.csv"), "--out", str(out),
            "--calibrated", str(result)]
    assert main(argv) == 0
    check_poses(out, calibrated, Q, 1e-9)


def test_help_says_effects_are_applied_only_when_asked(capsys):
    with pytest.raises(SystemExit):
        main(["fk", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "robot_calibrated.yaml" in text and "geometry is used unless --with-effects" in text


def bad_case(tmp_path: Path, case: str) -> tuple[list[str], str]:
    """Arguments for one bad input and a fragment the error line must contain."""
    robot, joints, out = tmp_path / "robot.yaml", tmp_path / "joints.csv", tmp_path / "poses.csv"
    robot.write_text(robot_yaml(SCARA_MM_DEG))
    Q = readings(SCARA_MM_DEG, 5, seed=13)
    argv = ["fk", str(robot), str(joints), "--out", str(out)]
    if case == "outside limits":
        Q[3, 1] = 170.0
        write_joints(joints, Q)
        return argv, "joints.csv: line 5: q2 = 170 deg is outside the robot's limits"
    if case == "prismatic outside limits":
        Q[0, 2] = 400.0
        write_joints(joints, Q)
        return argv, "line 2: q3 = 400 mm is outside the robot's limits [0, 300] mm"
    write_joints(joints, Q)
    if case == "missing joint column":
        joints.write_text("time,q1,q2,q3\n0,1,2,3\n")
        return argv, "missing joint column(s) ['q4']"
    if case == "non-numeric reading":
        joints.write_text("q1,q2,q3,q4\n1,2,3,4\n1,2,abc,4\n")
        return argv, "joints.csv: line 3: column 'q3': expected a number, got 'abc'"
    if case == "pose column clash":
        joints.write_text("q1,q2,q3,q4,x\n1,2,3,4,5\n")
        return argv, "['x'] would clash"
    if case == "missing robot file":
        robot.unlink()
        return argv, "robot.yaml: robot file not found"
    if case == "bad robot file":
        robot.write_text(robot_yaml(SCARA_MM_DEG).replace("mm", "furlong"))
        return argv, "robot.yaml: units.length: unknown length unit 'furlong'"
    if case == "missing joints file":
        joints.unlink()
        return argv, "joints.csv: data table not found"
    if case == "calibrated folder without robot":
        (tmp_path / "result").mkdir()
        return argv + ["--calibrated", str(tmp_path / "result")], "no robot_calibrated.yaml"
    raise AssertionError(case)


BAD = ["outside limits", "prismatic outside limits", "missing joint column", "non-numeric reading",
       "pose column clash", "missing robot file", "bad robot file", "missing joints file",
       "calibrated folder without robot"]


@pytest.mark.parametrize("case", BAD)
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, case):
    argv, fragment = bad_case(tmp_path, case)
    assert main(argv) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and error.startswith("robocal fk: error: ")
    assert fragment in error
    assert not (tmp_path / "poses.csv").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".poses.csv")]
