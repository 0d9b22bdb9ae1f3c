"""The pad's contact patch measured: Drake's hydroelastic contact surface, its pressure integrated.

``patch_figures(surface, pad_ids, p_WP, a)`` integrates one of SceneGraph's contact surfaces (the mesh of
the patch and the pressure field on it, ``ContactSurface``) between the pad and the workpiece::

    F   = sum_i p_i A_i n_i              the pressure's force on the pad (n_i: face normals from the
                                         workpiece into the pad)
    c   = sum_i p_i A_i c_i / sum p_i A_i    the centre of pressure (c_i the faces' centroids)
    offset = |(I - a a^T)(c - P)|        its distance from the tool's axis (P the controlled point, a the
                                         approach vector: the disc's axis)
    tilt   = angle(n, -a)                the tool's tilt against the real local surface: n the real
                                         surface's normal at its point nearest P, when the sensor is given
                                         the workpiece's real ``core.surfaces.Surface``; else the
                                         area-weighted normal of the patch's faces within ``local_radius``
                                         (5 mm) of the tool's axis (the nearest face if none is), which is
                                         the surface under the tool's centre only where the patch covers it

with the patch's area, its peak pressure (the field's largest vertex value) and mean pressure
|F| / area. ``ContactPatchSensor`` does it on a simulated plant's contact results every ``period`` (a
periodic update; the output holds the last figures) for its ``patch`` output (``PATCH_FIELDS``), and
``pressure_samples`` gives the pressure at the faces' centroids in the tool's frame, for a plot of the
pressure over the disc.
"""

import math
from typing import Any, Dict, Iterable, List, Optional, Tuple, cast

import numpy as np

from pydrake.common.cpp_param import List as CppList
from pydrake.common.value import AbstractValue, Value
from pydrake.geometry import ContactSurface, GeometryId
from pydrake.math import RigidTransform
from pydrake.multibody.plant import ContactResults, MultibodyPlant
from pydrake.systems.framework import Context, LeafSystem

from drake_hybrid.control.sampling import declare_periodic_update
from drake_hybrid.core.arguments import instance, positive, vector
from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.core.hints import Array
from drake_hybrid.core.kinematics import resolve_frame
from drake_hybrid.core.surfaces import Surface

# The ``patch`` output's entries (ContactPatchSensor), in order, with their units.
PATCH_FIELDS = {
    "cop_offset": "the centre of pressure's distance from the tool's axis (m)",
    "area": "the contact patch's area (m^2)",
    "area_fraction": "the patch's area over the tool's face (1; NaN for a tool without a face: the ball)",
    "peak_pressure": "the largest pressure on the patch (Pa)",
    "mean_pressure": "the normal force over the patch's area (Pa)",
    "tilt": "the angle between the tool's axis and the real surface's normal under it (rad)",
    "normal_force": "the pressure's resultant on the pad (N)",
    "cop_x": "the centre of pressure, world x (m)",
    "cop_y": "the centre of pressure, world y (m)",
    "cop_z": "the centre of pressure, world z (m)",
}
PATCH_SIZE = len(PATCH_FIELDS)
CENTROID: Array = np.full(3, 1.0 / 3.0)                # a triangle's centroid, barycentric
NO_PATCH: Array = np.array([math.nan, 0.0, 0.0, 0.0, 0.0, math.nan, 0.0, math.nan, math.nan, math.nan])


def _faces(surface: ContactSurface) -> Tuple[Array, Array, Array, Array, Array]:
    """(centroids N x 3, areas N, unit normals N x 3 out of N into M, pressures at the centroids N, the field's
    vertex values) of a contact surface, polygons or triangles."""
    mesh: Any
    field: Any
    if surface.is_triangle():
        mesh, field = surface.tri_mesh_W(), surface.tri_e_MN()
        count = mesh.num_triangles()
        centroids = np.array([mesh.element_centroid(i) for i in range(count)])
        pressures = np.array([field.Evaluate(i, CENTROID) for i in range(count)])
    else:
        mesh, field = surface.poly_mesh_W(), surface.poly_e_MN()
        count = mesh.num_elements()
        centroids = np.array([mesh.element_centroid(i) for i in range(count)])
        pressures = np.array([field.EvaluateCartesian(i, centroids[i]) for i in range(count)])
    areas = np.array([mesh.area(i) for i in range(count)])
    normals = np.array([mesh.face_normal(i) for i in range(count)])
    vertices = np.array([field.EvaluateAtVertex(v) for v in range(mesh.num_vertices())])
    return centroids.reshape(-1, 3), areas, normals.reshape(-1, 3), pressures, vertices


