"""The arm and its tool: a pad (the ball or a disc, ``station.tools``) mounted on any arm's frame, a gripper
welded or removed, actuators.
"""

import os
import re
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union, cast
from xml.etree import ElementTree

import numpy as np

from pydrake.geometry import GeometryId
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame, ModelInstanceIndex, RigidBody, WeldJoint

from drake_hybrid.core.arguments import describe, function, instance, positive, text
from drake_hybrid.core.errors import ArgumentError, ConfigError, DrakeHybridError
from drake_hybrid.station.parsing import ConfigureParser, add_model, models_directory
from drake_hybrid.station.robot_model import (RobotModel, check_arm_moves_end_effector, check_model_instance,
                                              check_unfinalized_plant, get_frame)
from drake_hybrid.station.tools import ToolConfig, disc_tool_sdf


def weld_joints(plant: MultibodyPlant, joint_names: Union[str, Sequence[str]],
                model_instance: Optional[ModelInstanceIndex] = None) -> List[WeldJoint]:
    """Replace each named joint by a weld at its zero position (before ``Finalize``).

    For parts the task does not move, such as gripper fingers: the hybrid law
    needs one actuator per joint and nq == nv. Drake's ``RemoveJoint`` refuses
    while the plant has any constraint, and pydrake does not say which joints a
    coupler constraint (what a parser makes of a URDF ``<mimic>``) couples, so
    **every** constraint of the plant is removed first: call this before adding
    constraints of your own. Returns the new WeldJoints.
    """
    owner = "weld_joints"
    check_unfinalized_plant(plant, owner)
    if model_instance is not None:
        check_model_instance(plant, model_instance, "model_instance", owner)
    if isinstance(joint_names, str):
        joint_names = [joint_names]
    if not isinstance(joint_names, (list, tuple)):
        raise ArgumentError(f"{owner}: joint_names must be a joint name or a list of joint names, got "
                            f"{describe(joint_names)}")
    joint_names = [text(name, "joint_names[]", owner) for name in joint_names]
    joints = []
    for name in joint_names:
        scope = () if model_instance is None else (model_instance,)
        if not plant.HasJointNamed(name, *scope):
            indices = plant.GetJointIndices(*scope)
            known = sorted(plant.get_joint(index).name() for index in indices)
            where = "the plant" if model_instance is None else f"model '{plant.GetModelInstanceName(model_instance)}'"
            raise ArgumentError(f"weld_joints: {where} has no joint '{name}'; its joints: {', '.join(known)}")
        joints.append(plant.GetJointByName(name, *scope))
    for constraint_id in plant.GetConstraintIds():
        plant.RemoveConstraint(constraint_id)
    welds = []
    for joint in joints:
        parent, child = joint.frame_on_parent(), joint.frame_on_child()
        plant.RemoveJoint(joint)
        welds.append(plant.WeldFrames(parent, child, RigidTransform()))
    return welds


def urdf_effort_limits(path: Union[str, os.PathLike]) -> Dict[str, float]:
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
    limits = {}
    for joint in root.iter("joint"):
        limit = joint.find("limit")
        effort = limit.get("effort") if limit is not None else None
        if effort:
            limits[cast(str, joint.get("name"))] = float(effort)     # a URDF's joints have names
    return limits


def add_actuators(plant: MultibodyPlant, model_instance: ModelInstanceIndex,
                  effort_limits: Optional[Mapping[str, float]] = None) -> List[str]:
    """One actuator per single-dof joint of ``model_instance`` that has none (a URDF without
    transmissions), with the effort limit ``effort_limits[joint name]`` (e.g. from
    ``urdf_effort_limits``; inf where not given). Returns the actuator names.

    ArgumentError for a limit that is not a number > 0 (inf: none), and for a name that is not a joint of
    ``model_instance`` while a joint to actuate has no limit (a misspelling would leave it unlimited; the
    names of joints ``weld_joints`` removed are otherwise let through, as ``urdf_effort_limits`` gives them)."""
    check_unfinalized_plant(plant, "add_actuators")
    check_model_instance(plant, model_instance, "model_instance", "add_actuators")
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


