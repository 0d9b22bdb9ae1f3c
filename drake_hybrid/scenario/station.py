"""Building blocks for your own Drake diagram: the hybrid controller as a part of your station.

Each block takes YOUR ``MultibodyPlant`` or ``DiagramBuilder`` and adds one part, returning what it
added, as the manipulation course's station helpers (``AddIiwa``, ``AddWsg``) and Drake's
``ApplyMultibodyPlantConfig`` do. ``scenario.builder.build_scenario`` is one composition of them
(the package's own tasks); yours can be any other::

    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(), builder)

    def add_robot(plant):                       # your arm and its tool: called for both plants
        arm = Parser(plant).AddModels(my_arm_urdf)[0]
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link", arm))
        return mount_tool(plant, arm, "tool0", X_flange_tool=RigidTransform([0, 0, 0.02]),
                          gripper_joints=["finger_joint"])

    robot = add_robot(plant)
    workpiece = add_rigid_workpiece(plant, Ellipsoid(0.3, 0.2, 0.1), X_WG)
    apply_contact_defaults(plant, scene_graph, robot, workpiece)
    plant.Finalize()
    only_tool_touches(plant, scene_graph, robot, workpiece)
    hybrid = add_hybrid_controller(builder, plant, robot, space, robot_plant(add_robot), gains=gains,
                                   control_period=1e-3, desired_velocity=Profile(value=[0.05, 0, 0, 0, 0]),
                                   desired_force=Profile(value=[8.0]))   # on the robot, along grad C
    loggers = add_loggers(builder, hybrid)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    solve_contact_start(diagram, context, hybrid, start_pose=X_WE, joint_guess=q_guess)
    Simulator(diagram, context).AdvanceTo(5.0)
    log = read_log(loggers, context)

and ``analysis.linearization.linearize_at_contact(diagram, context, hybrid)`` checks the closed
loop's eigenvalues against the design on the same station built with ``time_step=0`` and no
``control_period`` (Drake's ``Linearize`` needs a continuous loop).

The blocks:

``default_plant_config``     the package's MultibodyPlantConfig: 1 ms SAP steps, hydroelastic contact
``mount_tool``               the compliant pad on a frame of any arm, at an offset; a gripper's joints
                             welded (its geometry kept, or removed); ``name=`` for a further tool in the
                             plant; returns a ``RobotModel``
``add_rigid_workpiece``      a rigid hydroelastic shape at a pose, its mesh as fine as its curvature needs
``apply_contact_defaults``   the pad's modulus, dissipation and mesh, SAP's relaxation times, friction
``only_tool_touches``        collision filters: the robot touches the workpiece with its tool only
``robot_plant``              the controller's own model: your robot alone, in a continuous plant
``add_hybrid_controller``    controller, wrench sensor, wrench filter, command source (and contact
                             supervisor) in one call, wired (one per arm); returns a ``HybridSystems``
``add_loggers``, ``read_log``  every signal of the run, keyed by ``LOG_KEYS`` (the ports' names)

and ``scenario.contact_start.solve_contact_start`` (pressing with F_d, in your context).

Every block checks each input port it wires before ``Connect`` (``builder.IsConnectedOrExported``):
Drake ends the process at an input connected twice, the blocks raise an ArgumentError naming the port.

Size: the blocks share one vocabulary (the RobotModel of the mounted tool, the HybridSystems of the
controller) and each is a few lines; apart they would import each other.
"""

import inspect
import numbers
import os
import re
from dataclasses import dataclass
from typing import Dict, Optional
from xml.etree import ElementTree

import numpy as np

from pydrake.geometry import SceneGraph
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import ModelInstanceIndex
from pydrake.systems.framework import DiagramBuilder, OutputPort, System
from pydrake.systems.primitives import LogVectorOutput

from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.supervision import ContactSupervisor, SupervisionConfig
from drake_hybrid.core.arguments import describe, function, instance, nonnegative, positive, text, vector
from drake_hybrid.core.errors import ArgumentError, ConfigError, DrakeHybridError
from drake_hybrid.core.kinematics import EndEffectorKinematics
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.scenario.config import ContactConfig, ContactSensorConfig, WristSensorConfig
from drake_hybrid.scenario.parsing import ConfigureParser
from drake_hybrid.scenario.plant import (RobotModel, geometry_ids, get_frame,  # noqa: F401 (a block here too)
                                         only_tool_touches, set_contact_properties)
from drake_hybrid.scenario.root_context import subsystem_context
from drake_hybrid.scenario.tasks.robots import add_pad_tool
from drake_hybrid.scenario.workpieces import add_rigid_workpiece, default_resolution  # noqa: F401 (blocks here too)
from drake_hybrid.systems.faults import SensorFaultConfig, SensorFaultInjector
from drake_hybrid.systems.sensors import (ContactWrenchSensor, LowPassFilter, WrenchConditioner, WristForceTorqueSensor,
                                          low_pass_lag, sampled_reading_age)
from drake_hybrid.systems.sources import Profile, ProfileSource

CONTINUOUS_LOOP_BANDWIDTH = 200.0     # Hz: the wrench low-pass a continuous controller needs (no algebraic loop)


def default_plant_config(time_step=1.0e-3):
    """The package's MultibodyPlantConfig: SAP steps of ``time_step`` (0: continuous) with hydroelastic
    contact; a Drake struct, so ``ApplyMultibodyPlantConfig`` / ``AddMultibodyPlant`` take it and your
    own settings can replace any field."""
    time_step = nonnegative(time_step, "time_step", "default_plant_config", unit="s")
    return MultibodyPlantConfig(time_step=time_step, contact_model="hydroelastic", discrete_contact_approximation="sap")


# ------------------------------------------------------------------------------------------------
# Your arm: the tool, a gripper, actuators
# ------------------------------------------------------------------------------------------------

def weld_joints(plant, joint_names, model_instance=None):
    """Replace each named joint by a weld at its zero position (before ``Finalize``).

    For parts the task does not move, such as gripper fingers: the hybrid law
    needs one actuator per joint and nq == nv. Drake's ``RemoveJoint`` refuses
    while the plant has any constraint, and pydrake does not say which joints a
    coupler constraint (what a parser makes of a URDF ``<mimic>``) couples, so
    **every** constraint of the plant is removed first: call this before adding
    constraints of your own. Returns the new WeldJoints.
    """
    owner = "weld_joints"
    _unfinalized_plant(plant, owner)
    if model_instance is not None:
        _model_instance_of(plant, model_instance, "model_instance", owner)
    if isinstance(joint_names, str):
        joint_names = [joint_names]
    if not isinstance(joint_names, (list, tuple)):
        raise ArgumentError(f"{owner}: joint_names must be a joint name or a list of joint names, got "
                            f"{describe(joint_names)}")
    joint_names = [text(name, "joint_names[]", owner) for name in joint_names]
    joints = []
    for name in joint_names:
        owner = () if model_instance is None else (model_instance,)
        if not plant.HasJointNamed(name, *owner):
            indices = plant.GetJointIndices(*owner)
            known = sorted(plant.get_joint(index).name() for index in indices)
            where = "the plant" if not owner else f"model '{plant.GetModelInstanceName(model_instance)}'"
            raise ArgumentError(f"weld_joints: {where} has no joint '{name}'; its joints: {', '.join(known)}")
        joints.append(plant.GetJointByName(name, *owner))
    for constraint_id in plant.GetConstraintIds():
        plant.RemoveConstraint(constraint_id)
    welds = []
    for joint in joints:
        parent, child = joint.frame_on_parent(), joint.frame_on_child()
        plant.RemoveJoint(joint)
        welds.append(plant.WeldFrames(parent, child, RigidTransform()))
    return welds


