"""What every kind's simulator shares: the run's set-up, what a kind produces, helpers.

``simulate.simulate`` builds a ``Setup`` (the nominal and the true robot, the random
generator, the sizes and options of the run) and hands it to the simulator of the kind's
``Instrument``, which returns a ``Generated``: the joint readings as written, the
measured columns, the extra columns and the truth of what it placed. The readings come
from the true robot by the simulator's own geometry, never from the estimator.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..common import exact
from ..common.progress import Progress
from ..common.units import Units, exact_file_units, snapped
from ..errors import InputError
from ..model.ik import random_joints
from ..model.robot import Robot
from ..model.transforms import matrix_from_quaternion

if TYPE_CHECKING:
    from .simulate import TrueRobot

LIMIT_MARGIN = 0.03  # fraction of each joint range kept free at both ends for configurations


@dataclass(frozen=True)
class RandomRun:
    """Readings at random configurations and what the true robot did there: the joint
    readings ``Q_read`` and true joints ``Q_true`` (rad or m), each row's payload [kg]
    and temperature [C] (None without a drift), the true flange poses (4x4, world, m)."""

    Q_read: np.ndarray
    payloads: list[float]
    temperatures: list[float | None]
    Q_true: np.ndarray
    poses: np.ndarray


@dataclass
class Setup:
    """One simulated run: robots, randomness, sizes and options (see ``simulate``)."""

    kind: str
    nominal: Robot
    world: TrueRobot  # the true robot with its effects
    rng: np.random.Generator
    rows: int
    noise: float
    mounted_error: float
    angle_std: float
    payload: Any
    temperature: tuple[float, float] | None
    readings: str
    bar_length: float
    socket_distance: float
    sockets: int
    touches: int
    sphere_radius: float
    progress: bool
    # the mounted instrument of a held truth (``simulate --truth``), name -> value [m] or unit
    held_mounted: dict[str, np.ndarray] = field(default_factory=dict)
    length_scale: float = 1.0  # [m] per length unit of the truth file

    def payload_value(self) -> float:
        if self.payload is None:
            return 0.0
        if np.ndim(self.payload) == 0:
            return float(self.payload)
        low, high = self.payload
        return float(self.rng.uniform(low, high))

    def temperature_at(self, fraction: float) -> float | None:
        """A slowly drifting temperature [C] at ``fraction`` of the run, with 0.05 C jitter."""
        if self.temperature is None:
            return None
        start, end = self.temperature
        return float(start + (end - start) * fraction + self.rng.normal(0.0, 0.05))

    def random_run(self) -> RandomRun:
        """``rows`` random configurations within the limits (less ``LIMIT_MARGIN``), the
        payload and temperature of each row, and where the true robot's flange went."""
        Q_read = random_joints(self.nominal, self.rows, self.rng, margin=LIMIT_MARGIN)
        payloads = [self.payload_value() for _ in range(self.rows)]
        temperatures = [self.temperature_at(i / max(self.rows - 1, 1))
                        for i in range(self.rows)]
        Q_true = self.world.true_joints(Q_read, np.array(payloads))
        poses = self.world.flange_poses(Q_true, None if self.temperature is None else
                                        np.array(temperatures))
        return RandomRun(Q_read, payloads, temperatures, Q_true, poses)

    def mounted(self, nominal) -> np.ndarray:
        """The true mounted point [m]: ``nominal`` plus a random error, as the truth file
        will state it (``snapped`` to its length unit)."""
        drawn = np.asarray(nominal, dtype=float) + self.rng.normal(0.0, self.mounted_error, 3)
        return np.array([snapped(v, self.length_scale) for v in drawn])

    def keep(self, name: str, drawn: np.ndarray) -> np.ndarray:
        """The true mounted value ``name`` of a held truth (``simulate --truth``), else
        ``drawn``. Drawn either way, so the random stream runs as in the original run."""
        if name in self.held_mounted:
            return np.asarray(self.held_mounted[name], dtype=float).copy()
        return drawn

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Joint limits shrunk by 1e-6 of the range: readings after effects stay inside."""
        lower, upper = self.nominal.lower_limits, self.nominal.upper_limits
        inset = np.where(np.isfinite(upper - lower), 1e-6 * (upper - lower), 0.0)
        inset = inset + self.world.play()  # readings move by up to the play with the order
        return lower + inset, upper - inset

    def in_order(self, Q_read: list, Q_true: list, payloads: list) -> np.ndarray:
        """The readings of the rows in written order: as found row by row, or, with an
        effect of the order of motion (``TrueEffects.order_dependent``), found again in
        that order from the true joints (the direction of each row follows from its reading
        and the previous one)."""
        names = self.world.effects.order_dependent
        if not names:
            return np.array(Q_read)
        out = self.world.readings_in_order(np.array(Q_true), payloads)
        outside = [i for i, q in enumerate(out) if not self.within_limits(q)]
        if outside:
            raise InputError(f"with {', '.join(names)}, row {outside[0] + 1}'s reading leaves "
                             "the joint limits; use smaller values", where=f"effects.{names[0]}")
        return out

    def within_limits(self, q: np.ndarray) -> bool:
        robot = self.nominal
        return bool(np.all(q >= robot.lower_limits) and np.all(q <= robot.upper_limits))


@dataclass
class Generated:
    """What a kind produced: readings, extra columns, measured columns, truth parts."""

    Q_read: np.ndarray
    extras: dict[str, np.ndarray]
    mounted: dict[str, np.ndarray]
    placement: dict[str, Any]
    fields: Callable[[Units], dict]  # dataset-file entries in the given units
    measured: dict[str, np.ndarray] = field(default_factory=dict)  # column -> values [m] or text
    leading: dict[str, Any] = field(default_factory=dict)  # columns before the joints
    pendant: np.ndarray | None = None  # (N, 7) x, y, z [m], qw, qx, qy, qz
    # ``truth.yaml``'s mounted and placement entries in the given units; None: every
    # entry of ``mounted`` and ``placement`` is a position [m]
    written: Callable[[Units], tuple[dict, dict]] | None = None

    def truth_entries(self, units: Units) -> tuple[dict, dict]:
        """``(mounted, placement)`` of ``truth.yaml`` in ``units``."""
        if self.written is not None:
            return self.written(units)
        return ({k: in_units(units, v) for k, v in self.mounted.items()},
                {k: in_units(units, v) for k, v in self.placement.items()})

    def dataset_fields(self, units: Units) -> dict:
        """The dataset file's instrument entries in ``units``."""
        return self.fields(units)

    def table(self, robot: Robot, units: Units) -> tuple[list[str], list[list]]:
        columns: list[str] = list(self.leading)
        data: list[np.ndarray | list] = [self.leading[c] for c in self.leading]
        if self.pendant is not None:
            columns += ["x", "y", "z", "qw", "qx", "qy", "qz"]
            data += [self.pendant[:, k] / units.length_scale for k in range(3)]
            data += [self.pendant[:, k] for k in range(3, 7)]
        else:
            scales = np.array([units.angle_scale if j.revolute else units.length_scale
                               for j in robot.joints])
            columns += [f"q{i}" for i in range(1, robot.dof + 1)]
            data += [self.Q_read[:, i] / scales[i] for i in range(robot.dof)]
        for name, values in self.measured.items():
            columns.append(name)
            data.append(np.asarray(values) / units.length_scale)
        for name, values in self.extras.items():
            columns.append(name)
            data.append(values)
        rows = [[column[i] for column in data] for i in range(len(self.Q_read))]
        return columns, rows


