"""A wrist force/torque sensor in the weld joint between the wrist and the tool.

The joint's reaction force (on the tool, from the wrist) is what the sensor measures; subtracting
it from zero and removing the tool's weight gives the contact wrench at the end-effector point P, in
world (the sign convention of ``systems.wrench_frames``): static compensation, the tool's inertia
neglected unless ``compensate_tool_inertia`` removes it too. A TemplateSystem (float and
AutoDiffXd), so closed loops linearize.
"""

import sys

import numpy as np

from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.cpp_param import List
from pydrake.common.value import Value
from pydrake.math import RigidTransform_
from pydrake.multibody.math import SpatialAcceleration_, SpatialForce_, SpatialVelocity_
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_hybrid.core.kinematics import resolve_frame
from drake_hybrid.core.templates import default_instantiation
from drake_hybrid.systems.wrench_frames import _point, _point_in_world, _point_in_world_floats, _shift


def reaction_force_slot(plant, joint):
    """Where ``joint``'s entry is in the plant's reaction-forces output: its place among the plant's
    joints (GetJointIndices order). Not its JointIndex: after RemoveJoint (welded gripper fingers)
    the indices have gaps but the output has num_joints() entries."""
    return [int(index) for index in plant.GetJointIndices()].index(int(joint.index()))


