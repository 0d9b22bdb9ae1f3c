"""Velocity projections, the general E^-1 block and the force decomposition (docs/theory.md §3, §0)."""

import numpy as np
import pytest
from test_constraints import crank_point, random_sphere_points, sphere_paper_E_p, sphere_point

from pydrake.autodiffutils import InitializeAutoDiff

from drake_hybrid import (ConstraintRankError, ConstraintSpace, DimensionError, EulerZXZChart, GivenVelocityProjection,
                          KernelVelocityProjection, PlanarChart, PoseChart, crank_constraint, crank_paper_projection,
                          crank_true_velocity_projection, sphere_constraint, sphere_paper_projection,
                          sphere_true_velocity_projection, window_constraint)
from drake_hybrid.core.linalg import null_space_basis, value

EPS = 1e-6


def crank_true_velocity_rows(chart):
    """E_t of docs/theory.md §6 (Option A): psi-dot and the crank angle rate -y x-dot + x y-dot."""
    x, y = chart.symbols[:2]
    return GivenVelocityProjection(chart, [[0, 0, 0, 0, 0, 1], [-y, x, 0, 0, 0, 0]], name="E_t crank")


def test_paper_projections_window_and_crank():
    planar = PlanarChart()
    window = window_constraint(planar, height=1.0)
    E_p = GivenVelocityProjection(planar, [[1, 0, 0], [0, 0, 1]], name="(3.3-1)")   # r-dot_p = (x-dot, theta-dot)
    space = ConstraintSpace(window, E_p)
    values = space.evaluate(np.array([0.3, 1.0, 0.2]), np.array([0.1, 0.0, -0.3]))
    np.testing.assert_allclose(values.force_projection, [[0, 1, 0]])
    np.testing.assert_allclose(values.velocity_projection @ [0.1, 0.0, -0.3], [0.1, -0.3])


def test_task_acceleration_with_non_orthogonal_true_velocity_rows(rng):
    """Option A: E = [E_t; E_f] with E_f E_t^T != 0; r-ddot* meets both block rows of (3.0-11)."""
    chart = EulerZXZChart()
    crank = crank_constraint(chart, radius=1.0, form="paper")
    space = ConstraintSpace(crank, crank_true_velocity_rows(chart))
    for _ in range(5):
        r = crank_point(rng.uniform(-3, 3), rng.uniform(-3, 3))
        nu = null_space_basis(crank.force_projection(r)) @ rng.normal(size=2)
        values = space.evaluate(r, nu)
        assert np.abs(values.force_projection @ values.velocity_projection.T).max() > 0.5
        a_p = rng.normal(size=2)
        r_ddot = space.task_acceleration(values, a_p)
        np.testing.assert_allclose(values.velocity_projection @ r_ddot + values.velocity_curvature, a_p, atol=1e-12)
        np.testing.assert_allclose(values.force_projection @ r_ddot + values.force_curvature, 0, atol=1e-12)
        # The general block: E^-1 [a; 0] = N_f (E_p N_f)^-1 a, not E_p^T (E_p E_p^T)^-1 a.
        N_f = null_space_basis(values.force_projection)
        E_p = values.velocity_projection
        general = np.linalg.inv(values.matrix)[:, :2] @ a_p
        np.testing.assert_allclose(general, N_f @ np.linalg.solve(E_p @ N_f, a_p), atol=1e-12)
        assert np.abs(general - E_p.T @ np.linalg.solve(E_p @ E_p.T, a_p)).max() > 1e-3


def test_crank_det_of_true_velocity_E_is_2_on_N(rng):
    chart = EulerZXZChart()
    crank = crank_constraint(chart, radius=1.0, form="paper")
    space = ConstraintSpace(crank, crank_true_velocity_rows(chart))
    r = crank_point(0.3, 0.1)
    assert np.linalg.det(space.evaluate(r, np.zeros(6)).matrix) == pytest.approx(2.0)


def test_sphere_paper_projection_is_3_3_11_with_the_corrected_3_3_13(rng):
    chart = EulerZXZChart()
    sphere = sphere_constraint(chart, radius=1.0, form="paper", dropped_component=3)
    space = ConstraintSpace(sphere, sphere_paper_projection(chart, radius=1.0))
    for r in random_sphere_points(rng, 20):
        values = space.evaluate(r, rng.normal(size=6))
        np.testing.assert_allclose(values.velocity_projection, sphere_paper_E_p(r), atol=1e-10)
        np.testing.assert_allclose(values.force_projection @ values.velocity_projection.T, 0, atol=1e-12)
    # Off the unit sphere at the origin too: E_f E_p^T = 0 on N of a shifted, scaled sphere.
    center, radius = (0.4, -0.1, 0.3), 0.15
    shifted = ConstraintSpace(sphere_constraint(chart, center=center, radius=radius, form="paper",
                                                dropped_component=3),
                              sphere_paper_projection(chart, center=center, radius=radius))
    for r in random_sphere_points(rng, 10):
        r = np.r_[np.asarray(center) + radius * r[:3], r[3:]]
        values = shifted.evaluate(r, np.zeros(6))
        np.testing.assert_allclose(values.constraint_value, 0, atol=1e-14)
        np.testing.assert_allclose(values.force_projection @ values.velocity_projection.T, 0, atol=1e-12)


