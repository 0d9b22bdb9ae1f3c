"""The control law of Li & Sastry (1987): one small function per line, float or AutoDiffXd.

This module is the law's single home. ``HybridController`` (control/controller.py) keeps the
ports, cache entries, state and events, reads its inputs once per evaluation and calls
``evaluate_law``, which runs the lines below in order (docs/theory.md §4, §5 and §8 (a); F is the
force on the robot, §0; k = d - m velocity rows, m force rows)::

    line of the law                                                 function
    [F_v; F] = E^-T w                                     (3.0-8)   measured_forces
          ... + T E^-T E_f-dot^T F   (a wrench T late: split where it was measured)
    r-dot_p = E_p r-dot,  e_p' = r-dot_p - r-dot_pd        (3.0-6)   velocity_error
    e_f = F - F_d                       (0 on kinematic rows)        force_error
    a_p = r-ddot_pd - K_v e_p'                            (3.1-12)   motion_acceleration
          ... - K_p e_p                                  (Remark 3)
          ... + K_0 (F_v + F_m)                           (3.2-6)   impedance_compensation
          K_0 from J (M + h B)^-1 J^T   (discrete plant, joint damping B)   damping.step_task_mobility
    F_m = I_v a_p                       (a mechanism on the velocity rows)   mechanism_force
    F_c = -F_v                          (velocity and position modes)        tangential_compensation
    F_h = -F on the held rows           (velocity and position modes)        held_row_compensation
    a_f = -3 w_c C-dot - 2 w_c^2 C      (kinematic rows)             held_row_acceleration
    a_f = -K_fd C-dot                   (force rows, in contact; not the paper's)   force_row_damping
    a_f = -2 K_a (C-dot - s n_C) - K_a^2 (C - C_r)   (off the surface)   guarded_acceleration
    r-ddot* = E^-1 ([a_p; a_f] - E-dot r-dot)             (3.0-11)   ConstraintSpace.task_acceleration
    u_f = -F_d + K_fp e_f + K_fi xi (+ F_h)               (3.1-12)   force_command
    tau_f = J^T (E_f^T u_f + E_p^T (F_m + F_c))                      force_torque
    tau = ID(q, q-dot, J^-1 (r-ddot* - J-dot q-dot)) + tau_f   (n = d)   joint_torque
    tau = h + g + J^T Lambda (r-ddot* - J-dot q-dot) + tau_f
          - N^T M K_n q-dot,  Lambda = (J M^-1 J^T)^-1          (n > d)   joint_torque
    tau += h B a*          (discrete plant, the model's joint damping B)   damping.damping_compensation
    u = saturate(B_u^-1 tau)                                         safety.saturate
    xi-dot = e_f,  e_p-dot = e_p'       (frozen while saturated)     integral_rates

The protections of ``safety`` (bounded inverses near singularities, graceful saturation) enter
where the law inverts J or meets the effort limits; none changes the law where it is inactive.
Every function is pure except that ``joint_torque`` asks the plant for M and inverse dynamics
(the only Drake calls the law needs besides the kinematics the controller evaluates).

Float controllers run the same lines compiled (``fast_law``, ``fast_kernels``: numba, one call per
tick); this module stays the law's definition and its AutoDiffXd path, and tests/test_fast_law.py
holds the compiled path to it (every output port equal to 1e-12). A change here goes there too.
"""

import numpy as np

from drake_hybrid.control.damping import damping_compensation, step_task_mobility
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.safety import bounded_solve, bounded_task_inertia, saturate
from drake_hybrid.core.linalg import all_finite, inv, solve, value


