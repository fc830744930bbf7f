"""Forward kinematics and Jacobians: CasADi (interpreted, compiled), pinocchio, plain numpy.

Prints JSON: microseconds per configuration, one call per configuration from Python
("single") and 1,000 configurations in one call ("batched"), for

* ``fk``: the tool pose;
* ``fk_parameter_jacobian``: a flange point and its derivatives with respect to all
  geometric parameters (CasADi ``point_jacobians``: exact; numpy: central differences,
  two FK evaluations per parameter). Pinocchio has no parameter Jacobian;
* ``fk_joint_jacobian``: the tool pose and its 6 x dof geometric Jacobian (CasADi: one
  function with the outputs of ``tool_pose`` and ``tool_jacobian``; pinocchio
  ``computeFrameJacobian`` (which runs the forward kinematics) + ``updateFramePlacement``,
  LOCAL_WORLD_ALIGNED).

Pinocchio is called from Python in a loop over the 1,000 configurations;
numpy "batched" is vectorised over the configurations. CasADi interpreted batches
use ``Kinematics.mapped`` (``map`` over 2 threads); compiled batches use
``codegen.BatchFunction`` as ``Kinematics.batch`` does (one compiled loop per chunk of
256 configurations, the work that depends on the parameters alone done once per chunk,
results written into numpy arrays). Pinocchio's figures leave the result inside
pinocchio's ``data`` (no copy to numpy), which favours pinocchio. Beside the timings,
the largest disagreement between the methods shows that they compute the same thing.

Run: ``python benchmarks/kinematics.py`` (about a minute on 2 cores).
"""

from __future__ import annotations

import json
import math
import platform
import time

import casadi as ca
import numpy as np
import pinocchio as pin

from robocal_casadi.common import codegen
from robocal_casadi.common.progress import Progress
from robocal_casadi.model import examples
from robocal_casadi.model.kinematics import Kinematics
from robocal_casadi.model.pinocchio_model import pinocchio_model
from robocal_casadi.model.transforms import pose_from_xyz_rpy

BATCH = 1000
REPEATS = 5
OFFSET = np.array([0.01, -0.02, 0.15])  # [m] a probe tip in the flange frame
STEP = 1e-6  # central-difference step [m], [rad]


def per_configuration(run, count: int) -> float:
    """Best of ``REPEATS`` wall times of ``run()``, in microseconds per configuration."""
    run()  # warm up (builds maps, loads libraries)
    best = math.inf
    for _ in range(REPEATS):
        start = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - start)
    return round(best / count * 1e6, 3)


# ------------------------------------------------------------------ plain numpy DH


def numpy_flange_pose(kinematics: Kinematics, Q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """World flange poses (N x 4 x 4) [m], vectorised over configurations."""
    robot, registry = kinematics.robot, kinematics.registry
    N = len(Q)

    def rpy_pose(prefix):
        x, y, z, r, pt, yw = (p[registry.index(f"{prefix}_{k}")] for k in
                              ("x", "y", "z", "rx", "ry", "rz"))
        cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(pt), math.sin(pt), \
            math.cos(yw), math.sin(yw)
        return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr, x],
                         [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr, y],
                         [-sp, cp * sr, cp * cr, z], [0, 0, 0, 1.0]])

    T = np.broadcast_to(rpy_pose("base"), (N, 4, 4))
    for i, joint in enumerate(robot.joints, start=1):
        theta, d, a, alpha, beta = (p[registry.index(f"{s}{i}")] for s in
                                    ("theta", "d", "a", "alpha", "beta"))
        theta = theta + Q[:, i - 1] if joint.revolute else np.full(N, theta)
        d = d + Q[:, i - 1] if not joint.revolute else np.full(N, d)
        ct, st = np.cos(theta), np.sin(theta)
        ca_, sa, cb, sb = math.cos(alpha), math.sin(alpha), math.cos(beta), math.sin(beta)
        L = np.zeros((N, 4, 4))
        L[:, 3, 3] = 1.0
        if robot.convention == "dh":  # Rz(theta) Tz(d) Tx(a) Rx(alpha) Ry(beta)
            L[:, 0, 0] = ct * cb - st * sa * sb
            L[:, 0, 1] = -st * ca_
            L[:, 0, 2] = ct * sb + st * sa * cb
            L[:, 0, 3] = a * ct
            L[:, 1, 0] = st * cb + ct * sa * sb
            L[:, 1, 1] = ct * ca_
            L[:, 1, 2] = st * sb - ct * sa * cb
            L[:, 1, 3] = a * st
            L[:, 2, 0] = -ca_ * sb
            L[:, 2, 1] = sa
            L[:, 2, 2] = ca_ * cb
            L[:, 2, 3] = d
        else:  # Rx(alpha) Tx(a) Rz(theta) Tz(d) Ry(beta)
            L[:, 0, 0] = ct * cb
            L[:, 0, 1] = -st
            L[:, 0, 2] = ct * sb
            L[:, 0, 3] = a
            L[:, 1, 0] = ca_ * st * cb + sa * sb
            L[:, 1, 1] = ca_ * ct
            L[:, 1, 2] = ca_ * st * sb - sa * cb
            L[:, 1, 3] = -sa * d
            L[:, 2, 0] = sa * st * cb - ca_ * sb
            L[:, 2, 1] = sa * ct
            L[:, 2, 2] = sa * st * sb + ca_ * cb
            L[:, 2, 3] = ca_ * d
        T = T @ L
    return T


