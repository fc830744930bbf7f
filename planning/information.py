"""Information of candidate blocks and the spectra of designs made of them.

The design's Jacobian stacks the candidates' blocks ``X = [G S]``; its shared placement
columns ``S`` are projected out, the identifiable parameter columns kept and each scaled
to unit norm. Its singular values come exactly from an SVD (``spectrum``) or, for the
thousands of trial designs of a search, from the eigenvalues of the Schur complement of
the summed information ``sum X^T X`` (``spectra``, batched): the same numbers, squared.
The identifiable parameters are judged once on the whole pool of candidates by the
engine's rule (``robocal_casadi.calibration.identifiability.analyse``), so a plan is scored over the
same parameters the calibration will estimate.
"""

from __future__ import annotations

import numpy as np

from robocal_casadi.calibration.identifiability import EXACT_TOLERANCE, analyse
from robocal_casadi.common import exact

from .accuracy import tool_transform
from .rows import Block

NEGLIGIBLE = 1e-7  # relative column norm counted as no effect



class Information:
    """Per-candidate information matrices restricted to identifiable + shared columns.

    ``tolerance``: the smallest own part of a parameter's effect over the pool that counts
    as identifiable (default the engine's practical rule; ``EXACT_TOLERANCE`` keeps every
    parameter that is not exactly unidentifiable, as the condition index ``O2`` is judged).
    """

    def __init__(self, blocks: list[Block], parameters: tuple[str, ...], shared: int,
                 tool_weights: np.ndarray | None = None, tolerance: float | None = None):
        self.parameters = parameters
        self.shared = shared
        n_par = len(parameters)
        # common.exact (rows summed in order): the search's choices and the refinement
        # start from these sums
        full = np.array([exact.gram(b.X) for b in blocks])  # C x n x n
        X = np.vstack([b.X for b in blocks])
        # Touches reach their sockets to the IK tolerance (1e-9 m) only, so a column that
        # the local socket unknowns absorb keeps a remainder of that order: treat columns
        # below NEGLIGIBLE of the largest as changing nothing.
        norms = np.linalg.norm(X[:, :n_par], axis=0)
        X[:, :n_par][:, norms < NEGLIGIBLE * norms.max()] = 0.0
        shared_names = tuple(f"placement_{k}" for k in range(shared))
        judged = analyse(X, parameters + shared_names, range(n_par),
                         range(n_par, n_par + shared),
                         invisible_reason="no effect on these measurements",
                         absorbed_reason="absorbed by the placement unknowns",
                         **({} if tolerance is None else {"tolerance": tolerance}))
        self.identifiable = np.array([parameters.index(n) for n in judged.identifiable], int)
        self.reasons = dict(judged.unidentifiable)
        keep = np.concatenate([self.identifiable, np.arange(n_par, n_par + shared)]).astype(int)
        self.columns = keep
        self.blocks = [b.X[:, keep] for b in blocks]
        self.matrices = full[:, keep][:, :, keep]
        self.m = len(self.identifiable)
        pool = _schur_exact(self.matrices.sum(axis=0), self.m, shared)
        self.reference = np.sqrt(np.clip(np.diag(pool), 1e-300, None) / len(blocks))
        """Fixed column scales: RMS column norm per candidate over the pool."""
        self.tool_weights = None
        """The tool weights ``W`` on the identifiable columns (``accuracy``), or None."""
        self.tool = None
        """``L^-1`` with ``L L^T = W`` (``accuracy.tool_transform``), or None."""
        if tool_weights is not None:
            W = np.asarray(tool_weights, float)[np.ix_(self.identifiable, self.identifiable)]
            self.tool_weights = W
            self.tool = tool_transform(W)

    def __repr__(self) -> str:
        return (f"Information({len(self.blocks)} candidates, {self.m} identifiable of "
                f"{len(self.parameters)} parameters, shared={self.shared})")

    @property
    def identifiable_names(self) -> tuple[str, ...]:
        return tuple(self.parameters[i] for i in self.identifiable)

    def rows_per_candidate(self) -> float:
        return float(np.mean([len(b) for b in self.blocks]))

    def spectra(self, matrices: np.ndarray, scaling: str = "design") -> np.ndarray:
        """Singular values (B x m, largest first) of designs with information ``matrices``.

        ``scaling``: ``'design'`` normalises each design's columns, ``'reference'``
        divides them by the fixed ``reference``, ``'tool'`` transforms them by the tool
        weights (see ``indices``).
        """
        M = _schur(matrices, self.m, self.shared)
        if scaling == "tool":
            L = self._tool_transform()
            lam = np.linalg.eigvalsh(L @ M @ L.T)[:, ::-1]
            return np.sqrt(np.clip(lam, 0.0, None))
        if scaling == "design":
            d = np.sqrt(np.clip(np.einsum("bii->bi", M), 1e-300, None))
        else:
            d = np.broadcast_to(self.reference, M.shape[:2])
        M = M / d[:, :, None] / d[:, None, :]
        lam = np.linalg.eigvalsh(M)[:, ::-1]
        return np.sqrt(np.clip(lam, 0.0, None))

    def spectrum(self, chosen, scaling: str = "design") -> np.ndarray:
        """Exact singular values (largest first) of the design made of candidates ``chosen``."""
        return self.spectrum_of([self.blocks[i] for i in chosen], scaling)

    def restrict(self, block: Block) -> np.ndarray:
        """A new candidate's rows on this design's columns (identifiable, then shared)."""
        return block.X[:, self.columns]

    def spectrum_of(self, rows: list[np.ndarray], scaling: str = "design") -> np.ndarray:
        """Exact singular values of the design whose (restricted) row blocks are ``rows``."""
        X = np.vstack(rows)
        J = _project_shared(X[:, :self.m], X[:, self.m:])
        if scaling == "tool":
            return np.linalg.svd(J @ self._tool_transform().T, compute_uv=False)
        if scaling == "design":
            norms = np.linalg.norm(J, axis=0)
            return np.linalg.svd(J / np.where(norms > 0, norms, 1.0), compute_uv=False)
        return np.linalg.svd(J / self.reference, compute_uv=False)

    def _tool_transform(self) -> np.ndarray:
        if self.tool is None:
            raise ValueError("the index 'tool' needs tool weights (Information(..., "
                             "tool_weights=...))")
        return self.tool

    def jacobian(self, chosen) -> np.ndarray:
        """The design's identification Jacobian rows (identifiable then shared columns)."""
        return np.vstack([self.blocks[i] for i in chosen])


