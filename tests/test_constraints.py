"""Constraints: the corrected E_f of (3.3-2), (3.3-10), curvature terms, branches, equator and pole."""

import numpy as np
import pytest
import sympy

import pydrake.symbolic as drake_symbolic
from pydrake.autodiffutils import InitializeAutoDiff

from drake_hybrid import (BranchError, ChartSingularityError, Constraint, ConstraintRankError, DimensionError,
                          EulerZXZChart, OffConstraintError, PlanarChart, PoseChart, UnknownVariableError,
                          crank_constraint, sphere_constraint, surface_constraint, window_constraint)
from drake_hybrid.core.linalg import value

EPS = 1e-6
sin, cos = np.sin, np.cos


def crank_point(phi, psi, radius=1.0, height=0.3, center=(0.0, 0.0)):
    """Inward-branch point of the crank: (x, y) = c + radius (-sin phi, cos phi), theta = pi/2."""
    return np.array([center[0] - radius * sin(phi), center[1] + radius * cos(phi), height, phi, np.pi / 2, psi])


def sphere_point(phi, theta, psi, radius=1.0, center=(0.0, 0.0, 0.0)):
    """Inward point of the sphere: p = c - radius a(phi, theta)."""
    a = np.array([sin(theta) * sin(phi), -sin(theta) * cos(phi), cos(theta)])
    return np.r_[np.asarray(center) - radius * a, phi, theta, psi]


def corrected_crank_E_f(r):
    """(3.3-2), corrected (docs/theory.md §2)."""
    x, y, z, phi, theta, psi = r
    return np.array([[2 * x, 2 * y, 0, 0, 0, 0],
                     [0, 0, 1, 0, 0, 0],
                     [0, 0, 0, 0, -sin(theta), 0],
                     [cos(phi), sin(phi), 0, -x * sin(phi) + y * cos(phi), 0, 0]])


def corrected_sphere_E_f(r):
    """(3.3-10), corrected (docs/theory.md §2)."""
    x, y, z, phi, theta, psi = r
    return np.array([
        [2 * x, 2 * y, 2 * z, 0, 0, 0],
        [0, cos(theta), sin(theta) * cos(phi), -z * sin(phi) * sin(theta), -y * sin(theta) + z * cos(phi) * cos(theta), 0],
        [-cos(theta), 0, sin(theta) * sin(phi), z * cos(phi) * sin(theta), z * sin(phi) * cos(theta) + x * sin(theta), 0]])


def crank_paper_E_p(r):
    """(3.3-6)."""
    x, y = r[:2]
    return np.array([[0, 0, 0, 0, 0, 1], [-y, x, 0, 1, 0, 0]])


def sphere_paper_E_p(r):
    """(3.3-11) with the corrected (3.3-13a) and (3.3-13b): rows e1, e2, e3."""
    x, y, z, phi, theta, psi = r
    p = np.array([x, y, z])
    A = np.array([[-z * sin(phi) * sin(theta), -y * sin(theta) + z * cos(phi) * cos(theta)],
                  [z * cos(phi) * sin(theta), z * sin(phi) * cos(theta) + x * sin(theta)]])
    t1 = np.cross([0, 0, 1.0], p)
    t2 = np.cross(t1, p)
    rows = [np.eye(6)[5]]
    for alpha in (t1, t2):
        rhs = [-alpha[1] * cos(theta) - alpha[2] * cos(phi) * sin(theta),
               alpha[0] * cos(theta) - alpha[2] * sin(phi) * sin(theta)]
        rows.append(np.r_[alpha, np.linalg.solve(A, rhs), 0])
    return np.array(rows)


def random_sphere_points(rng, n):
    """Points of the inward sphere N away from the poles and the equator."""
    out = []
    for _ in range(n):
        theta = rng.uniform(0.3, 1.2) if rng.random() < 0.5 else rng.uniform(1.95, 2.85)
        out.append(sphere_point(rng.uniform(-3, 3), theta, rng.uniform(-3, 3)))
    return out


