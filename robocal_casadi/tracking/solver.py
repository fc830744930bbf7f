"""Solvers of the per-cycle tracking NLP (``tracking.problem``).

``GaussNewtonSolver`` is the real-time one: Gauss-Newton SQP steps solved in closed
form by one compiled CasADi function (``TrackingProblem.step``, called through CasADi's
buffer interface so no conversion happens per call), joint bounds by a primal active
set: a joint that a step would push out of its bounds is held at the bound, and let go
again when its bound multiplier changes sign. ``NlpsolSolver`` hands the same NLP to
``casadi.nlpsol`` (IPOPT, ``sqpmethod`` with qrqp or qpOASES) as the reference.

Both return a ``SolveOutcome``; whether the answer is used is decided by the tracker,
which verifies the constraint errors itself.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .problem import TrackingProblem

#: The solver's own stopping tolerance on the constraint errors [m] and [rad].
CONVERGENCE_TOLERANCE = 1e-12
#: A step shorter than this [rad or m] means the weighted smallest move is reached.
STATIONARY_STEP = 1e-9
#: Longest Newton step per iteration [rad or m]; longer ones are shortened.
LONGEST_STEP = 0.4
#: Iterations after which the errors must have fallen by ``STALL_FACTOR`` or the solver
#: concludes the target cannot be met from here (a least-squares point, not a solution).
STALL_WINDOW = 6
STALL_FACTOR = 0.5


@dataclass(frozen=True)
class SolveOutcome:
    """What a solver returns for one cycle.

    ``q`` (n) [rad or m] the last iterate; ``converged`` the constraints met to the
    solver's tolerance; ``infeasible`` evidence that no solution exists within the bounds
    near the previous joints (the errors stopped falling, or the NLP solver said so);
    ``iterations``; ``position_error`` [m] and ``angle_error`` [rad] of ``q``;
    ``message`` the solver's own word.
    """

    q: np.ndarray
    converged: bool
    infeasible: bool
    iterations: int
    position_error: float
    angle_error: float
    message: str = ""

    def __repr__(self) -> str:
        return (f"SolveOutcome(converged={self.converged}, infeasible={self.infeasible}, "
                f"iterations={self.iterations}, position_error={self.position_error:.3g} m, "
                f"angle_error={self.angle_error:.3g} rad, message={self.message!r})")


class GaussNewtonSolver:
    """Closed-form Gauss-Newton SQP with an active set on the joint bounds.

    Built once per (problem, robot parameters ``p``, ``up``, ``weights``); ``solve`` then
    allocates nothing in CasADi. ``compiled`` uses the step function as machine code
    (``codegen.compiled``: generated C, compiled once and cached on disk; the
    interpreted function where no C compiler is found). Each iteration: one evaluation
    of the step function at the current joints, the step shortened to ``LONGEST_STEP``,
    joints leaving their bounds clipped and held, held joints with a wrong-signed
    multiplier let go. The multipliers of one iteration are the proximal centre of the
    next (``TrackingProblem.step``).
    """

    def __init__(self, problem: TrackingProblem, p: np.ndarray, up: np.ndarray,
                 weights: np.ndarray, *, max_iterations: int = 40, compiled: bool = True):
        n = problem.dof
        self.problem = problem
        self.max_iterations = max_iterations
        self._q = np.zeros(n)
        self._q_previous = np.zeros(n)
        self._goal = np.zeros(12)
        self._up = np.array(up, dtype=float)
        self._p = np.array(p, dtype=float)
        self._weights = np.array(weights, dtype=float)
        self._free = np.ones(n)
        self._multipliers_previous = np.zeros(6)
        self._dq = np.zeros(n)
        self._multipliers = np.zeros(6)
        self._test = np.zeros(n)
        self._position_error = np.zeros(1)
        self._angle_error = np.zeros(1)
        # Keep the function alive with its buffer; arrays are bound once, filled per call.
        self.compiled = compiled
        self._function = problem.compiled_step if compiled else problem.step
        self._buffer, self._evaluate = self._function.buffer()
        bind_buffer(self._buffer,
                    (self._q, self._q_previous, self._goal, self._up, self._p, self._weights,
                     self._free, self._multipliers_previous),
                    (self._dq, self._multipliers, self._test, self._position_error,
                     self._angle_error))

    def __repr__(self) -> str:
        return (f"GaussNewtonSolver({self.problem.robot.name!r}, "
                f"max_iterations={self.max_iterations}, compiled={self.compiled})")

    # long: one real-time loop over arrays bound to the step function once; its active
    # set, history and errors would only be passed to and fro by a split, every cycle.
    def solve(self, previous: np.ndarray, goal: np.ndarray, lower: np.ndarray,
              upper: np.ndarray, start: np.ndarray | None = None) -> SolveOutcome:
        """Joints meeting ``goal`` (12-vector) closest to ``previous``, within bounds.

        The iterations start from ``start`` (default ``previous``), clipped to the bounds.
        """
        q, free, dq, test = self._q, self._free, self._dq, self._test
        self._q_previous[:] = previous
        self._goal[:] = goal
        np.maximum(previous if start is None else start, lower, out=q)
        np.minimum(q, upper, out=q)
        free.fill(1.0)
        holding = False
        self._multipliers_previous.fill(0.0)
        history: list[float] = []
        message = "iteration limit"
        converged = infeasible = False
        iteration = 0
        position_error = angle_error = math.nan
        while iteration < self.max_iterations:
            iteration += 1
            self._evaluate()
            self._multipliers_previous[:] = self._multipliers
            position_error = float(self._position_error[0])
            angle_error = float(self._angle_error[0])
            longest = float(np.abs(dq).max())
            if not (math.isfinite(position_error) and math.isfinite(angle_error)
                    and math.isfinite(longest)):
                message = "non-finite values"
                break
            if holding:
                release = (free == 0.0) & (((q <= lower) & (test < 0.0))
                                           | ((q >= upper) & (test > 0.0)))
                if release.any():
                    free[release] = 1.0
                    holding = bool((free == 0.0).any())
                    continue
            met = position_error < CONVERGENCE_TOLERANCE and angle_error < CONVERGENCE_TOLERANCE
            if met and longest < STATIONARY_STEP:
                converged, message = True, "converged"
                break
            error = position_error + angle_error
            history.append(error)
            if (not met and len(history) > STALL_WINDOW
                    and error > STALL_FACTOR * history[-1 - STALL_WINDOW]):
                infeasible, message = True, "errors stopped falling: no solution near here"
                break
            if longest > LONGEST_STEP:
                dq *= LONGEST_STEP / longest
            q += dq
            outside = (q < lower) | (q > upper)
            if outside.any():
                np.maximum(q, lower, out=q)
                np.minimum(q, upper, out=q)
                free[outside] = 0.0
                holding = True
        else:
            # Out of iterations: the errors at hand are those before the last step;
            # evaluate once more so the outcome describes ``q`` itself.
            self._evaluate()
            position_error = float(self._position_error[0])
            angle_error = float(self._angle_error[0])
            converged = (position_error < CONVERGENCE_TOLERANCE
                         and angle_error < CONVERGENCE_TOLERANCE)
        return SolveOutcome(q.copy(), converged, infeasible, iteration, position_error,
                            angle_error, message)


def bind_buffer(buffer: ca.FunctionBuffer, inputs: Sequence[np.ndarray],
                outputs: Sequence[np.ndarray]) -> None:
    """Bind float arrays to the inputs and outputs of a CasADi ``FunctionBuffer``.

    The buffer reads and writes the arrays in place: fill the inputs, evaluate, read the
    outputs, with no copy per call. The arrays must stay alive as long as the buffer.
    """
    # casadi's stubs ask for a byte size that its binding takes from the buffer itself, and
    # numpy's stubs do not declare ndarray a buffer: both calls are right as written.
    for k, array in enumerate(inputs):
        buffer.set_arg(k, memoryview(array))  # type: ignore[call-arg, arg-type]
    for k, array in enumerate(outputs):
        buffer.set_res(k, memoryview(array))  # type: ignore[call-arg, arg-type]


#: Options that silence CasADi's NLP solvers, by plugin.
QUIET: dict[str, dict[str, Any]] = {
    "ipopt": {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
              "ipopt.tol": 1e-12, "ipopt.constr_viol_tol": 1e-12,
              "ipopt.warm_start_init_point": "yes"},
    "sqpmethod": {"print_header": False, "print_iteration": False, "print_status": False,
                  "print_time": False, "tol_pr": 1e-12, "tol_du": 1e-10, "max_iter": 50},
}
QPSOL_QUIET = {
    "qrqp": {"print_iter": False, "print_header": False, "print_info": False,
             "error_on_fail": False},
    "qpoases": {"printLevel": "none", "error_on_fail": False},
}
INFEASIBLE_STATUSES = {"Infeasible_Problem_Detected", "Restoration_Failed",
                       "Search_Direction_Becomes_Too_Small"}


class NlpsolSolver:
    """The same NLP through ``casadi.nlpsol`` (``plugin`` 'ipopt' or 'sqpmethod').

    For ``sqpmethod``, ``qpsol`` names the QP solver ('qrqp' or 'qpoases'). Built once;
    each ``solve`` warm-starts from the previous joints and multipliers.
    """

    def __init__(self, problem: TrackingProblem, p: np.ndarray, up: np.ndarray,
                 weights: np.ndarray, *, plugin: str = "ipopt", qpsol: str = "qrqp"):
        self.problem = problem
        self.plugin = plugin
        self.qpsol = qpsol if plugin == "sqpmethod" else None
        options = dict(QUIET[plugin])
        if plugin == "sqpmethod":
            options.update(qpsol=qpsol, qpsol_options=QPSOL_QUIET[qpsol], error_on_fail=False)
        self._solver = ca.nlpsol(f"tracking_{plugin}", plugin, problem.nlp, options)
        self._p = np.array(p, dtype=float)
        self._up = np.array(up, dtype=float)
        self._weights = np.array(weights, dtype=float)
        self._lam_g = np.zeros(6)

    def __repr__(self) -> str:
        suffix = f", qpsol={self.qpsol!r}" if self.qpsol else ""
        return f"NlpsolSolver({self.problem.robot.name!r}, plugin={self.plugin!r}{suffix})"

    def solve(self, previous: np.ndarray, goal: np.ndarray, lower: np.ndarray,
              upper: np.ndarray, start: np.ndarray | None = None) -> SolveOutcome:
        """As ``GaussNewtonSolver.solve``."""
        parameters = np.concatenate([previous, goal, self._up, self._p, self._weights])
        x0 = previous if start is None else start
        result = self._solver(x0=np.clip(x0, lower, upper), p=parameters, lbx=lower,
                              ubx=upper, lbg=0.0, ubg=0.0, lam_g0=self._lam_g)
        stats = self._solver.stats()
        q = np.asarray(result["x"], dtype=float).ravel()
        position_error, angle_error, _ = self.problem.errors(q, goal, self._up, self._p)
        position_error, angle_error = float(position_error), float(angle_error)
        status = str(stats.get("return_status", ""))
        if stats.get("success", False):
            self._lam_g = np.asarray(result["lam_g"], dtype=float).ravel()
        met = position_error < 1e-9 and angle_error < 1e-9
        return SolveOutcome(q, bool(stats.get("success", False)) and met,
                            status in INFEASIBLE_STATUSES, int(stats.get("iter_count", 0)),
                            position_error, angle_error, status)
