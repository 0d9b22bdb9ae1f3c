"""The contact: the plant's configuration, the pad's and the workpiece's material, collision filters.
"""

import math
from dataclasses import dataclass
from typing import Any, Collection, List, Optional, Sequence, Tuple, Type, Union, cast

from pydrake.geometry import (CollisionFilterDeclaration, GeometryId, GeometrySet, ProximityProperties, Role,
                              RoleAssign, SceneGraph, SourceId)
from pydrake.multibody.plant import CoulombFriction, MultibodyPlant, MultibodyPlantConfig

from drake_hybrid.core.arguments import describe, instance, nonnegative
from drake_hybrid.core.errors import ArgumentError, ConfigError, check_fields, check_finite
from drake_hybrid.core.schema import check_types
from drake_hybrid.station.robot_model import RobotModel, check_unfinalized_plant
from drake_hybrid.station.tools import tool_contact

# The values Drake 1.51 accepts for the MultibodyPlantConfig fields checked here.
CONTACT_MODELS = ("hydroelastic", "hydroelastic_with_fallback", "point")
DISCRETE_APPROXIMATIONS = ("sap", "tamsi", "similar", "lagged")
SURFACE_REPRESENTATIONS = ("polygon", "triangle")


def validate_plant_config(plant: MultibodyPlantConfig, prefix: str = "plant.") -> None:
    """ConfigError naming the MultibodyPlantConfig field Drake would reject (or that would break the law)."""
    if not plant.time_step >= 0:
        raise ConfigError(f"{prefix}time_step must be >= 0 (0 means continuous), got {plant.time_step}")
    if plant.contact_model not in CONTACT_MODELS:
        raise ConfigError(f"{prefix}contact_model must be one of {CONTACT_MODELS}, got '{plant.contact_model}'")
    if plant.discrete_contact_approximation not in DISCRETE_APPROXIMATIONS + ("",):
        raise ConfigError(f"{prefix}discrete_contact_approximation must be one of {DISCRETE_APPROXIMATIONS}, "
                          f"got '{plant.discrete_contact_approximation}'")
    if plant.contact_surface_representation not in SURFACE_REPRESENTATIONS:
        raise ConfigError(f"{prefix}contact_surface_representation must be one of {SURFACE_REPRESENTATIONS}, "
                          f"got '{plant.contact_surface_representation}'")
    for name in ("penetration_allowance", "stiction_tolerance", "sap_near_rigid_threshold"):
        number = getattr(plant, name)
        if not 0 < number < math.inf:
            raise ConfigError(f"{prefix}{name} must be positive and finite, got {number}")
    if not plant.time_step < math.inf:
        raise ConfigError(f"{prefix}time_step must be finite, got {plant.time_step}")


@dataclass
class ContactConfig:
    """The pad's and the workpiece's contact material (the contact model itself is ``plant``)."""

    pad_modulus: float = 5.0e6                   # Pa, the ball pad's hydroelastic modulus (a disc has its own: tool)
    pad_dissipation: float = 10.0                # s/m, Hunt-Crossley dissipation (continuous, similar, lagged)
    # SAP's linear dissipation (discrete plants): the pad's and the workpiece's relaxation times,
    # which SAP adds (< 0: the model's own, Drake's default 0.1 s each). The default pair, 0.03 s,
    # damps the arm-on-pad mode about critically (zeta ~ 1.5 on the window). Drake's 0.2 s pair damps
    # it ten times critically and drags a pad sliding over a curved workpiece (0.24 N at 10 N,
    # 2 cm/s, R 5 cm: 6.6-6.9 % velocity error in impedance-force mode); a lighter pair, 0.01 s,
    # misses a 50 ms force step by 0.755 N while the arm compresses the pad (docs/drake_notes.md,
    # "Choosing the pair's dissipation").
    relaxation_time: float = 0.03                # s, the pad's (SAP); replaces the tool model's own; < 0 keeps it
    workpiece_relaxation_time: float = 0.0       # s, each workpiece geometry's, directives' too; < 0: the model's own
    friction: float = 0.0                        # Coulomb mu (static = dynamic) of pad and workpiece
    pad_resolution: float = 0.003                # m, the ball pad's mesh resolution hint (a disc's: tool.resolution)
    workpiece_resolution: float = 0.0            # m, the hint of each workpiece geometry that has one; 0: the model's
    # (docs/contact_resolution.md measures both hints' accuracy against their cost)

    def validate(self, prefix: str = "contact.") -> None:
        """ConfigError naming ``prefix`` and the field: the types first (``core.schema.check_types``: a
        config built in Python is checked as a file is), NaN and inf, then the values."""
        check_types(self, ContactConfig, prefix.rstrip("."))
        check_finite(self, prefix)
        check_fields(self, prefix, positive=("pad_modulus", "pad_resolution"),
                     nonnegative=("pad_dissipation", "friction", "workpiece_resolution"))


