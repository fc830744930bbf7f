"""Continuous refinement of a chosen plan in CasADi (IPOPT).

The joint readings of the chosen candidates become the variables; the objective is
``log`` of the index ``tool`` itself (``log sum 1 / s_i^2`` of ``J L^-T``); for the
condition number ``log sum 1 / s_i^2`` of the plan's columns normalised to unit length
(the smallest singular values weigh most; a smooth stand-in for ``s_max / s_min``);
for the other indices ``-log det`` of the information with the reference column
scales; all after the Schur complement of the shared placement unknowns. The
constraints keep each reading runnable:

* every instrument: joint limits, every joint frame origin and the measured point above
  the worktable, the arm's capsules clear of the table, of each other and of the line of
  sight (``collision.Body.clearance_bound``), each joint within ``STEP`` [rad or m] of
  the chosen candidate (the model is trusted locally only);

and, by the kind's ``Planner.refine`` (``robocal_casadi/instruments/<kind>/planning.py``),
e.g.:

* a tracker: the target faces the instrument (within the visibility cone);
* bars and artifacts: the probe stays on its socket (the placement is kept, the joints
  are re-solved), polished afterwards by inverse kinematics to 1e-9 m
  (``Planner.feasible``);
* a laser on a sphere: the beam still hits the sphere within the incidence limit and the
  sensor's range; the expected reading follows the pose.

The refined plan replaces the chosen one only when it is feasible and improves the
user's index.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from robocal_casadi.errors import InputError
from robocal_casadi.instruments import instrument
from robocal_casadi.instruments.planning import MARGIN

from .best_iterate import BestFeasible
from .candidates import Candidate
from .compare import clearly_greater
from .indices import index_value, scaling, score
from .information import Information
from .reach import Workspace
from .rows import RowModel

STEP = 0.35  # [rad] largest change of a joint during refinement
FEASIBLE = 1e-7  # violation of a usable iterate [m or cosine]: far inside the margins


def refine_plan(setup, workspace: Workspace, row_model: RowModel, info: Information,
                candidates: tuple[Candidate, ...], index: str, max_iterations: int = 100):
    """``(refined candidates, spectrum)`` or None when refinement does not help."""
    mode = scaling(index)
    rows = [info.restrict(b) for b in row_model.blocks(list(candidates))]
    before = index_value(index, info.spectrum_of(rows, mode))
    try:
        Q_new = _solve(setup, workspace, row_model, info, candidates, max_iterations, mode)
    except RuntimeError:
        return None
    if Q_new is None:
        return None
    refined = _rebuild(setup, workspace, candidates, Q_new)
    if refined is None:
        return None
    spectrum = info.spectrum_of([info.restrict(b) for b in row_model.blocks(refined)], mode)
    # better by more than rounding: a refinement that gains nothing must not be kept on
    # one processor and dropped on another
    if not clearly_greater(score(index, index_value(index, spectrum)), score(index, before)):
        return None
    return tuple(refined), spectrum


class _Program:
    """The refinement NLP as it is assembled: variables with bounds and starts,
    constraints with bounds, and the symbolic row blocks of each candidate."""

    def __init__(self) -> None:
        self.variables: list = []
        self.starts: list = []
        self.lower: list = []
        self.upper: list = []
        self.constraints: list = []
        self.c_lower: list = []
        self.c_upper: list = []
        self.blocks: list = []

    def constrain(self, expression, lower, upper) -> None:
        self.constraints.append(expression)
        self.c_lower.append(lower)
        self.c_upper.append(upper)


def _solve(setup, workspace, row_model, info, candidates, max_iterations, mode):
    dof = workspace.kinematics.dof
    program = _Program()
    clearance = None
    if workspace.body is not None:
        q = ca.SX.sym("q", dof)
        clearance = ca.Function("clearance", [q], [workspace.body.clearance_bound(q)])
    for c, candidate in enumerate(candidates):
        Q = _joint_variables(program, workspace, candidate, c)
        _keep_clear(program, workspace, row_model.p, Q, len(candidate.joints), clearance)
        _planner(setup).refine(program, setup, workspace, row_model, candidate, Q)
    objective = _objective(_information(program.blocks, info), info, mode)
    values = _run_ipopt(program, objective, max_iterations)
    out, start = [], 0
    for candidate in candidates:
        size = candidate.joints.size
        out.append(values[start:start + size].reshape(len(candidate.joints), dof))
        start += size
    return out


def _joint_variables(program: _Program, workspace, candidate, c: int):
    """The joint readings of candidate ``c`` as variables, within ``STEP`` of the chosen
    ones and inside the joint limits."""
    Q0 = candidate.joints
    Q = ca.MX.sym(f"Q{c}", workspace.kinematics.dof, len(Q0))
    program.variables.append(ca.vec(Q))
    program.starts.append(Q0.T.ravel(order="F"))
    lo = np.maximum(workspace.lower, -np.inf)
    hi = workspace.upper
    program.lower.append(np.maximum(np.tile(lo, (len(Q0), 1)), Q0 - STEP).T.ravel(order="F"))
    program.upper.append(np.minimum(np.tile(hi, (len(Q0), 1)), Q0 + STEP).T.ravel(order="F"))
    return Q


def _keep_clear(program: _Program, workspace, p, Q, readings: int, clearance) -> None:
    """Every joint frame origin above the worktable; the capsules clear of the table,
    of each other and of the sight line."""
    dof = workspace.kinematics.dof
    for k in range(readings):
        program.constrain(workspace.heights(Q[:, k], p),
                          np.full(dof, workspace.table_height + MARGIN), np.full(dof, np.inf))
        if clearance is not None:
            program.constrain(clearance(Q[:, k]), [MARGIN], [np.inf])


def _information(blocks, info: Information):
    """The plan's information over the kept columns, after the Schur complement of the
    shared placement unknowns (symbolic)."""
    m, shared = info.m, info.shared
    A: Any = 0  # becomes the symbolic sum of the blocks' normal matrices
    for X in blocks:
        Xk = ca.horzcat(*[X[:, int(j)] for j in info.columns])
        A = A + Xk.T @ Xk
    M = A[:m, :m]
    if shared:
        M = M - A[:m, m:] @ ca.solve(A[m:, m:], A[m:, :m])
    return M


def _objective(M, info: Information, mode: str):
    """The smooth objective standing for the user's index (see the module docstring)."""
    m = info.m
    if mode == "tool":
        # the index itself: log sum 1 / s_i^2 of J L^-T (info.tool = L^-1)
        T = ca.DM(info._tool_transform())
        return ca.log(ca.trace(ca.solve(T @ M @ T.T, ca.DM.eye(m))))
    if mode == "design":
        # columns normalised (unit diagonal): the sum of 1 / eigenvalues weighs the
        # smallest ones most, a smooth stand-in for the condition number
        d = ca.sqrt(ca.diag(M))
        return ca.log(ca.trace(ca.solve(M / (d @ d.T), ca.DM.eye(m))))
    d = ca.DM(info.reference)
    return -ca.log(ca.det(M / (d @ d.T)))


