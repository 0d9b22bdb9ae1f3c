"""A workpiece given as data (core.height_map): loading and checking the grid, the pad's rolling
offset against the exact one, the constraint against the analytic surface, its derivatives against
central differences (float and AutoDiffXd), and the closed mesh."""

import math

import numpy as np
import pytest

from pydrake.autodiffutils import InitializeAutoDiff
from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from drake_hybrid.core.charts import PoseChart
from drake_hybrid.core.errors import PathError
from drake_hybrid.core.height_field import REACH
from drake_hybrid.core.height_map import HeightMap, HeightMapSurface

RADIUS, PAD = 0.15, 0.02
X_WM = RigidTransform(RollPitchYaw(0.1, -0.05, 0.3), [0.4, 0.0, 0.1])


def cap(samples=33):
    """A sphere cap z = sqrt(R^2 - x^2 - y^2) sampled on a grid (map frame)."""
    x = np.linspace(-0.08, 0.08, samples)
    y = np.linspace(-0.07, 0.07, samples - 4)
    X, Y = np.meshgrid(x, y)
    return HeightMap(x, y, np.sqrt(RADIUS ** 2 - X ** 2 - Y ** 2), name="cap")


@pytest.fixture(scope="module")
def surface():
    return HeightMapSurface(cap(), X_WM)


@pytest.fixture(scope="module")
def constraint(surface):
    return surface.offset_constraint(PoseChart(), PAD)


def exact_value(x):
    """The same rows as the constraint, written from the exact offset sphere (rho = R + r), in numpy: the first
    the signed distance to second order (core.height_field), the others the held rows."""
    A = X_WM.rotation().inverse().matrix()
    X, Y, Z = A @ (x[:3] - X_WM.translation())
    rho2 = (RADIUS + PAD) ** 2
    H = math.sqrt(rho2 - X * X - Y * Y)
    H_X, H_Y = -X / H, -Y / H
    H_XX, H_XY, H_YY = -(rho2 - Y * Y) / H ** 3, -X * Y / H ** 3, -(rho2 - X * X) / H ** 3
    slope = math.sqrt(1 + H_X ** 2 + H_Y ** 2)
    first = (Z - H) / slope
    kappa = (H_X ** 2 * H_XX + 2 * H_X * H_Y * H_XY + H_Y ** 2 * H_YY) / slope ** 3
    gradient = A.T @ np.array([-H_X, -H_Y, 1.0])
    R = x[3:].reshape(3, 3)
    return np.array([first - kappa / 2 * first ** 2 / (1 + (first / REACH) ** 2), gradient @ R[:, 0],
                     gradient @ R[:, 1]])


def signed_distance(x):
    """The pad centre's signed distance from the exact offset sphere."""
    return float(np.linalg.norm(X_WM.inverse().multiply(x[:3]))) - (RADIUS + PAD)


def configurations(chart, rng, count=4):
    """Pad centres near the offset surface, with arbitrary orientations."""
    result = []
    for _ in range(count):
        x, y = rng.uniform(-0.04, 0.04, size=2)
        centre = X_WM.multiply([x, y, math.sqrt((RADIUS + PAD) ** 2 - x * x - y * y)]) + rng.normal(0, 1e-3, 3)
        result.append(chart.configuration(RotationMatrix(RollPitchYaw(rng.normal(size=3))).matrix(), centre))
    return result


def moved(chart, x, nu, t):
    """x after moving with the constant twist nu for t: p + v t, exp([omega] t) R."""
    R = RotationMatrix(x[3:].reshape(3, 3))
    omega = nu[3:]
    angle = np.linalg.norm(omega) * t
    turn = RotationMatrix() if angle == 0 else RotationMatrix(AngleAxis(angle, omega / np.linalg.norm(omega)))
    return chart.configuration(turn.multiply(R).matrix(), x[:3] + nu[:3] * t)


# ------------------------------------------------------------------------------------------------
# The grid
# ------------------------------------------------------------------------------------------------

def test_a_height_map_loads_from_csv_npy_and_npz(tmp_path):
    heights = np.outer(np.arange(8), np.ones(7)) * 1e-3          # 8 rows (y) x 7 columns (x)
    np.savetxt(tmp_path / "part.csv", heights, delimiter=",")
    np.save(tmp_path / "part.npy", heights)
    np.savez(tmp_path / "part.npz", heights=heights, x=np.arange(7) * 0.01, y=np.arange(8) * 0.02)
    for name in ("part.csv", "part.npy"):
        loaded = HeightMap.from_file(tmp_path / name, spacing=[0.01, 0.02], origin=[0.1, -0.05])
        np.testing.assert_allclose(loaded.heights, heights)
        np.testing.assert_allclose(loaded.x, 0.1 + 0.01 * np.arange(7))
        np.testing.assert_allclose(loaded.y, -0.05 + 0.02 * np.arange(8))
    loaded = HeightMap.from_file(tmp_path / "part.npz")
    np.testing.assert_allclose(loaded.y, 0.02 * np.arange(8))


