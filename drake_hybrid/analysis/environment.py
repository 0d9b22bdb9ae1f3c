"""The contact as the impedance meets it: its stiffness and damping along the motion rows.

In impedance-force mode the law makes every motion row an impedance (3.2-11),

    y-ddot + K_v y-dot + K_p y = M_d^-1 F_v,

of unit mass in the paper and by default (M_d, ``HybridGains.impedance_mass``, on the velocity rows),

y the position along the rows (y-dot = E_p r-dot; the held rows of a point contact count as
motion rows with C-ddot + 3 w_c C-dot + 2 w_c^2 C = F). F_v is the measured force on those rows:
an input the gains do not choose. The roots the gains design, those of s^2 + K_v s + K_p, are the
impedance's alone. Where the contact itself makes F_v depend on where and how fast the pad is,
linearized F_v = K_e y + B_e y-dot, the closed loop has the roots of

    s^2 I + (K_v - M_d^-1 B_e) s + (K_p - M_d^-1 K_e) = 0                    (impedance with its environment)

and that is what an impedance is for: it yields to its environment. For a smooth, frictionless
ball pad on a smooth workpiece both are zero (the contact force passes through the pad's centre
along E_f). A hydroelastic contact on a small curved workpiece has both (docs/drake_notes.md,
"The impedance and the contact's stiffness along the surface"):

* K_e: the tessellated pad and workpiece turn the contact force at a slightly different rate than
  the smooth surface's normal turns (the dk of ``analysis.modes``). UR10 on the 5 cm drum at the
  default meshes: +2.6 N/m along x, a fifth of the designed K_p = 21 (unit mass); 0.9 N/m with
  four times finer meshes.
* B_e: the contact's dissipation along the face normals of a curved workpiece (the front of the
  patch separates, the rear approaches): a drag although mu = 0. The continuous plant's
  Hunt-Crossley pad (d = 10 s/m) gives -0.20 N s/m on the drum; SAP's relaxation time gives
  the same mechanism on a discrete plant, about nine times stronger with the package's 0.03 s pair
  (a steady drag of -1.85 N s/m on the 5 cm drum and ball; docs/drake_notes.md, "The simulated
  contact's drag and the impedance's roots"). The prediction here is the continuous twin's.

In a run, the same holds with the measured F_v as the input: ``impedance_response`` integrates
(3.2-11) driven by a logged F_v(t) from the logged start, the velocity errors the designed impedance
predicts for that run. On the own-arm matrix's curved workpieces SAP's drag made them 6.6-6.9 % of
the command with Drake's 0.2 s pair relaxation (0.24 N), 0.49-0.68 % with the package's 0.03 s
(0.04 N), and the runs' measured ones are within 0.1 % of the command of them.

``contact_environment`` measures K_e and B_e by central differences of the wrench sensor's reading,
split by E^-T as the law splits it, with the arm's positions (velocities) moved along each motion
row; ``impedance_environment_shifts`` turns them into the designed eigenvalues' predicted shifts
(``tasks.task.EigenvalueShift``) that the linearizations match against. The velocity-force and
position-force modes cancel the measured F_v (``control.law.tangential_compensation``): for them
the environment's stiffness is ``analysis.modes.row_force_drift``'s business.
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from drake_hybrid.core.arguments import (complex_vector, describe, joint_vector, matrix, number, numeric_array,
                                         positive, relative_tolerance, vector)
from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.station.root_context import check_systems_context
from drake_hybrid.tasks.task import EigenvalueShift

# m (rad) along a motion row, and m/s (rad/s) of its velocity: the central differences' steps.
# The UR10 on the 5 cm drum: K_e agrees to 3 digits at 1e-5 and 1e-6 (facets straddled at 1e-4: 3 %).
ENVIRONMENT_STEP = 1e-6
# A designed eigenvalue the environment moves by less than this (relative) keeps its designed value:
# 1 % of it, a fifth of the match's 5 % tolerance (the sphere-polishing task's ball: 0.35 % at most).
SHIFT_THRESHOLD = 0.01


def _gain_matrices(owner, velocity_gain, position_gain, **optional):
    """[K_v, K_p, then each of ``optional`` (None kept)] as k x k float matrices, k from ``velocity_gain``."""
    velocity_gain = numeric_array(velocity_gain, "velocity_gain", owner, what="a square matrix")
    k = velocity_gain.shape[0] if velocity_gain.ndim == 2 else 0
    if velocity_gain.ndim != 2 or velocity_gain.shape != (k, k) or k == 0:
        raise ArgumentError(f"{owner}: velocity_gain must be a square matrix (k x k), got {describe(velocity_gain)}")
    checked = [velocity_gain, matrix(position_gain, "position_gain", owner, (k, k))]
    return checked + [None if value is None else matrix(value, name, owner, (k, k)) for name, value in optional.items()]


def row_forces(scenario, context, q=None, v=None):
    """[F_v; F] = E^-T w: the wrench sensor's reading split as the law splits it
    (``ConstraintSpace.split_wrench``), with the arm's positions ``q`` and velocities ``v`` (None:
    those of ``context``; the rest of ``context`` kept, ``context`` itself untouched). ArgumentError
    for a ``q`` or ``v`` that is not a vector of the plant's number of finite positions or velocities."""
    owner = "row_forces"
    check_systems_context(scenario, context, owner)
    plant, space = scenario.plant, scenario.constraint_space
    q = None if q is None else joint_vector(q, "q", owner, plant)
    v = None if v is None else joint_vector(v, "v", owner, plant, kind="velocities")
    work = context.Clone()
    plant_context = plant.GetMyMutableContextFromRoot(work)
    if q is not None:
        plant.SetPositions(plant_context, q)
    if v is not None:
        plant.SetVelocities(plant_context, v)
    wrench = np.asarray(scenario.sensor.get_output_port(0).Eval(scenario.sensor.GetMyContextFromRoot(work)))
    task = scenario.kinematics.evaluate(plant_context, check=False)
    values = space.evaluate(task.configuration, task.velocity, check=False)
    tangential, force = space.split_wrench(values, space.chart.generalized_force(task.configuration, wrench))
    return np.concatenate([tangential, force])


