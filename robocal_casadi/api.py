"""The Python front door: the command line's verbs as functions, in the files' units.

Each function runs what its ``robocal`` verb runs and takes and gives values as the files
hold them: joint readings in the robot file's units (its angle unit, its length unit for a
prismatic joint), tool poses ``x, y, z, qw, qx, qy, qz`` in the robot file's length unit in
the world frame (``world_T_tool = base * T(0,1) ... T(n-1,n) * tool``,
docs/conventions.md#pose-chain). Inside, everything is SI. The README's Python session
uses all seven (``load_robot``, ``load_dataset``, ``fk``, ``calibrate``, ``plan``,
``track``, ``compensate``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .common.checks import path_argument
from .common.table import Table
from .effects.effect_model import load_effects, row_values
from .errors import ArgumentError
from .instruments.datasets import Dataset
from .instruments.datasets import joint_readings as _checked_readings
from .instruments.datasets import load_dataset as _load_dataset
from .job.compensation import compensate as _compensate
from .job.run import JobOptions, ReportOptions, run_job
from .model.calibrated import calibrated_robot, nominal_of, pose_rows, tool_pose_rows
from .model.robot import Robot
from .model.robot import load_robot as _load_robot
from .results import CalibrationResult
from .tracking.job import load_tracking_job
from .tracking.run import TrackedJob, joint_scales, track_job

__all__ = ["Commands", "PlannedTable", "calibrate", "compensate", "fk", "load_dataset",
           "load_robot", "plan", "track"]


def load_robot(path: str | Path, *, base_link: str | None = None,
               tip_link: str | None = None) -> Robot:
    """The robot of a robot file (YAML, standard or modified DH) or of a URDF file.

    The ``Robot`` keeps the file's units (``robot.units``) for everything written back;
    its parameters are held in SI [m, rad] (``robot.parameter_vector()``). ``base_link``
    and ``tip_link`` choose a URDF's serial chain (default: its root to its single leaf).
    Bad content is an ``InputError`` naming the file and key (docs/formats.md#robot-file).

    >>> robot = load_robot("robocal_casadi/data/ur10-ipa/robot.yaml")   # the shipped UR10
    >>> robot.dof, robot.units.length, robot.units.angle
    (6, 'mm', 'deg')
    """
    return _load_robot(path, base_link=base_link, tip_link=tip_link)


def load_dataset(path: str | Path, *, robot: Robot | str | Path | None = None,
                 require_data: bool = True, allow_outside_data: bool = False) -> Dataset:
    """A dataset file (its kind, robot, units, instrument geometry) and its table.

    The readings are held in SI [m, rad]: joints in the robot's base-to-flange order,
    instrument offsets (probe, target, laser) in the flange frame. ``robot`` (a ``Robot``
    or a robot file) replaces the one the dataset names, e.g. a calibrated one;
    ``require_data=False`` reads the set-up only (planning). A bad file is an
    ``InputError`` naming the file, key or line (docs/formats.md#dataset-file).

    >>> dataset = load_dataset("robocal_casadi/data/ur10-ipa/series_D_fit.yaml")
    >>> dataset.joints.shape        # 474 readings of 6 joints, in rad (SI inside)
    (474, 6)
    """
    return _load_dataset(path, robot=robot, require_data=require_data,
                         allow_outside_data=allow_outside_data)


def fk(robot: Robot | str | Path, joints, *, calibrated: str | Path | None = None,
       with_effects: bool = False, payload=None, temperature=None) -> np.ndarray:
    """Tool poses (N x 7) ``x, y, z, qw, qx, qy, qz`` at joint readings, as ``robocal fk``.

    ``robot`` a ``Robot`` or a robot file; ``joints`` (N x dof, or one row) readings
    ``q1..qn`` in the robot file's units (deg or rad; mm or m for a prismatic joint),
    checked against the joint limits. The poses are in the world frame, positions in the
    robot file's length unit, unit quaternions with ``qw >= 0``. ``calibrated`` a
    calibration result folder: its ``robot_calibrated.yaml`` geometry (readings and poses
    keep ``robot``'s units); ``with_effects`` also applies the effects it identified
    (``effects_calibrated.yaml``), with ``payload`` [kg] and ``temperature`` [C] (one
    number, or one per row) where they need them. Backlash reads the direction of motion
    from the order of the rows.

    >>> fk("robocal_casadi/data/ur10-ipa/robot.yaml", [[0, -90, 90, 0, 90, 0]]).round(3).tolist()
    [[664.5, 163.941, 623.6, 0.5, 0.5, 0.5, 0.5]]
    >>> fk("robot.yaml", q, calibrated="result", with_effects=True, payload=5.0)  # kg
    """
    nominal = _robot(robot)
    model = nominal if calibrated is None else calibrated_robot(calibrated, nominal,
                                                                _robot_path(robot))
    extra = _per_row({"payload": payload, "temperature": temperature})
    table = _table("joints", _joint_columns(joints, model.dof), extra)
    Q = _checked_readings(table, model, model.units, set(), _robot_path(robot))
    if not with_effects:
        return tool_pose_rows(model, Q)
    if calibrated is None:
        raise ArgumentError("effects come from a calibration: give calibrated=DIR",
                            argument="with_effects")
    effects = load_effects(Path(calibrated), model)
    values = row_values(effects, table, **_single({"payload": payload,
                                                   "temperature": temperature}))
    return pose_rows(effects.tool_poses(Q, values), model)


def calibrate(datasets: Sequence, validation: Sequence = (), *, out: str | Path | None = None,
              profile: str | None = None, diagnose: bool = True, method: str = "lm",
              loss: str = "robust", rule: str = "prior", select_growth: float | None = None,
              max_iterations: int = 200, effects: Sequence = (),
              parameters: Sequence[str] | str | None = None, report: bool = True,
              pdf: bool = False, progress: bool = False) -> CalibrationResult:
    """The whole calibration job of ``robocal calibrate``; with ``out``, its files too.

    ``datasets`` and ``validation`` (held out) are dataset files or ``load_dataset``
    results sharing one robot. Identifies the geometry, adds the effects the data support
    (``diagnose``), chooses the geometry a controller runs (``result.delivery``) and, with
    ``out`` (a new folder), writes ``result.json``, ``errors.csv``,
    ``robot_calibrated.yaml`` (the robot file's units), ``report.html`` (``report``,
    ``pdf``) and ``effects_calibrated.yaml``. The returned ``CalibrationResult`` holds SI
    values [m, rad]: ``result.parameter("a2")``; its ``to_json()`` is result.json in the
    robot file's units. ``profile`` (``dh-only``, ``ur``, ``kuka``) fits only what that
    controller accepts; ``effects`` are declared from the start; ``parameters`` restricts
    the robot parameters fitted. Other options as the command line's
    (docs/methods.md#solvers); a bad one is an ``ArgumentError`` naming it.

    >>> result = calibrate(["bar/dataset.yaml"], ["bar-check/dataset.yaml"], out="bar-result")
    >>> result.parameter("a2")       # nominal, estimate, std [m]
    """
    fit, held_out = _datasets(datasets, "datasets"), _datasets(validation, "validation")
    options = JobOptions(diagnose=diagnose, method=method, loss=loss,
                         select_growth=select_growth, max_iterations=max_iterations,
                         rule=rule, profile=profile, progress=progress, effects=effects,
                         parameters=parameters)
    written = ReportOptions(report=report, pdf=pdf)
    outcome = run_job(fit, held_out, options, None if out is None else Path(out), written,
                      progress=progress)
    return outcome.result


@dataclass(frozen=True)
class PlannedTable:
    """A plan as PLAN.csv holds it: ``columns`` and ``rows`` in the dataset's units
    (joints ``q1..qn``, or pendant poses for a sensor-only scan; the measured cells
    ``distance`` or ``x, y, z`` left empty as NaN; bars and artifacts also the socket
    positions ``socket_x..z``, world frame); ``design`` the planner's ``Plan`` or
    ``Scan`` with its figures (SI); ``summary()`` what ``robocal plan`` prints."""

    columns: tuple[str, ...]
    rows: tuple[tuple, ...]
    design: object

    def summary(self) -> str:
        return str(self.design.summary())  # type: ignore[attr-defined]

    def column(self, name: str) -> np.ndarray:
        """Column ``name`` as numbers (NaN where empty)."""
        k = self.columns.index(name)
        return np.array([np.nan if r[k] in ("", None) else float(r[k]) for r in self.rows])

    def __repr__(self) -> str:
        return f"PlannedTable({len(self.rows)} rows, columns={list(self.columns)})"


def plan(dataset: Dataset | str | Path, count: int, *, index: str = "tool", seed: int = 0,
         refine: bool = True, sensor_only: bool = False,
         out: str | Path | None = None) -> PlannedTable:
    """Measurement poses for a dataset's set-up, as ``robocal plan`` designs them.

    ``dataset`` a dataset file (its table need not exist) or a ``load_dataset`` result;
    ``count`` bar or artifact placements, or readings; ``index`` ``tool`` (the predicted
    tool-position error over the workspace), ``cond``, ``O1`` .. ``O5``; ``seed`` of the
    candidate search; ``refine`` the continuous refinement (pose plans); ``sensor_only``
    a laser scan for the laser and sphere alone. The plan's table comes back in the
    dataset's units (``PlannedTable``) and, with ``out``, is written there as PLAN.csv
    (docs/formats.md#plan-table).

    >>> planned = plan("tracker.yaml", 12, seed=1, out="PLAN.csv")
    >>> planned.column("q2")        # the dataset's angle unit
    >>> print(planned.summary())    # what robocal plan prints
    """
    from planning.designed import design, table

    if not isinstance(dataset, Dataset):
        dataset = _load_dataset(path_argument(dataset, "dataset", what="a dataset file"),
                                require_data=False)
    designed = design(dataset, count, index, seed=seed, refine=refine,
                      sensor_only=sensor_only)
    columns, rows = table(designed)
    if out is not None:
        from .common.output import atomic_file
        from .common.table import write_table

        with atomic_file(out) as staging:
            write_table(staging, columns, rows)
    return PlannedTable(tuple(columns), tuple(tuple(r) for r in rows), designed)


def track(job: str | Path, *, calibrated: str | Path | None = None,
          max_step: float | None = None) -> TrackedJob:
    """Joints that keep the tool facing a moving target, as ``robocal track`` solves them.

    ``job`` a tracking job file (docs/formats.md#tracking-job): robot, camera on the end
    frame, standoff, worktable normal ``up`` and the observation table. Rows are solved in
    time order. ``calibrated`` a calibration result folder whose geometry replaces the
    job's robot; ``max_step`` the largest joint move per row in the job's angle unit
    (length unit for prismatic joints). Returns ``TrackedJob``: ``time`` [s], ``joints``
    (N x dof) in the job's units, ``status`` (``ok``, ``limited``, ``unreachable``,
    ``failed``) and ``solve_ms``.

    >>> tracked = track("job.yaml", calibrated="result")
    >>> tracked.counts()            # rows per status
    >>> tracked.joints              # (N x dof), the job's units
    """
    path = path_argument(job, "job", what="a tracking job file")
    loaded = load_tracking_job(path)
    if calibrated is not None:
        robot = calibrated_robot(calibrated, loaded.robot, loaded.robot_path)
        loaded = load_tracking_job(path, robot=robot)
    step: list[float] | None = None
    if max_step is not None:
        if not (isinstance(max_step, (int, float)) and np.isfinite(max_step) and max_step > 0):
            raise ArgumentError(f"expected a positive number, got {max_step!r}",
                                argument="max_step")
        step = [float(v) for v in joint_scales(loaded) * float(max_step)]
    return track_job(loaded, max_step=step)


@dataclass(frozen=True)
class Commands:
    """Joint commands per target, in the robot file's units.

    ``joints`` (N x dof), NaN where the status is not ``ok``; ``status`` per target
    ``ok``, ``branch`` (reachable only on another branch than its seed's) or
    ``unreachable``; ``position_error`` (N,) the tool's distance from the target at the
    answer (length unit); ``orientation_error`` (N,) its turn from the target's
    orientation (angle unit; NaN for position-only targets).
    """

    joints: np.ndarray
    status: tuple[str, ...]
    position_error: np.ndarray
    orientation_error: np.ndarray

    def __len__(self) -> int:
        return len(self.status)

    def __repr__(self) -> str:
        ok = sum(s == "ok" for s in self.status)
        return f"Commands({len(self)} targets, {ok} ok, {len(self) - ok} not)"


def compensate(robot: Robot | str | Path, targets, *, calibrated: str | Path | None = None,
               seeds=None, start=None, with_effects: bool = False, payload=None,
               temperature=None, restarts: int = 10, seed: int = 0) -> Commands:
    """Joint commands that put the (calibrated) tool on Cartesian targets, as
    ``robocal compensate``.

    ``robot`` a ``Robot`` or a robot file; ``targets`` (N x 3) tool positions ``x, y, z``
    or (N x 7) poses ``x, y, z, qw, qx, qy, qz`` in the robot file's length unit, world
    frame. ``seeds`` (N x dof, robot file units; NaN rows where none) the joints that
    reached each target before, whose branch (shoulder, elbow, wrist) each answer keeps;
    rows without one are seeded from the nominal robot's inverse kinematics, solved in
    order from ``start`` (dof, robot units; default mid-limits) with ``restarts`` random
    starts from ``seed``. ``calibrated`` a calibration result folder: its geometry, and
    with ``with_effects`` its effects (``payload`` [kg], ``temperature`` [C]: a number or
    one per target).

    >>> commands = compensate("robot.yaml", [[900, 100, 600]], calibrated="result")  # mm
    >>> commands.joints, commands.status     # robot file units; ('ok',) when reached
    """
    nominal = _robot(robot)
    model = nominal if calibrated is None else calibrated_robot(calibrated, nominal,
                                                                _robot_path(robot))
    L, A = model.units.length_scale, model.units.angle_scale
    goals = _compensate_targets(targets, L)
    scales = model.reading_scales()
    seeds_si = None if seeds is None else _joint_rows(seeds, model, "seeds", allow_nan=True)
    start_si = None if start is None else _joint_rows(start, model, "start")[0]
    effects = values = None
    if with_effects:
        if calibrated is None:
            raise ArgumentError("effects come from a calibration: give calibrated=DIR",
                                argument="with_effects")
        effects = load_effects(Path(calibrated), model)
        table = _table("targets", {}, _per_row({"payload": payload,
                                                "temperature": temperature}), rows=len(goals))
        values = row_values(effects, table, **_single({"payload": payload,
                                                       "temperature": temperature}))
    reference = model if calibrated is None or not (Path(calibrated) / "result.json").is_file() \
        else nominal_of(model, calibrated)
    solved = _compensate(model, goals, start=start_si, seeds=seeds_si, nominal=reference,
                         restarts=restarts, seed=seed, effects=effects, extras=values)
    return Commands(solved.joints / scales, solved.status, solved.position_error / L,
                    solved.orientation_error / A)


# ----------------------------------------------------------------------------- helpers


def _robot(robot: Robot | str | Path) -> Robot:
    if isinstance(robot, Robot):
        return robot
    return _load_robot(path_argument(robot, "robot", what="a Robot or a robot file"))


def _robot_path(robot: Robot | str | Path) -> Path | None:
    return None if isinstance(robot, Robot) else Path(robot)


def _datasets(values, argument: str) -> list:
    """Dataset files loaded, ``load_dataset`` results kept (anything else in the list is
    refused by the engine's own check, which names ``argument``)."""
    if isinstance(values, (str, Path)):
        raise ArgumentError(f"expected a list of dataset files or load_dataset results, got "
                            f"one {type(values).__name__}; wrap it in a list",
                            argument=argument)
    if not isinstance(values, (list, tuple)):
        raise ArgumentError(f"expected a list of dataset files or load_dataset results, got "
                            f"a {type(values).__name__}", argument=argument)
    return [_load_dataset(v) if isinstance(v, (str, Path)) else v for v in values]


def _joint_columns(joints, dof: int) -> dict[str, np.ndarray]:
    """``q1..qn`` columns of readings given as rows (N x dof, or one row)."""
    try:
        values = np.atleast_2d(np.asarray(joints, dtype=float))
    except (TypeError, ValueError):
        raise ArgumentError(f"expected numbers (N x {dof}), got a {type(joints).__name__}",
                            argument="joints") from None
    if values.ndim != 2 or values.shape[1] != dof or not values.size:
        raise ArgumentError(f"expected {dof} readings per row (N x {dof}), got shape "
                            f"{values.shape}", argument="joints")
    return {f"q{i + 1}": values[:, i] for i in range(dof)}


def _per_row(values: dict) -> dict[str, np.ndarray]:
    """The values given one per row (arrays), as table columns."""
    return {k: np.asarray(v, dtype=float).ravel() for k, v in values.items()
            if v is not None and np.ndim(v) > 0}


def _single(values: dict) -> dict:
    """The values given as one number for every row."""
    return {k: (float(v) if v is not None and np.ndim(v) == 0 else None)
            for k, v in values.items()}


def _table(name: str, columns: dict[str, np.ndarray], extra: dict[str, np.ndarray],
           rows: int | None = None) -> Table:
    """Arrays held as a table, cell by cell as a file would hold them (full precision), so
    they are read and checked as the command line reads a file; row k is 'line k'."""
    merged = {**columns, **extra}
    count = rows if rows is not None else len(next(iter(merged.values())))
    cells = []
    for key, values in merged.items():
        if len(values) != count:
            raise ArgumentError(f"expected one value per row ({count}), got {len(values)}",
                                argument=key)
        cells.append(np.array([repr(float(v)).encode() for v in values], dtype=bytes))
    return Table(Path(name), tuple(merged), tuple(cells), np.arange(1, count + 1))


def _joint_rows(values, robot: Robot, argument: str, *, allow_nan: bool = False) -> np.ndarray:
    """Rows of joints in the robot file's units as SI, within the joint limits."""
    try:
        rows = np.atleast_2d(np.asarray(values, dtype=float))
    except (TypeError, ValueError):
        raise ArgumentError(f"expected numbers, got a {type(values).__name__}",
                            argument=argument) from None
    if rows.ndim != 2 or rows.shape[1] != robot.dof:
        raise ArgumentError(f"expected {robot.dof} joints per row, got shape {rows.shape}",
                            argument=argument)
    empty = np.isnan(rows).all(axis=1) if allow_nan else np.zeros(len(rows), bool)
    bad = np.flatnonzero(~empty & ~np.isfinite(rows).all(axis=1))
    if bad.size:
        raise ArgumentError(f"row {int(bad[0])} is not finite (give all joints, or all NaN "
                            "for none)" if allow_nan else f"row {int(bad[0])} is not finite",
                            argument=argument)
    si = rows * robot.reading_scales()
    outside = np.argwhere(~empty[:, None] & ((si < robot.lower_limits - 1e-9)
                                            | (si > robot.upper_limits + 1e-9)))
    if outside.size:
        row, k = (int(v) for v in outside[0])
        raise ArgumentError(f"row {row}: q{k + 1} = {rows[row, k]:g} is outside the robot's "
                            "limits", argument=argument)
    return si


def _compensate_targets(targets, length_scale: float) -> np.ndarray:
    """Targets in the robot file's length unit as SI rows (positions scaled; the engine
    checks shape and finiteness and names ``targets``)."""
    try:
        rows = np.atleast_2d(np.asarray(targets, dtype=float)).copy()
    except (TypeError, ValueError):
        return targets  # the engine refuses it with its message
    if rows.ndim == 2 and rows.shape[1] in (3, 7):
        rows[:, :3] *= length_scale
    return rows

