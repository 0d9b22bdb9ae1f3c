"""Naming a linearized closed loop's unstable modes and their likely cause.

``diagnose_unstable_modes`` takes every eigenvalue of A with real part above
``UNSTABLE_RATE`` (0.01 1/s) and looks at its eigenvector's plant positions: the
motion dq of the mode mapped to the task, r-dot = J dq, and split into

* the velocity-controlled rows, E_p J dq (for velocity-force mode: positions the law
  does not regulate),
* the constraint rows, E_f J dq (pressing into / off the surface),
* the arm's self-motion, dq - J^+ J dq (redundant arms),

(norms of chart coordinates: m and rad together, as the chart has them). The largest
part names the mode; with how fast it is, it gives the likely cause.

The slow real mode of velocity-force mode on a curved workpiece (docs/drake_notes.md,
"Slow drift on curved workpieces"): the law leaves the positions along its velocity rows
unregulated (a zero eigenvalue per row, docs/theory.md §4), so any tangential contact force
that grows with the tangential position moves that zero. On a convex surface of radius rho
the contact force turns by 1/rho per metre of sliding, a tangential stiffness F / rho that
the law's push along E_f(x) cancels exactly for a smooth pad and surface; a tessellated pad
and workpiece turn it at a slightly different rate, and the difference dk gives a real
eigenvalue s with Lambda s (s + K_v) = dk (Lambda: the arm's inertia along the mode,
(u^T E_p J M^-1 J^T E_p^T u)^-1). The diagnosis reports that dk.

The law's F_v cancellation (``control.law.tangential_compensation``) removes that stiffness from the
velocity rows. The held (kinematic) rows carry a second such force: a point contact leaves them to
the controller (C-ddot + 3 w_c C-dot + 2 w_c^2 C = 0). For a smooth ball pad on a smooth surface
their measured force is zero (the contact force passes through the pad's centre along E_f's first
row); a tessellated pad and workpiece give a small contact torque about the pad's centre that
changes as the pad slides, and the arm's mobility carries it to the velocity rows. The law cancels
it with F_v under the same option (``control.law.held_row_compensation``); in the paper's form
(``compensate_tangential_force: false``) both stay on the arm. ``row_force_drift`` predicts the
resulting eigenvalues without the closed-loop Jacobian: the rigid arm under the law,

    y-ddot = -K_v y-dot (- K_p y) + (E J M^-1 J^T E^T)[p, u] (dF_u / dy) y,

y the positions along the velocity rows (y-dot = E_p r-dot), u the rows whose measured force the
law leaves on the arm (the held rows, and the velocity rows when F_v is not cancelled), and
dF_u / dy measured by central differences of the wrench sensor's reading split by E^-T
(``DRIFT_STEP``) with the pad moved along each velocity row. The sphere's pole path: +0.508
predicted, +0.497 1/s linearized with F_v alone cancelled (the law before the held rows' force was
cancelled too; now 0); in the paper's form +0.533 predicted, +0.510 linearized (docs/drake_notes.md).
A mode that prediction matches is
named with it (``ModeDiagnosis.predicted``, ``explained``).
"""

import numbers
from dataclasses import dataclass, field

import numpy as np

from drake_hybrid.analysis.environment import impedance_matrix, row_directions, row_forces
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.core.arguments import (complex_vector, describe, matrix, number, numeric_array, positive,
                                         relative_tolerance)
from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.station.root_context import check_systems_context

UNSTABLE_RATE = 0.01                  # 1/s: a mode growing faster than 1 % per second is named
# m (or rad) along a velocity row: the step of the row forces' central differences in row_force_drift.
# The sphere's pole path: dF/dy agrees to 3 digits at 1e-5, 1e-6 and 1e-7 (docs/drake_notes.md).
DRIFT_STEP = 1e-6


