"""A simulated truth read back from its ``truth.yaml`` (``simulate``'s record of what was true).

``read_truth(path)`` gives the true robot, its effects and its mounted instrument, the
noise and the kind, so that ``simulate --truth truth.yaml`` draws new readings of the same
robot (``simulate.simulate(..., held=...)``). The nominal robot is the ``robot.yaml`` beside
the truth file (``simulate`` writes both into one folder).

``truth_differences(a, b)`` names what differs between two truths (true parameters,
effects, and the mounted instrument where both are of one kind): ``calibrate --validate``
says so when the fit and the held-out data were simulated from different robots
(``truth_beside``: the truth file beside a dataset file).

Lengths and angles in the file are in its ``units``, effect parameters in SI; everything
here is SI.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..common.fields import check_keys, mapping, number, require, vector
from ..common.units import Units, units_of
from ..effects import EFFECTS
from ..errors import InputError
from ..model.robot import Robot, load_robot
from . import kinds

TRUTH_FILE = "truth.yaml"
NOMINAL_FILE = "robot.yaml"
KEYS = ("kind", "seed", "units", "noise", "reference_temperature", "robot", "parameter_errors",
        "mounted", "placement", "effects", "payload_com", "errors_drawn")
DIRECTIONS = ("laser_direction",)  # mounted entries that are unit vectors, not lengths
SAME = 1e-12  # relative: two truths read from files in different units still agree this well


@dataclass(frozen=True)
class HeldTruth:
    """A truth file's content in SI but for ``parameters`` (every true geometric parameter
    by name) and ``parameter_errors`` (true minus nominal), in the file's ``units`` until a
    robot's registry tells lengths from angles (``si``), ``mounted`` (the true
    instrument on the flange [m], ``laser_direction`` a unit vector), ``effects`` (name ->
    ``{"joints", "parameters", ...}`` as ``Effect.truth_dict`` writes it, SI),
    ``noise`` [m], ``payload_com`` [m] or None, ``errors_drawn`` (whether the geometric
    errors were drawn from the seed's random stream)."""

    path: Path
    kind: str
    seed: int
    units: Units
    noise: float
    reference_temperature: float
    parameters: Mapping[str, float]
    parameter_errors: Mapping[str, float]
    mounted: Mapping[str, np.ndarray]
    effects: Mapping[str, Mapping[str, Any]]
    payload_com: np.ndarray | None
    errors_drawn: bool

    def nominal(self) -> Robot:
        """The nominal robot written beside the truth file (``robot.yaml``)."""
        path = self.path.parent / NOMINAL_FILE
        if not path.is_file():
            raise InputError(f"no {NOMINAL_FILE} beside the truth file: simulate writes the "
                             "nominal robot there, and the truth's parameters belong to it",
                             file=self.path)
        return load_robot(path)

    def si(self, values: Mapping[str, float], registry) -> dict[str, float]:
        """``values`` (file units, by parameter name) in SI by ``registry``'s quantities;
        names the registry does not know are kept as read."""
        return {n: v * (self.units.scale(registry.quantity(n)) if n in registry else 1.0)
                for n, v in values.items()}

    def true_robot(self, nominal: Robot) -> Robot:
        """``nominal`` with the truth's parameters (every one of its names must be given)."""
        registry = nominal.parameters()
        missing = [n for n in registry.names if n not in self.parameters]
        extra = [n for n in self.parameters if n not in registry]
        if missing or extra:
            raise InputError(f"the true parameters do not fit {NOMINAL_FILE} "
                             f"(missing {missing}, unknown {extra})", file=self.path,
                             where="robot")
        values = self.si(self.parameters, registry)
        return nominal.with_parameters(np.array([values[n] for n in registry.names]))


def read_truth(path: str | Path) -> HeldTruth:
    """The truth file at ``path``; a malformed one is an ``InputError`` naming the key."""
    path = Path(path)
    try:
        content = yaml.safe_load(path.read_text())
    except yaml.YAMLError as error:
        raise InputError(f"not valid YAML ({' '.join(str(error).split())[:200]})",
                         file=path) from None
    content = mapping(content, file=path, where="")
    check_keys(content, KEYS, file=path, where="")
    kind = require(content, "kind", file=path)
    if kind not in kinds():
        raise InputError(f"unknown kind {kind!r}; expected one of {list(kinds())}", file=path,
                         where="kind")
    units = units_of(content, file=path)
    L = units.length_scale
    seed = require(content, "seed", file=path)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise InputError(f"expected a non-negative whole number, got {seed!r}", file=path,
                         where="seed")
    noise = number(require(content, "noise", file=path), file=path, where="noise") * L
    if not noise >= 0:
        raise InputError("must not be negative", file=path, where="noise")
    return HeldTruth(
        path=path, kind=kind, seed=seed, units=units, noise=noise,
        reference_temperature=number(content.get("reference_temperature", 20.0), file=path,
                                     where="reference_temperature"),
        parameters=_parameters(content, "robot", path),
        parameter_errors=_parameters(content, "parameter_errors", path),
        mounted=_mounted(content, path, L),
        effects=_effects(content, path),
        payload_com=None if content.get("payload_com") is None else
        np.array(vector(content["payload_com"], 3, file=path, where="payload_com")) * L,
        errors_drawn=bool(content.get("errors_drawn", False)))


def _parameters(content: dict, key: str, path: Path) -> dict[str, float]:
    """Parameters by name, in the file's units (``HeldTruth.si`` converts them)."""
    values = mapping(content.get(key) or {}, file=path, where=key)
    return {str(name): number(value, file=path, where=f"{key}.{name}")
            for name, value in values.items()}


def _mounted(content: dict, path: Path, L: float) -> dict[str, np.ndarray]:
    values = mapping(content.get("mounted") or {}, file=path, where="mounted")
    out = {}
    for name, value in values.items():
        xyz = np.array(vector(value, 3, file=path, where=f"mounted.{name}"), dtype=float)
        out[str(name)] = xyz if name in DIRECTIONS else xyz * L
    return out


def _effects(content: dict, path: Path) -> dict[str, dict[str, Any]]:
    values = mapping(content.get("effects") or {}, file=path, where="effects")
    for name, entry in values.items():
        if name not in EFFECTS:
            raise InputError(f"unknown effect {name!r}; expected one of {list(EFFECTS)}",
                             file=path, where=f"effects.{name}")
        entry = mapping(entry, file=path, where=f"effects.{name}")
        mapping(require(entry, "parameters", file=path, where=f"effects.{name}"), file=path,
                where=f"effects.{name}.parameters")
    return {str(k): dict(v) for k, v in values.items()}


def true_effects_of(truth: HeldTruth, robot: Robot) -> tuple[tuple[Any, dict[str, float]], ...]:
    """The truth's effects as the simulator's ``TrueEffects`` entries, ``(effect, values
    [SI])`` in the registry's order: each rebuilt from its joints (its driving joints for a
    coupling) and checked as ``simulate`` checks its own."""
    entries = []
    for name, entry in truth.effects.items():
        cls = EFFECTS[name]
        where = f"effects.{name}"
        if cls.per == "column":
            keys: list = []
        elif cls.per == "pair":
            drivers = mapping(entry.get("drivers") or {}, file=truth.path,
                              where=f"{where}.drivers")
            keys = [(int(j), int(k)) for j, k in drivers.items()]
        elif cls.per == "group":  # coupled joints: the groups, each a list of joints
            keys = [tuple(int(j) for j in g) for g in entry.get("groups") or []]
        else:
            keys = [int(j) for j in entry.get("joints") or []]
        orders = entry.get("orders")  # a periodic error's harmonics, per joint
        effect = cls.for_simulation(keys) if not isinstance(orders, dict) else \
            cls.create(keys, orders=[list(orders.get(j, ())) for j in keys])
        given = entry["parameters"]
        if set(given) != set(effect.parameter_names()):
            raise InputError(f"expected the parameters {list(effect.parameter_names())}, got "
                             f"{list(given)}", file=truth.path, where=f"{where}.parameters")
        values = {n: number(given[n], file=truth.path, where=f"{where}.parameters.{n}")
                  for n in effect.parameter_names()}
        effect.check_simulation(robot, values)
        entries.append((effect, values))
    order = list(EFFECTS)
    entries.sort(key=lambda item: order.index(item[0].name))
    return tuple(entries)


def truth_beside(dataset_path: str | Path) -> HeldTruth | None:
    """The simulated truth beside a dataset file, or None where there is none (or it cannot
    be read: it is no input of the calibration)."""
    path = Path(dataset_path).parent / TRUTH_FILE
    if not path.is_file():
        return None
    try:
        return read_truth(path)
    except (InputError, OSError, ValueError):
        return None


def truth_differences(a: HeldTruth, b: HeldTruth, registry) -> list[str]:
    """What differs between two truths of robots with parameters ``registry``: true
    parameters, effects (by name and value) and, for truths of one kind, the mounted
    instrument; empty for the same robot."""
    pa_si, pb_si = a.si(a.parameters, registry), b.si(b.parameters, registry)
    out = [name for name in sorted(set(pa_si) | set(pb_si))
           if not _close(pa_si.get(name), pb_si.get(name))]
    for name in sorted(set(a.effects) | set(b.effects)):
        pa = (a.effects.get(name) or {}).get("parameters", {})
        pb = (b.effects.get(name) or {}).get("parameters", {})
        out += [f"{name}.{p}" for p in sorted(set(pa) | set(pb))
                if not _close(pa.get(p), pb.get(p))]
    if a.kind == b.kind:
        out += [f"mounted {name}" for name in sorted(set(a.mounted) | set(b.mounted))
                if name not in a.mounted or name not in b.mounted
                or not np.allclose(a.mounted[name], b.mounted[name], rtol=SAME, atol=1e-15)]
    return out


def _close(x: float | None, y: float | None) -> bool:
    if x is None or y is None:
        return x is None and y is None
    return math.isclose(float(x), float(y), rel_tol=SAME, abs_tol=1e-15)


def held_out_truth_note(fit: list, validation: list) -> str:
    """A sentence when held-out datasets were simulated from another robot than the fit
    datasets (the truth files beside them differ), else ''. ``fit`` and ``validation``
    are loaded datasets (``path``, ``robot``)."""
    found = [(d, truth_beside(d.path)) for d in fit]
    fitted = [(d, t) for d, t in found if t is not None]
    if not fitted:
        return ""
    reference, truth = fitted[0]
    registry = reference.robot.parameters()
    for dataset in validation:
        other = truth_beside(dataset.path)
        if other is None:
            continue
        differs = truth_differences(truth, other, registry)
        if differs:
            shown = ", ".join(differs[:4]) + (f" and {len(differs) - 4} more"
                                              if len(differs) > 4 else "")
            return (f"the held-out data {dataset.path.name} were simulated from another robot "
                    f"than the fit data {reference.path.name} (their {TRUTH_FILE} files differ "
                    f"in {shown}): the validation compares the calibration with a robot it "
                    "was not fitted to; simulate held-out data with --truth "
                    f"{reference.path.parent.name}/{TRUTH_FILE}")
    return ""
