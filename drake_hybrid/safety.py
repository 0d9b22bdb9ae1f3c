"""Protections of the control law against what the paper assumes away: actuator limits and
kinematic singularities.

The paper's law (3.1-12) assumes unbounded torques and an invertible Jacobian J. A real arm
has effort limits (Drake's MultibodyPlant clamps the actuation input to
``JointActuator.effort_limit()``, measured in 1.51.1 for discrete and continuous plants) and
passes near configurations where J loses rank. ``HybridController`` uses the helpers here:

``saturate``
    graceful saturation: with tau = tau_0 + tau_task (tau_0 = h + g, the torque that holds the
    arm against gravity and velocity products), scale the task part by the largest
    s in [0, 1] that keeps every actuator within its limit. The task-space command keeps its
    direction (velocity and force loops are scaled together instead of one joint's clip
    distorting both); if tau_0 alone exceeds a limit, that actuator is clipped. The controller
    freezes its integrals while s < 1 or an actuator is clipped (conditional integration, the
    anti-windup of Astrom & Hagglund), so the integrals do not wind up during saturation.

``damped_solve``, ``damped_inverse``
    the damped least-squares inverse J^T (J J^T + lambda^2 I)^-1 (Nakamura & Hanafusa 1986;
    Chiaverini 1997) with the variable damping lambda^2 = lambda_max^2 (1 - (sigma_min /
    epsilon)^2) below the threshold sigma_min < epsilon and no damping above it: exact away from
    singularities, bounded near them. The first entry into the damped region warns once per
    controller (``KinematicSingularityWarning``).

``SafetyConfig`` is the YAML-friendly description (``ScenarioConfig.safety``).
"""

import enum
import warnings
from dataclasses import dataclass, field
from typing import List

import numpy as np

from pydrake.autodiffutils import AutoDiffXd

from drake_hybrid.errors import DimensionError
from drake_hybrid.linalg import inv, singular_values, solve, value


class KinematicSingularityWarning(UserWarning):
    """The arm is near a kinematic singularity: the controller uses a damped inverse of J there,
    so the commanded task acceleration is only approximately produced."""


@dataclass
class SafetyConfig:
    """Actuator saturation and singularity damping of the controller.

    effort_limits: per-actuator limits (N m); empty = the plant's ``effort_limit()`` (inf where
        the model has none).
    anti_windup: freeze the integrals (xi, e_p) while the actuation saturates.
    singularity_threshold: epsilon, the smallest singular value of the task Jacobian J (in the
        chart's units, m/rad for the position rows) below which the damped inverse is used.
    singularity_damping: lambda_max, the damping at sigma_min = 0 (same units).
    """

    effort_limits: List[float] = field(default_factory=list)
    anti_windup: bool = True
    singularity_threshold: float = 0.02
    singularity_damping: float = 0.05

    def validated(self, num_actuators, plant_limits):
        """(limits array, anti_windup, threshold, damping); ValueError naming the bad field."""
        limits = np.asarray(self.effort_limits if len(self.effort_limits) else plant_limits, dtype=float)
        if limits.shape != (num_actuators,):
            raise DimensionError(f"safety.effort_limits must have one entry per actuator ({num_actuators}), "
                                 f"got {len(self.effort_limits)}")
        if np.any(np.isnan(limits)) or np.any(limits <= 0):
            raise ValueError(f"safety.effort_limits must be positive, got {limits.tolist()}")
        if not float(self.singularity_threshold) >= 0:
            raise ValueError(f"safety.singularity_threshold must be >= 0, got {self.singularity_threshold}")
        if not float(self.singularity_damping) > 0:
            raise ValueError(f"safety.singularity_damping must be positive, got {self.singularity_damping}")
        return limits, bool(self.anti_windup), float(self.singularity_threshold), float(self.singularity_damping)


# ------------------------------------------------------------------------------------------------
# Saturation
# ------------------------------------------------------------------------------------------------

def saturation_scale(base, task, limits):
    """The largest s in [0, 1] with |base + s task| <= limits for every entry (0 if ``base``
    alone violates a limit). Floats."""
    scale = 1.0
    for b, t, limit in zip(base, task, limits):
        if abs(b) > limit:
            return 0.0
        if t > 0 and b + t > limit:
            scale = min(scale, (limit - b) / t)
        elif t < 0 and b + t < -limit:
            scale = min(scale, (-limit - b) / t)
    return max(scale, 0.0)


