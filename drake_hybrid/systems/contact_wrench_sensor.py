"""The ideal contact-wrench sensor: the contact results on the robot's bodies, summed and shifted to
the end-effector point P, in world (the sign convention of ``systems.wrench_frames``).

On a continuous plant the contact results are direct feedthrough of the actuation, so plant ->
sensor -> controller -> plant is an algebraic loop; a filter (``systems.low_pass_filter``) breaks
it (see docs/drake_notes.md). A TemplateSystem (float and AutoDiffXd), so closed loops linearize.
"""

import math
import sys

import numpy as np

from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.cpp_param import List
from pydrake.common.value import AbstractValue, Value
from pydrake.math import RigidTransform_
from pydrake.multibody.plant import ContactResults_
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_hybrid.core.kinematics import resolve_frame
from drake_hybrid.core.linalg import all_finite, value
from drake_hybrid.core.templates import default_instantiation
from drake_hybrid.systems.wrench_frames import _point, _point_in_world, _point_in_world_floats, _shift


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