def urdf_effort_limits(path):
    """{joint name: effort limit (N m or N)} from the ``<limit effort=...>`` tags of a URDF file.
    (Drake keeps a URDF's effort limits only on the actuators of its transmissions.)"""
    if not isinstance(path, (str, os.PathLike)):
        raise ArgumentError(f"urdf_effort_limits: path must be the path of a URDF file, got {describe(path)}")
    if not os.path.isfile(path):
        raise ArgumentError(f"urdf_effort_limits: path: no file '{os.fspath(path)}'")
    try:
        root = ElementTree.parse(path).getroot()
    except ElementTree.ParseError as error:
        raise ArgumentError(f"urdf_effort_limits: path: '{os.fspath(path)}' is not XML ({error})") from None
    return {joint.get("name"): float(joint.find("limit").get("effort"))
            for joint in root.iter("joint") if joint.find("limit") is not None and joint.find("limit").get("effort")}


def add_actuators(plant, model_instance, effort_limits=None):
    """One actuator per single-dof joint of ``model_instance`` that has none (a URDF without
    transmissions), with the effort limit ``effort_limits[joint name]`` (e.g. from
    ``urdf_effort_limits``; inf where not given). Returns the actuator names.

    ArgumentError for a limit that is not a number > 0 (inf: none), and for a name that is not a joint of
    ``model_instance`` while a joint to actuate has no limit (a misspelling would leave it unlimited; the
    names of joints ``weld_joints`` removed are otherwise let through, as ``urdf_effort_limits`` gives them)."""
    _unfinalized_plant(plant, "add_actuators")
    _model_instance_of(plant, model_instance, "model_instance", "add_actuators")
    owner = "add_actuators"
    effort_limits = instance(effort_limits, "effort_limits", owner, dict,
                             what="a dict {joint name: effort limit}", allow_none=True) or {}
    limits = {}
    for key, value in effort_limits.items():
        text(key, "effort_limits: a key", owner)
        limits[key] = positive(value, f"effort_limits['{key}']", owner, unit="N m or N; inf: none",
                               allow_infinite=True)
    actuated = {plant.get_joint_actuator(index).joint().index() for index in plant.GetJointActuatorIndices()}
    every = [plant.get_joint(index) for index in plant.GetJointIndices(model_instance)]
    joints = [joint for joint in every if joint.num_velocities() == 1 and joint.index() not in actuated]
    unknown = sorted(set(limits) - {joint.name() for joint in every})
    unlimited = [joint.name() for joint in joints if joint.name() not in limits]
    if unknown and unlimited:
        # A key for a joint the model no longer has (welded by weld_joints) is harmless; beside a joint left
        # without a limit it is most likely that joint's name misspelt.
        raise ArgumentError(f"{owner}: effort_limits names {', '.join(repr(name) for name in unknown)}, not a joint "
                            f"of model_instance, and gives no limit for {', '.join(repr(name) for name in unlimited)} "
                            "(a misspelt joint name?); its joints to actuate are "
                            f"{', '.join(repr(joint.name()) for joint in joints)} (give inf for no limit)")
    names = []
    for joint in joints:
        plant.AddJointActuator(f"{joint.name()}_actuator", joint, limits.get(joint.name(), np.inf))
        names.append(f"{joint.name()}_actuator")
    return names


GRIPPER_CHOICES = ("weld", "remove")
_DEFAULT_TOOL = "pad_tool"                  # the first tool's model instance; its end-effector frame "pad_center"
_TOOL_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.-]*")    # the whole name (fullmatch)


def _unfinalized_plant(plant, owner):
    """``plant`` if it is a MultibodyPlant not yet finalized (what adds to a model); typed errors otherwise."""
    instance(plant, "plant", owner, MultibodyPlant)
    if plant.is_finalized():
        raise ConfigError(f"{owner}: the plant is finalized; call {owner} before plant.Finalize()")
    return plant


def _model_instance_of(plant, model_instance, name, owner):
    """``model_instance`` if it is a ModelInstanceIndex of ``plant``; ArgumentError naming ``name`` otherwise."""
    if not isinstance(model_instance, ModelInstanceIndex):
        raise ArgumentError(f"{owner}: {name} must be a ModelInstanceIndex of the plant (e.g. "
                            f"Parser(plant).AddModels(...)[0]), got {describe(model_instance)}")
    if not int(model_instance) < plant.num_model_instances():
        raise ArgumentError(f"{owner}: {name} {int(model_instance)} is not a model instance of the plant (it has "
                            f"{plant.num_model_instances()})")
    return model_instance


def _tool_center_frame(name):
    """The end-effector frame of the pad tool mounted as ``name``: ``pad_center`` for the default tool,
    ``<name>_center`` for another (so that each tool's frame has a name of its own in the plant)."""
    return "pad_center" if name == _DEFAULT_TOOL else f"{name}_center"


def _moved_by(plant, model_instance, body):
    """True if ``body`` belongs to ``model_instance`` or hangs, in the joint tree (before or after
    ``Finalize``), from a body or a joint of it."""
    parent = {}
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        parent[joint.child_body().index()] = (joint.parent_body().index(), joint.model_instance())
    index, seen = body.index(), set()
    while index not in seen:
        seen.add(index)
        if plant.get_body(index).model_instance() == model_instance:
            return True
        if index not in parent:
            return False
        index, joint_instance = parent[index]
        if joint_instance == model_instance:
            return True
    return False


def _flange(plant, arm, flange_frame, owner):
    """The Frame ``flange_frame`` (a Frame or the name of one of ``arm``'s), checked to be moved by ``arm``."""
    if isinstance(flange_frame, str):
        return get_frame(plant, flange_frame, arm, f"{owner}: flange_frame")
    try:
        parent, body, name = flange_frame.GetParentPlant(), flange_frame.body(), flange_frame.name()
    except (AttributeError, TypeError):
        raise ArgumentError(f"{owner}: flange_frame must be a Frame of the arm or its name, got "
                            f"{describe(flange_frame)}") from None
    if parent is not plant:
        raise ArgumentError(f"{owner}: flange_frame '{name}' is a frame of another plant; pass a frame of this "
                            f"plant's arm (or its name)")
    if not _moved_by(plant, arm, body):
        arm_name = plant.GetModelInstanceName(arm)
        raise ArgumentError(f"{owner}: flange_frame '{name}' (on body '{body.name()}' of model "
                            f"'{plant.GetModelInstanceName(body.model_instance())}') is not moved by the arm "
                            f"'{arm_name}'; pass one of the arm's frames (or a frame on a part it carries)")
    return flange_frame


