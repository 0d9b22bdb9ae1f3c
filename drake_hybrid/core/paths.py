"""Paths over a workpiece: the pad centre's reference from waypoints or a pattern, time-parameterized.

A job's path is given on the workpiece (``core.surfaces``): waypoints in world coordinates, or the
strokes of a coverage pattern (``core.patterns``) in a view plane. ``path_from_waypoints`` and
``path_from_strokes`` turn it into a ``SurfacePath``, the reference of the pad's centre:

1. every stroke (a pattern's line, the step to the next line, the stretch between two waypoints
   with ``interpolation="linear"``, all the waypoints with ``"smooth"``) is sampled every
   ``patterns.STEP`` (1 mm): waypoints through a cubic ``PiecewisePolynomial`` in the world, then
   projected onto the surface (``closest_point``); pattern points lifted from the view
   (``lift``); a waypoint further than ``tolerance`` from the surface is a PathError;
2. each sample q (with its outward normal n) becomes the pad centre c = q + r n (r the pad's
   radius: the centre lies on the offset surface the task's constraint describes); the centres,
   over their arc length s, make a cubic spline P(s) with continuous second derivatives
   (``PiecewisePolynomial.CubicWithContinuousSecondDerivatives``), the normals another, N(s);
3. each stroke is a ``PathSegment`` from rest to rest, time-parameterized by Drake's ``Toppra``
   under the speed limit |c-dot| <= v and the acceleration limit |c-ddot| <= a (Toppra bounds the
   components of the acceleration in a frame along the stroke's chord; the solution is then
   sampled every millisecond and the box shrunk until the norm of the acceleration and the speed
   meet the limits, which Toppra meets only at its grid points);
4. the segments follow each other in time (the pad stops at each corner); the normal force
   F(s) is piecewise linear in the path's arc length (one value, one per waypoint, or a table).

``SurfacePath.evaluate(t)`` (t from the start of the path) gives the reference: c, c-dot,
c-ddot, the normal, F and where on the path it is; before the start it holds the first point at
rest, after the end the last. ``SurfacePath.hold(centre, normal, force)`` is the path of one point.

Every argument is checked at the call, before any Drake call: a bad one is a one-line ``PathError``
naming it (``evaluate``'s t finite, ``offset`` >= 0, at most ``core.patterns.MAX_PATH_POINTS`` samples).
"""

import math
from dataclasses import dataclass

import numpy as np

from pydrake.multibody.optimization import CalcGridPointsOptions, Toppra
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import PrismaticJoint, SpatialInertia
from pydrake.trajectories import PiecewisePolynomial

from drake_hybrid.core.arguments import describe, instance, number, numeric_array, positive, text, vector
from drake_hybrid.core.errors import PathError
from drake_hybrid.core.patterns import STEP, check_point_count, check_strokes
from drake_hybrid.core.surfaces import Surface, check_facing, check_offset, check_view

LIMIT_CHECK_PERIOD = 1e-3        # s: how finely a time scaling is checked against the limits
LIMIT_SLACK = 1e-3               # the limits may be exceeded by this fraction (Toppra's discretization)


@dataclass(frozen=True)
class PathLimits:
    """The speed (m/s) and acceleration (m/s^2) limits of the pad centre along a path."""

    speed: float
    acceleration: float

    def __post_init__(self):
        self.validated("")

    def validated(self, what="path"):
        """``self`` if both limits are positive finite numbers, else a PathError naming ``what``.field."""
        for name, unit in (("speed", "m/s"), ("acceleration", "m/s^2")):
            positive(getattr(self, name), f"{what}.{name}" if what else name, "PathLimits", unit=unit, error=PathError)
        return self


