"""Baseline hybrid controllers with the ports of ``HybridController`` (compared in docs/baselines.md).

What a user would write instead of Li & Sastry's law, as Drake LeafSystems (float and AutoDiffXd,
continuous or sampled) that drop into the same closed loop (``ScenarioConfig.controller``):

``JointServoHybridController`` (``mapping="inverse"``: Raibert & Craig 1981; ``"pseudoinverse"``:
Fisher & Mujtaba 1992)
    The classic hybrid position/force controller: a selection matrix S picks the motion-controlled
    task directions, their position error is mapped to the joints and closed by a joint servo with
    its own (generally unequal) joint gains K_q; the force rows get a PI force loop::

        q-dot_ref = T (nu_pd - K_q-mapped position error)
            Raibert-Craig:   T = J^-1 S        (S = E^-1 [I 0; 0 0] E, here J^-1 E^-1 [. ; 0])
            Fisher-Mujtaba:  T = (S J)^+ S     (here (E_p J)^+)
        q-dot_ref = T nu_pd - K_q T e_p,   e_p = integral of (E_p nu - nu_pd)
        tau = ID(q, q-dot, K_s (q-dot_ref - q-dot)) + J^T E_f^T (-F_d + K_fp e_f + K_fi xi)

    With a fast servo (K_s >> K_q) the motion obeys the first-order model q-dot = q-dot_ref, whose
    linearization at rest is dq-dot = -K_q T E_p J dq. For T = J^-1 S the matrix K_q J^-1 S J can
    have a negative eigenvalue when K_q is not a multiple of I: the loop is unstable although the
    model is exact (An & Hollerbach 1989; Fisher & Mujtaba 1992 trace it to J^-1 S). For
    T = (E_p J)^+ the product K_q P (P an orthogonal projector) has eigenvalues >= 0: stable.
    Each eigenvalue mu of K_q T E_p J gives the pair s^2 + K_s s + K_s mu = 0
    (``joint_servo_eigenvalues``).

``AxisPDOpenLoopForceController`` (the manipulation course's ``hybrid_force_position`` exercise)
    A task-space PD on the selected rows and the desired force applied open loop on the others,
    gravity compensated::

        tau = g(q) + J^T E^T [-K e_p - D e_p'; -F_d]

Both integrate e_p (the position error along the motion rows), so they report ``mode`` as
position-force; the force rows' e_f and the other diagnostics are those of HybridController.
"""

import sys
from dataclasses import dataclass, field
from typing import List

import numpy as np

from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import AbstractValue
from pydrake.multibody.tree import MultibodyForces_
from pydrake.systems.framework import LeafSystem_, ValueProducer
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_hybrid.control.gains import ControlMode, HybridGains
from drake_hybrid.control.law_system import LawSystemParts, MultibodyForcesHolder, declare_diagnostic_outputs
from drake_hybrid.control.sampling import declare_periodic_update, tick_offset
from drake_hybrid.core.errors import ConfigError, DimensionError, check_fields
from drake_hybrid.core.kinematics import declare_task_input, resolve_frame
from drake_hybrid.core.linalg import all_finite, solve, value
from drake_hybrid.core.templates import default_instantiation

MAPPINGS = ("inverse", "pseudoinverse")


@dataclass
class BaselineGains:
    """Gains of the baselines (``ScenarioConfig.baseline``).

    joint_gains: K_q (1/s) of the joint-servo controllers, one entry (all joints) or n.
    servo_rate: K_s (1/s), the joint velocity servo's rate (fast: the first-order model).
    stiffness, damping: K (1/s^2 per unit task inertia) and D (1/s) of the PD controller, one entry
        or k; its row forces are Lambda_p (-K e_p - D e_p') with Lambda_p = (E_p J M^-1 J^T E_p^T)^-1
        at the current state, so K = K_p and D = K_v of Li & Sastry's position mode give the same
        design on a free row.
    """

    joint_gains: List[float] = field(default_factory=lambda: [10.0])
    servo_rate: float = 200.0
    stiffness: List[float] = field(default_factory=lambda: [25.0])
    damping: List[float] = field(default_factory=lambda: [10.0])

    def validate(self, prefix="baseline."):
        check_fields(self, prefix, positive=("servo_rate",))
        for name in ("joint_gains", "stiffness", "damping"):
            entries = getattr(self, name)
            if not entries or not all(float(g) > 0 for g in entries):
                raise ConfigError(f"{prefix}{name} must be one or more positive numbers, got {entries}")
        return self


