"""One plan for a dataset's set-up, as ``robocal plan`` and ``robocal_casadi.plan`` make it.

A scanning instrument (the point laser) gets a scan trajectory sampled at its rate
(``trajectory.design_scan``); every other kind a set of placements or readings in run
order (``design.design_plan``). ``table`` gives what PLAN.csv holds: the data table's
columns in the dataset's units, the measured cells left empty.
"""

from __future__ import annotations

from robocal_casadi.errors import ArgumentError
from robocal_casadi.instruments import instrument
from robocal_casadi.instruments.datasets import Dataset

from .design import Plan, design_plan
from .export import scan_columns, scan_rows
from .plan_table import plan_columns, plan_rows
from .trajectory import Scan, design_scan


def scans(dataset: Dataset) -> bool:
    """Whether ``dataset``'s instrument is planned as a scan trajectory."""
    planner = instrument(dataset.kind).planner
    return planner is not None and planner.scans


def design(dataset: Dataset, count: int, index: str = "tool", *, seed: int = 0,
           refine: bool = True, sensor_only: bool = False) -> Plan | Scan:
    """The plan of ``count`` placements or readings (see the module docstring).

    ``sensor_only`` is for scans only (the laser and sphere alone; a scan of a dataset
    whose table holds pendant poses is sensor-only anyway); ``refine`` is for pose plans.
    """
    if scans(dataset):
        return design_scan(dataset, count, index, seed=seed,
                           sensor_only=True if sensor_only else None)
    if sensor_only:
        raise ArgumentError(f"is for laser scans, not {dataset.kind} data",
                            argument="sensor_only")
    return design_plan(dataset, count, index, seed=seed, refine=refine)


def table(designed: Plan | Scan) -> tuple[list[str], list[list]]:
    """Columns and rows of PLAN.csv for ``designed``, in the dataset's units."""
    if isinstance(designed, Scan):
        return scan_columns(designed), scan_rows(designed)
    return plan_columns(designed), plan_rows(designed)