def test_crank_E_f_is_the_corrected_3_3_2_and_orthogonal_to_3_3_6(rng):
    chart = EulerZXZChart()
    crank = crank_constraint(chart, radius=1.0, height=0.3, form="paper")
    for _ in range(20):
        r = rng.normal(size=6)
        r[4] = rng.uniform(0.3, 2.8)
        np.testing.assert_allclose(crank.force_projection(r), corrected_crank_E_f(r), atol=1e-14)
        # E_f E_p^T = 0 holds identically (not only on N) with the corrected E_f.
        np.testing.assert_allclose(crank.force_projection(r) @ crank_paper_E_p(r).T, 0, atol=1e-14)
    r = crank_point(0.4, 0.1)
    np.testing.assert_allclose(crank.value(r), 0, atol=1e-15)
    assert np.linalg.matrix_rank(crank.force_projection(r)) == 4
    assert np.linalg.det(np.vstack([crank_paper_E_p(r), crank.force_projection(r)])) == pytest.approx(4.0)


def test_sphere_E_f_is_the_corrected_3_3_10_and_orthogonal_to_3_3_11(rng):
    chart = EulerZXZChart()
    sphere = sphere_constraint(chart, radius=1.0, form="paper", dropped_component=3)
    for r in random_sphere_points(rng, 100):
        np.testing.assert_allclose(sphere.value(r), 0, atol=1e-14)
        E_f = sphere.force_projection(r)
        np.testing.assert_allclose(E_f, corrected_sphere_E_f(r), atol=1e-14)
        np.testing.assert_allclose(E_f @ sphere_paper_E_p(r).T, 0, atol=1e-12)


def test_sphere_det_A_is_minus_sin_cos_on_N(rng):
    for r in random_sphere_points(rng, 20):
        E_f = corrected_sphere_E_f(r)
        assert np.linalg.det(E_f[1:, 3:5]) == pytest.approx(-sin(r[4]) * cos(r[4]), abs=1e-12)


def test_crank_pseudo_velocity_relation_on_N(rng):
    """On N, E_p r-dot = (psi-dot, 2(-y x-dot + x y-dot)) and E_t r-dot = (psi-dot, -y x-dot + x y-dot)."""
    chart = EulerZXZChart()
    crank = crank_constraint(chart, radius=1.0, form="paper")
    for _ in range(10):
        r = crank_point(rng.uniform(-3, 3), rng.uniform(-3, 3))
        E_f = crank.force_projection(r)
        r_dot = np.linalg.svd(E_f)[2][4:].T @ rng.normal(size=2)        # admissible: E_f r-dot = 0
        x, y = r[:2]
        crank_rate = -y * r_dot[0] + x * r_dot[1]
        assert r_dot[3] == pytest.approx(crank_rate)                     # phi-dot is the crank angle rate
        np.testing.assert_allclose(crank_paper_E_p(r) @ r_dot, [r_dot[5], 2 * crank_rate], atol=1e-12)


@pytest.mark.parametrize("form", ["paper", "approach", "orientation"])
def test_crank_forms_vanish_on_the_inward_circle_and_reject_outward_starts(form):
    chart = EulerZXZChart()
    crank = crank_constraint(chart, radius=0.2, height=0.4, center=(0.5, -0.1), form=form)
    r = crank_point(0.7, -0.3, radius=0.2, height=0.4, center=(0.5, -0.1))
    np.testing.assert_allclose(crank.value(r), 0, atol=1e-14)
    crank.check_rank(r)
    crank.check_branch(r)
    if form != "orientation":
        # Outward: (x, y) on the circle with the approach vector pointing away from the axis.
        outward = r.copy()
        outward[:2] = [0.5 + 0.2 * sin(0.7), -0.1 - 0.2 * cos(0.7)]
        np.testing.assert_allclose(crank.value(outward), 0, atol=1e-14)
        with pytest.raises(BranchError, match="wrong branch of constraint 'crank'.*toward the crank axis"):
            crank.check_branch(outward)