def test_pseudo_velocity_error_equals_the_true_velocity_error(rng):
    """docs/theory.md §6: E_p r-dot - r-dot_pd^pseudo == E_t r-dot - r-dot_td for every r-dot (crank and sphere)."""
    from drake_hybrid.core.projections import pseudo_desired_velocity

    chart = EulerZXZChart()
    cases = [(crank_paper_projection(chart), crank_true_velocity_projection(chart), crank_point(0.3, 0.2)),
             (sphere_paper_projection(chart), sphere_true_velocity_projection(chart), sphere_point(0.4, 2.2, 0.1))]
    for paper, true, r in cases:
        E_p, E_t = paper.matrix(r), true.matrix(r)
        for _ in range(5):
            r_dot, r_dot_td = rng.normal(size=6), rng.normal(size=E_p.shape[0])
            pseudo = pseudo_desired_velocity(E_p, E_t, r_dot_td, r_dot)
            np.testing.assert_allclose(E_p @ r_dot - pseudo, E_t @ r_dot - r_dot_td, atol=1e-12)


def test_true_velocity_rows_have_the_units_of_the_task(rng):
    """Crank: E_t r-dot = (psi-dot, alpha-dot) on a circle of radius 0.2; sphere: t_2 . p-dot = -z-dot."""
    chart = EulerZXZChart()
    crank = crank_constraint(chart, radius=0.2, center=(0.5, 0.1), form="paper")
    E_t = crank_true_velocity_projection(chart, center=(0.5, 0.1), radius=0.2)
    alpha, alpha_dot = 0.7, 1.3
    r = crank_point(alpha, 0.0, radius=0.2, height=0.3, center=(0.5, 0.1))
    r_dot = np.array([-0.2 * np.cos(alpha) * alpha_dot, -0.2 * np.sin(alpha) * alpha_dot, 0, alpha_dot, 0, 0.4])
    np.testing.assert_allclose(crank.force_projection(r) @ r_dot, 0, atol=1e-12)
    np.testing.assert_allclose(E_t.matrix(r) @ r_dot, [0.4, alpha_dot], atol=1e-12)
    sphere_rows = sphere_true_velocity_projection(PoseChart(), center=(0, 0, 0.1), radius=0.15)
    x = PoseChart().configuration_of_pose(EulerZXZChart().pose(np.r_[[0, 0, 0.1] + 0.15 * sphere_point(0.3, 2.0, 0)[:3],
                                                                     0.3, 2.0, 0.0]))
    v = rng.normal(size=3)
    p_hat = (x[:3] - [0, 0, 0.1]) / 0.15
    v -= (v @ p_hat) * p_hat                                            # tangent to the sphere
    np.testing.assert_allclose((sphere_rows.matrix(x) @ np.r_[v, 0, 0, 0])[2], -v[2], atol=1e-12)


def check_projection_rate(space, x, nu, x_dot):
    E_p_plus = space.evaluate(x + EPS * x_dot, nu, check=False).velocity_projection
    E_p_minus = space.evaluate(x - EPS * x_dot, nu, check=False).velocity_projection
    np.testing.assert_allclose(space.evaluate(x, nu).velocity_curvature, (E_p_plus - E_p_minus) @ nu / (2 * EPS),
                               atol=1e-7)