def mount_tool(plant, arm, flange_frame, X_flange_tool=None, gripper_joints=(), gripper="weld", name="pad_tool"):
    """Mount the compliant ball pad (``models/pad_tool.sdf``: a ball of radius 20 mm, its centre 0.05 m
    along the tool's +z, the controlled point) on ``flange_frame`` of ``arm`` at ``X_flange_tool`` (default: the
    identity), before ``Finalize``.

    Args:
        plant: your MultibodyPlant (with or without a SceneGraph: the controller's own model too).
        arm: the ModelInstanceIndex of the arm.
        flange_frame: a frame of ``arm`` (or of a part the arm carries) or its name (UnknownFrameError
            lists the model's frames).
        X_flange_tool: RigidTransform of the tool's mounting frame in the flange frame (an adapter's
            length, a rotation about the flange axis).
        gripper_joints: joints of a gripper (or anything else the task does not move) to weld at
            their zero position: the law needs one actuator per joint it controls.
        gripper: "weld": the gripper stays a rigid part of the wrist, drawn and colliding like the arm's
            links (``only_tool_touches`` filters its contact with the workpiece as theirs: keep it
            clear; ``scenario.contact_start.solve_contact_start`` refuses a start where it is not); "remove":
            the collision geometries of every body the flange carries (the gripper's fixed and moving
            parts; ``RobotModel.passive_geometries``, dropped by ``only_tool_touches``): a gripper your
            model has but your station does not (it stays drawn).
        name: the tool's model instance name. The default ("pad_tool", end-effector frame
            ``pad_center``) is for one tool per plant; give each further tool a name of its own (two
            arms, each with its pad): its end-effector frame is then ``<name>_center``.

    Returns the RobotModel: the arm and tool instances, the end-effector frame (``pad_center``, or
    ``<name>_center``) and point (its origin), the wrist weld (where a wrist force/torque sensor sits),
    the pad's geometries.
    """
    owner = "mount_tool"
    instance(X_flange_tool, "X_flange_tool", owner, RigidTransform, allow_none=True)
    if gripper not in GRIPPER_CHOICES:
        raise ConfigError(f"mount_tool: gripper must be one of {', '.join(GRIPPER_CHOICES)}, got {describe(gripper)}")
    if isinstance(gripper_joints, str):
        gripper_joints = [gripper_joints]
    if not isinstance(gripper_joints, (list, tuple)):
        raise ArgumentError(f"{owner}: gripper_joints must be a joint name or a list of joint names, got "
                            f"{describe(gripper_joints)}")
    text(name, "name", owner)
    if not _TOOL_NAME.fullmatch(name):
        raise ArgumentError(f"{owner}: name must be a model name of letters, digits, '_', '.' and '-' (not "
                            f"starting with a digit), got {describe(name)}")
    _unfinalized_plant(plant, owner)
    _model_instance_of(plant, arm, "arm", owner)
    center = _tool_center_frame(name)
    if plant.HasModelInstanceNamed(name) or plant.HasFrameNamed(center):
        raise ArgumentError(f"{owner}: the plant already has a model '{name}' (or a frame '{center}'): a tool "
                            f"mounted before? Pass name= to mount another tool (e.g. name='{name}_2')")
    frame = _flange(plant, arm, flange_frame, owner)
    if gripper_joints:
        weld_joints(plant, list(gripper_joints), arm)
    removed = []
    if gripper == "remove" and plant.geometry_source_is_registered():
        removed = [geometry for body in carried_bodies(plant, arm, frame.body())
                   for geometry in plant.GetCollisionGeometriesForBody(body)]
    parser = ConfigureParser(Parser(plant))
    tool, weld, pad = add_pad_tool(plant, parser, frame, X_flange_tool if X_flange_tool is not None
                                   else RigidTransform(), name=name, center_frame=center)
    return RobotModel(arm=arm, model_instances=[arm, tool], end_effector_frame=center,
                      end_effector_point=np.zeros(3), tool_weld=weld, pad_geometries=pad,
                      passive_geometries=removed, only_pad_contact=True)


def carried_bodies(plant, model_instance, body):
    """The bodies of ``model_instance`` that ``body`` carries: outboard of it in the joint tree (before or
    after ``Finalize``), ``body`` itself excluded."""
    instance(plant, "plant", "carried_bodies", MultibodyPlant)
    _model_instance_of(plant, model_instance, "model_instance", "carried_bodies")
    if not hasattr(body, "index") or not hasattr(body, "model_instance"):
        raise ArgumentError(f"carried_bodies: body must be a RigidBody of the plant, got {describe(body)}")
    parent = {}
    for index in plant.GetJointIndices(model_instance):
        joint = plant.get_joint(index)
        parent[joint.child_body().index()] = joint.parent_body().index()
    carried = []
    for index in plant.GetBodyIndices(model_instance):
        ancestor = parent.get(index)
        while ancestor is not None and ancestor != body.index():
            ancestor = parent.get(ancestor)
        if ancestor == body.index():
            carried.append(plant.get_body(index))
    return carried


def robot_plant(add_robot):
    """The controller's own model of your robot: ``add_robot(plant) -> RobotModel`` called on a new
    continuous MultibodyPlant (no SceneGraph, no workpiece), finalized. Returns the plant."""
    function(add_robot, "add_robot", "robot_plant", "add_robot(plant) -> RobotModel")
    plant = MultibodyPlant(0.0)
    try:
        robot = add_robot(plant)
    except Exception as error:
        # The package's own errors keep their type; any other is an ArgumentError; the cause stays chained.
        kind = type(error) if isinstance(error, DrakeHybridError) else ArgumentError
        first_line = (str(error).strip().splitlines() or [""])[0]
        raise kind(f"robot_plant: add_robot(plant) raised {type(error).__name__}: {first_line}") from error
    if not isinstance(robot, RobotModel):
        raise ArgumentError(f"robot_plant: add_robot must return the RobotModel of mount_tool, got "
                            f"{type(robot).__name__}")
    plant.Finalize()
    return plant


# ------------------------------------------------------------------------------------------------
# The workpiece and the contact
# ------------------------------------------------------------------------------------------------

def _tool_geometries(robot, owner):
    if isinstance(robot, RobotModel):
        return list(robot.pad_geometries)
    return geometry_ids(robot, "robot", owner, "the RobotModel of mount_tool or a list of the pad's GeometryIds")