class LawConstants:
    """What the law needs that is fixed when the controller is built (no per-tick allocation).

    gains: control.gains.ValidatedGains; mode: ControlMode; kinematic_rows: indices of the rows of
    E_f held by the controller; force_controlled: 1 on force-controlled rows of E_f, 0 on kinematic
    ones; singularity_threshold, max_joint_acceleration, effort_limits, anti_windup: from
    SafetyConfig; actuation_from_torque: B^-1; zero_acceleration: a zero joint acceleration of the
    controller's scalar type (for h + g by inverse dynamics); approach_speed, approach_gain: the guarded move's s
    and K_a (None without a guarded move); velocity_row_inertia: I_v of a mechanism moving with the
    velocity rows (None: the paper's massless constraint); joint_damping, plant_time_step: the
    model's B and the simulated plant's step h (``control.damping``; h = 0: continuous);
    compensate_tangential_force: cancel the measured F_v and the held rows' measured force
    (``tangential_compensation``, ``held_row_compensation``); wrench_lag: T (s), how late the
    wrench path delivers the wrench (its low-pass, ``measured_forces``).
    """

    __slots__ = ("gains", "mode", "kinematic_rows", "force_controlled", "singularity_threshold",
                 "max_joint_acceleration", "effort_limits", "anti_windup", "actuation_from_torque",
                 "zero_acceleration", "approach_speed", "approach_gain", "velocity_row_inertia", "joint_damping",
                 "plant_time_step", "compensate_tangential_force", "wrench_lag")

    def __init__(self, gains, mode, kinematic_rows, force_size, singularity_threshold, max_joint_acceleration,
                 effort_limits, anti_windup, actuation_from_torque, zero_acceleration, approach_speed=None,
                 approach_gain=None, velocity_row_inertia=None, joint_damping=None, plant_time_step=0.0,
                 compensate_tangential_force=False, wrench_lag=0.0):
        self.gains, self.mode = gains, mode
        self.kinematic_rows = tuple(kinematic_rows)
        self.force_controlled = np.ones(force_size)
        self.force_controlled[list(self.kinematic_rows)] = 0.0
        self.singularity_threshold, self.max_joint_acceleration = singularity_threshold, max_joint_acceleration
        self.effort_limits, self.anti_windup = effort_limits, anti_windup
        self.actuation_from_torque, self.zero_acceleration = actuation_from_torque, zero_acceleration
        self.approach_speed, self.approach_gain = approach_speed, approach_gain
        self.velocity_row_inertia = velocity_row_inertia
        self.joint_damping, self.plant_time_step = joint_damping, plant_time_step
        self.compensate_tangential_force = compensate_tangential_force
        self.wrench_lag = float(wrench_lag)


class ControlSolution:
    """Everything one evaluation of the law computes (held in the controller's cache entry)."""

    __slots__ = ("actuation", "velocity_error", "force_error", "constraint_value", "projected_velocity", "force",
                 "tangential_force", "position_error_rate", "force_integral_rate", "wrench_valid", "contact_phase",
                 "saturation_scale", "actuator_clipped", "smallest_singular_value", "singularity_damping")

    def diagnostics_vector(self):
        """[e_p'; e_f; C; r-dot_p; F; F_v]: the diagnostics in the controller's ``diagnostics`` layout."""
        return np.concatenate([self.velocity_error, self.force_error, self.constraint_value, self.projected_velocity,
                               self.force, self.tangential_force])

    def integral_rates_vector(self, size):
        """The first ``size`` entries of [xi-dot; e_p-dot] (the integral states' layout)."""
        return np.concatenate([self.force_integral_rate, self.position_error_rate])[:size]


# ------------------------------------------------------------------------------------------------
# The lines of the law
# ------------------------------------------------------------------------------------------------

def measured_forces(space, values, configuration, wrench, desired_force, wrench_lag=0.0, force_projection_rate=None):
    """(F_v, F, valid): [F_v; F] = E^-T w (3.0-8), w the chart covector of the measured wrench
    (the SpatialForce vector [n; f] on the end effector by the environment) at ``configuration``.

    A wrench that arrives ``wrench_lag`` = T late (a low-pass on the wrench path) was exerted at
    x - T x-dot, where E had not yet turned: it is split there, to first order in T,
    [F_v; F] = E^-T (w + T E_f-dot^T F) (``force_projection_rate`` E_f-dot at (x, nu); F from the
    plain split; the turn of E_p weighs F_v, zero on the exact surface: second order). Split with
    the current E instead, a curved constraint's turning normal force reads as a tangential force
    T D r_p-dot, D = dF_v/dr_p (about -F / rho), whose cancellation gives the velocity rows a gain
    K_v + T S D (docs/theory.md §11). The chart's own turn weighs the moment (0 at a ball pad's
    centre): left out too.

    A wrench with a non-finite entry (sensor dropout) is ignored: F_v = 0 and F = F_d, so the
    force error is zero and xi holds for that evaluation (e_p, from the velocity error, does not).
    """
    if not all_finite(wrench):
        return np.zeros(space.velocity_size), desired_force, False
    covector = space.chart.generalized_force(configuration, wrench)
    tangential_force, force = space.split_wrench(values, covector)
    if wrench_lag > 0:
        tangential_force, force = space.split_wrench(values, covector + wrench_lag * (force_projection_rate.T @ force))
    return tangential_force, force, True


