"""Laser scans of the sphere as an optimal control problem (CasADi, IPOPT).

A point laser samples at ``laser_rate`` [Hz] while the robot moves, so a scan is a joint
trajectory, not a set of poses. The trajectory is a clamped cubic B-spline ``q(t) = sum
B_k(t) C_k`` over ``[0, T]``, ``T = (count - 1) / laser_rate`` [s], with
``KNOTS_PER_SECOND`` control points per second; the control points ``C`` (K x dof) are
the unknowns. Sampled at the laser's instants ``t_i``:

* constraints: joint limits (on ``C``: a B-spline stays in its control points' hull), joint
  speed and acceleration within ``max_joint_speed``, ``max_joint_acceleration`` (on the
  derivative's control points, so everywhere, not only at samples), at rest at both
  ends; at every instant the beam meets the sphere within the incidence limit
  (``sqrt(disc) >= R cos(max_incidence)``: ``sqrt(disc) / R`` is the cosine of the
  angle between the beam and the surface normal) and the reading lies within
  ``laser_range``, both a margin inside; the arm's capsules clear of the table and of
  each other (``collision.Body.clearance_bound``);
* objective: the chosen index of the sampled readings' information (rows as in
  ``rows``, the sphere centre projected out), as a logarithm: ``log`` of ``tool`` squared
  (``sum 1 / s_i^2`` of ``J L^-T``, the route of ``information``), ``-log det`` of the
  reference-scaled information for the others.

The information and the clearance are posed at a grid of instants (``SAMPLES_PER_SPAN``
per knot span, each a variable tied to the spline by a linear equality, so every
nonlinear constraint depends on one instant and its Jacobian is cheap); the beam's
conditions at every instant. Afterwards every instant is checked; instants that break a
constraint join the grid and the solve is repeated (``REPAIRS``).

Unknowns: sensor only (pendant poses: the robot is taken as exact) the 8 of the laser
and sphere (origin 3, beam 2, centre 3); robot plus laser the robot parameters the pool
of feasible poses identifies, the laser's 5 and the centre.

Start: a sweep of the beam over a cap of the sphere around the most informative of a few
feasible laser poses (hit normal, beam direction and stand-off interpolated between
waypoints, inverse kinematics for all instants at once), fitted by the spline under the
beam and motion constraints, so the solver starts feasible. IPOPT stops at
``max_iterations``; the best iterate that met every constraint is kept. After the solve
every sample is checked again (limits, beam, capsules of ``collision``, speed); a scan
that fails is refused.
"""

from __future__ import annotations

import io
import math
import time
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np
from scipy import sparse
from scipy.interpolate import BSpline

from robocal_casadi.common import exact
from robocal_casadi.common.progress import Progress
from robocal_casadi.errors import ArgumentError, InputError
from robocal_casadi.instruments import instrument
from robocal_casadi.instruments.datasets import Dataset
from robocal_casadi.model.kinematics import Kinematics

from .accuracy import tool_error, tool_weights
from .best_iterate import BestFeasible
from .candidates import generate
from .collision import Body
from .compare import clearly_greater
from .indices import DEFAULT_INDEX, DESCRIPTIONS, canonical, index_value, scaling
from .information import Information
from .rows import Block, RowModel
from .runnable import runnable_setup
from .setup import PlanSetup, setup_from_dataset

DEGREE = 3
POOL = 150  # feasible laser poses the waypoints are chosen from
MARGIN = 1e-3  # [m] kept between the capsules and the table and each other
SPEED_SHARE = 0.6  # of the speed limit the start path may use (the rest for acceleration)
LASER_NAMES = ("laser_x", "laser_y", "laser_z", "laser_n1", "laser_n2")
MIN_SAMPLES = 20
ANGLE_MARGIN = np.radians(1.0)  # [rad] kept inside the incidence limit by the solver
RANGE_MARGIN = 0.01  # share of the laser's range kept inside its ends by the solver
CENTRES = 4  # pool poses tried as the centre of the start sweep
SINGULAR = 1e-10  # relative singular value below which a start path identifies nothing there
LOG_DET_EQUAL = 1e-8  # start sweeps' log det values closer than this count as equal
WAYPOINTS = 12  # poses of the start sweep (fewer when the joint speed does not allow)
CAP = np.radians(35.0)  # [rad] hit normals of the start sweep, from the centre's
KNOTS_PER_SECOND = 4.0  # spline control points per second of scan (plus 6)
SAMPLES_PER_SPAN = 3  # laser instants per knot span posed in the OCP
REPAIRS = 2  # re-solves with the instants that broke a constraint added
FIT_ITERATIONS = 100  # of the start's fit
FEASIBLE = 1e-4  # violation of a usable iterate, solver units: well inside the margins
CLEARANCE_UNIT = 0.1  # [m] the clearance constraint's unit in the solver
IPOPT: dict[str, float | str] = {
    "print_level": 0, "sb": "yes", "hessian_approximation": "limited-memory",
    "tol": 1e-4, "constr_viol_tol": 1e-7, "acceptable_tol": 1e-2,
    "acceptable_iter": 4, "acceptable_obj_change_tol": 1e-3,
    "acceptable_constr_viol_tol": 1e-7,
    # the start is feasible: keep IPOPT from pushing it far into the interior
    "bound_push": 1e-6, "bound_frac": 1e-6, "slack_bound_push": 1e-6,
    "slack_bound_frac": 1e-6}


