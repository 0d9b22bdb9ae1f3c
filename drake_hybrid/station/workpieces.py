"""Rigid workpieces on the world body: library shapes and meshes, registered as rigid hydroelastic geometry.

``add_rigid_workpiece`` registers a shape (collision and visual), its mesh resolution tied to its
curvature (``default_resolution``); ``mesh_shape`` makes a height map's closed part
(``core.height_map.HeightMapSurface.mesh``) a Drake Mesh held in memory. ``tasks.custom`` re-exports
``add_rigid_workpiece`` (where the tutorials and your tasks import it from).
"""

from typing import List, Optional, Sequence

from pydrake.common import MemoryFile
from pydrake.geometry import (AddRigidHydroelasticProperties, Capsule, Cylinder, Ellipsoid, GeometryId, InMemoryMesh,
                              Mesh, ProximityProperties, Shape, Sphere)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import CoulombFriction, MultibodyPlant

from drake_hybrid.core.arguments import instance, positive, text, vector
from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.core.height_map import HeightMapSurface

MAX_RESOLUTION = 0.005            # m, the coarsest workpiece mesh
FACETS_PER_RADIUS = 20            # a curved shape's mesh: radius / 20 (2.5 mm at R = 5 cm)


def default_resolution(shape: Shape) -> float:
    """The workpiece mesh's resolution hint (m): MAX_RESOLUTION, finer on a curved shape of small
    radius (its smallest, for an ellipsoid). A facet's normal is off the surface's by up to half a
    facet angle, resolution / (2 R), and the pad reads that as a tangential force that comes and
    goes as it slides: at 5 mm on R = 5 cm the impedance-force velocity error stayed at 3.4 %,
    at 2.5 mm 0.6 % (docs/drake_notes.md)."""
    radii = {Sphere: lambda s: [s.radius()], Cylinder: lambda s: [s.radius()], Capsule: lambda s: [s.radius()],
             Ellipsoid: lambda s: [s.a(), s.b(), s.c()]}
    for kind, radius in radii.items():
        if isinstance(shape, kind):
            return min(MAX_RESOLUTION, min(radius(shape)) / FACETS_PER_RADIUS)
    return MAX_RESOLUTION


def add_rigid_workpiece(plant: MultibodyPlant, shape: Shape, X_WG: RigidTransform, name: str = "workpiece",
                        resolution_hint: Optional[float] = None,
                        color: Sequence[float] = (0.55, 0.6, 0.7, 1.0)) -> List[GeometryId]:
    """Register ``shape`` (a pydrake.geometry Shape) on the world body at X_WG as a rigid
    hydroelastic collision geometry (mesh resolution ``resolution_hint``, m; default
    ``default_resolution``: tied to the curvature) and a visual one. Returns the collision
    geometry ids. Contact friction is set from the scenario config. ``name``: the geometry's name,
    one of its own per workpiece (pass another for a second workpiece)."""
    owner = "add_rigid_workpiece"
    instance(plant, "plant", owner, MultibodyPlant)
    if plant.is_finalized() or not plant.geometry_source_is_registered():
        raise ArgumentError(f"{owner}: plant must be a MultibodyPlant with a SceneGraph (AddMultibodyPlant), not "
                            f"yet finalized")
    text(name, "name", owner)
    instance(shape, "shape", owner, Shape, what="a pydrake.geometry Shape (Box, Sphere, Cylinder, Ellipsoid, ...)")
    instance(X_WG, "X_WG", owner, RigidTransform)
    resolution_hint = positive(resolution_hint, "resolution_hint", owner, unit="m", allow_none=True)
    rgba = vector(color, "color", owner, 4)
    world = plant.world_body()
    properties = ProximityProperties()
    AddRigidHydroelasticProperties(default_resolution(shape) if resolution_hint is None else resolution_hint,
                                   properties)
    properties.AddProperty("material", "coulomb_friction", CoulombFriction(0.0, 0.0))
    try:
        geometry = plant.RegisterCollisionGeometry(world, X_WG, shape, name, properties)
        plant.RegisterVisualGeometry(world, X_WG, shape, f"{name}_visual", rgba)
    except RuntimeError as error:
        if "already been used" not in str(error):
            raise
        raise ArgumentError(f"{owner}: the plant already has a geometry named '{name}' (a workpiece added "
                            f"before?); pass name= to add another workpiece") from None
    return [geometry]


def mesh_shape(surface: HeightMapSurface, name: str) -> Shape:
    """A Drake Mesh (in memory, OBJ) of a HeightMapSurface's closed part (``HeightMapSurface.mesh``), for
    a rigid hydroelastic geometry at ``surface.X_WM``."""
    vertices, triangles = surface.mesh()
    text = "".join(f"v {a:.9g} {b:.9g} {c:.9g}\n" for a, b, c in vertices)
    text += "".join(f"f {i + 1} {j + 1} {k + 1}\n" for i, j, k in triangles)
    return Mesh(InMemoryMesh(mesh_file=MemoryFile(text, ".obj", name)), 1.0)
