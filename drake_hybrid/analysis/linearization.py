"""Stability analysis: designed eigenvalues, closed-loop linearization, matching.

* ``predicted_eigenvalues``: the eigenvalues the gains design (docs/theory.md §4,
  the table): -eig(K_v); the roots of s^2 + K_v s + K_p (position and impedance
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
  tolerance; ``predicted_match``: the match in which every miss is a predicted one
  (a task's shifted design, an unstable mode its diagnosis predicts), if any.

Size: the designed eigenvalues and the three linearizations (continuous, discrete, the sampled
loop's one-period map) are compared with each other; splitting them is planned with the law
module (issue 13 closing note).
"""

import copy
import dataclasses
import numbers
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import expm
from scipy.optimize import linear_sum_assignment

from pydrake.systems.analysis import ApplySimulatorConfig, InitializeParams, Simulator
from pydrake.systems.primitives import Linearize

from drake_hybrid.analysis.derivatives import JACOBIAN_TOLERANCE, JacobianCheck, checked_state_jacobian
from drake_hybrid.analysis.environment import impedance_environment_shifts, impedance_matrix
from drake_hybrid.analysis.modes import diagnose_unstable_modes, explained_modes
from drake_hybrid.control.damping import step_task_mobility
from drake_hybrid.control.gains import ControlMode, ValidatedGains
from drake_hybrid.control.law import impedance_blocks
from drake_hybrid.control.sampling import SAMPLE_LEAD
from drake_hybrid.core.arguments import (boolean, complex_vector, describe, function, instance, joint_rows, nonnegative,
                                         number, positive, relative_tolerance, text, vector)
from drake_hybrid.core.errors import ArgumentError, ConfigError, NotAtEquilibriumError
from drake_hybrid.core.progress import quiet
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.station.root_context import check_root_context
from drake_hybrid.systems.faults import SensorFaultConfig
from drake_hybrid.systems.sources import Profile
from drake_hybrid.systems.wrist_force_torque_sensor import WristForceTorqueSensor
from drake_hybrid.tasks.config import ScenarioConfig
from drake_hybrid.tasks.registry import get_task


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


def _design(gains, mode, owner):
    """(``gains``, ``mode`` as a ControlMode) checked: ValidatedGains (``HybridGains.matrices(k, m, mode)``)
    and a control mode; ArgumentError naming ``owner`` otherwise."""
    instance(gains, "gains", owner, ValidatedGains, what="ValidatedGains (HybridGains(...).matrices(k, m, mode))")
    return gains, ControlMode.parse(mode, owner)


def _kinematic_rows(kinematic_rows, force_size, owner):
    """The rows held kinematically: a count (the first ones) or a list of distinct row indices < ``force_size``."""
    allowed = f"a count or a list of distinct row indices < {force_size}"
    if isinstance(kinematic_rows, numbers.Integral) and not isinstance(kinematic_rows, (bool, np.bool_)):
        count = number(kinematic_rows, "kinematic_rows", owner, low=0, high=force_size, integer=True)
        return list(range(count))
    if not isinstance(kinematic_rows, (list, tuple, range, np.ndarray)):
        raise ArgumentError(f"{owner}: kinematic_rows must be {allowed}, got {describe(kinematic_rows)}")
    rows = [number(row, "kinematic_rows", owner, low=0, high=force_size - 1, integer=True) for row in kinematic_rows]
    if len(set(rows)) != len(rows):
        raise ArgumentError(f"{owner}: kinematic_rows must be {allowed}, got {describe(kinematic_rows)}")
    return rows


def velocity_loop_matrix(gains, mode):
    """A of the velocity loop: e_p'-dot = A e_p' (velocity mode) or d/dt [e_p; e_p'] = A [e_p; e_p']."""
    gains, mode = _design(gains, mode, "velocity_loop_matrix")
    if mode.integrates_position:
        return impedance_matrix(gains.velocity, gains.position)      # (3.2-11) with no environment
    return -gains.velocity


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
    owner = "predicted_eigenvalues"
    gains, mode = _design(gains, mode, owner)
    m = gains.force_rate.shape[0]
    kinematic = _kinematic_rows(kinematic_rows, m, owner)
    redundancy = number(redundancy, "redundancy", owner, low=0, integer=True, unit="joints beyond the task's d")
    velocity = np.linalg.eigvals(velocity_loop_matrix(gains, mode))
    physical = [i for i in range(m) if i not in kinematic]
    force = np.linalg.eigvals(-gains.force_rate[np.ix_(physical, physical)]) if physical else np.zeros(0)
    held = np.tile([-gains.constraint_frequency, -2.0 * gains.constraint_frequency], len(kinematic)).astype(complex)
    null_space = np.full(redundancy, -gains.null_space_damping, dtype=complex)
    return PredictedEigenvalues(velocity=np.sort_complex(np.concatenate([velocity, null_space])),
                                force=np.sort_complex(np.concatenate([force, held])),
                                marginal=gains.velocity.shape[0] + len(kinematic) + redundancy)


