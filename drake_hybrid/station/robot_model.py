"""The plant of a task: robot, tool and workpiece in a MultibodyPlant with the pad's contact material.

``build_plant`` adds the simulation plant (``ScenarioConfig.plant``, a Drake
``MultibodyPlantConfig``) to a builder; ``build_controller_plant`` builds the controller's own
model (robot and tool, no workpiece, continuous); ``apply_model_error`` makes the simulated robot
differ from that model (``ModelErrorConfig``).
"""

from dataclasses import dataclass, field
from typing import List, Optional

from pydrake.geometry import GeometryId
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame, ModelInstanceIndex, WeldJoint
from pydrake.systems.framework import DiagramBuilder

from drake_hybrid.core.arguments import describe, instance
from drake_hybrid.core.errors import ArgumentError, ConfigError, UnknownFrameError
from drake_hybrid.core.hints import Array
from drake_hybrid.station.tools import ToolConfig


@dataclass
class RobotModel:
    """What a task's ``add_robot`` added to a plant."""

    arm: ModelInstanceIndex                      # the actuated arm
    model_instances: List[ModelInstanceIndex]    # arm and tool instances
    end_effector_frame: str                      # name of frame E
    end_effector_point: Array                    # p_EP
    tool_weld: Optional[WeldJoint] = None        # wrist -> tool (for the wrist sensor)
    pad_geometries: List[GeometryId] = field(default_factory=list)
    passive_geometries: List[GeometryId] = field(default_factory=list)   # collision geometries to drop (arm links)
    only_pad_contact: bool = False               # filter every contact of the robot but the pad's
    tool: Optional[ToolConfig] = None            # the pad tool mounted (mount_tool's; None: the ball, or unknown)


def frame_names(plant: MultibodyPlant, model_instance: ModelInstanceIndex) -> List[str]:
    """The names of the frames of ``model_instance`` (bodies' frames and the model's own frames)."""
    return sorted({plant.get_frame(index).name() for index in plant.GetFrameIndices(model_instance)})


def get_frame(plant: MultibodyPlant, name: str, model_instance: ModelInstanceIndex, role: str = "frame") -> Frame:
    """Frame ``name`` of ``model_instance``; UnknownFrameError listing the model's frames otherwise."""
    if plant.HasFrameNamed(name, model_instance):
        return plant.GetFrameByName(name, model_instance)
    raise UnknownFrameError(f"{role} '{name}' is not a frame of model '{plant.GetModelInstanceName(model_instance)}'; "
                            f"its frames: {', '.join(frame_names(plant, model_instance))}")


def check_unfinalized_plant(plant: MultibodyPlant, owner: str) -> MultibodyPlant:
    """``plant`` if it is a MultibodyPlant not yet finalized (what adds to a model); typed errors otherwise."""
    instance(plant, "plant", owner, MultibodyPlant)
    if plant.is_finalized():
        raise ConfigError(f"{owner}: the plant is finalized; call {owner} before plant.Finalize()")
    return plant


def check_model_instance(plant: MultibodyPlant, model_instance: ModelInstanceIndex, name: str,
                         owner: str) -> ModelInstanceIndex:
    """``model_instance`` if it is a ModelInstanceIndex of ``plant``; ArgumentError naming ``name`` otherwise."""
    if not isinstance(model_instance, ModelInstanceIndex):
        raise ArgumentError(f"{owner}: {name} must be a ModelInstanceIndex of the plant (e.g. "
                            f"Parser(plant).AddModels(...)[0]), got {describe(model_instance)}")
    if not int(model_instance) < plant.num_model_instances():
        raise ArgumentError(f"{owner}: {name} {int(model_instance)} is not a model instance of the plant (it has "
                            f"{plant.num_model_instances()})")
    return model_instance


def arm_model_name(plant: MultibodyPlant, robot: RobotModel) -> str:
    return plant.GetModelInstanceName(robot.arm)


def check_station_parts(builder: DiagramBuilder, plant: MultibodyPlant, robot: RobotModel, owner: str) -> None:
    instance(builder, "builder", owner, DiagramBuilder)
    check_finalized_robot_plant(plant, robot, owner)


def check_finalized_robot_plant(plant: MultibodyPlant, robot: RobotModel, owner: str) -> None:
    instance(plant, "plant", owner, MultibodyPlant)
    instance(robot, "robot", owner, RobotModel, what="the RobotModel of mount_tool")
    if not plant.is_finalized():
        raise ConfigError(f"{owner}: finalize the plant first (plant.Finalize())")
    check_model_instance(plant, robot.arm, "robot.arm", owner)
    check_arm_moves_end_effector(plant, robot, owner)


def check_arm_moves_end_effector(plant: MultibodyPlant, robot: RobotModel, owner: str) -> None:
    """ArgumentError if no joint of ``robot.arm`` moves the body of ``robot.end_effector_frame`` in the finalized
    ``plant`` (a tool mounted on the arm's base, welded to the world): the law could not move the pad. A frame
    the plant does not have (or has in several models) is left to the checks that name it."""
    name = robot.end_effector_frame
    if not isinstance(name, str) or not plant.HasFrameNamed(name):
        return
    try:
        body = plant.GetFrameByName(name).body()
    except RuntimeError:                       # the name in several models: the frame's own checks name it
        return
    joints = [index for index in plant.GetJointIndices(robot.arm) if plant.get_joint(index).num_velocities() > 0]
    if not joints or body.index() not in plant.GetBodiesKinematicallyAffectedBy(joints):
        raise ArgumentError(f"{owner}: no joint of the arm '{plant.GetModelInstanceName(robot.arm)}' moves the "
                            f"end-effector frame '{name}' (on body '{body.name()}'): the tool is mounted on a part "
                            "that is welded to the world (the arm's base?); mount_tool it on the frame at the end of "
                            "the arm (its flange, e.g. 'tool0')")
