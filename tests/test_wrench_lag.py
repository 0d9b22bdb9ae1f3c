"""analysis.wrench_lag: the velocity rows' loop with a lagged cancellation of F_v on a curved
constraint (the full-arm figures are in tests/test_own_arms.py and docs/own_arms.md)."""

from types import SimpleNamespace

import numpy as np

from drake_hybrid.analysis.wrench_lag import lagged_loop_matrix


def _roots(polynomial):
    return np.sort_complex(np.roots(polynomial))


def test_one_row_is_the_lagged_characteristic_polynomial():
    # (s^2 + K_v s + K_p)(1 + s T) + S D s T = 0, one row, position-force
    K_v, K_p, S, D, T = 10.0, 21.0, 0.5, -300.0, 1e-3
    gains = SimpleNamespace(velocity=np.array([[K_v]]), position=np.array([[K_p]]))
    A = lagged_loop_matrix(gains, True, np.array([[D]]), np.array([[S]]), T)
    expected = np.polyadd(np.polymul([1.0, K_v, K_p], [T, 1.0]), [S * D * T, 0.0])
    assert np.allclose(np.sort_complex(np.linalg.eigvals(A)), _roots(expected), rtol=1e-9, atol=1e-9)


def test_velocity_force_keeps_its_root_at_zero_and_slows():
    # s (s + K_v)(1 + s T) + S D s T = 0: the drift root stays at 0, the row's root moves to about
    # -(K_v + T S D)
    K_v, S, D, T = 10.0, 0.5, -300.0, 1e-3
    gains = SimpleNamespace(velocity=np.array([[K_v]]), position=np.zeros((1, 1)))
    eigenvalues = np.linalg.eigvals(lagged_loop_matrix(gains, False, np.array([[D]]), np.array([[S]]), T))
    assert np.min(np.abs(eigenvalues)) < 1e-9
    row = eigenvalues[np.argmin(np.abs(eigenvalues + K_v))]
    assert abs(row.real + (K_v + T * S * D)) < 0.01 * K_v
    assert row.real > -K_v                                  # D < 0: slower than designed


def test_a_flat_surface_or_no_lag_keeps_the_design():
    gains = SimpleNamespace(velocity=np.diag([10.0, 10.0]), position=np.diag([21.0, 21.0]))
    A = lagged_loop_matrix(gains, True, np.zeros((2, 2)), np.eye(2), 1e-3)
    slow = np.sort(np.linalg.eigvals(A).real)[-4:]
    assert np.allclose(slow, [-7, -7, -3, -3])