def row_directions(scenario, context):
    """(E, dq per row): the stacked [E_p; E_f] at ``context`` and, as columns, the joint motions
    J^+ E^-1 e_i that move the pad by 1 along each row i (None if the plant's positions and
    velocities differ, a free body)."""
    check_systems_context(scenario, context, "row_directions")
    plant, space = scenario.plant, scenario.constraint_space
    plant_context = plant.GetMyContextFromRoot(context)
    task = scenario.kinematics.evaluate(plant_context, check=False)
    values = space.evaluate(task.configuration, task.velocity, check=False)
    E = np.vstack([values.velocity_projection, values.force_projection])
    J = task.jacobian
    if J.shape[1] != plant.num_positions():
        return E, None
    return E, np.linalg.pinv(J) @ np.linalg.inv(E)


@dataclass
class ContactEnvironment:
    """The contact's linearized force on the motion rows, F = K_e y + B_e y-dot."""

    rows: list                 # indices into [velocity rows; E_f rows]: the motion rows
    stiffness: np.ndarray      # K_e = dF/dy
    damping: np.ndarray        # B_e = dF/dy-dot


def contact_environment(scenario, context, rows, step=ENVIRONMENT_STEP):
    """K_e and B_e on ``rows`` (indices into [velocity rows; E_f rows]) by central differences of
    ``row_forces`` at ``context``, or None for a free-body plant."""
    owner = "contact_environment"
    check_systems_context(scenario, context, owner)
    size = scenario.constraint_space.velocity_size + scenario.constraint_space.force_size
    if not isinstance(rows, (list, tuple, range, np.ndarray)):
        raise ArgumentError(f"{owner}: rows must be a list of row indices (0 to {size - 1}), got {describe(rows)}")
    rows = [number(row, "rows", owner, low=0, high=size - 1, integer=True) for row in rows]
    step = positive(step, "step", owner, unit="m or rad along a row")
    plant = scenario.plant
    plant_context = plant.GetMyContextFromRoot(context)
    q0, v0 = plant.GetPositions(plant_context).copy(), plant.GetVelocities(plant_context).copy()
    _, directions = row_directions(scenario, context)
    if directions is None:
        return None
    stiffness, damping = np.zeros((len(rows), len(rows))), np.zeros((len(rows), len(rows)))
    for column, row in enumerate(rows):
        dq = step * directions[:, row]
        stiffness[:, column] = (row_forces(scenario, context, q=q0 + dq)[rows]
                                - row_forces(scenario, context, q=q0 - dq)[rows]) / (2.0 * step)
        damping[:, column] = (row_forces(scenario, context, v=v0 + dq)[rows]
                              - row_forces(scenario, context, v=v0 - dq)[rows]) / (2.0 * step)
    return ContactEnvironment(rows=rows, stiffness=stiffness, damping=damping)


