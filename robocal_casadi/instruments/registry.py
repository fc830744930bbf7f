"""The one registry of dataset kinds: an ``Instrument`` record per kind.

A kind is everything the toolkit knows about one instrument: the keys of its dataset
file and the reader that turns them into a frozen dataset record, its measurement model,
how the simulator produces its readings and corrupts one, the planner's set-up fields
and the checks that refuse degenerate data. Each lives in the kind's own package
(``instruments/<kind>/``), which builds its record; ``register`` adds it here. Callers
ask ``instrument(kind)`` and never spell a kind.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..common.fields import cut
from ..errors import InputError

if TYPE_CHECKING:
    from .dataset import DatasetBase
    from .model import MeasurementModel


def _no_check(dataset: Any, joints: Any, where: Path) -> None:
    """A kind without degeneracy checks of its own refuses nothing here."""
    return None


@dataclass(frozen=True)
class Planner:
    """How the planner (``planning/``) works with a kind.

    ``setup(dataset, options)`` the kind's fields of ``planning.setup.PlanSetup``
    (``options`` reads the dataset's ``planning`` block); ``candidates(setup, workspace,
    count, rng, progress)`` up to ``count`` feasible ``instruments.planning.Candidate``;
    ``refine(program, setup, workspace, row_model, candidate, Q)`` adds a candidate's
    Jacobian block and the constraints that keep it runnable to the refinement's
    program; ``feasible(setup, workspace, candidate, Q)`` the candidate at refined joints
    ``Q`` as ``(candidate, Q, measured points [m])``, or None when it fails a check.
    ``scans``: the kind's plans are continuous scan trajectories (``planning.trajectory``)
    rather than a chosen set of poses (``planning.design``). ``measured_point(setup)`` the
    flange-frame point whose accuracy is predicted and the two directions [m] the
    prediction varies it along (``planning.accuracy``); None: the set-up's ``offset`` and
    no variation.
    """

    setup: Callable[[Any, Any], dict]
    candidates: Callable[..., list]
    refine: Callable[..., None]
    feasible: Callable[..., Any]
    scans: bool = False
    measured_point: Callable[[Any], tuple[Any, Any, Any]] | None = None


@dataclass(frozen=True)
class Instrument:
    """One dataset kind and the pieces of its package.

    ``kind`` the ``kind:`` key of its dataset files; ``model`` its measurement model
    class; ``blocks`` the instrument keys of its dataset file, each with the keys allowed
    inside; ``read(content, table, common)`` the dataset record from the checked YAML
    mapping, the table (None when not read) and the fields every kind shares;
    ``simulate(setup)`` the readings of a simulated run (``instruments.simulation``);
    ``corrupt(rows, columns, row, length, rng, dataset)`` moves one row of a simulated
    table by ``length`` [m] (a gross error); ``planner`` what the planner asks
    (``Planner``); ``check(dataset, joints, where)`` refuses data that cannot calibrate
    (``calibration.degeneracy``). ``any_configuration``: a reading can be taken at any
    configuration, in the order the robot moves, so effects that need absolute points
    along a path (``Effect.tracker_only``) can be simulated for the kind. A kind without a
    simulator or planner is read and calibrated; simulating or planning it is refused.
    ``noun`` names the instrument in sentences ("tracker"); ``turned`` says what readings
    would see what it cannot see at one orientation of the measured point;
    ``plain_posterior``: the fit's covariance is the plain least-squares posterior (False
    where certified lengths enter it, as an artifact's distances do).
    """

    kind: str
    model: type[MeasurementModel]
    blocks: Mapping[str, tuple[str, ...]]
    read: Callable[[dict, Any, dict], DatasetBase]
    simulate: Callable[[Any], Any] | None = None
    corrupt: Callable[..., None] | None = None
    planner: Planner | None = None
    check: Callable[[Any, Any, Path], None] = field(default=_no_check)
    any_configuration: bool = False
    noun: str = "instrument"
    turned: str = "readings with the flange in other orientations"
    plain_posterior: bool = True

    def __repr__(self) -> str:
        return f"Instrument({self.kind!r}, model={self.model.__name__})"


INSTRUMENTS: dict[str, Instrument] = {}


def register(record: Instrument) -> Instrument:
    """Add ``record`` to the registry (a kind already registered is refused)."""
    if record.kind in INSTRUMENTS:
        raise ValueError(f"kind {record.kind!r} is registered already")
    if record.model.kind != record.kind:
        raise ValueError(f"{record.model.__name__} models kind {record.model.kind!r}, "
                         f"not {record.kind!r}")
    INSTRUMENTS[record.kind] = record
    return record


def kinds() -> tuple[str, ...]:
    """The registered kinds, in the order registered."""
    return tuple(INSTRUMENTS)


def instrument(kind: Any, *, file: str | Path | None = None) -> Instrument:
    """The record of ``kind``; an unknown kind is an ``InputError`` naming ``file``."""
    if not isinstance(kind, str) or kind not in INSTRUMENTS:
        raise InputError(f"unknown kind {cut(kind)}; expected one of {list(INSTRUMENTS)}",
                         file=file, where="kind")
    return INSTRUMENTS[kind]
