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
