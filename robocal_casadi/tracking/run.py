"""A tracking job solved row by row, as a controller would (``robocal track`` and
``robocal_casadi.track``; docs/formats.md#tracking-job).

Rows are solved in time order from the previous answer; each row's largest joint move is
the job's speed limits times the time since the previous row (``cycle_bound``) and, when
given, ``max_step``. The joints come back in the job's units.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..common.progress import Progress
from .job import TrackingJob
from .tracker import STATUSES, Tracker


@dataclass(frozen=True)
class TrackedJob:
    """The answer per row of a tracking job.

    ``time`` (N,) [s] as in the table; ``joints`` (N x dof) in the job's units (angle
    unit, length unit for prismatic joints); ``status`` per row one of ``ok``,
    ``limited``, ``unreachable``, ``failed`` (the last two keep the last safe joints);
    ``solve_ms`` (N,) [ms] the solve time of each row.
    """

    time: np.ndarray
    joints: np.ndarray
    status: tuple[str, ...]
    solve_ms: np.ndarray

    def counts(self) -> dict[str, int]:
        """How many rows have each status (every status listed, zero or not)."""
        counts = dict.fromkeys(STATUSES, 0)
        for status in self.status:
            counts[status] += 1
        return counts

    def columns(self) -> list[str]:
        """The columns of JOINTS.csv: ``time, q1..qn, status, solve_ms``."""
        dof = self.joints.shape[1]
        return ["time", *(f"q{i}" for i in range(1, dof + 1)), "status", "solve_ms"]

    def rows(self) -> list[list]:
        """The rows of JOINTS.csv, in the job's units."""
        return [[t, *q, s, ms] for t, q, s, ms in
                zip(self.time, self.joints, self.status, self.solve_ms)]

    def __repr__(self) -> str:
        tally = ", ".join(f"{n} {s}" for s, n in self.counts().items())
        return f"TrackedJob({len(self.status)} rows: {tally})"


def joint_scales(job: TrackingJob) -> np.ndarray:
    """Per joint, SI per job unit: the angle scale, the length scale for a prismatic joint."""
    return np.array([job.units.angle_scale if j.revolute else job.units.length_scale
                     for j in job.robot.joints])


def cycle_bound(job: TrackingJob, row: int) -> np.ndarray | None:
    """Row ``row``'s largest joint move [rad or m]: the job's speed limits times the time
    since the previous row (the first row: times the time to the next one, the cycle the
    controller runs at); None without speed limits or, for a one-row job, without a cycle
    time."""
    if job.max_velocity is None or job.rows < 2:
        return None
    other = row - 1 if row > 0 else 1
    return job.max_velocity * abs(float(job.time[row] - job.time[other]))


def track_job(job: TrackingJob, *, max_step: Sequence[float] | None = None) -> TrackedJob:
    """Solve every row of ``job`` in order; ``max_step`` (dof,) [rad or m] bounds each
    row's joint move besides the job's speed limits. Progress shows on a terminal."""
    tracker = Tracker(job.robot, job.camera_xyz, job.standoff, up=job.up, max_step=max_step)
    scales = joint_scales(job)
    joints, status, solve_ms = [], [], []
    with Progress("track", total=job.rows) as bar:
        for i in range(job.rows):
            step = tracker.step(job.joints[i], job.observations[i],
                                max_step=cycle_bound(job, i))
            joints.append(step.q / scales)
            status.append(step.status)
            solve_ms.append(step.solve_ms)
            bar.update(i + 1)
    return TrackedJob(np.asarray(job.time, dtype=float), np.array(joints), tuple(status),
                      np.array(solve_ms, dtype=float))