def test_sphere_equator_paper_form_loses_rank_and_the_fix_keeps_it():
    chart = EulerZXZChart()
    r = sphere_point(0.3, np.pi / 2, 0.2, radius=0.15, center=(0.4, 0.0, 0.2))
    paper = sphere_constraint(chart, center=(0.4, 0.0, 0.2), radius=0.15, form="paper", dropped_component=3)
    np.testing.assert_allclose(paper.value(r), 0, atol=1e-15)
    assert np.linalg.matrix_rank(paper.force_projection(r)) == 2
    with pytest.raises(ConstraintRankError, match=r"constraint 'sphere .*' loses rank at \{x=.*theta=1.5708"):
        paper.check_rank(r)
    fixed = sphere_constraint(chart, center=(0.4, 0.0, 0.2), radius=0.15, form="paper", dropped_component="auto")
    assert np.linalg.matrix_rank(fixed.force_projection(r)) == 3
    fixed.check_rank(r)
    for dropped in (1, 2):  # keep components (2, 3) or (1, 3): both rank 3 at this equator point
        piece = sphere_constraint(chart, center=(0.4, 0.0, 0.2), radius=0.15, form="paper", dropped_component=dropped)
        assert np.linalg.matrix_rank(piece.force_projection(r)) == 3
    approach = sphere_constraint(chart, center=(0.4, 0.0, 0.2), radius=0.15, form="approach")
    assert np.linalg.matrix_rank(approach.force_projection(r)) == 3


def test_sphere_spurious_equator_set_satisfies_the_paper_form():
    """{z = 0, cos(theta) = 0, x^2 + y^2 = 1} with a not radial satisfies (2.2-8) (docs/theory.md §2)."""
    chart = EulerZXZChart()
    paper = sphere_constraint(chart, radius=1.0, form="paper", dropped_component=3)
    r = np.array([cos(0.2), sin(0.2), 0.0, 1.3, np.pi / 2, 0.4])     # a is horizontal but not -p
    np.testing.assert_allclose(paper.value(r), 0, atol=1e-15)
    approach = sphere_constraint(chart, radius=1.0, form="approach")
    assert np.abs(approach.value(r)).max() > 0.5


def test_sphere_pole_euler_chart_fails_and_pose_chart_works():
    """Appendix B case (i): at the pole the Euler chart is singular; the p + a form on PoseChart is regular."""
    from pydrake.math import RigidTransform, RotationMatrix

    euler = EulerZXZChart()
    X_pole = RigidTransform(RotationMatrix.MakeXRotation(np.pi), [0, 0, 0.15])   # a = -z, on top of the sphere
    with pytest.raises(ChartSingularityError):
        euler.configuration_of_pose(X_pole)
    chart = PoseChart()
    sphere = sphere_constraint(chart, radius=0.15, form="approach")
    x = chart.configuration_of_pose(X_pole)
    np.testing.assert_allclose(sphere.value(x), 0, atol=1e-15)
    sphere.check_rank(x)
    sphere.check_branch(x)
    assert np.linalg.matrix_rank(sphere.force_projection(x)) == 3


def test_appendix_b_case_iii_never_occurs_on_N(rng):
    """-det A = z sin(theta) (p . a) (B-2), and p . a = -1 on the inward branch of the unit sphere."""
    for r in random_sphere_points(rng, 20):
        p = r[:3]
        a = EulerZXZChart().pose(r).rotation().matrix()[:, 2]
        assert p @ a == pytest.approx(-1.0)
        A = corrected_sphere_E_f(r)[1:, 3:5]
        assert -np.linalg.det(A) == pytest.approx(r[2] * np.sin(r[4]) * (p @ a))


def test_appendix_b_pole_row_on_N():
    """Case (i): on N at sin(theta) = 0, x = y = 0 and E_f row 2 is (0, 1, 0, 0, z cos(phi) cos(theta), 0)."""
    r = sphere_point(0.7, 0.0, 0.1)
    np.testing.assert_allclose(r[:2], 0, atol=1e-15)
    z, phi, theta = r[2], r[3], r[4]
    np.testing.assert_allclose(corrected_sphere_E_f(r)[1], [0, 1, 0, 0, z * cos(phi) * cos(theta), 0], atol=1e-15)
    chart = EulerZXZChart()
    with pytest.raises(ChartSingularityError):
        chart.check(r)


