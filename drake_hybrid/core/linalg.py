"""Small dense linear algebra that works for float and AutoDiffXd arrays.

numpy's LAPACK routines refuse object arrays (AutoDiffXd); ``pydrake.math``
provides ``inv`` for them. These helpers pick the right one, so the control law
is written once for both scalar types.

The float path calls LAPACK through ``scipy.linalg.lapack`` directly: for the
1x1 to 7x7 matrices of a control tick numpy's wrappers (type checks, error
state, broadcasting) cost 3-5 us per call against 0.5-1 us for the LAPACK work
(benchmarks/PROFILE.md). The direct calls do not raise on singular input, so
the info flags are checked here and raise ``numpy.linalg.LinAlgError`` as numpy
would.
"""

import math
from typing import Union, overload

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import lapack

import pydrake.math as drake_math
from pydrake.autodiffutils import AutoDiffXd
from pydrake.math import sqrt

from drake_hybrid.core.hints import Array

_getrf, _getrs, _getri, _gesv, _potrf = lapack.dgetrf, lapack.dgetrs, lapack.dgetri, lapack.dgesv, lapack.dpotrf


def is_autodiff(*arrays):
    """True if any argument is an object (AutoDiffXd) array or scalar."""
    for a in arrays:
        if isinstance(a, AutoDiffXd):
            return True
        if getattr(a, "dtype", None) == object:
            return True
    return False


@overload
def value(array: AutoDiffXd) -> float: ...


@overload
def value(array: ArrayLike) -> Array: ...


def value(array: Union[AutoDiffXd, ArrayLike]) -> Union[float, Array]:
    """The float value of a float or AutoDiffXd array."""
    if isinstance(array, AutoDiffXd):
        return array.value()
    array = np.asarray(array)
    if array.dtype == object:
        return np.array([a.value() if isinstance(a, AutoDiffXd) else float(a) for a in array.flat],
                        dtype=float).reshape(array.shape)
    return array


_SHORT = 64          # entries up to which all_finite sums Python floats


def all_finite(array):
    """True if every entry (float or AutoDiffXd value) is finite. For floats one reduction: NaN and
    inf propagate through the sum (which overflows only for entries near 1e308); a short array is
    summed as Python floats (a third of numpy's reduction's cost for a robot's state)."""
    array = np.asarray(array)
    if array.dtype == object:
        return bool(np.all(np.isfinite(value(array))))
    if array.size <= _SHORT:
        return math.isfinite(sum(array.ravel().tolist()))
    return math.isfinite(array.sum())


def _as_autodiff(matrix):
    matrix = np.asarray(matrix, dtype=object)
    return np.vectorize(lambda a: a if isinstance(a, AutoDiffXd) else AutoDiffXd(float(a)), otypes=[object])(matrix)


def _singular(info, what):
    if info > 0:
        raise np.linalg.LinAlgError(f"Singular matrix ({what}: zero pivot {info})")
    if info < 0:
        raise ValueError(f"LAPACK {what}: illegal argument {-info}")


def inv(matrix):
    """Inverse of a square float or AutoDiffXd matrix."""
    if is_autodiff(matrix):
        return drake_math.inv(_as_autodiff(matrix))
    if matrix.shape[0] == 0:
        return np.zeros((0, 0))
    lu, pivots, info = _getrf(matrix)
    _singular(info, "getrf")
    inverse, info = _getri(lu, pivots)
    _singular(info, "getri")
    return inverse


def solve(matrix, rhs):
    """Solve ``matrix @ x = rhs`` for float or AutoDiffXd operands."""
    if is_autodiff(matrix, rhs):
        return inv(matrix) @ rhs
    if matrix.shape[0] == 0:
        return np.zeros(np.shape(rhs))
    _, _, x, info = _gesv(matrix, rhs)
    _singular(info, "gesv")
    return x


def cholesky(S):
    """Lower-triangular L with L L^T = S, for a small float or AutoDiffXd S.

    Raises numpy.linalg.LinAlgError if S is not (numerically) positive definite.
    """
    if not is_autodiff(S):
        if S.shape[0] == 0:
            return np.zeros((0, 0))
        L, info = _potrf(S, lower=1, clean=1)
        if info > 0:
            raise np.linalg.LinAlgError(f"Matrix is not positive definite (leading minor {info})")
        return L
    k = S.shape[0]
    L = np.zeros((k, k), dtype=object)
    for j in range(k):
        diagonal = S[j, j] - sum(L[j, i] * L[j, i] for i in range(j))
        L[j, j] = sqrt(diagonal)
        for row in range(j + 1, k):
            L[row, j] = (S[row, j] - sum(L[row, i] * L[j, i] for i in range(j))) / L[j, j]
    return L


