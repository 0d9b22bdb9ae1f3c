"""A job over a surface, from the first touch to the last: the path, its start and its phases.

``path_job(surface, offset, settings)`` lays the path of ``settings`` (a ``PathConfig``: waypoints, a
raster or a spiral, speed, force, dwell, lift-off) on ``surface`` (a ``core.surfaces.Surface``) for a
pad centre held ``offset`` off it, checks it (``PathError`` naming the field) and returns a
``PathJob``. Give it to ``station.loop.add_hybrid_controller(..., path=job)``: the loop of a job is
then wired in one call (``station.loop.connect_hybrid_loop``)::

    PathSource ─desired_velocity, desired_acceleration, desired_force─► HybridController
    PathSource ─path_position_error──────────────────────────────────► HybridController (e_p against the path)
    ContactSupervisor ─contact_phase─► PathSource     (the path's clock starts at the first contact)
    PathSource ─path_done─► ContactSupervisor         (lift-off: leave the surface at the end)

and ``station.loggers.add_loggers`` logs the path's reference, error and progress and the
supervisor's lift-off. A job with a supervisor that starts in APPROACH
(``station.contact_start.solve_path_start`` puts the pad ``gap`` above the first point) lands on the path's
first point, presses there for ``settings.dwell`` s, follows the path and lifts off
``supervision.lift_height`` at its end; a job that starts in contact presses at the first point at t = 0 and
starts the path after the dwell.
"""

import math
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Optional, Tuple, cast

import numpy as np
from numpy.typing import ArrayLike

from pydrake.common.eigen_geometry import AngleAxis
from pydrake.geometry import Meshcat, Rgba
from pydrake.math import RigidTransform, RotationMatrix

from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.supervision import SupervisionConfig
from drake_hybrid.core.arguments import instance, vector
from drake_hybrid.core.errors import PathError
from drake_hybrid.core.height_map import HeightMapSurface
from drake_hybrid.core.hints import Array
from drake_hybrid.core.paths import PathLimits, SurfacePath, path_from_strokes, path_from_waypoints
from drake_hybrid.core.patterns import raster, spiral
from drake_hybrid.core.surfaces import Surface, ViewPlane, check_offset
from drake_hybrid.station.path_config import PathConfig
from drake_hybrid.systems.path_source import reference_rotation


@dataclass(frozen=True)
class PathJob:
    """A path laid on a surface and checked (``path_job`` makes it): what ``add_hybrid_controller(...,
    path=job)`` runs.

    ``surface`` (a ``core.surfaces.Surface``), ``offset`` (m: the pad centre off the surface, a ball
    pad's radius), ``settings`` (the ``PathConfig``), ``path`` (the ``core.paths.SurfacePath`` of the pad
    centre, timed) and ``heading`` (the world direction the tool's x axis keeps, turned into the tangent
    plane)."""

    surface: Surface
    offset: float
    settings: PathConfig
    path: SurfacePath
    heading: np.ndarray

    @property
    def holding(self) -> bool:
        """True if the job holds one point of the path (``settings.hold_at`` >= 0) instead of running it."""
        return self.settings.holding

    def lifts_off(self, supervised: bool) -> bool:
        """True if the job leaves the surface at its end: ``settings.lift_off``, a path that is run, and a
        contact supervisor (``supervised``) to lift."""
        return bool(supervised) and self.settings.lift_off and not self.holding

    def start_pose(self) -> Tuple[RigidTransform, np.ndarray]:
        """(X_WP, normal): the pad centre's pose at the path's first point (the reference orientation)
        and the surface's outward normal there."""
        return start_pose_on(self.surface, self.path, self.settings)

    def pose_at_depth(self, depth: float) -> RigidTransform:
        """The pad centre's pose ``depth`` (m) beyond the path's first point along its inward normal
        (negative: above it), turned as the constraint's held rows want it there
        (``Surface.held_normal``), not as the surface point's normal: the path's reference orientation
        there (``reference_rotation`` of the surface normal and the heading) turned by the smallest rotation
        that takes its approach vector onto the held one. That turn has no part about the approach vector, so
        the spin row's position error (``PathSource``) is zero there too: a held path is at rest where the
        held normal is not the surface point's (a height map's rows, a distance to second order, differ from
        the map's normal by a few mrad; building the frame again from the heading turned it 0.7 mrad about
        the approach vector, which K_p pulled on)."""
        X_WP, normal = self.start_pose()
        centre = X_WP.translation() - float(depth) * normal
        reference = RotationMatrix(reference_rotation(normal, self.heading))
        turn = _smallest_turn(-normal, -self.surface.held_normal(centre, self.offset))
        return RigidTransform(turn.multiply(reference), centre)

    def duration(self, supervision: Optional[SupervisionConfig] = None, gap: Optional[float] = None) -> float:
        """The simulated time the job needs (s, rounded up to 0.1 s): the guarded approach from ``gap``
        (m above the first point; None: a start in contact) at ``supervision.approach_speed`` and 0.2 s,
        the dwell, the path, and with a supervisor the lift-off and 0.3 s."""
        instance(supervision, "supervision", "PathJob.duration", SupervisionConfig, allow_none=True)
        approach = gap / supervision.approach_speed + 0.2 if supervision is not None and gap is not None else 0.0
        lift = (supervision.lift_height / supervision.approach_speed + 0.3
                if supervision is not None and self.lifts_off(True) else 0.0)
        return math.ceil(10 * (approach + self.settings.dwell + self.path.duration + lift)) / 10


