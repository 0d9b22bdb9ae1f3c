"""Stability analysis: designed eigenvalues, closed-loop linearization, matching.

* ``predicted_eigenvalues``: the eigenvalues the gains design (spec section 4
  table): -eig(K_v); the roots of s^2 + K_v s + K_p (position and impedance
  modes); eig(-(I + K_fp)^-1 K_fi).
* ``predicted_errors``: the error trajectories those loops predict from an
  initial condition (for plots and tracking tests).
* ``linearize_continuous``: Drake's ``Linearize`` of a continuous closed loop
  (continuous plant, continuous controller, low-pass on the wrench) at a
  contact equilibrium.
* ``linearize_discrete``: the Jacobian of the sampled closed loop's
  one-period map (discrete plant, sampled controller) by central
  differences: multipliers that see the control period.
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


def predicted_eigenvalues(gains, mode):
    """The closed-loop eigenvalues the validated gains design (``ValidatedGains``).

    Besides the designed ones, a linearized closed loop has k = d - m zero
    eigenvalues: in velocity mode the positions along the constraint are not
    regulated (any point of N is an equilibrium); in position and impedance
    modes the controller's integral e_p and the plant's tangent position move
    together (their difference is conserved), which leaves one zero per row.
    """
    mode = ControlMode.parse(mode)
    velocity = np.linalg.eigvals(velocity_loop_matrix(gains, mode))
    force = np.linalg.eigvals(-gains.force_rate)
    return PredictedEigenvalues(velocity=np.sort_complex(velocity), force=np.sort_complex(force),
                                marginal=gains.velocity.shape[0])


def predicted_errors(gains, mode, times, velocity_error0, force_integral0, position_error0=None):
    """Errors predicted by (3.1-14), (3.1-15) / Remark 3 from an initial condition.

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
    G = gains.force_rate
    xi = np.array([expm(-G * t) @ np.asarray(force_integral0, dtype=float) for t in times])
    force = -(G @ xi.T).T                                             # e_f = xi-dot = -G xi
    return velocity, force, position


def design_time_constant(gains, mode):
    """The slowest designed time constant 1 / min |Re(lambda)| (s)."""
    eigenvalues = predicted_eigenvalues(gains, mode).designed
    return 1.0 / np.min(np.abs(eigenvalues.real))


@dataclass
class EigenvalueMatch:
    predicted: np.ndarray
    measured: np.ndarray                               # all closed-loop eigenvalues
    partner: np.ndarray                                # measured eigenvalue matched to each predicted one
    relative_error: np.ndarray                         # |partner - predicted| / max(|predicted|, floor)
    tolerance: float
    matched: bool
    extra: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))   # measured, not matched
    unstable_extra: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))

    def as_dict(self):
        pairs = lambda values: [[float(np.real(v)), float(np.imag(v))] for v in values]
        return {"predicted": pairs(self.predicted), "closed_loop": pairs(self.measured),
                "matched_partners": pairs(self.partner), "relative_error": [float(e) for e in self.relative_error],
                "tolerance": self.tolerance, "matched": bool(self.matched), "extra_modes": pairs(self.extra),
                "unstable_extra_modes": pairs(self.unstable_extra)}


def match_eigenvalues(predicted, measured, tolerance=0.05, zero_floor=1.0, marginal_real=1e-6):
    """Assign each predicted eigenvalue a distinct measured one (Hungarian algorithm on the
    relative distance |mu - lambda| / max(|lambda|, zero_floor)).

    ``matched`` is True when every relative distance is within ``tolerance``
    and every unmatched measured eigenvalue has real part < ``marginal_real``
    (in the closed left half-plane up to numerical noise; the extra modes are
    the contact, filter and joint-space modes the paper's rigid model has not).
    A predicted 0 (an unregulated position) is matched with absolute tolerance
    ``tolerance * zero_floor``.
    """
    predicted = np.asarray(predicted, dtype=complex)
    measured = np.asarray(measured, dtype=complex)
    scale = np.maximum(np.abs(predicted), zero_floor)
    cost = np.abs(measured[None, :] - predicted[:, None]) / scale[:, None]
    rows, cols = linear_sum_assignment(cost)
    order = np.argsort(rows)
    rows, cols = rows[order], cols[order]
    partner = measured[cols]
    relative_error = cost[rows, cols]
    extra = np.delete(measured, cols)
    unstable = extra[extra.real >= marginal_real]
    matched = bool(np.all(relative_error <= tolerance) and unstable.size == 0)
    return EigenvalueMatch(predicted=predicted, measured=measured, partner=partner, relative_error=relative_error,
                           tolerance=tolerance, matched=matched, extra=extra, unstable_extra=unstable)


