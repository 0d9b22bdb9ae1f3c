"""Paths over a workpiece (core.surfaces, core.patterns, core.paths): geometry, limits, time
parameterization against finite differences, and the typed errors of bad paths."""

import math

import numpy as np
import pytest

from drake_hybrid.core.charts import PoseChart
from drake_hybrid.core.errors import PathError
from drake_hybrid.core.paths import PathLimits, SurfacePath, path_from_strokes, path_from_waypoints
from drake_hybrid.core.patterns import raster, spiral
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.core.surfaces import (CylinderSurface, PlaneSurface, SphereSurface, ViewPlane, check_facing,
                                        view_projection)
from drake_hybrid.systems.path_source import reference_frame

CENTER = np.array([0.45, 0.0, 0.10])
SPHERE = SphereSurface(CENTER, 0.15)
PAD = 0.02
LIMITS = PathLimits(0.05, 0.5)


@pytest.fixture(scope="module")
def raster_path():
    """Three strokes of a raster on the sphere's cap (two lines and the step between them)."""
    return path_from_strokes(SPHERE, SPHERE.default_view(), raster([0.0, 0.0], [0.06, 0.02], 0.02), PAD, LIMITS, 10.0)


def _samples(path, step=0.001):
    times = np.arange(0.0, path.duration, step)
    return times, [path.evaluate(t) for t in times]


# ------------------------------------------------------------------------------------------------
# Surfaces
# ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("surface", [
    PlaneSurface([0.4, 0.0, 0.2], [0.1, -0.2, 1.0]),
    SphereSurface(CENTER, 0.15),
    CylinderSurface([0.4, 0.0, 0.1], [1.0, 0.2, 0.0], 0.12, length=0.4),
], ids=["plane", "sphere", "cylinder"])
def test_a_lifted_point_is_on_the_surface_with_its_normal_and_its_pad_centre_on_the_offset_constraint(surface, rng):
    chart = PoseChart()
    constraint = surface.offset_constraint(chart, PAD)
    view = surface.default_view()
    for u, v in rng.uniform(-0.04, 0.04, size=(5, 2)):
        q, n = surface.lift(view, u, v)
        assert surface.signed_distance(q) == pytest.approx(0.0, abs=1e-12)
        np.testing.assert_allclose(view.coordinates(q), [u, v], atol=1e-12)        # seen at (u, v)
        np.testing.assert_allclose(surface.normal(q + 0.01 * n), n, atol=1e-12)    # the offset family's normal
        assert n @ view.normal > 0                                                 # the visible side
        # The pad centre with a = -n: every row of C is zero, and grad f_r is the unit normal.
        o1 = np.cross(n, [0.3, 1.0, 0.1])
        o1 /= np.linalg.norm(o1)
        R = np.column_stack([o1, np.cross(-n, o1), -n])
        x = chart.configuration(R, q + PAD * n)
        np.testing.assert_allclose(constraint.value(x), 0.0, atol=1e-12)
        np.testing.assert_allclose(constraint.force_projection(x)[0], np.r_[n, 0, 0, 0], atol=1e-12)
        closest, normal = surface.closest_point(q + 0.003 * n + 0.001 * o1)
        np.testing.assert_allclose(closest, surface.closest_point(closest)[0], atol=1e-12)
        assert surface.signed_distance(q + 0.003 * n) == pytest.approx(0.003, abs=1e-12)


def test_the_view_rows_make_E_invertible_on_the_cap_and_a_steep_place_is_refused():
    chart = PoseChart()
    space = ConstraintSpace(SPHERE.offset_constraint(chart, PAD), view_projection(chart, SPHERE.default_view()))
    q, n = SPHERE.lift(SPHERE.default_view(), 0.05, 0.05)          # a corner of the 10 cm patch: 28 deg
    R = np.column_stack([np.cross(-n, [0, 1, 0]) / np.linalg.norm(np.cross(-n, [0, 1, 0])), np.zeros(3), -n])
    R[:, 1] = np.cross(R[:, 2], R[:, 0])
    values = space.evaluate(chart.configuration(R, q + PAD * n), np.zeros(6))
    assert values.factorization.rank_margin() > 10 * space.invertibility_tolerance
    view = SPHERE.default_view()
    check_facing(n, view, "here")
    with pytest.raises(PathError, match=r"faces 70\.0 deg away .* \(at most 60 deg\)"):
        check_facing(SPHERE.lift(view, 0.15 * math.sin(math.radians(70)), 0.0)[1], view, "the point")