def _smallest_turn(a_from: Array, a_to: Array) -> RotationMatrix:
    """The smallest turn taking the unit vector ``a_from`` onto ``a_to`` (about their cross product)."""
    axis = np.cross(a_from, a_to)
    sine = float(np.linalg.norm(axis))
    if sine < 1e-15:
        return RotationMatrix()
    direction: Array = axis / sine
    return RotationMatrix(AngleAxis(math.atan2(sine, float(a_from @ a_to)), direction))


def path_job(surface: Surface, offset: float, settings: PathConfig) -> PathJob:
    """The PathJob of ``settings`` (a PathConfig) on ``surface`` for a pad centre ``offset`` off it (m,
    >= 0): the path laid, timed and checked (PathError, one line naming the field, for a path the job
    cannot follow; a ``settings.heading`` the path's normals reach)."""
    path = path_on(surface, offset, settings)
    heading = heading_of(settings, surface)
    if settings.heading:
        check_heading_along(path, heading)
    return PathJob(surface=surface, offset=float(offset), settings=settings, path=path, heading=heading)


def view_of(path_config: PathConfig, surface: Surface) -> ViewPlane:
    """The pattern's ViewPlane: ``path.view`` or the surface's default."""
    view = path_config.view
    if not (view.origin or view.axis_u or view.axis_v):
        return surface.default_view()
    default = surface.default_view()
    return ViewPlane.make(view.origin or default.origin, view.axis_u or default.axis_u, view.axis_v or default.axis_v,
                          what="path.view")


# The normals sampled per segment by check_heading_along: four per knot of its normals' spline, within these bounds.
_HEADING_SAMPLES = (64, 512)


def check_heading_along(path: SurfacePath, heading: ArrayLike) -> None:
    """PathError naming path.heading, the arc length and the path time where ``heading`` lies along the
    path's surface normal: the reference frame keeps the tool's x axis on the heading turned into the
    tangent plane (``systems.path_source.reference_frame``), which has no direction there. The normals'
    spline of each segment is sampled (four per knot, 64 to 512 per segment); a heading within the angle
    between neighbouring samples of a sample's normal line is refused, so a normal that passes through
    the heading between two samples is caught too."""
    h = np.asarray(heading, dtype=float) / np.linalg.norm(heading)
    for segment in path.segments:
        count = int(np.clip(4 * len(segment.arc_lengths), *_HEADING_SAMPLES))
        arcs = np.linspace(0.0, segment.length, count)
        normals = np.asarray(segment.normal.vector_values(arcs)).T
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        off_line = np.arccos(np.clip(np.abs(normals @ h), 0.0, 1.0))          # angle to the normal's line
        turns = np.arccos(np.clip(np.sum(normals[1:] * normals[:-1], axis=1), -1.0, 1.0))
        reach = np.maximum(np.concatenate([turns, [0.0]]), np.concatenate([[0.0], turns]))
        along = np.nonzero(off_line <= np.maximum(reach, 1e-6))[0]
        if along.size:
            i = along[np.argmin(off_line[along])]
            arc = segment.start_arc + arcs[i]
            raise PathError(
                f"build_path: path.heading {np.asarray(heading).tolist()} is along the surface normal "
                f"{np.round(normals[i], 4).tolist()} at arc length {arc:.4g} m of the path (path time "
                f"{_time_at_arc(path, arc):.4g} s, segment {path.segments.index(segment)}): the tool's x axis keeps "
                "the heading turned into the tangent plane, which has no direction there; give a heading that the "
                "path's normals do not reach (or none: the view's u axis)")