def impedance_matrix(velocity_gain, position_gain, stiffness=None, damping=None, inverse_mass=None):
    """A of d/dt [y; y-dot] = A [y; y-dot] for y-ddot = -(K_v - M_d^-1 B_e) y-dot - (K_p - M_d^-1 K_e) y
    (None: K_e, B_e = 0; ``inverse_mass`` M_d^-1, None: the paper's unit mass). ArgumentError for
    arguments that are not k x k matrices of finite numbers."""
    velocity_gain, position_gain, stiffness, damping, inverse_mass = _gain_matrices(
        "impedance_matrix", velocity_gain, position_gain, stiffness=stiffness, damping=damping,
        inverse_mass=inverse_mass)
    k = velocity_gain.shape[0]
    K_e = np.zeros((k, k)) if stiffness is None else stiffness
    B_e = np.zeros((k, k)) if damping is None else damping
    if inverse_mass is not None:
        K_e, B_e = inverse_mass @ K_e, inverse_mass @ B_e
    return np.block([[np.zeros((k, k)), np.eye(k)], [K_e - position_gain, B_e - velocity_gain]])


def impedance_loop(velocity_gain, position_gain, stiffness=None, damping=None, inverse_mass=None):
    """Eigenvalues of ``impedance_matrix``: the impedance's roots, with its environment if given."""
    return np.linalg.eigvals(impedance_matrix(velocity_gain, position_gain, stiffness, damping, inverse_mass))


def root_pairs(designed, moved):
    """Each root of ``designed`` paired with one of ``moved`` (Hungarian, on the relative distance, as
    match_eigenvalues pairs): (index pairs, relative distances of the pairs)."""
    designed = complex_vector(designed, "designed", "root_pairs", nonzero=True)
    moved = complex_vector(moved, "moved", "root_pairs")
    cost = np.abs(moved[None, :] - designed[:, None]) / np.abs(designed)[:, None]
    rows, columns = linear_sum_assignment(cost)
    return list(zip(rows, columns)), cost[rows, columns]


def mass_factor_within(velocity_gain, position_gain, stiffness, damping, inverse_mass, tolerance, velocity_rows):
    """The smallest factor c (two significant digits, rounded up) such that the impedance of mass c M_d on
    the first ``velocity_rows`` rows (``inverse_mass`` block-diagonal; the held rows keep theirs) closed
    through the contact's ``stiffness`` and ``damping`` keeps every root of s^2 + K_v s + K_p within
    ``tolerance`` (relative) of its designed value; 1 if the current mass does, None if no c up to 1e4
    does. The shift falls as 1 / c for small shifts."""
    owner = "mass_factor_within"
    velocity_gain, position_gain, stiffness, damping, inverse_mass = _gain_matrices(
        owner, velocity_gain, position_gain, stiffness=stiffness, damping=damping, inverse_mass=inverse_mass)
    tolerance = relative_tolerance(tolerance, "tolerance", owner)
    velocity_rows = number(velocity_rows, "velocity_rows", owner, low=0, high=velocity_gain.shape[0], integer=True)
    alone = impedance_loop(velocity_gain, position_gain)
    rows = np.arange(inverse_mass.shape[0]) < velocity_rows

    def miss(factor):
        scaled = np.diag(np.where(rows, 1.0 / factor, 1.0)) @ inverse_mass     # block-diagonal: M_d^-1 / c, I
        coupled = impedance_loop(velocity_gain, position_gain, stiffness, damping, scaled)
        return float(root_pairs(alone, coupled)[1].max())

    if miss(1.0) <= tolerance:
        return 1.0
    low, high = 1.0, 1e4
    if miss(high) > tolerance:
        return None
    while high / low > 1.001:
        middle = np.sqrt(low * high)
        low, high = (low, middle) if miss(middle) <= tolerance else (middle, high)
    digits = 10.0 ** (np.floor(np.log10(high)) - 1)
    return round(float(np.ceil(high / digits) * digits), 12)