@pytest.mark.parametrize("chart_name", ["euler", "pose"])
def test_kernel_projection_is_orthonormal_smooth_and_differentiated_correctly(chart_name, rng):
    if chart_name == "euler":
        chart = EulerZXZChart()
        sphere = sphere_constraint(chart, radius=1.0, form="paper", dropped_component=3)
        anchor = sphere_point(0.4, 2.2, 0.1)
        configuration_rate = lambda x, nu: nu
    else:
        chart = PoseChart()
        sphere = sphere_constraint(chart, radius=1.0, form="approach")
        anchor = chart.configuration_of_pose(EulerZXZChart().pose(sphere_point(0.4, 2.2, 0.1)))
        configuration_rate = lambda x, nu: np.r_[nu[:3], (np.cross(nu[3:], x[3:].reshape(3, 3).T).T).reshape(-1)]
    projection = KernelVelocityProjection(sphere, anchor)
    space = ConstraintSpace(sphere, projection)
    values = space.evaluate(anchor, np.zeros(6))
    np.testing.assert_allclose(values.velocity_projection, projection.basis, atol=1e-12)   # equals G at the anchor
    for _ in range(5):
        x = anchor + 0.05 * rng.normal(size=anchor.size)
        nu = rng.normal(size=6)
        values = space.evaluate(x, nu)
        E_p, E_f = values.velocity_projection, values.force_projection
        np.testing.assert_allclose(E_p @ E_p.T, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(E_f @ E_p.T, 0, atol=1e-12)
        check_projection_rate(space, x, nu, configuration_rate(x, nu))
        values_ad = space.evaluate(InitializeAutoDiff(x).reshape(-1), InitializeAutoDiff(nu).reshape(-1))
        np.testing.assert_allclose(value(values_ad.velocity_projection), E_p, atol=1e-13)
        np.testing.assert_allclose(value(values_ad.velocity_curvature), values.velocity_curvature, atol=1e-12)


def test_given_projection_rate_matches_finite_differences(rng):
    chart = EulerZXZChart()
    crank = crank_constraint(chart, radius=1.0, form="paper")
    x, y = chart.symbols[:2]
    E_p = GivenVelocityProjection(chart, [[0, 0, 0, 0, 0, 1], [-y, x, 0, 1, 0, 0]], name="(3.3-6)")
    space = ConstraintSpace(crank, E_p)
    r, nu = crank_point(0.2, 0.3), rng.normal(size=6)
    check_projection_rate(space, r, nu, nu)


def test_split_wrench_sign_and_scaling():
    """Example 2.1: the robot pushes up on a ceiling y = 1 with 5 N, so F = -5 (docs/theory.md §0)."""
    chart = PlanarChart()
    E_p = GivenVelocityProjection(chart, [[1, 0, 0], [0, 0, 1]])
    space = ConstraintSpace(window_constraint(chart, height=1.0), E_p)
    x = np.array([0.4, 1.0, 0.0])
    values = space.evaluate(x, np.zeros(3))
    on_robot = np.array([0, 0, 0, 0, 0, -5.0])     # SpatialForce [n; f] in world: the ceiling pushes down (-z)
    F_v, F = space.split_wrench(values, chart.generalized_force(x, on_robot))
    np.testing.assert_allclose(F, [-5.0])
    np.testing.assert_allclose(F_v, [0.0, 0.0])
    # Row scaling: C = 2 (y - 1) halves F.
    y = chart.symbols[1]
    scaled = ConstraintSpace(__import__("drake_hybrid").Constraint(chart, [2 * y - 2]), E_p)
    F_v, F = scaled.split_wrench(scaled.evaluate(x, np.zeros(3)), chart.generalized_force(x, on_robot))
    np.testing.assert_allclose(F, [-2.5])
    # A tangential (friction) force appears in F_v: along x-dot.
    F_v, F = space.split_wrench(values, chart.generalized_force(x, np.array([0, 0, 0, 1.5, 0, -5.0])))
    np.testing.assert_allclose(F_v, [1.5, 0.0])
    np.testing.assert_allclose(F, [-5.0])


def test_split_wrench_recovers_constraint_wrench_for_non_orthogonal_rows(rng):
    chart = EulerZXZChart()
    crank = crank_constraint(chart, radius=1.0, form="paper")
    space = ConstraintSpace(crank, crank_true_velocity_rows(chart))
    r = crank_point(0.5, 0.2)
    values = space.evaluate(r, np.zeros(6))
    F_true, F_v_true = rng.normal(size=4), rng.normal(size=2)
    w = values.force_projection.T @ F_true + values.velocity_projection.T @ F_v_true
    F_v, F = space.split_wrench(values, w)
    np.testing.assert_allclose(F, F_true, atol=1e-12)
    np.testing.assert_allclose(F_v, F_v_true, atol=1e-12)


def test_bad_projections_raise_clear_errors():
    chart = PlanarChart()
    window = window_constraint(chart)
    with pytest.raises(DimensionError, match="has 1 rows; constraint 'window' has m = 1 rows on a d = 3 chart"):
        ConstraintSpace(window, GivenVelocityProjection(chart, [[1, 0, 0]]))
    with pytest.raises(DimensionError, match="must have 3 columns"):
        GivenVelocityProjection(chart, [[1, 0]])
    # E_p rows dependent everywhere: refused when the space is built, not at the first evaluation.
    with pytest.raises(ConstraintRankError, match=r"E = \[E_p; E_f\] .*'twice x' is singular at every one of"):
        ConstraintSpace(window, GivenVelocityProjection(chart, [[1, 0, 0], [2, 0, 0]], name="twice x"))
    with pytest.raises(ValueError, match="same chart object"):
        ConstraintSpace(window, GivenVelocityProjection(PlanarChart(), [[1, 0, 0], [0, 0, 1]]))