def apply_contact_defaults(plant, scene_graph, robot, workpiece_geometries, contact=None):
    """The package's contact material (``contact``: a ContactConfig, default its defaults) on your
    tool (``robot``: the RobotModel of ``mount_tool``, or the pad's geometry ids) and workpiece
    geometries: the pad's hydroelastic modulus, mesh and dissipation, SAP's relaxation times (0.03 s
    for the pair: about critically damped), friction. Call it before ``plant.Finalize()``."""
    owner = "apply_contact_defaults"
    _unfinalized_plant(plant, owner)
    instance(scene_graph, "scene_graph", owner, SceneGraph, what="the SceneGraph of the plant (AddMultibodyPlant's)")
    if not plant.geometry_source_is_registered():
        raise ArgumentError(f"{owner}: the plant has no SceneGraph (make it with AddMultibodyPlant(config, builder))")
    tool = _tool_geometries(robot, owner)
    workpiece = geometry_ids(workpiece_geometries, "workpiece_geometries", owner,
                             "the GeometryIds of add_rigid_workpiece (a list)")
    contact = instance(contact, "contact", owner, ContactConfig, allow_none=True) or ContactConfig()
    contact.validate(f"{owner}: contact.")
    inspector, source = scene_graph.model_inspector(), plant.get_source_id()
    if not inspector.SourceIsRegistered(source):
        raise ArgumentError(f"{owner}: scene_graph is not the plant's SceneGraph (AddMultibodyPlant returns the pair)")
    known = set(inspector.GetAllGeometryIds())
    for name, ids in (("robot", tool), ("workpiece_geometries", workpiece)):
        for geometry_id in ids:
            if geometry_id not in known or not inspector.BelongsToSource(geometry_id, source):
                raise ArgumentError(f"{owner}: {name} holds a geometry ({geometry_id}) that is not the plant's in "
                                    f"scene_graph (another plant's or another SceneGraph's?)")
    set_contact_properties(plant, scene_graph, tool, contact, pad=True)
    set_contact_properties(plant, scene_graph, workpiece, contact, pad=False)


# ------------------------------------------------------------------------------------------------
# The controller and its signals
# ------------------------------------------------------------------------------------------------

@dataclass
class HybridSystems:
    """What ``add_hybrid_controller`` added to your builder, with what analysis needs to read it.

    ``controller`` (HybridController), ``sensor`` (ContactWrenchSensor or WristForceTorqueSensor),
    ``wrench_filter`` (LowPassFilter or None), ``conditioner`` (WrenchConditioner or None),
    ``fault_injector`` (SensorFaultInjector or None), ``source`` (the command source or None: you wire
    the controller's desired_* ports), ``supervisor`` (ContactSupervisor or None), ``wrench_output``
    (the port the controller reads the wrench from), ``true_wrench`` (the sensor's own output); the
    ``plant``, ``robot`` (RobotModel), ``controller_plant``, ``constraint_space`` and ``kinematics``
    (EndEffectorKinematics on the simulation plant) they were built for; ``diagram``: set by the
    functions that take the built diagram.
    """

    plant: object
    robot: RobotModel
    controller_plant: object
    constraint_space: object
    controller: object
    sensor: object
    kinematics: EndEffectorKinematics
    wrench_output: object = None
    true_wrench: object = None
    source: Optional[object] = None
    wrench_filter: Optional[object] = None
    conditioner: Optional[object] = None
    fault_injector: Optional[object] = None
    supervisor: Optional[object] = None
    diagram: Optional[object] = None

    def plant_context(self, root_context):
        return self.plant.GetMyMutableContextFromRoot(root_context)


def robot_bodies(plant, robot):
    """The bodies of every model instance of ``robot``: what a contact sensor counts as the robot."""
    return [plant.get_body(index) for instance in robot.model_instances for index in plant.GetBodyIndices(instance)]


def _port_label(port):
    """'system.port' of an input or output port, for a message."""
    return f"'{port.get_system().get_name()}.{port.get_name()}'"


def _refuse_wired(builder, input_port, owner, hint=""):
    """ArgumentError naming ``input_port`` (and ``hint``) if the builder already wires or exports it: Drake
    ends the process at a second Connect instead of raising."""
    if builder.IsConnectedOrExported(input_port):
        raise ArgumentError(f"{owner}: the input port {_port_label(input_port)} is already connected in the "
                            f"builder{hint}; an input takes one source")


def _connect(builder, output_port, input_port, owner):
    """``builder.Connect(output_port, input_port)`` after ``_refuse_wired``."""
    _refuse_wired(builder, input_port, owner)
    builder.Connect(output_port, input_port)


def _unique_name(builder, name, suffix):
    """``name``, or ``name_<suffix>`` (then ``_2``, ...) if the builder already has a system of that name:
    a diagram's systems need names of their own (Drake ends the process at Build otherwise)."""
    taken = {system.get_name() for system in builder.GetSystems()}
    candidates = [name, f"{name}_{suffix}"] + [f"{name}_{suffix}_{count}" for count in range(2, 1000)]
    return next(candidate for candidate in candidates if candidate not in taken)


def _add_named(builder, name, system, robot_name):
    """``builder.AddNamedSystem`` with ``_unique_name``."""
    return builder.AddNamedSystem(_unique_name(builder, name, robot_name), system)


def _arm_name(plant, robot):
    return plant.GetModelInstanceName(robot.arm)


def _port_of(system, name, kind, owner, argument):
    """``system``'s input (``kind`` "input") or output port ``name``; ArgumentError naming ``argument``."""
    has = system.HasInputPort(name) if kind == "input" else system.HasOutputPort(name)
    if not has:
        ports = (system.get_input_port(i) for i in range(system.num_input_ports())) if kind == "input" else (
            system.get_output_port(i) for i in range(system.num_output_ports()))
        raise ArgumentError(f"{owner}: {argument} ('{system.get_name()}') has no {kind} port '{name}'; its {kind} "
                            f"ports: {', '.join(port.get_name() for port in ports) or 'none'}")
    return system.GetInputPort(name) if kind == "input" else system.GetOutputPort(name)


def _station_parts(builder, plant, robot, owner):
    instance(builder, "builder", owner, DiagramBuilder)
    _finalized_robot_plant(plant, robot, owner)


def _finalized_robot_plant(plant, robot, owner):
    instance(plant, "plant", owner, MultibodyPlant)
    instance(robot, "robot", owner, RobotModel, what="the RobotModel of mount_tool")
    if not plant.is_finalized():
        raise ConfigError(f"{owner}: finalize the plant first (plant.Finalize())")
    _model_instance_of(plant, robot.arm, "robot.arm", owner)


def _sensor_config(sensor, owner):
    """``sensor`` (a ContactSensorConfig or WristSensorConfig) with its fields checked, naming ``owner``."""
    instance(sensor, "sensor", owner, (ContactSensorConfig, WristSensorConfig))
    sensor.validate(f"{owner}: sensor.")
    return sensor


def _controller_model(controller_plant, owner):
    instance(controller_plant, "controller_plant", owner, MultibodyPlant,
             what="a finalized MultibodyPlant of the robot alone (robot_plant(add_robot))")
    if not controller_plant.is_finalized():
        raise ConfigError(f"{owner}: controller_plant must be finalized (robot_plant(add_robot) does it)")
    return controller_plant