def designed_eigenvalues_by_row(gains, mode, kinematic_rows=(), redundancy=0):
    """The designed eigenvalues row by row: ([velocity row i's], [force row j's], [null-space ones]), or
    None when a gain couples rows (a full matrix: then only the loops have eigenvalues, not the rows).

    With diagonal gains each row is a loop of its own: velocity row i's eigenvalue is -K_v[i, i], or the
    two roots of s^2 + K_v[i, i] s + K_p[i, i] (position and impedance modes); force row j's is
    -K_fi[j, j] / (1 + K_fp[j, j]), or -w_c and -2 w_c when the controller holds it (``kinematic_rows``).
    Each is ``predicted_eigenvalues`` of that row's gains alone.
    """
    owner = "designed_eigenvalues_by_row"
    gains, mode = _design(gains, mode, owner)
    kinematic_rows = _kinematic_rows(kinematic_rows, gains.force_integral.shape[0], owner)
    redundancy = number(redundancy, "redundancy", owner, low=0, integer=True, unit="joints beyond the task's d")
    matrices = (gains.velocity, gains.position, gains.force_proportional, gains.force_integral, gains.impedance_mass)
    if any(np.count_nonzero(matrix - np.diag(np.diag(matrix))) for matrix in matrices):
        return None
    kinematic = set(kinematic_rows)

    def row_gains(i, j):
        pick = lambda matrix, index: matrix[index:index + 1, index:index + 1] if index is not None else np.eye(1)
        return ValidatedGains(pick(gains.velocity, i), pick(gains.position, i), pick(gains.force_proportional, j),
                              pick(gains.force_integral, j), gains.null_space_damping, gains.constraint_frequency,
                              pick(gains.impedance_mass, i))

    velocity = [predicted_eigenvalues(row_gains(i, None), mode).velocity for i in range(gains.velocity.shape[0])]
    force = [predicted_eigenvalues(row_gains(None, j), mode, [0] if j in kinematic else []).force
             for j in range(gains.force_integral.shape[0])]
    return velocity, force, [complex(-gains.null_space_damping)] * redundancy


def predicted_errors(gains, mode, times, velocity_error0, force_integral0, position_error0=None, kinematic_rows=()):
    """Errors predicted by (3.1-14), (3.1-15) / Remark 3 from an initial condition.

    Kinematic rows have no force loop (their force error is zero).
    Returns (velocity_error (N x k), force_error (N x m), position_error (N x k)).
    """
    owner = "predicted_errors"
    gains, mode = _design(gains, mode, owner)
    k, m = gains.velocity.shape[0], gains.force_integral.shape[0]
    times = vector(times, "times", owner, unit="s")
    velocity_error0 = vector(velocity_error0, "velocity_error0", owner, k)
    force_integral0 = vector(force_integral0, "force_integral0", owner, m)
    if position_error0 is not None:
        position_error0 = vector(position_error0, "position_error0", owner, k)
    kinematic_rows = _kinematic_rows(kinematic_rows, m, owner)
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
    if not all(hasattr(controller, name) for name in ("validated_gains", "mode", "kinematic_rows", "num_joints")):
        raise ArgumentError(f"controller_prediction: controller must be a HybridController, got {describe(controller)}")
    return predicted_eigenvalues(controller.validated_gains(), controller.mode, controller.kinematic_rows,
                                 controller.num_joints - controller.task_size)