def _diagonal(entries, size, name):
    entries = np.asarray(entries, dtype=float).reshape(-1)
    if entries.size == 1:
        return np.full(size, float(entries[0]))
    if entries.size != size:
        raise DimensionError(f"{name} must have 1 or {size} entries, got {entries.size}")
    return entries


def joint_servo_matrix(jacobian, velocity_projection, matrix, mapping):
    """T: the map from the motion rows to joint rates (J^-1 E^-1 [I; 0] or (E_p J)^+), float or AutoDiffXd."""
    k = velocity_projection.shape[0]
    if mapping == "inverse":
        selector = np.vstack([np.eye(k), np.zeros((matrix.shape[0] - k, k))])
        return solve(jacobian, solve(matrix, selector))
    A = velocity_projection @ jacobian                    # S J in the rows' coordinates (k x n)
    return A.T @ solve(A @ A.T, np.eye(k))


def joint_servo_eigenvalues(jacobian, velocity_projection, matrix, joint_gains, servo_rate, mapping):
    """The first-order model's rates mu = eig(K_q T E_p J) and the servo pairs s^2 + K_s s + K_s mu = 0
    (the nonzero-mu roots; a mu < 0 gives a root near -mu > 0). Returns (mu, roots)."""
    T = joint_servo_matrix(jacobian, velocity_projection, matrix, mapping)
    mu = np.linalg.eigvals(np.diag(joint_gains) @ T @ velocity_projection @ jacobian)
    roots = np.concatenate([np.roots([1.0, servo_rate, servo_rate * m]) for m in mu])
    return mu, roots


class BaselineSolution:
    __slots__ = ("actuation", "velocity_error", "force_error", "constraint_value", "projected_velocity", "force",
                 "tangential_force", "rates", "wrench_valid")