def add_wrench_sensor(builder, plant, robot, sensor=None):
    """The wrench sensor of ``sensor`` (a ContactSensorConfig, default; or a WristSensorConfig) on your
    plant, its inputs wired: the environment's wrench on the robot at the end-effector point, in
    world (the contact results of the robot's bodies, or the wrist weld's reaction force). Returns it
    (named "wrench_sensor", or "wrench_sensor_<arm>" if the builder has one)."""
    owner = "add_wrench_sensor"
    _station_parts(builder, plant, robot, owner)
    sensor = _sensor_config(sensor if sensor is not None else ContactSensorConfig(), owner)
    arm = _arm_name(plant, robot)
    if isinstance(sensor, WristSensorConfig):
        if robot.tool_weld is None:
            raise ConfigError("sensor: the robot has no wrist weld (mount_tool makes one) for a WristSensorConfig; "
                              "use ContactSensorConfig")
        system = _add_named(builder, "wrench_sensor", WristForceTorqueSensor(
            plant, robot.tool_weld, robot.end_effector_frame, robot.end_effector_point,
            compensate_tool_inertia=sensor.compensate_tool_inertia), arm)
        _connect(builder, plant.get_reaction_forces_output_port(), system.get_input_port(0), owner)
        if system.compensate_tool_inertia:
            _connect(builder, plant.get_body_spatial_velocities_output_port(),
                    system.GetInputPort("body_spatial_velocities"), owner)
            _connect(builder, plant.get_body_spatial_accelerations_output_port(),
                    system.GetInputPort("body_spatial_accelerations"), owner)
    else:
        system = _add_named(builder, "wrench_sensor", ContactWrenchSensor(
            plant, robot_bodies(plant, robot), robot.end_effector_frame, robot.end_effector_point), arm)
        _connect(builder, plant.get_contact_results_output_port(), system.get_input_port(0), owner)
    _connect(builder, plant.get_body_poses_output_port(), system.get_input_port(1), owner)
    return system


def add_wrench_path(builder, wrench_output, sensor, period, sequence=None, tare=False, suffix="wrench"):
    """The wrench's way to the controller (``sensor``: a ContactSensorConfig or WristSensorConfig): a
    WrenchConditioner with ``sensor.condition`` (fed the sample ``sequence`` output when given;
    ``tare``), else a low-pass filter when ``sensor.bandwidth_hz`` > 0, else nothing (``suffix``: what
    their names end with when the builder already has a system of that name). Returns (the output
    port the controller reads, the conditioner or None, the filter or None)."""
    owner = "add_wrench_path"
    instance(builder, "builder", owner, DiagramBuilder)
    instance(wrench_output, "wrench_output", owner, OutputPort, what="an OutputPort (the wrench sensor's)")
    instance(sequence, "sequence", owner, OutputPort, allow_none=True)
    _sensor_config(sensor, owner)
    conditioner = wrench_filter = None
    if sensor.condition:
        conditioner = _add_named(builder, "wrench_conditioner", WrenchConditioner(
            period, sensor.bandwidth_hz, sensor.max_hold_time, use_sequence=sequence is not None, tare=tare), suffix)
        _connect(builder, wrench_output, conditioner.GetInputPort("raw_wrench"), owner)
        if sequence is not None:
            _connect(builder, sequence, conditioner.GetInputPort("sequence"), owner)
        wrench_output = conditioner.GetOutputPort("wrench")
    elif sensor.bandwidth_hz > 0:
        wrench_filter = _add_named(builder, "wrench_filter", LowPassFilter(6, sensor.bandwidth_hz, period), suffix)
        _connect(builder, wrench_output, wrench_filter.get_input_port(0), owner)
        wrench_output = wrench_filter.get_output_port(0)
    return wrench_output, conditioner, wrench_filter


def wrench_lag(sensor, plant, control_period):
    """How late the wrench reaches the law (s), which splits it where it was exerted (the controller's
    ``wrench_lag``): the low-pass of ``sensor`` (``systems.sensors.low_pass_lag``), plus, for the
    contact sensor on a discrete plant's sampled results, their one step of age
    (``systems.sensors.sampled_reading_age``; the wrist sensor's reaction force is read as current,
    as a real sensor's)."""
    instance(sensor, "sensor", "wrench_lag", (ContactSensorConfig, WristSensorConfig))
    instance(plant, "plant", "wrench_lag", MultibodyPlant)
    age = sampled_reading_age(plant) if isinstance(sensor, ContactSensorConfig) else 0.0
    return low_pass_lag(sensor.bandwidth_hz, control_period) + age


_SOURCE_OUTPUTS = ("desired_velocity", "desired_acceleration", "desired_force")
_CONTROLLER_INPUTS = ("estimated_state", "measured_wrench") + _SOURCE_OUTPUTS
_SUPERVISED_INPUTS = ("contact_phase", "approach_reference")
_SUPERVISED_OUTPUTS = ("force", "constraint_value")


def _check_source(source, owner):
    instance(source, "source", owner, System, what="a System with the output ports " + ", ".join(_SOURCE_OUTPUTS)
             + " (or None: a ProfileSource of desired_velocity and desired_force; False: you wire them)")
    for name in _SOURCE_OUTPUTS:
        _port_of(source, name, "output", owner, "source")


def connect_source(builder, plant, robot, source, controller):
    """Add the command source ``source`` (a system with the output ports desired_velocity,
    desired_acceleration and desired_force; if it has inputs, its first is the arm's state, as
    ``DesiredFieldSource``'s and ``PathSource``'s) to ``builder`` as "desired" (or "desired_<arm>" if the
    builder has one) and wire it to ``controller``. Returns it."""
    owner = "connect_source"
    _station_parts(builder, plant, robot, owner)
    _check_source(source, owner)
    instance(controller, "controller", owner, System)
    inputs = [_port_of(controller, name, "input", owner, "controller") for name in _SOURCE_OUTPUTS]
    for port in inputs:
        _refuse_wired(builder, port, owner, " (the controller already has a command source)")
    source = _add_named(builder, "desired", source, _arm_name(plant, robot))
    if source.num_input_ports():
        _connect(builder, plant.get_state_output_port(robot.arm), source.get_input_port(0), owner)
    for name, port in zip(_SOURCE_OUTPUTS, inputs):
        _connect(builder, source.GetOutputPort(name), port, owner)
    return source


