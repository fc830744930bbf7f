"""Running a fleet's robots as tasks on a Dask cluster (``dask.distributed``).

Each robot is one task (``robot_task.calibrate_robot``) handed to the cluster; Dask
schedules them over its workers, one robot per worker process at a time, and reports
each as it finishes. Without a scheduler address, a local cluster of worker processes
is started on this machine and closed at the end; with one, the tasks go to that
existing cluster, whose workers must have robocal_casadi installed and see the fleet's
files and the output folder under the same paths.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import signal
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

from ..common.fields import cut
from ..common.output import note_interrupt
from ..errors import InputError
from .robot_task import RobotOutcome, Settings, calibrate_robot
from .spec import Fleet

# A worker process of the local cluster is replaced after this many robots: each robot
# leaves a few MiB behind in a long-lived worker (measured by benchmarks/fleet_memory.py),
# so without a restart a worker's memory grows with the size of the fleet.
RESTART_EVERY = 25
CONNECT_TIMEOUT = 5.0  # [s] to reach an existing scheduler (a live one answers in ms)
PROTOCOLS = ("tcp", "tls", "ucx", "ws", "wss")  # Dask's address schemes
_ADDRESS = re.compile(r"(?:(?P<scheme>[a-z]+)://)?(?P<host>\[[0-9a-fA-F:]+\]|[A-Za-z0-9._-]+)"
                      r"(?::(?P<port>\d{1,5}))?")


def check_address(address: str) -> None:
    """Refuse a scheduler address that is not ``[scheme://]host[:port]`` with a Dask
    scheme and a port in 1..65535 (``InputError`` naming ``--scheduler``), before any
    connection is tried."""
    match = _ADDRESS.fullmatch(address.strip())
    if match is None or (match["scheme"] or "tcp") not in PROTOCOLS or (
            match["port"] is not None and not 0 < int(match["port"]) < 65536):
        raise InputError(f"expected an address like tcp://HOST:PORT (schemes "
                         f"{', '.join(PROTOCOLS)}), got {cut(address)}", where="--scheduler")


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
        check_address(scheduler)
        try:
            return Client(scheduler, timeout=CONNECT_TIMEOUT), None
        except (OSError, TimeoutError, ValueError) as error:
            raise InputError(f"cannot reach the Dask scheduler at {scheduler} "
                             f"({' '.join(str(error).split()) or type(error).__name__})",
                             where="--scheduler") from None
    # One single-threaded process per core: a calibration is one busy thread, and
    # processes keep each worker's compiled functions and memory apart. The scheduler's
    # status page goes to a free port on this machine only (Dask's usual 8787 may be taken).
    with _interrupt_deferred() as seen:
        try:
            cluster = LocalCluster(n_workers=workers or machine_cores(), threads_per_worker=1,
                                   processes=True, dashboard_address="127.0.0.1:0",
                                   silence_logs=logging.ERROR)
        except Exception:
            if seen:  # a worker stopped by the same Ctrl-C while it started
                raise KeyboardInterrupt from None
            raise
    try:
        if seen:
            raise KeyboardInterrupt
        return Client(cluster), cluster
    except BaseException:
        cluster.close()
        raise


@contextlib.contextmanager
def _interrupt_deferred() -> Iterator[list[int]]:
    """Note Ctrl-C inside (in the yielded list) instead of raising it: a cluster stopped
    half-way through its start cannot be closed, and Dask would complain at exit."""
    if threading.current_thread() is not threading.main_thread():
        yield []
        return
    seen: list[int] = []

    def note(number: int, frame) -> None:
        seen.append(number)
        note_interrupt()

    previous = signal.signal(signal.SIGINT, note)
    try:
        yield seen
    finally:
        signal.signal(signal.SIGINT, previous)


def run_tasks(fleet: Fleet, out: Path, settings: Settings, *, scheduler: str | None = None,
              workers: int | None = None,
              restart_every: int = RESTART_EVERY) -> Iterator[RobotOutcome]:
    """Calibrate every robot of ``fleet`` into ``out/<name>/`` on the cluster; yield each
    robot's outcome as it finishes (in no fixed order). A task lost with its worker is a
    failed outcome of that robot.

    On a local cluster the robots go in batches of ``restart_every`` per worker, and the
    worker processes are restarted between batches (no task is running then), so a
    worker's memory stays that of its first batch however many robots follow. An
    existing cluster (``scheduler``) is not restarted: its workers are the operator's."""
    client, cluster = _client(scheduler, workers)
    try:
        out = Path(os.path.abspath(out))
        robots = fleet.robots
        size = len(robots) if cluster is None else \
            max(restart_every, 1) * (workers or machine_cores())
        for first in range(0, len(robots), size):
            if first:
                client.restart()
            yield from _batch(client, robots[first:first + size], out, settings, id(fleet))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _batch(client, robots, out: Path, settings: Settings, run: int) -> Iterator[RobotOutcome]:
    """Submit ``robots``; yield each outcome as it finishes."""
    from dask.distributed import as_completed

    futures = {}
    for robot in robots:
        future = client.submit(calibrate_robot, robot, out, settings, pure=False,
                               key=f"robocal-fleet-{robot.name}-{os.getpid()}-{run}")
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
