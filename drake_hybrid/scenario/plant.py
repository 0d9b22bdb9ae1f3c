"""The plant of a task: robot, tool and workpiece in a MultibodyPlant with the pad's contact material.

``build_plant`` adds the simulation plant (``ScenarioConfig.plant``, a Drake
``MultibodyPlantConfig``) to a builder; ``build_controller_plant`` builds the controller's own
model (robot and tool, no workpiece, continuous); ``apply_model_error`` makes the simulated robot
differ from that model (``ModelErrorConfig``).
"""

import copy
from dataclasses import dataclass, field

import numpy as np

from pydrake.geometry import (CollisionFilterDeclaration, GeometryId, GeometrySet, ProximityProperties, Role,
                              RoleAssign)
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlant
from pydrake.multibody.tree import SpatialInertia

from drake_hybrid.core.arguments import describe
from drake_hybrid.core.errors import ArgumentError, ConfigError, UnknownFrameError


@dataclass
class RobotModel:
    """What a task's ``add_robot`` added to a plant."""

    arm: object                                  # ModelInstanceIndex of the actuated arm
    model_instances: list                        # arm and tool instances
    end_effector_frame: str                      # name of frame E
    end_effector_point: np.ndarray               # p_EP
    tool_weld: object = None                     # WeldJoint wrist -> tool (for the wrist sensor)
    pad_geometries: list = field(default_factory=list)
    passive_geometries: list = field(default_factory=list)   # collision geometries to drop (arm links)
    only_pad_contact: bool = False               # filter every contact of the robot but the pad's


def frame_names(plant, model_instance):
    """The names of the frames of ``model_instance`` (bodies' frames and the model's own frames)."""
    return sorted({plant.get_frame(index).name() for index in plant.GetFrameIndices(model_instance)})


def get_frame(plant, name, model_instance, role="frame"):
    """Frame ``name`` of ``model_instance``; UnknownFrameError listing the model's frames otherwise."""
    if plant.HasFrameNamed(name, model_instance):
        return plant.GetFrameByName(name, model_instance)
    raise UnknownFrameError(f"{role} '{name}' is not a frame of model '{plant.GetModelInstanceName(model_instance)}'; "
                            f"its frames: {', '.join(frame_names(plant, model_instance))}")


def geometry_ids(value, name, owner, what, *, collections=(list, tuple), nonempty=False):
    """``value`` (a GeometryId, or one of ``collections`` of them; not empty if ``nonempty``) as a list of
    GeometryIds; ArgumentError naming ``owner`` and ``name``, ``what`` saying what it must be."""
    if isinstance(value, GeometryId):
        return [value]
    if (not isinstance(value, collections) or (nonempty and not value)
            or not all(isinstance(entry, GeometryId) for entry in value)):
        raise ArgumentError(f"{owner}: {name} must be {what}, got {describe(value)}")
    return list(value)


def set_contact_properties(plant, scene_graph, geometry_ids, config, pad):
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
        scene_graph.AssignRole(plant.get_source_id(), geometry_id, properties, RoleAssign.kReplace)


def build_plant(task, config, builder, time_step=None, sampled_outputs=None):
    """Add the task's plant (robot, tool, workpiece, contact properties) to ``builder``.

    ``sampled_outputs``: a discrete plant's contact results and reaction forces sampled at its last
    step or those of the step about to be taken; default ``config.plant.use_sampled_output_ports``
    (Drake's default: sampled). Sampled, the sensors read the contact solve the plant's step made
    (one solve per step; the contact sensor shifts it to the end effector as it was at that solve,
    ``ContactWrenchSensor``, and the law splits it one step old); unsampled, the reading is the
    current step's, and a controller that reads it at another instant than the plant steps costs a
    second contact solve per step (docs/drake_notes.md; the grinding task pays it).
    ``analysis.linearize_discrete`` asks for unsampled ports (abstract state does not linearize)."""
    if sampled_outputs is None:
        sampled_outputs = config.plant.use_sampled_output_ports
    time_step = config.plant.time_step if time_step is None else time_step
    plant_config = copy.copy(config.plant)
    plant_config.time_step = time_step
    plant_config.use_sampled_output_ports = sampled_outputs
    plant, scene_graph = AddMultibodyPlant(plant_config, builder)
    robot = task.add_robot(plant, config)
    if config.model_error.joint_damping > 0:
        for index in plant.GetJointIndices(robot.arm):
            joint = plant.get_joint(index)
            if joint.num_velocities() == 1:          # viscous friction of the simulated joints only
                joint.set_default_damping(joint.default_damping() + float(config.model_error.joint_damping))
    workpiece_geometries = task.add_workpiece(plant, config)
    for geometry_id in robot.passive_geometries:
        scene_graph.RemoveRole(plant.get_source_id(), geometry_id, Role.kProximity)
    set_contact_properties(plant, scene_graph, robot.pad_geometries, config.contact, pad=True)
    set_contact_properties(plant, scene_graph, workpiece_geometries, config.contact, pad=False)
    plant.Finalize()
    if robot.only_pad_contact:
        only_tool_touches(plant, scene_graph, robot, workpiece_geometries)
    return plant, scene_graph, robot


def only_tool_touches(plant, scene_graph, robot, workpiece_geometries):
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


def build_controller_plant(task, config):
    """The controller's own model: the robot and tool only, no workpiece."""
    plant = MultibodyPlant(0.0)
    robot = task.add_robot(plant, config)
    plant.Finalize()
    return plant, robot


def apply_model_error(plant, plant_context, robot, model_error):
    """Scale the simulated payload's and links' inertias in ``plant_context`` (see ModelErrorConfig)."""
    for name in ("payload_mass_scale", "link_mass_scale", "link_inertia_scale"):
        scale = getattr(model_error, name)
        if not (np.isfinite(scale) and scale > 0):
            raise ConfigError(f"model_error.{name} must be a positive number, got {scale}")
    for instance in robot.model_instances:
        on_arm = instance == robot.arm
        mass_scale = model_error.link_mass_scale if on_arm else model_error.payload_mass_scale
        inertia_scale = model_error.link_inertia_scale if on_arm else 1.0
        if mass_scale == 1.0 and inertia_scale == 1.0:
            continue
        for index in plant.GetBodyIndices(instance):
            body = plant.get_body(index)
            M_BBo_B = body.default_spatial_inertia()         # nominal (the model's), so applying twice is safe
            mass, com = M_BBo_B.get_mass(), M_BBo_B.get_com()
            if mass == 0:
                continue
            # Rotational inertia about the centre of mass: scaled with the mass, and by inertia_scale.
            central = M_BBo_B.Shift(com).CalcRotationalInertia() * (mass_scale * inertia_scale)
            body.SetSpatialInertiaInBodyFrame(plant_context,
                                              SpatialInertia.MakeFromCentralInertia(mass_scale * mass, com, central))