def add_contact_supervisor(builder, controller, wrench_output, supervision, control_period, initial_phase,
                           source=None, conditioner=None, lift_off=False, suffix="supervisor"):
    """Add a ContactSupervisor (``supervision``: a SupervisionConfig; starting in ``initial_phase``)
    between ``controller`` (a HybridController built with ``guarded_move=supervision``) and the
    wrench it reads (``wrench_output``), wired both ways::

        controller ─force, constraint_value─► supervisor ─contact_phase, approach_reference─► controller
        wrench_output ─► supervisor;  source ─desired_force─► supervisor;  supervisor ─contact_phase─► conditioner

    (``source``: the command source; ``conditioner``: a taring WrenchConditioner; ``lift_off``: the
    supervisor takes a ``path_done`` input and lifts off). Returns it."""
    owner = "add_contact_supervisor"
    instance(builder, "builder", owner, DiagramBuilder)
    instance(supervision, "supervision", owner, SupervisionConfig)
    instance(wrench_output, "wrench_output", owner, OutputPort, what="an OutputPort (the wrench the controller reads)")
    instance(controller, "controller", owner, System)
    phase = _contact_phase(initial_phase, owner)
    inputs = [_port_of(controller, name, "input", owner, "controller") for name in _SUPERVISED_INPUTS]
    outputs = [_port_of(controller, name, "output", owner, "controller") for name in _SUPERVISED_OUTPUTS]
    for port in inputs:
        _refuse_wired(builder, port, owner, " (the controller already has a contact supervisor)")
    for name in ("force_size", "kinematic_rows"):
        if not hasattr(controller, name):
            raise ArgumentError(f"{owner}: controller must be a HybridController (or have its {name}), got "
                                f"{describe(controller)}")
    supervisor = _add_named(builder, "contact_supervisor", ContactSupervisor(
        supervision, controller.force_size, controller.kinematic_rows, control_period, phase,
        lift_off=lift_off), suffix)
    for name, port in zip(_SUPERVISED_OUTPUTS, outputs):
        _connect(builder, port, supervisor.GetInputPort(name), owner)
    if source is not None:
        _connect(builder, _port_of(source, "desired_force", "output", owner, "source"),
                supervisor.GetInputPort("desired_force"), owner)
    _connect(builder, wrench_output, supervisor.GetInputPort("measured_wrench"), owner)
    for name, port in zip(("contact_phase", "approach_reference"), inputs):
        _connect(builder, supervisor.GetOutputPort(name), port, owner)
    if conditioner is not None:
        _connect(builder, supervisor.GetOutputPort("contact_phase"),
                _port_of(conditioner, "contact_phase", "input", owner, "conditioner"), owner)
    return supervisor


def _contact_phase(initial_phase, owner):
    """``initial_phase`` (a ContactPhase or its value; None: CONTACT) as a ContactPhase; ArgumentError otherwise."""
    if initial_phase is None:
        return ContactPhase.CONTACT
    if isinstance(initial_phase, str) and initial_phase.upper() in ContactPhase.__members__:
        return ContactPhase[initial_phase.upper()]
    if (isinstance(initial_phase, (bool, np.bool_)) or not isinstance(initial_phase, numbers.Integral)
            or int(initial_phase) not in {phase.value for phase in ContactPhase}):
        allowed = ", ".join(f"ContactPhase.{phase.name} ({phase.value})" for phase in ContactPhase)
        raise ArgumentError(f"{owner}: initial_phase must be one of {allowed} or None, got {describe(initial_phase)}")
    return ContactPhase(initial_phase)


def add_sensing(builder, plant, robot, controller, sensor, control_period, sensor_faults=None, tare=False):
    """The wrench sensor (``add_wrench_sensor``), a SensorFaultInjector when ``sensor_faults`` is active,
    and the wrench path (``add_wrench_path``), wired into ``controller``'s measured_wrench. Returns
    (sensor, its own output, the output the controller reads, injector, conditioner, filter)."""
    owner = "add_sensing"
    _station_parts(builder, plant, robot, owner)
    instance(controller, "controller", owner, System)
    instance(sensor_faults, "sensor_faults", owner, SensorFaultConfig, allow_none=True)
    measured = _port_of(controller, "measured_wrench", "input", owner, "controller")
    _refuse_wired(builder, measured, owner, " (the controller already reads a wrench)")
    arm = _arm_name(plant, robot)
    wrench_sensor = add_wrench_sensor(builder, plant, robot, sensor)
    true_wrench = wrench_output = wrench_sensor.get_output_port(0)
    injector = None
    if sensor_faults is not None and sensor_faults.active():
        injector = _add_named(builder, "sensor_faults", SensorFaultInjector(sensor_faults, control_period), arm)
        _connect(builder, wrench_output, injector.GetInputPort("wrench"), owner)
        wrench_output = injector.GetOutputPort("faulty_wrench")
    wrench_output, conditioner, wrench_filter = add_wrench_path(
        builder, wrench_output, sensor if sensor is not None else ContactSensorConfig(), control_period,
        sequence=injector.GetOutputPort("sequence") if injector is not None else None, tare=tare, suffix=arm)
    _connect(builder, wrench_output, measured, owner)
    return wrench_sensor, true_wrench, wrench_output, injector, conditioner, wrench_filter


def as_profile(command, size, name="command", owner="add_hybrid_controller"):
    """``command`` as a Profile of ``size`` entries: a Profile as it is (checked), a sequence of ``size``
    numbers as a constant one, None as zeros. Typed errors name ``name``."""
    if command is None:
        return Profile(value=[0.0] * size)
    if isinstance(command, Profile):
        command.validate(size, f"{owner}: {name}")
        return command
    return Profile(value=vector(command, name, owner, size).tolist())


CONTROLLER_OPTIONS = tuple(name for name in inspect.signature(HybridController._construct).parameters
                           if name not in ("self", "plant", "end_effector_frame", "end_effector_point",
                                           "constraint_space", "gains", "mode", "control_period", "guarded_move",
                                           "converter"))
_MATCH_TOLERANCE = 1e-6      # m and rad: the controller plant's end-effector pose against the plant's
_MATCH_CONFIGURATIONS = 3    # the default positions and two random ones within the limits


def check_controller_plant(plant, robot, controller_plant, owner="check_controller_plant"):
    """ArgumentError naming ``controller_plant`` if it does not model ``plant``'s arm ``robot.arm``: the
    numbers of positions, velocities and actuators, and the end-effector pose (``robot``'s frame and
    point) at the arm's default positions and two random ones within the joint limits (to
    1e-6 m and rad). Checked first: ``plant`` a finalized MultibodyPlant, ``robot`` the RobotModel of
    ``mount_tool`` on it, ``controller_plant`` a finalized MultibodyPlant (ArgumentError, ConfigError)."""
    _finalized_robot_plant(plant, robot, owner)
    _controller_model(controller_plant, owner)
    arm, arm_name = robot.arm, plant.GetModelInstanceName(robot.arm)
    counts = {"positions": (plant.num_positions(arm), controller_plant.num_positions()),
              "velocities": (plant.num_velocities(arm), controller_plant.num_velocities()),
              "actuators": (plant.num_actuated_dofs(arm), controller_plant.num_actuated_dofs())}
    for what, (simulated, model) in counts.items():
        if simulated != model:
            raise ArgumentError(f"{owner}: controller_plant has {model} {what}, the plant's arm '{arm_name}' "
                                f"{simulated}: pass the controller's model of this arm (robot_plant(add_robot))")
    frame = robot.end_effector_frame
    for name, model in (("plant", plant), ("controller_plant", controller_plant)):
        if not model.HasFrameNamed(frame):
            raise ArgumentError(f"{owner}: {name} has no end-effector frame '{frame}' (robot.end_effector_frame): "
                                f"pass the controller's model of this arm (robot_plant(add_robot))")
    context, model_context = plant.CreateDefaultContext(), controller_plant.CreateDefaultContext()
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    default = plant.GetPositions(context, arm)
    in_arm = plant.GetPositionsFromArray(arm, np.arange(plant.num_positions(), dtype=float)).astype(int)
    low = np.where(np.isfinite(lower[in_arm]), lower[in_arm], -np.pi)
    high = np.where(np.isfinite(upper[in_arm]), upper[in_arm], np.pi)
    generator = np.random.default_rng(0)
    configurations = [default] + [generator.uniform(low, high) for _ in range(_MATCH_CONFIGURATIONS - 1)]
    point = np.asarray(robot.end_effector_point, dtype=float)
    for number, q in enumerate(configurations):
        plant.SetPositions(context, arm, q)
        controller_plant.SetPositions(model_context, q)
        X_sim = plant.GetFrameByName(frame).CalcPoseInWorld(context)
        X_model = controller_plant.GetFrameByName(frame).CalcPoseInWorld(model_context)
        distance = float(np.linalg.norm(X_sim.multiply(point) - X_model.multiply(point)))
        angle = float(X_sim.rotation().InvertAndCompose(X_model.rotation()).ToAngleAxis().angle())
        if distance > _MATCH_TOLERANCE or angle > _MATCH_TOLERANCE:
            where = "the arm's default positions" if number == 0 else f"q = {np.round(q, 3).tolist()}"
            raise ArgumentError(f"{owner}: controller_plant does not model the plant's arm '{arm_name}': its "
                                f"end-effector frame '{frame}' is {distance:.3g} m and {angle:.3g} rad from the "
                                f"plant's at {where}; pass robot_plant(add_robot) of the add_robot that built the "
                                f"plant's arm")