@dataclass
class ModeDiagnosis:
    eigenvalue: complex
    shares: dict                      # part of the mode's task motion: velocity rows, constraint rows, self-motion
    dominant: str
    likely_cause: str
    stiffness: float = float("nan")   # dk (N/m or N m/rad) that explains a slow tangential mode, velocity mode
    direction: list = field(default_factory=list)   # the mode's direction in the velocity rows (unit)
    predicted: float = float("nan")   # 1/s: row_force_drift's nearest eigenvalue (slow velocity-row modes)
    driven_by: str = ""               # the rows whose measured force drives it in that prediction

    def explained(self, tolerance):
        """True when ``predicted`` is within ``tolerance`` (relative) of the mode's eigenvalue."""
        return bool(np.isfinite(self.predicted) and self.predicted != 0
                    and abs(self.eigenvalue - self.predicted) <= tolerance * abs(self.predicted))

    def summary(self):
        shares = ", ".join(f"{name} {100 * value:.0f} %" for name, value in self.shares.items())
        value = self.eigenvalue
        text = f"{value.real:.3g}{value.imag:+.3g}j" if abs(value.imag) > 1e-9 else f"{value.real:.3g}"
        return f"unstable mode {text} 1/s ({self.dominant}: {shares}): {self.likely_cause}"

    def as_dict(self):
        return {"eigenvalue": [float(self.eigenvalue.real), float(self.eigenvalue.imag)], "shares": self.shares,
                "dominant": self.dominant, "likely_cause": self.likely_cause,
                "stiffness": None if np.isnan(self.stiffness) else self.stiffness,
                "direction": self.direction,
                "predicted": None if np.isnan(self.predicted) else self.predicted, "driven_by": self.driven_by}


def explained_modes(unstable, diagnoses, tolerance):
    """True when every eigenvalue in ``unstable`` has a diagnosis (same eigenvalue) whose
    prediction it is within ``tolerance`` of (``ModeDiagnosis.explained``)."""
    owner = "explained_modes"
    unstable = complex_vector(np.atleast_1d(unstable) if isinstance(unstable, (numbers.Number, np.ndarray))
                              else unstable, "unstable", owner)
    tolerance = relative_tolerance(tolerance, "tolerance", owner)
    if not isinstance(diagnoses, (list, tuple)) or not all(isinstance(d, ModeDiagnosis) for d in diagnoses):
        raise ArgumentError(f"{owner}: diagnoses must be a list of ModeDiagnosis (diagnose_unstable_modes), got "
                            f"{describe(diagnoses)}")
    for value in np.atleast_1d(unstable):
        same = [d for d in diagnoses if abs(d.eigenvalue - value) <= 1e-6 * max(1.0, abs(value))]
        if not any(d.explained(tolerance) for d in same):
            return False
    return True


def drift_eigenvalues(mobility, stiffness, velocity_gain, position_gain=None):
    """Eigenvalues of y-ddot = -K_v y-dot - K_p y + G y, G = ``mobility`` @ ``stiffness`` (k x u
    and u x k: the velocity rows' mobility to the rows u and dF_u/dy); ``position_gain`` K_p is
    None in velocity-force mode. Sorted by real part, largest first."""
    owner = "drift_eigenvalues"
    mobility = numeric_array(mobility, "mobility", owner, what="a k x u matrix")
    if mobility.ndim != 2:
        raise ArgumentError(f"{owner}: mobility must be a k x u matrix, got {describe(mobility)}")
    k, u = mobility.shape
    G = mobility @ matrix(stiffness, "stiffness", owner, (u, k))
    K_v = matrix(velocity_gain, "velocity_gain", owner, (k, k))
    K_p = np.zeros((k, k)) if position_gain is None else matrix(position_gain, "position_gain", owner, (k, k))
    values = np.linalg.eigvals(impedance_matrix(K_v, K_p, stiffness=G))       # G acts as the environment's K_e
    return values[np.argsort(-values.real)]


@dataclass
class DriftPrediction:
    """``row_force_drift``'s result: the eigenvalues of the rigid arm's velocity rows under the row
    forces the law leaves on the arm, and of the held rows' and the velocity rows' parts alone."""

    eigenvalues: np.ndarray           # with every row u the law leaves (largest real part first)
    held_rows: np.ndarray             # with the held rows' force alone (empty without held rows, or cancelled)
    velocity_rows: np.ndarray         # with F_v alone (empty when the law cancels it)
    stiffness: np.ndarray             # dF/dy: all rows (velocity rows, then E_f's) by velocity row
    held: tuple                       # indices of the held rows among E_f's
    cancels_tangential: bool

    @property
    def driven_by(self):
        """The rows whose force drives the largest eigenvalue: the part alone that comes closer."""
        parts = {"held rows": self.held_rows, "velocity rows": self.velocity_rows}
        top = {name: values[0].real for name, values in parts.items() if len(values)}
        if not top:
            return ""
        return max(top, key=top.get)