def test_a_view_line_that_misses_the_surface_is_a_path_error():
    with pytest.raises(PathError, match="misses the surface"):
        SPHERE.lift(SPHERE.default_view(), 0.2, 0.0)
    with pytest.raises(PathError, match="beyond the cylinder's length"):
        CylinderSurface([0, 0, 0], [1, 0, 0], 0.1, length=0.2).lift(ViewPlane.make(), 0.15, 0.0)
    with pytest.raises(PathError, match="axis_v must not be parallel"):
        ViewPlane.make(axis_u=[1, 0, 0], axis_v=[2, 0, 0])


# ------------------------------------------------------------------------------------------------
# Patterns
# ------------------------------------------------------------------------------------------------

def test_a_raster_covers_its_region_boustrophedon_with_the_spacing():
    strokes = raster([0.01, -0.02], [0.10, 0.05], 0.02, direction="u")
    lines = strokes[::2]
    assert len(lines) == 4 and len(strokes) == 7                    # ceil(0.05 / 0.02) + 1 lines, 3 steps
    offsets = [line[0, 1] for line in lines]
    np.testing.assert_allclose(offsets, np.linspace(-0.045, 0.005, 4))   # edge to edge, evenly (<= 0.02 apart)
    for index, line in enumerate(lines):
        np.testing.assert_allclose(np.sort([line[0, 0], line[-1, 0]]), [-0.04, 0.06])
        assert (line[-1, 0] > line[0, 0]) == (index % 2 == 0)       # alternating directions
    for before, step, after in zip(strokes[0::2], strokes[1::2], strokes[2::2]):
        np.testing.assert_allclose(step[[0, -1]], [before[-1], after[0]])
    assert max(np.max(np.linalg.norm(np.diff(s, axis=0), axis=1)) for s in strokes) <= 0.001 + 1e-12
    vertical = raster([0, 0], [0.1, 0.05], 0.025, direction="v")
    assert len(vertical[::2]) == 5 and np.ptp(vertical[0][:, 1]) == pytest.approx(0.05)


def test_a_spiral_turns_out_to_its_radius_with_the_spacing():
    stroke, = spiral([0.0, 0.01], 0.05, 0.01)
    r = np.linalg.norm(stroke - [0.0, 0.01], axis=1)
    assert r[0] == pytest.approx(0.005) and r[-1] == pytest.approx(0.05)
    theta = np.unwrap(np.arctan2(stroke[:, 1] - 0.01, stroke[:, 0]))
    np.testing.assert_allclose(r, 0.01 * theta / (2 * math.pi), atol=1e-12)      # r grows by the spacing per turn
    np.testing.assert_allclose(np.linalg.norm(np.diff(stroke, axis=0), axis=1), 0.001, rtol=0.02)


@pytest.mark.parametrize("call, message", [
    (lambda: raster([0, 0], [0.1, 0.1], 0.0), r"pattern\.spacing must be a finite number > 0"),
    (lambda: raster([0, 0], [0.1, -0.1], 0.01), r"pattern\.size must be a finite number > 0"),
    (lambda: raster([0, 0], [0.1, 0.01], 0.02), r"spacing \(0\.02 m\) is larger than the region"),
    (lambda: raster([0, 0], [0.1, 0.1], 0.01, direction="x"), "direction must be one of 'u', 'v'"),
    (lambda: spiral([0, 0], 0.05, 0.06), r"spacing \(0\.06 m\) is larger than the radius"),
    (lambda: spiral([0, 0], math.inf, 0.01), r"radius must be a finite number > 0"),
])
def test_bad_patterns_are_one_line_path_errors(call, message):
    with pytest.raises(PathError, match=message) as error:
        call()
    assert "\n" not in str(error.value)


# ------------------------------------------------------------------------------------------------
# Paths and their time scaling
# ------------------------------------------------------------------------------------------------

def test_the_reference_lies_on_the_offset_surface_within_the_limits_and_starts_and_stops_at_rest(raster_path):
    path = raster_path
    assert len(path.segments) == 3
    times, samples = _samples(path)
    c = np.array([s.position for s in samples])
    v = np.array([s.velocity for s in samples])
    a = np.array([s.acceleration for s in samples])
    np.testing.assert_allclose(np.linalg.norm(c - CENTER, axis=1), 0.15 + PAD, atol=2e-6)
    speed, acceleration = np.linalg.norm(v, axis=1), np.linalg.norm(a, axis=1)
    assert speed.max() <= 0.05 * 1.001 and speed.max() > 0.05 * 0.99          # the limit, reached on the lines
    assert acceleration.max() <= 0.5 * 1.001 and acceleration.max() > 0.5 * 0.9
    for segment in path.segments:                                              # rest to rest
        for t in (segment.start_time, segment.start_time + segment.duration):
            assert np.linalg.norm(path.evaluate(t - 1e-12).velocity) < 1e-6
    np.testing.assert_allclose(path.evaluate(-1.0).position, path.first_point()[0])
    assert path.evaluate(path.duration + 1.0).segment == 3
    # The contact points lie on the sphere; the pad centre is the offset along the normal.
    np.testing.assert_allclose(np.linalg.norm(path.contact_points() - CENTER, axis=1), 0.15, atol=1e-12)


