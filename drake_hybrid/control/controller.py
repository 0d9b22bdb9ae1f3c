"""The hybrid velocity/force controller of Li & Sastry (1987) as a Drake LeafSystem.

Implements, in the implementable form of docs/theory.md §4 (general E^-1 block),

* hybrid velocity/force control (3.1-12),
* hybrid position/force control (Remark 3),
* hybrid impedance/force control (3.2-6),

for square arms (n = d, as in the paper) and redundant arms (n > d, with the
dynamically consistent generalization and null-space damping of docs/theory.md
§8 (a)), protected against what the paper assumes away (``safety``): effort limits
(graceful saturation, anti-windup), kinematic singularities (damped inverse),
non-finite inputs, and contact that is not there yet or is lost (the guarded
move of ``supervision.ContactSupervisor``). See ``HybridController`` for ports,
law and closed loop.

The law itself, line by line, is in ``law``; this module keeps the system: ports, cache
entries, state and events.
"""

# Longer than 500 lines because over half of it is the system's docstring (its ports, closed loop, protections
# and arguments), which the API reference renders.

import sys
from typing import Any, Dict, Optional, Tuple

import numpy as np

from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import AbstractValue
from pydrake.multibody.tree import MultibodyForces_
from pydrake.systems.framework import Context, ContinuousState, EventStatus, InputPort, LeafSystem_, ValueProducer
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_hybrid.control.damping import joint_damping, warn_damped_joints
from drake_hybrid.control.fast_law import FastLaw
from drake_hybrid.control.gains import ControlMode, HybridGains, ValidatedGains, check_poles
from drake_hybrid.control.law import LawConstants, evaluate_law
from drake_hybrid.control.law_system import LawSystemParts, declare_diagnostic_outputs, reported_diagnostics_vector
from drake_hybrid.control.normal_force import NORMAL_FORCE_AXES, tool_axis_wrench
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.safety import SafetyConfig, warn_singularity
from drake_hybrid.control.sampling import SAMPLE_LEAD, declare_periodic_update, tick_offset
from drake_hybrid.core.arguments import boolean, describe, instance, matrix, nonnegative, positive, vector
from drake_hybrid.core.errors import ArgumentError, DimensionError, OffConstraintError
from drake_hybrid.core.kinematics import AnyScalarContext, declare_task_input, resolve_frame, set_plant_state
from drake_hybrid.core.linalg import all_finite, value
from drake_hybrid.core.preconditions import check_generic_rank, check_pushing_force
from drake_hybrid.core.templates import default_instantiation

# The largest |C| (units of C's rows) at which a controller without a guarded move may start: the
# guarded move's default reach (supervision.max_travel). A start in contact is the pad pressed in by its
# rest compression: measured at the package's starts (set_initial_conditions, every built-in task)
# |C| <= 0.9 mm, and the start solvers press at most max_depth (10 mm by default). Farther off, the
# start was not solved (e.g. a Simulator on a default context: q = 0, C = 0.233 m on a Kinova Jaco).
START_CONSTRAINT_LIMIT = 0.05


class LawCache:
    """The solution cache entry's value, one per context (never shared between contexts): a context
    of the controller's plant at the estimated state, the force elements' contribution there (a
    MultibodyForces) and the ControlSolution computed from them. One cache entry, so one Python
    callback per evaluation of the law."""

    __slots__ = ("plant_context", "forces", "solution")

    def __init__(self, plant_context: AnyScalarContext, forces: Any) -> None:     # forces: a MultibodyForces_[T]
        self.plant_context, self.forces, self.solution = plant_context, forces, None