def row_force_drift(scenario, context, mode, step=DRIFT_STEP):
    """Predict the velocity rows' slow eigenvalues from the row forces the law leaves on the arm
    (module docstring): a ``DriftPrediction``, or None in impedance-force mode (whose K_0 takes
    every motion row's measured force) or without velocity rows.

    ``scenario``, ``context``: the closed loop at its linearization point (the arm's positions
    are moved by ``step`` along each velocity row, dq = J^+ E^-1 e_i, on clones of ``context``)."""
    owner = "row_force_drift"
    check_systems_context(scenario, context, owner)
    mode = ControlMode.parse(mode, owner)
    step = positive(step, "step", owner, unit="m or rad along a row")
    space = scenario.constraint_space
    k = space.velocity_size
    if k == 0 or mode is ControlMode.IMPEDANCE_FORCE:
        return None
    plant = scenario.plant
    plant_context = plant.GetMyContextFromRoot(context)
    q0 = plant.GetPositions(plant_context).copy()
    E, directions = row_directions(scenario, context)
    if directions is None:
        return None                                  # positions and velocities differ (a free body)
    J = scenario.kinematics.evaluate(plant_context, check=False).jacobian
    mobility = E @ J @ np.linalg.solve(plant.CalcMassMatrix(plant_context), J.T) @ E.T
    stiffness = np.zeros((E.shape[0], k))
    for i in range(k):
        dq = step * directions[:, i]
        stiffness[:, i] = (row_forces(scenario, context, q=q0 + dq)
                           - row_forces(scenario, context, q=q0 - dq)) / (2.0 * step)
    held = tuple(space.constraint.kinematic_rows)
    cancels = bool(getattr(scenario.controller, "compensate_tangential_force", False))
    gains = scenario.controller.validated_gains()
    K_p = gains.position if mode.integrates_position else None
    held_rows = [] if cancels else [k + i for i in held]          # law.held_row_compensation
    velocity_rows = [] if cancels else list(range(k))              # law.tangential_compensation

    def part(rows):
        if not rows:
            return np.zeros(0, complex)
        return drift_eigenvalues(mobility[:k][:, rows], stiffness[rows], gains.velocity, K_p)

    return DriftPrediction(eigenvalues=part(velocity_rows + held_rows), held_rows=part(held_rows),
                           velocity_rows=part(velocity_rows), stiffness=stiffness, held=held,
                           cancels_tangential=cancels)


def _plant_block(diagram, context, plant):
    """Offset of ``plant``'s continuous state in the diagram's continuous state vector."""
    offset = 0
    for system in diagram.GetSystems():
        if system is plant or system.get_name() == plant.get_name():
            return offset
        offset += system.GetMyContextFromRoot(context).num_continuous_states()
    raise ValueError("the plant has no continuous state in this diagram")