def test_the_velocity_and_acceleration_are_the_derivatives_of_the_reference(raster_path):
    path, h = raster_path, 1e-6
    for t in np.linspace(0.01, path.duration - 0.01, 60):
        s, plus, minus = path.evaluate(t), path.evaluate(t + h), path.evaluate(t - h)
        np.testing.assert_allclose((plus.position - minus.position) / (2 * h), s.velocity, atol=1e-7)
        np.testing.assert_allclose((plus.normal - minus.normal) / (2 * h), s.normal_rate, atol=1e-7)
        if np.linalg.norm(plus.acceleration - minus.acceleration) < 1e-3:      # not at a Toppra switch
            np.testing.assert_allclose((plus.velocity - minus.velocity) / (2 * h), s.acceleration, atol=1e-5)
            np.testing.assert_allclose((plus.normal_rate - minus.normal_rate) / (2 * h), s.normal_acceleration,
                                       atol=1e-5)


def test_the_reference_frame_turns_with_the_normal_and_keeps_its_heading(raster_path):
    """omega and omega-dot of R_d against central differences of R_d; a = -n; o_1 in the plane of a and h."""
    path, h, heading = raster_path, 1e-5, np.array([1.0, 0.3, 0.1])

    def frame(t):
        s = path.evaluate(t)
        return reference_frame(s.normal, s.normal_rate, s.normal_acceleration, heading), s.normal

    for t in np.linspace(0.05, path.duration - 0.05, 25):
        (R, omega, omega_dot), n = frame(t)
        (R_plus, omega_plus, _), _ = frame(t + h)
        (R_minus, omega_minus, _), _ = frame(t - h)
        W = (R_plus - R_minus) / (2 * h) @ R.T
        np.testing.assert_allclose([W[2, 1], W[0, 2], W[1, 0]], omega, atol=1e-8)
        np.testing.assert_allclose((omega_plus - omega_minus) / (2 * h), omega_dot, atol=1e-6)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(R[:, 2], -n, atol=1e-12)
        assert np.cross(R[:, 2], heading) @ R[:, 0] == pytest.approx(0.0, abs=1e-12)   # o_1 in the plane of a, h


def test_waypoints_are_projected_and_the_force_is_interpolated_along_the_arc_length():
    points = [CENTER + 0.15 * np.array([math.sin(a) * math.cos(b), math.sin(a) * math.sin(b), math.cos(a)])
              for a, b in [(0.2, 0.0), (0.3, 0.5), (0.25, 1.4), (0.1, 2.0)]]
    smooth = path_from_waypoints(SPHERE, points, PAD, LIMITS, [10.0, 12.0, 8.0, 10.0], 1e-3)
    assert len(smooth.segments) == 1
    np.testing.assert_allclose(smooth.force.forces, [10, 12, 8, 10])
    arcs = smooth.force.arc_lengths
    centres = smooth.segments[0].centres
    for point, arc in zip(points, arcs):                      # the force's knots are at the waypoints
        q, n = SPHERE.closest_point(point)
        index = int(np.argmin(np.linalg.norm(centres - (q + PAD * n), axis=1)))
        assert smooth.segments[0].arc_lengths[index] == pytest.approx(arc)
    assert smooth.force(0.5 * (arcs[1] + arcs[2])) == pytest.approx(10.0)
    linear = path_from_waypoints(SPHERE, points, PAD, LIMITS, 10.0, 1e-3, interpolation="linear")
    assert len(linear.segments) == 3 and linear.force(0.01) == 10.0
    np.testing.assert_allclose(np.linalg.norm(linear.centres() - CENTER, axis=1), 0.17, atol=1e-12)


