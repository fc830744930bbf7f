"""The contract every measurement model fulfils.

A measurement model turns one dataset into a residual vector ``r`` whose least-squares
minimum is the calibration. Its unknowns besides the robot are of two sorts:

* ``mounted``: what is fixed to the robot (probe tip, tracker reflector, laser origin
  and beam). Shared by name between datasets, carried from calibration into validation.
* ``placement``: where the instrument sits in the room (socket positions, the tracker's
  frame, the sphere centre). Per dataset (names carry the dataset label) and fitted
  again on validation data, unless the dataset names its instrument ``station``: then
  the names carry the station (``station:<name>/...``), datasets of one station share
  them, and data of a station the calibration fitted keep its placement.

Each model class also says what its instrument means to the rest of the toolkit (the
kind's ``Instrument`` record in ``instruments.registry`` names its class; nothing else
switches on the kind): the name of its data table, how the robot takes one reading
(``reach``), what a planned or simulated unit is (``unit_name``), its plan-table
columns, how a planned dataset is filled with nominal readings, the minimal coordinates
of its mounted unknowns the planner varies, and the name of its error in the report.

The engine hands the model ``points(offsets)``: world positions [m] (3 x N, one column
per data row) of flange-frame points ``offsets`` (3 x 1 or 3 x N) [m], with the robot
and effect parameters already inside. ``residual`` returns an MX column; ``errors``
turns a numeric residual into the per-measurement error lengths the RMS values of
``result.json`` are taken over (docs/formats.md#result-file).
"""

from __future__ import annotations

import copy
from abc import ABCMeta, abstractmethod
from collections.abc import Callable, Mapping
from typing import ClassVar

import casadi as ca
import numpy as np

from ..model.parameters import ParameterRegistry
from ..results import ErrorTerm
from .dataset import dataset_rows
from .noise import InstrumentNoise

PointsFunction = Callable[[ca.MX], ca.MX]

STATION_PREFIX = "station:"


def station_prefix(station: str) -> str:
    """The prefix of the placement names of instrument station ``station``."""
    return f"{STATION_PREFIX}{station}"


class _Immutable(ABCMeta):
    """Models are frozen once their class's ``__init__`` has run."""

    def __call__(cls, *args, **kwargs):
        model = super().__call__(*args, **kwargs)
        object.__setattr__(model, "_frozen", True)
        return model