def _check_actuation_free(builder, plant, robot, owner):
    port = plant.get_actuation_input_port(robot.arm)
    if not builder.IsConnectedOrExported(port):
        return
    source = builder.connection_map().get((plant, port.get_index()))
    driver = source[0] if source is not None else None
    if driver is not None and driver.HasInputPort("estimated_state") and driver.HasOutputPort("actuation"):
        hint = (f" by '{driver.get_name()}': the builder already has a hybrid controller on this arm (one "
                f"controller per arm)")
    elif driver is not None:
        hint = f" by your system '{driver.get_name()}': leave the arm's actuation input to the hybrid controller"
    else:
        hint = " (exported): leave the arm's actuation input to the hybrid controller"
    raise ArgumentError(f"{owner}: the input port {_port_label(port)} is already connected in the builder{hint}")


def add_hybrid_controller(builder, plant, robot, constraint_space, controller_plant, gains=None,
                          mode=ControlMode.VELOCITY_FORCE, control_period=None, desired_velocity=None,
                          desired_force=None, source=None, sensor=None, supervision=None, initial_phase=None,
                          sensor_faults=None, controller=None, **controller_options):
    """Add the hybrid controller and what feeds it to your builder, wired to your plant.

    ::

        plant ─contact_results / reaction_forces, body_poses─► wrench_sensor ─► [filter or conditioner] ─┐
        plant ─state (robot.arm)──────────────────────────────────────────────────────────────────────┼─► controller
        source ─desired_velocity, desired_acceleration, desired_force─────────────────────────────────┘      │
        controller ─actuation─► plant (robot.arm)  ◄───────────────────────────────────────────────────────────┘
        [supervisor: controller ─force, constraint_value─► supervisor ─contact_phase, approach_reference─► controller]

    One controller per arm: the arm's actuation input must not be wired yet (ArgumentError naming the
    port otherwise). The systems are named controller, wrench_sensor, desired, ... ; a second arm's
    (a second call with another ``robot``) get its model instance name appended.

    Args:
        builder: your DiagramBuilder; ``plant``: your finalized MultibodyPlant in it (with its SceneGraph).
        robot: the RobotModel of ``mount_tool``.
        constraint_space: a ConstraintSpace (chart, C, E_p).
        controller_plant: the controller's own model of the robot (``robot_plant(add_robot)``): checked
            against the plant's arm (positions, velocities, actuators, the end-effector pose at three
            configurations).
        gains, mode, control_period: of the HybridController (None: continuous, for linearization).
        desired_velocity, desired_force: Profiles (time profiles, k and m entries; a list of numbers is a
            constant one, ``[10.0]`` for one force row; default zero) for a ProfileSource; or ``source``: a
            system of your own with the output ports desired_velocity, desired_acceleration and
            desired_force (wired here), or False: you wire the controller's desired_* input ports yourself.
        sensor: a ContactSensorConfig (default) or WristSensorConfig: which wrench, and its path (a
            low-pass of ``bandwidth_hz``, a conditioner). A continuous controller needs a low-pass
            (default then ``CONTINUOUS_LOOP_BANDWIDTH``): its actuation feeds through to the wrench.
        supervision: a SupervisionConfig: a ContactSupervisor (guarded approach, contact loss) starting
            in ``initial_phase`` (a ContactPhase; default CONTACT).
        sensor_faults: a SensorFaultConfig: its injector between the sensor and the wrench path.
        controller: a controller system of your own with the HybridController's ports (e.g. a baseline
            of ``control.baselines``) instead of building one.
        controller_options: further HybridController arguments (``CONTROLLER_OPTIONS``: safety,
            velocity_row_inertia, compensate_tangential_force, sample_lead, sampled_diagnostics,
            plant_time_step, fast_law, ...); only when ``controller`` is None.

    Returns a HybridSystems. Every port stays reachable by name for wiring by hand.
    """
    owner = "add_hybrid_controller"
    _station_parts(builder, plant, robot, owner)
    _controller_model(controller_plant, owner)
    instance(constraint_space, "constraint_space", owner, ConstraintSpace,
             what="a ConstraintSpace (a constraint with its velocity projection)")
    unknown = sorted(set(controller_options) - set(CONTROLLER_OPTIONS))
    if unknown:
        raise ArgumentError(f"{owner}: unknown argument(s) {', '.join(unknown)}; the HybridController options are "
                            f"{', '.join(CONTROLLER_OPTIONS)}")
    if controller is not None and controller_options:
        raise ArgumentError(f"{owner}: {', '.join(sorted(controller_options))} configure the HybridController "
                            f"built here, not your controller: pass them to your controller")
    if sensor is None:
        sensor = ContactSensorConfig(bandwidth_hz=CONTINUOUS_LOOP_BANDWIDTH if control_period is None else 0.0)
    _sensor_config(sensor, owner)
    if control_period is None and not (sensor.bandwidth_hz > 0):
        raise ConfigError("sensor.bandwidth_hz: a continuous controller (control_period None) needs a wrench "
                          "low-pass (> 0 Hz): its actuation feeds through to the measured wrench")
    instance(supervision, "supervision", owner, SupervisionConfig, allow_none=True)
    instance(sensor_faults, "sensor_faults", owner, SensorFaultConfig, allow_none=True)
    phase = _contact_phase(initial_phase, owner)
    k, m = constraint_space.velocity_size, constraint_space.force_size
    if source is None:
        source = ProfileSource(as_profile(desired_velocity, k, "desired_velocity"),
                               as_profile(desired_force, m, "desired_force"), k, m)
    elif source is not False:
        _check_source(source, owner)
    if controller is not None:
        instance(controller, "controller", owner, System, what="a controller System with the HybridController's "
                 "ports (e.g. a baseline of control.baselines) or None")
        for name in _CONTROLLER_INPUTS + (_SUPERVISED_INPUTS if supervision is not None else ()):
            _port_of(controller, name, "input", owner, "controller")
        for name in ("actuation",) + (_SUPERVISED_OUTPUTS if supervision is not None else ()):
            _port_of(controller, name, "output", owner, "controller")
    check_controller_plant(plant, robot, controller_plant, owner)
    _check_actuation_free(builder, plant, robot, owner)
    if controller is None:
        options = dict(sampled_diagnostics=control_period is not None, plant_time_step=plant.time_step(),
                       wrench_lag=wrench_lag(sensor, plant, control_period))
        options.update(controller_options)
        controller = HybridController(controller_plant, robot.end_effector_frame, robot.end_effector_point,
                                      constraint_space, gains=gains, mode=mode, control_period=control_period,
                                      guarded_move=supervision, **options)
    arm = _arm_name(plant, robot)
    controller = _add_named(builder, "controller", controller, arm)
    tare = supervision is not None and supervision.tare_time > 0 and phase == ContactPhase.TARE
    wrench_sensor, true_wrench, wrench_output, injector, conditioner, wrench_filter = add_sensing(
        builder, plant, robot, controller, sensor, control_period, sensor_faults, tare)
    _connect(builder, plant.get_state_output_port(robot.arm), controller.GetInputPort("estimated_state"), owner)
    _connect(builder, controller.GetOutputPort("actuation"), plant.get_actuation_input_port(robot.arm), owner)
    source = connect_source(builder, plant, robot, source, controller) if source is not False else None
    supervisor = None
    if supervision is not None:
        supervisor = add_contact_supervisor(builder, controller, wrench_output, supervision, control_period, phase,
                                            source=source, conditioner=conditioner if tare else None, suffix=arm)
    kinematics = EndEffectorKinematics(plant, robot.end_effector_frame, robot.end_effector_point,
                                       constraint_space.chart)
    return HybridSystems(plant=plant, robot=robot, controller_plant=controller_plant,
                         constraint_space=constraint_space, controller=controller, sensor=wrench_sensor,
                         kinematics=kinematics, wrench_output=wrench_output, true_wrench=true_wrench, source=source,
                         wrench_filter=wrench_filter, conditioner=conditioner, fault_injector=injector,
                         supervisor=supervisor)