def in_units(units: Units, xyz) -> list[float]:
    """A position [m] as a list in ``units``, each the shortest decimal that reads back to
    the same metres (a truth file read again gives the same truth)."""
    return [exact_file_units(float(v), units.length_scale) for v in xyz]


def run_extras(payloads: list[float], temperatures: list, setup: Setup) -> dict[str, np.ndarray]:
    """The extra columns of the run: ``temperature`` [C] and ``payload`` [kg] where the
    set-up asks for them."""
    extras = {}
    if setup.temperature is not None:
        extras["temperature"] = np.array(temperatures, dtype=float)
    if setup.payload is not None:
        extras["payload"] = np.array(payloads, dtype=float)
    return extras


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random 3x3 rotation (from a random unit quaternion)."""
    q = rng.normal(size=4)
    return matrix_from_quaternion(q / exact.norm(q))


def tilt(rng: np.random.Generator, max_angle: float) -> np.ndarray:
    """A rotation by up to ``max_angle`` [rad] about a random axis (3x3)."""
    axis = rng.normal(size=3)
    axis /= exact.norm(axis)
    angle = rng.uniform(0.0, max_angle)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * exact.matmul(K, K)


def progress_of(setup: Setup):
    """A progress bar over the rows to simulate, or a silent stand-in."""
    return Progress(f"simulate {setup.kind}", total=setup.rows) if setup.progress else _Quiet()


class _Quiet:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return None

    def update(self, *args, **kwargs):
        return None