class ForceProfile:
    """The normal force (N) along the path, piecewise linear in its arc length s (m), constant beyond."""

    def __init__(self, arc_lengths, forces, what="path.force"):
        what = text(what, "what", "ForceProfile", error=PathError)
        self.arc_lengths = numeric_array(arc_lengths, f"{what} (arc lengths)", "ForceProfile",
                                         what="a vector of arc lengths (m)", error=PathError).reshape(-1)
        self.forces = numeric_array(forces, f"{what} (forces)", "ForceProfile", what="a vector of forces (N)",
                                    error=PathError).reshape(-1)
        if self.forces.size == 0 or self.arc_lengths.shape != self.forces.shape:
            raise PathError(f"{what}: give one force per arc length, got {self.forces.size} and "
                            f"{self.arc_lengths.size}")
        if not np.all(np.isfinite(self.forces)) or not np.all(self.forces > 0):
            raise PathError(f"{what}: the normal force must be positive and finite (N; the pad presses), got "
                            f"{self.forces.tolist()}")
        if not np.all(np.diff(self.arc_lengths) >= 0):
            raise PathError(f"{what}: the arc lengths must not decrease, got {self.arc_lengths.tolist()}")

    def __call__(self, s):
        """F(s), ``s`` a finite arc length (m)."""
        return float(np.interp(number(s, "s", "ForceProfile", unit="m", error=PathError), self.arc_lengths,
                               self.forces))


@dataclass
class PathSample:
    """The reference at one instant (world frame; floats)."""

    position: np.ndarray          # c, the pad centre (m)
    velocity: np.ndarray          # c-dot
    acceleration: np.ndarray      # c-ddot
    normal: np.ndarray            # n, the outward unit normal of the surface there
    normal_rate: np.ndarray       # n-dot
    normal_acceleration: np.ndarray   # n-ddot
    force: float                  # the normal force (N)
    segment: int                  # the segment's index (-1 before the start, len(segments) after the end)
    arc_length: float             # s along the whole path (m)


_POINT_PLANT = []


def _point_plant():
    """A point moved by three prismatic joints (x, y, z): Toppra's plant for a path of positions."""
    if not _POINT_PLANT:
        plant = MultibodyPlant(0.0)
        parent = plant.world_frame()
        for index, axis in enumerate(np.eye(3)):
            body = plant.AddRigidBody(f"point_{index}", SpatialInertia.SolidSphereWithMass(1.0, 0.01))
            plant.AddJoint(PrismaticJoint(f"axis_{index}", parent, body.body_frame(), axis))
            parent = body.body_frame()
        plant.Finalize()
        _POINT_PLANT.extend([plant, parent])
    return _POINT_PLANT


def _spline(arc_lengths, samples):
    """The cubic PiecewisePolynomial through ``samples`` (N x 3) over ``arc_lengths``, end slopes from the ends."""
    start = (samples[1] - samples[0]) / (arc_lengths[1] - arc_lengths[0])
    end = (samples[-1] - samples[-2]) / (arc_lengths[-1] - arc_lengths[-2])
    return PiecewisePolynomial.CubicWithContinuousSecondDerivatives(arc_lengths, samples.T, start, end)


def unit_and_rates(N, N_dot, N_ddot):
    """(n, n-dot, n-ddot) of n = N / |N| from N and its first two time derivatives."""
    length = np.sqrt(N @ N)
    n = N / length
    n_dot = (N_dot - (n @ N_dot) * n) / length
    length_dot = n @ N_dot
    n_ddot = (N_ddot - (n_dot @ N_dot + n @ N_ddot) * n - (n @ N_dot) * n_dot - n_dot * length_dot) / length
    return n, n_dot, n_ddot


def _kinematics(position, timing, times):
    """(c, c-dot, c-ddot) at ``times`` of a segment (position P(s), timing s(t))."""
    c, v, a = [], [], []
    for t in times:
        s, s_dot, s_ddot = (timing.EvalDerivative(t, k)[0, 0] if k else timing.value(t)[0, 0] for k in range(3))
        tangent, bend = position.EvalDerivative(s, 1)[:, 0], position.EvalDerivative(s, 2)[:, 0]
        c.append(position.value(s)[:, 0])
        v.append(tangent * s_dot)
        a.append(bend * s_dot * s_dot + tangent * s_ddot)
    return np.array(c), np.array(v), np.array(a)