def _force_field(settings):
    """The PathConfig field the path's force comes from (``PathConfig.force_argument``), for its messages."""
    if settings.force_by_arc_length:
        return "force_by_arc_length"
    return "waypoints[].force" if settings.waypoints and any(w.force > 0 for w in settings.waypoints) else "force"


def path_on(surface: Surface, offset: float, settings: PathConfig) -> SurfacePath:
    """The SurfacePath of the PathConfig ``settings`` on ``surface`` (a core.surfaces.Surface) for a pad
    centre ``offset`` off it (m, >= 0)."""
    instance(surface, "surface", "path_on", Surface, what="a core.surfaces.Surface", error=PathError)
    offset = check_offset(offset, "path_on")
    instance(settings, "settings", "path_on", PathConfig, error=PathError).validate()
    view = view_of(settings, surface)
    limits = PathLimits(settings.speed, settings.acceleration)
    force, force_field = settings.force_argument(), _force_field(settings)
    check_inside = getattr(surface, "check_inside", None)       # a height map: the pad must stay on the map
    if settings.waypoints:
        points = [w.point for w in settings.waypoints]
        if check_inside is not None:
            field = cast(HeightMapSurface, surface).field
            for index, point in enumerate(points):
                check_inside([field.map_point(vector(point, f"path.waypoints[{index}].point", "path_on", 3,
                                                     error=PathError))[:2]],
                             offset, f"path.waypoints[{index}].point {list(point)} (the pad must stay on the map: "
                                     "move it inside)")
        path = path_from_waypoints(surface, points, offset, limits, force, settings.tolerance,
                                   settings.interpolation, view, what="path", force_field=force_field)
    else:
        pattern = settings.pattern
        if pattern.kind == "raster":
            strokes = raster(pattern.center, pattern.size, pattern.spacing, pattern.direction, what="path.pattern")
        else:
            strokes = spiral(pattern.center, pattern.radius, pattern.spacing, what="path.pattern")
        if check_inside is not None:
            corners = np.vstack([stroke[[0, -1]] for stroke in strokes])
            field = cast(HeightMapSurface, surface).field          # the surface with check_inside
            map_points = [field.map_point(view.point(u, v))[:2] for u, v in corners]
            check_inside(map_points, offset, "the pattern's corner")
        path = path_from_strokes(surface, view, strokes, offset, limits, force, what="path", force_field=force_field)
    if check_inside is not None:
        _check_on_map(cast(HeightMapSurface, surface), path, offset, "waypoints" if settings.waypoints else "pattern")
    if settings.holding:
        arc = settings.hold_at * path.length
        sample = path.evaluate(_time_at_arc(path, arc))
        path = SurfacePath.hold(sample.position, sample.normal, path.force(arc))
    return path


def _check_on_map(surface, path, offset, field):
    """PathError naming ``path.<field>`` and the arc length where a contact point of ``path`` leaves the height
    map's grid (less the pad's radius): there the surface is the spline's extrapolation, not the part."""
    map_points = []
    for segment in path.segments:
        for arc, point in zip(segment.start_arc + segment.arc_lengths, surface.field.map_point(segment.contact_points)):
            map_points.append((arc, point[:2]))
    x0, x1, y0, y1 = surface.field.bounds
    for arc, (X, Y) in map_points:
        if not (x0 + offset <= X <= x1 - offset and y0 + offset <= Y <= y1 - offset):
            surface.check_inside([(X, Y)], offset, f"path.{field}: the path at arc length {arc:.4g} m (keep the "
                                                   "path on the map, the pad's radius inside its edge)")