@dataclass(frozen=True)
class Scan:
    """A planned scan: samples at the laser's instants.

    ``times`` (N,) [s]; ``joints`` (N x dof) [rad or m]; ``flange_poses`` (N x 4 x 4) [m],
    base frame; ``readings`` (N,) [m] what the laser reads on the nominal sphere;
    ``index``, ``value`` the index of the scan and ``start_value`` of the start path;
    ``tool_error`` [m] the predicted standard error (``accuracy``; sensor only: of the
    laser spot at mid-range in the flange frame); ``laser_errors`` (5,) [m, m, m, rad,
    rad] predicted standard errors of the laser origin and beam direction;
    ``identifiable`` the parameters; ``seconds`` the solve time.
    """

    setup: PlanSetup
    times: np.ndarray
    joints: np.ndarray
    flange_poses: np.ndarray
    readings: np.ndarray
    index: str
    value: float
    start_value: float
    tool_error: float
    laser_errors: np.ndarray
    identifiable: tuple[str, ...]
    seconds: float
    solver_status: str
    waypoints: int

    @property
    def sensor_only(self) -> bool:
        return self.setup.sensor_only

    def __repr__(self) -> str:
        return (f"Scan({len(self.times)} samples over {self.times[-1]:.3g} s, {self.index} = "
                f"{self.value:.6g} (start {self.start_value:.6g}), "
                f"{'sensor only' if self.sensor_only else 'robot and laser'})")

    def summary(self) -> str:
        speeds = np.abs(np.diff(self.joints, axis=0)) * self.setup.laser_rate
        return (f"planned a scan of {len(self.times)} readings over {self.times[-1]:.3g} s at "
                f"{self.setup.laser_rate:g} Hz for {len(self.identifiable)} identifiable "
                f"parameters ({'laser and sphere only' if self.sensor_only else 'robot and laser'}"
                f"), through {self.waypoints} start poses, solved in {self.seconds:.3g} s "
                f"({self.solver_status})\n"
                f"{self.index} ({DESCRIPTIONS[self.index]}): scan {self.value:.6g}, start path "
                f"{self.start_value:.6g}\n"
                f"predicted {'laser spot' if self.sensor_only else 'tool-position'} error at "
                f"{1e3 * self.setup.noise:.3g} mm reading noise: {1e3 * self.tool_error:.4g} mm;"
                f" laser origin +-{1e3 * np.max(self.laser_errors[:3]):.3g} mm, beam "
                f"+-{1e3 * np.max(self.laser_errors[3:]):.3g} mrad\n"
                f"readings {1e3 * self.readings.min():.4g}-{1e3 * self.readings.max():.4g} mm; "
                f"fastest joint {np.degrees(speeds.max()):.3g} deg/s")


# ---------------------------------------------------------------------------- splines


def spline_basis(times: np.ndarray, count: int, duration: float):
    """Clamped uniform cubic B-spline over ``[0, duration]`` with ``count`` control points:
    ``(B, knots)``, ``B`` (len(times) x count) the basis at ``times`` [s]."""
    inner = np.linspace(0.0, duration, count - DEGREE + 1)
    knots = np.concatenate([[0.0] * DEGREE, inner, [duration] * DEGREE])
    B = BSpline.design_matrix(np.clip(times, 0, duration), knots, DEGREE).toarray()
    return B, knots