def trajectory_points(chart, rng):
    if isinstance(chart, PoseChart):
        from pydrake.math import RigidTransform, RollPitchYaw

        X = RigidTransform(RollPitchYaw(rng.normal(size=3)), rng.normal(size=3))
        return chart.configuration_of_pose(X)
    x = rng.normal(size=chart.configuration_size)
    if isinstance(chart, EulerZXZChart):
        x[4] = rng.uniform(0.4, 2.7)
    return x


def constraints_for_derivative_tests():
    euler, pose, planar = EulerZXZChart(), PoseChart(), PlanarChart()
    ellipsoid = lambda p: p[0] ** 2 / 0.09 + p[1] ** 2 / 0.04 + (p[2] - 0.3) ** 2 / 0.01 - 1
    return [
        crank_constraint(euler, form="paper"),
        crank_constraint(pose, form="approach"),
        crank_constraint(pose, form="orientation"),
        sphere_constraint(euler, form="paper", dropped_component=3),
        sphere_constraint(pose, form="approach"),
        surface_constraint(pose, ellipsoid),
        surface_constraint(euler, ellipsoid),
        window_constraint(planar, height=1.0),
        surface_constraint(planar, lambda p: p[0] ** 2 + p[1] ** 2 - 1),
    ]


@pytest.mark.parametrize("constraint", constraints_for_derivative_tests(), ids=lambda c: f"{c.name}-{c.chart.name}")
def test_derivatives_match_finite_differences(constraint, rng):
    """E_f = d/dt C / nu, E_f-dot nu and E_f-dot along x(t) with x-dot = L(x) nu."""
    chart = constraint.chart
    x_rate = __import__("drake_hybrid.core.symbolic", fromlist=["CompiledFunction"]).CompiledFunction(
        "L nu", [chart.configuration_symbols, chart.velocity_symbols], chart.configuration_rate, vector=True)
    for _ in range(5):
        x = trajectory_points(chart, rng)
        nu = rng.normal(size=chart.velocity_size)
        x_dot = x_rate(x, nu)
        C_dot = (constraint.value(x + EPS * x_dot) - constraint.value(x - EPS * x_dot)) / (2 * EPS)
        np.testing.assert_allclose(constraint.force_projection(x) @ nu, C_dot, atol=1e-7)
        E_f_dot = (constraint.force_projection(x + EPS * x_dot) - constraint.force_projection(x - EPS * x_dot)) / (2 * EPS)
        np.testing.assert_allclose(constraint.force_projection_rate(x, nu), E_f_dot, atol=1e-7)
        np.testing.assert_allclose(constraint.curvature(x, nu), E_f_dot @ nu, atol=1e-7)


def test_curvature_is_the_hessian_term_3_0_8(rng):
    chart = EulerZXZChart()
    sphere = sphere_constraint(chart, radius=1.0, form="paper", dropped_component=3)
    r_symbols = sympy.Matrix(chart.symbols)
    hessians = [sympy.lambdify([chart.symbols], sympy.hessian(c, r_symbols)) for c in sphere.expressions]
    for _ in range(5):
        r, r_dot = trajectory_points(chart, rng), rng.normal(size=6)
        expected = [r_dot @ np.array(H(r), dtype=float) @ r_dot for H in hessians]
        np.testing.assert_allclose(sphere.curvature(r, r_dot), expected, atol=1e-12)


