"""Small dense linear algebra that works for float and AutoDiffXd arrays.

numpy's LAPACK routines refuse object arrays (AutoDiffXd); ``pydrake.math``
provides ``inv`` for them. These helpers pick the right one, so the control law
is written once for both scalar types.
"""

import math

import numpy as np

import pydrake.math as drake_math
from pydrake.autodiffutils import AutoDiffXd


def is_autodiff(*arrays):
    """True if any argument is an object (AutoDiffXd) array or scalar."""
    for a in arrays:
        if isinstance(a, AutoDiffXd):
            return True
        if getattr(a, "dtype", None) == object:
            return True
    return False


def value(array):
    """The float value of a float or AutoDiffXd array."""
    if isinstance(array, AutoDiffXd):
        return array.value()
    array = np.asarray(array)
    if array.dtype == object:
        return np.array([a.value() if isinstance(a, AutoDiffXd) else float(a) for a in array.flat],
                        dtype=float).reshape(array.shape)
    return array


def _as_autodiff(matrix):
    matrix = np.asarray(matrix, dtype=object)
    return np.vectorize(lambda a: a if isinstance(a, AutoDiffXd) else AutoDiffXd(float(a)), otypes=[object])(matrix)


def inv(matrix):
    """Inverse of a square float or AutoDiffXd matrix."""
    if is_autodiff(matrix):
        return drake_math.inv(_as_autodiff(matrix))
    return np.linalg.inv(matrix)


def solve(matrix, rhs):
    """Solve ``matrix @ x = rhs`` for float or AutoDiffXd operands."""
    if is_autodiff(matrix, rhs):
        return inv(matrix) @ rhs
    return np.linalg.solve(matrix, rhs)


def singular_values(matrix):
    """Singular values of the float value of ``matrix`` (descending)."""
    return np.linalg.svd(value(matrix), compute_uv=False)


def rank_margin(matrix):
    """How far the rows of ``matrix`` are from linear dependence, in [0, 1].

    sqrt(det(A A^T) / prod_i |a_i|^2): 1 for orthogonal rows, 0 for dependent
    (or zero) rows, and unchanged by rescaling any row (so it does not depend
    on the units of the constraint rows). For two rows it is the sine of the
    angle between them.
    """
    A = value(matrix)
    norms_squared = np.einsum("ij,ij->i", A, A)
    if A.shape[0] == 0:
        return 1.0
    if not np.all(norms_squared > 0.0):
        return 0.0
    ratio = np.linalg.det(A @ A.T) / np.prod(norms_squared)
    return float(math.sqrt(max(ratio, 0.0)))


def null_space_basis(matrix):
    """Orthonormal basis (columns) of the null space of a full-row-rank float matrix."""
    matrix = value(matrix)
    rows = matrix.shape[0]
    return np.linalg.svd(matrix)[2][rows:].T
