"""Observability indices of an identification Jacobian.

All indices are functions of the singular values ``s_1 >= ... >= s_m`` of the
column-scaled identification Jacobian ``J`` (rows: residuals [m], columns: the ``m``
identifiable parameters, placement unknowns projected out). They are singular values of
``J`` itself, not eigenvalues of ``J^T J``.

Column scaling (``scaling``): the condition number is scale-free only up to the
columns' units, so ``O2`` divides each column by its own norm in the design (the
engine's identifiability does the same, so the numbers agree). ``O1, O3, O4, O5``
measure size as well as shape; with each design's columns normalised they would only
reward balance (the sum of ``s_i^2`` is then always ``m``). They divide each column by
a fixed reference instead: its RMS norm per candidate over the pool of feasible
candidates, so a typical candidate has unit columns and more informative poses score
higher.

* ``O1`` geometric mean ``(prod s_i)^(1/m)`` (maximise; Borm and Menq)
* ``O2`` condition number ``s_max / s_min`` (minimise; Driels and Pathre); alias ``cond``
* ``O3`` smallest singular value ``s_min`` (maximise; Nahvi and Hollerbach)
* ``O4`` noise amplification ``s_min^2 / s_max`` (maximise; Nahvi and Hollerbach)
* ``O5`` ``1 / sum(1 / s_i)`` (maximise; Sun and Hollerbach)
* ``tool`` ``sqrt(sum 1 / s_i^2)`` of ``J L^-T`` (minimise; the default): the predicted
  standard error of the tool position over the workspace per unit reading noise, see
  ``accuracy`` (an I-optimal design; its columns are transformed by ``L^-T``, not scaled)

The condition number rewards balance between parameters, not information: a plan can be
well conditioned and still leave every parameter noisy. ``tool`` asks directly for the
accuracy the calibration will deliver, so it is the default.
"""

from __future__ import annotations

import numpy as np

from robocal_casadi.common.checks import choice

INDICES = ("O1", "O2", "O3", "O4", "O5", "tool")
ALIASES = {"cond": "O2"}
DEFAULT_INDEX = "tool"
DESCRIPTIONS = {
    "O1": "geometric mean of the singular values",
    "O2": "condition number",
    "O3": "smallest singular value",
    "O4": "noise amplification index",
    "O5": "inverse sum of inverse singular values",
    "tool": "predicted tool-position error per unit noise",
}
MAXIMISE = {"O1": True, "O2": False, "O3": True, "O4": True, "O5": True, "tool": False}


def scaling(name: str) -> str:
    """``'design'`` (columns normalised per design) for ``O2``, ``'tool'`` (columns
    transformed by ``L^-T``) for ``tool``, else ``'reference'``."""
    key = canonical(name)
    return {"O2": "design", "tool": "tool"}.get(key, "reference")


def canonical(name: str) -> str:
    """``'cond'`` -> ``'O2'``; other valid names unchanged; anything else raises ValueError."""
    key = ALIASES.get(name, name) if isinstance(name, str) else name
    if key not in INDICES:
        choice(name, ("cond", *INDICES), "index")  # raises, listing the valid names
    return key


def singular_values(J: np.ndarray) -> np.ndarray:
    """Singular values of ``J`` (rows x m), largest first."""
    return np.linalg.svd(np.asarray(J, dtype=float), compute_uv=False)


def scale_columns(J: np.ndarray) -> np.ndarray:
    """``J`` with every non-zero column divided by its Euclidean norm."""
    J = np.asarray(J, dtype=float)
    norms = np.linalg.norm(J, axis=0)
    return J / np.where(norms > 0, norms, 1.0)


def index_value(name: str, s: np.ndarray) -> float:
    """Index ``name`` of singular values ``s`` (any order); ``s_min = 0`` gives the worst value."""
    key = canonical(name)
    s = np.sort(np.asarray(s, dtype=float))[::-1]
    if s.size == 0:
        raise ValueError("no singular values")
    s_max, s_min = float(s[0]), float(s[-1])
    if s_min <= 0.0:
        return np.inf if key in ("O2", "tool") else 0.0
    if key == "O1":
        return float(np.exp(np.mean(np.log(s))))
    if key == "O2":
        return s_max / s_min
    if key == "O3":
        return s_min
    if key == "tool":
        return float(np.sqrt(np.sum(1.0 / s**2)))
    if key == "O4":
        return s_min**2 / s_max
    return float(1.0 / np.sum(1.0 / s))


def index_of_jacobian(name: str, J: np.ndarray, *, scaled: bool = True) -> float:
    """Index ``name`` of ``J``; with ``scaled`` its columns are normalised first."""
    return index_value(name, singular_values(scale_columns(J) if scaled else J))


def maximise(name: str) -> bool:
    """True when a larger value of index ``name`` is better."""
    return MAXIMISE[canonical(name)]


def better(name: str, a: float, b: float) -> bool:
    """True when value ``a`` of index ``name`` is strictly better than ``b``."""
    return a > b if maximise(name) else a < b


def score(name: str, value: float) -> float:
    """A number to maximise for index ``name`` (the value, or minus it for ``O2``, ``tool``)."""
    return value if maximise(name) else -value