def derivative_map(knots: np.ndarray, count: int, degree: int) -> np.ndarray:
    """``D`` ((count - 1) x count): control points of the derivative of a degree-``degree``
    B-spline are ``D @ C`` (per second)."""
    D = np.zeros((count - 1, count))
    for i in range(count - 1):
        span = knots[i + degree + 1] - knots[i + 1]
        if span > 0:
            D[i, i], D[i, i + 1] = -degree / span, degree / span
    return D


# ---------------------------------------------------------------------------- rows


class ScanRows:
    """Per-sample information rows and constraint values of a laser at joint readings."""

    def __init__(self, setup: PlanSetup, kinematics: Kinematics, row_model: RowModel,
                 columns: np.ndarray, body: Body):
        kin = kinematics
        p = kin.nominal
        q = ca.SX.sym("q", kin.dof)
        T = kin.flange_pose(q, p)
        axis = setup.axis / exact.norm(setup.axis)
        o = T[:3, :3] @ setup.offset + T[:3, 3]
        d = T[:3, :3] @ axis
        if setup.centre is None:
            raise ValueError("a laser scan's set-up needs the sphere's centre")
        v = o - setup.centre
        b = ca.dot(d, v)
        disc = b**2 - (ca.dot(v, v) - setup.radius**2)
        reading = -b - ca.sqrt(ca.fmax(disc, 1e-12))
        G, S = row_model.row_jacobians(q, reading)
        row = ca.horzcat(G, S)
        g = ca.vertcat(*[row[0, int(j)] for j in columns])
        clearance = body.clearance_bound(q)
        self.function = ca.Function("scan_row", [q], [g, disc, reading, clearance])
        self.rows = ca.Function("scan_information", [q], [g])
        self.beam = ca.Function("scan_beam", [q], [disc, reading])
        self.clearance = ca.Function("scan_clearance", [q], [clearance])
        self.size = len(columns)

    def evaluate(self, Q: np.ndarray):
        """``(rows N x size, disc [m^2], readings [m], clearance [m])`` at joint readings
        ``Q`` (N x dof); ``clearance`` a smooth lower bound of the capsules' gaps to the
        table and to each other (``collision.Body.clearances``)."""
        f = self.function.map(len(Q))
        g, disc, reading, clearance = f(np.asarray(Q, float).T)
        return (np.asarray(g).T, np.asarray(disc).ravel(), np.asarray(reading).ravel(),
                np.asarray(clearance).ravel())


# ---------------------------------------------------------------------------- design


def design_scan(dataset: Dataset, count: int, index: str = DEFAULT_INDEX, *, seed: int = 0,
                sensor_only: bool | None = None, max_iterations: int = 100,
                quiet: bool = False) -> Scan:
    """A scan of ``count`` readings for ``dataset``'s sphere and laser (see the module
    docstring); ``sensor_only`` overrides what the dataset says (pendant poses or not)."""
    index = canonical(index)
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise ArgumentError(f"expected a whole number >= 1, got {count!r}", argument="count")
    setup = setup_from_dataset(dataset)
    planner = instrument(setup.kind).planner
    if planner is None or not planner.scans:
        raise InputError(f"scans are planned for laser data, not {setup.kind}",
                         file=setup.path, where="kind")
    if count < MIN_SAMPLES:
        raise InputError(f"--count {count} is too few readings for a scan; ask for at least "
                         f"{MIN_SAMPLES}", file=setup.path)
    setup = replace(setup,
                    sensor_only=setup.sensor_only if sensor_only is None else sensor_only)
    setup, kinematics, workspace = runnable_setup(setup)
    setup = replace(setup, table_height=workspace.table_height)
    # the pool, the tool weights' workspace samples and the start's centres draw from
    # streams of their own: how many draws one took does not move the others'
    draws, samples, rng = (np.random.default_rng(s)
                           for s in np.random.SeedSequence(seed).spawn(3))
    stream = io.StringIO() if quiet else None
    with Progress("plan: laser poses", total=POOL, stream=stream) as progress:
        pool = generate(setup, workspace, POOL, draws, progress)
    row_model = RowModel(setup, kinematics)
    info, columns = _information(setup, workspace, row_model, pool, samples)
    duration = (count - 1) / setup.laser_rate
    times = np.arange(count) / setup.laser_rate
    rows = ScanRows(setup, kinematics, row_model, columns, workspace.body)
    start_path, waypoints = _start_path(setup, workspace, rows, info, pool, times, rng)
    started = time.perf_counter()
    with Progress("plan: scan", total=None, stream=stream):
        Q, status = _solve(setup, workspace, rows, info, index, times, duration, start_path,
                           max_iterations)
    seconds = time.perf_counter() - started
    start_value = _index_of(info, index, rows.evaluate(start_path)[0], SINGULAR)
    problems = _problems(setup, workspace, rows, Q, times)
    if problems:
        problems_start = _problems(setup, workspace, rows, start_path, times)
        if problems_start:
            raise InputError(f"no runnable scan of {count} readings found (the optimised scan: "
                             f"{problems}; the start path: {problems_start}); try another "
                             f"--seed or other laser_rate, max_joint_speed", file=setup.path)
        Q, status = start_path, f"start path kept: {problems}"
    g, disc, readings, _ = rows.evaluate(Q)
    value = _index_of(info, index, g)
    if not math.isfinite(value):
        raise InputError(f"a scan of {count} readings does not identify all "
                         f"{info.m} parameters; ask for more (--count)", file=setup.path)
    predicted = tool_error(info.spectrum_of([g], "tool"), setup.noise)
    laser = _laser_errors(info, g, setup.noise)
    poses = kinematics.flange_poses(Q)
    return Scan(setup, times, Q, poses, readings, index, value, start_value, predicted, laser,
                info.identifiable_names, seconds, status, waypoints)