def default_plant_config(time_step: float = 1.0e-3) -> MultibodyPlantConfig:
    """The package's MultibodyPlantConfig: SAP steps of ``time_step`` (0: continuous) with hydroelastic
    contact; a Drake struct, so ``ApplyMultibodyPlantConfig`` / ``AddMultibodyPlant`` take it and your
    own settings can replace any field."""
    time_step = nonnegative(time_step, "time_step", "default_plant_config", unit="s")
    return MultibodyPlantConfig(time_step=time_step, contact_model="hydroelastic", discrete_contact_approximation="sap")


def _tool_geometries(robot, owner):
    if isinstance(robot, RobotModel):
        return list(robot.pad_geometries)
    return geometry_ids(robot, "robot", owner, "the RobotModel of mount_tool or a list of the pad's GeometryIds")


def apply_contact_defaults(plant: MultibodyPlant, scene_graph: SceneGraph,
                           robot: Union[RobotModel, Sequence[GeometryId]], workpiece_geometries: Sequence[GeometryId],
                           contact: Optional[ContactConfig] = None) -> None:
    """The package's contact material (``contact``: a ContactConfig, default its defaults) on your
    tool (``robot``: the RobotModel of ``mount_tool``, or the pad's geometry ids) and workpiece
    geometries: the pad's hydroelastic modulus, mesh and dissipation, SAP's relaxation times (0.03 s
    for the pair: about critically damped), friction. A disc tool (``RobotModel.tool``, ``station.tools``) keeps
    its own modulus and mesh resolution. Call it before ``plant.Finalize()``."""
    owner = "apply_contact_defaults"
    check_unfinalized_plant(plant, owner)
    instance(scene_graph, "scene_graph", owner, SceneGraph, what="the SceneGraph of the plant (AddMultibodyPlant's)")
    if not plant.geometry_source_is_registered():
        raise ArgumentError(f"{owner}: the plant has no SceneGraph (make it with AddMultibodyPlant(config, builder))")
    tool = _tool_geometries(robot, owner)
    workpiece = geometry_ids(workpiece_geometries, "workpiece_geometries", owner,
                             "the GeometryIds of add_rigid_workpiece (a list)")
    contact = instance(contact, "contact", owner, ContactConfig, allow_none=True) or ContactConfig()
    contact.validate(f"{owner}: contact.")
    pad_contact = tool_contact(robot.tool if isinstance(robot, RobotModel) else None, contact)
    inspector, source = scene_graph.model_inspector(), plant.get_source_id()
    assert source is not None                   # the plant's geometry source is registered (above)
    if not inspector.SourceIsRegistered(source):
        raise ArgumentError(f"{owner}: scene_graph is not the plant's SceneGraph (AddMultibodyPlant returns the pair)")
    known = set(inspector.GetAllGeometryIds())
    for name, ids in (("robot", tool), ("workpiece_geometries", workpiece)):
        for geometry_id in ids:
            if geometry_id not in known or not inspector.BelongsToSource(geometry_id, source):
                raise ArgumentError(f"{owner}: {name} holds a geometry ({geometry_id}) that is not the plant's in "
                                    f"scene_graph (another plant's or another SceneGraph's?)")
    set_contact_properties(plant, scene_graph, tool, pad_contact, pad=True)
    set_contact_properties(plant, scene_graph, workpiece, contact, pad=False)


def geometry_ids(value: Any, name: str, owner: str, what: str, *,
                 collections: Tuple[Type[Collection[Any]], ...] = (list, tuple),
                 nonempty: bool = False) -> List[GeometryId]:
    """``value`` (a GeometryId, or one of ``collections`` of them; not empty if ``nonempty``) as a list of
    GeometryIds; ArgumentError naming ``owner`` and ``name``, ``what`` saying what it must be."""
    if isinstance(value, GeometryId):
        return [value]
    if (not isinstance(value, collections) or (nonempty and not value)
            or not all(isinstance(entry, GeometryId) for entry in value)):
        raise ArgumentError(f"{owner}: {name} must be {what}, got {describe(value)}")
    return list(value)


