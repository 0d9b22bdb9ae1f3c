"""The parts of a task file for a job over a surface: the workpiece's surface (analytic or a height
map read from a file) and the paper's fields Y_d(r), F_d(r) as expressions.

``workpiece.surface`` (``SurfaceSpec``) names the surface a path lies on (``config.path``) and, when no
``constraint.rows`` are given, the constraint (the surface offset by the pad's radius,
``Surface.offset_constraint``) and, when no ``velocity_projection.rows`` are given, E_p (the view's
rows, ``core.surfaces.view_projection``)::

    workpiece:
      surface: {kind: sphere, center: [0.45, 0.0, 0.1], radius: 0.15, offset: 0.02}
      # {kind: plane, center: [...], normal: [0, 0, 1], size: [0.3, 0.3]}
      # {kind: cylinder, center: [...], axis: [1, 0, 0], radius: 0.1, length: 0.3}
      # {kind: height_map, file: bump.csv, spacing: [0.004, 0.004], origin: [-0.08, -0.08],
      #  X_WM: {translation: [0.45, 0.0, 0.15]}}

With ``geometry: true`` (default) the surface's rigid hydroelastic geometry is added too: the sphere,
the cylinder (``length`` needed), a box of ``size`` (u, v, thickness) under the plane, the height
map's closed mesh (``workpieces.mesh_shape``: made from the same spline as its constraint).

``fields`` (``FieldsSpec``): the desired velocity field Y_d(x) (d expressions in the chart's
coordinates, a tangent vector in its velocity coordinates) and force field F_d(x) (m expressions),
(2.3-1), (2.3-4), run by ``systems.sources.DesiredFieldSource`` instead of the config's profiles.
"""

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import List

import numpy as np

from pydrake.common.schema import Transform
from pydrake.geometry import Box, Cylinder, Sphere
from pydrake.math import RigidTransform, RotationMatrix

from drake_hybrid.core.errors import ConfigError, PathError
from drake_hybrid.core.expressions import expression_to_sympy
from drake_hybrid.core.height_map import HeightMap, HeightMapSurface
from drake_hybrid.core.surfaces import CylinderSurface, PlaneSurface, SphereSurface
from drake_hybrid.station.workpieces import add_rigid_workpiece, mesh_shape
from drake_hybrid.systems.sources import DesiredFieldSource

SURFACE_KINDS = ("plane", "sphere", "cylinder", "height_map")


@dataclass
class SurfaceSpec:
    """The workpiece's surface (see the module docstring); empty ``kind``: none."""

    kind: str = ""                                # plane, sphere, cylinder or height_map
    center: List[float] = field(default_factory=list)    # m: a point of the plane, the sphere's centre, on the axis
    normal: List[float] = field(default_factory=lambda: [0.0, 0.0, 1.0])   # the plane's outward normal
    axis: List[float] = field(default_factory=lambda: [1.0, 0.0, 0.0])     # the cylinder's axis
    radius: float = 0.0                           # m, sphere and cylinder
    length: float = 0.0                           # m, the cylinder's (0: unbounded, no geometry)
    size: List[float] = field(default_factory=lambda: [0.3, 0.3, 0.02])    # m, the plane's box: u, v, thickness
    file: str = ""                                # height map: .csv / .npy (heights, rows along y) or .npz
    spacing: List[float] = field(default_factory=list)   # m, the height map's (dx, dy)
    origin: List[float] = field(default_factory=lambda: [0.0, 0.0])     # m, (x, y) of the first sample
    X_WM: Transform = field(default_factory=Transform)   # the height map's frame in the world (m, deg)
    offset: float = 0.02                          # m, the pad centre's distance from the surface (its radius)
    geometry: bool = True                         # add the surface's rigid hydroelastic geometry
    resolution_hint: float = 0.0                  # m, its mesh resolution (0: the library's)


@dataclass
class FieldsSpec:
    """The paper's fields (2.3-1), (2.3-4) as expressions of the chart's coordinates (and parameters)."""

    velocity: List[str] = field(default_factory=list)   # Y_d(x): d expressions (chart velocity coordinates)
    force: List[str] = field(default_factory=list)      # F_d(x): m expressions (force on the robot, E_f's rows)


def _numbers(values, size, what):
    values = list(values)
    if len(values) != size or not all(math.isfinite(float(v)) for v in values):
        raise ConfigError(f"{what} must be {size} finite numbers, got {values}")
    return np.asarray(values, dtype=float)


