"""The float fast path of drake_hybrid.core.linalg against numpy, and its AutoDiffXd path."""

import math

import numpy as np
import pytest

from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, InitializeAutoDiff

from drake_hybrid.core.linalg import LUFactorization, cholesky, inv, rank_margin, rank_margin_from_cholesky, solve


def svd_rank_margin(A):
    """The definition: sqrt(det(A A^T) / prod |a_i|^2), through singular values (no LU involved)."""
    s = np.linalg.svd(A, compute_uv=False)
    return math.sqrt(np.prod(s ** 2) / np.prod((A * A).sum(axis=1)))


@pytest.mark.parametrize("shape", [(1, 3), (2, 3), (3, 6), (5, 6), (6, 6), (4, 4)])
def test_rank_margin_matches_its_definition(rng, shape):
    for _ in range(10):
        A = rng.normal(size=shape) * rng.uniform(0.01, 100, size=(shape[0], 1))   # row scaling must not matter
        assert rank_margin(A) == pytest.approx(svd_rank_margin(A), rel=1e-9)


def test_rank_margin_of_dependent_zero_and_nan_rows():
    A = np.array([[1.0, 2.0, 0.0], [2.0, 4.0, 0.0]])
    assert rank_margin(A) < 1e-7
    assert rank_margin(np.array([[1.0, 0.0], [0.0, 0.0]])) == 0.0
    assert rank_margin(np.array([[1.0, np.nan], [0.0, 1.0]])) == 0.0
    assert rank_margin(np.eye(3)) == pytest.approx(1.0)
    assert rank_margin(np.zeros((0, 3))) == 1.0


def test_rank_margin_from_cholesky_and_from_lu_agree_with_the_definition(rng):
    for _ in range(10):
        Y = rng.normal(size=(3, 6))
        S = Y @ Y.T
        assert rank_margin_from_cholesky(cholesky(S), S.diagonal()) == pytest.approx(svd_rank_margin(Y), rel=1e-9)
        E = rng.normal(size=(6, 6))
        assert LUFactorization(E).rank_margin() == pytest.approx(svd_rank_margin(E), rel=1e-9)


def test_float_solves_match_numpy(rng):
    A = rng.normal(size=(6, 6)) + 3 * np.eye(6)
    b, B = rng.normal(size=6), rng.normal(size=(6, 2))
    np.testing.assert_allclose(solve(A, b), np.linalg.solve(A, b), rtol=1e-12)
    np.testing.assert_allclose(solve(A, B), np.linalg.solve(A, B), rtol=1e-12)
    np.testing.assert_allclose(inv(A), np.linalg.inv(A), rtol=1e-12, atol=1e-14)
    factor = LUFactorization(A)
    np.testing.assert_allclose(factor.solve(b), np.linalg.solve(A, b), rtol=1e-12)
    np.testing.assert_allclose(factor.solve_transpose(b), np.linalg.solve(A.T, b), rtol=1e-12)
    S = A @ A.T
    L = cholesky(S)
    np.testing.assert_allclose(L, np.linalg.cholesky(S), rtol=1e-12, atol=1e-14)
    assert np.all(np.triu(L, 1) == 0)


def test_singular_input_raises_instead_of_returning_garbage():
    singular = np.array([[1.0, 2.0], [2.0, 4.0]])
    with pytest.raises(np.linalg.LinAlgError, match="Singular"):
        solve(np.zeros((2, 2)), np.ones(2))
    with pytest.raises(np.linalg.LinAlgError, match="Singular"):
        inv(np.zeros((3, 3)))
    with pytest.raises(np.linalg.LinAlgError, match="Singular"):
        LUFactorization(np.zeros((2, 2))).solve(np.ones(2))
    assert LUFactorization(np.zeros((2, 2))).rank_margin() == 0.0
    with pytest.raises(np.linalg.LinAlgError, match="positive definite"):
        cholesky(-np.eye(2))
    assert rank_margin(singular) < 1e-7


def test_autodiff_path_gives_values_and_derivatives(rng):
    A0 = rng.normal(size=(3, 3)) + 3 * np.eye(3)
    b = rng.normal(size=3)
    A = InitializeAutoDiff(A0.reshape(-1)).reshape(3, 3)
    assert isinstance(A[0, 0], AutoDiffXd)
    x = solve(A, b)
    np.testing.assert_allclose(ExtractValue(x).ravel(), np.linalg.solve(A0, b), rtol=1e-12)
    # d(A^-1 b)/dA_ij = -A^-1 e_i x_j, against central finite differences
    gradient = ExtractGradient(x)
    h = 1e-6
    for k in range(9):
        dA = np.zeros(9)
        dA[k] = h
        fd = (np.linalg.solve(A0 + dA.reshape(3, 3), b) - np.linalg.solve(A0 - dA.reshape(3, 3), b)) / (2 * h)
        np.testing.assert_allclose(gradient[:, k], fd, atol=1e-7)
    factor = LUFactorization(A)
    np.testing.assert_allclose(ExtractValue(factor.solve_transpose(b)).ravel(), np.linalg.solve(A0.T, b), rtol=1e-12)
    assert factor.rank_margin() == pytest.approx(svd_rank_margin(A0), rel=1e-9)
    S0 = A0 @ A0.T
    L = cholesky(InitializeAutoDiff(S0.reshape(-1)).reshape(3, 3))
    np.testing.assert_allclose(ExtractValue(L.reshape(-1)).reshape(3, 3), np.linalg.cholesky(S0), atol=1e-12)
