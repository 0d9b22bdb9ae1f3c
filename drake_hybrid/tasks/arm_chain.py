"""The arm in the plant made fit for the hybrid law (``fix_arm``, the second stage of
``tasks.robots.load_arm``, run each time the model is parsed, before ``Finalize``):

* the base is welded to the world at ``base_pose`` (a floating base, a floating or planar joint to the
  world, or a weld of the model's own);
* every joint that is not on the chain from the base to the flange (gripper fingers) is welded at
  its zero position, and multi-dof joints on the chain too (the law needs one actuator per joint
  and nq = nv);
* each chain joint gets an actuator with the model file's effort limit (Drake keeps a URDF's
  effort limits only for joints with a ``<transmission>``).

Unknown frames raise ``UnknownFrameError`` listing the model's frames.
"""

import numpy as np

from pydrake.math import RigidTransform

from drake_hybrid.core.errors import ConfigError
from drake_hybrid.station.robot_model import get_frame


def _inboard_joints(plant, model_instance):
    """{child body index: joint} for the joints of ``model_instance``."""
    return {plant.get_joint(index).child_body().index(): plant.get_joint(index)
            for index in plant.GetJointIndices(model_instance)}


def _chain(plant, body, inboard):
    """The joints from the world (or a free root) to ``body``, base first."""
    joints = []
    while body.index() in inboard:
        joint = inboard[body.index()]
        joints.append(joint)
        body = joint.parent_body()
    return joints[::-1], body


def _weld(plant, joint, X_PC=None):
    """Replace ``joint`` by a weld (at its zero position, or ``X_PC`` between the bodies' frames)."""
    for index in plant.GetJointActuatorIndices():
        if plant.get_joint_actuator(index).joint().index() == joint.index():
            plant.RemoveJointActuator(plant.get_joint_actuator(index))
    parent, child = joint.frame_on_parent(), joint.frame_on_child()
    plant.RemoveJoint(joint)
    if X_PC is None:
        return plant.WeldFrames(parent, child, RigidTransform())
    return plant.WeldFrames(parent.body().body_frame(), child.body().body_frame(), X_PC)


def fix_arm(plant, model_instance, flange, tool_frame, base_pose, effort_limits, report=None):
    """Weld the base at ``base_pose`` and every joint off the base-to-flange chain, add the chain's
    actuators; returns (flange frame, tool frame). ``report`` (a LoadReport) gets the changes."""
    note = (lambda line: report.changes.append(line)) if report is not None else (lambda line: None)
    flange_frame = get_frame(plant, flange, model_instance, "flange")
    tool = get_frame(plant, tool_frame, model_instance, "tool_frame")
    inboard = _inboard_joints(plant, model_instance)
    chain, root = _chain(plant, flange_frame.body(), inboard)
    tool_chain, _ = _chain(plant, tool.body(), inboard)
    if not set(j.index() for j in chain) <= set(j.index() for j in tool_chain):
        raise ConfigError(f"tool_frame '{tool_frame}' is not carried by the flange '{flange}' (it is on body "
                          f"'{tool.body().name()}', not downstream of '{flange_frame.body().name()}')")
    world = plant.world_body()
    X_WB = base_pose if base_pose is not None else RigidTransform()
    # The base: the first chain joint from the world that is not a one-dof joint, or a free root.
    if root.index() != world.index():
        plant.WeldFrames(plant.world_frame(), root.body_frame(), X_WB)
        note(f"floating base '{root.name()}': welded to the world at base_pose")
        base = root
    else:
        first = chain[0]
        base = first.child_body()
        if first.num_velocities() == 1:
            base = first.parent_body()                 # the model's own world link holds a one-dof joint
            if base_pose is not None:
                note(f"base_pose not applied: the model attaches its first joint '{first.name()}' to the world itself")
        else:
            kind = first.type_name()
            # The model's own weld to the world, kept under base_pose: X_W_child = X_WB X_WF X_FM X_CM^-1.
            X_PC = X_WB if kind != "weld" else X_WB.multiply(
                first.frame_on_parent().GetFixedPoseInBodyFrame().multiply(first.X_FM()).multiply(
                    first.frame_on_child().GetFixedPoseInBodyFrame().inverse()))
            _weld(plant, first, X_PC)
            chain = chain[1:]
            note(f"base '{base.name()}': its {kind} joint '{first.name()}' to the world replaced by a weld at "
                 "base_pose" + (" (times the model's own weld)" if kind == "weld" else ""))
    if report is not None:
        report.base = base.name()
    on_chain = {joint.index() for joint in chain}
    welded = []
    movable = [plant.get_joint(index) for index in plant.GetJointIndices(model_instance)
               if plant.get_joint(index).num_velocities() > 0]
    if any(joint.index() not in on_chain or joint.num_velocities() != 1 for joint in movable):
        for constraint_id in plant.GetConstraintIds():  # couplers (<mimic>) block RemoveJoint
            plant.RemoveConstraint(constraint_id)
    for joint in movable:
        if joint.index() not in on_chain or joint.num_velocities() != 1:
            welded.append(f"{joint.name()} ({joint.type_name()})")
            _weld(plant, joint)
    if welded:
        note(f"welded {len(welded)} joints off the chain to '{flange}' (or not one-dof) at zero: {', '.join(welded)}")
        if report is not None:
            report.welded_joints = welded
    arm_joints = [joint for joint in chain if joint.num_velocities() == 1]
    # (GetJointActuatorIndices(model_instance) is empty before Finalize: filter all of them.)
    actuated = {int(plant.get_joint_actuator(index).joint().index()): plant.get_joint_actuator(index)
                for index in plant.GetJointActuatorIndices()
                if plant.get_joint_actuator(index).model_instance() == model_instance}
    added, unlimited = [], []
    for joint in arm_joints:
        limit = float(effort_limits.get(joint.name(), np.inf))
        if not limit > 0:
            limit = np.inf
        if int(joint.index()) in actuated:
            actuator = actuated[int(joint.index())]
            if not np.isfinite(actuator.effort_limit()) and np.isfinite(limit):
                actuator.set_effort_limit(limit)
        else:
            actuator = plant.AddJointActuator(f"{joint.name()}_actuator", joint, limit)
            added.append(joint.name())
        if not np.isfinite(actuator.effort_limit()):
            unlimited.append(joint.name())
        if report is not None:
            report.effort_limits[joint.name()] = float(actuator.effort_limit())
    if added:
        note(f"added actuators to {len(added)} joints without a transmission, effort limits from the model file")
    kept = len(arm_joints) - len(added)
    if kept:
        note(f"kept the model's actuators (transmissions) of {kept} joints")
    if unlimited:
        note(f"no effort limit in the model for {', '.join(unlimited)}: unlimited")
    damped = [f"{joint.name()} {joint.default_damping():g}" for joint in arm_joints if joint.default_damping() > 0]
    if damped:
        note(f"kept the model's joint damping (N m s/rad): {', '.join(damped)}")
    if report is not None:
        report.arm_joints = [joint.name() for joint in arm_joints]
    return flange_frame, tool
