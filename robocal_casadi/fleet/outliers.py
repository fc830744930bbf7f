"""Which robots stand out from the fleet: a robust rule over one quantity at a time.

For a quantity with one value per robot (an RMS error, a joint's compliance), the
fleet's centre is the median ``m`` and its spread the robust standard deviation
``s = 1.4826 * median(|x - m|)`` (the median absolute deviation, scaled to equal the
standard deviation for normally distributed values), so a few outlying robots cannot
hide themselves by inflating the spread. A robot stands out when

    score = (x - m) / sqrt(s^2 + sigma^2 + sigma_m^2 + (FLOOR * |m|)^2) > LIMIT

with ``sigma`` the standard error of the robot's own value (for an RMS error, what the
noise of its own fit leaves uncertain; 0 where it has none), ``sigma_m`` the typical
(median) standard error of the fleet's values, which the median carries too, and
``FLOOR`` a small relative spread that keeps a fleet of nearly identical robots from
turning a hair's difference into an outlier. So no robot is flagged on a difference that
the noise of the robots' own fits explains, however tight the fleet happens to be. Only
values far ABOVE the fleet count: a compliance or an error far below the others is no
fault.

A spread needs robots to be estimated from: with fewer than ``MIN_ROBOTS`` values, the
median absolute deviation is the distance to the nearest neighbour or little more (with
three robots, the smaller of two differences, which chance alone often makes tiny), so no
robot is judged against the others (``Spread.judged`` is False) and the fleet says so.

A joint offset moved since an earlier run when ``|now - before| > LIMIT * sqrt(sigma_now^2
+ sigma_before^2)``: the robot compared with itself, beyond both standard errors (no
fleet spread is needed for that).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

MAD_TO_SD = 1.4826  # robust sd per median absolute deviation (normal values)
LIMIT = 5.0  # scores above this stand out
FLOOR = 0.01  # relative spread always allowed around the median
MIN_ROBOTS = 5  # values needed before a fleet's spread is estimated (module docstring)


@dataclass(frozen=True)
class Spread:
    """The fleet's median and robust standard deviation of one quantity (its unit), the
    ``count`` of values they come from and the values' typical standard error ``noise``
    (0 when none has one)."""

    median: float
    robust_sd: float
    count: int
    noise: float = 0.0

    @property
    def judged(self) -> bool:
        """Whether there are enough values to estimate a spread (``MIN_ROBOTS``)."""
        return self.count >= MIN_ROBOTS

    def score(self, value: float, std: float | None = None) -> float:
        """How far ``value`` lies above the median, in combined standard deviations
        (infinite for a value above a fleet with no spread and no noise at all)."""
        scale = math.sqrt(self.robust_sd ** 2 + (std or 0.0) ** 2 + self.noise ** 2
                          + (FLOOR * abs(self.median)) ** 2)
        excess = value - self.median
        if scale == 0.0:
            return math.inf if excess > 0 else 0.0
        return excess / scale

    @property
    def threshold(self) -> float:
        """The value above which a robot with the typical standard error stands out."""
        return self.median + LIMIT * math.sqrt(self.robust_sd ** 2 + 2.0 * self.noise ** 2
                                               + (FLOOR * self.median) ** 2)


def spread(values: Sequence[float], stds: Sequence[float | None] = ()) -> Spread:
    """Median and robust standard deviation of the finite ``values``; ``noise`` the median
    of the finite standard errors ``stds`` (0 when there are none)."""
    data = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    errors = [e for e in stds if e is not None and math.isfinite(e)]
    noise = float(np.median(errors)) if errors else 0.0
    if data.size == 0:
        return Spread(math.nan, math.nan, 0, noise)
    median = float(np.median(data))
    return Spread(median, MAD_TO_SD * float(np.median(np.abs(data - median))), int(data.size),
                  noise)


@dataclass(frozen=True)
class Finding:
    """One robot standing out on one quantity: its ``value`` and the fleet's ``median``
    and ``robust_sd`` (the quantity's unit), and the ``score``."""

    robot: str
    quantity: str
    value: float
    median: float
    robust_sd: float
    score: float


def high_outliers(quantity: str, values: Mapping[str, tuple[float, float | None]]
                  ) -> tuple[Spread, list[Finding]]:
    """The fleet's spread of ``values`` (robot -> (value, standard error or None)) and
    the robots whose score exceeds ``LIMIT``, highest first; none when the fleet is too
    small to estimate a spread (``Spread.judged``)."""
    fleet = spread([v for v, _ in values.values()], [s for _, s in values.values()])
    if not fleet.judged:
        return fleet, []
    found = []
    for robot, (value, std) in values.items():
        if value is None or not math.isfinite(value):
            continue
        score = fleet.score(value, std)
        if score > LIMIT:
            found.append(Finding(robot, quantity, value, fleet.median, fleet.robust_sd, score))
    return fleet, sorted(found, key=lambda f: -f.score)


@dataclass(frozen=True)
class Move:
    """A joint offset that changed since an earlier run: ``before`` and ``now`` with
    their standard errors (SI: [rad] or [m]) and the change in combined standard errors."""

    robot: str
    joint: int
    name: str
    quantity: str
    before: float
    before_std: float
    now: float
    now_std: float

    @property
    def change(self) -> float:
        return self.now - self.before

    @property
    def score(self) -> float:
        scale = math.hypot(self.now_std, self.before_std)
        return math.inf if scale == 0.0 else abs(self.change) / scale

    @property
    def moved(self) -> bool:
        return self.score > LIMIT
