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
"""

from dataclasses import dataclass, field

import numpy as np

UNSTABLE_RATE = 0.01                  # 1/s: a mode growing faster than 1 % per second is named


@dataclass
class ModeDiagnosis:
    eigenvalue: complex
    shares: dict                      # part of the mode's task motion: velocity rows, constraint rows, self-motion
    dominant: str
    likely_cause: str
    stiffness: float = float("nan")   # dk (N/m or N m/rad) that explains a slow tangential mode, velocity mode
    direction: list = field(default_factory=list)   # the mode's direction in the velocity rows (unit)

    def summary(self):
        shares = ", ".join(f"{name} {100 * value:.0f} %" for name, value in self.shares.items())
        value = self.eigenvalue
        text = f"{value.real:.3g}{value.imag:+.3g}j" if abs(value.imag) > 1e-9 else f"{value.real:.3g}"
        return f"unstable mode {text} 1/s ({self.dominant}: {shares}): {self.likely_cause}"

    def as_dict(self):
        return {"eigenvalue": [float(self.eigenvalue.real), float(self.eigenvalue.imag)], "shares": self.shares,
                "dominant": self.dominant, "likely_cause": self.likely_cause,
                "stiffness": None if np.isnan(self.stiffness) else self.stiffness,
                "direction": self.direction}


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
        if dominant == "velocity rows" and slow_real:
            u = np.real(tangential) / (np.linalg.norm(np.real(tangential)) or 1.0)
            direction = [float(x) for x in u]
            inertia = 1.0 / float(u @ mobility @ u)
            s = float(value.real)
            stiffness = inertia * s * (s + float(u @ K_v @ u))
            if mode.integrates_position:                 # Lambda (s^2 + K_v s + K_p) = dk
                stiffness += inertia * float(u @ scenario.controller.validated_gains().position @ u)
            if mode.integrates_position:
                cause = (f"a contact stiffness along the velocity rows (direction {np.round(u, 2).tolist()}) beyond "
                         f"what K_p holds (about {stiffness:.3g} N/m or N m/rad); raise gains.position")
            else:
                if getattr(scenario.config, "compensate_tangential_force", False):
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
        diagnoses.append(ModeDiagnosis(eigenvalue=complex(value), shares=shares, dominant=dominant,
                                       likely_cause=cause, stiffness=stiffness, direction=direction))
    return diagnoses