def numpy_point(kinematics: Kinematics, Q: np.ndarray, p: np.ndarray, offset: np.ndarray):
    """World position (N x 3) [m] of a flange point ``offset`` [m]."""
    T = numpy_flange_pose(kinematics, Q, p)
    return T[:, :3, :3] @ offset + T[:, :3, 3]


def numpy_tool_pose(kinematics: Kinematics, Q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """World tool poses (N x 4 x 4) [m]: the flange poses times the tool transform."""
    registry = kinematics.registry
    T_flange_tool = pose_from_xyz_rpy([p[registry.index(f"tool_{k}")] for k in "xyz"],
                                      [p[registry.index(f"tool_r{k}")] for k in "xyz"])
    return numpy_flange_pose(kinematics, Q, p) @ T_flange_tool


def numpy_parameter_jacobian(kinematics, Q, p, offset) -> np.ndarray:
    """d point / d p (N x 3 x n_p) by central differences, vectorised over configurations."""
    J = np.empty((len(Q), 3, len(p)))
    for k in range(len(p)):
        e = np.zeros(len(p))
        e[k] = STEP
        J[:, :, k] = (numpy_point(kinematics, Q, p + e, offset)
                      - numpy_point(kinematics, Q, p - e, offset)) / (2 * STEP)
    return J


# ------------------------------------------------------------------ one robot


def configurations(robot, count: int, seed: int = 0) -> np.ndarray:
    lower = np.where(np.isfinite(robot.lower_limits), robot.lower_limits, -math.pi)
    upper = np.where(np.isfinite(robot.upper_limits), robot.upper_limits, math.pi)
    return np.random.default_rng(seed).uniform(lower, upper, size=(count, robot.dof))


def bench_robot(name: str, progress: Progress, step: list[int]) -> dict:
    robot = examples.ROBOTS[name]()
    kinematics = Kinematics(robot)
    p = kinematics.nominal
    Q = configurations(robot, BATCH)
    QT = np.ascontiguousarray(Q.T)
    model = pinocchio_model(robot)
    data = model.createData()
    tool = model.getFrameId("tool")

    def tick(note):
        step[0] += 1
        progress.update(step[0], f"{name}: {note}")

    # The pose and the joint Jacobian from one function, as pinocchio gives them together.
    q_symbol, p_symbol = kinematics.tool_pose.sx_in()
    pose_and_jacobian = ca.Function(
        "tool_pose_and_jacobian", [q_symbol, p_symbol],
        [kinematics.tool_pose(q_symbol, p_symbol), kinematics.tool_jacobian(q_symbol, p_symbol)],
        ["q", "p"], ["T_world_tool", "J"])
    interpreted = {f: getattr(kinematics, f) for f in ("tool_pose", "point_jacobians")}
    interpreted["tool_pose_and_jacobian"] = pose_and_jacobian
    start = time.perf_counter()
    compiled = {f: codegen.compiled(function) if f == "tool_pose_and_jacobian"
                else kinematics.compiled(f) for f, function in interpreted.items()}
    batches = {f: codegen.BatchFunction(function) for f, function in interpreted.items()}
    compile_seconds = time.perf_counter() - start
    results: dict = {"dof": robot.dof, "parameters": len(kinematics.registry),
                     "compiled": all(f.is_a("External") for f in compiled.values())
                     and all(b.function.is_a("External") for b in batches.values()),
                     "compile_or_load_s": round(compile_seconds, 3)}

    def casadi_rows(label, function_names, extra_args):
        """Single calls of each function per configuration, and the whole batch at once."""
        functions = interpreted if label == "casadi_interpreted" else compiled
        single = per_configuration(
            lambda: [[functions[f](q, p, *extra_args) for f in function_names] for q in Q], BATCH)
        if label == "casadi_interpreted":
            maps = [kinematics.mapped(functions[f], BATCH) for f in function_names]
            batched = per_configuration(lambda: [m(QT, p, *extra_args) for m in maps], BATCH)
        else:
            chosen = [batches[f] for f in function_names]
            batched = per_configuration(lambda: [b(Q, p, *extra_args) for b in chosen], BATCH)
        return single, batched

    # FK
    fk: dict = {}
    for label in ("casadi_interpreted", "casadi_compiled"):
        fk[f"{label}_single"], fk[f"{label}_batched"] = casadi_rows(label, ["tool_pose"], ())
        tick(f"fk {label}")

    def pinocchio_fk():
        for q in Q:
            pin.forwardKinematics(model, data, q)
            pin.updateFramePlacement(model, data, tool)

    fk["pinocchio_python_loop"] = per_configuration(pinocchio_fk, BATCH)
    fk["numpy_single"] = per_configuration(
        lambda: [numpy_tool_pose(kinematics, q[None], p) for q in Q], BATCH)
    fk["numpy_batched"] = per_configuration(lambda: numpy_tool_pose(kinematics, Q, p), BATCH)
    tick("fk pinocchio, numpy")
    results["fk_us"] = fk

    # FK + parameter Jacobian
    fkp: dict = {}
    for label in ("casadi_interpreted", "casadi_compiled"):
        fkp[f"{label}_single"], fkp[f"{label}_batched"] = casadi_rows(
            label, ["point_jacobians"], (OFFSET,))
        tick(f"parameter jacobian {label}")
    few = Q[:100]
    fkp["numpy_finite_differences_single"] = per_configuration(
        lambda: [(numpy_point(kinematics, q[None], p, OFFSET),
                  numpy_parameter_jacobian(kinematics, q[None], p, OFFSET)) for q in few],
        len(few))
    fkp["numpy_finite_differences_batched"] = per_configuration(
        lambda: (numpy_point(kinematics, Q, p, OFFSET),
                 numpy_parameter_jacobian(kinematics, Q, p, OFFSET)), BATCH)
    tick("parameter jacobian numpy")
    results["fk_parameter_jacobian_us"] = fkp

    # FK + joint Jacobian
    fkq: dict = {}
    for label in ("casadi_interpreted", "casadi_compiled"):
        fkq[f"{label}_single"], fkq[f"{label}_batched"] = casadi_rows(
            label, ["tool_pose_and_jacobian"], ())
        tick(f"joint jacobian {label}")

    def pinocchio_fk_jacobian():
        for q in Q:
            pin.computeFrameJacobian(model, data, q, tool, pin.LOCAL_WORLD_ALIGNED)
            pin.updateFramePlacement(model, data, tool)

    fkq["pinocchio_python_loop"] = per_configuration(pinocchio_fk_jacobian, BATCH)
    tick("joint jacobian pinocchio")
    results["fk_joint_jacobian_us"] = fkq

    # Agreement between the methods on the same configurations.
    casadi_poses, casadi_J = batches["tool_pose_and_jacobian"](Q, p)
    J_p = batches["point_jacobians"](Q, p, OFFSET)[1]
    pinocchio_poses = []
    pinocchio_jacobians = []
    for q in Q:
        pinocchio_jacobians.append(
            pin.computeFrameJacobian(model, data, q, tool, pin.LOCAL_WORLD_ALIGNED).copy())
        pinocchio_poses.append(pin.updateFramePlacement(model, data, tool).homogeneous.copy())

    def largest(difference) -> float:
        return float(np.abs(difference).max())

    results["agreement"] = {
        "tool_pose_casadi_vs_pinocchio_max_abs": largest(casadi_poses - np.array(pinocchio_poses)),
        "tool_pose_casadi_vs_numpy_max_abs": largest(casadi_poses
                                                     - numpy_tool_pose(kinematics, Q, p)),
        "joint_jacobian_casadi_vs_pinocchio_max_abs": largest(
            casadi_J - np.array(pinocchio_jacobians)),
        "parameter_jacobian_casadi_vs_numpy_fd_max_abs": largest(
            J_p - numpy_parameter_jacobian(kinematics, Q, p, OFFSET)),
    }
    return results


def main() -> None:
    names = ["industrial_6r", "panda_7dof"]
    step = [0]
    with Progress("kinematics benchmark", total=9 * len(names)) as progress:
        robots = {name: bench_robot(name, progress, step) for name in names}
    summary = {}
    for name, r in robots.items():
        fk, fkq = r["fk_us"], r["fk_joint_jacobian_us"]
        fkp = r["fk_parameter_jacobian_us"]
        summary[name] = {
            "fk_pinocchio_loop_over_compiled_batched": round(
                fk["pinocchio_python_loop"] / fk["casadi_compiled_batched"], 2),
            "fk_joint_jacobian_pinocchio_loop_over_compiled_batched": round(
                fkq["pinocchio_python_loop"] / fkq["casadi_compiled_batched"], 2),
            "fk_numpy_batched_over_compiled_batched": round(
                fk["numpy_batched"] / fk["casadi_compiled_batched"], 2),
            "fk_parameter_jacobian_numpy_fd_batched_over_compiled_batched": round(
                fkp["numpy_finite_differences_batched"] / fkp["casadi_compiled_batched"], 2),
        }
    print(json.dumps({
        "unit": "microseconds per configuration",
        "batch": BATCH,
        "machine": {"python": platform.python_version(), "casadi": ca.__version__,
                    "pinocchio": pin.__version__, "numpy": np.__version__,
                    "compiler": codegen.compiler()},
        "robots": robots,
        "speedup_factors": summary,
        "speedup_note": "ratio of times: above 1 means the compiled batch is faster",
    }, indent=2))


if __name__ == "__main__":
    main()