def _welded_to_world(plant, body):
    """True if ``body`` hangs from the world body by welds alone (no joint with a degree of freedom between
    them, in the joint tree as it stands: a body not yet welded nor jointed to anything is not)."""
    parent = {}
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        parent[joint.child_body().index()] = (joint.parent_body().index(), joint.num_velocities())
    world, index, seen = plant.world_body().index(), body.index(), set()
    while index != world:
        if index in seen or index not in parent:
            return False
        seen.add(index)
        index, velocities = parent[index]
        if velocities > 0:
            return False
    return True


def _check_moved(plant, frame, owner):
    """ArgumentError if no joint moves ``frame``'s body (it is welded to the world: the arm's base)."""
    body = frame.body()
    if _welded_to_world(plant, body):
        raise ArgumentError(f"{owner}: flange_frame '{frame.name()}' (on body '{body.name()}') is welded to the world: "
                            "no joint moves it, so the pad could not move (the arm's base?); pass the frame at the end "
                            "of the arm (its flange, e.g. 'tool0')")


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


def mount_tool(plant: MultibodyPlant, arm: ModelInstanceIndex, flange_frame: Union[str, Frame],
               X_flange_tool: Optional[RigidTransform] = None, gripper_joints: Union[str, Sequence[str]] = (),
               gripper: str = "weld", name: str = "pad_tool", tool: Optional[ToolConfig] = None) -> RobotModel:
    """Mount the compliant pad tool on ``flange_frame`` of ``arm`` at ``X_flange_tool`` (default: the identity),
    before ``Finalize``: the ball pad (``models/pad_tool.sdf``: a ball of radius 20 mm, its centre 0.05 m along
    the tool's +z, the controlled point) or, with ``tool=ToolConfig(kind="disc", ...)``, a flat compliant disc
    (``station.tools``: the centre of its face 0.05 m along +z, the controlled point).

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
            clear; ``station.contact_start.solve_contact_start`` refuses a start where it is not); "remove":
            the collision geometries of every body the flange carries (the gripper's fixed and moving
            parts; ``RobotModel.passive_geometries``, dropped by ``only_tool_touches``): a gripper your
            model has but your station does not (it stays drawn).
        name: the tool's model instance name. The default ("pad_tool", end-effector frame
            ``pad_center``) is for one tool per plant; give each further tool a name of its own (two
            arms, each with its pad): its end-effector frame is then ``<name>_center``.
        tool: a ``station.tools.ToolConfig`` (None: the ball); checked (ConfigError naming its field).

    Returns the RobotModel: the arm and tool instances, the end-effector frame (``pad_center``, or
    ``<name>_center``) and point (its origin), the wrist weld (where a wrist force/torque sensor sits),
    the pad's geometries and the tool (``RobotModel.tool``).
    """
    owner = "mount_tool"
    instance(X_flange_tool, "X_flange_tool", owner, RigidTransform, allow_none=True)
    tool = (instance(tool, "tool", owner, ToolConfig, allow_none=True) or ToolConfig())
    tool.validate(f"{owner}: tool.")
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
    check_unfinalized_plant(plant, owner)
    check_model_instance(plant, arm, "arm", owner)
    center = _tool_center_frame(name)
    if plant.HasModelInstanceNamed(name) or plant.HasFrameNamed(center):
        raise ArgumentError(f"{owner}: the plant already has a model '{name}' (or a frame '{center}'): a tool "
                            f"mounted before? Pass name= to mount another tool (e.g. name='{name}_2')")
    frame = _flange(plant, arm, flange_frame, owner)
    if gripper_joints:
        weld_joints(plant, list(gripper_joints), arm)
    _check_moved(plant, frame, owner)
    removed = []
    if gripper == "remove" and plant.geometry_source_is_registered():
        removed = [geometry for body in carried_bodies(plant, arm, frame.body())
                   for geometry in plant.GetCollisionGeometriesForBody(body)]
    parser = ConfigureParser(Parser(plant))
    tool_instance, weld, pad = add_pad_tool(plant, parser, frame, X_flange_tool if X_flange_tool is not None
                                            else RigidTransform(), name=name, center_frame=center, tool=tool)
    return RobotModel(arm=arm, model_instances=[arm, tool_instance], end_effector_frame=center,
                      end_effector_point=np.zeros(3), tool_weld=weld, pad_geometries=pad,
                      passive_geometries=removed, only_pad_contact=True, tool=tool)


