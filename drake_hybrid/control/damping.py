"""Joint damping declared in the model, on a discrete plant: the law consistent with the step.

The law cancels the model's joint damping explicitly: its inverse dynamics include the force
elements, so tau contains + B v at the velocity v of the tick. A discrete (SAP or TAMSI)
MultibodyPlant applies joint damping implicitly, at the end-of-step velocity v+ (everything
else at the start of the step)::

    M (v+ - v) = h (tau - c(q, v) + g(q) - B v+ + J^T F)

With tau = M a* + c - g + B v - J^T F (the law's a*, its contact terms balanced) this is
(M + h B)(v+ - v) = h M a*: the joint accelerates at (M + h B)^-1 M a*, not a*. A joint with
b h / M of order 10 (a light wrist with the damping of its URDF) gets a tenth of what the law
asks: its velocity row stalls (the designed -K_v becomes about -K_v / (1 + b h / M)), though
the continuous linearization, which has no step, shows nothing.

Compensating the damping on the *predicted end-of-step* velocity v+ = v + h a* instead of v,
tau_damping = B (v + h a*), adds h B a* to the explicit B v already in tau::

    M (v+ - v) = h (M a* + B v + h B a* - B v+)
    (M + h B)(v+ - v) = h (M + h B) a*    ->    v+ = v + h a*

exactly the designed step, whatever b h / M. ``damping_compensation`` returns that h B a*;
the law adds it to its torque (``HybridController``, ``plant_time_step``). On a continuous plant
(h = 0) it vanishes. With a control period of several plant steps the held torque uses the
tick's a* for each of them: exact in the first step, to O(h) after.

The compensation makes the *commanded* step exact; a force the law does not command (the
measured contact force J^T F, the constraint's reaction) still meets the implicit damping::

    (M + h B)(v+ - v) = h (M + h B) a* + h J^T F    ->    (v+ - v) / h = a* + (M + h B)^-1 J^T F

so within a step the arm answers a force through (M + h B)^-1, not M^-1. The impedance law's K_0
(3.2-6) cancels that answer (its "- S F_v" term, S = M_p - M_fp^T M_f^-1 M_fp: the force rows'
reaction (3.2-9) acts through the same step): built from J M^-1 J^T it over-cancels on a joint
with large b h / M (the xArm7's wrist, b h / M = 11.8: 2.07 % velocity error on a 5 cm sphere
against 0.64 %). The law builds K_0's blocks from the step's task mobility J (M + h B)^-1 J^T
(``step_task_mobility``, same condition as ``damping_compensation``); the task inertia that turns
a* into torque keeps Lambda = (J M^-1 J^T)^-1, since the compensation above already makes the
commanded step exact.

Conditioning: where b h / M_ii > 1, the joint's step is dominated by its damping and the row
relies on this compensation (a torque 1 + b h / M times the inertial one, so errors in the
modelled damping or in the time step scale with it). ``damped_joints`` finds such joints and
``warn_damped_joints`` says so, one line per joint; a smaller plant step is the remedy.
"""

import warnings

import numpy as np

from drake_hybrid.core.linalg import inv

# b h / M above which a joint's step is dominated by its damping (warned).
DAMPING_DOMINATED = 1.0


class JointDampingWarning(UserWarning):
    """A joint's damping dominates the plant's discrete step (b h / M > 1): its velocity row relies
    on the law's compensation of the implicit damping."""


def joint_damping(plant):
    """The model's viscous joint damping B (diagonal, per generalized velocity; N m s/rad or
    N s/m) from the joints' default damping."""
    damping = np.zeros(plant.num_velocities())
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        if joint.num_velocities() > 0:
            start = joint.velocity_start()
            damping[start:start + joint.num_velocities()] = joint.default_damping_vector()
    return damping


def damped_step(damping, time_step):
    """True when the plant's step damps implicitly: a discrete plant (h > 0) and joint damping B in
    the model (``damping``: B's diagonal or None)."""
    return time_step > 0 and damping is not None and bool(np.any(damping))


def damping_compensation(damping, joint_acceleration, time_step):
    """h B a*: the torque that makes a discrete plant's implicit damping B v+ match the law's
    explicit B v (tau_damping = B v+ with v+ = v + h a* predicted; module docstring)."""
    if not damped_step(damping, time_step):
        return joint_acceleration * 0.0
    return time_step * damping * joint_acceleration


def step_task_mobility(jacobian, M, task_mobility, damping, time_step):
    """J (M + h B)^-1 J^T: how the task answers a force within one step of a discrete plant with
    joint damping B (module docstring); ``task_mobility`` (J M^-1 J^T) itself when the step does not
    damp (``damped_step``: a continuous plant, no damping). Float or AutoDiffXd."""
    if not damped_step(damping, time_step):
        return task_mobility
    return jacobian @ inv(M + time_step * np.diag(damping)) @ jacobian.T


def damped_joints(plant, time_step, context=None, threshold=DAMPING_DOMINATED):
    """[(joint name, b h / M_ii)] for the joints of ``plant`` (float) whose damping dominates a
    step of ``time_step`` (b h / M_ii > ``threshold``), M at ``context`` (default: the plant's
    default context)."""
    if not time_step > 0:
        return []
    damping = joint_damping(plant)
    if not np.any(damping):
        return []
    context = context if context is not None else plant.CreateDefaultContext()
    inertia = np.diag(plant.CalcMassMatrix(context))
    ratios = damping * time_step / inertia
    found = []
    for index in plant.GetJointIndices():
        joint = plant.get_joint(index)
        for i in range(joint.velocity_start(), joint.velocity_start() + joint.num_velocities()):
            if ratios[i] > threshold:
                found.append((joint.name(), float(ratios[i])))
    return found


def warn_damped_joints(plant, time_step, context=None):
    """One ``JointDampingWarning`` line per joint whose damping dominates the step (``damped_joints``)."""
    for name, ratio in damped_joints(plant, time_step, context):
        warnings.warn(JointDampingWarning(
            f"joint '{name}': damping b h / M = {ratio:.3g} at the plant step h = {time_step:g} s; its velocity row "
            f"relies on compensating the solver's implicit damping (control.damping); a step below "
            f"{time_step / ratio:.3g} s makes it well conditioned"), stacklevel=3)