# ------------------------------------------------------------------------------------------------
# Linearization of a scenario's closed loop
# ------------------------------------------------------------------------------------------------

def at_rest_config(config):
    """``config`` at rest, its sampling kept: zero desired velocity, constant F_d(0), zero start
    integrals, starting in contact. Its start is an equilibrium of the closed loop."""
    import copy

    from drake_hybrid.sources import Profile

    c = copy.deepcopy(config)
    size = len(c.desired_velocity.value)
    c.desired_velocity = Profile(kind="constant", value=[0.0] * size)
    c.desired_force = Profile(kind="constant", value=list(c.desired_force.evaluate(0.0)[0]))
    c.start.force_integral = []
    c.start.position_error = []
    c.start.in_contact = True
    return c


def equilibrium_config(config, bandwidth_hz=200.0):
    """The continuous-time version of ``config`` at rest (``at_rest_config``): continuous plant and
    controller, a low-pass on the wrench (to break the algebraic loop)."""
    c = at_rest_config(config)
    c.time_step = 0.0
    c.control_period = 0.0
    if not c.sensor.bandwidth_hz > 0:
        c.sensor.bandwidth_hz = bandwidth_hz
    return c


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
    predicted = predicted_eigenvalues(scenario.controller.validated_gains(), scenario.controller.mode)
    match = match_eigenvalues(predicted.all, eigenvalues, tolerance=tolerance)
    return Linearization(A=A, eigenvalues=eigenvalues, equilibrium_residual=residual, predicted=predicted,
                         match=match, wall_time=wall)


# ------------------------------------------------------------------------------------------------
# The sampled closed loop: Jacobian of the one-period map
# ------------------------------------------------------------------------------------------------

@dataclass
class DiscreteLinearization:
    Phi: np.ndarray                    # d x_{k+1} / d x_k over one control period
    multipliers: np.ndarray            # eig(Phi)
    eigenvalues: np.ndarray            # log(multipliers) / h: the equivalent continuous eigenvalues (1/s)
    period: float
    equilibrium_residual: float        # max |x_{k+1} - x_k| at the linearization point
    predicted: PredictedEigenvalues
    match: EigenvalueMatch
    wall_time: float


