"""Robots and tools shared by the tasks: the pad tool and the UR5e arm.

``add_pad_tool`` welds ``models/pad_tool.sdf`` to a wrist frame; that weld
joint is where the wrist force/torque sensor sits. ``add_ur5e`` loads the UR5e
of the ``airo-models`` package (MIT; OBJ meshes load offline) and welds its
base. The controlled point of every task is the pad's centre, frame
``pad_center`` of the tool (its +z is the approach vector a).
"""

import airo_models
import numpy as np

from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser

from drake_hybrid.core.arguments import joint_rows
from drake_hybrid.station.arm import add_pad_tool
from drake_hybrid.station.parsing import ConfigureParser
from drake_hybrid.station.robot_model import RobotModel
from drake_hybrid.station.tools import ToolConfig

# A comfortable UR5e posture (elbow up, tool pointing forward-down), used as IK seed.
UR5E_SEED = np.array([0.0, -1.9, 1.9, -1.6, -1.57, 0.0])


def add_ur5e_with_pad(plant, X_WBase=None, tool=None):
    """The UR5e (airo-models) with its base welded at ``X_WBase`` and the pad tool at tool0: the ball, or
    ``tool`` (a ``station.tools.ToolConfig``, e.g. a disc).

    Returns a RobotModel whose end effector is the pad centre. The arm's own
    collision geometries are listed as ``passive_geometries``: the scenario
    removes their proximity role, so only the pad touches the workpiece (the
    tasks keep the links away from it; see docs).
    """


    parser = Parser(plant)
    ConfigureParser(parser)
    parser.SetAutoRenaming(True)
    arm = parser.AddModels(airo_models.get_urdf_path("ur5e"))[0]
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link", arm),
                     X_WBase if X_WBase is not None else RigidTransform())
    tool = (tool or ToolConfig()).validate()
    tool_instance, weld, pad = add_pad_tool(plant, parser, plant.GetFrameByName("tool0", arm), RigidTransform(),
                                            tool=tool)
    passive = []
    if plant.geometry_source_is_registered():
        for body_index in plant.GetBodyIndices(arm):
            passive += list(plant.GetCollisionGeometriesForBody(plant.get_body(body_index)))
    return RobotModel(arm=arm, model_instances=[arm, tool_instance], end_effector_frame="pad_center",
                      end_effector_point=np.zeros(3), tool_weld=weld, pad_geometries=pad,
                      passive_geometries=passive, tool=tool)


def worst_condition_number(kinematics, plant, positions):
    """max over rows of ``positions`` of cond(J_g) (the geometric Jacobian at the pad centre)."""
    context = plant.CreateDefaultContext()
    worst = 0.0
    for q in joint_rows(positions, "positions", "worst_condition_number", plant):
        plant.SetPositions(context, q)
        J = kinematics.evaluate(context, check=False).spatial_jacobian
        worst = max(worst, float(np.linalg.cond(J)))
    return worst
