"""A workpiece's surface moved: the surface the controller is given where the real one is not.

A real workpiece is never where its model says. ``surface_error_pose(tilt, axis, pivot, shift)`` is the
rigid motion X that takes the model's surface to the real one (turned by ``tilt`` degrees about ``axis``
through ``pivot``, then moved by ``shift``), and ``moved_surface(surface, X)`` the surface moved by a rigid
motion, for the provided kinds (``core.surfaces``' plane, sphere and cylinder, ``core.height_map``'s
height map)::

    X = surface_error_pose(8.0, axis=[1, 0, 0], pivot=[0.45, 0, 0.1], shift=[0, 0, -0.005])
    model = moved_surface(real, X.inverse())      # what the controller is given; the geometry stays the real one

A task's run does the same from ``ModelErrorConfig``'s ``workpiece_*`` fields (``tasks.plant``): the geometry
Drake simulates is the task's surface, the controller's constraint, path and view are laid on the model.
"""

import math
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike

from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import RigidTransform, RotationMatrix

from drake_hybrid.core.arguments import describe, instance, number, vector
from drake_hybrid.core.errors import PathError
from drake_hybrid.core.height_map import HeightMapSurface
from drake_hybrid.core.surfaces import CylinderSurface, PlaneSurface, SphereSurface, Surface


def surface_error_pose(tilt: float, axis: ArrayLike = (1.0, 0.0, 0.0), pivot: ArrayLike = (0.0, 0.0, 0.0),
                       shift: ArrayLike = (0.0, 0.0, 0.0)) -> RigidTransform:
    """X_real_model: the rigid motion that turns a surface by ``tilt`` (deg) about ``axis`` (a world direction,
    not zero) through ``pivot`` (world, m) and then moves it by ``shift`` (world, m). PathError naming the
    argument for a value that is not finite (or a zero axis)."""
    owner = "surface_error_pose"
    tilt = number(tilt, "tilt", owner, unit="deg", error=PathError)
    axis = vector(axis, "axis", owner, 3, error=PathError)
    if not np.linalg.norm(axis) > 1e-12:
        raise PathError(f"{owner}: axis must be a nonzero direction [x, y, z], got {axis.tolist()}")
    pivot = vector(pivot, "pivot", owner, 3, unit="m", error=PathError)
    shift = vector(shift, "shift", owner, 3, unit="m", error=PathError)
    R = RotationMatrix(AngleAxis(math.radians(tilt), axis / np.linalg.norm(axis)))
    return RigidTransform(R, pivot + shift - R.multiply(pivot))


def moved_surface(surface: Surface, X: RigidTransform, name: Optional[str] = None) -> Surface:
    """``surface`` moved by the rigid motion ``X`` (a RigidTransform, world): a PlaneSurface,
    SphereSurface, CylinderSurface or HeightMapSurface of the same shape and ``name`` (default its own).
    PathError for another kind of surface (a Surface of your own: move it yourself)."""
    owner = "moved_surface"
    instance(surface, "surface", owner, Surface, what="a core.surfaces.Surface", error=PathError)
    instance(X, "X", owner, RigidTransform, error=PathError)
    name = name or surface.name
    R = X.rotation()
    if isinstance(surface, PlaneSurface):
        return PlaneSurface(X.multiply(surface.point), R.multiply(surface.unit_normal), name=name)
    if isinstance(surface, SphereSurface):
        return SphereSurface(X.multiply(surface.center), surface.radius, name=name)
    if isinstance(surface, CylinderSurface):
        return CylinderSurface(X.multiply(surface.center), R.multiply(surface.axis), surface.radius, surface.length,
                               name=name)
    if isinstance(surface, HeightMapSurface):
        return HeightMapSurface(surface.height_map, X.multiply(surface.X_WM), name=name)
    raise PathError(f"{owner}: surface must be a PlaneSurface, SphereSurface, CylinderSurface or HeightMapSurface, "
                    f"got {describe(surface)}")
