"""What the fleet reveals: every robot's outcome side by side, the quantities compared
across robots, the robots that stand out, and ``fleet.json``.

Values are SI inside (``FleetSummary``); ``to_json`` writes lengths and angles in the
fleet's units: those of the robot files when all calibrated robots share them, else
metres and radians. Compliance is in rad/Nm whatever the files say.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..common.output import json_safe as _clean
from ..common.units import ANGLE_SCALE, LENGTH_SCALE, SI, Units
from .outliers import FLOOR, LIMIT, MAD_TO_SD, MIN_ROBOTS, Finding, Move, Spread, high_outliers
from .robot_task import RobotOutcome
from .spec import Fleet

# (key in a summary's RMS block, label, judged): the errors before and after calibration.
RMS_QUANTITIES = (("fit", "rms_nominal", "fit RMS before calibration (nominal robot)", False),
                  ("fit", "rms_final", "fit RMS after calibration", True),
                  ("validation", "rms_nominal", "validation RMS before calibration", False),
                  ("validation", "rms_final", "validation RMS after calibration", True))


@dataclass(frozen=True)
class Quantity:
    """One quantity across the fleet: ``values`` robot -> (value, standard error or None)
    in SI of ``kind`` (``length`` [m], ``angle`` [rad], ``compliance`` [rad/Nm]);
    ``judged`` quantities have a ``spread`` and ``findings``; ``changes`` marks the
    offset changes since an earlier run (judged robot by robot, see ``outliers.Move``)."""

    key: str
    label: str
    kind: str
    values: Mapping[str, tuple[float, float | None]]
    judged: bool
    spread: Spread | None = None
    findings: tuple[Finding, ...] = ()
    changes: bool = False


@dataclass(frozen=True)
class FleetSummary:
    """The outcome of a fleet run: each robot's ``outcomes`` (the fleet file's order),
    the ``quantities`` compared, the joint offsets that ``moves`` (all compared; those
    with ``moved`` set stand out), and the robots' previous parameters where given."""

    fleet: Fleet
    outcomes: tuple[RobotOutcome, ...]
    quantities: tuple[Quantity, ...]
    moves: tuple[Move, ...] = ()
    previous: str | None = None
    missing_previous: tuple[str, ...] = ()
    units: Units = SI

    @property
    def failed(self) -> list[RobotOutcome]:
        return [o for o in self.outcomes if not o.ok]

    @property
    def findings(self) -> list[Finding]:
        return [f for q in self.quantities for f in q.findings]

    @property
    def moved(self) -> list[Move]:
        return [m for m in self.moves if m.moved]

    @property
    def judged(self) -> bool:
        """Whether the fleet had enough robots to estimate its spread (``MIN_ROBOTS``)."""
        return sum(o.summary is not None for o in self.outcomes) >= MIN_ROBOTS

    @property
    def note(self) -> str:
        """What a reader must know about the comparison ('' when the robots were judged)."""
        if self.judged:
            return ""
        count = sum(o.summary is not None for o in self.outcomes)
        return (f"{count} robot{'s' if count != 1 else ''} with results: at least {MIN_ROBOTS} "
                "are needed to estimate the fleet's spread, so no robot is judged against the "
                "others" + ("; joint offsets are still compared with the previous run"
                            if self.previous else ""))

    @property
    def standing_out(self) -> list[str]:
        """Names of the robots that stand out on any quantity or moved, in fleet order."""
        names = {f.robot for f in self.findings} | {m.robot for m in self.moved}
        return [o.name for o in self.outcomes if o.name in names]

    def count(self, status: str) -> int:
        return sum(o.status == status for o in self.outcomes)

    # ------------------------------------------------------------------ units at the edge

    def scale(self, kind: str) -> float:
        """SI per fleet unit of ``kind``."""
        return {"length": self.units.length_scale, "angle": self.units.angle_scale}.get(kind, 1.0)

    def unit(self, kind: str) -> str:
        return {"length": self.units.length, "angle": self.units.angle,
                "compliance": "rad/Nm"}.get(kind, "")

    def reasons(self) -> list[dict]:
        """Every finding and every moved offset, as fleet.json lists them."""
        out = []
        labels = {q.key: q for q in self.quantities}
        for finding in self.findings:
            quantity = labels[finding.quantity]
            s, unit = self.scale(quantity.kind), self.unit(quantity.kind)
            out.append({
                "robot": finding.robot, "quantity": finding.quantity, "label": quantity.label,
                "value": finding.value / s, "median": finding.median / s,
                "robust_sd": finding.robust_sd / s, "score": finding.score, "unit": unit,
                "reason": (f"{quantity.label} {_number(finding.value / s)}{_unit(unit)} is "
                           f"{_score(finding.score)} standard deviations above the fleet "
                           f"median {_number(finding.median / s)}{_unit(unit)} (the fleet's "
                           f"robust spread {_number(finding.robust_sd / s)}{_unit(unit)} "
                           "combined with the noise of the robots' own values)")})
        for move in self.moved:
            s, unit = self.scale(move.quantity), self.unit(move.quantity)
            out.append({
                "robot": move.robot, "quantity": f"offset_change.{move.name}",
                "label": f"change of joint {move.joint}'s offset {move.name}",
                "value": move.change / s, "before": move.before / s, "now": move.now / s,
                "std": math.hypot(move.now_std, move.before_std) / s, "score": move.score,
                "unit": unit,
                "reason": (f"joint {move.joint}'s offset {move.name} moved by "
                           f"{_number(move.change / s)} {unit} since the previous run "
                           f"({_score(move.score)} standard errors)")})
        order = {name: k for k, name in enumerate(o.name for o in self.outcomes)}
        return sorted(out, key=lambda r: (order[r["robot"]], -r["score"]))

    def to_json(self) -> dict:
        """The content of ``fleet.json``."""
        reasons = self.reasons()
        by_robot: dict[str, list[str]] = {}
        for reason in reasons:
            by_robot.setdefault(reason["robot"], []).append(reason["quantity"])
        return _clean({
            "fleet": str(self.fleet.path),
            "units": {**self.units.as_dict(), "compliance": "rad/Nm"},
            "counts": {"robots": len(self.outcomes), "calibrated": self.count("calibrated"),
                       "unchanged": self.count("unchanged"), "failed": self.count("failed"),
                       "standing_out": len(self.standing_out)},
            "rule": {"limit": LIMIT, "robust_sd_per_mad": MAD_TO_SD, "relative_floor": FLOOR,
                     "min_robots": MIN_ROBOTS, "judged": self.judged, "note": self.note,
                     "text": (f"with at least {MIN_ROBOTS} robots, a robot stands out on a "
                              f"quantity when it lies more than {LIMIT:g} standard deviations "
                              "above the fleet median: the robust spread (1.4826 x the median "
                              "absolute deviation over the fleet) combined with the standard "
                              "error of the robot's own value and the fleet's typical one (for "
                              "an RMS error, what the noise of the robot's own fit leaves "
                              "uncertain), so no difference the noise explains is flagged; a "
                              f"joint offset moved when it changed by more than {LIMIT:g} "
                              "combined standard errors since the previous run")},
            "previous": self.previous,
            "failed": [{"robot": o.name, "error": o.error} for o in self.failed],
            "standing_out": reasons,
            "quantities": [self._quantity_json(q) for q in self.quantities],
            "robots": [self._robot_json(o, by_robot.get(o.name, [])) for o in self.outcomes],
        })

    def _quantity_json(self, quantity: Quantity) -> dict:
        s = self.scale(quantity.kind)
        entry = {"key": quantity.key, "label": quantity.label, "unit": self.unit(quantity.kind),
                 "judged": quantity.judged or quantity.changes,
                 "values": {name: {"value": value / s,
                                   "std": None if std is None else std / s}
                            for name, (value, std) in quantity.values.items()}}
        if quantity.spread is not None:
            entry.update(median=quantity.spread.median / s,
                         robust_sd=quantity.spread.robust_sd / s,
                         noise=quantity.spread.noise / s,
                         threshold=quantity.spread.threshold / s, count=quantity.spread.count)
            entry["judged"] = entry["judged"] and (quantity.spread.judged or quantity.changes)
        return entry

    def _robot_json(self, outcome: RobotOutcome, flags: list[str]) -> dict:
        robot = next(r for r in self.fleet.robots if r.name == outcome.name)
        entry: dict[str, Any] = {
            "name": outcome.name, "status": outcome.status, "error": outcome.error,
            "folder": outcome.name + "/",
            "datasets": [str(p) for p in robot.datasets],
            "validate": [str(p) for p in robot.validate],
            "standing_out": flags, "warnings": list(outcome.warnings),
            "seconds": outcome.seconds, "cpu_seconds": outcome.cpu_seconds,
            "worker": outcome.worker, "memory": outcome.memory,
            "peak_memory": outcome.peak_memory, "finished": outcome.finished}
        summary = outcome.summary
        if summary is None:
            return entry
        length = self.units.length_scale
        for block in ("fit", "validation"):
            rms = summary.get(block)
            entry[block] = None if rms is None else {
                "unit": self.units.length, **{k: v / length for k, v in rms.items()}}
        entry["effects"] = summary.get("effects", [])
        entry["recommended"] = summary.get("recommended")
        entry["delivered_model"] = summary.get("delivered_model")
        predicted = summary.get("predicted_accuracy")
        entry["predicted_accuracy"] = None if predicted is None else {
            "unit": self.units.length, **{k: _scaled(v, length) for k, v in predicted.items()}}
        entry["joint_offsets"] = {
            name: {"name": o["name"], "unit": self.unit(o["quantity"]),
                   "estimate": o["estimate"] / self.scale(o["quantity"]),
                   "std": None if o["std"] is None else o["std"] / self.scale(o["quantity"]),
                   "identifiable": o["identifiable"]}
            for name, o in summary.get("joint_offsets", {}).items()}
        if self.previous is not None:
            entry["previous_found"] = outcome.name not in self.missing_previous
        return entry