def _information(setup, workspace, row_model, pool, rng):
    """Information of the pool over the scan's unknowns, and the row-model columns used."""
    blocks = row_model.blocks(pool)
    n_p = len(row_model.parameters)
    weights = tool_weights(setup, workspace, row_model.parameters, rng,
                           rigid_motion=setup.sensor_only)
    if not setup.sensor_only:
        info = Information(blocks, row_model.parameters, row_model.shared, weights)
        return info, info.columns
    laser = np.arange(n_p - len(LASER_NAMES), n_p)
    keep = np.concatenate([laser, np.arange(n_p, n_p + row_model.shared)])
    sensor_blocks = [Block(b.X[:, keep]) for b in blocks]
    info = Information(sensor_blocks, LASER_NAMES, row_model.shared,
                       weights[np.ix_(laser, laser)])
    return info, keep[info.columns]


def _index_of(info, index, g, singular: float = 0.0) -> float:
    """Index ``index`` of rows ``g``; singular values at most ``singular`` times the
    largest count as zero (the index's worst value): below that they are rounding, and
    the number they would give differs from one processor to the next."""
    s = info.spectrum_of([g], scaling(index))
    return index_value(index, np.where(s <= singular * s.max(), 0.0, s))


def _laser_errors(info, g, noise) -> np.ndarray:
    """Predicted standard errors of the laser's 5 values from rows ``g`` [m, rad]."""
    X = g
    m = info.m
    M = X.T @ X
    S = M[:m, :m] - M[:m, m:] @ np.linalg.solve(M[m:, m:], M[m:, :m]) if info.shared else M
    try:
        C = noise**2 * np.linalg.inv(S)
    except np.linalg.LinAlgError:
        return np.full(5, np.inf)
    names = info.identifiable_names
    out = []
    for k, name in enumerate(LASER_NAMES):
        if name in names:
            j = names.index(name)
            scale = 1.0
            if k >= 3:  # a tangent unit moves the beam by 1 rad
                scale = 1.0
            out.append(scale * math.sqrt(max(C[j, j], 0.0)))
        else:
            out.append(math.nan)
    return np.array(out)


# ---------------------------------------------------------------------------- start path


def _start_path(setup, workspace, rows, info, pool, times, rng):
    """A continuous feasible joint path at ``times``: a sweep of the beam over a cap of the
    sphere around the best of a few pool poses, as far as the joint speed allows."""
    duration = times[-1]
    budget = SPEED_SHARE * setup.max_joint_speed * duration
    best = None
    for centre in rng.choice(len(pool), size=min(CENTRES, len(pool)), replace=False):
        Q = _local_waypoints(setup, workspace, pool[centre].joints[0], budget)
        if len(Q) < 2:
            continue
        g = rows.evaluate(Q)[0]
        A = exact.gram(g)
        ridge = 1e-9 * np.trace(A) / len(A) * np.eye(len(A))
        score = np.linalg.slogdet(A + ridge)[1]
        # sweeps whose log det agree within rounding: the first is kept
        if best is None or clearly_greater(score, best[0], 0.0, LOG_DET_EQUAL):
            best = (score, Q)
    if best is None:
        raise InputError("no sweep of the beam over the sphere is reachable from the planned "
                         "laser poses", file=setup.path, where="sphere.centre_guess")
    Q = best[1]
    moves = np.maximum(np.max(np.abs(np.diff(Q, axis=0)), axis=1), 1e-6)
    shares = np.concatenate([[0.0], np.cumsum(moves)])
    shares /= shares[-1]
    phase = times / duration
    segment = np.minimum(np.searchsorted(shares, phase, side="right") - 1, len(Q) - 2)
    s = (phase - shares[segment]) / (shares[segment + 1] - shares[segment])
    s = 0.5 - 0.5 * np.cos(np.pi * np.clip(s, 0, 1))  # at rest at every waypoint
    return _slide(setup, workspace, Q, segment, s), len(Q)