def impedance_environment_shifts(scenario, context, designed, step=ENVIRONMENT_STEP, tolerance=0.05):
    """The designed eigenvalues of an impedance-force loop that its contact moves, and where:
    [EigenvalueShift] (module docstring; empty when none moves by SHIFT_THRESHOLD or more, or for
    a plant with joints beyond the arm's, a mechanism). ``designed``: the controller's designed eigenvalues
    (the shifts take theirs). Where a root moves by more than ``tolerance``, the reason names the
    impedance mass that would keep every root within it (``mass_factor_within``)."""
    owner = "impedance_environment_shifts"
    check_systems_context(scenario, context, owner)
    designed = complex_vector(designed, "designed", owner)
    step = positive(step, "step", owner, unit="m or rad along a row")
    tolerance = relative_tolerance(tolerance, "tolerance", owner)
    plant = scenario.plant
    if plant.num_positions() != plant.num_positions(scenario.robot.arm):
        return []      # a mechanism (the crank's handle): moving the arm alone would measure its joints, not a contact
    gains = scenario.controller.validated_gains()
    k = scenario.constraint_space.velocity_size
    held = list(scenario.constraint_space.constraint.kinematic_rows)
    rows = list(range(k)) + [k + i for i in held]
    if not rows:
        return []
    environment = contact_environment(scenario, context, rows, step)
    if environment is None:
        return []
    w_c = gains.constraint_frequency
    velocity_gain = np.diag(np.concatenate([np.zeros(k), np.full(len(held), 3.0 * w_c)]))
    position_gain = np.diag(np.concatenate([np.zeros(k), np.full(len(held), 2.0 * w_c**2)]))
    velocity_gain[:k, :k], position_gain[:k, :k] = gains.velocity, gains.position
    inverse_mass = np.eye(len(rows))
    inverse_mass[:k, :k] = gains.impedance_inverse_mass
    alone = impedance_loop(velocity_gain, position_gain)
    coupled = impedance_loop(velocity_gain, position_gain, environment.stiffness, environment.damping, inverse_mass)
    # Each root of the impedance alone is the designed eigenvalue nearest to it; its partner with the
    # contact, the coupled root nearest to it (Hungarian, as match_eigenvalues pairs).
    designed = np.asarray(designed, dtype=complex)
    pairs, _ = root_pairs(alone, coupled)
    K_e, B_e = environment.stiffness, environment.damping
    reason = (f"the impedance (3.2-11) meets the contact's own stiffness and damping along its rows "
              f"(central differences: dF/dy up to {np.max(np.abs(K_e)):.3g}, dF/dy-dot up to "
              f"{np.max(np.abs(B_e)):.3g}, row units): roots of s^2 + (K_v - M_d^-1 B_e) s + (K_p - M_d^-1 K_e); "
              f"a tessellated curved workpiece's facets and normal dissipation (analysis.environment)")
    factor = mass_factor_within(velocity_gain, position_gain, K_e, B_e, inverse_mass, tolerance, k)
    if factor is not None and factor > 1.0:
        reason += (f"; an impedance mass {factor:g} times the current one (gains.impedance_mass) would keep "
                   f"every designed root within {100 * tolerance:g} %")
    shifts = []
    for i, j in pairs:
        nearest = designed[np.argmin(np.abs(designed - alone[i]))]
        if abs(nearest - alone[i]) > 1e-6 * abs(nearest):
            continue                                  # not a designed eigenvalue (e.g. a zero)
        if abs(coupled[j] - nearest) >= SHIFT_THRESHOLD * abs(nearest):
            shifts.append(EigenvalueShift(designed=nearest, predicted=complex(coupled[j]), reason=reason))
    return shifts


def impedance_response(velocity_gain, position_gain, t, tangential_force, position_error0, velocity_error0,
                       inverse_mass=None):
    """e_p'(t) of the designed impedance (3.2-11), e_p'' + K_v e_p' + K_p e_p = M_d^-1 F_v, driven by a
    logged F_v (``tangential_force``, samples at ``t``, linear between them) from e_p(0), e_p'(0): the
    velocity errors a run realizing the impedance has (module docstring; ``inverse_mass`` M_d^-1,
    None: the paper's unit mass)."""
    from scipy.signal import lsim  # about a second to load: only where used (tests/test_architecture.py)

    owner = "impedance_response"
    velocity_gain, position_gain, inverse_mass = _gain_matrices(owner, velocity_gain, position_gain,
                                                                inverse_mass=inverse_mass)
    k = velocity_gain.shape[0]
    t = vector(t, "t", owner, unit="s")
    tangential_force = numeric_array(tangential_force, "tangential_force", owner, what=f"a {len(t)}x{k} matrix")
    if tangential_force.shape not in ((len(t), k),) + (((len(t),),) if k == 1 else ()):
        raise ArgumentError(f"{owner}: tangential_force must be a {len(t)}x{k} matrix (a sample per time of t), got "
                            f"{describe(tangential_force)}")
    position_error0 = vector(position_error0, "position_error0", owner, k)
    velocity_error0 = vector(velocity_error0, "velocity_error0", owner, k)
    A = impedance_matrix(velocity_gain, position_gain)
    B = np.vstack([np.zeros((k, k)), np.eye(k) if inverse_mass is None else inverse_mass])
    C = np.hstack([np.zeros((k, k)), np.eye(k)])
    x0 = np.concatenate([position_error0, velocity_error0])
    _, response, _ = lsim((A, B, C, np.zeros((k, k))), tangential_force, t, X0=x0)
    return np.asarray(response).reshape(len(t), k)
