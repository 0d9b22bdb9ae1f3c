"""Stability analysis: designed eigenvalues, closed-loop linearization, matching.

* ``predicted_eigenvalues``: the eigenvalues the gains design (spec section 4
  table): -eig(K_v); the roots of s^2 + K_v s + K_p (position and impedance
  modes); eig(-(I + K_fp)^-1 K_fi).
* ``predicted_errors``: the error trajectories those loops predict from an
  initial condition (for plots and tracking tests).
* ``linearize_continuous``: Drake's ``Linearize`` of a continuous closed loop
  (continuous plant, continuous controller, low-pass on the wrench) at a
  contact equilibrium.
* ``match_eigenvalues``: pairs every predicted eigenvalue with a distinct
  measured one (minimum total relative distance) and says which are within
  tolerance.
"""

from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import expm
from scipy.optimize import linear_sum_assignment

from drake_hybrid.gains import ControlMode


@dataclass
class PredictedEigenvalues:
    """Designed eigenvalues, by loop."""

    velocity: np.ndarray          # -eig(K_v), or the roots of s^2 + K_v s + K_p
    force: np.ndarray             # eig(-(I + K_fp)^-1 K_fi)
    marginal: int = 0             # zero eigenvalues expected: k = d - m (see predicted_eigenvalues)

    @property
    def designed(self):
        return np.concatenate([self.velocity, self.force])

    @property
    def all(self):
        return np.concatenate([self.designed, np.zeros(self.marginal)])


def velocity_loop_matrix(gains, mode):
    """A of the velocity loop: e_p'-dot = A e_p' (velocity mode) or d/dt [e_p; e_p'] = A [e_p; e_p']."""
    K_v, K_p = gains.velocity, gains.position
    k = K_v.shape[0]
    if ControlMode.parse(mode).integrates_position:
        return np.block([[np.zeros((k, k)), np.eye(k)], [-K_p, -K_v]])
    return -K_v


def predicted_eigenvalues(gains, mode, kinematic_rows=0, redundancy=0):
    """The closed-loop eigenvalues the validated gains design (``ValidatedGains``).

    Besides the designed ones, a linearized closed loop has k = d - m zero
    eigenvalues: in velocity mode the positions along the constraint are not
    regulated (any point of N is an equilibrium); in position and impedance
    modes the controller's integral e_p and the plant's tangent position move
    together (their difference is conserved), which leaves one zero per row.

    Each of ``kinematic_rows`` (rows the controller holds, not the contact)
    replaces a force eigenvalue by the roots -w_c, -2 w_c of C-ddot + 3 w_c C-dot
    + 2 w_c^2 C = 0 and leaves its (frozen) force integral as another zero.
    The force loop's eigenvalues are then those of the force-controlled rows
    (``gains.force_rate`` restricted to them).

    A redundant arm (``redundancy`` = n - d > 0) adds its self-motion: the
    null-space damping q-ddot_0 = -K_n q-dot gives -K_n and a zero per extra joint.
    """
    mode = ControlMode.parse(mode)
    velocity = np.linalg.eigvals(velocity_loop_matrix(gains, mode))
    kinematic = list(kinematic_rows) if not isinstance(kinematic_rows, int) else list(range(kinematic_rows))
    m = gains.force_rate.shape[0]
    physical = [i for i in range(m) if i not in kinematic]
    force = np.linalg.eigvals(-gains.force_rate[np.ix_(physical, physical)]) if physical else np.zeros(0)
    held = np.tile([-gains.constraint_frequency, -2.0 * gains.constraint_frequency], len(kinematic)).astype(complex)
    null_space = np.full(redundancy, -gains.null_space_damping, dtype=complex)
    return PredictedEigenvalues(velocity=np.sort_complex(np.concatenate([velocity, null_space])),
                                force=np.sort_complex(np.concatenate([force, held])),
                                marginal=gains.velocity.shape[0] + len(kinematic) + redundancy)