def _local_waypoints(setup, workspace, q0, budget):
    """Poses around ``q0`` whose beams circle over the sphere: hit normals on a cone of
    ``CAP`` about ``q0``'s, beams tilted alternately to 70% of the incidence limit,
    stand-offs alternately near both ends of the range; each solved from the previous,
    kept while the total largest joint move stays within ``budget`` [rad]."""
    d0, n0, _ = _beam(setup, workspace, q0)
    helper = np.array([1.0, 0, 0]) if abs(n0[0]) < 0.9 else np.array([0, 1.0, 0])
    u = exact.cross(n0, helper)
    u /= exact.norm(u)
    v = exact.cross(n0, u)
    lo, hi = setup.laser_range
    tilt = 0.7 * setup.max_incidence
    out = [q0]
    travel = 0.0
    for k in range(WAYPOINTS):
        phi = 2 * np.pi * k / WAYPOINTS
        side = np.cos(phi) * u + np.sin(phi) * v
        normal = np.cos(CAP) * n0 + np.sin(CAP) * side
        across = exact.cross(normal, side)
        across /= exact.norm(across)
        lean = tilt * (1 if k % 2 else -1)
        beam = -(np.cos(lean) * normal + np.sin(lean) * across)
        reading = lo + (0.3 if k % 2 else 0.7) * (hi - lo)
        hit = setup.centre + setup.radius * normal
        origin = hit - reading * beam
        if hit[2] <= workspace.table_height:
            continue
        solved = workspace.solve_beams(origin[None], beam[None], setup.offset, setup.axis,
                                       out[-1][None])
        q = solved.joints[0]
        if not (solved.ok[0] and workspace.clear_of_table(q[None], origin[None])[0]):
            continue
        move = float(np.max(np.abs(q - out[-1])))
        if travel + move > budget:
            break
        travel += move
        out.append(q)
    return np.array(out)


def _beam(setup, workspace, q):
    """Laser origin, beam direction, hit normal and stand-off of joints ``q``."""
    T = workspace.kinematics.flange_poses(q[None], workspace.p)[0]
    o = exact.matmul(T[:3, :3], setup.offset) + T[:3, 3]
    d = exact.matmul(T[:3, :3], setup.axis / exact.norm(setup.axis))
    v = o - setup.centre
    b = exact.dot(d, v)
    disc = max(b * b - (exact.dot(v, v) - setup.radius**2), 0.0)
    reading = -b - math.sqrt(disc)
    normal = (o + reading * d - setup.centre) / setup.radius
    return d, normal / exact.norm(normal), reading


def _slerp(a, b, s):
    angle = math.acos(float(np.clip(exact.dot(a, b), -1.0, 1.0)))
    if angle < 1e-9:
        return a
    return (math.sin((1 - s) * angle) * a + math.sin(s * angle) * b) / math.sin(angle)


def _slide(setup, workspace, Q, segment, s):
    """Joints a fraction ``s`` (N,) of the way along ``segment`` (N,) from waypoint
    ``Q[segment]`` to the next, with the beam kept on the sphere (hit normal, beam
    direction and stand-off interpolated; inverse kinematics for all samples at once,
    seeded by the joint interpolation); the joint interpolation where inverse kinematics
    fails or would jump."""
    beams = [_beam(setup, workspace, q) for q in Q]
    origins, directions = [], []
    for k, share in zip(segment, s):
        (da, na, la), (db, nb, lb) = beams[k], beams[k + 1]
        d = _slerp(da, db, share)
        origins.append(setup.centre + setup.radius * _slerp(na, nb, share)
                       - ((1 - share) * la + share * lb) * d)
        directions.append(d)
    guess = (1 - s)[:, None] * Q[segment] + s[:, None] * Q[segment + 1]
    solved = workspace.solve_beams(np.array(origins), np.array(directions), setup.offset,
                                   setup.axis, guess, iterations=60)
    step = setup.max_joint_speed / setup.laser_rate * 2
    path = np.where(solved.ok[:, None], solved.joints, guess)
    for k in range(1, len(path)):  # again, one by one, where the batch failed or jumped
        if solved.ok[k] and np.max(np.abs(path[k] - path[k - 1])) <= step:
            continue
        path[k] = guess[k]
        for seed in (path[k - 1], guess[k]):
            again = workspace.solve_beams(origins[k][None], directions[k][None], setup.offset,
                                          setup.axis, seed[None], iterations=60)
            if again.ok[0] and np.max(np.abs(again.joints[0] - path[k - 1])) <= step:
                path[k] = again.joints[0]
                break
    return path


