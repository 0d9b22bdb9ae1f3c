"""The hybrid velocity/force controller of Li & Sastry (1987) as a Drake LeafSystem.

Implements, in the implementable form of spec section 4 (general E^-1 block),

* hybrid velocity/force control (3.1-12),
* hybrid position/force control (Remark 3),
* hybrid impedance/force control (3.2-6),

for square arms (n = d, as in the paper) and redundant arms (n > d, with the
dynamically consistent generalization and null-space damping of spec section
8a). See ``HybridController`` for ports, law and closed loop.
"""

import numpy as np

from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import AbstractValue
from pydrake.multibody.tree import MultibodyForces_
from pydrake.systems.framework import BasicVector_, LeafSystem_, ValueProducer
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_hybrid.errors import DimensionError
from drake_hybrid.gains import ControlMode, HybridGains
from drake_hybrid.kinematics import EndEffectorKinematics, declare_plant_context_cache, resolve_frame
from drake_hybrid.linalg import inv, is_autodiff, solve, value


def impedance_blocks(velocity_projection, force_projection, task_mobility, kinematic_rows=()):
    """The blocks (3.2-8) of the impedance/force law on its partition of E's rows.

    Motion rows: [E_p; E_f[kinematic_rows]]; force rows: the other rows of E_f. With the task
    mobility L = J M^-1 J^T (= Lambda^-1, also for redundant arms), returns
    (M_f, M_fp, M_p) = (F L F^T, F L P^T, P L P^T) for force rows F and motion rows P
    (M_f and M_fp have no rows when every row of E_f is kinematic). Float or AutoDiffXd.
    """
    kinematic = list(kinematic_rows)
    physical = [i for i in range(force_projection.shape[0]) if i not in kinematic]
    motion_rows = np.vstack([velocity_projection, force_projection[kinematic]]) if kinematic else velocity_projection
    force_rows = force_projection[physical]
    return (force_rows @ task_mobility @ force_rows.T, force_rows @ task_mobility @ motion_rows.T,
            motion_rows @ task_mobility @ motion_rows.T)


def impedance_gain(velocity_projection, force_projection, task_mobility, kinematic_rows=()):
    """K_0 = I + M_fp^T M_f^-1 M_fp - M_p of the impedance/force law (3.2-6), spec section 5.

    K_0 = I - S with S = M_p - M_fp^T M_f^-1 M_fp, the Schur complement of M_f (the inverse of the
    constrained task inertia in the motion-row coordinates); blocks from ``impedance_blocks``.
    """
    M_f, M_fp, M_p = impedance_blocks(velocity_projection, force_projection, task_mobility, kinematic_rows)
    K_0 = np.eye(M_p.shape[0]) - M_p
    if M_f.shape[0]:
        K_0 = K_0 + M_fp.T @ solve(M_f, M_fp)
    return K_0


# A sampled controller ticks this fraction of a period before each multiple of the period (see
# HybridController's docstring): late enough to read the plant's newest state, early enough for a
# discrete plant stepping at the multiples of the period to apply the new torque at once.
SAMPLE_LEAD = 1e-6


class ControlSolution:
    """Everything one evaluation of the law computes (held in a cache entry)."""

    __slots__ = ("actuation", "velocity_error", "force_error", "constraint_value", "projected_velocity", "force",
                 "tangential_force", "position_error_rate", "wrench_valid")


