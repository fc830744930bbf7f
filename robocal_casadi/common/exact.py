"""Small dense linear algebra whose results do not depend on the machine.

NumPy hands ``a @ b``, ``np.dot``, ``np.linalg.norm`` of a vector and every
``np.linalg`` solver to the BLAS / LAPACK library it was built with, and OpenBLAS picks
its kernels by processor (``OPENBLAS_CORETYPE`` forces one): a kernel with fused
multiply-add, or another order of the partial sums, changes the last bits of the result.
Where such a result decides what goes into a file (a simulated reading, which inverse
kinematics branch is kept, whether a seat is reachable), two machines write two files.

The functions here compute the same quantities from NumPy's element-wise operations and
its reductions, which run NumPy's own loops in a fixed order, never BLAS: the same bits on
every processor and BLAS kernel, for the small matrices (3x3 rotations, 4x4 poses, the
6- or 7-column Jacobians of inverse kinematics) where speed is not the point. Large
problems (a calibration's thousands of rows) keep BLAS; their results agree across
machines to rounding, and the decisions taken on them keep margins (``docs/conventions.md``,
"Same answer everywhere").
"""

from __future__ import annotations

import numpy as np


def matmul(a, b) -> np.ndarray:
    """``a @ b`` for 1-D and 2-D operands and stacks of matrices (``(..., m, k) @ (..., k, n)``
    or ``(..., m, k) @ (k,)``), summed over ``k`` in index order."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.ndim == 1 and b.ndim == 1:
        return (a * b).sum()
    if b.ndim == 1:
        return (a * b).sum(axis=-1)
    if a.ndim == 1:
        return (a[:, None] * b).sum(axis=-2)
    return (a[..., :, :, None] * b[..., None, :, :]).sum(axis=-2)


def chain(*matrices) -> np.ndarray:
    """The product of ``matrices`` from left to right (``matmul`` applied in turn)."""
    out = np.asarray(matrices[0], dtype=float)
    for m in matrices[1:]:
        out = matmul(out, m)
    return out


def dot(a, b) -> float:
    """The scalar product of two vectors."""
    return float((np.asarray(a, dtype=float) * np.asarray(b, dtype=float)).sum())


def norm(x, axis: int | None = None):
    """The Euclidean norm of ``x`` (all entries), or along ``axis``."""
    x = np.asarray(x, dtype=float)
    if axis is None:
        return float(np.sqrt((x * x).sum()))
    return np.sqrt((x * x).sum(axis=axis))


def cross(a, b) -> np.ndarray:
    """The cross product of 3-vectors (``np.cross`` uses no BLAS; here for one home)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def gram(J) -> np.ndarray:
    """``J^T J`` for a tall ``J`` (rows summed in order)."""
    J = np.asarray(J, dtype=float)
    return (J[:, :, None] * J[:, None, :]).sum(axis=0)


def transpose_times(J, r) -> np.ndarray:
    """``J^T r`` (rows summed in order)."""
    J = np.asarray(J, dtype=float)
    return (J * np.asarray(r, dtype=float)[:, None]).sum(axis=0)


class SingularMatrix(ArithmeticError):
    """``solve`` met a zero pivot."""


def solve(A, b) -> np.ndarray:
    """``x`` with ``A x = b`` for a small square ``A``: Gaussian elimination with partial
    pivoting (the pivot chosen by the first largest magnitude, so ties break alike).

    Raises ``SingularMatrix`` on a zero pivot.
    """
    M = np.array(A, dtype=float)
    x = np.array(b, dtype=float)
    n = len(M)
    for k in range(n):
        pivot = k + int(np.argmax(np.abs(M[k:, k])))
        if M[pivot, k] == 0.0 or not np.isfinite(M[pivot, k]):
            raise SingularMatrix(f"zero pivot in column {k}")
        if pivot != k:
            M[[k, pivot]] = M[[pivot, k]]
            x[[k, pivot]] = x[[pivot, k]]
        factors = M[k + 1:, k] / M[k, k]
        M[k + 1:, k:] -= factors[:, None] * M[k, k:]
        x[k + 1:] -= factors * x[k]
    for k in range(n - 1, -1, -1):
        x[k] = (x[k] - (M[k, k + 1:] * x[k + 1:]).sum()) / M[k, k]
    return x