@pytest.mark.parametrize("call, message", [
    (lambda: path_from_waypoints(SPHERE, [CENTER + [0, 0, 0.153], CENTER + [0.02, 0, 0.148]], PAD, LIMITS, 10.0,
                                 1e-3),
     r"waypoints\[0\] .* is \+3\.00 mm off the surface of 'sphere' \(tolerance 1 mm\)"),
    (lambda: path_from_waypoints(SPHERE, [CENTER + [0, 0, 0.15]], PAD, LIMITS, 10.0, 1e-3), "at least two"),
    (lambda: path_from_waypoints(SPHERE, [CENTER + [0, 0, 0.15]] * 2, PAD, LIMITS, 10.0, 1e-3), "coincide"),
    (lambda: path_from_strokes(SPHERE, SPHERE.default_view(), raster([0, 0], [0.1, 0.1], 0.05), PAD,
                               PathLimits(0.0, 0.5), 10.0), r"PathLimits: speed must be a finite number > 0"),
    (lambda: path_from_strokes(SPHERE, SPHERE.default_view(), raster([0, 0], [0.1, 0.1], 0.05), PAD,
                               PathLimits(0.05, math.nan), 10.0), r"PathLimits: acceleration must be a finite number > 0"),
    (lambda: path_from_strokes(SPHERE, SPHERE.default_view(), raster([0, 0], [0.4, 0.1], 0.05), PAD, LIMITS, 10.0),
     "misses the surface"),
    (lambda: path_from_strokes(SPHERE, SPHERE.default_view(), raster([0, 0], [0.26, 0.02], 0.02), PAD, LIMITS,
                               10.0), "faces .* deg away"),
    (lambda: path_from_strokes(SPHERE, SPHERE.default_view(), raster([0, 0], [0.04, 0.02], 0.02), PAD, LIMITS,
                               -5.0), "normal force must be positive"),
    (lambda: path_from_strokes(SPHERE, SPHERE.default_view(), raster([0, 0], [0.04, 0.02], 0.02), PAD, LIMITS,
                               [[0.0, 10.0], [9.0, 12.0]]), r"must lie in \[0, 0\.\d+\] m"),
])
def test_bad_paths_are_one_line_path_errors_before_the_run(call, message):
    with pytest.raises(PathError, match=message) as error:
        call()
    assert "\n" not in str(error.value)


def test_a_held_path_holds_its_point():
    path = SurfacePath.hold([0.1, 0.2, 0.3], [0.0, 0.0, 1.0], 7.0)
    sample = path.evaluate(3.0)
    np.testing.assert_allclose(sample.position, [0.1, 0.2, 0.3])
    assert np.all(sample.velocity == 0) and sample.force == 7.0 and path.duration == 0


@pytest.mark.parametrize("surface, offset_surface", [
    (PlaneSurface([0.4, 0.0, 0.2], [0.0, 0.0, 1.0]), lambda c: c[2] - (0.2 + PAD)),
    (SphereSurface(CENTER, 0.15), lambda c: np.linalg.norm(c - CENTER) - (0.15 + PAD)),
    (CylinderSurface([0.45, 0.0, 0.1], [1.0, 0.0, 0.0], 0.15, length=0.3),
     lambda c: np.linalg.norm((c - [0.45, 0.0, 0.1])[1:]) - (0.15 + PAD)),
], ids=["plane", "sphere cap", "cylinder patch"])
@pytest.mark.parametrize("pattern", ["raster", "spiral"])
def test_patterns_cover_a_plane_a_sphere_cap_and_a_cylinder_patch(surface, offset_surface, pattern):
    """Both patterns on each surface: the pad centre's reference on the offset surface throughout, the
    pattern's lines (turns) the spacing apart in the view, the contact points on the surface."""
    view = surface.default_view()
    if pattern == "raster":
        strokes = raster([0.0, 0.0], [0.04, 0.03], 0.015)
    else:
        strokes = spiral([0.0, 0.0], 0.02, 0.01)
    path = path_from_strokes(surface, view, strokes, PAD, LIMITS, 10.0)
    for t in np.linspace(0.0, path.duration, 200):
        assert offset_surface(path.evaluate(t).position) == pytest.approx(0.0, abs=2e-6)
    contacts = path.contact_points()
    np.testing.assert_allclose([surface.signed_distance(q) for q in contacts], 0.0, atol=1e-10)
    seen = view.coordinates(contacts)
    if pattern == "raster":
        lines = [view.coordinates(segment.contact_points) for segment in path.segments[::2]]
        for line, offset in zip(lines, [-0.015, 0.0, 0.015]):      # each line straight in the view, 1.5 cm apart
            np.testing.assert_allclose(line[:, 1], offset, atol=1e-12)
            assert np.ptp(line[:, 0]) == pytest.approx(0.04)
        assert len(lines) == 3
    else:
        radius = np.linalg.norm(seen, axis=1)
        assert radius[-1] == pytest.approx(0.02, abs=1e-9) and radius[0] == pytest.approx(0.005, abs=1e-9)