def surface_of(spec, path, where):
    """The (Surface, offset) of ``spec`` (a SurfaceSpec), files relative to the task file ``path``; None
    without a kind. ConfigError / PathError naming the field."""
    if not spec.kind:
        return None
    what = f"{where}workpiece.surface"
    if spec.kind not in SURFACE_KINDS:
        raise ConfigError(f"{what}.kind must be one of {', '.join(SURFACE_KINDS)}, got '{spec.kind}'")
    if not 0 <= spec.offset < math.inf:
        raise ConfigError(f"{what}.offset must be >= 0 (m, the pad's radius), got {spec.offset}")
    try:
        if spec.kind == "height_map":
            file = Path(spec.file) if Path(spec.file).is_absolute() else Path(path).parent / spec.file
            if not spec.file:
                raise ConfigError(f"{what}.file: give the height map's .csv, .npy or .npz file")
            spacing = _numbers(spec.spacing, 2, f"{what}.spacing") if spec.spacing else None
            X_WM = spec.X_WM.GetDeterministicValue()
            if not np.all(np.isfinite(X_WM.GetAsMatrix4())):
                raise ConfigError(f"{what}.X_WM must be a transform of finite numbers (translation in m, rotation in "
                                  f"deg), got translation {X_WM.translation().tolist()}")
            heights = HeightMap.from_file(file, spacing, _numbers(spec.origin, 2, f"{what}.origin"))
            return HeightMapSurface(heights, X_WM, name=f"height map '{file.name}'"), spec.offset
        center = _numbers(spec.center, 3, f"{what}.center")
        if spec.kind == "plane":
            return PlaneSurface(center, _numbers(spec.normal, 3, f"{what}.normal"), name="plane"), spec.offset
        if spec.kind == "sphere":
            return SphereSurface(center, spec.radius, name="sphere"), spec.offset
        return CylinderSurface(center, _numbers(spec.axis, 3, f"{what}.axis"), spec.radius,
                               spec.length if spec.length > 0 else math.inf, name="cylinder"), spec.offset
    except PathError as error:
        raise PathError(f"{what}: {error}") from None


def add_surface_geometry(plant, surface, spec, name="surface"):
    """Register the surface's rigid hydroelastic geometry on the world (module docstring); its ids."""
    if not spec.geometry:
        return []
    hint = spec.resolution_hint or None
    if isinstance(surface, HeightMapSurface):
        return add_rigid_workpiece(plant, mesh_shape(surface, name), surface.X_WM, name=name,
                                   resolution_hint=hint or 0.002)
    if isinstance(surface, SphereSurface):
        return add_rigid_workpiece(plant, Sphere(surface.radius), RigidTransform(surface.center), name=name,
                                   resolution_hint=hint)
    if isinstance(surface, CylinderSurface):
        if not math.isfinite(surface.length):
            raise ConfigError("workpiece.surface: a cylinder's geometry needs its length (or geometry: false)")
        R = RotationMatrix.MakeFromOneVector(surface.axis, 2)       # Drake's cylinder is along its z
        return add_rigid_workpiece(plant, Cylinder(surface.radius, surface.length), RigidTransform(R, surface.center),
                                   name=name, resolution_hint=hint)
    size = _numbers(spec.size, 3, "workpiece.surface.size")
    R = RotationMatrix.MakeFromOneVector(surface.unit_normal, 2)
    X_WG = RigidTransform(R, surface.point - 0.5 * size[2] * surface.unit_normal)
    return add_rigid_workpiece(plant, Box(*size), X_WG, name=name, resolution_hint=hint)


def field_expressions(spec, chart, parameters, where, force_size):
    """(Y_d, F_d) of ``spec`` (a FieldsSpec) as lists of sympy expressions, or None without fields;
    ConfigError naming the field for a wrong count (d = the chart's velocity size, m = ``force_size``)."""
    if not spec.velocity and not spec.force:
        return None
    if not spec.velocity or not spec.force:
        raise ConfigError(f"{where}fields: give both velocity (Y_d, d expressions) and force (F_d, m expressions)")
    for name, texts, size, what in (("velocity", spec.velocity, chart.velocity_size, "d"),
                                    ("force", spec.force, force_size, "m")):
        if len(texts) != size:
            raise ConfigError(f"{where}fields.{name} must have {what} = {size} expressions, got {len(texts)}")
    symbols = chart.configuration_symbols
    velocity = [expression_to_sympy(text, symbols, parameters, f"{where}fields.velocity[{i}]")
                for i, text in enumerate(spec.velocity)]
    force = [expression_to_sympy(text, symbols, parameters, f"{where}fields.force[{i}]")
             for i, text in enumerate(spec.force)]
    return velocity, force


def field_source(fields, controller_plant, robot, constraint_space, where):
    """The DesiredFieldSource of the fields (ConfigError naming the section for a wrong count)."""
    try:
        return DesiredFieldSource(controller_plant, robot.end_effector_frame, robot.end_effector_point,
                                  constraint_space, fields[0], fields[1])
    except ValueError as error:
        raise ConfigError(f"{where}fields: {error}") from None