@TemplateSystem.define("HybridController_", T_list=[float, AutoDiffXd])
def HybridController_(T):

    class Impl(LeafSystem_[T]):
        """Hybrid velocity/force (3.1-12), position/force (Remark 3) and impedance/force (3.2-6) control.

        .. pydrake_system::

            name: HybridController
            input_ports:
            - estimated_state
            - measured_wrench
            - desired_velocity
            - desired_acceleration
            - desired_force
            output_ports:
            - actuation
            - velocity_error
            - force_error
            - constraint_value
            - projected_velocity
            - force
            - tangential_force
            - position_error

        Ports (k = d - m velocity-controlled and m force-controlled coordinates):

        ====================  ====  ===================================================
        estimated_state       2n    [q; v] of the controller's plant
        measured_wrench       6     SpatialForce [n; f] on the end effector BY the
                                    environment, at the end-effector point, world frame
        desired_velocity      k     r-dot_pd
        desired_acceleration  k     r-ddot_pd (its derivative along the trajectory)
        desired_force         m     F_d, in the coordinates of the constraint's E_f
        actuation             n_u   joint torques mapped to the actuators
        velocity_error        k     e_p' = E_p r-dot - r-dot_pd
        force_error           m     e_f = F - F_d
        constraint_value      m     C(r)
        projected_velocity    k     r-dot_p = E_p r-dot
        force                 m     F, from [F_v; F] = E^-T w (w: the wrench in chart coordinates)
        tangential_force      k     F_v
        position_error        k     e_p = integral of e_p' (zero in velocity-force mode)
        ====================  ====  ===================================================

        Law (spec section 4; F is the force on the robot, spec section 0)::

            a_p  = r-ddot_pd - K_v e_p'              velocity-force  (3.1-12)
                   ... - K_p e_p                     position-force  (Remark 3)
                   ... - K_p e_p + K_0 F_v           impedance-force (3.2-6)
            r-ddot* = E^-1 ([a_p; 0] - E-dot r-dot)                  (3.0-11)
            u_f  = -F_d + K_fp e_f + K_fi xi,   xi = integral of e_f
            tau  = h + g + M J^-1 (r-ddot* - J-dot q-dot) + J^T E_f^T u_f          (n = d)
            tau  = h + g + J^T Lambda (r-ddot* - J-dot q-dot) + J^T E_f^T u_f
                   - N^T M K_n q-dot,  Lambda = (J M^-1 J^T)^-1                  (n > d)

        with K_0 = I + M_fp^T M_f^-1 M_fp - M_p recomputed every evaluation
        (spec section 5).

        In impedance mode the kinematic rows count as motion-controlled rows:
        K_0 is built on the partition [E_p; kinematic rows of E_f] / (force-
        controlled rows of E_f), and the measured force along them is
        compensated like F_v, so their closed loop is C-ddot + 3 w_c C-dot +
        2 w_c^2 C = F (unit-mass impedance).

        Kinematic rows (``constraint.kinematic_rows``, e.g. the orientation rows
        of a point contact, which the environment does not enforce) are held by
        the controller instead of force-controlled: their row of [a_p; a_f] is
        a_f = -3 w_c C-dot - 2 w_c^2 C (C-dot = E_f r-dot), so C-ddot + 3 w_c C-dot
        + 2 w_c^2 C = 0: eigenvalues -w_c and -2 w_c (``gains.constraint_frequency``;
        distinct roots, so a linearization can tell them apart).
        Their force error is zero: no force feedback and no integral, only the
        feedforward -F_d (normally 0). With an exact model and rigid contact the closed loop
        is (3.1-13)-(3.1-15)::

            e_p'-dot + K_v e_p' (+ K_p e_p) = 0 (+ F_v in impedance mode)
            (I + K_fp) e_f + K_fi xi = 0  ->  xi-dot = -(I + K_fp)^-1 K_fi xi

        so the designed eigenvalues are -eig(K_v) (or the roots of
        s^2 + K_v s + K_p) and eig(-(I + K_fp)^-1 K_fi).

        State: xi (m) and, in position and impedance modes, e_p (k). Without a
        ``control_period`` they are continuous and the actuation is direct
        feedthrough (use this for linearization). With a period h the law runs
        in a periodic discrete update (forward-Euler integrals) and the
        actuation is held in discrete state until the next tick (a sampled
        controller; no direct feedthrough). The ticks are at k h - delta
        (delta = ``SAMPLE_LEAD`` h, a nanosecond at 1 kHz), just before a
        discrete plant's steps at k h: the torque for the step from t_k is
        computed from the state at t_k, a zero-order hold without computation
        delay. (Ticking at k h itself would apply every torque one period late;
        the lagged feedforward h + g then biases the velocity loop by about
        M^-1 (dh/dq) q-dot h.) An initialization event computes the first
        held actuation from the initial state.

        A measured wrench with a NaN or inf entry (sensor dropout) is ignored
        for that evaluation: the force error is taken as zero and the
        integrals hold, so the torque stays finite.

        Preconditions: the plant is finalized, has nq = nv = n >= d and one
        actuator per joint; J has full row rank along the task; the chart and
        E = [E_p; E_f] are regular there (typed errors otherwise).

        Args:
            plant: the controller's model of the robot (float MultibodyPlant).
            end_effector_frame: a Frame of ``plant`` or its name.
            end_effector_point: p_EP, the controlled point in that frame (m).
            constraint_space: a ConstraintSpace (chart, C, E_p).
            gains: HybridGains.
            mode: ControlMode or its string ("velocity-force", ...).
            control_period: None (continuous) or the sampling period (s).
            sample_lead: with a control period, tick just before the multiples of
                the period (zero-delay hold, default) or exactly at them (every
                torque one period late; all discrete updates then share one
                timing, which the discrete-time linearization needs).
        """

        def _construct(self, plant, end_effector_frame, end_effector_point, constraint_space, gains=None,
                       mode=ControlMode.VELOCITY_FORCE, control_period=None, sample_lead=True, converter=None):
            LeafSystem_[T].__init__(self, converter)
            if plant.is_finalized() is False:
                raise ValueError("HybridController: the plant must be finalized")
            self._float_plant = plant
            self._float_frame = resolve_frame(plant, end_effector_frame)
            self._end_effector_point = np.asarray(end_effector_point, dtype=float)
            self.constraint_space = constraint_space
            self.gains = gains if gains is not None else HybridGains()
            self.mode = ControlMode.parse(mode)
            self.control_period = control_period
            self.sample_lead = bool(sample_lead)
            chart = constraint_space.chart
            d, m, k = chart.velocity_size, constraint_space.force_size, constraint_space.velocity_size
            n = plant.num_velocities()
            self.task_size, self.force_size, self.velocity_size, self.num_joints = d, m, k, n
            if n < d:
                raise DimensionError(
                    f"HybridController: the task has d = {d} coordinates ({chart.name} chart) but the plant has "
                    f"only n = {n} joints; the law needs n >= d")
            if control_period is not None and not float(control_period) > 0:
                raise ValueError(f"HybridController: control_period must be positive or None, got {control_period}")
            self._gains = self.gains.matrices(k, m, self.mode)
            self.kinematic_rows = tuple(constraint_space.constraint.kinematic_rows)
            self._force_controlled = np.ones(m)
            self._force_controlled[list(self.kinematic_rows)] = 0.0
            actuation_matrix = plant.MakeActuationMatrix()
            if actuation_matrix.shape != (n, n) or abs(np.linalg.det(actuation_matrix)) < 0.5:
                raise ValueError(
                    f"HybridController needs one actuator per joint; the plant has {plant.num_actuators()} actuators "
                    f"for {n} joints")
            self._actuation_from_torque = np.linalg.inv(actuation_matrix)  # u = B^-1 tau (a permutation here)

            # The controller's own plant, of this system's scalar type.
            self._plant = plant if T == float else plant.ToAutoDiffXd()
            self.kinematics = EndEffectorKinematics(
                self._plant, self._plant.get_frame(self._float_frame.index()), self._end_effector_point, chart)
            self._forces = MultibodyForces_[T](self._plant)
            self._zero_acceleration = np.zeros(n) if T == float else np.array([AutoDiffXd(0.0)] * n, dtype=object)

            # -- ports ------------------------------------------------------------------
            self._state_port = self.DeclareVectorInputPort("estimated_state", 2 * n)
            self._wrench_port = self.DeclareVectorInputPort("measured_wrench", 6)
            self._velocity_port = self.DeclareVectorInputPort("desired_velocity", k)
            self._acceleration_port = self.DeclareVectorInputPort("desired_acceleration", k)
            self._force_port = self.DeclareVectorInputPort("desired_force", m)

            integrated = m + (k if self.mode.integrates_position else 0)
            self._integrated_size = integrated
            self._plant_context_cache = declare_plant_context_cache(self, self._plant, self._state_port)
            if control_period is None:
                self.DeclareContinuousState(integrated)
                state_ticket = self.xc_ticket()
            else:
                # Discrete state: [xi; e_p; held actuation].
                self.DeclareDiscreteState(integrated + n)
                offset = float(control_period) * (1.0 - SAMPLE_LEAD) if self.sample_lead else 0.0
                self.DeclarePeriodicDiscreteUpdateEvent(float(control_period), offset, self._discrete_update)
                self.DeclareInitializationDiscreteUpdateEvent(self._initialize_actuation)
                state_ticket = self.xd_ticket()
            self._solution_cache = self.DeclareCacheEntry(
                description="hybrid control law",
                value_producer=ValueProducer(allocate=lambda: AbstractValue.Make(ControlSolution()),
                                             calc=self._calc_solution),
                prerequisites_of_calc={self.all_input_ports_ticket(), state_ticket,
                                       self._plant_context_cache.ticket()})
            solution_ticket = {self._solution_cache.ticket()}
            if control_period is None:
                self.DeclareVectorOutputPort("actuation", n, self._calc_actuation, prerequisites_of_calc=solution_ticket)
            else:
                self.DeclareVectorOutputPort("actuation", n, self._calc_held_actuation,
                                             prerequisites_of_calc={self.xd_ticket()})
            for name, size, field in [("velocity_error", k, "velocity_error"), ("force_error", m, "force_error"),
                                      ("constraint_value", m, "constraint_value"),
                                      ("projected_velocity", k, "projected_velocity"), ("force", m, "force"),
                                      ("tangential_force", k, "tangential_force")]:
                self.DeclareVectorOutputPort(name, size, self._make_solution_output(field),
                                             prerequisites_of_calc=solution_ticket)
            self.DeclareVectorOutputPort("position_error", k, self._calc_position_error,
                                         prerequisites_of_calc={state_ticket})

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other._float_plant, other._float_frame, other._end_effector_point,
                            other.constraint_space, other.gains, other.mode, other.control_period,
                            other.sample_lead, converter=converter)

        # -- public helpers ---------------------------------------------------------------
        def plant(self):
            """The controller's own plant (of this system's scalar type)."""
            return self._plant

        def validated_gains(self):
            """The gains as matrices (K_v, K_p, K_fp, K_fi)."""
            return self._gains

        def get_estimated_state_input_port(self):
            return self._state_port

        def get_measured_wrench_input_port(self):
            return self._wrench_port

        def get_desired_velocity_input_port(self):
            return self._velocity_port

        def get_desired_acceleration_input_port(self):
            return self._acceleration_port

        def get_desired_force_input_port(self):
            return self._force_port

        def integral_state_slices(self):
            """Slices of (xi, e_p) in the continuous or discrete state vector."""
            m, k = self.force_size, self.velocity_size
            return slice(0, m), slice(m, m + (k if self.mode.integrates_position else 0))

        # -- evaluation -----------------------------------------------------------------
        def _integrals(self, context):
            if self.control_period is None:
                return context.get_continuous_state_vector().CopyToVector()
            return context.get_discrete_state(0).CopyToVector()[:self._integrated_size]

        def _calc_solution(self, context, abstract_value):
            plant_context = self._plant_context_cache.Eval(context)
            abstract_value.set_value(self._evaluate_law(context, plant_context))

        def _evaluate_law(self, context, plant_context):
            space = self.constraint_space
            gains = self._gains
            m, k = self.force_size, self.velocity_size
            plant = self._plant
            kin = self.kinematics.evaluate(plant_context)
            x, nu = kin.configuration, kin.velocity
            values = space.evaluate(x, nu)                                   # E_p, E_f, E-dot r-dot, C
            integrals = self._integrals(context)
            xi = integrals[:m]
            e_p = integrals[m:]

            desired_velocity = self._velocity_port.Eval(context)
            desired_acceleration = self._acceleration_port.Eval(context)
            desired_force = self._force_port.Eval(context)
            wrench = self._wrench_port.Eval(context)

            # Force decomposition [F_v; F] = E^-T w (spec section 0); a dropout is ignored.
            wrench_valid = bool(np.all(np.isfinite(value(wrench))))
            if wrench_valid:
                tangential_force, force = space.split_wrench(values, self.kinematics.chart.generalized_force(x, wrench))
            else:
                tangential_force, force = np.zeros(k), desired_force
            force_error = (force - desired_force) * self._force_controlled     # e_f = F - F_d (0 on kinematic rows)
            projected_velocity = values.velocity_projection @ nu                # r-dot_p = E_p r-dot  (3.0-6)
            velocity_error = projected_velocity - desired_velocity              # e_p'

            acceleration = desired_acceleration - gains.velocity @ velocity_error             # (3.1-12)
            if self.mode.integrates_position:
                acceleration = acceleration - gains.position @ e_p                            # Remark 3
            J, bias = kin.jacobian, kin.bias
            n, d = self.num_joints, self.task_size
            need_inertia = self.mode is ControlMode.IMPEDANCE_FORCE or n > d
            if need_inertia:
                M = plant.CalcMassMatrix(plant_context)
                M_inverse = inv(M)
                task_mobility = J @ M_inverse @ J.T                              # J M^-1 J^T = Lambda^-1
            constraint_acceleration = None
            if self.kinematic_rows:
                # Kinematic rows are held by the controller: C-ddot = -3 w_c C-dot - 2 w_c^2 C.
                w_c = gains.constraint_frequency
                C_dot = values.force_projection @ nu
                held = (-3.0 * w_c * C_dot - 2.0 * w_c * w_c * values.constraint_value) * (1.0 - self._force_controlled)
                constraint_acceleration = held
            if self.mode is ControlMode.IMPEDANCE_FORCE:
                # Motion-controlled rows: E_p and the kinematic rows; force-controlled rows: the rest of
                # E_f. The measured force along the motion rows is F_v (and F on kinematic rows).
                kinematic = list(self.kinematic_rows)
                K_0 = impedance_gain(values.velocity_projection, values.force_projection, task_mobility, kinematic)
                motion_force = np.concatenate([tangential_force, force[kinematic]]) if kinematic else tangential_force
                compensation = K_0 @ motion_force                                # (3.2-6)
                acceleration = acceleration + compensation[:k]
                if kinematic:
                    extra = np.zeros(m, dtype=compensation.dtype)
                    extra[kinematic] = compensation[k:]
                    constraint_acceleration = constraint_acceleration + extra

            task_acceleration = space.task_acceleration(values, acceleration, constraint_acceleration)  # (3.0-11)
            force_command = -desired_force + gains.force_proportional @ force_error + gains.force_integral @ xi
            force_torque = J.T @ (values.force_projection.T @ force_command)    # J^T E_f^T u_f

            self._plant.CalcForceElementsContribution(plant_context, self._forces)
            if n == d:
                joint_acceleration = solve(J, task_acceleration - bias)         # J^-1 (r-ddot* - J-dot q-dot)
                torque = plant.CalcInverseDynamics(plant_context, joint_acceleration, self._forces) + force_torque
            else:
                # Dynamically consistent generalization (spec section 8a).
                v = plant.GetVelocities(plant_context)
                Lambda = inv(task_mobility)
                J_bar = M_inverse @ J.T @ Lambda
                null_space_transpose = np.eye(n) - J.T @ J_bar.T
                torque = (plant.CalcInverseDynamics(plant_context, self._zero_acceleration, self._forces)
                          + J.T @ (Lambda @ (task_acceleration - bias)) + force_torque
                          - null_space_transpose @ (M @ (gains.null_space_damping * v)))

            solution = ControlSolution()
            solution.actuation = self._actuation_from_torque @ torque
            solution.velocity_error = velocity_error
            solution.force_error = force_error
            solution.constraint_value = values.constraint_value
            solution.projected_velocity = projected_velocity
            solution.force = force
            solution.tangential_force = tangential_force
            solution.position_error_rate = velocity_error
            solution.wrench_valid = wrench_valid
            return solution

        def _solution(self, context):
            return self._solution_cache.Eval(context)

        def _make_solution_output(self, field):
            def calc(context, output):
                output.SetFromVector(getattr(self._solution(context), field))
            return calc

        def _calc_actuation(self, context, output):
            output.SetFromVector(self._solution(context).actuation)

        def _calc_held_actuation(self, context, output):
            output.SetFromVector(context.get_discrete_state(0).CopyToVector()[self._integrated_size:])

        def _calc_position_error(self, context, output):
            m, k = self.force_size, self.velocity_size
            if self.mode.integrates_position:
                output.SetFromVector(self._integrals(context)[m:m + k])
            else:
                output.SetFromVector(np.zeros(k))

        def DoCalcTimeDerivatives(self, context, derivatives):
            if self.control_period is not None or self._integrated_size == 0:
                return
            solution = self._solution(context)
            rates = [solution.force_error]
            if self.mode.integrates_position:
                rates.append(solution.position_error_rate)
            derivatives.get_mutable_vector().SetFromVector(np.concatenate(rates))

        def _discrete_update(self, context, discrete_state):
            solution = self._solution(context)
            h = float(self.control_period)
            integrals = self._integrals(context)
            rates = [solution.force_error]
            if self.mode.integrates_position:
                rates.append(solution.position_error_rate)
            new_integrals = integrals + h * np.concatenate(rates)
            discrete_state.get_mutable_vector(0).SetFromVector(np.concatenate([new_integrals, solution.actuation]))

        def _initialize_actuation(self, context, discrete_state):
            solution = self._solution(context)
            discrete_state.get_mutable_vector(0).SetFromVector(
                np.concatenate([self._integrals(context), solution.actuation]))

    return Impl


HybridController = HybridController_[None]