# The log's keys (read_log; log.npz names a few otherwise), each (samples x size), with "t" the sample times.
LOG_KEYS = {
    "t": "sample times (s)",
    "velocity_error": "e_p' = E_p r-dot - r-dot_pd (k; each row in its own units)",
    "force_error": "e_f = F - F_d (m; zero on kinematic rows, NaN while the wrench is invalid)",
    "wrench_valid": "1 where the measured wrench was finite, 0 where not (then force, force_error and "
                    "tangential_force read NaN) (1)",
    "constraint_value": "C(r) (m; in C's units: a contact's compression, a weld's offset)",
    "projected_velocity": "r-dot_p = E_p r-dot (k)",
    "force": "F, the force on the robot in E_f's coordinates ([F_v; F] = E^-T w) (m)",
    "tangential_force": "F_v, the measured force along the velocity rows (k)",
    "position_error": "e_p, the integral of e_p' (k; zero in velocity-force mode)",
    "actuation": "the actuators' torques (n_u, N m or N, in the plant's actuator order)",
    "desired_velocity": "r-dot_pd (k)",
    "desired_force": "F_d (m)",
    "state": "[q; v] of the arm (2n, in the plant's joint order for robot.arm)",
    "wrench": "the wrench the controller reads: [torque; force] on the robot BY the environment at the "
              "end-effector point, world frame (6; N m, N), after the filter or conditioner",
    "true_wrench": "the sensor's own wrench, before faults, filter or conditioner (6; only when they differ)",
    "contact_phase": "the ContactSupervisor's phase (1; control.phases.ContactPhase values; only when supervised)",
}


def add_loggers(builder, systems, period=None):
    """Loggers for every signal of ``systems`` (a HybridSystems), keyed by ``LOG_KEYS``.

    ``period``: sample period (s); None logs every publish of the simulator's steps. A controller with
    ``sampled_diagnostics`` is logged from its ``diagnostics`` port (what each tick computed, read
    once). Returns {key: VectorLogSink or (sink, column slice)}; ``read_log`` turns it into arrays."""
    instance(builder, "builder", "add_loggers", DiagramBuilder)
    instance(systems, "systems", "add_loggers", HybridSystems, what="the HybridSystems of add_hybrid_controller")
    controller = systems.controller
    loggers = {}
    period = nonnegative(0.0 if period is None else period, "period", "add_loggers", unit="s")
    if getattr(controller, "sampled_diagnostics", False):
        diagnostics = LogVectorOutput(controller.GetOutputPort("diagnostics"), builder, period)
        for name, columns in controller.diagnostic_slices().items():
            loggers[name] = (diagnostics, columns)
    else:
        for name in controller.diagnostic_slices():
            loggers[name] = LogVectorOutput(controller.GetOutputPort(name), builder, period)
    for name in ("position_error", "actuation"):
        loggers[name] = LogVectorOutput(controller.GetOutputPort(name), builder, period)
    if systems.source is not None:
        for name in ("desired_velocity", "desired_force"):
            loggers[name] = LogVectorOutput(systems.source.GetOutputPort(name), builder, period)
    loggers["state"] = LogVectorOutput(systems.plant.get_state_output_port(systems.robot.arm), builder, period)
    loggers["wrench"] = LogVectorOutput(systems.wrench_output, builder, period)
    if systems.true_wrench is not None and systems.true_wrench is not systems.wrench_output:
        loggers["true_wrench"] = LogVectorOutput(systems.true_wrench, builder, period)
    if systems.supervisor is not None:
        loggers["contact_phase"] = LogVectorOutput(systems.supervisor.GetOutputPort("contact_phase"), builder, period)
    return loggers


def logged(loggers, root_context, name, owner="logged"):
    """(times, samples x size) of logger ``name`` of ``loggers`` (``add_loggers``) in ``root_context`` (the
    root context of the diagram they were added to: ArgumentError naming ``owner`` otherwise)."""
    instance(loggers, "loggers", owner, dict, what="the dict of add_loggers")
    if name not in loggers:
        raise ArgumentError(f"{owner}: no logger '{name}'; these were logged: {', '.join(loggers)}")
    logger, columns = loggers[name], slice(None)
    if isinstance(logger, tuple):
        logger, columns = logger
    subsystem_context(logger, root_context, owner, "the diagram the loggers were added to")
    log = logger.FindLog(root_context)
    return log.sample_times(), log.data().T[:, columns]


def read_log(loggers: Dict[str, object], root_context):
    """{key: array} of every logger of ``add_loggers`` in ``root_context``, with "t" (the sample times of
    the first), keyed by ``LOG_KEYS`` (log.npz calls a few otherwise: velocity, constraint, torque, q and v)."""
    instance(loggers, "loggers", "read_log", dict, what="the dict of add_loggers")
    log = {}
    for name in loggers:
        times, values = logged(loggers, root_context, name, "read_log")
        log.setdefault("t", times)
        log[name] = values
    return log