def predicted_errors(gains, mode, times, velocity_error0, force_integral0, position_error0=None, kinematic_rows=()):
    """Errors predicted by (3.1-14), (3.1-15) / Remark 3 from an initial condition.

    Kinematic rows have no force loop (their force error is zero).
    Returns (velocity_error (N x k), force_error (N x m), position_error (N x k)).
    """
    mode = ControlMode.parse(mode)
    times = np.asarray(times, dtype=float)
    k = gains.velocity.shape[0]
    A = velocity_loop_matrix(gains, mode)
    if mode.integrates_position:
        e_p0 = np.zeros(k) if position_error0 is None else np.asarray(position_error0, dtype=float)
        initial = np.concatenate([e_p0, velocity_error0])
        states = np.array([expm(A * t) @ initial for t in times])
        position, velocity = states[:, :k], states[:, k:]
    else:
        velocity = np.array([expm(A * t) @ velocity_error0 for t in times])
        position = np.zeros_like(velocity)
    G = gains.force_rate.copy()
    kinematic = list(kinematic_rows)
    G[kinematic, :] = 0.0
    G[:, kinematic] = 0.0
    xi = np.array([expm(-G * t) @ np.asarray(force_integral0, dtype=float) for t in times])
    force = -(G @ xi.T).T                                             # e_f = xi-dot = -G xi
    return velocity, force, position


def controller_prediction(controller):
    """``predicted_eigenvalues`` for a HybridController (its gains, mode, kinematic rows, n - d)."""
    return predicted_eigenvalues(controller.validated_gains(), controller.mode, controller.kinematic_rows,
                                 controller.num_joints - controller.task_size)


def design_time_constant(gains, mode, kinematic_rows=()):
    """The slowest designed time constant 1 / min |Re(lambda)| (s)."""
    eigenvalues = predicted_eigenvalues(gains, mode, kinematic_rows).designed
    return 1.0 / np.min(np.abs(eigenvalues.real))


@dataclass
class EigenvalueMatch:
    predicted: np.ndarray
    measured: np.ndarray                               # all closed-loop eigenvalues
    partner: np.ndarray                                # measured eigenvalue matched to each predicted one
    relative_error: np.ndarray                         # |partner - predicted| / |predicted|
    tolerance: float
    matched: bool
    extra: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))   # measured, not matched
    unstable_extra: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    marginal_partners: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))  # nearest 0

    def as_dict(self):
        pairs = lambda values: [[float(np.real(v)), float(np.imag(v))] for v in values]
        return {"predicted": pairs(self.predicted), "closed_loop": pairs(self.measured),
                "matched_partners": pairs(self.partner), "relative_error": [float(e) for e in self.relative_error],
                "tolerance": self.tolerance, "matched": bool(self.matched), "extra_modes": pairs(self.extra),
                "marginal_modes": pairs(self.marginal_partners), "unstable_modes": pairs(self.unstable_extra)}


def match_eigenvalues(designed, measured, tolerance=0.05, marginal=0, marginal_real=None):
    """Pair each designed eigenvalue with a distinct measured one (Hungarian algorithm on the
    relative distance |mu - lambda| / |lambda|) and sort out the rest.

    The designed eigenvalues are the nonzero ones of ``predicted_eigenvalues``. The theory also
    predicts ``marginal`` zero eigenvalues (unregulated positions, frozen integrals): the
    ``marginal`` unmatched measured eigenvalues nearest to 0 are reported as their partners
    (``marginal_partners``); compliant contact may move them slightly either way. Every other
    unmatched eigenvalue is an extra mode (contact, filter, sampling, joint space).

    ``matched`` is True when every designed eigenvalue has a partner within ``tolerance`` and no
    unmatched eigenvalue (marginal or extra) has a real part above ``marginal_real`` (default
    ``tolerance`` times 1 1/s: slower than 5 % per second of growth is counted as marginal, not
    unstable).
    """
    designed = np.asarray(designed, dtype=complex)
    measured = np.asarray(measured, dtype=complex)
    marginal_real = tolerance * 1.0 if marginal_real is None else marginal_real
    cost = np.abs(measured[None, :] - designed[:, None]) / np.abs(designed)[:, None]
    rows, cols = linear_sum_assignment(cost)
    order = np.argsort(rows)
    rows, cols = rows[order], cols[order]
    partner = measured[cols]
    relative_error = cost[rows, cols]
    rest = np.delete(measured, cols)
    by_size = np.argsort(np.abs(rest))
    marginal_partners = rest[by_size[:marginal]]
    extra = rest[by_size[marginal:]]
    unstable = rest[rest.real > marginal_real]
    matched = bool(np.all(relative_error <= tolerance) and unstable.size == 0)
    return EigenvalueMatch(predicted=designed, measured=measured, partner=partner, relative_error=relative_error,
                           tolerance=tolerance, matched=matched, extra=extra, unstable_extra=unstable,
                           marginal_partners=marginal_partners)


