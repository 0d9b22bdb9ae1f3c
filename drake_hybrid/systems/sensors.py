"""Wrench sensing for the controller's ``measured_wrench`` input.

All sensors output the SpatialForce [n; f] (6-vector) exerted **on the robot
by the environment**, at the end-effector point P, expressed in the world
frame: the sign convention of docs/theory.md §0.

``ContactWrenchSensor``
    ideal: sums the contact results on the robot's bodies and shifts them to P.
``WristForceTorqueSensor``
    a force/torque sensor in a weld joint between the wrist and the tool: the
    joint's reaction force (on the tool, from the wrist) is what the sensor
    measures; subtracting it from zero and removing the tool's weight gives
    the contact wrench (static compensation: tool inertia is neglected).
``LowPassFilter``
    first-order low-pass with a bandwidth in Hz, continuous or sampled. On a
    continuous plant, the contact results are direct feedthrough of the
    actuation, so plant -> sensor -> controller -> plant is an algebraic loop;
    a filter breaks it (see docs/drake_notes.md).
``WrenchConditioner``
    what a real sensor needs before the controller: dropout (NaN) and
    stale-sample rejection with a bounded hold, a tare against a constant bias,
    and the same low-pass, sampled at the control period.

All are TemplateSystems (float and AutoDiffXd) so closed loops linearize.

Size: the four wrench systems share the sign convention, the shift to the end-effector point
and the sampling; each is a TemplateSystem of about 100 lines.
"""

import math
import sys

import numpy as np

from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.cpp_param import List
from pydrake.common.value import AbstractValue, Value
from pydrake.math import RigidTransform_
from pydrake.multibody.math import SpatialAcceleration_, SpatialForce_, SpatialVelocity_
from pydrake.multibody.plant import ContactResults_
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.sampling import SAMPLE_LEAD
from drake_hybrid.core.arguments import boolean, nonnegative, number, positive, vector
from drake_hybrid.core.errors import DimensionError
from drake_hybrid.core.kinematics import resolve_frame
from drake_hybrid.core.linalg import all_finite, value
from drake_hybrid.core.templates import default_instantiation


def sampled_reading_age(plant):
    """How old a reading of ``plant``'s contact results or reaction forces is when a sensor uses it: one
    step h on a discrete plant with sampled output ports (the last step's solve, made at the
    configuration q_k before it, while the arm is at q_k+1 now), 0 otherwise. The law splits the
    wrench where it was exerted (``HybridController``'s ``wrench_lag``)."""
    return plant.time_step() if plant.time_step() > 0 and plant.has_sampled_output_ports() else 0.0


def _robot_geometry_ids(plant, robot_bodies):
    ids = set()
    for body in robot_bodies:
        ids.update(plant.GetCollisionGeometriesForBody(body))
    return ids


def _point_in_world(body_poses, body_index, point_in_body):
    X_WB = body_poses[int(body_index)]
    return X_WB.translation() + X_WB.rotation().matrix() @ point_in_body


def reaction_force_slot(plant, joint):
    """Where ``joint``'s entry is in the plant's reaction-forces output: its place among the plant's
    joints (GetJointIndices order). Not its JointIndex: after RemoveJoint (welded gripper fingers)
    the indices have gaps but the output has num_joints() entries."""
    return [int(index) for index in plant.GetJointIndices()].index(int(joint.index()))


def _point_in_world_floats(X_WB, point_in_body):
    """p_WP = X_WB p_BP for T = float, as a list of three floats: RigidTransform.multiply's numpy
    wrapper costs three times this arithmetic on a 3-vector (the sensors run it every step)."""
    (r00, r01, r02, t0), (r10, r11, r12, t1), (r20, r21, r22, t2) = X_WB.GetAsMatrix34().tolist()
    a, b, c = point_in_body
    return [t0 + r00 * a + r01 * b + r02 * c, t1 + r10 * a + r11 * b + r12 * c, t2 + r20 * a + r21 * b + r22 * c]


def _point(point, owner):
    return vector(point, "end_effector_point", owner, 3, unit="m", error=DimensionError)


def _shift(F_coefficients, p_from_to_W):
    """Shift a spatial force [n; f] applied at point A to point B (p_from_to = p_AB): n_B = n_A - p_AB x f."""
    n, f, p = F_coefficients[:3], F_coefficients[3:], p_from_to_W
    # p x f written out: np.cross costs ~15 us on 3-vectors in numpy 2 (benchmarks/PROFILE.md)
    return np.array([n[0] - (p[1] * f[2] - p[2] * f[1]),
                     n[1] - (p[2] * f[0] - p[0] * f[2]),
                     n[2] - (p[0] * f[1] - p[1] * f[0]),
                     f[0], f[1], f[2]])


