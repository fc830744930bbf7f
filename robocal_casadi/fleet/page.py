"""``fleet.html``: the fleet summary as one self-contained page.

Counts, the robots that failed (with their one-line errors), the robots that stand out
and why, one plot per quantity across the robots (PNG embedded as ``data:`` URIs, so the
page needs no other file), and a table of every robot's error before and after and its
effects, each robot linking to its own report.
"""

from __future__ import annotations

import base64
import html
import io
import math

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .summary import FleetSummary, Quantity

STYLE = """
body{font-family:system-ui,sans-serif;margin:2em auto;max-width:70em;color:#222}
h1{font-size:1.5em}h2{font-size:1.2em;margin-top:1.6em;border-bottom:1px solid #ccc}
table{border-collapse:collapse;font-size:.9em}td,th{padding:.2em .6em;border-bottom:1px solid #eee;
text-align:left;vertical-align:top}th{background:#f4f4f4}.failed{color:#a00}.out{color:#b35c00}
figure{margin:1em 0}img{max-width:100%}.num{text-align:right;font-variant-numeric:tabular-nums}
"""
ANNOTATED = 12  # at most this many robots are named in a plot


def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _png(figure: Figure) -> str:
    FigureCanvasAgg(figure)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=100)
    return "data:image/png;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


def quantity_plot(summary: FleetSummary, quantity: Quantity) -> str:
    """One dot per robot (fleet file order), standard errors as bars where known, the
    fleet median and the limit above which a robot stands out; robots that stand out in
    orange and named."""
    order = [o.name for o in summary.outcomes if o.name in quantity.values]
    s, unit = summary.scale(quantity.kind), summary.unit(quantity.kind)
    x = np.arange(len(order))
    y = np.array([quantity.values[n][0] / s for n in order])
    err = np.array([(quantity.values[n][1] or 0.0) / s for n in order])
    if quantity.changes:
        flagged = {m.robot for m in summary.moved if f"offset_change.{m.name}" == quantity.key}
    else:
        flagged = {f.robot for f in quantity.findings}
    mask = np.array([n in flagged for n in order], dtype=bool)
    figure = Figure(figsize=(9, 3.2))
    axes = figure.add_subplot()
    if err.any():
        axes.errorbar(x, y, yerr=err, fmt="none", ecolor="#999", lw=0.8)
    axes.plot(x[~mask], y[~mask], "o", ms=4, color="#1f5fa8", label="robot")
    if mask.any():
        axes.plot(x[mask], y[mask], "o", ms=6, color="#e07000", label="stands out")
    spread = quantity.spread
    if spread is not None and spread.count and not quantity.changes:
        axes.axhline(spread.median / s, color="#444", lw=1, label="fleet median")
        if quantity.judged and math.isfinite(spread.threshold):
            axes.axhline(spread.threshold / s, color="#e07000", lw=1, ls="--",
                         label="stands out above")
    if quantity.changes:
        axes.axhline(0.0, color="#444", lw=1)
    for k in np.flatnonzero(mask)[:ANNOTATED]:
        axes.annotate(order[k], (x[k], y[k]), xytext=(4, 4), textcoords="offset points",
                      fontsize=8, color="#e07000")
    axes.set_ylabel(f"[{unit}]" if unit else "")
    axes.set_xlabel("robot (fleet file order)")
    if len(order) <= 30:
        axes.set_xticks(x, order, rotation=60, fontsize=7, ha="right")
    axes.set_title(quantity.label, fontsize=10)
    axes.legend(fontsize=7, loc="best")
    figure.tight_layout()
    return _png(figure)


def _effects(summary: dict | None) -> str:
    if not summary or not summary.get("effects"):
        return "none"
    parts = []
    for effect in summary["effects"]:
        values = ", ".join(f"{k} = {v:.3g}" for k, v in effect["parameters"].items())
        parts.append(f"{effect['name']} ({values} {effect['unit']})")
    return "; ".join(parts)


