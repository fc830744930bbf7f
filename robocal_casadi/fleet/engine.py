"""Running a fleet's robots as tasks on a Dask cluster (``dask.distributed``).

Each robot is one task (``robot_task.calibrate_robot``) handed to the cluster; Dask
schedules them over its workers, one robot per worker process at a time, and reports
each as it finishes. Without a scheduler address, a local cluster of worker processes
is started on this machine and closed at the end; with one, the tasks go to that
existing cluster, whose workers must have robocal_casadi installed and see the fleet's
files and the output folder under the same paths.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator
from pathlib import Path

from ..errors import InputError
from .robot_task import RobotOutcome, Settings, calibrate_robot
from .spec import Fleet

CONNECT_TIMEOUT = 30.0  # [s] to reach an existing scheduler


def machine_cores() -> int:
    """The processor cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def require_engine() -> None:
    """Refuse at once, in one line, when Dask's distributed engine is not installed."""
    try:
        import dask.distributed  # noqa: F401
    except ImportError:
        raise InputError("fleet calibration needs Dask: pip install 'robocal_casadi[fleet]' "
                         "(or: pip install 'dask[distributed]')") from None


def _client(scheduler: str | None, workers: int | None):
    """A connected client, and the local cluster it owns (None for an existing one)."""
    require_engine()
    from dask.distributed import Client, LocalCluster
    if scheduler is not None:
        try:
            return Client(scheduler, timeout=CONNECT_TIMEOUT), None
        except (OSError, TimeoutError, ValueError) as error:
            raise InputError(f"cannot reach the Dask scheduler at {scheduler} "
                             f"({' '.join(str(error).split()) or type(error).__name__})",
                             where="--scheduler") from None
    # One single-threaded process per core: a calibration is one busy thread, and
    # processes keep each worker's compiled functions and memory apart. The scheduler's
    # status page goes to a free port on this machine only (Dask's usual 8787 may be taken).
    cluster = LocalCluster(n_workers=workers or machine_cores(), threads_per_worker=1,
                           processes=True, dashboard_address="127.0.0.1:0",
                           silence_logs=logging.ERROR)
    try:
        return Client(cluster), cluster
    except BaseException:
        cluster.close()
        raise


def run_tasks(fleet: Fleet, out: Path, settings: Settings, *, scheduler: str | None = None,
              workers: int | None = None) -> Iterator[RobotOutcome]:
    """Calibrate every robot of ``fleet`` into ``out/<name>/`` on the cluster; yield each
    robot's outcome as it finishes (in no fixed order). A task lost with its worker is a
    failed outcome of that robot."""
    client, cluster = _client(scheduler, workers)
    try:
        from dask.distributed import as_completed

        out = Path(os.path.abspath(out))
        futures = {}
        for robot in fleet.robots:
            future = client.submit(calibrate_robot, robot, out, settings, pure=False,
                                   key=f"robocal-fleet-{robot.name}-{os.getpid()}-{id(fleet)}")
            futures[future] = robot
        for future in as_completed(futures):
            robot = futures[future]
            try:
                yield future.result()
            except Exception as error:  # noqa: BLE001 - the worker died, not the robot's code
                message = " ".join(str(error).split()) or type(error).__name__
                yield RobotOutcome(name=robot.name, status="failed",
                                   error=f"its worker was lost ({message})")
            finally:
                future.release()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def run_fleet(fleet: Fleet, out: Path, settings: Settings, *, scheduler: str | None = None,
              workers: int | None = None,
              on_done: Callable[[RobotOutcome], None] | None = None) -> list[RobotOutcome]:
    """Every robot's outcome, in the fleet file's order; ``on_done`` sees each as it
    finishes."""
    outcomes = {}
    for outcome in run_tasks(fleet, out, settings, scheduler=scheduler, workers=workers):
        outcomes[outcome.name] = outcome
        if on_done is not None:
            on_done(outcome)
    return [outcomes[robot.name] for robot in fleet.robots]