@pytest.mark.parametrize("constraint", constraints_for_derivative_tests()[:6], ids=lambda c: f"{c.name}-{c.chart.name}")
def test_autodiff_evaluations_equal_float(constraint, rng):
    chart = constraint.chart
    x = trajectory_points(chart, rng)
    nu = rng.normal(size=chart.velocity_size)
    x_ad = InitializeAutoDiff(x).reshape(-1)
    nu_ad = InitializeAutoDiff(nu).reshape(-1)
    for method, args, args_ad in [("value", (x,), (x_ad,)), ("force_projection", (x,), (x_ad,)),
                                  ("curvature", (x, nu), (x_ad, nu_ad)),
                                  ("force_projection_rate", (x, nu), (x_ad, nu_ad))]:
        got = getattr(constraint, method)(*args_ad)
        assert got.dtype == object
        np.testing.assert_allclose(value(got), getattr(constraint, method)(*args), atol=1e-14, err_msg=method)


def test_autodiff_derivative_of_C_is_E_f_on_r_charts(rng):
    chart = EulerZXZChart()
    crank = crank_constraint(chart, form="paper")
    r = trajectory_points(chart, rng)
    C = crank.value(InitializeAutoDiff(r).reshape(-1))
    np.testing.assert_allclose(np.array([c.derivatives() for c in C]), crank.force_projection(r), atol=1e-14)


def test_user_constraint_in_a_few_lines_with_pydrake_symbolic():
    chart = EulerZXZChart()
    x, y, z, phi, theta, psi = (drake_symbolic.Variable(str(s)) for s in chart.symbols)
    table = Constraint(chart, [z - 0.8, drake_symbolic.cos(theta) + 1.0], name="table")
    r = np.array([0.1, 0.2, 0.8, 0.3, 2.0, 0.0])
    np.testing.assert_allclose(table.value(r), [0.0, np.cos(2.0) + 1.0], atol=1e-15)
    np.testing.assert_allclose(table.force_projection(r), [[0, 0, 1, 0, 0, 0], [0, 0, 0, 0, -np.sin(2.0), 0]], atol=1e-15)


def test_bad_constraints_raise_clear_errors():
    chart = EulerZXZChart()
    x, y, z, phi, theta, psi = chart.symbols
    w = sympy.Symbol("w")
    with pytest.raises(UnknownVariableError, match=r"constraint 'bad' uses variables \['w'\] that are not coordinates"):
        Constraint(chart, [x + w], name="bad")
    with pytest.raises(DimensionError, match="needs 1 <= m <= 5"):
        Constraint(chart, [x, y, z, phi, theta, psi], name="all")
    with pytest.raises(DimensionError, match="kinematic_rows"):
        Constraint(chart, [x], kinematic_rows=[3])
    with pytest.raises(TypeError, match="needs a chart of type EulerZXZChart"):
        crank_constraint(PoseChart(), form="paper")
    with pytest.raises(TypeError, match="needs a 6-DOF chart"):
        sphere_constraint(PlanarChart())
    with pytest.raises(ValueError, match="unknown form 'round'"):
        sphere_constraint(chart, form="round")
    with pytest.raises(DimensionError, match="C\\[constraint\\]: expected an argument of size 6, got 5"):
        Constraint(chart, [x]).value(np.zeros(5))
    with pytest.raises(DimensionError, match="normal must be a nonzero 2-vector"):
        window_constraint(PlanarChart(), normal=(0, 0))


def test_rank_deficient_user_constraint_names_itself_and_the_configuration():
    chart = PlanarChart()
    x, y, theta = chart.symbols
    doubled = Constraint(chart, [y - 1, 2 * y - 2], name="doubled window")
    with pytest.raises(ConstraintRankError, match=r"constraint 'doubled window' loses rank at \{x=0.3, y=1, theta=0\}"):
        doubled.check_rank(np.array([0.3, 1.0, 0.0]))


def test_start_off_the_constraint_is_reported():
    window = window_constraint(PlanarChart(), height=1.0)
    window.check_satisfied(np.array([0.2, 1.0 + 1e-9, 0.0]), tolerance=1e-6)
    with pytest.raises(OffConstraintError, match=r"not on constraint 'window': C = \[-0.5\]"):
        window.check_satisfied(np.array([0.2, 0.5, 0.0]), tolerance=1e-3)