@TemplateSystem.define("HybridController_", T_list=[float, AutoDiffXd], scope=sys.modules[__name__])
def HybridController_(T):

    class Impl(LawSystemParts, LeafSystem_[T]):
        """Hybrid velocity/force (3.1-12), position/force (Remark 3) and impedance/force (3.2-6) control.

        .. pydrake_system::

            name: HybridController
            input_ports:
            - estimated_state
            - measured_wrench
            - desired_velocity
            - desired_acceleration
            - desired_force
            - contact_phase (only with guarded_move)
            - approach_reference (only with guarded_move)
            - path_position_error (only with path_position_error)
            output_ports:
            - actuation
            - computed_actuation
            - velocity_error
            - force_error
            - constraint_value
            - projected_velocity
            - force
            - tangential_force
            - wrench_valid
            - position_error

        Ports (k = d - m velocity-controlled and m force-controlled coordinates):

        ====================  ====  ===================================================
        estimated_state       2n    [q; v] of the controller's plant
        measured_wrench       6     SpatialForce [n; f] on the end effector BY the
                                    environment, at the end-effector point, world frame
        desired_velocity      k     r-dot_pd
        desired_acceleration  k     r-ddot_pd (its derivative along the trajectory)
        desired_force         m     F_d, in the coordinates of the constraint's E_f
        contact_phase         1     phases.ContactPhase (only with ``guarded_move``)
        approach_reference    m     C_r, the guarded move's reference (only with ``guarded_move``)
        path_position_error   k     e_p measured against a path (only with ``path_position_error``;
                                    e.g. ``systems.path_source.PathSource``)
        actuation             n_u   joint torques mapped to the actuators (held between ticks
                                    with a ``control_period``)
        computed_actuation    n_u   the actuation the law computes from the inputs and state now
                                    (direct feedthrough): what a tick stores and ``actuation``
                                    holds from then on; for a system that ticks with the law and
                                    acts on its torque in the same tick (hardware.command)
        velocity_error        k     e_p' = E_p r-dot - r-dot_pd
        force_error           m     e_f = F - F_d
        constraint_value      m     C(r)
        projected_velocity    k     r-dot_p = E_p r-dot
        force                 m     F, from [F_v; F] = E^-T w (w: the wrench in chart coordinates)
        tangential_force      k     F_v
        wrench_valid          1     1 if the measured wrench was finite, 0 if not (then force,
                                    force_error and tangential_force read NaN)
        position_error        k     e_p = integral of e_p' (zero in velocity-force mode); with
                                    ``path_position_error``, that input (position and impedance modes)
        ====================  ====  ===================================================

        Law (docs/theory.md §4; F is the force on the robot, docs/theory.md §0)::

            a_p  = r-ddot_pd - K_v e_p'              velocity-force  (3.1-12)
                   ... - K_p e_p                     position-force  (Remark 3)
                   ... - K_p e_p + K_0 F_v           impedance-force (3.2-6)
            r-ddot* = E^-1 ([a_p; 0] - E-dot r-dot)                  (3.0-11)
            u_f  = -F_d + K_fp e_f + K_fi xi,   xi = integral of e_f
            tau  = h + g + M J^-1 (r-ddot* - J-dot q-dot) + J^T E_f^T u_f          (n = d)
            tau  = h + g + J^T Lambda (r-ddot* - J-dot q-dot) + J^T E_f^T u_f
                   - N^T M K_n q-dot,  Lambda = (J M^-1 J^T)^-1                  (n > d)

        with K_0 = I + M_fp^T M_f^-1 M_fp - M_p recomputed every evaluation
        (docs/theory.md §5); with the impedance's mass M_d (``gains.impedance_mass``,
        the paper's 1 by default) the velocity rows' I is M_d^-1.

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

            e_p'-dot + K_v e_p' (+ K_p e_p) = 0 (+ M_d^-1 F_v in impedance mode)
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
        for that evaluation: the law takes the force error as zero and the force
        integral xi holds (e_p keeps integrating the velocity error), so the
        torque stays finite; the ports that report what the wrench gives (force,
        force_error, tangential_force) read NaN, never a perfect match, and
        wrench_valid reads 0. A non-finite state or command raises ValueError
        naming the port.

        Before the first step (an initialization event, or ``check_start`` on a context
        you set up) the controller checks that the law can start there: E_f and E of
        full rank (``ConstraintRankError``, also when it is built: a constraint whose rows
        are dependent everywhere is refused then) and a desired force that pushes
        (``core.preconditions.check_pushing_force``: ``ForceSignError`` if the measured
        force pushes against F_d, or, off the surface with ``guarded_move``, if -F_d
        leads away from C = 0; ``OffConstraintError`` if C = 0 is beyond the guarded
        move's ``max_travel``).

        Protections (``safety``; none changes the law where it is not active):

        * effort limits: the actuation is saturated gracefully (the task part of
          tau = (h + g) + tau_task scaled by the largest s <= 1 within the limits)
          and, with ``anti_windup``, xi and e_p are frozen while saturated;
        * kinematic singularities: where sigma_min(J) < ``singularity_threshold``
          and the task part would command a joint acceleration beyond
          ``max_joint_acceleration``, the inverse of J (n = d) or of J M^-1 J^T
          (n > d) is damped just enough to meet the bound, with a
          ``KinematicSingularityWarning`` the first time;
        * contact not there (``guarded_move`` given): with ``contact_phase`` not
          CONTACT the force-controlled rows of [a_p; a_f] become the guarded move
          a_f = -2 K_a (C-dot - s n_C) - K_a^2 (C - C_r) (n_C = -F_d / |F_d|, the
          pressing direction; s = approach_speed in APPROACH, 0 in TARE and HOLD; C_r
          from ``approach_reference``, moving at s n_C in APPROACH: integral action,
          ``law.guarded_acceleration``), u_f = 0 on them and
          xi is frozen (anti-windup while off the surface). The velocity rows keep
          their law.

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
            safety: a SafetyConfig (effort limits, anti-windup, the joint
                acceleration bound); None = defaults (the plant's effort limits).
            guarded_move: None, or an object with ``approach_speed`` (units of C
                per second, >= 0) and ``approach_gain`` (K_a, 1/s), e.g. a
                ``supervision.SupervisionConfig``: declares the ``contact_phase``
                and ``approach_reference`` inputs and the guarded move off the surface.
            plant_time_step: the simulated plant's step h (0: continuous). On a discrete plant the
                model's joint damping B is compensated on the predicted end-of-step velocity,
                B (v + h a*), as the solver applies it implicitly (``control.damping``); a
                ``JointDampingWarning`` names joints with b h / M > 1.
            sampled_diagnostics: with a control period, also store the
                diagnostics (velocity_error, force_error, constraint_value,
                projected_velocity, force, tangential_force) computed at each
                tick in discrete state and output them, concatenated, on a
                ``diagnostics`` port (layout: ``diagnostic_slices()``). Loggers
                then read what the tick computed, as Drake's sampled output
                ports do, instead of re-evaluating the law after the tick has
                changed the integrals (which runs the law twice per period).
                Off by default: the stored copy adds states with zero
                multipliers to a discrete-time linearization.
            velocity_row_inertia: None (the paper's massless constraint, default) or I_v (k x k): the
                inertia of a mechanism that moves along the velocity rows (a crank's handle). See
                ``law.mechanism_force``.
            compensate_tangential_force: in velocity-force and position-force mode, cancel the
                measured force along the velocity rows, F_v, which the paper's §3.1 assumes zero
                (friction, a tessellated or curved workpiece); see ``law.tangential_compensation``.
                Default True; False is the paper's form (the crank and grinding tasks keep it). Impedance mode uses F_v as (3.2-6) says.
            wrench_lag: T (s), how late the measured wrench arrives (the wrench path's low-pass,
                ``systems.low_pass_filter.low_pass_lag``): the law splits it at the configuration T earlier,
                to first order (``law.measured_forces``). Default 0.
            path_position_error: declare the ``path_position_error`` input: in position-force and
                impedance-force mode the law's e_p is that input (a position error measured against a
                path, which does not drift as an integral does) instead of the integral of e_p' (still
                integrated in the state, unused). Default False.
            normal_force_axis: "model" (default): the normal row (the first force-controlled one) reads the
                force along the model's normal, in E's dual basis; "tool": along the tool's axis (the
                end-effector frame's z), the real normal once a flat tool lies flat on a surface the model
                gets wrong (``control.normal_force``).
            fast_law: for T = float, evaluate the law through its compiled
                float path (``fast_law``; the same law, equal to 1e-12) when
                numba is available; False = the generic ``law.evaluate_law``.
        """

        def _construct(self, plant, end_effector_frame, end_effector_point, constraint_space, gains=None,
                       mode=ControlMode.VELOCITY_FORCE, control_period=None, sample_lead=True, safety=None,
                       guarded_move=None, sampled_diagnostics=False, velocity_row_inertia=None,
                       plant_time_step=0.0, compensate_tangential_force=True, wrench_lag=0.0, fast_law=True,
                       path_position_error=False, normal_force_axis="model", converter=None):
            # Every argument as given, for scalar conversion (_construct_copy): one added later cannot
            # be forgotten there.
            arguments = locals()
            code = Impl._construct.__code__
            self._arguments = {name: arguments[name] for name in code.co_varnames[1:code.co_argcount]
                               if name != "converter"}
            LeafSystem_[T].__init__(self, converter)
            owner = "HybridController"
            if not hasattr(plant, "is_finalized") or not hasattr(plant, "MakeActuationMatrix"):
                raise ArgumentError(f"{owner}: plant must be a MultibodyPlant, got {describe(plant)}")
            if plant.is_finalized() is False:
                raise ArgumentError(f"{owner}: the plant must be finalized")
            if not all(hasattr(constraint_space, name) for name in ("chart", "force_size", "velocity_size", "evaluate")):
                raise ArgumentError(f"{owner}: constraint_space must be a ConstraintSpace (a constraint with its "
                                    f"velocity projection), got {describe(constraint_space)}")
            self._float_plant = plant
            self._float_frame = resolve_frame(plant, end_effector_frame)
            self._end_effector_point = vector(end_effector_point, "end_effector_point", owner, 3, unit="m")
            self.constraint_space = constraint_space
            # A HybridGains is validated here; ValidatedGains come validated (scenario.builder.prepare_config).
            self.gains = instance(gains, "gains", owner, (HybridGains, ValidatedGains), allow_none=True,
                                  what="a HybridGains (e.g. HybridGains(velocity=[10.0]))") or HybridGains()
            self.mode = ControlMode.parse(mode)
            self.control_period = positive(control_period, "control_period", owner, unit="s", allow_none=True)
            self.sample_lead = boolean(sample_lead, "sample_lead", owner)
            chart = constraint_space.chart
            d, m, k = chart.velocity_size, constraint_space.force_size, constraint_space.velocity_size
            n = plant.num_velocities()
            self.task_size, self.force_size, self.velocity_size, self.num_joints = d, m, k, n
            if n < d:
                raise DimensionError(
                    f"HybridController: the task has d = {d} coordinates ({chart.name} chart) but the plant has "
                    f"only n = {n} joints; the law needs n >= d")
            # Joint damping of the model, compensated at the simulated plant's step (control.damping).
            self.plant_time_step = nonnegative(plant_time_step, "plant_time_step", owner, unit="s")
            self.wrench_lag = nonnegative(wrench_lag, "wrench_lag", owner, unit="s")
            self.joint_damping = joint_damping(plant)   # B per velocity, which the plant's step applies implicitly
            if T == float:                        # once, not again for the AutoDiffXd copy
                warn_damped_joints(plant, self.plant_time_step)
            self.sampled_diagnostics = boolean(sampled_diagnostics, "sampled_diagnostics", owner)
            if self.sampled_diagnostics and control_period is None:
                raise ArgumentError(f"{owner}: sampled_diagnostics needs a control_period (a sampled controller)")
            compensate_tangential_force = boolean(compensate_tangential_force, "compensate_tangential_force", owner)
            fast_law = boolean(fast_law, "fast_law", owner)
            if normal_force_axis not in NORMAL_FORCE_AXES:
                raise ArgumentError(f"{owner}: normal_force_axis must be one of {', '.join(NORMAL_FORCE_AXES)}, got "
                                    f"{normal_force_axis!r}")
            self.normal_force_axis = normal_force_axis
            if isinstance(self.gains, ValidatedGains):
                self._gains = self.gains.check_sizes(k, m, owner)
            else:
                self._gains = self.gains.matrices(k, m, self.mode, self.control_period)
            self.kinematic_rows = tuple(constraint_space.constraint.kinematic_rows)
            check_generic_rank(constraint_space)
            actuation_matrix = plant.MakeActuationMatrix()
            if actuation_matrix.shape != (n, n) or abs(np.linalg.det(actuation_matrix)) < 0.5:
                raise ArgumentError(
                    f"HybridController needs one actuator per joint; the plant has {plant.num_actuators()} actuators "
                    f"for {n} joints")
            actuation_from_torque = np.linalg.inv(actuation_matrix)   # u = B^-1 tau (a permutation here)
            self.safety = instance(safety, "safety", owner, SafetyConfig, allow_none=True) or SafetyConfig()
            plant_limits = [plant.get_joint_actuator(i).effort_limit() for i in plant.GetJointActuatorIndices()]
            (self.effort_limits, anti_windup, singularity_threshold,
             self._max_joint_acceleration) = self.safety.validated(n, plant_limits)
            self.guarded_move = guarded_move
            speed = gain = None
            if guarded_move is not None:
                speed = nonnegative(getattr(guarded_move, "approach_speed", None), "guarded_move.approach_speed",
                                    owner, unit="units of C per s")
                gain = positive(getattr(guarded_move, "approach_gain", None), "guarded_move.approach_gain", owner,
                                unit="1/s")
                check_poles([-gain], "guarded_move.approach_gain (K_a)", self.control_period)
            # The mechanism's inertia along the velocity rows (None: the paper's massless constraint).
            I_v = None
            if velocity_row_inertia is not None:
                I_v = matrix(velocity_row_inertia, "velocity_row_inertia", owner, (k, k), error=DimensionError)
            self.velocity_row_inertia = I_v
            zero_acceleration = np.zeros(n) if T == float else np.array([AutoDiffXd(0.0)] * n, dtype=object)
            self._law = LawConstants(self._gains, self.mode, self.kinematic_rows, m, singularity_threshold,
                                     self._max_joint_acceleration, self.effort_limits, anti_windup,
                                     actuation_from_torque, zero_acceleration, speed, gain, I_v,
                                     self.joint_damping, self.plant_time_step, compensate_tangential_force,
                                     self.wrench_lag)

            # -- ports ------------------------------------------------------------------
            # estimated_state, the controller's own plant of this system's scalar type, its kinematics.
            # (The plant context lives in the law's cache entry, LawCache, with the force elements.)
            _, self.kinematics, self._state_port, _ = declare_task_input(
                self, T, plant, self._float_frame, self._end_effector_point, chart, plant_context_cache=False)
            self._plant = self.kinematics.plant
            self._wrench_port = self.DeclareVectorInputPort("measured_wrench", 6)
            self._velocity_port = self.DeclareVectorInputPort("desired_velocity", k)
            self._acceleration_port = self.DeclareVectorInputPort("desired_acceleration", k)
            self._force_port = self.DeclareVectorInputPort("desired_force", m)
            self._phase_port = self._reference_port = None
            if guarded_move is not None:
                self._phase_port = self.DeclareVectorInputPort("contact_phase", 1)
                self._reference_port = self.DeclareVectorInputPort("approach_reference", m)
            self._path_error_port = (self.DeclareVectorInputPort("path_position_error", k) if path_position_error
                                     else None)

            integrated = m + (k if self.mode.integrates_position else 0)
            self._integrated_size = integrated
            if control_period is None:
                self.DeclareContinuousState(integrated)
                state_ticket = self.xc_ticket()
            else:
                # Discrete state: [xi; e_p; held actuation].
                self.DeclareDiscreteState(integrated + n)
                declare_periodic_update(self, float(control_period), tick_offset(control_period, self.sample_lead),
                                        self._discrete_update)
                self.DeclareInitializationDiscreteUpdateEvent(self._initialize_actuation)
                state_ticket = self.xd_ticket()
            self._solution_cache = self.DeclareCacheEntry(
                description="hybrid control law",
                value_producer=ValueProducer(allocate=self._allocate_law_cache, calc=self._calc_solution),
                prerequisites_of_calc={self.all_input_ports_ticket(), state_ticket})
            solution_ticket = {self._solution_cache.ticket()}
            if control_period is None:
                self.DeclareVectorOutputPort("actuation", n, self._calc_actuation, prerequisites_of_calc=solution_ticket)
            else:
                self.DeclareVectorOutputPort("actuation", n, self._calc_held_actuation,
                                             prerequisites_of_calc={self.xd_ticket()})
            self.DeclareVectorOutputPort("computed_actuation", n, self._calc_actuation,
                                         prerequisites_of_calc=solution_ticket)
            start = declare_diagnostic_outputs(self, k, m, self._solution, solution_ticket)
            if self.sampled_diagnostics:
                # Discrete state group 1: the diagnostics of the last tick (output by Drake: no Python call).
                self.DeclareStateOutputPort("diagnostics", self.DeclareDiscreteState(start))
            self.DeclareVectorOutputPort("position_error", k, self._calc_position_error,
                                         prerequisites_of_calc={state_ticket} if self._path_error_port is None else
                                         {self._path_error_port.ticket()})
            # Before the first step: the law's preconditions at the start (check_start).
            self.DeclareInitializationPublishEvent(self._check_start_event)
            # The float fast path (control/fast_law.py): the same law compiled; None = the generic law.
            self.fast_law = FastLaw.build(self, self._law, constraint_space) if T == float and fast_law else None

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, **other._arguments, converter=converter)

        def _allocate_law_cache(self):
            return AbstractValue.Make(LawCache(self._plant.CreateDefaultContext(), MultibodyForces_[T](self._plant)))

        # -- public helpers ---------------------------------------------------------------
        def get_desired_velocity_input_port(self) -> InputPort:
            return self._velocity_port

        def get_desired_acceleration_input_port(self) -> InputPort:
            return self._acceleration_port

        def get_desired_force_input_port(self) -> InputPort:
            return self._force_port

        def get_contact_phase_input_port(self) -> Optional[InputPort]:
            """The ``contact_phase`` input (only with ``guarded_move``; else None)."""
            return self._phase_port

        def get_approach_reference_input_port(self) -> Optional[InputPort]:
            """The ``approach_reference`` input (only with ``guarded_move``; else None)."""
            return self._reference_port

        @property
        def compensate_tangential_force(self) -> bool:
            """Whether the law cancels the measured F_v (and the held rows' force) in velocity-force and
            position-force mode (the constructor's ``compensate_tangential_force``)."""
            return self._law.compensate_tangential_force

        def check_start(self, context: Context) -> None:
            """Raise a typed error if the law cannot start at ``context`` (this controller's): E_f or E
            singular there (``ConstraintRankError``, ``ChartSingularityError``), a desired force that pulls
            (``ForceSignError``: the measured force pushes against F_d; or, off the surface with a guarded
            move, -F_d leads away from C = 0) or a surface beyond the guarded move's reach
            (``OffConstraintError``). An initialization event calls it when a Simulator initializes;
            call it yourself on a context you have set up (``core.preconditions``).

            Without a guarded move (no contact supervisor to approach the surface) it also refuses a start
            farther than START_CONSTRAINT_LIMIT (units of C) off C = 0 (``OffConstraintError`` naming C, and
            the joints outside the plant's limits if any): the start was not solved."""
            solution = self._solution(context)
            phase = ContactPhase(solution.contact_phase)
            if self._phase_port is None:
                self._check_start_on_constraint(context, np.asarray(value(solution.constraint_value), dtype=float))
            check_pushing_force(
                self._force_port.Eval(context), force=solution.force if solution.wrench_valid else None,
                constraint_value=solution.constraint_value, force_controlled=self._law.force_controlled,
                off_surface=phase is not ContactPhase.CONTACT,
                max_travel=getattr(self.guarded_move, "max_travel", None),
                where=f"the controller's first tick (t = {float(value(context.get_time())):g} s, {phase.name})")

        def _check_start_on_constraint(self, context, constraint_value):
            """OffConstraintError if |C| at the start is above START_CONSTRAINT_LIMIT (no guarded move)."""
            worst = float(np.max(np.abs(constraint_value))) if constraint_value.size else 0.0
            if not worst > START_CONSTRAINT_LIMIT:
                return
            plant = self._float_plant
            q = np.asarray(value(self._state_port.Eval(context)), dtype=float)[:plant.num_positions()]
            outside = [i for i, (low, x, high) in enumerate(zip(plant.GetPositionLowerLimits(), q,
                                                                 plant.GetPositionUpperLimits()))
                       if not low <= x <= high]
            limits = (f"; q = {np.round(q, 3).tolist()} is outside the plant's joint limits at position(s) {outside}"
                      if outside else "")
            raise OffConstraintError(
                f"HybridController: the start is off the constraint: C = {np.round(constraint_value, 4).tolist()} "
                f"(|C| up to {worst:.3g} > {START_CONSTRAINT_LIMIT:g} units of C) with no guarded move to approach the "
                f"surface{limits}: put the arm at rest pressing with F_d first (station.contact_start."
                "solve_contact_start, or station.start.prime_start after setting the state), or add a contact "
                "supervisor (supervision=SupervisionConfig())")

        def _check_start_event(self, context):
            self.check_start(context)
            return EventStatus.Succeeded()
        def get_path_position_error_input_port(self) -> Optional[InputPort]:
            """The ``path_position_error`` input (only with ``path_position_error``; else None)."""
            return self._path_error_port

        def diagnostics(self, context: Context) -> Dict[str, Any]:
            """What the protections did in the evaluation at ``context``: a dict with the contact
            phase, the saturation scale s, whether an actuator was clipped, sigma_min(J) (None
            when the exact inverse was within its bound and no SVD was needed), the damping
            lambda^2 and whether the wrench was valid."""
            solution = self._solution(context)
            return {"contact_phase": ContactPhase(solution.contact_phase),
                    "saturation_scale": solution.saturation_scale, "actuator_clipped": solution.actuator_clipped,
                    "smallest_singular_value": solution.smallest_singular_value,
                    "singularity_damping": solution.singularity_damping, "wrench_valid": solution.wrench_valid}

        def integral_state_slices(self) -> Tuple[slice, slice]:
            """Slices of (xi, e_p) in the continuous or discrete state vector."""
            m, k = self.force_size, self.velocity_size
            return slice(0, m), slice(m, m + (k if self.mode.integrates_position else 0))

        # -- evaluation -----------------------------------------------------------------
        def _calc_solution(self, context, abstract_value):
            cache = abstract_value.get_mutable_value()
            plant_context = cache.plant_context
            # The plant at the estimated state, its force elements (gravity, joint damping, ...), the law.
            state = set_plant_state(self, self._plant, self._state_port, context, plant_context)
            self._plant.CalcForceElementsContribution(plant_context, cache.forces)
            cache.solution = self._evaluate_law(context, plant_context, cache.forces, state)

        def _contact_phase(self, context):
            if self._phase_port is None:
                return ContactPhase.CONTACT
            code = float(value(self._phase_port.Eval(context))[0])
            if code not in (0.0, 1.0, 2.0, 3.0):
                raise ValueError(f"HybridController: contact_phase must be one of {[int(p) for p in ContactPhase]} "
                                 f"({', '.join(p.name for p in ContactPhase)}), got {code}")
            return ContactPhase(int(code))

        def _check_finite_commands(self, *commands):
            """ValueError naming the first non-finite command (the state is checked by the plant-context cache)."""
            for port, command in zip((self._velocity_port, self._acceleration_port, self._force_port), commands):
                if not all_finite(command):
                    raise ValueError(f"HybridController: input '{port.get_name()}' has non-finite entries "
                                     f"{value(command).tolist()}")

        def _evaluate_law(self, context, plant_context, forces, state):
            """Read each input once and run the law (control/law.py) at ``context`` (``state``: the
            estimated [q; v] already set in ``plant_context``)."""
            desired_velocity = self._velocity_port.Eval(context)
            desired_acceleration = self._acceleration_port.Eval(context)
            desired_force = self._force_port.Eval(context)
            integrals = self._law_integrals(context)
            wrench = self._wrench_port.Eval(context)
            phase = self._contact_phase(context)
            # C_r, read off the surface only (in CONTACT the law does not use it).
            reference = (self._reference_port.Eval(context) if phase is not ContactPhase.CONTACT
                         else np.zeros(self.force_size))
            solution = None
            if self.fast_law is not None:              # None: a check failed, the generic law raises (or copes)
                # The compiled law reads the normal row along the tool's axis itself (fast_kernels).
                solution = self.fast_law.evaluate(plant_context, forces, state[self.num_joints:], integrals,
                                                  desired_velocity, desired_acceleration, desired_force, wrench,
                                                  phase, reference)
            if solution is None:
                if self.normal_force_axis == "tool":
                    wrench = self._force_along_tool_axis(plant_context, wrench)
                self._check_finite_commands(desired_velocity, desired_acceleration, desired_force)
                solution = evaluate_law(
                    self._law, self.constraint_space, self.kinematics.evaluate(plant_context), self._plant,
                    plant_context, forces, integrals, desired_velocity, desired_acceleration, desired_force, wrench,
                    phase, reference)
            if solution.singularity_damping > 0:
                warn_singularity(self, solution.smallest_singular_value, self._max_joint_acceleration)
            return solution

        def _solution(self, context):
            return self._solution_cache.Eval(context).solution

        def _force_along_tool_axis(self, plant_context, wrench):
            """The measured wrench as the normal row reads it with normal_force_axis="tool" (control.normal_force)."""
            kinematics = self.kinematics
            X_WE = self._plant.CalcRelativeTransform(plant_context, self._plant.world_frame(), kinematics.frame)
            R_WE = X_WE.rotation().matrix()
            x = kinematics.chart.configuration(R_WE, X_WE.translation() + R_WE @ kinematics.point_in_frame)
            return tool_axis_wrench(self.constraint_space, x, R_WE, wrench)

        def _calc_actuation(self, context, output):
            output.SetFromVector(self._solution(context).actuation)

        def _calc_held_actuation(self, context, output):
            output.SetFromVector(context.get_discrete_state(0).CopyToVector()[self._integrated_size:])

        def _store_diagnostics(self, solution, discrete_state):
            if self.sampled_diagnostics:
                discrete_state.get_mutable_vector(1).SetFromVector(reported_diagnostics_vector(solution))

        def _law_integrals(self, context):
            """[xi; e_p] as the law reads them: e_p from ``path_position_error`` when declared."""
            integrals = self._integrals(context)
            if self._path_error_port is not None and self.mode.integrates_position:
                integrals = np.concatenate([integrals[:self.force_size], self._path_error_port.Eval(context)])
            return integrals

        def _calc_position_error(self, context, output):
            m, k = self.force_size, self.velocity_size
            if self.mode.integrates_position:
                output.SetFromVector(self._law_integrals(context)[m:m + k])
            else:
                output.SetFromVector(np.zeros(k))

        def DoCalcTimeDerivatives(self, context: Context, derivatives: ContinuousState) -> None:
            if self.control_period is not None or self._integrated_size == 0:
                return
            solution = self._solution(context)
            derivatives.get_mutable_vector().SetFromVector(solution.integral_rates_vector(self._integrated_size))

        def _discrete_update(self, context, discrete_state):
            solution = self._solution(context)
            h = float(self.control_period)
            new_integrals = self._integrals(context) + h * solution.integral_rates_vector(self._integrated_size)
            discrete_state.get_mutable_vector(0).SetFromVector(np.concatenate([new_integrals, solution.actuation]))
            self._store_diagnostics(solution, discrete_state)

        def _initialize_actuation(self, context, discrete_state):
            solution = self._solution(context)
            discrete_state.get_mutable_vector(0).SetFromVector(
                np.concatenate([self._integrals(context), solution.actuation]))
            self._store_diagnostics(solution, discrete_state)

    return Impl


HybridController = default_instantiation(HybridController_)