def design_time_constant(gains, mode, kinematic_rows=()):
    """The slowest designed time constant 1 / min |Re(lambda)| (s) (arguments as ``predicted_eigenvalues``)."""
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

    ArgumentError for ``designed`` and ``measured`` that are not vectors of finite numbers (``designed``
    nonzero, no more of them than measured), a ``marginal`` that is not an integer >= 0, a ``tolerance``
    outside (0, 1].
    """
    owner = "match_eigenvalues"
    tolerance = relative_tolerance(tolerance, "tolerance", owner)
    designed = complex_vector(designed, "designed", owner, nonzero=True)
    measured = complex_vector(measured, "measured", owner)
    marginal = number(marginal, "marginal", owner, low=0, integer=True, unit="zero eigenvalues")
    marginal_real = number(tolerance * 1.0 if marginal_real is None else marginal_real, "marginal_real", owner,
                           unit="1/s", allow_none=True)
    if designed.size > measured.size:
        raise ArgumentError(f"{owner}: measured has {measured.size} eigenvalues, fewer than the {designed.size} "
                            "designed ones")
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


def shift_indices(designed, shifts):
    """{index in ``designed``: shift}: each ``tasks.task.EigenvalueShift`` takes one designed
    eigenvalue equal to its ``designed``, not yet taken; ValueError if there is none."""
    designed = np.asarray(designed, dtype=complex)
    taken = {}
    for shift in shifts:
        same = [i for i, value in enumerate(designed)
                if i not in taken and abs(value - shift.designed) <= 1e-9 * max(1.0, abs(shift.designed))]
        if not same:
            raise ValueError(f"a predicted shift of {shift.designed} matches no designed eigenvalue {designed}")
        taken[same[0]] = shift
    return taken


def nyquist_split(modes, period):
    """(modes, the ones at the discrete step's Nyquist frequency): for a one-period map of step ``period``
    (None: a continuous linearization, nothing to split), log(mu)/h of a real multiplier mu < 0 has
    imaginary part +-pi/h; such a mode has no conjugate partner (log's principal branch gives one sign)."""
    modes = np.asarray(modes, dtype=complex)
    if not period:
        return modes, modes[:0]
    at = np.abs(np.abs(modes.imag) - np.pi / period) <= 1e-6 * np.pi / period
    return modes[~at], modes[at]


def shifted_design(designed, shifts):
    """The designed eigenvalues with, for each ``tasks.task.EigenvalueShift``, one equal designed
    eigenvalue replaced by the shift's prediction (order kept)."""
    corrected = np.array(designed, dtype=complex)
    for index, shift in shift_indices(designed, shifts).items():
        corrected[index] = shift.predicted
    return corrected


def predicted_match(result, tolerance=0.05):
    """The match of a linearization ``result`` in which every miss is a predicted one, or None.

    Tries the plain match, then the one against the task's shifted design (``shifted_match``); a
    match counts when every designed eigenvalue is within ``tolerance`` of its partner and every
    unstable extra mode is within ``tolerance`` of the prediction of its diagnosis
    (``result.unstable_modes``, ``analysis.modes.ModeDiagnosis.explained``). ``drake-hybrid analyze``
    exits 0 on it (``--strict``: only on a plain match)."""
    tolerance = relative_tolerance(tolerance, "tolerance", "predicted_match")
    diagnoses = getattr(result, "unstable_modes", [])
    for candidate in (result.match, getattr(result, "shifted_match", None)):
        if (candidate is not None and bool(np.all(candidate.relative_error <= tolerance))
                and explained_modes(candidate.unstable_extra, diagnoses, tolerance)):
            return candidate
    return None


def _task_shifts(task, scenario, root_context, predicted, measured, tolerance):
    """The predicted shifts and the match against the shifted design (no shifts, no match): the
    task's own (physics the paper's model leaves out, e.g. the crank's handle inertia; ``task`` None:
    none), or else, in impedance-force mode, those of the impedance meeting its contact's stiffness
    and damping (``analysis.environment``)."""
    shifts = task.eigenvalue_shifts(scenario, root_context) if task is not None else []
    if not shifts and scenario.controller.mode is ControlMode.IMPEDANCE_FORCE:
        shifts = impedance_environment_shifts(scenario, root_context, predicted.designed, tolerance=tolerance)
    if not shifts:
        return [], None
    match = match_eigenvalues(shifted_design(predicted.designed, shifts), measured, tolerance=tolerance,
                              marginal=predicted.marginal)
    return shifts, match


# ------------------------------------------------------------------------------------------------
# Linearization of a scenario's closed loop
# ------------------------------------------------------------------------------------------------

def at_rest_config(config, owner="at_rest_config"):
    """A copy of ``config`` at rest, its sampling kept: zero desired velocity, constant F_d(0), zero
    start integrals, starting in contact, no contact supervisor, sensor faults or wrench conditioner
    (sampled systems outside the law, with their own timing); the model error is kept; a job's path
    held at a point (``path.hold_at``, its first point unless set). Its start is an equilibrium of
    the closed loop. ArgumentError (naming ``owner``) for a ``config`` that is not a ScenarioConfig."""
    c = copy.deepcopy(_scenario_config(config, owner))
    size = get_task(c.task).constraint_space(c).velocity_size
    c.desired_velocity = Profile(kind="constant", value=[0.0] * size)
    c.desired_force = Profile(kind="constant", value=list(c.desired_force.evaluate(0.0)[0]))
    c.start.force_integral = []
    c.start.position_error = []
    c.start.in_contact = True
    c.supervision.enabled = False
    c.sensor_faults = SensorFaultConfig()
    c.sensor.condition = False
    if c.path.active and c.path.hold_at < 0:     # a job's path: held at its first point (path.hold_at)
        c.path.hold_at = 0.0
    return c


def equilibrium_config(config, bandwidth_hz=200.0, owner="equilibrium_config"):
    """The continuous-time version of ``at_rest_config(config)``: continuous plant and controller,
    a low-pass on the wrench (to break the algebraic loop), and no friction.

    Friction is removed because at rest it sticks: the pad is then held in the tangent directions
    by the contact, not by the designed loop, whose modes become marginal (DRAKE_NOTES); the
    designed loop is the paper's frictionless one (section 3.1). ArgumentError (naming ``owner``) for a
    ``config`` that is not a ScenarioConfig, a ``bandwidth_hz`` that is not a finite number > 0."""
    _scenario_config(config, owner)
    bandwidth_hz = positive(bandwidth_hz, "bandwidth_hz", owner, unit="Hz")
    c = at_rest_config(config, owner)
    c.plant.time_step = 0.0
    c.control_period = 0.0
    c.contact.friction = 0.0
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
    shifts: list = field(default_factory=list)       # the task's EigenvalueShift predictions
    shifted_match: EigenvalueMatch = None            # the match against the design with those shifts
    jacobian_check: JacobianCheck = None   # AutoDiffXd against central differences; which A is used
    unstable_modes: list = field(default_factory=list)   # analysis.modes.ModeDiagnosis, real part > 0.01 1/s


def _stages(stages, owner):
    """``stages`` (a ``core.progress.Stages``, or None: silent) checked, naming ``owner``."""
    function(stages, "stages", owner, "stages(label) -> a context manager (core.progress.Stages)", allow_none=True)
    return stages or quiet()


def _scenario_config(config, owner):
    """``config`` if it is a ScenarioConfig; ArgumentError naming ``owner`` otherwise."""
    return instance(config, "config", owner, ScenarioConfig,
                    what="a ScenarioConfig (e.g. get_task(name).default_config())")


def linearize_continuous(config, tolerance=0.05, bandwidth_hz=200.0, stages=None,
                         jacobian_tolerance=JACOBIAN_TOLERANCE, require_equilibrium=True):
    """Linearize the continuous closed loop of ``config`` at its contact equilibrium.

    Builds ``equilibrium_config(config)``, sets the start, checks it is an
    equilibrium, runs Drake's ``Linearize`` (AutoDiffXd through plant,
    contact, sensor, filter and controller), checks its A against central
    differences of the time derivatives, every column (``analysis.derivatives``:
    where they disagree beyond ``jacobian_tolerance``, relative per column, the
    central-difference A is used, ``jacobian_check.used`` says so and a
    ``DerivativeMismatchWarning`` is issued), and matches eig(A) against the
    designed eigenvalues. ``wall_time`` covers both derivatives. Every mode with real part
    above 0.01 1/s is named with its likely cause (``unstable_modes``, ``analysis.modes``).
    ``stages`` (``core.progress.Stages``): one line per stage with its time. ``tolerance`` (relative, in
    (0, 1]), ``jacobian_tolerance`` and ``require_equilibrium`` as for ``linearize_at_contact``.
    """
    owner = "linearize_continuous"
    _scenario_config(config, owner)
    relative_tolerance(tolerance, "tolerance", owner)
    stages = _stages(stages, owner)
    c = equilibrium_config(config, bandwidth_hz, owner)
    with stages(f"{c.task}: building the continuous closed loop"):
        scenario = build_scenario(c, with_loggers=False)
        context = scenario.diagram.CreateDefaultContext()
    with stages(f"{c.task}: solving the start (contact equilibrium)"):
        set_initial_conditions(scenario, context)
    return linearize_at_contact(scenario.diagram, context, scenario, tolerance=tolerance,
                                jacobian_tolerance=jacobian_tolerance, stages=stages, task=scenario.task,
                                what=c.task, require_equilibrium=require_equilibrium)


# The largest max |x-dot| (per second) accepted at a linearization point, relative to the state's size
# max(1, max |x|) (the filter's N, the joints' rad): 1 % per second. Measured at the package's own
# equilibria (``equilibrium_config`` of every continuous registered task in every mode, after
# ``set_initial_conditions``): 1.2e-10 to 3.3e-10 in velocity- and position-force; in impedance-force
# 6.1e-4 (surface polishing, max |x| 8.8) and 4.5e-3 (sphere polishing, max |x| 7), i.e. at most 6.4e-4 of
# the state's size per second. Off equilibrium (a Kinova Jaco on a cylinder, F_d 10 N): commanded to slide
# at 3 cm/s 1.08 (about 0.1 of its size), solve_contact_start forgotten 28.6, a wrist sensor on a
# continuous plant 593 (565 with hydroelastic_with_fallback).
EQUILIBRIUM_RATE = 0.01


def _largest_rates(diagram, root_context):
    """[(max |x-dot| of a subsystem's continuous state, its name)], largest first."""
    rates = []
    for system in diagram.GetSystems():
        context = system.GetMyContextFromRoot(root_context)
        if context.num_continuous_states():
            rate = np.max(np.abs(system.EvalTimeDerivatives(context).CopyToVector()))
            rates.append((float(rate), system.get_name()))
    return sorted(rates, reverse=True)


def check_equilibrium(diagram, root_context, systems, what="your diagram", owner="check_equilibrium"):
    """max |x-dot| of the continuous state at ``root_context``; NotAtEquilibriumError if it is above
    EQUILIBRIUM_RATE (1/s) times the state's size max(1, max |x|), naming the subsystem where it is
    largest and the likely cause: a desired velocity that is not zero, a wrist force/torque sensor on
    a continuous plant, or else the start not solved (``solve_contact_start`` / ``prime_start`` not
    called, or the state changed after it). ArgumentError (naming ``owner``) for a ``diagram``,
    ``root_context`` and ``systems`` that do not belong together (``station.root_context``)."""
    where = f"{owner}({text(what, 'what', owner)})"
    check_root_context(diagram, root_context, systems, where)
    derivatives = diagram.EvalTimeDerivatives(root_context).CopyToVector()
    residual = float(np.max(np.abs(derivatives))) if derivatives.size else 0.0
    state = root_context.get_continuous_state_vector().CopyToVector()
    scale = max(1.0, float(np.max(np.abs(state)))) if state.size else 1.0
    if not residual > EQUILIBRIUM_RATE * scale:
        return residual
    controller = systems.controller
    velocity = controller.get_desired_velocity_input_port().Eval(controller.GetMyContextFromRoot(root_context))
    if np.any(np.asarray(velocity) != 0):
        cause = (f"the controller is commanded to move (desired_velocity = {np.round(velocity, 6).tolist()}): "
                 "linearize with a zero desired velocity")
    elif isinstance(systems.sensor, WristForceTorqueSensor):
        cause = ("a WristForceTorqueSensor on a continuous plant: its reading is not the contact's at rest; use the "
                 "contact sensor (sensor=None) for the continuous loop")
    else:
        cause = ("the start is not solved: call station.contact_start.solve_contact_start (or prime_start after "
                 "setting the arm at rest pressing with F_d) on this context, and change no state after it")
    rate, name = _largest_rates(diagram, root_context)[0]
    raise NotAtEquilibriumError(
        f"{where}: the state is not an equilibrium: max |x-dot| = {residual:.3g} (largest in "
        f"'{name}', {rate:.3g}) > {EQUILIBRIUM_RATE:g}/s x the state's size {scale:.3g}, so its eigenvalues would "
        f"not be the design's; likely cause: {cause} (require_equilibrium=False linearizes there anyway)")


def linearize_at_contact(diagram, root_context, systems, tolerance=0.05, jacobian_tolerance=JACOBIAN_TOLERANCE,
                         stages=None, task=None, what="your diagram", require_equilibrium=True):
    """Linearize your continuous closed loop at the contact equilibrium ``root_context`` holds (e.g.
    after ``station.contact_start.solve_contact_start``), with what ``drake-hybrid analyze`` reports.

    ``systems``: the ``HybridSystems`` of ``station.loop.add_hybrid_controller`` (or a built
    ``Scenario``). The diagram must be purely continuous (a plant with ``time_step=0``, a controller
    without ``control_period``, a wrench low-pass). Runs Drake's ``Linearize`` (AutoDiffXd through
    plant, contact, sensor, filter and controller), checks its A against central differences of the
    time derivatives, every column (``analysis.derivatives``: beyond ``jacobian_tolerance``, relative
    per column, the central-difference A is used and ``jacobian_check.used`` says so), matches eig(A)
    against the controller's designed eigenvalues within ``tolerance`` (``controller_prediction``), in
    impedance-force mode also against the design shifted by the contact's measured stiffness and
    damping (``analysis.environment``; ``task``: a Task whose own shifts come first), and names every
    mode with real part above 0.01 1/s with its likely cause (``analysis.modes``). Returns a
    Linearization; ``equilibrium_residual`` is max |x-dot| at the start (near 0 at an equilibrium).

    The state must be an equilibrium (``check_equilibrium``: max |x-dot| at most EQUILIBRIUM_RATE = 1 %
    per second of the state's size, else NotAtEquilibriumError naming the likely cause: a desired
    velocity that is not zero, the start not solved, a wrist sensor on a continuous plant);
    ``require_equilibrium=False`` linearizes anywhere. ArgumentError for a ``tolerance`` outside (0, 1],
    a ``jacobian_tolerance`` that is not > 0 (inf: never replace a column), a ``diagram``,
    ``root_context`` and ``systems`` that do not belong together (``station.root_context``)."""
    owner = f"linearize_at_contact({text(what, 'what', 'linearize_at_contact')})"
    check_root_context(diagram, root_context, systems, owner)
    tolerance = relative_tolerance(tolerance, "tolerance", owner)
    jacobian_tolerance = positive(jacobian_tolerance, "jacobian_tolerance", owner, allow_infinite=True,
                                  unit="relative column error")
    stages = _stages(stages, owner)
    require_equilibrium = boolean(require_equilibrium, "require_equilibrium", owner)
    if task is not None and not hasattr(task, "eigenvalue_shifts"):
        raise ArgumentError(f"{owner}: task must be a Task (scenario.task) or None, got {type(task).__name__}")
    if not (root_context.num_abstract_states() == 0 and root_context.has_only_continuous_state()):
        raise ArgumentError(f"{owner}: the closed loop must be purely continuous (a plant with time_step=0, a "
                            "controller without control_period); it has discrete or abstract state")
    if require_equilibrium:
        residual = check_equilibrium(diagram, root_context, systems, what, "linearize_at_contact")
    else:
        derivatives = diagram.EvalTimeDerivatives(root_context).CopyToVector()
        residual = float(np.max(np.abs(derivatives))) if derivatives.size else 0.0
    start = time.perf_counter()
    with stages(f"{what}: linearizing ({root_context.num_continuous_states()} states, AutoDiffXd)"):
        linear = Linearize(diagram, root_context, equilibrium_check_tolerance=np.inf)
    with stages(f"{what}: checking A against central differences"):
        A, check = checked_state_jacobian(diagram, root_context, linear.A(), tolerance=jacobian_tolerance,
                                          what=f"linearize_at_contact({what})")
    wall = time.perf_counter() - start
    eigenvalues = np.linalg.eigvals(A)
    predicted = controller_prediction(systems.controller)
    match = match_eigenvalues(predicted.designed, eigenvalues, tolerance=tolerance, marginal=predicted.marginal)
    shifts, shifted_match = _task_shifts(task, systems, root_context, predicted, eigenvalues, tolerance)
    view = systems if getattr(systems, "diagram", None) is not None else dataclasses.replace(systems, diagram=diagram)
    modes = diagnose_unstable_modes(view, root_context, A, systems.controller.mode, predicted.designed)
    return Linearization(A=A, eigenvalues=eigenvalues, equilibrium_residual=residual, predicted=predicted,
                         match=match, wall_time=wall, shifts=shifts, shifted_match=shifted_match,
                         jacobian_check=check, unstable_modes=modes)


# ------------------------------------------------------------------------------------------------
# Discrete closed loops: Jacobian of the one-period map
# ------------------------------------------------------------------------------------------------

def _one_period_jacobian(step, x0, epsilon):
    """Central-difference Jacobian of a one-period map ``step`` at x0, and max |step(x0) - x0|."""
    residual = float(np.max(np.abs(step(x0) - x0)))
    A = np.zeros((x0.size, x0.size))
    for j in range(x0.size):
        dx = np.zeros(x0.size)
        dx[j] = epsilon
        A[:, j] = (step(x0 + dx) - step(x0 - dx)) / (2 * epsilon)
    return A, residual


# A one-period map is only piecewise smooth with SAP and hydroelastic contact: at an equilibrium on
# a kink, small central-difference steps can show a multiplier outside the unit circle that the
# loop does not have. One found above this rate (1/s) is checked at a step ten times larger.
STEP_CHECK_RATE = 0.01
STEP_CHECK_FACTOR = 10.0


@dataclass
class StepCheck:
    """The second look at an unstable-looking one-period map: its worst real part (1/s) at
    ``epsilon`` and at ``larger_epsilon``; ``confirmed`` when both are above STEP_CHECK_RATE."""

    epsilon: float
    worst_real: float
    larger_epsilon: float
    larger_worst_real: float

    @property
    def confirmed(self):
        return self.worst_real > STEP_CHECK_RATE and self.larger_worst_real > STEP_CHECK_RATE

    def summary(self):
        verdict = ("confirmed" if self.confirmed else
                   "NOT confirmed: the one-period map is not smooth at this equilibrium (a contact-solver kink), "
                   "so the linearization cannot decide; trust the simulation")
        return (f"step check: worst real part {self.worst_real:.3g} 1/s at step {self.epsilon:g}, "
                f"{self.larger_worst_real:.3g} 1/s at step {self.larger_epsilon:g}: {verdict}")

    def as_dict(self):
        return {"epsilon": self.epsilon, "worst_real": self.worst_real, "larger_epsilon": self.larger_epsilon,
                "larger_worst_real": self.larger_worst_real, "confirmed": self.confirmed}


def _map_eigenvalues(A, period):
    """The continuous-time equivalents log(mu) / period of A's multipliers (|mu| floored: a
    multiplier at 0, a pure delay, maps to a large negative real part instead of -inf)."""
    multipliers = np.linalg.eigvals(A)
    magnitude = np.maximum(np.abs(multipliers), np.finfo(float).tiny)
    return multipliers, (np.log(magnitude) + 1j * np.angle(multipliers)) / period


def _step_checked_jacobian(step, x0, epsilon, period):
    """(A, residual, StepCheck or None): the one-period map's Jacobian at ``epsilon``; if it has a
    rate above STEP_CHECK_RATE, the same at STEP_CHECK_FACTOR times the step, for the StepCheck."""
    A, residual = _one_period_jacobian(step, x0, epsilon)
    worst = float(np.max(_map_eigenvalues(A, period)[1].real))
    if worst <= STEP_CHECK_RATE:
        return A, residual, None
    larger = STEP_CHECK_FACTOR * epsilon
    A_larger, _ = _one_period_jacobian(step, x0, larger)
    return A, residual, StepCheck(epsilon, worst, larger, float(np.max(_map_eigenvalues(A_larger, period)[1].real)))


@dataclass
class DiscreteLinearization:
    A: np.ndarray                    # Jacobian of the one-period map x_{k+1} = f(x_k)
    multipliers: np.ndarray          # eig(A)
    eigenvalues: np.ndarray          # log(multipliers) / period: the equivalent continuous eigenvalues
    period: float
    equilibrium_residual: float      # max |f(x) - x| at the linearization point
    predicted: PredictedEigenvalues
    match: EigenvalueMatch
    wall_time: float
    shifts: list = field(default_factory=list)       # the task's EigenvalueShift predictions
    shifted_match: EigenvalueMatch = None            # the match against the design with those shifts
    step_check: StepCheck = None     # set when the map looked unstable: the check at a larger step


def linearize_discrete(config, tolerance=0.05, epsilon=1e-6, settle_time=0.0, stages=None):
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
    compliant constraint forces settle onto the equilibrium. ``stages`` (``core.progress.Stages``):
    one line per stage with its time.
    """
    owner = "linearize_discrete"
    _scenario_config(config, owner)
    relative_tolerance(tolerance, "tolerance", owner)
    positive(epsilon, "epsilon", owner)
    settle_time = nonnegative(settle_time, "settle_time", owner, unit="s")
    stages = _stages(stages, owner)
    c = at_rest_config(config, owner)
    if not c.plant.time_step > 0:
        raise ConfigError(f"{owner}: config.plant.time_step must be > 0 (a discrete plant), got {c.plant.time_step:g}")
    c.control_period = c.plant.time_step
    c.log_period = c.plant.time_step
    c.sensor.bandwidth_hz = 0.0
    with stages(f"{c.task}: building the discrete closed loop"):
        scenario = build_scenario(c, with_loggers=False, sampled_plant_outputs=False, controller_sample_lead=False)
        simulator = Simulator(scenario.diagram)
        ApplySimulatorConfig(c.simulator, simulator)
        context = simulator.get_mutable_context()
    with stages(f"{c.task}: solving the start"):
        set_initial_conditions(scenario, context)
        simulator.Initialize()
    if settle_time > 0:
        with stages(f"{c.task}: settling at rest for {settle_time:g} s"):
            simulator.AdvanceTo(settle_time)
    if context.num_abstract_states() != 0 or context.num_continuous_states() != 0:
        raise ConfigError(f"{owner} needs a closed loop with discrete state only (no wrench filter or other "
                          "continuous or abstract state)")
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

    start = time.perf_counter()
    x0 = state_vector(context)
    with stages(f"{c.task}: linearizing (one-period map, {x0.size} states, {2 * x0.size} steps)"):
        A, residual, step_check = _step_checked_jacobian(step, x0, epsilon, c.plant.time_step)
    wall = time.perf_counter() - start
    multipliers = np.linalg.eigvals(A)
    h = c.plant.time_step
    # Multipliers at 0 (pure delays, e.g. the held torque) have no continuous-time counterpart.
    keep = np.abs(multipliers) > 1e-9
    eigenvalues = np.log(multipliers[keep].astype(complex)) / h
    predicted = controller_prediction(scenario.controller)
    match = match_eigenvalues(predicted.designed, eigenvalues, tolerance=tolerance, marginal=predicted.marginal)
    shifts, shifted_match = _task_shifts(get_task(c.task), scenario, context, predicted, eigenvalues, tolerance)
    return DiscreteLinearization(A=A, multipliers=multipliers, eigenvalues=eigenvalues, period=h,
                                 equilibrium_residual=residual, predicted=predicted, match=match, wall_time=wall,
                                 shifts=shifts, shifted_match=shifted_match, step_check=step_check)


def impedance_realization(scenario, log):
    """How well a logged run realizes the impedance/force design (docs/theory.md §5).

    Returns a dict of arrays over the log:

    * ``impedance_residual``: e_p'' + K_v e_p' + K_p e_p - M_d^-1 F_v (3.2-11, first line; M_d the
      impedance's mass, 1 in the paper), with e_p'' from central differences of the logged e_p';
    * ``tangential_force``: F_v;
    * ``force_loop`` and ``force_loop_predicted``: g_f = (I + K_fp) e_f + K_fi xi on the
      force-controlled rows (xi rebuilt from the logged e_f and xi(0)) and its prediction
      -M_f^-1 M_fp F_v (3.2-11, second line), with the partition of HybridController (kinematic
      rows count as motion rows, their measured force with F_v) and its blocks (from
      J (M + h B)^-1 J^T on a discrete plant with joint damping, control.damping).
    """
    controller = scenario.controller
    gains = controller.validated_gains()
    t = log["t"]
    e_p, e_p_dot, F_v = log["position_error"], log["velocity_error"], log["tangential_force"]
    e_p_ddot = np.gradient(e_p_dot, t, axis=0)
    residual = e_p_ddot + e_p_dot @ gains.velocity.T + e_p @ gains.position.T - F_v @ gains.impedance_inverse_mass.T
    m = controller.force_size
    physical = [i for i in range(m) if i not in controller.kinematic_rows]
    kinematic = list(controller.kinematic_rows)
    start = scenario.config.start.force_integral
    xi0 = np.asarray(start, dtype=float) if start else np.zeros(m)
    period = np.diff(t, prepend=t[0])
    xi = xi0 + np.cumsum(log["force_error"] * period[:, None], axis=0) - log["force_error"] * period[:, None]
    g_f = log["force_error"] @ (np.eye(m) + gains.force_proportional).T + xi @ gains.force_integral.T
    plant = scenario.controller_plant
    positions = joint_rows(log["q"], "log['q']", "impedance_realization", plant)
    velocities = joint_rows(log["v"], "log['v']", "impedance_realization", plant, kind="velocities")
    context = plant.CreateDefaultContext()
    predicted = []
    for q, v, F_tangent, F in zip(positions, velocities, F_v, log["force"]):
        plant.SetPositions(context, q)
        plant.SetVelocities(context, v)
        task = controller.kinematics.evaluate(context)
        values = scenario.constraint_space.evaluate(task.configuration, task.velocity)
        M = plant.CalcMassMatrix(context)
        mobility = task.jacobian @ np.linalg.solve(M, task.jacobian.T)
        # the law's: J (M + h B)^-1 J^T on a discrete plant with joint damping (control.damping)
        mobility = step_task_mobility(task.jacobian, M, mobility, controller.joint_damping, controller.plant_time_step)
        M_f, M_fp, _ = impedance_blocks(values.velocity_projection, values.force_projection, mobility, kinematic)
        motion_force = np.concatenate([F_tangent, F[kinematic]])
        predicted.append(-np.linalg.solve(M_f, M_fp @ motion_force))
    return {"impedance_residual": residual, "tangential_force": F_v, "force_loop": g_f[:, physical],
            "force_loop_predicted": np.array(predicted)}


def linearize_sampled_loop(config, epsilon=1e-5, tolerance=0.05, periods=1):
    """Jacobian of the simulated sampled closed loop's one-period map at its contact equilibrium.

    Unlike ``linearize_discrete`` (which rebuilds the loop with one period of actuation delay so
    that Drake evaluates its map directly), this differentiates the loop exactly as ``simulate``
    runs it, zero-delay hold and sampled sensors included, by simulating one period from perturbed
    states: slower, and only piecewise smooth with hydroelastic contact (below), but it is the
    loop whose stability a sweep over control periods asks about.

    The map takes the vector state x_k (plant q, v; controller xi, e_p and
    held torque) at t_k = k h - delta/2, between the controller's tick at
    k h - delta and the plant's step at k h (docs/design.md, "Sampling"), to
    x_{k+1} one control period h later, by simulating the full diagram. At that
    instant the plant's sampled contact results (abstract state) are overwritten
    by the step at k h before the next tick reads them, so x_k is the whole
    state of the loop and the map is a function of it alone. Its Jacobian is taken
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

    ArgumentError for a ``config`` that is not a ScenarioConfig, an ``epsilon`` that is not > 0, a
    ``tolerance`` outside (0, 1], ``periods`` that is not an integer >= 1; ConfigError for a config
    without the loop above.
    """
    owner = "linearize_sampled_loop"
    _scenario_config(config, owner)
    positive(epsilon, "epsilon", owner)
    relative_tolerance(tolerance, "tolerance", owner)
    periods = number(periods, "periods", owner, low=1, integer=True, unit="control periods")
    h, time_step = float(config.control_period), float(config.plant.time_step)
    if not (time_step > 0 and h > 0):
        raise ConfigError(f"{owner} needs a discrete plant (time_step > 0) and a sampled controller "
                          f"(control_period > 0); got time_step = {time_step:g}, control_period = {h:g}")
    steps = h / time_step
    if abs(steps - round(steps)) > 1e-9 * steps:
        raise ConfigError(f"{owner} needs control_period to be a whole number of plant steps; "
                          f"got control_period = {h:g}, time_step = {time_step:g}")
    if config.sensor.bandwidth_hz > 0:
        raise ConfigError(f"{owner} needs sensor.bandwidth_hz = 0 (a sampled wrench filter reads the plant's "
                          "sampled contact results at the plant's steps, outside the map's vector state)")

    c = at_rest_config(config, owner)
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
    A, residual, step_check = _step_checked_jacobian(one_period, get_state(base), epsilon, periods * h)
    wall = time.perf_counter() - start
    # Multipliers at 0 (the held torque is recomputed every tick) have no continuous counterpart.
    multipliers, eigenvalues = _map_eigenvalues(A, periods * h)
    predicted = controller_prediction(scenario.controller)
    match = match_eigenvalues(predicted.designed, eigenvalues, tolerance=tolerance, marginal=predicted.marginal)
    return DiscreteLinearization(A=A, multipliers=multipliers, eigenvalues=eigenvalues, period=h,
                                 equilibrium_residual=residual, predicted=predicted, match=match, wall_time=wall,
                                 step_check=step_check)