def velocity_error(velocity_projection, velocity, desired_velocity):
    """(r-dot_p, e_p'): r-dot_p = E_p r-dot (3.0-6) and e_p' = r-dot_p - r-dot_pd."""
    projected_velocity = velocity_projection @ velocity
    return projected_velocity, projected_velocity - desired_velocity


def force_error(force, desired_force, force_controlled):
    """e_f = F - F_d on the force-controlled rows (0 on kinematic rows: no force loop there)."""
    return (force - desired_force) * force_controlled


def motion_acceleration(desired_acceleration, gains, velocity_error, position_error, mode):
    """a_p = r-ddot_pd - K_v e_p' (3.1-12), minus K_p e_p in position and impedance modes (Remark 3)."""
    acceleration = desired_acceleration - gains.velocity @ velocity_error
    if mode.integrates_position:
        acceleration = acceleration - gains.position @ position_error
    return acceleration


def mechanism_force(velocity_row_inertia, motion_acceleration):
    """F_m = I_v a_p: the force along the velocity rows that a mechanism of inertia I_v moving with
    them needs at the commanded acceleration a_p (None without I_v: the paper's form).

    The paper's constraint is massless; a handle that spins with a velocity row pushes back with
    F_v = -I_v r-ddot_p, which slows that row's loop to (1 + M_p I_v) s + K_v (M_p: the row's
    mobility with the constraint rows held). The law adds the wrench J^T E_p^T F_m, so the robot
    supplies that force itself, and in impedance mode counts the mechanism as part of the robot
    (F_v + F_m is the external force its K_0 compensates). With an exact I_v the row closes as
    designed: r-ddot_p = a_p.
    """
    if velocity_row_inertia is None:
        return None
    return velocity_row_inertia @ motion_acceleration


def tangential_compensation(tangential_force, mode, enabled):
    """F_c = -F_v: the force along the velocity rows that cancels the measured tangential force, in
    velocity-force and position-force mode (None when off, and always in impedance mode, where F_v
    drives the impedance (3.2-6) instead).

    The paper's §3.1 assumes F_v = 0: a frictionless contact on the exact surface. A real contact
    has F_v from friction, from a tessellated or rough surface, or from a mechanism; left in, it
    drives the velocity rows, whose positions velocity-force mode leaves unregulated. On a curved
    workpiece the tessellated contact's tangential stiffness differs from the F/rho that the
    turning E_f(x) cancels by dk, and that moves a zero of the velocity rows to s with
    Lambda s (s + K_v) = dk: a slow real instability for dk > 0 (docs/theory.md §11). With the
    measured F_v cancelled, dk acts only through the wrench path's lag: with a first-order
    low-pass of w_w the root stays at 0 and the rest satisfy Lambda (s + K_v)(s + w_w) = dk, stable
    for dk < Lambda K_v w_w. It also removes F_v's pull on the force rows, M_fp F_v of (3.2-9).
    The wrench must be the force on the model's end effector: a wrist sensor's reading of a tool
    the model already carries is not (``WristSensorConfig.compensate_tool_inertia``).
    """
    if not enabled or mode is ControlMode.IMPEDANCE_FORCE:
        return None
    return -tangential_force