def _time_at_arc(path, arc):
    """The path time at which the reference reaches arc length ``arc``."""
    times = np.linspace(0.0, path.duration, 2001)
    arcs = [path.evaluate(t).arc_length for t in times]
    return float(np.interp(arc, arcs, times))


def heading_of(settings: PathConfig, surface: Surface) -> np.ndarray:
    """The world direction the tool's x axis keeps: ``settings.heading`` (a PathConfig; 3 finite numbers,
    not zero) or the view's u axis."""
    if not settings.heading:
        return np.asarray(view_of(settings, surface).axis_u)
    heading = vector(settings.heading, "path.heading", "heading_of", 3, error=PathError)
    if not np.linalg.norm(heading) > 1e-12:
        raise PathError(f"heading_of: path.heading must be a nonzero direction [x, y, z] (or empty), got "
                        f"{heading.tolist()}")
    return heading


def start_pose_on(surface: Surface, path: SurfacePath, settings: PathConfig) -> Tuple[RigidTransform, np.ndarray]:
    """(X_WP, normal): the pad centre's pose at the first point of ``path`` (its reference orientation,
    ``settings`` a PathConfig) and the surface's outward normal there."""
    centre, normal = instance(path, "path", "start_pose_on", SurfacePath, error=PathError).first_point()
    R = reference_rotation(normal, heading_of(settings, surface), "path.heading at the path's first point")
    return RigidTransform(RotationMatrix(R), centre), np.asarray(normal, dtype=float)


def path_events(log: Mapping[str, np.ndarray]) -> List[Dict[str, Any]]:
    """A job's phases for the plots and the summary (``Task.run_events``' format): the guarded approach,
    the dwell at the first point, each line change (an instant: a segment's start) and the lift-off."""
    if "path_progress" not in log:
        return []
    t = np.asarray(log["t"])
    segment, t_path = np.asarray(log["path_progress"])[:, 0], np.asarray(log["path_progress"])[:, 2]
    events = []
    started = np.nonzero(t_path >= 0)[0]
    if "contact_phase" in log:
        contact = np.nonzero(np.asarray(log["contact_phase"])[:, 0] == float(ContactPhase.CONTACT))[0]
        if contact.size and contact[0] > 0:
            events.append({"start": float(t[0]), "end": float(t[contact[0]]), "label": "guarded approach"})
        if contact.size and started.size and started[0] > contact[0]:
            events.append({"start": float(t[contact[0]]), "end": float(t[started[0]]),
                           "label": "pressing at the path's first point (dwell)"})
    done = np.asarray(log["path_done"])[:, 0] > 0.5 if "path_done" in log else np.zeros(len(t), dtype=bool)
    for index in np.nonzero(np.diff(segment) > 0)[0]:
        if segment[index] >= 0 and not done[index + 1]:                       # not the path's start or end
            events.append({"start": float(t[index + 1]), "end": None, "label": "a line change (segment start)"})
    if "lifting" in log:
        lifting = np.nonzero(np.asarray(log["lifting"])[:, 0] > 0.5)[0]
        if lifting.size:
            events.append({"start": float(t[lifting[0]]), "end": float(t[-1]), "label": "lift-off"})
    return events


def draw_path(meshcat: Meshcat, path: SurfacePath, name: str = "path") -> None:
    """Draw ``path`` in ``meshcat`` (the animation): the pad centre's reference as a line, and the
    points on the workpiece it passes over (the contact points), under ``/name``."""
    centres, contacts = instance(path, "path", "draw_path", SurfacePath).centres(), path.contact_points()
    meshcat.SetLine(f"{name}/pad_centre", centres.T, 2.0, Rgba(0.1, 0.6, 0.2, 1.0))
    meshcat.SetLine(f"{name}/on_the_workpiece", contacts.T, 2.0, Rgba(0.9, 0.4, 0.1, 1.0))