class MeasurementModel(metaclass=_Immutable):
    """Residuals of one dataset; see the module docstring for the unknowns.

    A model is immutable after construction: what changes as a problem is set up (the
    tracker's reference rotation) comes back as a new model (``placed``, ``follow``).
    """

    def __setattr__(self, name: str, value) -> None:
        if getattr(self, "_frozen", False):
            raise AttributeError(f"{type(self).__name__} is immutable; {name!r} cannot be set "
                                 f"after construction")
        object.__setattr__(self, name, value)

    def __delattr__(self, name: str) -> None:
        raise AttributeError(f"{type(self).__name__} is immutable; {name!r} cannot be deleted")

    def _replaced(self, **attributes) -> MeasurementModel:
        """A copy of this model with ``attributes`` set (the copy is immutable too)."""
        model = copy.copy(self)
        for name, value in attributes.items():
            object.__setattr__(model, name, value)
        return model

    kind: ClassVar[str]
    table: ClassVar[str]
    """File name of the data table the simulator writes (``points.csv`` ...)."""
    reach: ClassVar[str]
    """How the robot takes one reading: ``"configuration"`` (any configuration in which
    the instrument sees the target), ``"sockets"`` (the probe seated in the sockets of a
    placed artifact) or ``"beam"`` (the laser aimed at a surface)."""
    unit_name: ClassVar[str] = "readings"
    """What one planned candidate (and one simulated ``--rows``) is, plural."""
    reading_name: ClassVar[str] = "reading"
    """What one row of the data table is, in the instrument's words (singular)."""

    @classmethod
    def table_rows_per_unit(cls, sockets: int, touches: int) -> int:
        """Rows of a simulated table per unit (``unit_name``): one reading a row; an
        artifact placement has ``sockets`` sockets touched ``touches`` times each."""
        return 1
    error_title: ClassVar[str]
    """What one entry of ``errors`` is called in the report."""
    measured_columns: ClassVar[tuple[str, ...]] = ()
    """Table columns the operator fills in when running a plan."""
    placement_shared: ClassVar[bool] = True
    """True: the placement unknowns are common to all rows; False: each unit of data
    (``residual_groups``) has its own, and the planner projects them out per candidate."""
    separable: ClassVar[bool] = False
    """True: the residual is exactly ``row_residual`` of every row, in row order, so the
    engine may evaluate it row by row in compiled code."""
    pool_size: ClassVar[tuple[int, int]] = (300, 10)
    """Feasible candidates the planner draws for a plan of ``count``: ``max(a, b count)``."""
    sphere: ClassVar[bool] = False
    """True: the placement is a sphere's centre [m] (base frame) of radius
    ``dataset.radius``; the report and ``result.json`` list the fitted spheres."""
    instrument_name: ClassVar[str] = "instrument"
    """The instrument in a person's words (``the tracker's noise``)."""
    default_noise: ClassVar[tuple[float, float]] = (1e-5, 0.0)
    """A typical instrument's noise where the dataset declares none: one reading's
    standard deviation per coordinate ``(a [m], b_per_m [m/m])`` (``instruments.noise``)."""
    noise_grows_with_range: ClassVar[bool] = False
    """True: the dataset may declare ``instrument_noise: {a, b_per_m}`` (a tracker)."""

    def __init__(self, dataset, label: str):
        self.dataset = dataset
        self.label = label  # unique among the datasets solved
        self.station: str | None = getattr(dataset, "station", None)

    @property
    def placement_prefix(self) -> str:
        """Prefix of the placement names: the station when the dataset names one (shared
        with the other datasets of that station), else the dataset's label."""
        return station_prefix(self.station) if self.station is not None else self.label

    def follow(self, leader: MeasurementModel) -> MeasurementModel:
        """This model with the reference of the placement unknowns taken from ``leader``,
        a model of the same station whose placement values this one shares (e.g. the
        tracker's reference rotation). Models whose placement needs no reference are
        returned as they are."""
        return self

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({self.label!r}, rows={self.dataset.rows}, "
                f"mounted={len(self.mounted)}, placement={len(self.placement)})")

    @property
    @abstractmethod
    def mounted(self) -> ParameterRegistry:
        """Instrument-on-robot unknowns (shared by name)."""

    @property
    @abstractmethod
    def placement(self) -> ParameterRegistry:
        """Instrument-in-room unknowns (per dataset)."""

    @abstractmethod
    def initial_mounted(self) -> np.ndarray:
        """Nominal values of ``mounted`` from the dataset file [SI]."""

    @abstractmethod
    def initial_placement(self, points: Callable[[np.ndarray], np.ndarray] | None,
                          mounted: np.ndarray) -> np.ndarray:
        """A starting value of ``placement`` without user help.

        ``points(offsets)`` evaluates world positions (3 x N) numerically for the
        current robot (None for data that carry their own flange poses); ``mounted`` are
        the current mounted values.
        """

    def placed(self, points: Callable[[np.ndarray], np.ndarray] | None,
               mounted: np.ndarray) -> tuple[MeasurementModel, np.ndarray]:
        """``(model, values)``: the model a problem solves with (its placement's reference
        set, where it has one) and the starting ``initial_placement`` values."""
        return self, self.initial_placement(points, mounted)

    @abstractmethod
    def residual(self, points: PointsFunction, mounted: ca.MX, placement: ca.MX) -> ca.MX:
        """Residual column [m] (the residuals of the dataset's kind, before any weighting)."""

    @abstractmethod
    def errors(self, residual: np.ndarray) -> np.ndarray:
        """Per-measurement error lengths [m] (the RMS in ``result.json`` is taken over these)."""

    def error_rows(self) -> np.ndarray:
        """For each entry of ``errors``, the data row it belongs to (-1 if none)."""
        return np.full(len(self.errors(np.zeros(self.residual_size()))), -1)

    def error_entries(self) -> list[np.ndarray]:
        """For each entry of ``errors``, the indices of the residual entries it is made of.

        Default: the errors take equal consecutive blocks from the start of the residual
        (entries past the last block, such as a gauge row, belong to no error)."""
        count = len(self.error_rows())
        size = self.residual_size() // max(count, 1)
        return [np.arange(i * size, (i + 1) * size) for i in range(count)]

    component_frame = ""  # frame of 3-D error components ("instrument", "base")

    def error_components(self, residual: np.ndarray) -> np.ndarray:
        """Signed parts of each error (N x 3) [m]: by default the error itself in
        column 0 and NaN after; models with 3-D or signed errors say more."""
        errors = self.errors(residual)
        out = np.full((len(errors), 3), np.nan)
        out[:, 0] = errors
        return out

    def error_terms(self) -> tuple:
        """What each entry of ``errors`` is (``results.ErrorTerm``)."""
        return (ErrorTerm("error"),) * len(self.error_rows())

    @abstractmethod
    def residual_size(self) -> int:
        """Length of the residual column."""

    def certified_entries(self) -> np.ndarray:
        """Mask over the residual of the entries that hold no reading: they compare fitted
        placement unknowns with the instrument's certified geometry (an artifact's known
        distances between sockets located by repeated touches), so they carry no reading
        noise of their own. Default: none."""
        return np.zeros(self.residual_size(), dtype=bool)

    @property
    def instrument_noise(self) -> InstrumentNoise:
        """The noise the dataset declares, else the instrument's typical value."""
        given = getattr(self.dataset, "instrument_noise", None)
        return given if given is not None else InstrumentNoise(*self.default_noise)

    def entry_noise(self) -> np.ndarray:
        """The standard deviation [m] of each residual entry that the instrument's noise
        alone gives: ``a`` on each entry that holds a reading, zero on the certified
        ones. Models whose noise grows with range say more."""
        out = np.full(self.residual_size(), self.instrument_noise.a)
        out[self.certified_entries()] = 0.0
        return out

    def residual_groups(self) -> np.ndarray:
        """For each residual entry, the unit of data it belongs to (-1: none).

        A unit is what is kept or held out together: a data row here; a placement for
        artifacts (their sockets are per placement). Used by data selection and by
        cross-validation.
        """
        rows = max(self.dataset.rows, 1)
        size = self.residual_size()
        per_row = size // rows
        groups = np.full(size, -1)
        groups[:rows * per_row] = np.repeat(np.arange(rows), per_row)
        return groups

    def row_units(self) -> np.ndarray:
        """For each data row, the unit of data it belongs to (see ``residual_groups``)."""
        return np.arange(self.dataset.rows)

    def subset(self, groups: np.ndarray):
        """A copy of the dataset with only the given units (see ``residual_groups``)."""
        return dataset_rows(self.dataset, np.isin(np.arange(self.dataset.rows), groups))

    # A model whose residual has the same few entries per data row (each row's entries
    # depending on that row's point only) gives them by ``row_residual``; the planner
    # builds its Jacobian rows from it, and when the residual has nothing else
    # (``separable``) the engine evaluates residual and Jacobian row by row in compiled
    # code. ``row_residual`` returns None for models without such entries. The compiled
    # code is cached by its source, so numbers that depend on the data must come in as
    # ``data`` or ``constants``, never as literals: a literal makes every new dataset
    # compile anew.

    @property
    def per_row(self) -> bool:
        """True when the model gives its residual's entries row by row (``row_residual``)."""
        return type(self).row_residual is not MeasurementModel.row_residual

    def row_residual(self, point, data, mounted, placement, constants):
        """One row's residual entries from its world point ``point`` [m] (CasADi SX).

        ``data`` are the row's own numbers (``row_data``), ``mounted`` and
        ``placement`` this model's unknowns, ``constants`` numbers fixed for the whole
        dataset (``row_constants``). None: the model is not separable.
        """
        return None

    def row_data(self) -> np.ndarray:
        """Per-row numbers the separable residual reads (N x k)."""
        return np.zeros((self.dataset.rows, 0))

    def row_constants(self) -> np.ndarray:
        """Numbers the separable residual reads that are the same for every row (k,)."""
        return np.zeros(0)

    def row_offset(self, data, mounted):
        """The flange-frame point measured in one row (CasADi SX) [m]."""
        return mounted

    def consistent_dataset(self, kinematics, p: np.ndarray, mounted: np.ndarray,
                           placement: np.ndarray):
        """A copy of the dataset whose readings the model fits exactly, or None.

        Identifiability is judged on consistent data: where residuals are not zero, a
        rigid motion of all points also rotates the residual pattern, which looks like
        information but is not. Models whose Jacobian depends on that pattern (touches
        spread around a socket, laser points off the sphere) override this.
        """
        return None

    @property
    def uses_robot(self) -> bool:
        """False when the data carries its own flange poses (pendant readings)."""
        return True

    # ------------------------------------------------------------------ planning

    @abstractmethod
    def nominal_mounted(self) -> np.ndarray:
        """The mounted values the dataset file gives (no fit) [SI]: where a plan is judged."""

    def nominal_placement(self, sockets: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
        """The placement values where a plan is judged [SI]; ``sockets``: socket name ->
        world position [m] of one placed artifact, for models that touch sockets."""
        return np.zeros(len(self.placement))

    def mounted_chart(self, nominal: np.ndarray):
        """``(names, chart)``: minimal coordinates ``delta`` of the mounted unknowns about
        ``nominal``, ``chart(delta)`` the mounted vector (CasADi), ``delta = 0`` at
        ``nominal``. Default: the mounted unknowns themselves."""
        centre = ca.DM(np.asarray(nominal, float).reshape(-1, 1))
        return self.mounted.names, lambda delta: centre + delta

    @classmethod
    def plan_columns(cls, joints: list[str]) -> list[str]:
        """Columns of the table a plan is written as (joint columns given)."""
        return list(joints) + list(cls.measured_columns)

    @classmethod
    def plan_row(cls, pose: int, joints: list[float], point: str | None,
                 socket: np.ndarray | None) -> list:
        """One plan-table row: joints in the file's units, measured columns empty
        (``pose``, ``point``, ``socket`` [file length unit] for models that touch sockets)."""
        return list(joints) + [np.nan] * len(cls.measured_columns)

    @classmethod
    @abstractmethod
    def planned_dataset(cls, dataset, joints: np.ndarray, kinematics, *,
                        pose: np.ndarray | None = None, point: tuple[str, ...] = (),
                        distance: np.ndarray | None = None):
        """``dataset`` with the rows ``joints`` (N x dof) [rad or m] and the readings the
        nominal robot ``kinematics`` would give (``pose``, ``point``: placement and socket
        per row; ``distance`` [m]: the laser readings aimed at)."""
