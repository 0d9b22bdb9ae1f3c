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
from drake_hybrid.scenario.parsing import ConfigureParser, add_model, models_directory
from drake_hybrid.scenario.plant import RobotModel

PAD_RADIUS = 0.02            # m, the pad sphere of models/pad_tool.sdf
PAD_CENTER_IN_TOOL = 0.05    # m along the tool's +z axis (frame "pad_center")

# A comfortable UR5e posture (elbow up, tool pointing forward-down), used as IK seed.
UR5E_SEED = np.array([0.0, -1.9, 1.9, -1.6, -1.57, 0.0])


def add_pad_tool(plant, parser, wrist_frame, X_wrist_flange, name="pad_tool", center_frame="pad_center"):
    """Parse the pad tool as model ``name`` with its pad centre frame called ``center_frame`` (the
    model's own names by default; others let a plant hold several tools) and weld its flange to
    ``wrist_frame``. Returns (instance, weld, pad geometries)."""
    if (name, center_frame) == ("pad_tool", "pad_center"):
        tool = add_model(parser, "pad_tool.sdf")[0]
    else:
        sdf = (models_directory() / "pad_tool.sdf").read_text()
        sdf = sdf.replace('<model name="pad_tool">', f'<model name="{name}">')
        sdf = sdf.replace('<frame name="pad_center"', f'<frame name="{center_frame}"')
        tool = parser.AddModelsFromString(sdf, "sdf")[0]
    tool_frame = plant.GetFrameByName("tool", tool)
    weld = plant.WeldFrames(wrist_frame, tool_frame, X_wrist_flange)
    geometries = []
    if plant.geometry_source_is_registered():
        geometries = list(plant.GetCollisionGeometriesForBody(plant.GetBodyByName("tool", tool)))
    return tool, weld, geometries


def add_ur5e_with_pad(plant, X_WBase=None):
    """The UR5e (airo-models) with its base welded at ``X_WBase`` and the pad tool at tool0.

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
    tool, weld, pad = add_pad_tool(plant, parser, plant.GetFrameByName("tool0", arm), RigidTransform())
    passive = []
    if plant.geometry_source_is_registered():
        for body_index in plant.GetBodyIndices(arm):
            passive += list(plant.GetCollisionGeometriesForBody(plant.get_body(body_index)))
    return RobotModel(arm=arm, model_instances=[arm, tool], end_effector_frame="pad_center",
                      end_effector_point=np.zeros(3), tool_weld=weld, pad_geometries=pad,
                      passive_geometries=passive)


def worst_condition_number(kinematics, plant, positions):
    """max over rows of ``positions`` of cond(J_g) (the geometric Jacobian at the pad centre)."""
    context = plant.CreateDefaultContext()
    worst = 0.0
    for q in joint_rows(positions, "positions", "worst_condition_number", plant):
        plant.SetPositions(context, q)
        J = kinematics.evaluate(context, check=False).spatial_jacobian
        worst = max(worst, float(np.linalg.cond(J)))
    return worst