def _run_ipopt(program: _Program, objective, max_iterations: int) -> np.ndarray:
    """IPOPT from the chosen plan; the best feasible iterate when it stops early."""
    x = ca.vertcat(*program.variables)
    g = ca.vertcat(*program.constraints)
    lbg = np.concatenate([np.ravel(v) for v in program.c_lower])
    ubg = np.concatenate([np.ravel(v) for v in program.c_upper])
    best = BestFeasible(x.shape[0], g.shape[0], lbg, ubg, FEASIBLE, "refine_best_feasible")
    solver = ca.nlpsol("refine", "ipopt", {"x": x, "f": objective, "g": g},
                       {"print_time": False, "iteration_callback": best,
                        "ipopt": {"print_level": 0, "sb": "yes", "max_iter": max_iterations,
                                  "hessian_approximation": "limited-memory",
                                  "tol": 1e-6, "constr_viol_tol": 1e-9,
                                  "bound_relax_factor": 0.0}})
    x0 = np.concatenate(program.starts)
    result = solver(x0=x0, lbx=np.concatenate(program.lower), ubx=np.concatenate(program.upper),
                    lbg=lbg, ubg=ubg)
    if not solver.stats().get("success") and best.x is not None:
        # stopped at the iteration limit: its last iterate may break a constraint, the
        # best one that met them all is a plan
        result = {"x": best.x}
    return np.asarray(result["x"]).ravel()


def _rebuild(setup, workspace, candidates, Q_new):
    """Feasible candidates at the refined joints (polished), or None when none moved.

    A candidate whose refined joints break a check is tried half-way from its start,
    else kept as it was: one reading the solver left infeasible does not cost the others
    their improvement (the caller keeps the result only if the index improves)."""
    rebuilt, moved = [], False
    for candidate, Q in zip(candidates, Q_new):
        found = None
        for share in (1.0, 0.5):
            found = _feasible(setup, workspace, candidate,
                              candidate.joints + share * (Q - candidate.joints))
            if found is not None:
                break
        moved = moved or found is not None
        rebuilt.append(candidate if found is None else found)
    return rebuilt if moved else None


def _feasible(setup, workspace, candidate, Q):
    """``candidate`` at joints ``Q`` (polished) when it passes every check, else None."""
    Q = np.clip(Q, workspace.lower, workspace.upper)
    checked = _planner(setup).feasible(setup, workspace, candidate, Q)
    if checked is None:
        return None
    candidate, Q, points = checked
    if not (workspace.within_limits(Q).all() and workspace.clear_of_table(Q, points).all()):
        return None
    return Candidate(Q, candidate.points, candidate.sockets, candidate.distance)


def _planner(setup):
    """The planning pieces of ``setup``'s kind."""
    planner = instrument(setup.kind, file=setup.path).planner
    if planner is None:
        raise InputError(f"the planner cannot refine {setup.kind} data", file=setup.path,
                         where="kind")
    return planner
