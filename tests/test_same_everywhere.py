"""The same input gives the same answer on every processor.

NumPy's BLAS (OpenBLAS) chooses its kernels by processor; ``OPENBLAS_CORETYPE`` forces
one, so two kernels on this machine stand in for two users' machines. A seeded
``simulate`` must write the same bytes under both (everything that decides or is written
runs on ``common.exact``), and a calibration of those files must agree to 1e-6 relative.

The small algebra of ``common.exact`` is checked against NumPy within the floating-point
bound of the operation (a sum of k products is off by at most about k units in the last
place of the sum of magnitudes).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from robocal_casadi.common import exact

EPS = np.finfo(float).eps


def test_products_agree_with_numpy_within_rounding():
    rng = np.random.default_rng(7)
    for shape_a, shape_b in [((3, 3), (3, 3)), ((3, 3), (3,)), ((5, 3, 3), (3,)),
                             ((4, 3), (3, 3)), ((3,), (3, 4)), ((2, 4, 4), (2, 4, 4))]:
        a, b = rng.normal(size=shape_a), rng.normal(size=shape_b)
        k = shape_a[-1]
        bound = k * EPS * (np.abs(a) @ np.abs(b))
        assert np.all(np.abs(exact.matmul(a, b) - a @ b) <= 2 * bound + 1e-300)
    J, r = rng.normal(size=(12, 6)), rng.normal(size=12)
    assert np.allclose(exact.gram(J), J.T @ J, rtol=0, atol=24 * EPS * np.max(np.abs(J)) ** 2)
    assert np.allclose(exact.transpose_times(J, r), J.T @ r, rtol=0,
                       atol=24 * EPS * np.max(np.abs(J)) * np.max(np.abs(r)))
    assert exact.norm([3.0, 4.0]) == 5.0
    assert np.array_equal(exact.cross([1.0, 0, 0], [0, 1.0, 0]), [0, 0, 1.0])


def test_solve_meets_the_backward_error_bound():
    rng = np.random.default_rng(3)
    for n in (1, 3, 6, 7):
        A = rng.normal(size=(n, n)) + n * np.eye(n)
        b = rng.normal(size=n)
        x = exact.solve(A, b)
        # Gaussian elimination with partial pivoting is backward stable: the residual is
        # of the order of n eps |A| |x|
        assert np.all(np.abs(A @ x - b) <= 10 * n * EPS * (np.abs(A) @ np.abs(x) + np.abs(b)))
    with pytest.raises(exact.SingularMatrix):
        exact.solve(np.zeros((2, 2)), np.ones(2))


def test_pose_inverse_is_exact_on_a_rotation_about_z():
    T = np.eye(4)
    T[:3, :3] = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    T[:3, 3] = [1.0, 2.0, 3.0]
    assert np.array_equal(exact.matmul(exact.inverse_pose(T), T), np.eye(4))


# ------------------------------------------------------------------ two BLAS kernels

KERNELS = ("Haswell", "Sandybridge", "Nehalem", "Prescott")
SIMULATIONS = {
    "bar": ["--example", "industrial_6r", "--kind", "cross_bar", "--rows", "12",
            "--noise", "0.01", "--errors", "0.5,0.05", "--seed", "1"],
    "artifact": ["--example", "industrial_6r", "--kind", "artifact_touches", "--rows", "3",
                 "--noise", "0.01", "--errors", "0.5,0.05", "--effect", "joint_compliance:2,3",
                 "--payload", "2,8", "--seed", "2"],
    "tracker": ["--example", "industrial_6r", "--kind", "tracker_points", "--rows", "60",
                "--noise", "0.01", "--errors", "0.5,0.05", "--effect", "backlash:2",
                "--effect", "joint_cyclic:3", "--seed", "3"],
    "laser": ["--example", "industrial_6r", "--kind", "sphere_laser", "--rows", "40",
              "--noise", "0.005", "--errors", "0.5,0.05", "--effect", "joint_scale:2",
              "--seed", "4"],
    # joints driven together: coupled compliance (pinocchio's gravity) and motor play
    # (the motors' directions of motion from the row order)
    "cable": ["--robot", "{cable_robot}", "--kind", "tracker_points", "--rows", "60",
              "--noise", "0.01", "--errors", "0.5,0.05", "--effect",
              "coupled_compliance:2-3=3e-4/-1e-4/5e-4", "--effect", "motor_play:2=4e-3,3",
              "--seed", "5"],
}
# A small cable arm of our own whose joints 2 and 3 share a differential.
CABLE_ROBOT = """\
convention: dh
units: {length: mm, angle: deg}
joints:
  - {theta: 0, d: 350, a: 0, alpha: -90, mass: 7.0, com: [0, 50, 0], drive: cable}
  - {theta: 0, d: 0, a: 450, alpha: 0, mass: 4.0, com: [-220, 0, 20], drive: cable}
  - {theta: 90, d: 0, a: 40, alpha: 90, mass: 3.0, com: [0, -40, 0], drive: cable}
  - {theta: 0, d: 380, a: 0, alpha: -90, mass: 1.5, com: [0, 0, -120], drive: cable}