def time_scaling(position, limits, frame):
    """s(t) of a segment from rest to rest (Toppra, module docstring step 3); ``frame``: 3 x 3, its
    columns the axes of the acceleration box (the first along the stroke)."""
    plant, point_frame = _point_plant()
    breaks = position.get_segment_times()
    samples = np.array([frame.T @ position.value(s)[:, 0] for s in breaks])
    local = _spline(np.asarray(breaks), samples)
    options = CalcGridPointsOptions()
    options.max_seg_length = 0.002
    grid = Toppra.CalcGridPoints(local, options)
    speed, box = limits.speed, limits.acceleration
    for _ in range(8):
        toppra = Toppra(local, plant, grid)
        toppra.AddFrameTranslationalSpeedLimit(point_frame, speed)
        toppra.AddJointAccelerationLimit(-box * np.ones(3), box * np.ones(3))
        timing = toppra.SolvePathParameterization()
        if timing is None:
            raise PathError(f"Toppra found no time scaling for a segment of {breaks[-1]:.4g} m under "
                            f"{limits.speed:g} m/s and {limits.acceleration:g} m/s^2")
        times = np.arange(timing.start_time(), timing.end_time(), LIMIT_CHECK_PERIOD)
        _, v, a = _kinematics(position, timing, np.append(times, timing.end_time()))
        worst_speed, worst_acceleration = np.max(np.linalg.norm(v, axis=1)), np.max(np.linalg.norm(a, axis=1))
        if worst_speed <= limits.speed * (1 + LIMIT_SLACK) and worst_acceleration <= limits.acceleration * (
                1 + LIMIT_SLACK):
            return timing
        speed *= min(1.0, limits.speed / worst_speed)
        box *= min(1.0, limits.acceleration / worst_acceleration)
    raise PathError(f"Toppra's time scaling of a segment of {breaks[-1]:.4g} m did not meet {limits.speed:g} m/s and "
                    f"{limits.acceleration:g} m/s^2 (reached {worst_speed:.4g} m/s, {worst_acceleration:.4g} m/s^2)")


class PathSegment:
    """One stroke from rest to rest (module docstring): the centres' spline P(s) and the normals'
    N(s) over s in [0, length], and Toppra's s(t) over [0, duration]."""

    def __init__(self, contact_points, normals, offset, limits, start_time=0.0, start_arc=0.0):
        owner = "PathSegment"
        offset, limits = check_offset(offset, owner), _limits(limits, owner)
        self.contact_points = _samples(contact_points, "contact_points", owner)
        self.normals = _samples(normals, "normals", owner)
        if self.normals.shape != self.contact_points.shape:
            raise PathError(f"{owner}: give one normal per contact point, got {len(self.normals)} and "
                            f"{len(self.contact_points)}")
        start_time, start_arc = (number(x, n, owner, error=PathError) for x, n in ((start_time, "start_time"),
                                                                                  (start_arc, "start_arc")))
        self.centres = self.contact_points + offset * self.normals
        steps = np.linalg.norm(np.diff(self.centres, axis=0), axis=1)
        keep = np.concatenate([[True], steps > 1e-9])                    # repeated points (a stop) once
        self.centres, self.normals, self.contact_points = (a[keep] for a in (self.centres, self.normals,
                                                                               self.contact_points))
        if len(self.centres) < 2:
            raise PathError("a path segment needs two distinct points")
        arcs = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(self.centres, axis=0), axis=1))])
        self.arc_lengths = arcs
        self.length = float(arcs[-1])
        self.position = _spline(arcs, self.centres)
        self.normal = _spline(arcs, self.normals)
        chord = self.centres[-1] - self.centres[0]
        axis = chord / np.linalg.norm(chord) if np.linalg.norm(chord) > 1e-9 else np.array([1.0, 0.0, 0.0])
        helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
        second = np.cross(axis, helper)
        second /= np.linalg.norm(second)
        self.timing = time_scaling(self.position, limits, np.column_stack([axis, second, np.cross(axis, second)]))
        self.duration = float(self.timing.end_time())
        self.start_time, self.start_arc = float(start_time), float(start_arc)

    def sample(self, t_local):
        """(c, c-dot, c-ddot, (n, n-dot, n-ddot), s) at ``t_local`` in [0, duration]; n = N / |N| of the
        normals' spline N(s), differentiated along s(t)."""
        t_local = min(max(number(t_local, "t_local", "PathSegment.sample", unit="s", error=PathError), 0.0),
                      self.duration)
        timing = self.timing
        s, s_dot, s_ddot = timing.value(t_local)[0, 0], timing.EvalDerivative(t_local, 1)[0, 0], \
            timing.EvalDerivative(t_local, 2)[0, 0]
        position, normal = self.position, self.normal
        tangent, bend = position.EvalDerivative(s, 1)[:, 0], position.EvalDerivative(s, 2)[:, 0]
        N = normal.value(s)[:, 0]
        N_dot = normal.EvalDerivative(s, 1)[:, 0] * s_dot
        N_ddot = normal.EvalDerivative(s, 2)[:, 0] * s_dot * s_dot + normal.EvalDerivative(s, 1)[:, 0] * s_ddot
        return (position.value(s)[:, 0], tangent * s_dot, bend * s_dot * s_dot + tangent * s_ddot,
                unit_and_rates(N, N_dot, N_ddot), float(s))