def _scaled(value, length: float):
    """A length [m], or a list of them (a band), or None, in the fleet's length unit."""
    if value is None:
        return None
    if isinstance(value, (list, tuple)):
        return [v / length for v in value]
    return value / length


def _number(value: float) -> str:
    return f"{value:.4g}"


def _unit(unit: str) -> str:
    """`` unit`` after a number; nothing for a dimensionless quantity (a share)."""
    return f" {unit}" if unit else ""


def _score(score: float) -> str:
    return "infinitely many" if math.isinf(score) else f"{score:.1f}"


# ----------------------------------------------------------------------------- previous run


def previous_parameters(folder: Path) -> dict[str, tuple[float, float | None]] | None:
    """A robot's parameters from an earlier run's ``result.json`` in ``folder``: name ->
    (estimate, standard error or None) in SI; None when there is no readable result."""
    try:
        content = json.loads((folder / "result.json").read_text())
        rows = content["parameters"]
        out = {}
        for row in rows:
            unit = row.get("unit", "")
            scale = LENGTH_SCALE.get(unit) or ANGLE_SCALE.get(unit) or 1.0
            std = row.get("std")
            usable = row.get("identifiable", True) and std is not None
            out[str(row["name"])] = (float(row["estimate"]) * scale,
                                     float(std) * scale if usable else None)
        return out
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