class LUFactorization:
    """A square matrix factored once, for solves with it and its transpose and its determinant.

    Float matrices are LU-factored by LAPACK (getrf); AutoDiffXd ones are
    inverted by ``pydrake.math.inv``. ``solve`` and ``solve_transpose`` then cost
    one triangular solve pair each.
    """

    __slots__ = ("matrix", "_lu", "_pivots", "_inverse", "singular")

    def __init__(self, matrix):
        self.matrix = matrix
        self._inverse = None
        self._lu = self._pivots = None
        if is_autodiff(matrix):
            self.singular = False
            self._inverse = inv(matrix)
            return
        self._lu, self._pivots, info = _getrf(matrix)
        self.singular = info > 0

    def _check(self):
        if self.singular:
            raise np.linalg.LinAlgError("Singular matrix (getrf: zero pivot)")

    def solve(self, rhs):
        """x with A x = rhs."""
        if self._inverse is not None:
            return self._inverse @ rhs
        self._check()
        return _getrs(self._lu, self._pivots, rhs)[0]

    def solve_transpose(self, rhs):
        """x with A^T x = rhs."""
        if self._inverse is not None:
            return self._inverse.T @ rhs
        self._check()
        return _getrs(self._lu, self._pivots, rhs, trans=1)[0]

    def rank_margin(self):
        """``rank_margin(A)``, from the LU factors when A is float: |det A| / prod_i |a_i|."""
        if self._inverse is not None:
            return rank_margin(self.matrix)
        norms_squared = row_norms_squared(self.matrix)
        if self.singular or not norms_squared.min() > 0.0:
            return 0.0
        margin = abs(float(self._lu.diagonal().prod())) / math.sqrt(float(norms_squared.prod()))
        return margin if math.isfinite(margin) else 0.0


def singular_values(matrix):
    """Singular values of the float value of ``matrix`` (descending)."""
    return np.linalg.svd(value(matrix), compute_uv=False)


def row_norms_squared(matrix):
    """|a_i|^2 for the rows a_i of a float matrix."""
    return (matrix * matrix).sum(axis=1)


def rank_margin(matrix):
    """How far the rows of ``matrix`` are from linear dependence, in [0, 1].

    sqrt(det(A A^T) / prod_i |a_i|^2): 1 for orthogonal rows, 0 for dependent
    (or zero) rows, and unchanged by rescaling any row (so it does not depend
    on the units of the constraint rows). For two rows it is the sine of the
    angle between them.
    """
    A = value(matrix)
    if A.shape[0] == 0:
        return 1.0
    norms_squared = row_norms_squared(A)
    if not norms_squared.min() > 0.0:          # also catches NaN
        return 0.0
    if A.shape[0] == A.shape[1]:               # det(A A^T) = det(A)^2: from the LU factors
        return LUFactorization(A).rank_margin()
    ratio = _gram_determinant(A @ A.T) / float(norms_squared.prod())
    return math.sqrt(max(ratio, 0.0)) if math.isfinite(ratio) else 0.0


def rank_margin_from_cholesky(L, gram_diagonal):
    """rank_margin of A from the Cholesky factor L of its Gram matrix A A^T and that matrix's diagonal.

    det(A A^T) = prod(diag L)^2, so the margin is prod(diag L) / sqrt(prod |a_i|^2):
    the same number as ``rank_margin(A)`` at no extra factorization.
    """
    if L.shape[0] == 0:
        return 1.0
    L_diagonal, gram_diagonal = value(L.diagonal()), value(gram_diagonal)
    if not gram_diagonal.min() > 0.0:
        return 0.0
    return float(abs(L_diagonal.prod()) / math.sqrt(gram_diagonal.prod()))


def _gram_determinant(G):
    k = G.shape[0]
    if k == 1:
        return float(G[0, 0])
    if k == 2:
        return float(G[0, 0] * G[1, 1] - G[0, 1] * G[1, 0])
    lu, _, info = _getrf(G)
    return 0.0 if info > 0 else abs(float(lu.diagonal().prod()))   # det G >= 0; the LU pivots flip the sign


def null_space_basis(matrix):
    """Orthonormal basis (columns) of the null space of a full-row-rank float matrix."""
    matrix = value(matrix)
    rows = matrix.shape[0]
    return np.linalg.svd(matrix)[2][rows:].T