def _standing_out(summary: FleetSummary) -> list[str]:
    """The section of the robots that stand out, or why none does (none judged when the
    fleet is too small to estimate its spread)."""
    parts = ["<h2 id='standing-out'>Robots that stand out</h2>"]
    reasons = summary.reasons()
    if reasons:
        parts.append("<table><tr><th>robot</th><th>why</th></tr>")
        parts += [f"<tr class='out'><td><a href='{_e(r['robot'])}/'>{_e(r['robot'])}"
                  f"</a></td><td>{_e(r['reason'])}</td></tr>" for r in reasons]
        parts.append("</table>")
    elif not summary.judged:
        parts.append(f"<p>None judged: {_e(summary.note)}.</p>")
    else:
        parts.append("<p>None: no robot lies far above the fleet on any quantity compared"
                     + (", and no joint offset moved since the previous run" if summary.previous
                        else "") + ".</p>")
    if reasons and not summary.judged:
        parts.append(f"<p>{_e(summary.note[0].upper() + summary.note[1:])}.</p>")
    return parts


def render(summary: FleetSummary, extra: str = "") -> str:
    """The page's HTML; ``extra`` (HTML) is a section added at the end."""
    length = summary.units.length
    s = summary.units.length_scale
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
             f"<title>Fleet calibration: {_e(summary.fleet.path.name)}</title>"
             f"<style>{STYLE}</style></head><body>",
             f"<h1>Fleet calibration: {_e(summary.fleet.path.name)}</h1>",
             f"<p>{len(summary.outcomes)} robots: {summary.count('calibrated')} calibrated, "
             f"{summary.count('unchanged')} unchanged since the last run (not recomputed), "
             f"{summary.count('failed')} failed; {len(summary.standing_out)} stand out.</p>"]
    if summary.failed:
        parts.append("<h2 id='failed'>Failed</h2><table><tr><th>robot</th><th>error</th></tr>")
        parts += [f"<tr class='failed'><td>{_e(o.name)}</td><td>{_e(o.error)}</td></tr>"
                  for o in summary.failed]
        parts.append("</table>")
    parts += _standing_out(summary)
    data = summary.to_json()
    parts.append(f"<p><small>Rule: {_e(data['rule']['text'])}.</small></p>")
    if summary.quantities:
        parts.append("<h2 id='quantities'>Across the fleet</h2>")
        for quantity in summary.quantities:
            parts.append(f"<figure id='plot-{_e(quantity.key)}'><img alt='{_e(quantity.label)}' "
                         f"src='{quantity_plot(summary, quantity)}'></figure>")
    validated = any(o.summary and o.summary.get("validation") for o in summary.outcomes)
    parts.append(f"<h2 id='robots'>Every robot</h2><table><tr><th>robot</th><th>status</th>"
                 f"<th class='num'>fit RMS before [{_e(length)}]</th>"
                 f"<th class='num'>after [{_e(length)}]</th>"
                 + (f"<th class='num'>validation before [{_e(length)}]</th>"
                    f"<th class='num'>after [{_e(length)}]</th>" if validated else "")
                 + "<th>effects</th></tr>")
    flagged = set(summary.standing_out)
    for outcome in summary.outcomes:
        cells = ["", "", "", ""]
        if outcome.summary:
            fit, val = outcome.summary["fit"], outcome.summary.get("validation")
            cells = [f"{fit['rms_nominal'] / s:.4g}", f"{fit['rms_final'] / s:.4g}",
                     f"{val['rms_nominal'] / s:.4g}" if val else "",
                     f"{val['rms_final'] / s:.4g}" if val else ""]
        cells = cells if validated else cells[:2]
        name = _e(outcome.name)
        link = name if not outcome.ok else f"<a href='{name}/'>{name}</a>"
        css = "failed" if not outcome.ok else ("out" if outcome.name in flagged else "")
        status = outcome.status + (" (stands out)" if outcome.name in flagged else "")
        parts.append(f"<tr class='{css}'><td>{link}</td><td>{_e(status)}</td>"
                     + "".join(f"<td class='num'>{c}</td>" for c in cells)
                     + f"<td>{_e(_effects(outcome.summary)) if outcome.ok else _e(outcome.error)}"
                     "</td></tr>")
    parts.append("</table>" + extra + "</body></html>\n")
    return "".join(parts)