@TemplateSystem.define("ContactWrenchSensor_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def ContactWrenchSensor_(T):

    class Impl(LeafSystem_[T]):
        """Ideal contact-wrench sensor: the environment's wrench on the robot at P.

        .. pydrake_system::

            name: ContactWrenchSensor
            input_ports:
            - contact_results
            - body_poses
            output_ports:
            - wrench

        Sums, over hydroelastic and point contacts between a robot body and a
        non-robot body, the spatial force on the robot body, shifted from the
        contact point (centroid) to P, in world.

        On a discrete plant with sampled output ports (Drake's default,
        ``plant.has_sampled_output_ports()``) the contact results are those of
        the plant's last step, solved at the configuration q_k before it, while
        ``body_poses`` is the current q_{k+1}. The sensor then keeps p_WP(q_k)
        in its state (an unrestricted update at the plant's steps, which reads
        the same q_k as the plant's step) and shifts the step's forces to that
        point: the reading is the wrench the step applied, about P where P was,
        one step old, with no false moment |f| |v| h from a lever arm taken
        across the step (docs/drake_notes.md). With unsampled ports the results
        are those of the step about to be taken (a second contact solve per step
        when the controller reads them at another instant than the plant steps)
        and the current pose is used.

        Args:
            plant: the simulation plant (float, finalized, with a SceneGraph).
            robot_bodies: the bodies that count as "the robot" (e.g. all bodies
                of the arm and tool model instances).
            end_effector_frame: frame E of ``plant`` (or its name) holding P.
            end_effector_point: p_EP (m).
        """

        def _construct(self, plant, robot_bodies, end_effector_frame, end_effector_point, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._plant = plant
            self._robot_bodies = list(robot_bodies)
            if not self._robot_bodies:
                raise ValueError("ContactWrenchSensor: robot_bodies is empty; give the bodies of the arm and tool")
            if not plant.geometry_source_is_registered():
                raise ValueError("ContactWrenchSensor: the plant has no SceneGraph (no contact results)")
            self._robot_body_indices = {int(b.index()) for b in self._robot_bodies}
            self._robot_geometries = _robot_geometry_ids(plant, self._robot_bodies)
            frame = resolve_frame(plant, end_effector_frame)
            self._frame = frame
            self._end_effector_point = _point(end_effector_point, "ContactWrenchSensor")
            self._body_index = frame.body().index()
            self._body_slot = int(self._body_index)
            self._point_in_body = frame.GetFixedPoseInBodyFrame().multiply(self._end_effector_point)
            self._point_in_body_list = self._point_in_body.tolist()
            self._robot_geometry_values = {geometry.get_value() for geometry in self._robot_geometries}
            self._results_port = self.DeclareAbstractInputPort("contact_results",
                                                               AbstractValue.Make(ContactResults_[T]()))
            self._poses_port = self.DeclareAbstractInputPort("body_poses", Value[List[RigidTransform_[T]]]([]))
            prerequisites = {self.all_input_ports_ticket()}
            # Sampled contact results: P where the step that computed them found it (class docstring).
            self.samples_point = plant.time_step() > 0 and plant.has_sampled_output_ports()
            if self.samples_point:
                # NaN until the first step: the results then come from the start (scenario.start), P is current.
                self._point_state = self.DeclareDiscreteState(np.full(3, np.nan))
                self.DeclarePeriodicUnrestrictedUpdateEvent(plant.time_step(), 0.0, self._sample_point)
                prerequisites.add(self.xd_ticket())
            # A function of the inputs (and the sampled P), not of time: a logger at the next instant reuses it.
            self.DeclareVectorOutputPort("wrench", 6, self._calc_wrench_float if T == float else self._calc_wrench,
                                         prerequisites_of_calc=prerequisites)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other._plant, other._robot_bodies, other._frame, other._end_effector_point,
                            converter=converter)

        def _current_point(self, context):
            if T == float:
                return _point_in_world_floats(self._poses_port.Eval(context)[self._body_slot], self._point_in_body_list)
            return _point_in_world(self._poses_port.Eval(context), self._body_index, self._point_in_body)

        def _sample_point(self, context, state):
            """At the plant's step: P at the configuration the step solves the contact at."""
            state.get_mutable_discrete_state(self._point_state).SetFromVector(self._current_point(context))

        def set_sampled_point(self, context):
            """Take P's position for the contact results the plant holds now (``scenario.start`` after it
            primed the plant at the start, before the first step; until then, or if this is never called,
            the sensor shifts to the current P)."""
            if self.samples_point:
                context.get_mutable_discrete_state(self._point_state).SetFromVector(
                    value(self._current_point(context)))

        def _contact_point(self, context):
            """p_WP the contact results are shifted to: sampled with them, else current."""
            if self.samples_point:
                sampled = context.get_discrete_state(self._point_state).value()
                if all_finite(sampled):
                    return sampled
            return np.asarray(self._current_point(context))

        def _calc_wrench(self, context, output):
            results = self.get_input_port(0).Eval(context)
            p_WP = self._contact_point(context)
            total = np.zeros(6, dtype=p_WP.dtype)
            for i in range(results.num_hydroelastic_contacts()):
                info = results.hydroelastic_contact_info(i)
                surface = info.contact_surface()
                on_M = surface.id_M() in self._robot_geometries
                on_N = surface.id_N() in self._robot_geometries
                if on_M == on_N:
                    continue
                # F_Ac_W: on the body of geometry M, at the centroid; the other body gets its negative.
                F = info.F_Ac_W().get_coeffs() * (1.0 if on_M else -1.0)
                total = total + _shift(F, p_WP - surface.centroid())
            for i in range(results.num_point_pair_contacts()):
                info = results.point_pair_contact_info(i)
                on_A = int(info.bodyA_index()) in self._robot_body_indices
                on_B = int(info.bodyB_index()) in self._robot_body_indices
                if on_A == on_B:
                    continue
                # F_Bc_W: on body B at the contact point; body A gets its negative.
                F = info.contact_force() * (1.0 if on_B else -1.0)
                total = total + _shift(np.concatenate([np.zeros(3), F]), p_WP - info.contact_point())
            output.SetFromVector(total)

        def _calc_wrench_float(self, context, output):
            """``_calc_wrench`` for T = float in plain Python floats (a numpy call on a 3-vector costs more
            than its arithmetic): the forces f_i and moments about the world origin n_i + c_i x f_i
            summed, then moved to P once, n_P = sum(n_i + c_i x f_i) - p_WP x sum f_i."""
            results = self._results_port.Eval(context)
            n0 = n1 = n2 = f0 = f1 = f2 = 0.0
            robot = self._robot_geometry_values
            for i in range(results.num_hydroelastic_contacts()):
                info = results.hydroelastic_contact_info(i)
                surface = info.contact_surface()
                on_M = surface.id_M().get_value() in robot
                if on_M == (surface.id_N().get_value() in robot):
                    continue
                # F_Ac_W: on the body of geometry M, at the centroid; the other body gets its negative.
                a0, a1, a2, b0, b1, b2 = info.F_Ac_W().get_coeffs().tolist()
                if not on_M:
                    a0, a1, a2, b0, b1, b2 = -a0, -a1, -a2, -b0, -b1, -b2
                c0, c1, c2 = surface.centroid().tolist()
                n0 += a0 + c1 * b2 - c2 * b1
                n1 += a1 + c2 * b0 - c0 * b2
                n2 += a2 + c0 * b1 - c1 * b0
                f0, f1, f2 = f0 + b0, f1 + b1, f2 + b2
            for i in range(results.num_point_pair_contacts()):
                info = results.point_pair_contact_info(i)
                on_A = int(info.bodyA_index()) in self._robot_body_indices
                on_B = int(info.bodyB_index()) in self._robot_body_indices
                if on_A == on_B:
                    continue
                # F_Bc_W: on body B at the contact point; body A gets its negative.
                b0, b1, b2 = info.contact_force().tolist()
                if not on_B:
                    b0, b1, b2 = -b0, -b1, -b2
                c0, c1, c2 = info.contact_point().tolist()
                n0 += c1 * b2 - c2 * b1
                n1 += c2 * b0 - c0 * b2
                n2 += c0 * b1 - c1 * b0
                f0, f1, f2 = f0 + b0, f1 + b1, f2 + b2
            p0 = math.nan
            if self.samples_point:
                p0, p1, p2 = context.get_discrete_state(self._point_state).value().tolist()
            if p0 != p0:                        # no sampled point (not sampling, or before the first step)
                p0, p1, p2 = self._current_point(context)
            output.SetFromVector([n0 - (p1 * f2 - p2 * f1), n1 - (p2 * f0 - p0 * f2), n2 - (p0 * f1 - p1 * f0),
                                  f0, f1, f2])

    return Impl


ContactWrenchSensor = default_instantiation(ContactWrenchSensor_)


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

        With ``compensate_tool_inertia`` (issue 18) the sensor also removes the tool's inertial
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
            # Issue 18: the tool's inertial wrench, from its model (off: the paper's static compensation).
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


MAX_FILTER_SIZE = 10_000      # entries a LowPassFilter filters (a wrench has 6)


def low_pass_coefficient(bandwidth_hz, period):
    """alpha = 1 - exp(-2 pi f_c h): the exact discretization of y-dot = 2 pi f_c (u - y) for a held
    input (1 when bandwidth_hz is 0: no filtering)."""
    if not bandwidth_hz > 0:
        return 1.0
    return 1.0 - math.exp(-2 * math.pi * bandwidth_hz * period)


def low_pass_lag(bandwidth_hz, period):
    """T (s): how far a first-order low-pass's output trails a ramp input, 1 / (2 pi f_c)
    continuous (``period`` None or 0), h (1 - alpha) / alpha sampled (``low_pass_coefficient``);
    0 without a filter (bandwidth_hz 0)."""
    if not bandwidth_hz > 0:
        return 0.0
    if not period:
        return 1.0 / (2 * math.pi * bandwidth_hz)
    alpha = low_pass_coefficient(bandwidth_hz, period)
    return period * (1.0 - alpha) / alpha


@TemplateSystem.define("LowPassFilter_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def LowPassFilter_(T):

    class Impl(LeafSystem_[T]):
        """First-order low-pass y-dot = 2 pi f_c (u - y), continuous or sampled exactly.

        .. pydrake_system::

            name: LowPassFilter
            input_ports:
            - u
            output_ports:
            - y

        The output is the state (no direct feedthrough). With ``period`` h the
        update is y+ = y + (1 - exp(-2 pi f_c h)) (u - y), the exact
        discretization for a held input. Set the initial state with
        ``set_initial_output``.
        """

        def _construct(self, size, bandwidth_hz, period=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            size = number(size, "size", "LowPassFilter", low=1, high=MAX_FILTER_SIZE, integer=True)
            bandwidth_hz = positive(bandwidth_hz, "bandwidth_hz", "LowPassFilter", unit="Hz")
            period = positive(period, "period", "LowPassFilter", unit="s", allow_none=True)
            self._size, self.bandwidth_hz, self.period = size, bandwidth_hz, period
            self._rate = 2 * math.pi * self.bandwidth_hz
            self.DeclareVectorInputPort("u", size)
            if period is None:
                state = self.DeclareContinuousState(size)
                self.DeclareStateOutputPort("y", state)
            else:
                self._alpha = low_pass_coefficient(self.bandwidth_hz, period)
                state = self.DeclareDiscreteState(size)
                self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
                self.DeclareStateOutputPort("y", state)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other._size, other.bandwidth_hz, other.period, converter=converter)

        def DoCalcTimeDerivatives(self, context, derivatives):
            u = self.get_input_port(0).Eval(context)
            y = context.get_continuous_state_vector().CopyToVector()
            derivatives.get_mutable_vector().SetFromVector(self._rate * (u - y))

        def _update(self, context, discrete_state):
            u = self.get_input_port(0).Eval(context)
            y = context.get_discrete_state(0).get_value()
            discrete_state.get_mutable_vector(0).SetFromVector(y + self._alpha * (u - y))

        def set_initial_output(self, context, y0):
            """Set the filter's state (= output) in its own context."""
            if self.period is None:
                context.get_mutable_continuous_state_vector().SetFromVector(y0)
            else:
                context.get_mutable_discrete_state(0).SetFromVector(y0)

    return Impl


LowPassFilter = default_instantiation(LowPassFilter_)



@TemplateSystem.define("WrenchConditioner_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def WrenchConditioner_(T):

    class Impl(LeafSystem_[T]):
        """Between a wrench sensor and the controller: rejects dropouts, tares, low-pass filters.

        .. pydrake_system::

            name: WrenchConditioner
            input_ports:
            - raw_wrench
            - sequence (only with use_sequence)
            - contact_phase (only with tare)
            output_ports:
            - wrench

        Every ``period`` (at the controller's tick) a raw sample u_k is *fresh* when it is finite
        and, with ``use_sequence``, its sequence number (the sensor's packet counter, as on an
        F/T sensor's streaming interface) differs from the last one: a stale sample, repeated
        by a stalled sensor, is not fresh. Then

            y_k = y_{k-1} + alpha (u_k - y_{k-1}),   alpha = 1 - exp(-2 pi f_c h)   (alpha = 1: no filter)

        and otherwise y_k = y_{k-1} (the last good value is held). The output is y_k - b (b: the
        tare) while the last fresh sample is at most ``max_hold_time`` old, and NaN after: the
        controller then ignores the wrench (no force feedback, integrals held) and the contact
        supervisor makes no decision, instead of acting on a value that no longer describes the
        contact. With ``tare``, b is the mean of the fresh samples taken while ``contact_phase``
        is TARE (the arm held still in free space): a constant sensor bias is removed.

        The output is direct feedthrough of the inputs (y_k from u_k at the same tick: no added
        delay); the state [y (6), b (6), tare samples, age (samples since the last fresh one),
        last sequence] advances at each tick.

        The AutoDiffXd instance computes on values (no derivatives through the conditioner).

        Args:
            period: the sampling period h (s), normally the control period.
            bandwidth_hz: f_c of the low-pass (0: none).
            max_hold_time: how long a dropout is bridged by holding (s, >= 0).
            use_sequence: declare the ``sequence`` input (stale-sample detection).
            tare: declare the ``contact_phase`` input and tare during TARE.
        """

        def _construct(self, period, bandwidth_hz=0.0, max_hold_time=0.01, use_sequence=False, tare=False,
                       converter=None):
            LeafSystem_[T].__init__(self, converter)
            owner = "WrenchConditioner"
            self.period = positive(period, "period", owner, unit="s")
            self.bandwidth_hz = nonnegative(bandwidth_hz, "bandwidth_hz", owner, unit="Hz")
            self.max_hold_time = nonnegative(max_hold_time, "max_hold_time", owner, unit="s")
            self.use_sequence, self.tare = boolean(use_sequence, "use_sequence", owner), boolean(tare, "tare", owner)
            self._alpha = low_pass_coefficient(self.bandwidth_hz, self.period)
            self._max_age = int(math.floor(self.max_hold_time / self.period + 1e-9))
            self._raw_port = self.DeclareVectorInputPort("raw_wrench", 6)
            self._sequence_port = self.DeclareVectorInputPort("sequence", 1) if self.use_sequence else None
            self._phase_port = self.DeclareVectorInputPort("contact_phase", 1) if self.tare else None
            self.DeclareDiscreteState(15)
            self.DeclarePeriodicDiscreteUpdateEvent(self.period, self.period * (1.0 - SAMPLE_LEAD), self._update)
            self.DeclareVectorOutputPort("wrench", 6, self._calc_wrench)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.period, other.bandwidth_hz, other.max_hold_time, other.use_sequence,
                            other.tare, converter=converter)

        def set_initial_output(self, context, y0, sequence=0.0):
            """Start from the reading y0 (no tare, fresh)."""
            state = np.zeros(15)
            state[:6] = value(np.asarray(y0))
            state[14] = float(sequence)
            context.get_mutable_discrete_state(0).SetFromVector(state)

        def _step(self, context):
            """(new state, output) of the tick at ``context``'s time (floats)."""
            state = value(context.get_discrete_state(0).CopyToVector())
            y, tare, samples, age, last_sequence = state[:6], state[6:12], state[12], state[13], state[14]
            raw = value(self._raw_port.Eval(context))
            fresh = all_finite(raw)
            sequence = last_sequence
            if self._sequence_port is not None:
                sequence = float(value(self._sequence_port.Eval(context))[0])
                fresh = fresh and sequence != last_sequence
            if fresh:
                y = y + self._alpha * (raw - y)
                age = 0.0
                if self._phase_port is not None and int(value(self._phase_port.Eval(context))[0]) == ContactPhase.TARE:
                    tare = (tare * samples + raw) / (samples + 1.0)
                    samples += 1.0
            else:
                age += 1.0
            output = y - tare if age <= self._max_age else np.full(6, np.nan)
            return np.concatenate([y, tare, [samples, age, sequence]]), output

        def _calc_wrench(self, context, output):
            output.SetFromVector(self._step(context)[1])

        def _update(self, context, discrete_state):
            discrete_state.get_mutable_vector(0).SetFromVector(self._step(context)[0])

    return Impl


WrenchConditioner = default_instantiation(WrenchConditioner_)