# ---------------------------------------------------------------------------- the OCP


def _solve(setup, workspace, rows, info, index, times, duration, start, max_iterations):
    """Control points that optimise ``index`` from the start path ``start`` (N x dof):
    ``(joints at times, status)``.

    The spline has ``K`` control points, so the information and the constraints need not
    be posed at every laser instant: the OCP uses every ``stride``-th one
    (``SAMPLES_PER_SPAN`` per knot span; the information sum is then a quadrature of the
    full one, and the constraints' margins cover the instants between). Every instant is
    checked afterwards; instants that break a constraint join the grid and the solve is
    repeated from the last result (at most ``REPAIRS`` times)."""
    N = len(times)
    K = int(np.clip(round(duration * KNOTS_PER_SECOND) + 6, 8, max(8, N // 6)))
    B, knots = spline_basis(times, K, duration)
    lower = np.where(np.isfinite(workspace.lower), workspace.lower, -1e3)
    upper = np.where(np.isfinite(workspace.upper), workspace.upper, 1e3)
    C = _fit(setup, rows, B, knots, start, lower, upper)
    stride = max(1, int(N // (SAMPLES_PER_SPAN * (K - DEGREE))))
    grid = np.unique(np.concatenate([np.arange(0, N, stride), [N - 1]]))
    status = "not solved"
    for _ in range(REPAIRS + 1):
        problem = _ScanProblem(setup, rows, info, index, B, grid, knots, lower, upper,
                               max_iterations)
        C, status = problem.solve(C)
        broken = np.flatnonzero(_broken(setup, rows, exact.matmul(B, C)))
        missing = np.setdiff1d(broken, grid)
        if not missing.size:
            break
        grid = np.union1d(grid, missing)
    return exact.matmul(B, C), status


def _broken(setup, rows, Q) -> np.ndarray:
    """Where samples ``Q`` break the OCP's beam, range or clearance constraint (N,)."""
    _, disc, reading, clearance = rows.evaluate(Q)
    lo, hi = setup.laser_range
    return ((disc < (setup.radius * math.cos(setup.max_incidence)) ** 2)
            | (reading < lo) | (reading > hi) | (clearance < 0.0))


def _fit(setup, rows, B, knots, path, lower, upper) -> np.ndarray:
    """Control points (K x dof) whose spline is closest to ``path`` (N x dof) at the samples
    (least squares) among those within the joint limits, the speed and acceleration
    limits everywhere, at rest at both ends, and with the beam on the sphere within the
    incidence limit and the range at every instant (the OCP's margins kept): the start
    path as a point that meets the OCP's constraints but the capsules' (a plain fit may
    overshoot the acceleration where the path eases in and out of its waypoints, or
    lose the sphere between them)."""
    K, dof = B.shape[1], path.shape[1]
    N = len(path)
    c = ca.MX.sym("C", K * dof)
    C = ca.reshape(c, K, dof)
    banded = ca.DM(sparse.csc_matrix(np.where(np.abs(B) > 1e-14, B, 0.0)))
    Q = ca.mtimes(banded, C)
    disc, reading = rows.beam.map(N, "serial")(Q.T)
    parts = _linear_parts(setup, knots, C) + _beam_parts(setup, disc, reading)
    nlp: dict[str, ca.MX] = {"x": c, "f": 0.5 * ca.sumsqr(Q - ca.DM(path)),
                             "g": ca.vertcat(*[p[0] for p in parts])}
    solver = ca.nlpsol("scan_fit", "ipopt", nlp,
                       {"print_time": False,
                        "ipopt": {**IPOPT, "tol": 1e-8, "max_iter": FIT_ITERATIONS}})
    first = _least_squares(B, path)
    result = solver(x0=np.clip(first, lower, upper).T.ravel(),
                    lbg=np.concatenate([np.full(p[0].shape[0], p[1], float) for p in parts]),
                    ubg=np.concatenate([np.full(p[0].shape[0], p[2], float) for p in parts]),
                    lbx=np.tile(lower, (K, 1)).T.ravel(), ubx=np.tile(upper, (K, 1)).T.ravel())
    return np.asarray(result["x"], float).reshape(dof, K).T


def _least_squares(B: np.ndarray, Y: np.ndarray, chunk: int = 256) -> np.ndarray:
    """``X`` minimising ``|B X - Y|`` (``B`` N x K of full column rank) by the normal
    equations on ``common.exact``, the rows summed a chunk at a time in order: the
    solver starts here, and its path must not depend on the processor."""
    K = B.shape[1]
    normal = np.zeros((K, K))
    right = np.zeros((K, Y.shape[1]))
    for start in range(0, len(B), chunk):
        rows = B[start:start + chunk]
        normal += exact.gram(rows)
        right += (rows[:, :, None] * Y[start:start + chunk, None, :]).sum(axis=0)
    return np.stack([exact.solve(normal, right[:, j]) for j in range(Y.shape[1])], axis=1)


def _linear_parts(setup, knots, C):
    """``(expression, lower, upper)`` of the spline's linear constraints: speed and
    acceleration on the derivative's control points (so everywhere), at rest at both ends."""
    K = C.shape[0]
    D1 = derivative_map(knots, K, DEGREE)
    D2 = exact.matmul(derivative_map(knots[1:-1], K - 1, DEGREE - 1), D1)
    vmax, amax = setup.max_joint_speed, setup.max_joint_acceleration
    return [(ca.vec(ca.mtimes(ca.DM(sparse.csc_matrix(D1)), C)), -vmax, vmax),
            (ca.vec(ca.mtimes(ca.DM(sparse.csc_matrix(D2)), C)), -amax, amax),
            (ca.vertcat((C[1, :] - C[0, :]).T, (C[K - 2, :] - C[K - 1, :]).T), 0.0, 0.0)]


def _beam_parts(setup, disc, reading):
    """``(expression, lower, upper)`` of the beam's conditions at instants with ``disc``
    [m^2] and ``reading`` [m] (1 x N): a little inside the limits (an iterate stopped
    early still passes), each in a unit of its own size (IPOPT's tolerances are absolute)."""
    cos_limit = math.cos(setup.max_incidence - ANGLE_MARGIN)
    lo, hi = setup.laser_range
    return [(disc.T / setup.radius**2, cos_limit**2, np.inf),
            ((reading.T - lo) / (hi - lo), RANGE_MARGIN, 1.0 - RANGE_MARGIN)]


class _ScanProblem:
    """The scan OCP over the control points ``C`` (K x dof) as one IPOPT problem.

    Every per-sample quantity is one mapped CasADi function of a sample (built once in
    ``ScanRows``), differentiated exactly by CasADi: the beam's conditions at every
    instant from ``Q = B C`` (``B`` sparse: a sample depends on ``DEGREE + 1`` control
    points, so the constraint Jacobian stays sparse), the information and the capsules'
    clearance at the ``grid`` instants as variables of their own; the objective is
    logarithmic (``log`` of ``tool``, ``-log det`` of the reference-scaled information
    otherwise), so its scale does not depend on the set-up's units or sample count.
    """

    def __init__(self, setup, rows, info, index, B, grid, knots, lower, upper,
                 max_iterations):
        K = B.shape[1]
        dof = len(lower)
        N = B.shape[0]
        self.K, self.dof = K, dof
        c = ca.MX.sym("C", K * dof)
        C = ca.reshape(c, K, dof)
        # the samples are variables of their own, tied to the spline by linear equalities:
        # every per-sample constraint then depends on one sample only, and its Jacobian
        # costs dof directional derivatives, not one per colour of the spline's band
        samples = ca.MX.sym("Q", dof, len(grid))
        x = ca.vertcat(c, ca.vec(samples))
        banded = sparse.csc_matrix(np.where(np.abs(B) > 1e-14, B, 0.0))
        Bs = ca.DM(banded[grid])
        g = rows.rows.map(len(grid), "serial")(samples)
        clearance = rows.clearance.map(len(grid), "serial")(samples)
        # the beam's conditions are cheap: posed at every instant, from the spline itself
        disc, reading = rows.beam.map(N, "serial")(ca.mtimes(ca.DM(banded), C).T)
        self.B = B[grid]
        M = ca.mtimes(g, g.T)
        m, shared = info.m, info.shared
        S = M[:m, :m]
        if shared:
            S = S - M[:m, m:] @ ca.solve(M[m:, m:], M[m:, :m])
        # a start path may not identify everything yet: a ridge far below any real
        # information keeps the objective finite there
        S = S + 1e-9 * ca.trace(S) / m * ca.DM.eye(m)
        if index == "tool":
            # the index's own route: sum 1 / s_i^2 of J L^-T (info.tool = L^-1)
            T = ca.DM(info.tool)
            objective = ca.log(ca.trace(ca.solve(T @ S @ T.T, ca.DM.eye(m))))
        else:
            d = ca.DM(info.reference)
            objective = -ca.log(ca.det(S / (d @ d.T)))
        parts = (_linear_parts(setup, knots, C)
                 + [(ca.vec(samples - ca.mtimes(Bs, C).T), 0.0, 0.0)]
                 + _beam_parts(setup, disc, reading)
                 + [(clearance.T / CLEARANCE_UNIT, MARGIN / CLEARANCE_UNIT, np.inf)])
        constraints = ca.vertcat(*[p[0] for p in parts])
        self.lbg = np.concatenate([np.full(p[0].shape[0], p[1], float) for p in parts])
        self.ubg = np.concatenate([np.full(p[0].shape[0], p[2], float) for p in parts])
        self.lbx = np.concatenate([np.tile(lower, (K, 1)).T.ravel(), np.tile(lower, len(grid))])
        self.ubx = np.concatenate([np.tile(upper, (K, 1)).T.ravel(), np.tile(upper, len(grid))])
        self.best = BestFeasible(x.shape[0], constraints.shape[0], self.lbg, self.ubg,
                                  FEASIBLE)
        self._objective = ca.Function("scan_objective", [x], [objective])
        self.solver = ca.nlpsol("scan", "ipopt", {"x": x, "f": objective, "g": constraints},
                                {"print_time": False, "iteration_callback": self.best,
                                 "ipopt": {**IPOPT, "max_iter": int(max_iterations)}})

    def _point(self, C: np.ndarray) -> np.ndarray:
        """The solver's variables for control points ``C`` (K x dof)."""
        C = np.asarray(C, float)
        return np.concatenate([C.T.ravel(), exact.matmul(self.B, C).ravel()])

    def objective(self, C: np.ndarray) -> float:
        """The OCP's objective at control points ``C`` (K x dof)."""
        return float(self._objective(self._point(C)))

    def solve(self, C0: np.ndarray):
        """``(C, status)`` from control points ``C0`` (K x dof)."""
        x0 = self._point(C0)
        self.best.reset()
        result = self.solver(x0=x0, lbx=self.lbx, ubx=self.ubx, lbg=self.lbg, ubg=self.ubg)
        stats = self.solver.stats()
        status = "solved" if stats.get("success") else stats.get("return_status", "not solved")
        x = np.asarray(result["x"], float).ravel()
        if not stats.get("success") and self.best.x is not None:
            # stopped early: the best iterate that met every constraint, not the last one
            x, status = self.best.x, f"{status}; best feasible iterate kept"
        C = x[:self.K * self.dof].reshape(self.dof, self.K).T
        return C, status


def _problems(setup, workspace, rows, Q, times) -> str:
    """What makes joint samples ``Q`` unrunnable ('' when nothing)."""
    _, disc, reading, _ = rows.evaluate(Q)
    found = []
    if not workspace.within_limits(Q, margin=-1e-9).all():
        found.append("joint limits")
    lo, hi = setup.laser_range
    if np.any(disc < (setup.radius * math.cos(setup.max_incidence)) ** 2 * (1 - 1e-6)):
        found.append("beam off the sphere or beyond the incidence limit")
    if np.any((reading < lo - 1e-7) | (reading > hi + 1e-7)):
        found.append("reading out of the laser's range")
    if not workspace.body.clear(Q).all():
        found.append("a link touches the table or another link")
    speed = np.abs(np.diff(Q, axis=0)) / np.diff(times)[:, None]
    if np.any(speed > setup.max_joint_speed * (1 + 1e-3)):
        found.append("joint speed")
    return ", ".join(found)