def _declare_common(system, T, plant, end_effector_frame, end_effector_point, constraint_space, gains,
                    control_period, sample_lead, calc_law):
    """Ports, state and caches shared by the baselines (those of HybridController without the options)."""
    frame = resolve_frame(plant, end_effector_frame)
    chart = constraint_space.chart
    d, m, k = chart.velocity_size, constraint_space.force_size, constraint_space.velocity_size
    n = plant.num_velocities()
    if n != d:
        raise DimensionError(f"{type(system).__name__}: the baselines need a square arm (n = d); got n = {n}, d = {d}")
    system.constraint_space = constraint_space
    system.gains = gains if gains is not None else HybridGains()
    system.mode = ControlMode.POSITION_FORCE                 # they integrate e_p
    system._gains = system.gains.matrices(k, m, system.mode)
    system.task_size, system.force_size, system.velocity_size, system.num_joints = d, m, k, n
    system.kinematic_rows = tuple(constraint_space.constraint.kinematic_rows)
    system.control_period = control_period
    system.sampled_diagnostics = False
    _, system.kinematics, system._state_port, system._plant_context_cache = declare_task_input(
        system, T, plant, frame, np.asarray(end_effector_point, dtype=float), chart)
    system._plant = system.kinematics.plant
    # Per-context scratch: the force elements (gravity, ...) at the context's state (as HybridController).
    system._forces_cache = system.DeclareCacheEntry(
        description="force elements", value_producer=ValueProducer(
            allocate=lambda: AbstractValue.Make(MultibodyForcesHolder(MultibodyForces_[T](system._plant))),
            calc=lambda context, abstract: system._plant.CalcForceElementsContribution(
                system._plant_context_cache.Eval(context), abstract.get_mutable_value().forces)),
        prerequisites_of_calc={system._plant_context_cache.ticket()})
    system._wrench_port = system.DeclareVectorInputPort("measured_wrench", 6)
    system._velocity_port = system.DeclareVectorInputPort("desired_velocity", k)
    system._acceleration_port = system.DeclareVectorInputPort("desired_acceleration", k)
    system._force_port = system.DeclareVectorInputPort("desired_force", m)
    integrated = m + k
    system._integrated_size = integrated
    if control_period is None:
        system.DeclareContinuousState(integrated)
        state_ticket = system.xc_ticket()
    else:
        system.DeclareDiscreteState(integrated + n)
        declare_periodic_update(system, float(control_period), tick_offset(control_period, sample_lead),
                                system._discrete_update)
        system.DeclareInitializationDiscreteUpdateEvent(system._initialize_actuation)
        state_ticket = system.xd_ticket()
    system._solution_cache = system.DeclareCacheEntry(
        description="baseline law", value_producer=ValueProducer(
            allocate=lambda: AbstractValue.Make(BaselineSolution()),
            calc=lambda context, abstract: abstract.set_value(calc_law(context))),
        prerequisites_of_calc={system.all_input_ports_ticket(), state_ticket, system._plant_context_cache.ticket()})
    ticket = {system._solution_cache.ticket()}
    if control_period is None:
        system.DeclareVectorOutputPort("actuation", n, lambda c, o: o.SetFromVector(system._solution(c).actuation),
                                       prerequisites_of_calc=ticket)
    else:
        system.DeclareVectorOutputPort("actuation", n, lambda c, o: o.SetFromVector(
            c.get_discrete_state(0).CopyToVector()[integrated:]), prerequisites_of_calc={system.xd_ticket()})
    declare_diagnostic_outputs(system, k, m, system._solution, ticket)
    system.DeclareVectorOutputPort("position_error", k, lambda c, o: o.SetFromVector(system._integrals(c)[m:]),
                                   prerequisites_of_calc={state_ticket})


class _BaselineMixin(LawSystemParts):
    """State handling shared by the baselines (continuous integrals, or sampled with a held torque)."""

    def integral_state_slices(self):
        m, k = self.force_size, self.velocity_size
        return slice(0, m), slice(m, m + k)

    def _solution(self, context):
        return self._solution_cache.Eval(context)

    def DoCalcTimeDerivatives(self, context, derivatives):
        if self.control_period is None:
            derivatives.get_mutable_vector().SetFromVector(self._solution(context).rates)

    def _discrete_update(self, context, discrete_state):
        solution = self._solution(context)
        integrals = self._integrals(context) + float(self.control_period) * solution.rates
        discrete_state.get_mutable_vector(0).SetFromVector(np.concatenate([integrals, solution.actuation]))

    def _initialize_actuation(self, context, discrete_state):
        discrete_state.get_mutable_vector(0).SetFromVector(
            np.concatenate([self._integrals(context), self._solution(context).actuation]))

    def _measure(self, context):
        """Common pieces of both laws: task kinematics, E, errors, the force decomposition."""
        plant_context = self._plant_context_cache.Eval(context)
        kin = self.kinematics.evaluate(plant_context)
        space = self.constraint_space
        values = space.evaluate(kin.configuration, kin.velocity)
        desired_velocity = self._velocity_port.Eval(context)
        desired_force = self._force_port.Eval(context)
        wrench = self._wrench_port.Eval(context)
        for port, command in ((self._velocity_port, desired_velocity), (self._force_port, desired_force)):
            if not all_finite(command):
                raise ValueError(f"{type(self).__name__}: input '{port.get_name()}' has non-finite entries "
                                 f"{value(command).tolist()}")
        if all_finite(wrench):
            tangential_force, force = space.split_wrench(values, self.kinematics.chart.generalized_force(
                kin.configuration, wrench))
        else:
            tangential_force, force = np.zeros(self.velocity_size), desired_force
        solution = BaselineSolution()
        solution.wrench_valid = all_finite(wrench)
        solution.projected_velocity = values.velocity_projection @ kin.velocity
        solution.velocity_error = solution.projected_velocity - desired_velocity
        solution.force_error = force - desired_force
        solution.constraint_value = values.constraint_value
        solution.force = force
        solution.tangential_force = tangential_force
        integrals = self._integrals(context)
        xi, e_p = integrals[:self.force_size], integrals[self.force_size:]
        solution.rates = np.concatenate([solution.force_error, solution.velocity_error])
        return plant_context, kin, values, xi, e_p, desired_velocity, desired_force, solution