def carried_bodies(plant: MultibodyPlant, model_instance: ModelInstanceIndex, body: RigidBody) -> List[RigidBody]:
    """The bodies of ``model_instance`` that ``body`` carries: outboard of it in the joint tree (before or
    after ``Finalize``), ``body`` itself excluded."""
    instance(plant, "plant", "carried_bodies", MultibodyPlant)
    check_model_instance(plant, model_instance, "model_instance", "carried_bodies")
    if not hasattr(body, "index") or not hasattr(body, "model_instance"):
        raise ArgumentError(f"carried_bodies: body must be a RigidBody of the plant, got {describe(body)}")
    parent = {}
    for index in plant.GetJointIndices(model_instance):
        joint = plant.get_joint(index)
        parent[joint.child_body().index()] = joint.parent_body().index()
    carried = []
    for body_index in plant.GetBodyIndices(model_instance):
        ancestor = parent.get(body_index)
        while ancestor is not None and ancestor != body.index():
            ancestor = parent.get(ancestor)
        if ancestor == body.index():
            carried.append(plant.get_body(body_index))
    return carried


def robot_plant(add_robot: Callable[[MultibodyPlant], RobotModel]) -> MultibodyPlant:
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
    check_arm_moves_end_effector(plant, robot, "robot_plant")
    return plant


PAD_RADIUS = 0.02            # m, the pad sphere of models/pad_tool.sdf
PAD_CENTER_IN_TOOL = 0.05    # m along the tool's +z axis (frame "pad_center")


def add_pad_tool(plant: MultibodyPlant, parser: Parser, wrist_frame: Frame, X_wrist_flange: RigidTransform,
                 name: str = "pad_tool", center_frame: str = "pad_center",
                 tool: Optional[ToolConfig] = None) -> Tuple[ModelInstanceIndex, WeldJoint, List[GeometryId]]:
    """Parse the pad tool as model ``name`` with its pad centre frame called ``center_frame`` (the
    model's own names by default; others let a plant hold several tools) and weld its flange to
    ``wrist_frame``: the ball of ``models/pad_tool.sdf``, or the disc of ``tool`` (a validated
    ``station.tools.ToolConfig`` of kind disc). Returns (instance, weld, pad geometries)."""
    if tool is not None and tool.is_disc:
        tool_model = parser.AddModelsFromString(disc_tool_sdf(tool, name, center_frame), "sdf")[0]
    elif (name, center_frame) == ("pad_tool", "pad_center"):
        tool_model = add_model(parser, "pad_tool.sdf")[0]
    else:
        sdf = (models_directory() / "pad_tool.sdf").read_text()
        sdf = sdf.replace('<model name="pad_tool">', f'<model name="{name}">')
        sdf = sdf.replace('<frame name="pad_center"', f'<frame name="{center_frame}"')
        tool_model = parser.AddModelsFromString(sdf, "sdf")[0]
    tool_frame = plant.GetFrameByName("tool", tool_model)
    weld = plant.WeldFrames(wrist_frame, tool_frame, X_wrist_flange)
    geometries = []
    if plant.geometry_source_is_registered():
        geometries = list(plant.GetCollisionGeometriesForBody(plant.GetBodyByName("tool", tool_model)))
    return tool_model, weld, geometries