transmission:
  - {joints: [2, 3], motors: [[20, 20], [20, -20]]}
"""


def _environment(kernel: str) -> dict[str, str]:
    env = dict(os.environ, OPENBLAS_CORETYPE=kernel)
    env["PYTHONPATH"] = os.pathsep.join([str(Path(__file__).resolve().parents[1]),
                                         env.get("PYTHONPATH", "")])
    return env


def _runs(kernel: str) -> bool:
    """Whether this processor runs the kernel (an unsupported one dies of an illegal
    instruction)."""
    probe = subprocess.run([sys.executable, "-c", "import numpy as n; a = n.ones((9, 9)); "
                            "print((a @ a).sum())"], env=_environment(kernel),
                           capture_output=True, text=True, timeout=120)
    return probe.returncode == 0


@pytest.fixture(scope="module")
def kernels() -> tuple[str, str]:
    usable = [k for k in KERNELS if _runs(k)]
    if len(usable) < 2:
        pytest.skip(f"fewer than two OpenBLAS kernels run here (usable: {usable})")
    return usable[0], usable[1]


def _robocal(kernel: str, *args: str) -> None:
    subprocess.run([sys.executable, "-m", "robocal_casadi.cli", *args, "--quiet"],
                   env=_environment(kernel), check=True, capture_output=True, timeout=600)


def test_seeded_simulation_is_byte_identical_under_two_kernels(kernels, tmp_path):
    robot = tmp_path / "cable.yaml"
    robot.write_text(CABLE_ROBOT)
    for kernel in kernels:
        for name, args in SIMULATIONS.items():
            args = [a.replace("{cable_robot}", str(robot)) for a in args]
            _robocal(kernel, "simulate", *args, "--out", str(tmp_path / kernel / name))
    first, second = (tmp_path / k for k in kernels)
    files = sorted(p.relative_to(first) for p in first.rglob("*") if p.is_file())
    assert len(files) >= 4 * len(SIMULATIONS)  # robot, dataset, table, truth at least
    for relative in files:
        assert (first / relative).read_bytes() == (second / relative).read_bytes(), relative


def _numbers_agree(a, b, path="result") -> list[str]:
    """Paths where two result.json trees differ beyond 1e-6 relative (timings and
    iteration counts aside)."""
    if isinstance(a, dict):
        if set(a) != set(b):
            return [f"{path}: keys {sorted(set(a) ^ set(b))}"]
        return [d for k in a if k not in ("seconds", "iterations")
                for d in _numbers_agree(a[k], b[k], f"{path}.{k}")]
    if isinstance(a, list):
        if len(a) != len(b):
            return [f"{path}: {len(a)} vs {len(b)} entries"]
        return [d for i, (x, y) in enumerate(zip(a, b))
                for d in _numbers_agree(x, y, f"{path}[{i}]")]
    if isinstance(a, float) and isinstance(b, float):
        return [] if abs(a - b) <= 1e-6 * max(abs(a), abs(b)) else [f"{path}: {a} vs {b}"]
    return [] if a == b else [f"{path}: {a!r} vs {b!r}"]


def test_calibration_agrees_under_two_kernels(kernels, tmp_path):
    data = tmp_path / "data"
    _robocal(kernels[0], "simulate", *SIMULATIONS["tracker"], "--out", str(data))
    results = {}
    for kernel in kernels:
        _robocal(kernel, "calibrate", str(data / "dataset.yaml"), "--out", str(tmp_path / kernel))
        results[kernel] = json.loads((tmp_path / kernel / "result.json").read_text())
    assert _numbers_agree(*results.values()) == []


# ------------------------------------------------------------------ plans, tracking, fleet

# (simulation, plan arguments): every kind, the refinement on and off, several indices
PLANS = {
    "bar": ("bar", ["--count", "7", "--seed", "1"]),
    "tracker": ("tracker", ["--count", "12", "--seed", "2", "--index", "O1", "--no-refine"]),
    "artifact": ("artifact", ["--count", "3", "--seed", "3", "--index", "cond", "--no-refine"]),
    "laser": ("laser", ["--count", "60", "--seed", "1", "--sensor-only"]),
}


def _cells(path: Path) -> list[list[str]]:
    return [line.split(",") for line in path.read_text().splitlines()]


def _tables_agree(first: Path, second: Path, skip: tuple[str, ...] = ()) -> list[str]:
    """Where two CSV tables differ: a label, or a number beyond 1e-9 relative (of the
    number, at least 1; the kernels' rounding is 1e-16) outside the ``skip`` columns."""
    a, b = _cells(first), _cells(second)
    if len(a) != len(b) or a[0] != b[0]:
        return [f"{first.name}: {len(a)} vs {len(b)} lines, header {a[0]} vs {b[0]}"]
    found = []
    for line, (row_a, row_b) in enumerate(zip(a[1:], b[1:]), start=2):
        for name, x, y in zip(a[0], row_a, row_b):
            if name in skip or x == y:
                continue
            try:
                u, v = float(x), float(y)
            except ValueError:
                found.append(f"line {line} {name}: {x!r} vs {y!r}")
                continue
            if abs(u - v) > 1e-9 * max(abs(u), abs(v), 1.0):
                found.append(f"line {line} {name}: {x} vs {y}")
    return found


def test_plans_choose_the_same_poses_under_two_kernels(kernels, tmp_path):
    """The same candidates, the same chosen poses in the same order and the same joints
    (to rounding) for every kind, with and without refinement."""
    for name in {simulation for simulation, _ in PLANS.values()}:
        _robocal(kernels[0], "simulate", *SIMULATIONS[name], "--out", str(tmp_path / name))
    for kind, (simulation, args) in PLANS.items():
        for kernel in kernels:
            _robocal(kernel, "plan", str(tmp_path / simulation / "dataset.yaml"), *args,
                     "--out", str(tmp_path / f"{kind}_{kernel}.csv"))
        first, second = (tmp_path / f"{kind}_{k}.csv" for k in kernels)
        assert len(_cells(first)) > 3
        assert _tables_agree(first, second) == [], kind


def test_tracking_compensation_and_fleet_agree_under_two_kernels(kernels, tmp_path):
    """``track`` and ``compensate``: the same statuses and joints within 1e-9; ``fleet``:
    every robot's result.json within 1e-6 relative, the same decisions."""
    from test_tracking import lissajous_joints, write_job

    from robocal_casadi.model.examples import industrial_6r

    job, _ = write_job(tmp_path, industrial_6r(), lissajous_joints("industrial_6r", 30))
    data = tmp_path / "tracker"
    _robocal(kernels[0], "simulate", *SIMULATIONS["tracker"], "--out", str(data))
    (tmp_path / "fleet.yaml").write_text("robots:\n  - {name: r1, datasets: "
                                         "[tracker/dataset.yaml]}\n")
    for kernel in kernels:
        _robocal(kernel, "track", str(job), "--out", str(tmp_path / f"track_{kernel}.csv"))
        _robocal(kernel, "fleet", str(tmp_path / "fleet.yaml"), "--out",
                 str(tmp_path / f"fleet_{kernel}"), "--workers", "1", "--no-report")
    # compensate: the fleet's calibrated robot on targets from its own simulated readings
    points = _cells(data / "points.csv")
    header = points[0]
    joints = [header.index(f"q{i}") for i in range(1, 7)]
    xyz = [header.index(c) for c in ("x", "y", "z")]
    (tmp_path / "targets.csv").write_text("x,y,z,q1,q2,q3,q4,q5,q6\n" + "".join(
        ",".join([row[i] for i in xyz] + [row[i] for i in joints]) + "\n"
        for row in points[1:21]))
    for kernel in kernels:
        _robocal(kernel, "compensate", str(data / "robot.yaml"), str(tmp_path / "targets.csv"),
                 "--calibrated", str(tmp_path / f"fleet_{kernels[0]}" / "r1"),
                 "--out", str(tmp_path / f"compensate_{kernel}.csv"))
    first, second = kernels
    assert {row[-2] for row in _cells(tmp_path / f"track_{first}.csv")[1:]} == {"ok"}
    assert _tables_agree(tmp_path / f"track_{first}.csv", tmp_path / f"track_{second}.csv",
                         skip=("solve_ms",)) == []
    assert _tables_agree(tmp_path / f"compensate_{first}.csv",
                         tmp_path / f"compensate_{second}.csv") == []
    results = [json.loads((tmp_path / f"fleet_{k}" / "r1" / "result.json").read_text())
               for k in kernels]
    assert _numbers_agree(*results) == []


def test_independent_columns_keep_a_basis_of_what_is_not_spanned_already():
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(12, 1)), rng.normal(size=(12, 1))
    constant = np.ones((12, 1)) / np.sqrt(12)
    columns = np.hstack([a, 2 * a - b, b, 3 * constant, a + b + constant])
    kept, span = exact.independent_columns(columns, constant, 1e-12, 1e-8)
    # two new directions (a, b): the rest are combinations of them and the constant
    assert len(kept) == 2 and np.linalg.matrix_rank(columns[:, kept]) == 2
    assert 3 not in kept  # the constant is spanned from the start
    assert np.allclose(span.T @ span, np.eye(3), atol=1e-12)
    assert np.linalg.matrix_rank(np.hstack([span, columns])) == 3
