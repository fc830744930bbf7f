"""A fleet that learns its prior as it goes (``robocal fleet --learn-prior``).

Every robot is first calibrated with the tolerance prior into ``DIR/tolerance-prior/<name>/``;
from those results the population prior of all robots is written to ``DIR/prior.yaml``
and, for each robot, the prior of the others (leave one out: a robot never confirms
itself) to ``DIR/priors/<name>.yaml``; then every robot is calibrated again with its own
leave-one-out prior into ``DIR/<name>/``. ``changes`` compares the two results per robot
for ``fleet.json`` and ``fleet.html``.
"""

from __future__ import annotations

import html
import json
import math
import shutil
from pathlib import Path

from ..calibration.population_prior import learn, read_calibration, save_prior
from ..errors import InputError

FIRST_PASS = "tolerance-prior"  # subfolder of the calibrations with the tolerance prior
PRIORS = "priors"  # subfolder of the leave-one-out priors
PRIOR_FILE = "prior.yaml"
MIN_ROBOTS = 3  # a leave-one-out prior needs at least two other robots


def learn_priors(out: Path, names: list[str]) -> list[str]:
    """``DIR/prior.yaml`` from every robot of ``names`` calibrated in the first pass and a
    leave-one-out prior per robot in ``DIR/priors/``; returns the robots the population
    came from. A robot the first pass could not calibrate (measured too briefly for the
    tolerance prior, say) is given the prior of all the others, which may calibrate it."""
    first = Path(out) / FIRST_PASS
    calibrations = {n: read_calibration(first / n) for n in names
                    if (first / n / "result.json").is_file()}
    if len(calibrations) < MIN_ROBOTS:
        raise InputError(f"a fleet prior needs at least {MIN_ROBOTS} calibrated robots, got "
                         f"{len(calibrations)}", where="--learn-prior")
    save_prior(learn(list(calibrations.values())), Path(out) / PRIOR_FILE)
    folder = Path(out) / PRIORS
    folder.mkdir(exist_ok=True)
    for name in calibrations:
        others = [c for other, c in calibrations.items() if other != name]
        save_prior(learn(others), folder / f"{name}.yaml")
    for name in names:
        if name not in calibrations:
            shutil.copyfile(Path(out) / PRIOR_FILE, folder / f"{name}.yaml")
    return list(calibrations)


def changes(out: Path, names: list[str]) -> list[dict]:
    """Per robot, what the fleet prior changed: which prior was used, whether the robot
    belongs, the predicted work-cell RMS and the held-out RMS with each prior (file
    length unit), and the largest change of an estimate in its standard errors."""
    rows = []
    for name in names:
        before = _result(Path(out) / FIRST_PASS / name)
        after = _result(Path(out) / name)
        if after is None:
            continue
        # before None: the tolerance prior could not calibrate it, the fleet's could
        prior = after.get("prior") or {}
        row = {"robot": name, "source": prior.get("source"), "belongs": prior.get("belongs"),
               "unit": after["fit"]["unit"],
               "predicted_rms": [None if before is None else
                                 _rms(before.get("predicted_accuracy")),
                                 _rms(after.get("predicted_accuracy"))],
               "validation_rms": [None if before is None else _validation(before),
                                  _validation(after)]}
        row.update({"moved": None, "moved_by_std": None} if before is None
                   else _largest_move(before, after))
        rows.append(row)
    return rows


def _result(folder: Path) -> dict | None:
    path = folder / "result.json"
    return json.loads(path.read_text()) if path.is_file() else None


def _rms(block: dict | None) -> float | None:
    return None if not block else block.get("rms")


def _validation(result: dict) -> float | None:
    block = result.get("validation")
    return None if not block else block.get("rms_geometric")


def _largest_move(before: dict, after: dict) -> dict:
    """The estimate that moved most, in the first pass's standard errors (none where no
    estimate moved: a robot calibrated with the tolerance prior again)."""
    first = {p["name"]: p for p in before["parameters"]}
    best = {"moved": None, "moved_by_std": None}
    for entry in after["parameters"]:
        old = first.get(entry["name"])
        if old is None or not old.get("std"):
            continue
        score = abs(entry["estimate"] - old["estimate"]) / old["std"]
        if score > (best["moved_by_std"] or 0.0):
            best = {"moved": entry["name"], "moved_by_std": score}
    return best


def table_html(rows: list[dict]) -> str:
    """The section of ``fleet.html`` that shows what the fleet prior changed."""
    def number(value) -> str:
        return "" if value is None or not math.isfinite(value) else f"{value:.4g}"

    parts = ["<h2 id='fleet-prior'>What the fleet prior changed</h2>",
             "<p>Each robot calibrated again with the prior learned from the others (leave one "
             "out); a robot whose data contradict it keeps the tolerance prior. Predicted: the "
             "work-cell RMS predicted for the delivered model; held-out: the validation RMS "
             "of the geometric model.</p>",
             "<table><tr><th>robot</th><th>prior used</th><th>belongs</th>"
             "<th class='num'>predicted, tolerance</th><th class='num'>predicted, fleet</th>"
             "<th class='num'>held-out, tolerance</th><th class='num'>held-out, fleet</th>"
             "<th>largest change of an estimate</th></tr>"]
    for row in rows:
        unit = html.escape(str(row["unit"]))
        moved = "none" if row["moved"] is None else \
            f"{html.escape(row['moved'])}: {row['moved_by_std']:.3g} standard errors"
        if row["predicted_rms"][0] is None and row["validation_rms"][0] is None:
            moved = "refused with the tolerance prior alone: calibrated only with the fleet's"
        source = "fleet" if row["source"] not in (None, "tolerance") else "tolerance"
        parts.append(
            f"<tr><td><a href='{html.escape(row['robot'])}/'>{html.escape(row['robot'])}</a>"
            f"</td><td>{source}</td><td>{'yes' if row['belongs'] else 'NO'}</td>"
            + "".join(f"<td class='num'>{number(v)}{' ' + unit if v is not None else ''}</td>"
                      for v in (*row["predicted_rms"], *row["validation_rms"]))
            + f"<td>{moved}</td></tr>")
    parts.append("</table>")
    return "".join(parts)
