"""The eigenvalues and error trajectories the gains design, and a logged run checked against the design.

* ``predicted_eigenvalues``: the eigenvalues the gains design (docs/theory.md §4,
  the table): -eig(K_v); the roots of s^2 + K_v s + K_p (position and impedance
  modes); eig(-(I + K_fp)^-1 K_fi); with those of the held rows and the arm's self-motion, and the
  number of zero eigenvalues a linearization must also show. ``controller_prediction``: the same for
  a HybridController; ``designed_eigenvalues_by_row``: row by row, for diagonal gains;
  ``design_time_constant``: the slowest designed time constant.
* ``predicted_errors``: the error trajectories those loops predict from an
  initial condition (for plots and tracking tests).
* ``impedance_realization``: how well a logged run realizes the impedance/force design (3.2-11).

The closed loop's own eigenvalues are measured by ``analysis.linearization`` (continuous) and
``analysis.discrete_linearization`` (sampled), and paired with these by ``analysis.matching``.
"""

import numbers
from dataclasses import dataclass
from typing import Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import expm

from drake_hybrid.analysis.environment import impedance_matrix
from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.damping import step_task_mobility
from drake_hybrid.control.gains import ControlMode, ValidatedGains
from drake_hybrid.control.law import impedance_blocks
from drake_hybrid.core.arguments import describe, instance, joint_rows, number, vector
from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.core.hints import Array
from drake_hybrid.tasks.task import Scenario

# The rows held kinematically: a count (the first ones) or the row indices.
KinematicRows = Union[int, Sequence[int], Array]


@dataclass
class PredictedEigenvalues:
    """Designed eigenvalues, by loop."""

    velocity: np.ndarray          # -eig(K_v), or the roots of s^2 + K_v s + K_p
    force: np.ndarray             # eig(-(I + K_fp)^-1 K_fi)
    marginal: int = 0             # zero eigenvalues expected: k = d - m (see predicted_eigenvalues)

    @property
    def designed(self) -> Array:
        return np.concatenate([self.velocity, self.force])

    @property
    def all(self) -> Array:
        return np.concatenate([self.designed, np.zeros(self.marginal)])


def _design(gains: ValidatedGains, mode: Union[ControlMode, str], owner: str) -> Tuple[ValidatedGains, ControlMode]:
    """(``gains``, ``mode`` as a ControlMode) checked: ValidatedGains (``HybridGains.matrices(k, m, mode)``)
    and a control mode; ArgumentError naming ``owner`` otherwise."""
    instance(gains, "gains", owner, ValidatedGains, what="ValidatedGains (HybridGains(...).matrices(k, m, mode))")
    return gains, ControlMode.parse(mode, owner)


def _kinematic_rows(kinematic_rows: KinematicRows, force_size: int, owner: str) -> List[int]:
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


def velocity_loop_matrix(gains: ValidatedGains, mode: ControlMode) -> Array:
    """A of the velocity loop: e_p'-dot = A e_p' (velocity mode) or d/dt [e_p; e_p'] = A [e_p; e_p']."""
    gains, mode = _design(gains, mode, "velocity_loop_matrix")
    if mode.integrates_position:
        return impedance_matrix(gains.velocity, gains.position)      # (3.2-11) with no environment
    return -gains.velocity


def predicted_eigenvalues(gains: ValidatedGains, mode: Union[ControlMode, str], kinematic_rows: KinematicRows = 0,
                          redundancy: int = 0) -> PredictedEigenvalues:
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


def designed_eigenvalues_by_row(gains: ValidatedGains, mode: Union[ControlMode, str],
                                kinematic_rows: KinematicRows = (), redundancy: int = 0
                                ) -> Optional[Tuple[List[Array], List[Array], List[complex]]]:
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
    assert gains.impedance_mass is not None          # set by ValidatedGains.__post_init__
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


def predicted_errors(gains: ValidatedGains, mode: Union[ControlMode, str], times: ArrayLike, velocity_error0: ArrayLike,
                     force_integral0: ArrayLike, position_error0: Optional[ArrayLike] = None,
                     kinematic_rows: KinematicRows = ()) -> Tuple[Array, Array, Array]:
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


def controller_prediction(controller: HybridController) -> PredictedEigenvalues:
    """``predicted_eigenvalues`` for a HybridController (its gains, mode, kinematic rows, n - d)."""
    if not all(hasattr(controller, name) for name in ("validated_gains", "mode", "kinematic_rows", "num_joints")):
        raise ArgumentError(f"controller_prediction: controller must be a HybridController, got {describe(controller)}")
    return predicted_eigenvalues(controller.validated_gains(), controller.mode, controller.kinematic_rows,
                                 controller.num_joints - controller.task_size)


def design_time_constant(gains: ValidatedGains, mode: Union[ControlMode, str],
                         kinematic_rows: KinematicRows = ()) -> float:
    """The slowest designed time constant 1 / min |Re(lambda)| (s) (arguments as ``predicted_eigenvalues``)."""
    eigenvalues = predicted_eigenvalues(gains, mode, kinematic_rows).designed
    return 1.0 / np.min(np.abs(eigenvalues.real))


def impedance_realization(scenario: Scenario, log: Mapping[str, Array]) -> Dict[str, Array]:
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