def _pad_surfaces(surfaces: Iterable[ContactSurface], pad_ids: Iterable[GeometryId]) -> List[Tuple[ContactSurface,
                                                                                                   float]]:
    """The surfaces touching the pad, each with the sign that turns its normals toward the pad (+1: the pad
    is geometry M)."""
    pad = set(pad_ids)
    chosen = []
    for surface in surfaces:
        on_M, on_N = surface.id_M() in pad, surface.id_N() in pad
        if on_M != on_N:
            chosen.append((surface, 1.0 if on_M else -1.0))
    return chosen


LOCAL_RADIUS = 0.005          # m: the faces under the tool's centre whose normal is the real local surface's


def patch_figures(surfaces: Iterable[ContactSurface], pad_ids: Iterable[GeometryId], p_WP: Array, a_W: Array,
                  face_area: Optional[float] = None, local_radius: float = LOCAL_RADIUS,
                  real_surface: Optional[Surface] = None) -> Array:
    """The ``PATCH_FIELDS`` of the contact surfaces touching ``pad_ids`` (the module docstring): ``p_WP`` the
    controlled point, ``a_W`` the tool's approach vector (world, unit), ``face_area`` the tool's face (m^2;
    None: ``area_fraction`` NaN), ``local_radius`` (m) the faces whose normal is the local surface's without
    ``real_surface`` (the workpiece's, a ``core.surfaces.Surface``: its normal nearest ``p_WP`` is).
    ``NO_PATCH`` when nothing touches."""
    chosen = _pad_surfaces(surfaces, pad_ids)
    if not chosen:
        return NO_PATCH.copy()
    parts = [_faces(surface) + (sign,) for surface, sign in chosen]
    centroids = np.vstack([part[0] for part in parts])
    areas = np.concatenate([part[1] for part in parts])
    normals = np.vstack([part[2] * part[5] for part in parts])
    pressures = np.concatenate([part[3] for part in parts])
    peak = max(float(np.max(part[4], initial=0.0)) for part in parts)
    weights = np.clip(pressures, 0.0, None) * areas
    total = float(weights.sum())
    area = float(areas.sum())
    if not total > 0:
        return NO_PATCH.copy()
    force = (weights[:, None] * normals).sum(axis=0)
    magnitude = float(np.linalg.norm(force))
    cop = (weights[:, None] * centroids).sum(axis=0) / total
    a = np.asarray(a_W, dtype=float)
    d = cop - np.asarray(p_WP, dtype=float)
    offset = float(np.linalg.norm(d - (d @ a) * a))
    if real_surface is not None:
        n_local = real_surface.closest_point(np.asarray(p_WP, dtype=float))[1]
    else:
        radial = centroids - np.asarray(p_WP, dtype=float)
        radial = np.linalg.norm(radial - np.outer(radial @ a, a), axis=1)        # each face from the tool's axis
        local = radial <= max(float(radial.min()), float(local_radius))
        n_local = (areas[local, None] * normals[local]).sum(axis=0)
    tilt = float(math.acos(float(np.clip(-(n_local @ a) / np.linalg.norm(n_local), -1.0, 1.0))))
    fraction = area / face_area if face_area else math.nan
    return np.array([offset, area, fraction, peak, magnitude / area if area > 0 else 0.0, tilt, magnitude,
                     cop[0], cop[1], cop[2]])


def pressure_samples(surfaces: Iterable[ContactSurface], pad_ids: Iterable[GeometryId],
                     X_WT: RigidTransform) -> Dict[str, Array]:
    """The pressure over the patch in the tool's frame T (origin the controlled point, z the approach axis):
    {"points": N x 3 face centroids (m, frame T), "pressure": N (Pa), "area": N (m^2)}; empty arrays when
    nothing touches the pad."""
    chosen = _pad_surfaces(surfaces, pad_ids)
    if not chosen:
        return {"points": np.zeros((0, 3)), "pressure": np.zeros(0), "area": np.zeros(0)}
    parts = [_faces(surface) for surface, _ in chosen]
    X_TW = X_WT.inverse()
    points = np.vstack([part[0] for part in parts])
    return {"points": np.array([X_TW.multiply(point) for point in points]).reshape(-1, 3),
            "pressure": np.concatenate([part[3] for part in parts]),
            "area": np.concatenate([part[1] for part in parts])}