class SurfacePath:
    """Segments one after the other in time, and the force along them (module docstring)."""

    def __init__(self, segments, force, hold_point=None):
        owner = "SurfacePath"
        if isinstance(segments, (str, bytes)) or not hasattr(segments, "__iter__"):
            raise PathError(f"{owner}: segments must be a list of PathSegment, got {describe(segments)}")
        self.segments = list(segments)
        for index, segment in enumerate(self.segments):
            instance(segment, f"segments[{index}]", owner, PathSegment, error=PathError)
        self.force = instance(force, "force", owner, ForceProfile, error=PathError)
        if not self.segments and hold_point is None:
            raise PathError(f"{owner}: a path needs at least one segment (or SurfacePath.hold for one point)")
        time = arc = 0.0
        for segment in self.segments:
            segment.start_time, segment.start_arc = time, arc
            time, arc = time + segment.duration, arc + segment.length
        self.duration, self.length = time, arc
        self._starts = np.array([segment.start_time for segment in self.segments])
        self._hold = hold_point

    @staticmethod
    def hold(centre, normal, force):
        """The path of one point: the pad centre held at ``centre`` (normal ``normal``, made unit) with ``force``."""
        owner = "SurfacePath.hold"
        centre = vector(centre, "centre", owner, 3, unit="m", error=PathError)
        normal = vector(normal, "normal", owner, 3, error=PathError)
        if not np.linalg.norm(normal) > 1e-12:
            raise PathError(f"{owner}: normal must be a nonzero vector, got {normal.tolist()}")
        force = positive(force, "force", owner, unit="N; the pad presses", error=PathError)
        return SurfacePath([], ForceProfile([0.0], [force]), hold_point=(centre, normal / np.linalg.norm(normal)))

    def first_point(self):
        """(centre, normal) where the path starts."""
        if not self.segments:
            return self._hold
        return self.segments[0].centres[0], self.segments[0].normals[0]

    def evaluate(self, t):
        """The PathSample at ``t`` (s from the path's start; a finite number)."""
        t = number(t, "t", "SurfacePath.evaluate", unit="s from the path's start", error=PathError)
        zero = np.zeros(3)
        if not self.segments:
            centre, normal = self._hold
            return PathSample(centre, zero, zero, normal, zero, zero, self.force(0.0), 0, 0.0)
        if t < 0:
            centre, normal = self.first_point()
            return PathSample(centre, zero, zero, normal / np.linalg.norm(normal), zero, zero, self.force(0.0), -1, 0.0)
        index = int(np.searchsorted(self._starts, t, side="right")) - 1
        segment = self.segments[index]
        if t > self.duration:
            c, _, _, (n, _, _), s = segment.sample(segment.duration)
            return PathSample(c, zero, zero, n, zero, zero, self.force(self.length), len(self.segments), self.length)
        c, v, a, (n, n_dot, n_ddot), s = segment.sample(t - segment.start_time)
        arc = segment.start_arc + s
        return PathSample(c, v, a, n, n_dot, n_ddot, self.force(arc), index, arc)

    def centres(self):
        """Every sample's pad centre (N x 3), segment after segment (for plots)."""
        return np.vstack([segment.centres for segment in self.segments]) if self.segments else self._hold[0][None]

    def contact_points(self):
        return (np.vstack([segment.contact_points for segment in self.segments]) if self.segments
                else (self._hold[0] - 0.0 * self._hold[1])[None])


