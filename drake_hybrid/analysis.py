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

def equilibrium_config(config, bandwidth_hz=200.0):
    """The continuous-time version of ``config`` at rest: continuous plant and controller, a
    low-pass on the wrench (to break the algebraic loop), zero desired velocity, zero start
    integrals. Its start (in contact, pressing with F_d) is an equilibrium of the closed loop."""
    from drake_hybrid.scenarios import ScenarioConfig  # noqa: F401  (type of config)
    from drake_hybrid.sources import Profile
    import copy

    c = copy.deepcopy(config)
    c.time_step = 0.0
    c.control_period = 0.0
    if not c.sensor.bandwidth_hz > 0:
        c.sensor.bandwidth_hz = bandwidth_hz
    size = len(c.desired_velocity.value)
    c.desired_velocity = Profile(kind="constant", value=[0.0] * size)
    c.desired_force = Profile(kind="constant", value=list(c.desired_force.evaluate(0.0)[0]))
    c.start.force_integral = []
    c.start.position_error = []
    c.start.in_contact = True
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