class ContactPatchSensor(LeafSystem):
    """The pad's contact patch on a simulated plant (module docstring), float only.

    .. pydrake_system::

        name: ContactPatchSensor
        input_ports:
        - contact_results
        - body_poses
        output_ports:
        - patch

    ``patch`` (``PATCH_FIELDS``, 10 entries) holds the figures of the last periodic update (every ``period``
    s, and at initialization); NaN and zeros (``NO_PATCH``) while nothing touches.

    Args:
        plant: the simulation plant (finalized, with a SceneGraph).
        pad_geometries: the pad's collision geometry ids (``RobotModel.pad_geometries``).
        end_effector_frame: the tool's frame (or its name) whose +z is the approach vector a.
        end_effector_point: the controlled point P in that frame (m).
        face_area: the tool's face (m^2; None: no face, the ball).
        period: s between updates (positive, finite).
        real_surface: the workpiece's real ``core.surfaces.Surface`` (its normal is the tilt's reference; None:
            the patch's faces under the tool's centre, ``patch_figures``).
    """

    def __init__(self, plant: MultibodyPlant, pad_geometries: Iterable[GeometryId], end_effector_frame: object,
                 end_effector_point: Array, face_area: Optional[float] = None, period: float = 0.01,
                 real_surface: Optional[Surface] = None) -> None:
        super().__init__()
        owner = "ContactPatchSensor"
        instance(plant, "plant", owner, MultibodyPlant)
        if not plant.is_finalized() or not plant.geometry_source_is_registered():
            raise ArgumentError(f"{owner}: plant must be finalized and have a SceneGraph (contact results)")
        self._pad = list(pad_geometries)
        if not self._pad or not all(isinstance(entry, GeometryId) for entry in self._pad):
            raise ArgumentError(f"{owner}: pad_geometries must be the pad's GeometryIds (RobotModel.pad_geometries)")
        frame = resolve_frame(plant, end_effector_frame)
        point = vector(end_effector_point, "end_effector_point", owner, 3, unit="m")
        self._body_slot = int(frame.body().index())
        self._X_BT = frame.GetFixedPoseInBodyFrame().multiply(RigidTransform(point))
        self.face_area = positive(face_area, "face_area", owner, unit="m^2", allow_none=True)
        self.period = positive(period, "period", owner, unit="s")
        self.real_surface = instance(real_surface, "real_surface", owner, Surface, allow_none=True,
                                     what="a core.surfaces.Surface (the workpiece's) or None")
        self._results = self.DeclareAbstractInputPort("contact_results", AbstractValue.Make(ContactResults()))
        self._poses = self.DeclareAbstractInputPort("body_poses", Value[CppList[RigidTransform]]([]))
        self._state = self.DeclareDiscreteState(NO_PATCH.copy())
        declare_periodic_update(self, self.period, 0.0, self._update)
        self.DeclareInitializationDiscreteUpdateEvent(self._update)
        self.DeclareStateOutputPort("patch", self._state)

    def tool_pose(self, context: Context) -> RigidTransform:
        """X_WT: the tool frame at the controlled point (z the approach vector) in ``context`` (this system's)."""
        poses = cast(List[RigidTransform], self._poses.Eval(context))
        return poses[self._body_slot].multiply(self._X_BT)

    def figures(self, context: Context) -> Array:
        """The ``PATCH_FIELDS`` of the contact results the inputs hold now (what the update stores)."""
        results = cast(ContactResults, self._results.Eval(context))
        X_WT = self.tool_pose(context)
        surfaces = [results.hydroelastic_contact_info(i).contact_surface()
                    for i in range(results.num_hydroelastic_contacts())]
        return patch_figures(surfaces, self._pad, X_WT.translation(), X_WT.rotation().matrix()[:, 2], self.face_area,
                             real_surface=self.real_surface)

    def _update(self, context, discrete_state):
        discrete_state.get_mutable_vector(0).SetFromVector(self.figures(context))