def set_contact_properties(plant: MultibodyPlant, scene_graph: SceneGraph, geometry_ids: Sequence[GeometryId],
                           config: ContactConfig, pad: bool) -> None:
    """The contact material of ``config`` (a ContactConfig) on ``geometry_ids``, before ``Finalize``: a
    pad's (``pad``: hydroelastic modulus, mesh, Hunt-Crossley dissipation, SAP relaxation time) or a
    workpiece's (relaxation time, mesh); friction on both."""
    inspector = scene_graph.model_inspector()
    for geometry_id in geometry_ids:
        properties = ProximityProperties(inspector.GetProximityProperties(geometry_id))
        if pad:
            properties.UpdateProperty("hydroelastic", "hydroelastic_modulus", float(config.pad_modulus))
            properties.UpdateProperty("hydroelastic", "resolution_hint", float(config.pad_resolution))
            properties.UpdateProperty("material", "hunt_crossley_dissipation", float(config.pad_dissipation))
            if config.relaxation_time >= 0:
                properties.UpdateProperty("material", "relaxation_time", float(config.relaxation_time))
        else:
            if config.workpiece_relaxation_time >= 0:
                # SAP's pair relaxation time is the sum of the two geometries' (Drake's default 0.1 s each):
                # docs/drake_notes.md, "SAP's normal damping drags a pad over a curved workpiece".
                properties.UpdateProperty("material", "relaxation_time", float(config.workpiece_relaxation_time))
            if config.workpiece_resolution > 0 and properties.HasProperty("hydroelastic", "resolution_hint"):
                properties.UpdateProperty("hydroelastic", "resolution_hint", float(config.workpiece_resolution))
        properties.UpdateProperty("material", "coulomb_friction",
                                  CoulombFriction(float(config.friction), float(config.friction)))
        # The plant's geometry source: registered (a plant with a SceneGraph, before Finalize).
        scene_graph.AssignRole(cast(SourceId, plant.get_source_id()), geometry_id, properties, RoleAssign.kReplace)


def only_tool_touches(plant: MultibodyPlant, scene_graph: SceneGraph, robot: RobotModel,
                      workpiece_geometries: Sequence[GeometryId]) -> List[GeometryId]:
    """Collision filters after ``plant.Finalize()``: the robot (every body of ``robot.model_instances``)
    touches the workpiece with its tool's pad (``robot.pad_geometries``) only, and its links do not
    touch each other; ``robot.passive_geometries`` lose their proximity role. Returns the filtered
    robot geometries.

    Without it, an arm model made for motion planning (spheres and cylinders around the links) touches
    itself between non-adjacent links, and Drake asks every robot geometry near the workpiece for a
    hydroelastic or point contact ("Requested a contact surface between a pair of geometries without
    hydroelastic representation"; AutoDiffXd point-contact queries, Linearize's, reject most shape
    pairs even out of contact). The filtered links can pass through the workpiece unseen: keep them
    clear (watch the animation)."""
    if not plant.is_finalized():
        raise ConfigError("only_tool_touches: call it after plant.Finalize() (collision filters need the bodies' "
                          "geometries)")
    inspector = scene_graph.model_inspector()
    for geometry_id in robot.passive_geometries:
        if inspector.GetProximityProperties(geometry_id) is not None:
            scene_graph.RemoveRole(plant.get_source_id(), geometry_id, Role.kProximity)
    pad, passive = list(robot.pad_geometries), set(robot.passive_geometries)
    robot_geometries = [geometry for instance in robot.model_instances for index in plant.GetBodyIndices(instance)
                        for geometry in plant.GetCollisionGeometriesForBody(plant.get_body(index))
                        if geometry not in pad and geometry not in passive]
    scene_graph.collision_filter_manager().Apply(
        CollisionFilterDeclaration()
        .ExcludeWithin(GeometrySet(robot_geometries + pad))
        .ExcludeBetween(GeometrySet(robot_geometries), GeometrySet(list(workpiece_geometries))))
    return robot_geometries
