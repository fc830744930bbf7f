"""The tracking NLP of one cycle, built once in CasADi for a robot structure.

Unknowns: the joint readings ``q`` (n) [rad or m]. Parameters of a cycle: the previous
joints ``q_previous`` (n), the goal end pose ``goal`` (12: position [m], then the x, y, z
axes of ``A''``, world frame), the unit worktable normal ``up`` (3, world frame), the
robot's geometric parameter vector ``p`` (``ParameterRegistry`` order, SI) and the joint
weights ``weights`` (n).

    minimise    1/2 sum_i weights_i (q_i - q_previous_i)^2
    subject to  p_world_end(q) - p_goal = 0            (3)  position, i.e. the target at
                                                            (0, 0, Z) in the end frame
                x_goal . z_end(q) = 0,  y_goal . z_end(q) = 0   (2)  z axis on the goal's
                u . x_end(q) = 0                       (1)  level: x axis perpendicular to up
                lower <= q <= upper                         joint limits (and step bound)

with ``u = up - (up . z_goal) z_goal``, the part of ``up`` across the goal's z axis. Where
the z axis is met, ``u . x_end = up . x_end`` (``x_end`` is perpendicular to ``z_end``), so
this is the level condition itself; written with ``u`` it stays well posed when the goal
looks straight along ``up`` (camera looking down at the table): then every turn about z
is level, the row vanishes, and the turn goes to the smallest-move objective. The row
also vanishes (and the level is not counted in the angle error) while the goal's z axis
is within ``DEGENERATE_TILT`` of ``+-up``: there every turn is level to within that tilt.

``z_end = z_goal`` rather than ``-z_goal`` is checked by the angle error, not by the
equations; starting from the previous joints the solver stays on the right side. A 6R
arm meets the six equations in isolated points; the weighted smallest move resolves
the redundancy of a 7-DOF arm.

Two forms of the same problem are built: the NLP ``nlp`` for CasADi's ``nlpsol``
(IPOPT, ``sqpmethod``), and ``step``, one Gauss-Newton SQP step solved in closed form
(``tracking.solver``). ``goal`` evaluates the method's frame chain (``tracking.goal``)
and ``errors`` the constraint errors used to verify every answer.
"""

from __future__ import annotations

import math
from functools import cached_property

import casadi as ca
import numpy as np

from ..common.codegen import compiled
from ..model.kinematics import Kinematics
from ..model.robot import Robot
from .goal import goal_pose

#: [rad] A goal whose z axis is within this angle of the worktable normal has a free turn
#: about it: every turn is level to within this angle (0.06 deg), and requiring an exact
#: level there would swing the last joint by up to a half turn between two cycles whose
#: z axes differ by a hair. Beyond it the x axis is held level exactly.
DEGENERATE_TILT = 1e-3
#: Number of equality constraints: position (3), z axis direction (2), level (1).
CONSTRAINTS = 6
#: Proximal term on the multipliers in the closed-form step: keeps the step defined when
#: the constraints are dependent (z axis parallel to ``up``, singular arm). It pulls the
#: multipliers towards the previous iteration's, so it vanishes at convergence and does
#: not bias the answer.
MULTIPLIER_REGULARISATION = 1e-12


def goal_vector(goal):
    """The 12-vector ``[p, x, y, z]`` of a 4x4 goal pose (numpy or CasADi)."""
    if isinstance(goal, (ca.SX, ca.MX)):
        return ca.vertcat(goal[:3, 3], goal[:3, 0], goal[:3, 1], goal[:3, 2])
    return np.concatenate([goal[:3, 3], goal[:3, 0], goal[:3, 1], goal[:3, 2]])