def held_row_compensation(force, force_controlled, wrench_valid, mode, enabled):
    """F_h = -F on the kinematic (held) rows of E_f, added to u_f: the force that cancels the measured
    force along the rows the controller holds, in velocity-force and position-force mode (None when
    off, and in impedance mode, whose K_0 takes it as a motion row's external force; 0 on a rejected
    wrench, as F_v is).

    A held row is one the contact cannot push along (a point contact's torques): the law's (3.0-11)
    assumes nothing acts there. A real contact does: a compliant pad on a tessellated workpiece
    reports a torque about its centre that changes as the pad moves over the facets. Left in, it
    reaches the velocity rows through the arm's coupled mobility, (E J M^-1 J^T E^T)[p, h] dF_h/dy y,
    a slow real mode of the positions velocity-force mode leaves unregulated (+0.50 1/s at the
    sphere's pole; ``analysis.modes.row_force_drift`` predicts it), and it keeps the start from being
    an equilibrium. Cancelled with ``tangential_compensation`` under the same option.
    """
    if not enabled or mode is ControlMode.IMPEDANCE_FORCE or not wrench_valid:
        return None
    return -force * (1.0 - force_controlled)


def impedance_blocks(velocity_projection, force_projection, task_mobility, kinematic_rows=()):
    """The blocks (3.2-8) of the impedance/force law on its partition of E's rows.

    Motion rows: [E_p; E_f[kinematic_rows]]; force rows: the other rows of E_f. With the task
    mobility L = J M^-1 J^T (= Lambda^-1, also for redundant arms), returns
    (M_f, M_fp, M_p) = (F L F^T, F L P^T, P L P^T) for force rows F and motion rows P
    (M_f and M_fp have no rows when every row of E_f is kinematic). Float or AutoDiffXd. The law
    passes the step's L = J (M + h B)^-1 J^T on a discrete plant with joint damping B: the blocks
    say how the arm answers a force (control.damping).
    """
    kinematic = list(kinematic_rows)
    physical = [i for i in range(force_projection.shape[0]) if i not in kinematic]
    motion_rows = np.vstack([velocity_projection, force_projection[kinematic]]) if kinematic else velocity_projection
    force_rows = force_projection[physical]
    return (force_rows @ task_mobility @ force_rows.T, force_rows @ task_mobility @ motion_rows.T,
            motion_rows @ task_mobility @ motion_rows.T)


def impedance_gain(velocity_projection, force_projection, task_mobility, kinematic_rows=(), inverse_mass=None):
    """K_0 = I + M_fp^T M_f^-1 M_fp - M_p of the impedance/force law (3.2-6), docs/theory.md §5.

    K_0 = I - S with S = M_p - M_fp^T M_f^-1 M_fp, the Schur complement of M_f (the inverse of the
    constrained task inertia in the motion-row coordinates); blocks from ``impedance_blocks``. With
    the impedance's mass M_d on the velocity rows (``inverse_mass`` = M_d^-1, k x k; None: the paper's
    unit mass) the velocity rows' block of I is M_d^-1: e'' + K_v e' + K_p e = M_d^-1 F_v.
    """
    M_f, M_fp, M_p = impedance_blocks(velocity_projection, force_projection, task_mobility, kinematic_rows)
    target = np.eye(M_p.shape[0])
    if inverse_mass is not None:
        k = velocity_projection.shape[0]
        target[:k, :k] = inverse_mass
    K_0 = target - M_p
    if M_f.shape[0]:
        K_0 = K_0 + M_fp.T @ solve(M_f, M_fp)
    return K_0


def impedance_compensation(values, task_mobility, tangential_force, force, kinematic_rows, inverse_mass=None):
    """K_0 [F_v; F_kinematic] (3.2-6), split into its velocity rows (k) and its rows of E_f (m).

    In impedance mode the kinematic rows count as motion rows: K_0 is built on the partition
    [E_p; kinematic rows of E_f] / (force-controlled rows), and the measured force along them is
    compensated like F_v, giving them the unit-mass impedance C-ddot + 3 w_c C-dot + 2 w_c^2 C = F
    (the velocity rows get M_d^-1 F_v, ``inverse_mass``; ``impedance_gain``).
    """
    kinematic = list(kinematic_rows)
    K_0 = impedance_gain(values.velocity_projection, values.force_projection, task_mobility, kinematic, inverse_mass)
    motion_force = np.concatenate([tangential_force, force[kinematic]]) if kinematic else tangential_force
    compensation = K_0 @ motion_force
    k = tangential_force.shape[0]
    on_force_rows = np.zeros(force.shape[0], dtype=compensation.dtype)
    if kinematic:
        on_force_rows[kinematic] = compensation[k:]
    return compensation[:k], on_force_rows