def diagnose_unstable_modes(scenario, context, A, mode, designed, threshold=UNSTABLE_RATE):
    """A ``ModeDiagnosis`` for every eigenvalue of ``A`` with real part above ``threshold``.

    ``scenario``, ``context``: the linearized closed loop and its linearization point; ``mode``:
    the ControlMode; ``designed``: the designed eigenvalues (to tell slow modes from fast ones)."""
    owner = "diagnose_unstable_modes"
    check_systems_context(scenario, context, owner)
    if getattr(scenario, "diagram", None) is None:
        raise ArgumentError(f"{owner}: scenario must have its diagram (a built Scenario, or HybridSystems with "
                            "diagram set: dataclasses.replace(systems, diagram=diagram))")
    size = context.num_continuous_states()
    A = matrix(A, "A", owner, (size, size))
    mode = ControlMode.parse(mode, owner)
    designed = complex_vector(designed, "designed", owner)
    threshold = number(threshold, "threshold", owner, unit="1/s")
    eigenvalues, vectors = np.linalg.eig(A)
    plant = scenario.plant
    plant_context = plant.GetMyContextFromRoot(context)
    offset = _plant_block(scenario.diagram, context, plant)
    nq = plant.num_positions()
    task = scenario.kinematics.evaluate(plant_context, check=False)
    values = scenario.constraint_space.evaluate(task.configuration, task.velocity, check=False)
    J = task.jacobian
    E_p, E_f = values.velocity_projection, values.force_projection
    M = plant.CalcMassMatrix(plant_context)
    mobility = E_p @ J @ np.linalg.solve(M, J.T) @ E_p.T
    K_v = scenario.controller.validated_gains().velocity
    slowest = float(np.min(np.abs(np.real(designed)))) if len(designed) else 1.0
    prediction = []                                  # row_force_drift, computed once when needed
    diagnoses = []
    for value, vector in zip(eigenvalues, vectors.T):
        if not value.real > threshold:
            continue
        dq = vector[offset:offset + nq]
        dq = dq / (np.max(np.abs(dq)) or 1.0)
        motion = J @ dq
        tangential, normal = E_p @ motion, E_f @ motion
        self_motion = dq - np.linalg.pinv(J) @ motion
        parts = {"velocity rows": np.linalg.norm(tangential), "constraint rows": np.linalg.norm(normal),
                 "self-motion": np.linalg.norm(self_motion)}
        total = sum(parts.values())
        shares = {name: float(part / total) if total > 0 else 0.0 for name, part in parts.items()}
        dominant = max(shares, key=shares.get) if total > 0 else "controller and sensor states"
        slow_real = abs(value.imag) < 1e-6 * max(1.0, abs(value)) and abs(value) < 0.5 * slowest
        stiffness, direction = float("nan"), []
        predicted, driven_by = float("nan"), ""
        if dominant == "velocity rows" and slow_real:
            if not prediction:
                prediction.append(row_force_drift(scenario, context, mode))
            drift = prediction[0]
            if drift is not None and len(drift.eigenvalues):
                nearest = drift.eigenvalues[np.argmin(np.abs(drift.eigenvalues - value))]
                predicted, driven_by = float(nearest.real), drift.driven_by
            u = np.real(tangential) / (np.linalg.norm(np.real(tangential)) or 1.0)
            direction = [float(x) for x in u]
            inertia = 1.0 / float(u @ mobility @ u)
            s = float(value.real)
            stiffness = inertia * s * (s + float(u @ K_v @ u))
            if mode.integrates_position:                 # Lambda (s^2 + K_v s + K_p) = dk
                stiffness += inertia * float(u @ scenario.controller.validated_gains().position @ u)
            if driven_by == "held rows":
                rows = ", ".join(str(i + 1) for i in drift.held)
                tail = f"F_v's part alone predicts {drift.velocity_rows[0].real:.3g}"
                cause = (f"drift of the positions the velocity rows leave unregulated along r_p direction "
                         f"{np.round(u, 2).tolist()}, driven by the measured force on the held row(s) {rows} of E_f: "
                         "a contact torque about the pad's centre from the tessellated pad and workpiece (a smooth "
                         "ball on a smooth surface gives none), which the paper's form of the law leaves on the "
                         f"arm in {mode.value} mode; the rigid arm's loop with the contact's measured row-force stiffness "
                         f"predicts {predicted:.3g} 1/s ({tail}; analysis.modes.row_force_drift). It changes with "
                         "the pad's place on the meshes and their resolution (contact.pad_resolution); "
                         "compensate_tangential_force: true (the default; off here) cancels it, and position-force "
                         "or impedance-force mode regulates it (docs/drake_notes.md)")
            elif mode.integrates_position:
                cause = (f"a contact stiffness along the velocity rows (direction {np.round(u, 2).tolist()}) beyond "
                         f"what K_p holds (about {stiffness:.3g} N/m or N m/rad); raise gains.position")
            else:
                if getattr(scenario.controller, "compensate_tangential_force", False):
                    remedy = ("the law cancels the measured F_v, so the stiffness acts through the wrench path's "
                              "lag: raise sensor.bandwidth_hz, or use position-force or impedance-force mode")
                else:
                    remedy = ("compensate_tangential_force: true (the default; off here), position-force or "
                              "impedance-force mode removes it")
                cause = (f"drift of the positions the velocity rows leave unregulated (velocity-force mode has no "
                         f"position feedback) along r_p direction {np.round(u, 2).tolist()}: a destabilizing contact "
                         f"stiffness of about {stiffness:.3g} (N/m or N m/rad along it) beyond the geometric F/rho "
                         "that the law cancels, from the tessellated pad and workpiece on a curved surface "
                         f"(docs/drake_notes.md); {remedy}")
        elif dominant == "velocity rows":
            cause = "a fast mode along the velocity rows: contact and sensor dynamics against K_v (wrench filter, pad)"
        elif dominant == "self-motion":
            cause = "the redundant arm's self-motion: raise gains.null_space_damping"
        elif dominant == "constraint rows":
            cause = ("the force loop against the contact: pad stiffness (contact.pad_modulus) with K_fp, K_fi and the "
                     "wrench filter (sensor.bandwidth_hz)")
        else:
            cause = "controller or sensor states without arm motion (integrals, wrench filter)"
        if np.isfinite(predicted) and driven_by != "held rows":
            cause += f"; predicted {predicted:.3g} 1/s by analysis.modes.row_force_drift"
        diagnoses.append(ModeDiagnosis(eigenvalue=complex(value), shares=shares, dominant=dominant,
                                       likely_cause=cause, stiffness=stiffness, direction=direction,
                                       predicted=predicted, driven_by=driven_by))
    return diagnoses