@pytest.mark.parametrize("heights, message", [
    (np.ones((5, 9)), r"9 x 5 samples \(x by y\) are too few; at least 6 per axis"),
    (np.where(np.eye(8) > 0, np.nan, 0.0), r"8 height\(s\) missing or not finite, the first at row 0, column 0"),
    (np.ones(12), "must be a 2-D grid"),
])
def test_a_grid_with_holes_or_too_few_samples_is_a_one_line_path_error(tmp_path, heights, message):
    np.save(tmp_path / "scan.npy", heights)
    with pytest.raises(PathError, match=message) as error:
        HeightMap.from_file(tmp_path / "scan.npy", spacing=0.005)
    assert "\n" not in str(error.value) and "scan.npy" in str(error.value)


def test_bad_files_and_coordinates_are_path_errors(tmp_path):
    (tmp_path / "text.csv").write_text("1,2,x\n")
    with pytest.raises(PathError, match="not a grid of numbers"):
        HeightMap.from_file(tmp_path / "text.csv", spacing=0.01)
    with pytest.raises(PathError, match="give the grid's spacing"):
        np.save(tmp_path / "a.npy", np.zeros((8, 8)))
        HeightMap.from_file(tmp_path / "a.npy")
    with pytest.raises(PathError, match="must be .csv, .npy or .npz"):
        (tmp_path / "a.txt").write_text("0")
        HeightMap.from_file(tmp_path / "a.txt", spacing=0.01)
    with pytest.raises(PathError, match="does not exist"):
        HeightMap.from_file(tmp_path / "missing.csv", spacing=0.01)
    with pytest.raises(PathError, match="x coordinates must be finite and strictly increasing"):
        HeightMap(np.r_[0.0, 0.02, 0.01, 0.03, 0.04, 0.05], np.arange(6) * 0.01, np.zeros((6, 6)))


# ------------------------------------------------------------------------------------------------
# The surface, the offset and the constraint
# ------------------------------------------------------------------------------------------------

def test_the_pads_rolling_offset_of_a_sampled_sphere_is_the_larger_sphere(surface):
    field = surface.offset_field(PAD)
    points = np.linspace(-0.045, 0.045, 7)
    for a in points:
        for b in points:
            assert field(a, b) == pytest.approx(math.sqrt((RADIUS + PAD) ** 2 - a * a - b * b), abs=1e-9)


def test_lift_and_closest_point_agree_with_the_spline(surface):
    view = surface.default_view()
    q, n = surface.lift(view, 0.02, -0.01)
    np.testing.assert_allclose(surface.field.map_point(q), [0.02, -0.01, surface.field(0.02, -0.01)], atol=1e-12)
    closest, normal = surface.closest_point(q + 0.004 * n)
    np.testing.assert_allclose(closest, q, atol=1e-10)
    np.testing.assert_allclose(normal, n, atol=1e-10)
    assert surface.signed_distance(q + 0.004 * n) == pytest.approx(0.004, abs=1e-10)
    with pytest.raises(PathError, match="outside the grid"):
        surface.lift(view, 0.09, 0.0)


def test_the_constraint_matches_the_analytic_surface(constraint, rng):
    """C, E_f and E_f-dot nu against the exact offset sphere's rows: their value, and their first and
    second derivatives along a motion with a constant twist (central differences)."""
    chart = constraint.chart
    for x in configurations(chart, rng):
        nu = rng.normal(size=6) * [0.1, 0.1, 0.1, 1, 1, 1]
        np.testing.assert_allclose(constraint.value(x), exact_value(x), atol=1e-9)
        h = 1e-4
        plus, minus = exact_value(moved(chart, x, nu, h)), exact_value(moved(chart, x, nu, -h))
        np.testing.assert_allclose(constraint.force_projection(x) @ nu, (plus - minus) / (2 * h), atol=1e-6)
        second = (plus - 2 * exact_value(x) + minus) / h ** 2
        np.testing.assert_allclose(constraint.curvature(x, nu), second, atol=1e-4 * max(1.0, np.max(np.abs(second))))
    # On the surface the first row's gradient is the unit normal: its force is the normal force in N.
    x = chart.configuration(np.eye(3), X_WM.multiply([0.0, 0.0, RADIUS + PAD]))
    assert np.linalg.norm(constraint.force_projection(x)[0, :3]) == pytest.approx(1.0, abs=1e-9)
    # Off it (the pad pressed in or lifted, up to 3 mm) the first row is the signed distance to second order: its
    # remainder is third order, below |f|^3 / rho^2 (at most 9.3e-7 here; the first-order distance alone was off
    # by up to 2.8e-6), and its gradient the unit normal to second order.
    for depth in (-0.003, -0.001, 0.002):
        for X, Y in ((0.0, 0.0), (0.03, -0.02), (-0.04, 0.035)):
            on = np.array([X, Y, math.sqrt((RADIUS + PAD) ** 2 - X * X - Y * Y)])
            p = X_WM.multiply(on * (1 + depth / (RADIUS + PAD)))
            x = chart.configuration(np.eye(3), p)
            assert constraint.value(x)[0] == pytest.approx(signed_distance(x), abs=abs(depth) ** 3 / (RADIUS + PAD) ** 2)
            gradient = constraint.force_projection(x)[0, :3]
            normal = X_WM.rotation().multiply(on / np.linalg.norm(on))
            np.testing.assert_allclose(gradient, normal, atol=(depth / (RADIUS + PAD)) ** 2)