def offset_moves(outcomes: Sequence[RobotOutcome],
                 previous: Mapping[str, Mapping[str, tuple[float, float | None]]]
                 ) -> list[Move]:
    """Each calibrated robot's joint offsets compared with the earlier run's, where both
    runs identified them."""
    moves = []
    for outcome in outcomes:
        before = previous.get(outcome.name)
        if outcome.summary is None or before is None:
            continue
        for joint, offset in outcome.summary.get("joint_offsets", {}).items():
            old = before.get(offset["name"])
            if (old is None or old[1] is None or offset["std"] is None
                    or not offset["identifiable"]):
                continue
            moves.append(Move(robot=outcome.name, joint=int(joint), name=offset["name"],
                              quantity=offset["quantity"], before=old[0], before_std=old[1],
                              now=offset["estimate"], now_std=offset["std"]))
    return moves


# ----------------------------------------------------------------------------- the summary


def _fleet_units(outcomes: Sequence[RobotOutcome]) -> Units:
    found = {tuple(sorted(o.summary["units"].items())) for o in outcomes if o.summary}
    if len(found) == 1:
        units = dict(next(iter(found)))
        return Units(units["length"], units["angle"])
    return SI


def summarise(fleet: Fleet, outcomes: Sequence[RobotOutcome], *,
              previous: Mapping[str, Mapping[str, tuple[float, float | None]]] | None = None,
              previous_folder: str | None = None) -> FleetSummary:
    """Compare the robots of a finished run (``outcomes`` in the fleet file's order) and,
    with ``previous`` (robot -> ``previous_parameters``), their joint offsets with the
    earlier run's."""
    good = [o for o in outcomes if o.summary is not None]
    summaries = {o.name: o.summary for o in outcomes if o.summary is not None}
    quantities: list[Quantity] = []
    for block, key, label, judged in RMS_QUANTITIES:
        values = {name: (summary[block][key], (summary.get(f"{block}_std") or {}).get(key))
                  for name, summary in summaries.items() if summary.get(block) is not None}
        if values:
            quantities.append(_judged(f"{block}.{key}", label, "length", values, judged))
    rejected = {name: summary["rejected"] for name, summary in summaries.items()
                if summary.get("rejected") is not None}
    if rejected:
        quantities.append(_rejections(rejected))
    joints = sorted({int(j) for summary in summaries.values()
                     for j in summary.get("compliance", {})})
    for joint in joints:
        values = {}
        for name, summary in summaries.items():
            entry = summary.get("compliance", {}).get(str(joint))
            # A robot whose diagnosis found no compliance at this joint has none to speak of.
            values[name] = (entry["value"], entry["std"]) if entry else (0.0, None)
        quantities.append(_judged(f"compliance.c{joint}", f"compliance of joint {joint} (c{joint})",
                                  "compliance", values, True))
    moves = offset_moves(good, previous or {})
    for name in sorted({m.name for m in moves}, key=lambda n: (len(n), n)):
        chosen = [m for m in moves if m.name == name]
        quantities.append(Quantity(
            key=f"offset_change.{name}",
            label=f"change of the offset {name} since the previous run",
            kind=chosen[0].quantity,
            values={m.robot: (m.change, math.hypot(m.now_std, m.before_std)) for m in chosen},
            judged=False, changes=True))
    missing = tuple(o.name for o in good if previous is not None and o.name not in previous)
    return FleetSummary(fleet=fleet, outcomes=tuple(outcomes), quantities=tuple(quantities),
                        moves=tuple(moves), previous=previous_folder, missing_previous=missing,
                        units=_fleet_units(good))


