"""A calibration job runs its linear algebra on one thread, whatever the caller set.

A matrix product split over threads sums in another order: the job's numbers would then
depend on the machine's cores, and a fleet's worker processes (one thread each) would
write other bytes than ``robocal calibrate`` (``tests/test_fleet.py`` compares the files).
"""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_info, threadpool_limits

from robocal_casadi.job import run as job


def _blas_threads() -> list[int]:
    return [entry["num_threads"] for entry in threadpool_info() if entry["user_api"] == "blas"]


def test_a_job_step_runs_on_one_blas_thread_and_gives_the_callers_setting_back():
    seen: list[int] = []

    @job.on_one_blas_thread
    def step(a: np.ndarray) -> float:
        seen.extend(_blas_threads())
        return float(np.sum(a @ a))

    with threadpool_limits(limits=2, user_api="blas"):
        before = _blas_threads()
        assert step(np.eye(3)) == 3.0
        after = _blas_threads()
    assert seen and set(seen) == {1}
    assert after == before


def test_the_calibration_inside_a_job_sees_one_blas_thread(monkeypatch):
    seen: list[int] = []

    def calibrate(datasets, validation, **options):
        seen.extend(_blas_threads())
        return "calibrated"

    monkeypatch.setattr(job, "_calibrate", calibrate)
    monkeypatch.setattr(job, "deliver", lambda result, datasets, validation: result)
    with threadpool_limits(limits=2, user_api="blas"):
        assert job.calibrate_job([], []) == "calibrated"
    assert seen and set(seen) == {1}