def held_row_acceleration(constraint_value, constraint_rate, constraint_frequency, force_controlled):
    """a_f = -3 w_c C-dot - 2 w_c^2 C on the kinematic rows (0 on the others).

    The controller holds these rows (the environment does not): C-ddot + 3 w_c C-dot + 2 w_c^2 C
    = 0, eigenvalues -w_c and -2 w_c (distinct, so a linearization tells them apart).
    """
    w_c = constraint_frequency
    return (-3.0 * w_c * constraint_rate - 2.0 * w_c * w_c * constraint_value) * (1.0 - force_controlled)


def force_row_damping(constraint_rate, force_damping, force_controlled, in_contact):
    """a_f = -K_fd C-dot on the force-controlled rows in contact (0 elsewhere, and with K_fd = 0: the
    paper's a_f = 0).

    Not the paper's line: rigid contact holds C-dot = 0 on the force rows, so it changes nothing the paper
    designs, while on a compliant contact it damps the rows' motion, which the force loop alone leaves
    undamped (``control.gains``, the module docstring: a flat tool's moment rows need it).
    """
    if not in_contact:
        return constraint_rate * 0.0
    return -(force_damping @ constraint_rate) * force_controlled


def guarded_acceleration(constraint_value, constraint_rate, approach_reference, desired_force, force_controlled,
                         phase, approach_speed, approach_gain):
    """a_f = -2 K_a (C-dot - s n_C) - K_a^2 (C - C_r) on the force-controlled rows, off the surface
    (0 on kinematic rows): a critically damped servo to the reference C_r, double pole at -K_a.

    n_C = -F_d / |F_d| is the way the robot pushes; s = ``approach_speed`` in APPROACH, 0 in TARE and
    HOLD; C_r = ``approach_reference``, the supervisor's reference: C at the start of APPROACH, then
    moving at s n_C (standing in TARE and HOLD). C - C_r is the integral of the velocity error
    C-dot - s n_C since APPROACH began: integral action. A velocity servo alone, -K_a (C-dot - s n_C),
    stalls against the surface at the pressing force Lambda K_a s, which may lie below the contact
    threshold (1.45 N against 3 N for the UR5e on the sphere); with the integral the force keeps
    rising, at Lambda K_a^2 s per second, until the supervisor declares contact, whatever the arm's
    task inertia Lambda and the contact's damping. In free space C tracks the ramp C_r with no lag.
    """
    pressing = -value(desired_force) * force_controlled
    norm = np.linalg.norm(pressing)
    direction = pressing / norm if norm > 0 else pressing
    speed = approach_speed if phase is ContactPhase.APPROACH else 0.0
    return (-2.0 * approach_gain * (constraint_rate - speed * direction)
            - approach_gain * approach_gain * (constraint_value - approach_reference)) * force_controlled


def force_command(desired_force, gains, force_error, force_integral, force_controlled, in_contact):
    """u_f = -F_d + K_fp e_f + K_fi xi (3.1-12); off the surface only the kinematic rows' feedforward."""
    command = -desired_force + gains.force_proportional @ force_error + gains.force_integral @ force_integral
    return command if in_contact else command * (1.0 - force_controlled)


def force_torque(jacobian, force_projection, command, velocity_projection=None, velocity_row_forces=()):
    """tau_f = J^T E_f^T u_f, plus J^T E_p^T F for each force F on the velocity rows that is not
    None (the mechanism force F_m, the tangential compensation F_c)."""
    wrench = force_projection.T @ command
    for row_force in velocity_row_forces:
        if row_force is not None:
            wrench = wrench + velocity_projection.T @ row_force
    return jacobian.T @ wrench