# ------------------------------------------------------------------------------------------------
# Linearization of a scenario's closed loop
# ------------------------------------------------------------------------------------------------

def equilibrium_config(config, bandwidth_hz=200.0):
    """The continuous-time version of ``config`` at rest: continuous plant and controller, a
    low-pass on the wrench (to break the algebraic loop), zero desired velocity, zero start
    integrals, no sensor faults or contact supervision. Its start (in contact, pressing with
    F_d) is an equilibrium of the closed loop."""
    import copy

    c = copy.deepcopy(config)
    c.time_step = 0.0
    c.control_period = 0.0
    if not c.sensor.bandwidth_hz > 0:
        c.sensor.bandwidth_hz = bandwidth_hz
    _at_rest(c)
    _without_fault_handling(c)
    return c


def _without_fault_handling(config):
    """In place: start in contact, no contact supervisor, no sensor faults, no wrench conditioner
    (sampled systems outside the law, with their own timing); the model error is kept."""
    from drake_hybrid.faults import SensorFaultConfig

    config.start.in_contact = True
    config.supervision.enabled = False
    config.sensor_faults = SensorFaultConfig()
    config.sensor.condition = False


def _at_rest(config):
    """Zero desired velocity, constant desired force F_d(0), zero start integrals (in place)."""
    from drake_hybrid.sources import Profile
    from drake_hybrid.tasks import get_task

    size = get_task(config.task).constraint_space(config).velocity_size
    config.desired_velocity = Profile(kind="constant", value=[0.0] * size)
    config.desired_force = Profile(kind="constant", value=list(config.desired_force.evaluate(0.0)[0]))
    config.start.force_integral = []
    config.start.position_error = []


@dataclass
class Linearization:
    A: np.ndarray
    eigenvalues: np.ndarray
    equilibrium_residual: float        # max |x-dot| at the linearization point
    predicted: PredictedEigenvalues
    match: EigenvalueMatch
    wall_time: float


def linearize_continuous(config, tolerance=0.05, bandwidth_hz=200.0):
    """Linearize the continuous closed loop of ``config`` at its contact equilibrium.

    Builds ``equilibrium_config(config)``, sets the start, checks it is an
    equilibrium, runs Drake's ``Linearize`` (AutoDiffXd through plant,
    contact, sensor, filter and controller) and matches eig(A) against the
    designed eigenvalues.
    """
    import time

    from pydrake.systems.primitives import Linearize

    from drake_hybrid.scenarios import build_scenario, set_initial_conditions

    c = equilibrium_config(config, bandwidth_hz)
    scenario = build_scenario(c, with_loggers=False)
    context = scenario.diagram.CreateDefaultContext()
    set_initial_conditions(scenario, context)
    derivatives = scenario.diagram.EvalTimeDerivatives(context).CopyToVector()
    residual = float(np.max(np.abs(derivatives)))
    if not (context.num_abstract_states() == 0 and context.has_only_continuous_state()):
        raise ValueError("linearize_continuous needs a purely continuous closed loop")
    start = time.perf_counter()
    linear = Linearize(scenario.diagram, context, equilibrium_check_tolerance=np.inf)
    wall = time.perf_counter() - start
    A = np.asarray(linear.A())
    eigenvalues = np.linalg.eigvals(A)
    predicted = controller_prediction(scenario.controller)
    match = match_eigenvalues(predicted.designed, eigenvalues, tolerance=tolerance, marginal=predicted.marginal)
    return Linearization(A=A, eigenvalues=eigenvalues, equilibrium_residual=residual, predicted=predicted,
                         match=match, wall_time=wall)


