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

``bounded_solve``, ``bounded_task_inertia``
    the joint acceleration J^-1 (r-ddot* - J-dot q-dot) of the law, exact unless J is near a
    singularity (sigma_min(J) < ``singularity_threshold``) and the exact solution exceeds
    ``max_joint_acceleration``; then the damped least-squares solution J^T (J J^T +
    lambda^2 I)^-1 (Nakamura & Hanafusa 1986; Wampler 1986) with the smallest damping that
    brings it to the bound (the trust-region solution of min |J x - r| s.t. |x| <= bound).
    Near a singularity J^-1 grows like 1 / sigma_min, but only the part of the command along
    the lost direction is amplified: a path that crosses a singularity consistently (the crank's
    UR5e crosses its wrist singularity with |q-ddot| < 20 rad/s^2) stays exact, while a command
    the arm cannot follow (the planar arm stretched against the window: about 380 rad/s^2
    undamped) is bounded. A threshold on sigma_min alone damps both (measured on the crank: the
    force error after five time constants rises from 0.2 % to 2-2.7 % for thresholds 0.002-0.02).
    The first time the bound is active the controller warns (``KinematicSingularityWarning``).

``SafetyConfig`` is the YAML-friendly description (``ScenarioConfig.safety``).
"""

import math
import warnings
from dataclasses import dataclass, field
from typing import List

import numpy as np

from pydrake.autodiffutils import AutoDiffXd

from drake_hybrid.core.arguments import boolean, describe, number, numeric_array
from drake_hybrid.core.errors import ArgumentError, DimensionError, KinematicSingularityWarning
from drake_hybrid.core.linalg import inv, solve, value


@dataclass
class SafetyConfig:
    """Actuator saturation and singularity damping of the controller.

    effort_limits: per-actuator limits (N m); empty = the plant's ``effort_limit()`` (inf where
        the model has none).
    anti_windup: freeze the integrals (xi, e_p) while the actuation saturates.
    singularity_threshold: sigma_min(J) below which J counts as near singular (in the chart's
        units: m/rad on position rows, 1 on angle rows). The window task runs at 0.41 or more,
        the sphere at 0.067 or more; the crank's UR5e crosses its wrist singularity (6e-4).
    max_joint_acceleration: near a singularity, the bound (rad/s^2, Euclidean norm over the
        joints) on the joint acceleration the law's task part may command; beyond it the
        damped least-squares solution is used. The window, crank and sphere tasks command at
        most 2, 19 and 16 rad/s^2 (measured along their default runs).
    """

    effort_limits: List[float] = field(default_factory=list)
    anti_windup: bool = True
    singularity_threshold: float = 0.05
    max_joint_acceleration: float = 50.0

    def validated(self, num_actuators, plant_limits):
        """(limits, anti_windup, singularity_threshold, max_joint_acceleration); ValueError naming the
        bad field."""
        owner = "SafetyConfig"
        given = numeric_array(self.effort_limits, "safety.effort_limits", owner, finite=False,
                              what="a vector with one limit per actuator (N m; inf: none; empty: the plant's)")
        limits = given if given.size else np.asarray(plant_limits, dtype=float)
        if given.ndim > 1:
            raise DimensionError(f"{owner}: safety.effort_limits must be a vector with one entry per actuator "
                                 f"({num_actuators}), not a matrix: got {describe(self.effort_limits)}")
        if limits.shape != (num_actuators,):
            raise DimensionError(f"safety.effort_limits must have one entry per actuator ({num_actuators}), "
                                 f"got {given.size}")
        if np.any(limits <= 0):
            raise ArgumentError(f"safety.effort_limits must be positive, got {limits.tolist()}")
        number(self.max_joint_acceleration, "safety.max_joint_acceleration", owner, low=0.0, low_inclusive=False,
               unit="rad/s^2")
        number(self.singularity_threshold, "safety.singularity_threshold", owner, low=0.0)
        boolean(self.anti_windup, "safety.anti_windup", owner)
        return limits, bool(self.anti_windup), float(self.singularity_threshold), float(self.max_joint_acceleration)


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
    values = value(actuation) if actuation.dtype == object else actuation
    if (np.abs(values) <= limits).all():
        return actuation, 1.0, False
    base = base_actuation()
    base_values = value(base)
    scale = saturation_scale(base_values, values - base_values, limits)
    saturated = base + scale * (actuation - base)
    saturated_values = value(saturated)
    # Clipped: the base itself violates a limit (then s = 0). Entries the scale put at their limit may
    # overshoot it by rounding; they are set to the limit too, but that is not clipping.
    clipped = bool(np.any(np.abs(base_values) > limits))
    if np.any(np.abs(saturated_values) > limits):
        saturated = np.array(saturated, copy=True)
        for i, (v, limit) in enumerate(zip(saturated_values, limits)):
            if abs(v) > limit:
                bound = float(np.sign(v) * limit)        # a constant: zero derivative beyond the limit
                saturated[i] = AutoDiffXd(bound) if saturated.dtype == object else bound
    return saturated, scale, clipped


# ------------------------------------------------------------------------------------------------
# Bounded (damped) inverses near kinematic singularities
# ------------------------------------------------------------------------------------------------

def _damping_for_norm(norm_at, max_norm, scale):
    """The smallest lambda^2 >= 0 with norm_at(lambda^2) <= max_norm (norm_at decreasing), by bisection
    on log lambda^2 between 1e-12 scale and 1e6 scale (scale: the squared size of the matrix)."""
    low, high = 1e-12 * scale, 1e6 * scale
    for _ in range(60):
        middle = math.sqrt(low * high)
        if norm_at(middle) > max_norm:
            low = middle
        else:
            high = middle
    return high


def bounded_solve(J, rhs, threshold, max_norm):
    """x = J^-1 rhs, unless J is near singular (sigma_min(J) < threshold) and |J^-1 rhs| > max_norm
    (or J is singular): then the damped least-squares solution x = J^T (J J^T + lambda^2 I)^-1 rhs
    with the smallest lambda giving |x| = max_norm.

    That is the trust-region solution of min |J x - rhs| subject to |x| <= max_norm: exact
    whenever the exact solution is within the bound (however close J is to singular), bounded
    and continuous where it is not, and defined at an exact singularity. Returns (x, sigma_min,
    lambda^2); lambda^2 = 0 means exact, and sigma_min is None when the exact solution is within
    the bound (the common case, which then costs no SVD). Float or AutoDiffXd J and rhs (lambda^2
    from the values).
    """
    try:
        exact = solve(J, rhs)
        exact_value = value(exact) if exact.dtype == object else exact
        if exact_value @ exact_value <= max_norm * max_norm:   # (False for NaN)
            return exact, None, 0.0
    except np.linalg.LinAlgError:                              # J exactly singular
        exact = None
    J_value, rhs_value = value(J), value(rhs)
    U, sigma, _ = np.linalg.svd(J_value)
    sigma_min = float(sigma[-1])
    if exact is not None and sigma_min >= threshold:
        return exact, sigma_min, 0.0                           # a large command, but far from a singularity
    coefficients = U.T @ rhs_value                              # rhs in the left singular basis
    norm_at = lambda l2: np.linalg.norm(sigma * coefficients / (sigma * sigma + l2))   # |x(lambda)|
    lambda_squared = _damping_for_norm(norm_at, max_norm, float(sigma[0] ** 2))
    d = J.shape[0]
    return J.T @ solve(J @ J.T + lambda_squared * np.eye(d), rhs), sigma_min, lambda_squared


def bounded_task_inertia(J, M_inverse, task_mobility, rhs, threshold, max_norm):
    """Lambda = (J M^-1 J^T)^-1, unless sigma_min(J) < threshold and the joint acceleration
    M^-1 J^T Lambda rhs exceeds max_norm: then (J M^-1 J^T + mu I)^-1 with the smallest mu that
    brings it to max_norm (the redundant arm's version of ``bounded_solve``).
    Returns (Lambda, sigma_min(J) or None, mu)."""
    J_value, M_inverse_value, mobility_value, rhs_value = value(J), value(M_inverse), value(task_mobility), value(rhs)
    d = J.shape[0]

    def norm_at(mu):
        return np.linalg.norm(M_inverse_value @ J_value.T @ np.linalg.solve(mobility_value + mu * np.eye(d), rhs_value))

    try:
        exact_norm = norm_at(0.0)
        if np.isfinite(exact_norm) and exact_norm <= max_norm:
            return inv(task_mobility), None, 0.0
    except np.linalg.LinAlgError:
        exact_norm = np.inf
    sigma_min = float(np.linalg.svd(J_value, compute_uv=False)[-1])
    if sigma_min >= threshold and np.isfinite(exact_norm):
        return inv(task_mobility), sigma_min, 0.0
    mu = _damping_for_norm(norm_at, max_norm, float(np.trace(mobility_value)) / d)
    return inv(task_mobility + mu * np.eye(d)), sigma_min, mu


def warn_singularity(owner, sigma_min, max_norm):
    """Warn, once per ``owner`` (a controller), that the bounded inverse is active."""
    if getattr(owner, "_singularity_warned", False):
        return
    owner._singularity_warned = True
    warnings.warn(KinematicSingularityWarning(
        f"{type(owner).__name__}: near a kinematic singularity (smallest singular value of J {sigma_min:.3g}) "
        f"the commanded task acceleration needs more than {max_norm:g} rad/s^2 of joint acceleration; using the "
        "damped least-squares solution bounded there, so the task acceleration is only approximately produced"),
        stacklevel=3)