def saturate(actuation, base_actuation, limits):
    """Graceful saturation of ``actuation`` = base + task (see the module docstring).

    ``base_actuation`` is a callable returning the base (h + g mapped to the actuators); it is
    only called when a limit is exceeded. Returns (saturated actuation, s, clipped) where s is
    the scale of the task part and ``clipped`` says whether the base itself had to be clipped.
    Works for float and AutoDiffXd arrays (s is computed from the values and held constant).
    """
    values = value(actuation)
    if np.all(np.abs(values) <= limits):
        return actuation, 1.0, False
    base = base_actuation()
    base_values = value(base)
    scale = saturation_scale(base_values, values - base_values, limits)
    saturated = base + scale * (actuation - base)
    saturated_values = value(saturated)
    clipped = bool(np.any(np.abs(saturated_values) > limits))
    if clipped:
        saturated = np.array(saturated, copy=True)
        for i, (v, limit) in enumerate(zip(saturated_values, limits)):
            if abs(v) > limit:
                bound = float(np.sign(v) * limit)        # a constant: zero derivative beyond the limit
                saturated[i] = AutoDiffXd(bound) if saturated.dtype == object else bound
    return saturated, scale, clipped


# ------------------------------------------------------------------------------------------------
# Damped inverses near kinematic singularities
# ------------------------------------------------------------------------------------------------

def damping_factor(sigma_min, threshold, damping):
    """lambda^2 = lambda_max^2 (1 - (sigma_min / epsilon)^2) for sigma_min < epsilon, else 0."""
    if not sigma_min < threshold:
        return 0.0
    return damping * damping * (1.0 - (sigma_min / threshold) ** 2)


def warn_singularity(owner, sigma_min, threshold):
    """Warn, once per ``owner`` (a controller), that J is nearly singular."""
    if getattr(owner, "_singularity_warned", False):
        return
    owner._singularity_warned = True
    warnings.warn(KinematicSingularityWarning(
        f"{type(owner).__name__}: the task Jacobian is near a kinematic singularity (smallest singular value "
        f"{sigma_min:.3g} < threshold {threshold:.3g}); using the damped least-squares inverse, so the commanded "
        "task acceleration is only approximately produced"), stacklevel=3)


def damped_solve(J, rhs, threshold, damping):
    """x = J^-1 rhs for square J, or J^T (J J^T + lambda^2 I)^-1 rhs near a singularity.

    Returns (x, sigma_min, lambda^2)."""
    sigma_min = float(singular_values(J)[-1])
    lambda_squared = damping_factor(sigma_min, threshold, damping)
    if lambda_squared == 0.0:
        return solve(J, rhs), sigma_min, 0.0
    d = J.shape[0]
    return J.T @ solve(J @ J.T + lambda_squared * np.eye(d), rhs), sigma_min, lambda_squared


def damped_task_inertia(J, task_mobility, threshold, damping):
    """Lambda = (J M^-1 J^T)^-1, or (J M^-1 J^T + lambda^2 rho I)^-1 near a singularity of J.

    rho = trace(J M^-1 J^T) / trace(J J^T) converts the Jacobian-unit damping to mobility units
    (an average inverse mass). Returns (Lambda, sigma_min, lambda^2)."""
    sigma_min = float(singular_values(J)[-1])
    lambda_squared = damping_factor(sigma_min, threshold, damping)
    if lambda_squared == 0.0:
        return inv(task_mobility), sigma_min, 0.0
    J_value, mobility_value = value(J), value(task_mobility)
    rho = float(np.trace(mobility_value) / np.trace(J_value @ J_value.T))
    d = J.shape[0]
    return inv(task_mobility + (lambda_squared * rho) * np.eye(d)), sigma_min, lambda_squared


def all_finite(array):
    """True if every entry (float or AutoDiffXd value) is finite."""
    return bool(np.all(np.isfinite(value(np.asarray(array)))))


# ------------------------------------------------------------------------------------------------
# Contact phases (the contact supervisor's state; the controller's law depends on it)
# ------------------------------------------------------------------------------------------------

class ContactPhase(enum.IntEnum):
    """Phases of ``supervision.ContactSupervisor``; the value travels on its ``contact_phase`` port.

    In every phase but CONTACT the controller runs the guarded move on the force-controlled rows
    of C: C-ddot = -K_a (C-dot - s n_C) with n_C the pressing direction in C's coordinates and
    s the approach speed (APPROACH) or 0 (TARE, HOLD); no force feedback, integrals frozen.
    """

    TARE = 0        # in free space, holding still while the wrench conditioner measures the sensor's bias
    APPROACH = 1    # guarded move toward the surface at the approach speed
    CONTACT = 2     # the hybrid law of the paper
    HOLD = 3        # no surface within the allowed travel: holding still, waiting for a force