@TemplateSystem.define("WristForceTorqueSensor_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def WristForceTorqueSensor_(T):

    class Impl(LeafSystem_[T]):
        """Wrist force/torque sensor in the weld joint between wrist and tool.

        .. pydrake_system::

            name: WristForceTorqueSensor
            input_ports:
            - reaction_forces
            - body_poses
            output_ports:
            - wrench

        The plant's reaction force of the weld joint J is F_CJc_Jc, the force
        on the child (tool) at the joint's child frame, expressed there. For a
        tool of mass m_t at rest, F_contact + F_CJc + m_t g = 0, so

            wrench = -(F_CJc shifted to P) - (m_t g at the tool's centre of mass, shifted to P)

        in world. During motion the tool's own inertia (m_t a) remains in the
        reading; for the light tools here it is far below the contact forces.
        Use it on a discrete plant. On a continuous plant the weld's reaction
        depends on the accelerations the controller's torque causes (an algebraic
        loop through the wrench filter), so its reading at a start is not the
        contact's rest wrench and the start cannot be put at rest, with strict
        hydroelastic or with ``contact_model="hydroelastic_with_fallback"``
        (measured on a Kinova Jaco pressing 10 N: the filter primed to 11.94 N,
        the sensor then reading 11.46 N; primed to its own fixed point, 11.54 N,
        max |x-dot| still 12.3; with the fallback model max |x-dot| 565).
        ``station.contact_start.solve_contact_start`` refuses that combination:
        give a continuous twin (for ``linearize_at_contact``) the contact sensor.

        With ``compensate_tool_inertia`` the sensor also removes the tool's inertial
        wrench, its spatial momentum rate from the tool's model (mass, centre of mass, rotational
        inertia) and the plant's body velocities and accelerations (two more input ports,
        ``body_spatial_velocities`` and ``body_spatial_accelerations``)::

            wrench += [I_W alpha + omega x I_W omega; m_t a_com]   (at the centre of mass, shifted to P)

        so it reports the contact wrench during motion too (the tool is exactly the model's here).

        Args:
            plant: simulation plant (float, finalized).
            weld_joint: the WeldJoint between wrist (parent) and tool (child).
            end_effector_frame, end_effector_point: P, as for the controller.
            compensate_tool_inertia: remove the tool's inertial wrench too (default False: static
                compensation, the tool's weight only).
        """

        def _construct(self, plant, weld_joint, end_effector_frame, end_effector_point, compensate_tool_inertia=False,
                       converter=None):
            LeafSystem_[T].__init__(self, converter)
            if type(weld_joint).__name__ != "WeldJoint" or weld_joint.GetParentPlant() is not plant:
                raise ValueError(f"WristForceTorqueSensor: weld_joint must be a WeldJoint of the plant, got "
                                 f"{type(weld_joint).__name__}")
            self._plant = plant
            self._weld_joint = weld_joint
            self._joint_index = reaction_force_slot(plant, weld_joint)
            tool = weld_joint.child_body()
            self._tool_index = tool.index()
            self._child_frame = weld_joint.frame_on_child()
            self._X_tool_Jc = self._child_frame.GetFixedPoseInBodyFrame()
            self._tool_mass = tool.default_mass()
            self._tool_com = tool.default_com()
            self._gravity = plant.gravity_field().gravity_vector()
            self._R_tool_Jc = self._X_tool_Jc.rotation().matrix()
            self._p_tool_Jc_and_com = np.column_stack([self._X_tool_Jc.translation(), self._tool_com])
            self._weight = (self._tool_mass * np.asarray(self._gravity, dtype=float)).tolist()
            frame = resolve_frame(plant, end_effector_frame)
            self._frame = frame
            self._end_effector_point = _point(end_effector_point, "WristForceTorqueSensor")
            self._body_index = frame.body().index()
            self._point_in_body = frame.GetFixedPoseInBodyFrame().multiply(self._end_effector_point)
            self._body_slot, self._tool_slot = int(self._body_index), int(self._tool_index)
            self._point_in_body_list = self._point_in_body.tolist()
            self._reactions_port = self.DeclareAbstractInputPort("reaction_forces", Value[List[SpatialForce_[T]]]([]))
            self._poses_port = self.DeclareAbstractInputPort("body_poses", Value[List[RigidTransform_[T]]]([]))
            # The tool's inertial wrench, from its model (off: the paper's static compensation).
            self.compensate_tool_inertia = bool(compensate_tool_inertia)
            if self.compensate_tool_inertia:
                self._tool_inertia_B = tool.default_rotational_inertia().CopyToFullMatrix3()   # about Bo, in B
                self._velocities_port = self.DeclareAbstractInputPort("body_spatial_velocities",
                                                                      Value[List[SpatialVelocity_[T]]]([]))
                self._accelerations_port = self.DeclareAbstractInputPort("body_spatial_accelerations",
                                                                         Value[List[SpatialAcceleration_[T]]]([]))
            # A function of the inputs only (not of time): a logger at the next instant reuses the value.
            fast = T == float and not self.compensate_tool_inertia
            self.DeclareVectorOutputPort("wrench", 6, self._calc_wrench_float if fast else self._calc_wrench,
                                         prerequisites_of_calc={self.all_input_ports_ticket()})

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other._plant, other._weld_joint, other._frame, other._end_effector_point,
                            other.compensate_tool_inertia, converter=converter)

        def _tool_momentum_rate(self, context, R_W_tool, p_Wcom):
            """The tool's spatial momentum rate [torque about the centre of mass; m a_com] in world."""
            V = self._velocities_port.Eval(context)[int(self._tool_index)]
            A = self._accelerations_port.Eval(context)[int(self._tool_index)]
            omega, alpha, a_Bo = V.rotational(), A.rotational(), A.translational()
            p_BoCm_W = R_W_tool @ self._tool_com
            a_com = a_Bo + np.cross(alpha, p_BoCm_W) + np.cross(omega, np.cross(omega, p_BoCm_W))
            # Rotational inertia about the centre of mass (parallel-axis theorem), in world.
            c = self._tool_com
            I_com_B = self._tool_inertia_B - self._tool_mass * (np.dot(c, c) * np.eye(3) - np.outer(c, c))
            I_com_W = R_W_tool @ I_com_B @ R_W_tool.T
            torque = I_com_W @ alpha + np.cross(omega, I_com_W @ omega)
            return np.concatenate([torque, self._tool_mass * a_com])

        def tool_mass(self):
            return self._tool_mass

        def _calc_wrench(self, context, output):
            reaction = self.get_input_port(0).Eval(context)[self._joint_index]
            body_poses = self.get_input_port(1).Eval(context)
            X_W_tool = body_poses[int(self._tool_index)]
            R_W_tool = X_W_tool.rotation().matrix()
            p_WP = _point_in_world(body_poses, self._body_index, self._point_in_body)
            R_WJc = R_W_tool @ self._X_tool_Jc.rotation().matrix()
            p_WJc = X_W_tool.translation() + R_W_tool @ self._X_tool_Jc.translation()
            coefficients = reaction.get_coeffs()
            on_tool_from_wrist = np.concatenate([R_WJc @ coefficients[:3], R_WJc @ coefficients[3:]])
            p_Wcom = X_W_tool.translation() + R_W_tool @ self._tool_com
            weight = np.concatenate([np.zeros(3), self._tool_mass * self._gravity])
            wrench = -_shift(on_tool_from_wrist, p_WP - p_WJc) - _shift(weight, p_WP - p_Wcom)
            if self.compensate_tool_inertia:
                wrench = wrench + _shift(self._tool_momentum_rate(context, R_W_tool, p_Wcom), p_WP - p_Wcom)
            output.SetFromVector(wrench)

        def _calc_wrench_float(self, context, output):
            """``_calc_wrench`` (static compensation) for T = float with one 3 x 3 product and the rest in
            plain Python floats: wrench = -[R_WJc n + (p_WJc - p_WP) x R_WJc f; R_WJc f]
            - [(p_Wcom - p_WP) x m g; m g]."""
            coefficients = self._reactions_port.Eval(context)[self._joint_index].get_coeffs()
            body_poses = self._poses_port.Eval(context)
            X_W_tool = body_poses[self._tool_slot]
            R_W_tool = X_W_tool.rotation().matrix()
            R_WJc = R_W_tool @ self._R_tool_Jc
            (n0, f0), (n1, f1), (n2, f2) = (R_WJc @ coefficients.reshape(2, 3).T).tolist()
            t0, t1, t2 = X_W_tool.translation().tolist()
            j0, j1, j2 = (R_W_tool @ self._p_tool_Jc_and_com).tolist()    # columns p_tool_Jc, p_tool_com
            p0, p1, p2 = _point_in_world_floats(body_poses[self._body_slot], self._point_in_body_list)
            a0, a1, a2 = t0 + j0[0] - p0, t1 + j1[0] - p1, t2 + j2[0] - p2    # p_WJc - p_WP
            c0, c1, c2 = t0 + j0[1] - p0, t1 + j1[1] - p1, t2 + j2[1] - p2    # p_Wcom - p_WP
            w0, w1, w2 = self._weight
            output.SetFromVector([-(n0 + a1 * f2 - a2 * f1) - (c1 * w2 - c2 * w1),
                                  -(n1 + a2 * f0 - a0 * f2) - (c2 * w0 - c0 * w2),
                                  -(n2 + a0 * f1 - a1 * f0) - (c0 * w1 - c1 * w0),
                                  -f0 - w0, -f1 - w1, -f2 - w2])

    return Impl


WristForceTorqueSensor = default_instantiation(WristForceTorqueSensor_)