@TemplateSystem.define("JointServoHybridController_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def JointServoHybridController_(T):

    class Impl(_BaselineMixin, LeafSystem_[T]):
        """Hybrid position/force control with a joint servo: Raibert-Craig (J^-1 S) or Fisher-Mujtaba ((S J)^+ S).

        .. pydrake_system::

            name: JointServoHybridController
            input_ports:
            - estimated_state
            - measured_wrench
            - desired_velocity
            - desired_acceleration (unused; the servo has no acceleration feedforward)
            - desired_force
            output_ports:
            - actuation
            - velocity_error
            - force_error
            - constraint_value
            - projected_velocity
            - force
            - tangential_force
            - wrench_valid
            - position_error

        Ports as HybridController's. Law (module docstring)::

            q-dot_ref = T nu_pd - K_q T e_p,  T = J^-1 E^-1 [I; 0] (inverse) or (E_p J)^+ (pseudoinverse)
            tau = ID(q, q-dot, K_s (q-dot_ref - q-dot)) + J^T E_f^T (-F_d + K_fp e_f + K_fi xi)

        State: xi (m) and e_p (k), continuous or, with a ``control_period``, sampled with the
        actuation held (as HybridController). Square arms (n = d) only.

        Args:
            plant, end_effector_frame, end_effector_point, constraint_space, gains, control_period,
                sample_lead: as HybridController (gains: K_fp, K_fi of the force loop).
            joint_gains: K_q (1/s), a scalar or n entries.
            servo_rate: K_s (1/s).
            mapping: "inverse" (Raibert-Craig) or "pseudoinverse" (Fisher-Mujtaba).
        """

        def _construct(self, plant, end_effector_frame, end_effector_point, constraint_space, gains=None,
                       joint_gains=10.0, servo_rate=200.0, mapping="inverse", control_period=None, sample_lead=True,
                       converter=None):
            arguments = locals()
            code = Impl._construct.__code__
            self._arguments = {name: arguments[name] for name in code.co_varnames[1:code.co_argcount]
                               if name != "converter"}
            LeafSystem_[T].__init__(self, converter)
            if mapping not in MAPPINGS:
                raise ValueError(f"JointServoHybridController: mapping must be one of {list(MAPPINGS)}, got '{mapping}'")
            if not float(servo_rate) > 0:
                raise ValueError(f"JointServoHybridController: servo_rate must be positive, got {servo_rate}")
            self.mapping = mapping
            self.servo_rate = float(servo_rate)
            _declare_common(self, T, plant, end_effector_frame, end_effector_point, constraint_space, gains,
                            control_period, sample_lead, self._law)
            self.joint_gains = _diagonal(joint_gains, self.num_joints, "joint_gains")

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, **other._arguments, converter=converter)

        def _law(self, context):
            plant_context, kin, values, xi, e_p, nu_pd, F_d, solution = self._measure(context)
            gains = self._gains
            T_map = joint_servo_matrix(kin.jacobian, values.velocity_projection, values.matrix, self.mapping)
            q_dot_ref = T_map @ nu_pd - self.joint_gains * (T_map @ e_p)
            v = self._plant.GetVelocities(plant_context)
            acceleration = self.servo_rate * (q_dot_ref - v)
            u_f = -F_d + gains.force_proportional @ solution.force_error + gains.force_integral @ xi
            forces = self._forces_cache.Eval(context).forces
            torque = (self._plant.CalcInverseDynamics(plant_context, acceleration, forces)
                      + kin.jacobian.T @ (values.force_projection.T @ u_f))
            solution.actuation = torque
            return solution

    return Impl