def inverse_pose(T) -> np.ndarray:
    """The inverse of a 4x4 rigid transform."""
    T = np.asarray(T, dtype=float)
    R = T[:3, :3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -matmul(R.T, T[:3, 3])
    return out


def solve_stack(A, b) -> np.ndarray:
    """``x`` with ``A[k] x[k] = b[k]`` for a stack of small square systems (``A``:
    ``(B, n, n)``, ``b``: ``(B, n)``): ``solve`` applied to each, all at once.

    Raises ``SingularMatrix`` when a system meets a zero pivot.
    """
    M = np.array(A, dtype=float)
    x = np.array(b, dtype=float)
    rows = np.arange(len(M))
    n = M.shape[-1]
    for k in range(n):
        pivot = k + np.argmax(np.abs(M[:, k:, k]), axis=1)
        value = M[rows, pivot, k]
        if np.any(value == 0.0) or not np.all(np.isfinite(value)):
            raise SingularMatrix(f"zero pivot in column {k}")
        row_k, row_p = M[rows, k].copy(), M[rows, pivot].copy()
        M[rows, k], M[rows, pivot] = row_p, row_k
        x_k, x_p = x[rows, k].copy(), x[rows, pivot].copy()
        x[rows, k], x[rows, pivot] = x_p, x_k
        factors = M[:, k + 1:, k] / M[:, k, k][:, None]
        M[:, k + 1:, k:] -= factors[:, :, None] * M[:, None, k, k:]
        x[:, k + 1:] -= factors * x[:, k][:, None]
    for k in range(n - 1, -1, -1):
        x[:, k] = (x[:, k] - (M[:, k, k + 1:] * x[:, k + 1:]).sum(axis=1)) / M[:, k, k]
    return x


def cholesky(A) -> np.ndarray:
    """Lower-triangular ``L`` with ``L L^T = A`` for a symmetric positive definite ``A``.

    Raises ``SingularMatrix`` when a pivot is not positive.
    """
    A = np.asarray(A, dtype=float)
    n = len(A)
    L = np.zeros_like(A)
    for j in range(n):
        pivot = A[j, j] - (L[j, :j] * L[j, :j]).sum()
        if not pivot > 0.0:
            raise SingularMatrix(f"not positive definite at column {j}")
        L[j, j] = np.sqrt(pivot)
        L[j + 1:, j] = (A[j + 1:, j] - (L[j + 1:, :j] * L[j, :j]).sum(axis=1)) / L[j, j]
    return L


def lower_inverse(L) -> np.ndarray:
    """The inverse of a lower-triangular ``L`` with a non-zero diagonal (forward
    substitution, column by column of the identity)."""
    L = np.asarray(L, dtype=float)
    n = len(L)
    X = np.zeros_like(L)
    for i in range(n):
        # row i of L X = I: L[i, i] X[i] = e_i - sum_{k<i} L[i, k] X[k]
        right = -(L[i, :i, None] * X[:i]).sum(axis=0)
        right[i] += 1.0
        X[i] = right / L[i, i]
    return X


def orthonormal_basis(A, rtol: float) -> np.ndarray:
    """Orthonormal columns spanning the column space of ``A`` (rows x k): modified
    Gram-Schmidt with column pivoting, each new column orthogonalised twice; a direction
    whose remaining norm is at most ``rtol`` times the largest column norm of ``A`` counts
    as already spanned (the pivot is the first largest, so ties break alike)."""
    R = np.array(A, dtype=float)
    if R.size == 0:
        return np.zeros((R.shape[0], 0))
    largest = float(np.sqrt((R * R).sum(axis=0)).max())
    basis: list[np.ndarray] = []
    for _ in range(min(R.shape)):
        norms = np.sqrt((R * R).sum(axis=0))
        j = int(np.argmax(norms))
        if not norms[j] > rtol * largest:
            break
        u = R[:, j] / norms[j]
        for q in basis:  # the second pass removes what rounding left of earlier directions
            u = u - (q * u).sum() * q
        u = u / np.sqrt((u * u).sum())
        basis.append(u)
        R = R - u[:, None] * (u[:, None] * R).sum(axis=0)[None, :]
    if not basis:
        return np.zeros((R.shape[0], 0))
    return np.stack(basis, axis=1)


def project_out(G, A, rtol: float) -> np.ndarray:
    """``G`` with its component in the column space of ``A`` removed (``orthonormal_basis``
    of ``A`` at ``rtol``)."""
    G = np.asarray(G, dtype=float)
    U = orthonormal_basis(A, rtol)
    if U.shape[1] == 0:
        return G.copy()
    return G - matmul(U, matmul(U.T, G))


def independent_columns(columns, span, floor: float, rtol: float
                        ) -> tuple[list[int], np.ndarray]:
    """Columns of ``columns`` (n x m) picked greedily, each time the one with the largest
    share of its norm outside what is spanned already, while that share exceeds ``rtol``;
    ``span`` (n x k, orthonormal, k may be 0) what counts as spanned from the start;
    columns of norm ``floor`` or less are never picked. Returns the indices in the order
    found and the span grown by them (pivoted Gram-Schmidt, fixed-order sums)."""
    columns = np.asarray(columns, dtype=float)
    span = np.asarray(span, dtype=float).reshape(columns.shape[0], -1)
    norms = norm(columns, axis=0)
    remaining = columns - matmul(span, matmul(span.T, columns)) if span.shape[1] \
        else columns.copy()
    candidates = [k for k in range(columns.shape[1]) if norms[k] > floor]
    kept: list[int] = []
    while candidates:
        left = norm(remaining[:, candidates], axis=0)
        relative = left / norms[candidates]
        best = int(np.argmax(relative))
        if relative[best] <= rtol:
            break
        k = candidates.pop(best)
        u = remaining[:, k] / left[best]
        remaining -= np.outer(u, matmul(u, remaining))
        span = np.column_stack([span, u])
        kept.append(k)
    return kept, span