REJECTED_SHARE = 0.01  # a robot with more of its readings set aside as gross errors, and
# standing out from the fleet, is flagged


def _rejections(rejected: dict[str, dict]) -> Quantity:
    """The share of each robot's readings set aside as gross errors; a robot stands out
    above the fleet's spread (``high_outliers``) and above ``REJECTED_SHARE``.

    Each share's standard error is the binomial one of its count at the fleet's pooled
    rate, ``sqrt(p (1 - p) / n)`` (``n`` the robot's readings, ``p`` all robots' readings
    set aside over all their readings): in a fleet where most robots lose none, one
    reading of a hundred is what the common rate gives, not a robot standing out."""
    counted = {name: r for name, r in rejected.items() if r.get("of")}
    total = sum(r["of"] for r in counted.values())
    rate = sum(r["readings"] for r in counted.values()) / total if total else None
    values = {name: (r["share"], None if rate is None or name not in counted else
                     math.sqrt(rate * (1.0 - rate) / counted[name]["of"]))
              for name, r in rejected.items()}
    spread, findings = high_outliers("rejected.share", values)
    return Quantity(key="rejected.share", label="share of the readings set aside as gross errors",
                    kind="share", values=values, judged=True, spread=spread,
                    findings=tuple(f for f in findings if f.value > REJECTED_SHARE))


def _judged(key: str, label: str, kind: str, values: dict, judged: bool) -> Quantity:
    spread, findings = high_outliers(key, values)
    return Quantity(key=key, label=label, kind=kind, values=values, judged=judged,
                    spread=spread, findings=tuple(findings) if judged else ())