# ------------------------------------------------------------------------------------------------
# Building a path
# ------------------------------------------------------------------------------------------------

def _limits(limits, owner):
    """``limits`` if it is a PathLimits (checked when made), else a PathError."""
    return instance(limits, "limits", owner, PathLimits, what="a PathLimits(speed, acceleration)", error=PathError)


def _samples(points, name, owner):
    """N x 3 float points (m), N >= 1, finite, else a PathError naming ``name``."""
    allowed = "N x 3 finite [x, y, z] points (m)"
    array = numeric_array(points, name, owner, what=allowed, error=PathError)
    if array.ndim != 2 or array.shape[1] != 3 or len(array) == 0:
        raise PathError(f"{owner}: {name} must be {allowed}, got {describe(points)}")
    return array


def _force_profile(force, waypoint_arcs, length, what, owner):
    """A ForceProfile from a number, a list with one value per waypoint (``waypoint_arcs``, a callable
    giving them), or a table [[s, F], ...] (s in m along the path)."""
    allowed = "a number (N), " + ("one per waypoint, " if waypoint_arcs is not None else "") + "or a table [[s, F], ...]"
    values = numeric_array(force, what, owner, what=allowed, error=PathError)
    if values.ndim == 0:
        return ForceProfile([0.0], [float(values)], what)
    if values.ndim == 2 and values.shape[1] == 2 and len(values):
        if values[0, 0] < 0 or values[-1, 0] > length + 1e-9:
            raise PathError(f"{what}: the arc lengths of the force table must lie in [0, {length:.4g}] m (the path's "
                            f"length), got {values[:, 0].tolist()}")
        return ForceProfile(values[:, 0], values[:, 1], what)
    arcs = waypoint_arcs() if waypoint_arcs is not None else None
    if arcs is None or values.shape != (len(arcs),):
        raise PathError(f"{what}: give {allowed}, got {values.tolist()}")
    return ForceProfile(arcs, values, what)


def path_from_strokes(surface, view, strokes, offset, limits, force, what="path", force_field="force"):
    """A SurfacePath from pattern strokes ((u, v) polylines in ``view``): each stroke lifted onto
    ``surface`` (PathError where the view misses it or it faces away) and made a segment. ``force_field``:
    the field the force's messages name (``what``.``force_field``)."""
    owner = "path_from_strokes"
    what = text(what, "what", owner, error=PathError)
    surface = instance(surface, "surface", owner, Surface, what="a core.surfaces.Surface", error=PathError)
    view = check_view(view, owner)
    strokes = check_strokes(strokes, what, owner)
    offset, limits = check_offset(offset, owner), _limits(limits, owner)
    limits.validated(what)
    force_name = f"{what}.{text(force_field, 'force_field', owner, error=PathError)}"
    numeric_array(force, force_name, owner, what="a number (N) or a table [[s, F], ...]", error=PathError)
    segments = []
    for index, stroke in enumerate(strokes):
        lifted = []
        for u, v in stroke:
            try:
                q, n = surface.lift(view, u, v)
            except PathError as error:
                reason = str(error).rsplit(": ", 1)[-1]
                raise PathError(f"{what}: stroke {index} at (u, v) = ({u:.4g}, {v:.4g}) m is off '{surface.name}' as "
                                f"the view sees it ({reason}); keep the pattern on the surface: make "
                                f"{what}.pattern.size smaller or move {what}.pattern.center") from None
            check_facing(n, view, f"{what}: stroke {index} at (u, v) = ({u:.4g}, {v:.4g}) m")
            lifted.append((q, n))
        segments.append(PathSegment([q for q, _ in lifted], [n for _, n in lifted], offset, limits))
    length = sum(segment.length for segment in segments)
    return SurfacePath(segments, _force_profile(force, None, length, force_name, owner))