def constraint_expressions(T_world_end, goal, up):
    """The six equality constraints of ``T_world_end`` against ``goal`` (12-vector) and ``up``.

    Rows: position difference [m] (3), ``x_goal . z_end``, ``y_goal . z_end``,
    ``(up - (up . z_goal) z_goal) . x_end`` (dimensionless).
    """
    p_end, x_end, z_end = T_world_end[:3, 3], T_world_end[:3, 0], T_world_end[:3, 2]
    p_goal, x_goal, y_goal, z_goal = goal[0:3], goal[3:6], goal[6:9], goal[9:12]
    across = up - ca.dot(up, z_goal) * z_goal
    across = ca.if_else(_turn_is_free(up, z_goal), ca.DM.zeros(3), across)
    return ca.vertcat(p_end - p_goal, ca.dot(x_goal, z_end), ca.dot(y_goal, z_end),
                      ca.dot(across, x_end))


def _turn_is_free(up, z_goal):
    """1 where the goal's z axis lies within ``DEGENERATE_TILT`` of ``+-up``: every turn
    about it is level to within that tilt, so the turn is left to the smallest move."""
    return ca.norm_2(ca.cross(up, z_goal)) <= math.sin(DEGENERATE_TILT)


def error_expressions(T_world_end, goal, up):
    """``(position_error [m], angle_error [rad])`` of an end pose against the goal.

    ``angle_error`` is the larger of the angle between the end frame's z axis and the
    goal's (0 to pi: an end frame facing away counts as pi) and the tilt of its x axis
    out of the level plane, ``|asin(up . x_end)|``.
    """
    p_end, x_end, z_end = T_world_end[:3, 3], T_world_end[:3, 0], T_world_end[:3, 2]
    position_error = ca.norm_2(p_end - goal[0:3])
    z_goal = goal[9:12]
    facing = ca.atan2(ca.norm_2(ca.cross(z_end, z_goal)), ca.dot(z_end, z_goal))
    tilt = ca.fabs(ca.asin(ca.fmin(1.0, ca.fmax(-1.0, ca.dot(up, x_end)))))
    tilt = ca.if_else(_turn_is_free(up, z_goal), 0.0, tilt)
    return position_error, ca.fmax(facing, tilt)