def linearize_discrete(config, epsilon=1e-5, tolerance=0.05, periods=1):
    """Jacobian of the sampled closed loop's one-period map at its contact equilibrium.

    The map Phi takes the vector state x_k (plant q, v; controller xi, e_p and
    held torque) at t_k = k h - delta/2, between the controller's tick at
    k h - delta and the plant's step at k h (docs/design.md, "Sampling"), to
    x_{k+1} one control period h later, by simulating the full diagram. At that
    instant the plant's sampled contact results (abstract state) are overwritten
    by the step at k h before the next tick reads them, so x_k is the whole
    state of the loop and Phi is a function of it alone. Its Jacobian is taken
    by central differences (``epsilon``, absolute, per state; about 1e-5 with
    SAP, smaller is noisy). Multipliers inside the unit circle mean a stable
    sampled loop: this sees the sampling, the zero-order hold and the SAP step
    that the continuous linearization cannot. ``eigenvalues`` are
    log(multipliers) / (periods h), matched against the designed continuous
    ones; ``periods`` > 1 differentiates the map over that many periods.

    Accuracy (window task, 5 MPa pad, 1 ms): the SAP solve and the tessellated
    contact surface make the map only piecewise smooth, so the slow rates
    (multipliers near 1) move by a few 1/s with ``epsilon`` (1e-4, 1e-5,
    1e-6: the velocity-loop rates between -3.6 and -10.7 1/s against the
    designed -10, -8; a -5.0 1/s mode in all). Multipliers far outside the
    unit circle (the stiff-contact force loop: |mu| 1.1 to 1.9) are robust.

    Needs a discrete plant, a sampled controller with a period that is a whole
    number of plant steps, and no wrench filter (a filter would sample the
    contact results at k h, where the stale abstract state would enter).
    """
    import time

    from pydrake.systems.analysis import InitializeParams, Simulator

    from drake_hybrid.controller import SAMPLE_LEAD
    from drake_hybrid.scenarios import build_scenario, set_initial_conditions

    h, time_step = float(config.control_period), float(config.time_step)
    if not (time_step > 0 and h > 0):
        raise ValueError("linearize_discrete needs a discrete plant (time_step > 0) and a sampled controller "
                         f"(control_period > 0); got time_step = {time_step}, control_period = {h}")
    steps = h / time_step
    if abs(steps - round(steps)) > 1e-9 * steps:
        raise ValueError(f"linearize_discrete needs control_period to be a whole number of plant steps; "
                         f"got control_period = {h}, time_step = {time_step}")
    if config.sensor.bandwidth_hz > 0:
        raise ValueError("linearize_discrete needs sensor.bandwidth_hz = 0 (a sampled wrench filter reads the "
                         "plant's sampled contact results at the plant's steps, outside the map's vector state)")
    if not epsilon > 0:
        raise ValueError(f"epsilon must be positive, got {epsilon}")

    c = at_rest_config(config)
    scenario = build_scenario(c, with_loggers=False)
    diagram = scenario.diagram
    base = diagram.CreateDefaultContext()
    set_initial_conditions(scenario, base)
    t_k = h * (1.0 - 0.5 * SAMPLE_LEAD)
    base.SetTime(t_k)
    groups = base.num_discrete_state_groups()
    sizes = [base.get_discrete_state(i).size() for i in range(groups)]
    continuous_size = base.num_continuous_states()

    def get_state(context):
        parts = [context.get_discrete_state(i).CopyToVector() for i in range(groups)]
        if continuous_size:
            parts.append(context.get_continuous_state_vector().CopyToVector())
        return np.concatenate(parts)

    def one_period(x):
        context = base.Clone()
        offset = 0
        for i, size in enumerate(sizes):
            context.SetDiscreteState(i, x[offset:offset + size])
            offset += size
        if continuous_size:
            context.SetContinuousState(x[offset:])
        simulator = Simulator(diagram, context)
        # No initialization events: they would recompute the held torque from the stale sensor reading.
        simulator.Initialize(InitializeParams(suppress_initialization_events=True))
        simulator.AdvanceTo(t_k + periods * h)
        return get_state(context)

    start = time.perf_counter()
    x0 = get_state(base)
    residual = float(np.max(np.abs(one_period(x0) - x0)))
    Phi = np.zeros((x0.size, x0.size))
    for j in range(x0.size):
        dx = np.zeros(x0.size)
        dx[j] = epsilon
        Phi[:, j] = (one_period(x0 + dx) - one_period(x0 - dx)) / (2 * epsilon)
    wall = time.perf_counter() - start
    multipliers = np.linalg.eigvals(Phi)
    # Multipliers at 0 (the held torque is recomputed every tick) have no continuous counterpart:
    # floor |mu| so that they map to a large negative real part instead of -inf.
    magnitude = np.maximum(np.abs(multipliers), np.finfo(float).tiny)
    eigenvalues = (np.log(magnitude) + 1j * np.angle(multipliers)) / (periods * h)
    predicted = predicted_eigenvalues(scenario.controller.validated_gains(), scenario.controller.mode)
    match = match_eigenvalues(predicted.all, eigenvalues, tolerance=tolerance)
    return DiscreteLinearization(Phi=Phi, multipliers=multipliers, eigenvalues=eigenvalues, period=h,
                                 equilibrium_residual=residual, predicted=predicted, match=match, wall_time=wall)