@dataclass
class DiscreteLinearization:
    A: np.ndarray                    # Jacobian of the one-period map x+ = f(x)
    multipliers: np.ndarray          # eig(A)
    eigenvalues: np.ndarray          # log(multipliers) / period: the equivalent continuous eigenvalues
    period: float
    equilibrium_residual: float      # max |f(x) - x| at the linearization point
    predicted: PredictedEigenvalues
    match: EigenvalueMatch
    wall_time: float


def linearize_discrete(config, tolerance=0.05, epsilon=1e-6, settle_time=0.0):
    """Linearize a discrete closed loop (discrete SAP plant and sampled controller) at its equilibrium.

    For plants that only exist in discrete time (the crank: its SAP weld constraint needs a discrete
    plant). The closed loop is rebuilt with every discrete update at the same instants (the
    controller ticks at k h, one period of delay; the plant's output ports unsampled, so the state
    is just the plant's and the controller's), which makes it one map x+ = f(x) per period
    (``EvalUniquePeriodicDiscreteUpdate``). Its Jacobian is taken by central differences
    (``epsilon``; DRAKE_NOTES: much smaller is noisy with SAP), and the multipliers mu are mapped
    to continuous-time eigenvalues log(mu) / h. The one period of actuation delay shifts the
    designed eigenvalues by about lambda^2 h / 2 (0.5 % at -10 1/s and 1 kHz).

    ``settle_time`` (s): first simulate the rebuilt loop at rest for this long, so that the
    compliant constraint forces settle onto the equilibrium.
    """
    import copy
    import time

    from pydrake.systems.analysis import Simulator

    from drake_hybrid.scenarios import build_scenario, set_initial_conditions

    c = copy.deepcopy(config)
    if not c.time_step > 0:
        raise ValueError("linearize_discrete needs a discrete plant (time_step > 0)")
    c.control_period = c.time_step
    c.log_period = c.time_step
    c.sensor.bandwidth_hz = 0.0
    _at_rest(c)
    _without_fault_handling(c)
    scenario = build_scenario(c, with_loggers=False, sampled_plant_outputs=False, controller_sample_lead=False)
    simulator = Simulator(scenario.diagram)
    context = simulator.get_mutable_context()
    set_initial_conditions(scenario, context)
    simulator.Initialize()
    if settle_time > 0:
        simulator.AdvanceTo(settle_time)
    if context.num_abstract_states() != 0 or context.num_continuous_states() != 0:
        raise ValueError("linearize_discrete needs a closed loop with discrete state only")
    diagram = scenario.diagram

    def state_vector(ctx):
        return np.concatenate([ctx.get_discrete_state(i).CopyToVector()
                               for i in range(ctx.num_discrete_state_groups())])

    def set_state(ctx, x):
        start = 0
        for i in range(ctx.num_discrete_state_groups()):
            size_i = ctx.get_discrete_state(i).size()
            ctx.SetDiscreteState(i, x[start:start + size_i])
            start += size_i

    def step(x):
        work = context.Clone()
        set_state(work, x)
        update = diagram.EvalUniquePeriodicDiscreteUpdate(work)
        return np.concatenate([update.get_vector(i).CopyToVector() for i in range(update.num_groups())])

    x0 = state_vector(context)
    start = time.perf_counter()
    residual = float(np.max(np.abs(step(x0) - x0)))
    A = np.zeros((x0.size, x0.size))
    for j in range(x0.size):
        dx = np.zeros(x0.size)
        dx[j] = epsilon
        A[:, j] = (step(x0 + dx) - step(x0 - dx)) / (2 * epsilon)
    wall = time.perf_counter() - start
    multipliers = np.linalg.eigvals(A)
    h = c.time_step
    # Multipliers at 0 (pure delays, e.g. the held torque) have no continuous-time counterpart.
    keep = np.abs(multipliers) > 1e-9
    eigenvalues = np.log(multipliers[keep].astype(complex)) / h
    predicted = controller_prediction(scenario.controller)
    match = match_eigenvalues(predicted.designed, eigenvalues, tolerance=tolerance, marginal=predicted.marginal)
    return DiscreteLinearization(A=A, multipliers=multipliers, eigenvalues=eigenvalues, period=h,
                                 equilibrium_residual=residual, predicted=predicted, match=match, wall_time=wall)