def joint_torque(plant, plant_context, forces, jacobian, task_rhs, tau_f, constants, dynamics=None):
    """(tau, base torque or None, sigma_min, lambda^2) for r-ddot* - J-dot q-dot = ``task_rhs``.

    n = d: tau = ID(q, q-dot, J^-1 task_rhs) + tau_f, the inverse solved by ``bounded_solve``.
    n > d (docs/theory.md §8 (a)): tau = h + g + J^T Lambda task_rhs + tau_f - N^T M K_n q-dot with the
    dynamically consistent Lambda = (J M^-1 J^T)^-1 (``bounded_task_inertia``) and
    N^T = I - J^T J_bar^T, J_bar = M^-1 J^T Lambda; ``dynamics`` = (M, M^-1, J M^-1 J^T).
    ``forces`` holds the plant's force elements (gravity, joint damping, ...); the base torque
    h + g is returned when computed.
    """
    threshold, bound = constants.singularity_threshold, constants.max_joint_acceleration
    d, n = jacobian.shape
    if n == d:
        joint_acceleration, sigma_min, lambda_squared = bounded_solve(jacobian, task_rhs, threshold, bound)
        base_torque = None
        torque = plant.CalcInverseDynamics(plant_context, joint_acceleration, forces) + tau_f
    else:
        M, M_inverse, task_mobility = dynamics
        Lambda, sigma_min, lambda_squared = bounded_task_inertia(jacobian, M_inverse, task_mobility, task_rhs,
                                                                 threshold, bound)
        J_bar = M_inverse @ jacobian.T @ Lambda
        null_space_transpose = np.eye(n) - jacobian.T @ J_bar.T
        base_torque = plant.CalcInverseDynamics(plant_context, constants.zero_acceleration, forces)
        v = plant.GetVelocities(plant_context)
        motion_torque = (jacobian.T @ (Lambda @ task_rhs)
                         - null_space_transpose @ (M @ (constants.gains.null_space_damping * v)))
        joint_acceleration = M_inverse @ motion_torque
        torque = base_torque + motion_torque + tau_f
    if constants.joint_damping is not None:
        # A discrete plant damps at the end-of-step velocity: B (v + h a*), not B v (control.damping).
        torque = torque + damping_compensation(constants.joint_damping, joint_acceleration, constants.plant_time_step)
    return torque, base_torque, sigma_min, lambda_squared


def integral_rates(velocity_error, force_error, frozen, in_contact):
    """(xi-dot, e_p-dot) = (e_f, e_p'), both frozen while saturated (anti-windup) and xi also off the
    surface."""
    position_rate = velocity_error * 0.0 if frozen else velocity_error
    force_rate = force_error * 0.0 if (frozen or not in_contact) else force_error
    return force_rate, position_rate


# ------------------------------------------------------------------------------------------------
# The law, line by line
# ------------------------------------------------------------------------------------------------

