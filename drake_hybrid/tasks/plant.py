"""The plant of a task: robot, tool and workpiece in a MultibodyPlant with the pad's contact material.
"""

import copy

import numpy as np

from pydrake.geometry import Role
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant
from pydrake.multibody.tree import SpatialInertia

from drake_hybrid.core.errors import ConfigError
from drake_hybrid.station.contact import only_tool_touches, set_contact_properties
from drake_hybrid.station.tools import tool_contact


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
    check_mounted_tool(task, config, robot)
    if config.model_error.joint_damping > 0:
        for index in plant.GetJointIndices(robot.arm):
            joint = plant.get_joint(index)
            if joint.num_velocities() == 1:          # viscous friction of the simulated joints only
                joint.set_default_damping(joint.default_damping() + float(config.model_error.joint_damping))
    workpiece_geometries = task.add_workpiece(plant, config)
    for geometry_id in robot.passive_geometries:
        scene_graph.RemoveRole(plant.get_source_id(), geometry_id, Role.kProximity)
    set_contact_properties(plant, scene_graph, robot.pad_geometries, tool_contact(robot.tool, config.contact), pad=True)
    set_contact_properties(plant, scene_graph, workpiece_geometries, config.contact, pad=False)
    plant.Finalize()
    if robot.only_pad_contact:
        only_tool_touches(plant, scene_graph, robot, workpiece_geometries)
    return plant, scene_graph, robot


def check_mounted_tool(task, config, robot):
    """ConfigError if ``config.tool`` asks for a disc and the task's robot mounts another tool (a task that
    mounts its own: the paper's tasks, a Python ``CustomTask``; surface-polishing and a task file's robot mount
    ``config.tool``)."""
    if config.tool.is_disc and not (robot.tool is not None and robot.tool.is_disc):
        raise ConfigError(f"tool.kind: task '{task.name}' mounts its own tool (the ball pad), not the disc of "
                          "config.tool; a disc needs a task that mounts config.tool (surface-polishing, a task file's "
                          "robot) or your own add_robot with mount_tool(..., tool=ToolConfig(kind='disc'))")


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
