"""The ``path:`` section of a ScenarioConfig: a job's path over the workpiece (YAML).

A job presses on the workpiece while the pad's centre follows a path (``core.paths``) from the
first touch to the last::

    path:
      pattern: {kind: raster, center: [0.0, 0.0], size: [0.10, 0.10], spacing: 0.02, direction: u}
      # or waypoints on the workpiece (world, m), each with its own force or none:
      # waypoints: [{point: [0.45, 0.0, 0.25]}, {point: [0.47, 0.02, 0.248], force: 12.0}]
      # interpolation: smooth                 # smooth (one curve) | linear (stop at each waypoint)
      view: {origin: [], axis_u: [], axis_v: []}   # the pattern's plane (empty: the surface's default)
      speed: 0.05                              # m/s, the pad centre's speed limit
      acceleration: 0.5                        # m/s^2, its acceleration limit (norm)
      force: 10.0                              # N, the normal force (unless per waypoint or by arc length)
      force_by_arc_length: []                  # [{arc_length: 0.0, force: 10.0}, ...] (m, N)
      moments: []                              # N m on the force-controlled orientation rows (empty: zero)
      tolerance: 0.002                         # m, how far a waypoint may be off the surface
      heading: []                              # the tool's x axis, turned into the tangent plane (world)
      dwell: 0.2                               # s pressing at the first point before moving
      lift_off: true                           # leave the surface at the end (supervision.lift_height)
      hold_at: -1.0                            # >= 0: hold at this fraction of the path's length instead
                                               # (what linearizations at a point of the path use)

The task gives the surface (``Task.workpiece_surface``); ``station.path_job`` builds the path,
its source and the wiring. ``validate`` checks every field once, naming it (``PathError``); what
needs the surface (a waypoint off it, a pattern outside the region) is checked when the path is
built, before the run.
"""

import math
from dataclasses import dataclass, field
from typing import List, Union

import numpy as np

from drake_hybrid.core.errors import PathError
from drake_hybrid.core.schema import check_types

PATTERN_KINDS = ("", "raster", "spiral")


@dataclass
class PatternConfig:
    """A coverage pattern in the view plane (``core.patterns``): ``raster`` over the rectangle of
    ``size`` (along u, along v) about ``center``, lines along ``direction`` ``spacing`` apart; or
    ``spiral`` out to ``radius`` with ``spacing`` between turns. Empty ``kind``: no pattern."""

    kind: str = ""                       # raster | spiral | "" (no pattern)
    center: List[float] = field(default_factory=lambda: [0.0, 0.0])    # (u, v), m
    size: List[float] = field(default_factory=lambda: [0.1, 0.1])      # raster: (along u, along v), m
    radius: float = 0.05                                                # spiral, m
    spacing: float = 0.01                                               # m between lines or turns
    direction: str = "u"                                                # raster: the lines run along u or v


@dataclass
class ViewConfig:
    """The plane a pattern is drawn in (``core.surfaces.ViewPlane``); empty: the surface's default."""

    origin: List[float] = field(default_factory=list)    # the plane's origin (world, m); empty: the default
    axis_u: List[float] = field(default_factory=list)    # its u axis (world, unit vector: dimensionless)
    axis_v: List[float] = field(default_factory=list)    # its v axis (world, unit vector: dimensionless)


@dataclass
class WaypointConfig:
    """A point on the workpiece's surface (world, m) and, optionally, the normal force there (N)."""

    point: List[float] = field(default_factory=list)    # on the surface (world, m)
    force: float = 0.0                       # 0: the path's force


@dataclass
class ForcePointConfig:
    """The normal force (N) at an arc length (m) of the path; linear in between."""

    arc_length: float = 0.0              # m along the path from its start
    force: float = 0.0                   # N, the normal force there


