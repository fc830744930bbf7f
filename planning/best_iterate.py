"""The best feasible iterate of an IPOPT solve.

IPOPT's last iterate need not meet the constraints when it stops at its iteration limit
(an interior-point method reaches feasibility and optimality together). The planners'
starts are feasible, so an iterate that met every constraint and lowered the objective
on the way is worth keeping: ``BestFeasible`` watches every iteration and holds it.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np


class BestFeasible(ca.Callback):
    """IPOPT iteration callback (``nlpsol`` option ``iteration_callback``) that keeps the
    iterate ``x`` of lowest objective among those within ``feasible`` (the solver's
    constraint units) of every bound ``lbg <= g <= ubg``."""

    def __init__(self, nx: int, ng: int, lbg: np.ndarray, ubg: np.ndarray, feasible: float,
                 name: str = "best_feasible"):
        ca.Callback.__init__(self)
        self.nx, self.ng = nx, ng
        self.lbg, self.ubg = np.asarray(lbg, float), np.asarray(ubg, float)
        self.feasible = float(feasible)
        self.reset()
        self.construct(name, {})

    def __repr__(self) -> str:
        held = "none" if self.x is None else f"objective {self.value:.6g}"
        return f"BestFeasible({self.nx} variables, {self.ng} constraints, held: {held})"

    def reset(self) -> None:
        """Forget the held iterate (before a new solve)."""
        self.x: np.ndarray | None = None
        self.value = math.inf

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_name_out(self, i):
        return "ret"

    def get_sparsity_in(self, i):
        name = ca.nlpsol_out(i)
        if name == "f":
            return ca.Sparsity.scalar()
        if name in ("x", "lam_x"):
            return ca.Sparsity.dense(self.nx)
        if name in ("g", "lam_g"):
            return ca.Sparsity.dense(self.ng)
        return ca.Sparsity(0, 0)

    def eval(self, arg):
        x, f, g = (np.asarray(a, float).ravel() for a in arg[:3])
        violation = max(np.max(self.lbg - g, initial=0.0), np.max(g - self.ubg, initial=0.0))
        if violation <= self.feasible and f[0] < self.value:
            self.x, self.value = x.copy(), float(f[0])
        return [0]