def path_from_waypoints(surface, waypoints, offset, limits, force, tolerance, interpolation="smooth", view=None,
                        what="path", force_field="force"):
    """A SurfacePath through ``waypoints`` (N x 3, world, on the surface within ``tolerance`` m):
    one smooth segment through them all, or (``interpolation="linear"``) a segment between each
    pair, stopping at every waypoint. ``force``: a number, one per waypoint, or a table; ``force_field``:
    the field its messages name (``what``.``force_field``)."""
    owner = "path_from_waypoints"
    what = text(what, "what", owner, error=PathError)
    surface = instance(surface, "surface", owner, Surface, what="a core.surfaces.Surface", error=PathError)
    offset, limits = check_offset(offset, owner), _limits(limits, owner)
    limits.validated(what)
    allowed = "at least two finite [x, y, z] points (m)"
    points = numeric_array(waypoints, f"{what}.waypoints", owner, what=allowed, error=PathError)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 2:
        raise PathError(f"{what}.waypoints must be {allowed}, got shape {list(points.shape)}")
    tolerance = positive(tolerance, f"{what}.tolerance", owner, unit="m", error=PathError)
    interpolation = text(interpolation, f"{what}.interpolation", owner, allowed=("smooth", "linear"), error=PathError)
    view = check_view(view, owner) if view is not None else surface.default_view()
    force_name = f"{what}.{text(force_field, 'force_field', owner, error=PathError)}"
    numeric_array(force, force_name, owner, what="a number (N), one per waypoint, or a table [[s, F], ...]",
                  error=PathError)
    for index, point in enumerate(points):
        distance = surface.signed_distance(point)
        if abs(distance) > tolerance:
            raise PathError(f"{what}.waypoints[{index}] {np.round(point, 4).tolist()} is {distance * 1000:+.2f} mm off "
                            f"the surface of '{surface.name}' (tolerance {tolerance * 1000:g} mm)")
    chords = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    if np.any(np.diff(chords) < 1e-6):
        raise PathError(f"{what}.waypoints: two consecutive waypoints coincide")
    check_point_count(chords[-1] / STEP, f"{owner}: {what}.waypoints {chords[-1]:.4g} m apart along the path",
                      "the waypoints are too far apart for one job; split it")
    if interpolation == "smooth":
        curve = (PiecewisePolynomial.CubicWithContinuousSecondDerivatives(chords, points.T, False) if len(points) > 2
                 else PiecewisePolynomial.FirstOrderHold(chords, points.T))
        strokes = [np.array([curve.value(s)[:, 0] for s in _even(0.0, chords[-1])])]
    else:
        strokes = [np.vstack([points[i] + f * (points[i + 1] - points[i]) for f in _even(0.0, 1.0, chords[i + 1] -
                                                                                         chords[i])])
                   for i in range(len(points) - 1)]
    segments = []
    for index, stroke in enumerate(strokes):
        projected = [surface.closest_point(p) for p in stroke]
        for q, n in projected[:: max(1, len(projected) // 50)]:
            check_facing(n, view, f"{what}: near {np.round(q, 4).tolist()}")
        segments.append(PathSegment([q for q, _ in projected], [n for _, n in projected], offset, limits))
    length = sum(segment.length for segment in segments)
    profile = _force_profile(force, lambda: _waypoint_arcs(segments, surface, points), length, force_name, owner)
    return SurfacePath(segments, profile)


def _waypoint_arcs(segments, surface, points):
    """The arc length of the path of ``segments`` at each waypoint: the nearest sample, searched forward."""
    samples = np.vstack([segment.contact_points for segment in segments])
    starts = np.concatenate([[0.0], np.cumsum([segment.length for segment in segments])[:-1]])
    arcs = np.concatenate([start + segment.arc_lengths for start, segment in zip(starts, segments)])
    arcs_of_waypoints, first = [], 0
    for point in points:
        q = surface.closest_point(point)[0]
        index = first + int(np.argmin(np.linalg.norm(samples[first:] - q, axis=1)))
        arcs_of_waypoints.append(float(arcs[index]))
        first = index
    return arcs_of_waypoints


def _even(start, end, length=None):
    """Parameters from ``start`` to ``end`` every STEP of ``length`` (default end - start)."""
    length = end - start if length is None else length
    return np.linspace(start, end, max(2, int(math.ceil(length / STEP)) + 1))