@dataclass
class PathConfig:
    """A job's path (module docstring); inactive (no waypoints, no pattern) by default."""

    waypoints: List[WaypointConfig] = field(default_factory=list)    # points on the surface, in order
    interpolation: str = "smooth"            # smooth (one curve) | linear (stop at each waypoint)
    pattern: PatternConfig = field(default_factory=PatternConfig)
    view: ViewConfig = field(default_factory=ViewConfig)
    speed: float = 0.05                      # m/s, the pad centre's speed limit
    acceleration: float = 0.5                # m/s^2, its acceleration limit (norm)
    force: float = 10.0                      # N, the normal force (unless per waypoint or by arc length)
    force_by_arc_length: List[ForcePointConfig] = field(default_factory=list)   # the force along the path
    tolerance: float = 0.002                 # m, how far a waypoint may be off the surface
    heading: List[float] = field(default_factory=list)   # the tool's x axis (world, dimensionless), in the tangent plane
    dwell: float = 0.2                       # s pressing at the first point before moving
    lift_off: bool = True                    # leave the surface at the end (supervision.lift_height)
    hold_at: float = -1.0                    # >= 0: hold at this fraction of the path's length instead
    moments: List[float] = field(default_factory=list)   # N m, a flat tool's moment rows' F_d (empty: zero)

    @property
    def active(self) -> bool:
        """True if the config has a path (waypoints or a pattern)."""
        return bool(self.waypoints or self.pattern.kind)

    @property
    def holding(self) -> bool:
        """True if the path is held at one point (``hold_at`` >= 0) instead of run."""
        return self.active and self.hold_at >= 0

    def force_argument(self) -> Union[float, List[float], List[List[float]]]:
        """The force for ``core.paths``: a number, one per waypoint, or a table [[s, F], ...]."""
        if self.force_by_arc_length:
            return [[point.arc_length, point.force] for point in self.force_by_arc_length]
        if self.waypoints and any(w.force > 0 for w in self.waypoints):
            return [w.force for w in self.waypoints]
        return self.force

    def validate(self, prefix: str = "path.") -> "PathConfig":
        """PathError naming the first field that is not allowed (every field, also of an inactive path:
        a misspelt value is refused wherever it is); the types first (``core.schema.check_types``)."""
        check_types(self, PathConfig, prefix.rstrip("."), error=PathError)
        field = prefix.rsplit(": ", 1)[-1]            # the field's name without a task file's "file: "
        if self.waypoints and self.pattern.kind:
            raise PathError(f"{prefix}waypoints and pattern (kind '{self.pattern.kind}'): give waypoints or a pattern, "
                            f"not both; a pattern you did not write is the task's default path: clear it with "
                            f"{field}pattern.kind: '' to follow the waypoints")
        if self.pattern.kind not in PATTERN_KINDS:
            raise PathError(f"{prefix}pattern.kind must be one of raster, spiral (or empty), got "
                            f"'{self.pattern.kind}'")
        if self.pattern.direction not in ("u", "v"):
            raise PathError(f"{prefix}pattern.direction must be u or v (the axis the raster's lines run along), got "
                            f"'{self.pattern.direction}'")
        for name, unit in (("speed", "m/s"), ("acceleration", "m/s^2"), ("tolerance", "m")):
            number = float(getattr(self, name))
            if not 0 < number < math.inf:
                raise PathError(f"{prefix}{name} must be positive and finite ({unit}), got {number}")
        if not 0 < float(self.force) < math.inf:
            raise PathError(f"{prefix}force must be positive and finite (N: the pad presses), got {self.force}")
        if not 0 <= float(self.dwell) < math.inf:
            raise PathError(f"{prefix}dwell must be >= 0 (s), got {self.dwell}")
        if self.interpolation not in ("smooth", "linear"):
            raise PathError(f"{prefix}interpolation must be smooth or linear, got '{self.interpolation}'")
        if not (self.hold_at < 0 or 0 <= self.hold_at <= 1):
            raise PathError(f"{prefix}hold_at must be a fraction of the path's length in [0, 1] (or < 0: run the "
                            f"path), got {self.hold_at}")
        if self.moments and (len(self.moments) != 2 or not all(math.isfinite(float(v)) for v in self.moments)):
            raise PathError(f"{prefix}moments must be two finite numbers (N m, the moments about the tool's y and -x "
                            f"axes commanded on the force-controlled orientation rows) or empty, got {self.moments}")
        for index, waypoint in enumerate(self.waypoints):
            if len(waypoint.point) != 3:
                raise PathError(f"{prefix}waypoints[{index}].point must be [x, y, z] (m), got {waypoint.point}")
            if not 0 <= waypoint.force < math.inf:
                raise PathError(f"{prefix}waypoints[{index}].force must be > 0 (N), or 0 for the path's force, got "
                                f"{waypoint.force}")
        forces = [w.force for w in self.waypoints]
        if any(f > 0 for f in forces) and not all(f > 0 for f in forces):
            raise PathError(f"{prefix}waypoints: give a force at every waypoint or at none, got {forces}")
        if any(f > 0 for f in forces) and self.force_by_arc_length:
            table = [[point.arc_length, point.force] for point in self.force_by_arc_length]
            raise PathError(f"{prefix}waypoints[].force and {field}force_by_arc_length both give the path's force "
                            f"(per waypoint {forces} N, by arc length {table}): give one of them")
        for name in ("origin", "axis_u", "axis_v"):
            if len(getattr(self.view, name)) not in (0, 3):
                raise PathError(f"{prefix}view.{name} must be [x, y, z] or empty, got {getattr(self.view, name)}")
        if self.heading and (len(self.heading) != 3 or not np.all(np.isfinite(np.asarray(self.heading, dtype=float)))
                             or not np.linalg.norm(np.asarray(self.heading, dtype=float)) > 0):
            raise PathError(f"{prefix}heading must be a world direction [x, y, z] (finite, not zero) or empty, got "
                            f"{list(self.heading)}")
        return self