def test_the_constraints_derivatives_are_those_of_its_value_along_a_motion(constraint, rng):
    """E_f nu = d/dt C, E_f-dot nu = d/dt (E_f nu) and E_f-dot = d/dt E_f along x(t) moving with nu
    (central differences of the constraint's own float path)."""
    chart, h = constraint.chart, 1e-6
    for x in configurations(chart, rng):
        nu = rng.normal(size=6) * [0.1, 0.1, 0.1, 1, 1, 1]
        plus, minus = moved(chart, x, nu, h), moved(chart, x, nu, -h)
        np.testing.assert_allclose((constraint.value(plus) - constraint.value(minus)) / (2 * h),
                                   constraint.force_projection(x) @ nu, atol=1e-7)
        rate = (constraint.force_projection(plus) - constraint.force_projection(minus)) / (2 * h)
        np.testing.assert_allclose(rate, constraint.force_projection_rate(x, nu), atol=1e-5)
        np.testing.assert_allclose(rate @ nu, constraint.curvature(x, nu), atol=1e-5)


def test_the_autodiff_gradients_are_the_central_differences_of_the_float_path(constraint, rng):
    chart, h = constraint.chart, 1e-6
    x = configurations(chart, rng, 1)[0]
    nu = rng.normal(size=6)
    variables = InitializeAutoDiff(np.concatenate([x, nu])).reshape(-1)
    for name, call in (("E_f", lambda x_, nu_: constraint.force_projection(x_)),
                       ("E_f-dot nu", lambda x_, nu_: constraint.curvature(x_, nu_)),
                       ("C", lambda x_, nu_: constraint.value(x_))):
        value = np.asarray(call(variables[:12], variables[12:])).ravel()
        gradient = np.array([v.derivatives() if hasattr(v, "derivatives") else np.zeros(18) for v in value])
        float_value = np.asarray(call(x, nu)).ravel()
        np.testing.assert_allclose([v.value() if hasattr(v, "value") else v for v in value], float_value, atol=1e-12)
        for k in range(18):
            step = np.zeros(18)
            step[k] = h
            plus, minus = np.concatenate([x, nu]) + step, np.concatenate([x, nu]) - step
            difference = (np.asarray(call(plus[:12], plus[12:])).ravel()
                          - np.asarray(call(minus[:12], minus[12:])).ravel()) / (2 * h)
            scale = max(1.0, np.max(np.abs(difference)))
            np.testing.assert_allclose(gradient[:, k], difference, atol=2e-6 * scale, err_msg=f"{name}, variable {k}")


def test_a_part_curving_inward_more_tightly_than_the_pad_is_refused():
    x = np.linspace(-0.05, 0.05, 41)
    X, Y = np.meshgrid(x, x)
    dip = HeightMap(x, x, -0.005 * np.exp(-(X ** 2 + Y ** 2) / (2 * 0.005 ** 2)), name="dimple")
    with pytest.raises(PathError, match="dimple: a pad of radius 20 mm cannot roll over the part near"):
        HeightMapSurface(dip).offset_field(PAD)


def test_the_mesh_is_closed_outward_and_follows_the_spline(surface):
    vertices, triangles = surface.mesh(resolution=0.004, thickness=0.01)
    edges = {}
    for triangle in triangles:
        for i in range(3):
            edge = (triangle[i], triangle[(i + 1) % 3])
            edges[edge] = edges.get(edge, 0) + 1
    assert all(count == 1 and edges.get((b, a)) == 1 for (a, b), count in edges.items())   # closed, consistent
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    volume = np.sum(np.einsum("ij,ij->i", a, np.cross(b, c))) / 6.0                           # outward: positive
    x, y = surface.height_map.x, surface.height_map.y
    bottom = vertices[:, 2].min()
    area = (x[-1] - x[0]) * (y[-1] - y[0])
    expected = surface.field.spline.integral(x[0], x[-1], y[0], y[-1]) - bottom * area
    # The facets are chords of the spline: below it by at most resolution^2 max|h''| / 8 (|h''| <= 15 1/m here).
    assert 0 < expected - volume <= area * 0.004 ** 2 * 15.0 / 8
    top = vertices[:-1][vertices[:-1, 2] > bottom]
    np.testing.assert_allclose(top[:, 2], surface.field(top[:, 0], top[:, 1]), atol=1e-12)