def _schur(A: np.ndarray, m: int, shared: int) -> np.ndarray:
    """``A_pp - A_ps A_ss^-1 A_sp`` for a batch of (m + shared) square matrices."""
    if shared == 0:
        return A[:, :m, :m]
    App, Aps, Ass = A[:, :m, :m], A[:, :m, m:], A[:, m:, m:]
    ridge = 1e-12 * np.einsum("bii->b", Ass)[:, None, None] * np.eye(shared) + 1e-300
    return App - Aps @ np.linalg.solve(Ass + ridge, np.swapaxes(Aps, 1, 2))


def _schur_exact(A: np.ndarray, m: int, shared: int) -> np.ndarray:
    """``_schur`` of one matrix on ``common.exact`` (the same bits on every processor)."""
    if shared == 0:
        return A[:m, :m].copy()
    App, Aps, Ass = A[:m, :m], A[:m, m:], A[m:, m:]
    ridge = 1e-12 * np.trace(Ass) * np.eye(shared) + 1e-300
    columns = [exact.solve(Ass + ridge, Aps[i]) for i in range(m)]  # rows of Ass^-1 A_sp^T
    return App - exact.matmul(Aps, np.array(columns).T)


def _project_shared(J: np.ndarray, S: np.ndarray) -> np.ndarray:
    """``J`` with its component in the column space of ``S`` removed (SVD, exact)."""
    if S.shape[1] == 0:
        return J
    U, s, _ = np.linalg.svd(S, full_matrices=False)
    U = U[:, s > 1e-12 * s.max()]
    return J - U @ (U.T @ J)


def exact_condition(blocks: list[Block], parameters: tuple[str, ...], shared: int) -> float:
    """Condition number of a design's column-scaled Jacobian over every parameter not
    exactly unidentifiable on it (the engine's rule at ``EXACT_TOLERANCE``): the weak
    directions that the 1% rule sets aside are counted here."""
    X = np.vstack([b.X for b in blocks])
    n_par = len(parameters)
    names = parameters + tuple(f"placement_{k}" for k in range(shared))
    judged = analyse(X, names, range(n_par), range(n_par, n_par + shared),
                     invisible_reason="no effect on these measurements",
                     absorbed_reason="absorbed by the placement unknowns",
                     tolerance=EXACT_TOLERANCE)
    return float(judged.condition_number)