class TrackingProblem:
    """The CasADi functions of the tracking NLP for one robot structure (built once).

    The geometry enters through the parameter vector ``p``, so one problem serves the
    nominal and the calibrated robot alike.
    """

    def __init__(self, robot: Robot):
        self.robot = robot
        self.kinematics = Kinematics(robot)
        n = robot.dof
        self.dof = n
        self.parameter_count = len(self.kinematics.registry)
        self._q = ca.SX.sym("q", n)
        self._q_previous = ca.SX.sym("q_previous", n)
        self._goal = ca.SX.sym("goal", 12)
        self._up = ca.SX.sym("up", 3)
        self._p = ca.SX.sym("p", self.parameter_count)
        self._weights = ca.SX.sym("weights", n)
        self._T = self.kinematics.tool_pose(self._q, self._p)
        self._c = constraint_expressions(self._T, self._goal, self._up)

    def __repr__(self) -> str:
        return f"TrackingProblem({self.robot.name!r}, dof={self.dof}, constraints={CONSTRAINTS})"

    @property
    def parameter_layout(self) -> tuple[tuple[str, int], ...]:
        """Blocks of the NLP parameter vector, in order: (name, length)."""
        return (("q_previous", self.dof), ("goal", 12), ("up", 3), ("p", self.parameter_count),
                ("weights", self.dof))

    # ------------------------------------------------------------------ functions

    @cached_property
    def goal(self) -> ca.Function:
        """``(q_capture, observation, p, camera_xyz, standoff, up) -> goal`` (12-vector).

        ``observation = (x, y, z [m], roll, pitch, yaw [rad])``; ``camera_xyz`` [m] in the
        end frame; ``standoff`` [m]; ``up`` unit, world frame.
        """
        q = ca.SX.sym("q_capture", self.dof)
        observation = ca.SX.sym("observation", 6)
        camera = ca.SX.sym("camera_xyz", 3)
        standoff = ca.SX.sym("standoff")
        up = ca.SX.sym("up", 3)
        T_world_end = self.kinematics.tool_pose(q, self._p)
        goal = goal_pose(T_world_end, camera, observation, standoff, up)
        return ca.Function("tracking_goal", [q, observation, self._p, camera, standoff, up],
                           [goal_vector(goal)],
                           ["q_capture", "observation", "p", "camera_xyz", "standoff", "up"],
                           ["goal"])

    @cached_property
    def errors(self) -> ca.Function:
        """``(q, goal, up, p) -> (position_error [m], angle_error [rad], c)``."""
        position_error, angle_error = error_expressions(self._T, self._goal, self._up)
        return ca.Function("tracking_errors", [self._q, self._goal, self._up, self._p],
                           [position_error, angle_error, self._c],
                           ["q", "goal", "up", "p"], ["position_error", "angle_error", "c"])

    @cached_property
    def step(self) -> ca.Function:
        """One Gauss-Newton SQP step with some joints held, in closed form.

        ``(q, q_previous, goal, up, p, weights, free, multipliers_previous) -> (dq,
        multipliers, multiplier_test, position_error, angle_error)``. ``free`` is 1 for a
        joint that may move and 0 for one held at a bound. With ``W = diag(weights)``,
        ``g = W (q - q_previous)``, ``J = dc/dq`` and ``M = diag(free / weights)``, the
        equality QP ``min 1/2 dq' W dq + g' dq  s.t.  J dq = -c, dq_held = 0`` has

            (J M J' + eps I) lambda = c - J M g + eps lambda_previous,
            dq = -M (g + J' lambda)

        and ``multiplier_test = W (q + dq - q_previous) + J' lambda``, whose entries on
        held joints are the bound multipliers (positive: the lower bound is pushing,
        negative: the upper bound is). The errors are those of ``q`` itself.
        """
        free = ca.SX.sym("free", self.dof)
        J = ca.jacobian(self._c, self._q)
        g = self._weights * (self._q - self._q_previous)
        M = ca.diag(free / self._weights)
        S = J @ M @ J.T + MULTIPLIER_REGULARISATION * ca.SX.eye(CONSTRAINTS)
        multipliers_previous = ca.SX.sym("multipliers_previous", CONSTRAINTS)
        multipliers = ca.solve(S, self._c - J @ M @ g
                               + MULTIPLIER_REGULARISATION * multipliers_previous)
        dq = -M @ (g + J.T @ multipliers)
        test = self._weights * (self._q + dq - self._q_previous) + J.T @ multipliers
        position_error, angle_error = error_expressions(self._T, self._goal, self._up)
        return ca.Function(
            "tracking_step",
            [self._q, self._q_previous, self._goal, self._up, self._p, self._weights, free,
             multipliers_previous],
            [dq, multipliers, test, position_error, angle_error],
            ["q", "q_previous", "goal", "up", "p", "weights", "free", "multipliers_previous"],
            ["dq", "multipliers", "multiplier_test", "position_error", "angle_error"],
        )

    @cached_property
    def compiled_step(self) -> ca.Function:
        """``step`` as machine code (``codegen.compiled``; ``step`` itself without a
        compiler)."""
        return compiled(self.step)

    @cached_property
    def compiled_goal(self) -> ca.Function:
        """``goal`` as machine code (``codegen.compiled``; ``goal`` itself without a
        compiler)."""
        return compiled(self.goal)

    @cached_property
    def nlp(self) -> dict:
        """The NLP for ``casadi.nlpsol``: ``x = q``, ``p`` per ``parameter_layout``."""
        objective = 0.5 * ca.dot(self._weights, (self._q - self._q_previous) ** 2)
        parameters = ca.vertcat(self._q_previous, self._goal, self._up, self._p, self._weights)
        return {"x": self._q, "p": parameters, "f": objective, "g": self._c}