JointServoHybridController = default_instantiation(JointServoHybridController_)


@TemplateSystem.define("AxisPDOpenLoopForceController_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def AxisPDOpenLoopForceController_(T):

    class Impl(_BaselineMixin, LeafSystem_[T]):
        """Task-space PD on the motion rows, open-loop force on the force rows, gravity compensated.

        .. pydrake_system::

            name: AxisPDOpenLoopForceController
            input_ports:
            - estimated_state
            - measured_wrench (only for the reported force; not fed back)
            - desired_velocity
            - desired_acceleration (unused)
            - desired_force
            output_ports:
            - actuation
            - velocity_error
            - force_error
            - constraint_value
            - projected_velocity
            - force
            - tangential_force
            - wrench_valid
            - position_error

        Law (the manipulation course's hybrid_force_position exercise, in the task's rows)::

            tau = g(q) + J^T E^T [Lambda_p (-K e_p - D e_p'); -F_d],   Lambda_p = (E_p J M^-1 J^T E_p^T)^-1

        State: e_p (k) and, for the force error's report only, xi (m).

        Args:
            plant, end_effector_frame, end_effector_point, constraint_space, gains, control_period,
                sample_lead: as HybridController.
            stiffness, damping: K (1/s^2), D (1/s), scalars or k entries.
        """

        def _construct(self, plant, end_effector_frame, end_effector_point, constraint_space, gains=None,
                       stiffness=25.0, damping=10.0, control_period=None, sample_lead=True, converter=None):
            arguments = locals()
            code = Impl._construct.__code__
            self._arguments = {name: arguments[name] for name in code.co_varnames[1:code.co_argcount]
                               if name != "converter"}
            LeafSystem_[T].__init__(self, converter)
            _declare_common(self, T, plant, end_effector_frame, end_effector_point, constraint_space, gains,
                            control_period, sample_lead, self._law)
            self.stiffness = _diagonal(stiffness, self.velocity_size, "stiffness")
            self.damping = _diagonal(damping, self.velocity_size, "damping")

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, **other._arguments, converter=converter)

        def _law(self, context):
            plant_context, kin, values, xi, e_p, nu_pd, F_d, solution = self._measure(context)
            plant = self._plant
            J, E_p = kin.jacobian, values.velocity_projection
            M = plant.CalcMassMatrix(plant_context)
            A = E_p @ J @ solve(M, J.T) @ E_p.T
            row_force = solve(A, -self.stiffness * e_p - self.damping * solution.velocity_error)
            w = values.matrix.T @ np.concatenate([row_force, -F_d])
            solution.actuation = -plant.CalcGravityGeneralizedForces(plant_context) + J.T @ w
            return solution

    return Impl


AxisPDOpenLoopForceController = default_instantiation(AxisPDOpenLoopForceController_)


def make_baseline(name, plant, end_effector_frame, end_effector_point, constraint_space, gains=None, baseline=None,
                  control_period=None, sample_lead=True):
    """The baseline ``name`` ("raibert-craig", "fisher-mujtaba", "pd-open-loop-force") with ``baseline``
    (BaselineGains; None = defaults) and the force gains of ``gains``."""
    baseline = baseline if baseline is not None else BaselineGains()
    if name in ("raibert-craig", "fisher-mujtaba"):
        return JointServoHybridController(plant, end_effector_frame, end_effector_point, constraint_space, gains,
                                          joint_gains=baseline.joint_gains, servo_rate=baseline.servo_rate,
                                          mapping="inverse" if name == "raibert-craig" else "pseudoinverse",
                                          control_period=control_period, sample_lead=sample_lead)
    if name == "pd-open-loop-force":
        return AxisPDOpenLoopForceController(plant, end_effector_frame, end_effector_point, constraint_space, gains,
                                             stiffness=baseline.stiffness, damping=baseline.damping,
                                             control_period=control_period, sample_lead=sample_lead)
    raise ValueError(f"unknown baseline '{name}'; use raibert-craig, fisher-mujtaba or pd-open-loop-force")