def evaluate_law(constants, space, kinematics, plant, plant_context, forces, integrals, desired_velocity,
                 desired_acceleration, desired_force, wrench, phase, approach_reference=None):
    """One evaluation of the law (the lines of the module docstring, in order) -> ControlSolution.

    ``kinematics``: a core.kinematics evaluation (configuration r, velocity r-dot, J, J-dot q-dot);
    ``integrals``: [xi; e_p] (e_p only in position and impedance modes); ``wrench``: the measured
    SpatialForce vector [n; f] on the end effector by the environment; ``phase``: ContactPhase;
    ``approach_reference``: the guarded move's C_r (needed off the surface only).
    Raises FloatingPointError if the actuation is not finite.
    """
    gains, mode, mask = constants.gains, constants.mode, constants.force_controlled
    m = space.force_size
    in_contact = phase is ContactPhase.CONTACT
    x, nu, J = kinematics.configuration, kinematics.velocity, kinematics.jacobian
    values = space.evaluate(x, nu)                                       # E_p, E_f, E-dot r-dot, C
    xi, e_p = integrals[:m], integrals[m:]

    E_f_dot = space.constraint.force_projection_rate(x, nu) if constants.wrench_lag > 0 else None
    tangential_force, force, wrench_valid = measured_forces(space, values, x, wrench, desired_force,
                                                            constants.wrench_lag, E_f_dot)
    projected_velocity, e_p_dot = velocity_error(values.velocity_projection, nu, desired_velocity)
    e_f = force_error(force, desired_force, mask)

    a_p = motion_acceleration(desired_acceleration, gains, e_p_dot, e_p, mode)
    F_m = mechanism_force(constants.velocity_row_inertia, a_p)
    F_c = tangential_compensation(tangential_force, mode, constants.compensate_tangential_force)
    C_dot = values.force_projection @ nu
    a_f = held_row_acceleration(values.constraint_value, C_dot, gains.constraint_frequency, mask)
    a_f = a_f + force_row_damping(C_dot, gains.force_damping, mask, in_contact)
    n, d = J.shape[1], J.shape[0]
    dynamics = None
    if mode is ControlMode.IMPEDANCE_FORCE or n > d:
        M = plant.CalcMassMatrix(plant_context)
        M_inverse = inv(M)
        task_mobility = J @ M_inverse @ J.T                               # J M^-1 J^T = Lambda^-1
        dynamics = (M, M_inverse, task_mobility)
    if mode is ControlMode.IMPEDANCE_FORCE:
        # K_0 (3.2-6) cancels the arm's answer to F_v, the force rows' reaction (3.2-9) included: on a
        # discrete plant it answers through (M + h B)^-1, its damping implicit (control.damping).
        response = step_task_mobility(J, M, task_mobility, constants.joint_damping, constants.plant_time_step)
        external = tangential_force if F_m is None else tangential_force + F_m
        on_velocity_rows, on_force_rows = impedance_compensation(values, response, external, force,
                                                                 constants.kinematic_rows, gains.impedance_inverse_mass)
        a_p = a_p + on_velocity_rows
        a_f = a_f + on_force_rows
    if not in_contact:
        a_f = a_f + guarded_acceleration(values.constraint_value, C_dot, approach_reference, desired_force, mask,
                                         phase, constants.approach_speed, constants.approach_gain)
    task_acceleration = space.task_acceleration(values, a_p, a_f)       # (3.0-11)

    u_f = force_command(desired_force, gains, e_f, xi, mask, in_contact)
    F_h = held_row_compensation(force, mask, wrench_valid, mode, constants.compensate_tangential_force)
    if F_h is not None:
        u_f = u_f + F_h
    tau_f = force_torque(J, values.force_projection, u_f, values.velocity_projection, (F_m, F_c))
    torque, base_torque, sigma_min, lambda_squared = joint_torque(
        plant, plant_context, forces, J, task_acceleration - kinematics.bias, tau_f, constants, dynamics)

    B_inverse = constants.actuation_from_torque

    def base_actuation():
        torque_0 = base_torque if base_torque is not None else plant.CalcInverseDynamics(
            plant_context, constants.zero_acceleration, forces)
        return B_inverse @ torque_0

    actuation, scale, clipped = saturate(B_inverse @ torque, base_actuation, constants.effort_limits)
    if not all_finite(actuation):
        raise FloatingPointError(f"HybridController: non-finite actuation {value(actuation).tolist()} at "
                                 f"q = {value(plant.GetPositions(plant_context)).tolist()}")
    frozen = constants.anti_windup and (scale < 1.0 or clipped)           # conditional integration

    solution = ControlSolution()
    solution.actuation = actuation
    solution.velocity_error = e_p_dot
    solution.force_error = e_f
    solution.constraint_value = values.constraint_value
    solution.projected_velocity = projected_velocity
    solution.force = force
    solution.tangential_force = tangential_force
    solution.force_integral_rate, solution.position_error_rate = integral_rates(e_p_dot, e_f, frozen, in_contact)
    solution.wrench_valid = wrench_valid
    solution.contact_phase = int(phase)
    solution.saturation_scale = scale
    solution.actuator_clipped = clipped
    solution.smallest_singular_value = sigma_min
    solution.singularity_damping = lambda_squared
    return solution
