"""Charts: Euler z-x-z maps (docs/theory.md §1), planar and pose charts, against finite differences."""

import numpy as np
import pytest

from pydrake.autodiffutils import InitializeAutoDiff
from pydrake.math import RigidTransform, RotationMatrix

from drake_hybrid import ChartSingularityError, EulerZXZChart, PlanarChart, PoseChart
from drake_hybrid.core.linalg import value

EPS = 1e-6


def random_euler(rng, n):
    """Euler angles away from the chart singularity and from the phi/psi wrap."""
    return np.column_stack([rng.uniform(-2.5, 2.5, n), rng.uniform(0.3, np.pi - 0.3, n), rng.uniform(-2.5, 2.5, n)])


def skew_to_vector(S):
    return np.array([S[2, 1], S[0, 2], S[1, 0]])


def test_euler_convention_is_zxz_with_approach_vector(rng):
    chart = EulerZXZChart()
    for phi, theta, psi in random_euler(rng, 10):
        X = chart.pose(np.array([0.1, 0.2, 0.3, phi, theta, psi]))
        R = X.rotation().matrix()
        expected = (RotationMatrix.MakeZRotation(phi) @ RotationMatrix.MakeXRotation(theta)
                    @ RotationMatrix.MakeZRotation(psi)).matrix()
        np.testing.assert_allclose(R, expected, atol=1e-14)
        a = [np.sin(theta) * np.sin(phi), -np.sin(theta) * np.cos(phi), np.cos(theta)]
        np.testing.assert_allclose(R[:, 2], a, atol=1e-14)
        np.testing.assert_allclose(np.cross(R[:, 1], R[:, 2]), R[:, 0], atol=1e-14)  # n = o x a
        x = chart.configuration_of_pose(X)
        np.testing.assert_allclose(x, [0.1, 0.2, 0.3, phi, theta, psi], atol=1e-12)


def test_euler_rate_map_matches_rotation_derivative(rng):
    chart = EulerZXZChart()
    for eta in random_euler(rng, 10):
        eta_dot = rng.normal(size=3)
        R = lambda t: chart.pose(np.r_[0, 0, 0, eta + t * eta_dot]).rotation().matrix()
        R_dot = (R(EPS) - R(-EPS)) / (2 * EPS)
        omega = skew_to_vector(R_dot @ R(0).T)                    # [omega]x = R-dot R^T
        T = chart.rate_matrix(eta)
        np.testing.assert_allclose(T @ eta_dot, omega, atol=1e-8)
        np.testing.assert_allclose(chart.rate_matrix_inverse(eta) @ T, np.eye(3), atol=1e-12)
        assert np.linalg.det(T) == pytest.approx(-np.sin(eta[1]))


def test_euler_acceleration_bias_matches_finite_difference(rng):
    chart = EulerZXZChart()
    for eta in random_euler(rng, 10):
        eta_dot = rng.normal(size=3)
        T_dot = (chart.rate_matrix(eta + EPS * eta_dot) - chart.rate_matrix(eta - EPS * eta_dot)) / (2 * EPS)
        np.testing.assert_allclose(chart.rate_matrix_bias(eta, eta_dot), T_dot @ eta_dot, atol=1e-8)


def test_euler_wrench_dual_preserves_power(rng):
    chart = EulerZXZChart()
    for eta in random_euler(rng, 5):
        x = np.r_[rng.normal(size=3), eta]
        nu = rng.normal(size=6)
        F_spatial = rng.normal(size=6)                             # [n; f]
        V = chart.spatial_velocity(x, nu)                          # [omega; v]
        assert chart.generalized_force(x, F_spatial) @ nu == pytest.approx(F_spatial @ V, rel=1e-12)
        np.testing.assert_allclose(chart.task_velocity(x, V), nu, atol=1e-12)


@pytest.mark.parametrize("theta", [0.0, 1e-4, np.pi, np.pi - 5e-3])
def test_euler_singularity_raises_typed_error(theta):
    chart = EulerZXZChart()
    X = chart.pose(np.array([0, 0, 0, 0.3, theta, -0.2]))
    with pytest.raises(ChartSingularityError, match=r"singular at theta = .*\|sin\(theta\)\|"):
        chart.configuration_of_pose(X)
    with pytest.raises(ChartSingularityError, match="PoseChart"):
        chart.task_jacobian(np.array([0, 0, 0, 0.3, theta, -0.2]), np.ones((6, 6)))


def test_euler_singularity_tolerance_must_be_positive():
    with pytest.raises(ValueError, match=r"singularity_tolerance must be a finite number > 0 and < 1, got 0"):
        EulerZXZChart(singularity_tolerance=0.0)


def test_pose_chart_is_regular_at_the_pole():
    chart = PoseChart()
    X = RigidTransform(RotationMatrix.MakeXRotation(np.pi), [0, 0, 0.15])     # a = -z: the pole
    x = chart.configuration_of_pose(X)
    assert np.all(np.isfinite(x))
    np.testing.assert_allclose(chart.pose(x).GetAsMatrix4(), X.GetAsMatrix4(), atol=1e-15)


def test_planar_chart_round_trip_and_plane():
    chart = PlanarChart()
    np.testing.assert_allclose(chart.normal, [0, -1, 0])
    x = np.array([0.4, 0.9, 0.7])
    X = chart.pose(x)
    np.testing.assert_allclose(X.translation(), [0.4, 0, 0.9])
    np.testing.assert_allclose(chart.configuration_of_pose(X), x, atol=1e-14)


def test_planar_chart_rejects_non_orthonormal_axes():
    with pytest.raises(ValueError, match="orthonormal"):
        PlanarChart(axis_x=(1, 0, 0), axis_y=(1, 0, 1))


@pytest.mark.parametrize("chart", [EulerZXZChart(), PoseChart(), PlanarChart()], ids=lambda c: c.name)
def test_configuration_autodiff_equals_float(chart, rng):
    R = RotationMatrix.MakeZRotation(0.3).multiply(RotationMatrix.MakeXRotation(1.1)).matrix()
    if isinstance(chart, PlanarChart):
        R = RotationMatrix.MakeYRotation(-0.4).matrix()
    p = rng.normal(size=3)
    x_float = chart.configuration(R, p)
    R_ad = InitializeAutoDiff(R.reshape(-1)).reshape(3, 3)
    p_ad = InitializeAutoDiff(p).reshape(-1)
    x_ad = chart.configuration(R_ad, p_ad)
    assert x_ad.dtype == object
    np.testing.assert_allclose(value(x_ad), x_float, atol=1e-15)
