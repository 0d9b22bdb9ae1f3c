"""A start in any diagram: the states around the plant primed for the arm where it is.
"""

from typing import Callable, Optional, cast

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import brentq

from pydrake.systems.framework import Context

from drake_hybrid.core.arguments import joint_vector, vector
from drake_hybrid.core.errors import ConfigError, ForceSignError, OffConstraintError
from drake_hybrid.core.hints import Array
from drake_hybrid.station.handles import HybridSystems
from drake_hybrid.station.root_context import check_systems, systems_in_context
from drake_hybrid.station.sensing import WrenchSensor

# Plant steps taken (and undone) at the start so that a discrete plant's sampled outputs hold the
# start's static contact or constraint wrench (see set_initial_conditions).
PRIMING_STEPS = 20


def _contact_error(error: RuntimeError, owner: str) -> ConfigError:
    """Drake's refusal of a contact at the start (two geometries touching without a hydroelastic
    representation: the arm's links with each other or with the workpiece) as a ConfigError saying what to do."""
    return ConfigError(f"{owner}: {str(error).strip().splitlines()[0]} -- the start's contact is computed with "
                       "hydroelastic contact: give the workpiece a rigid hydroelastic geometry "
                       "(station.workpieces.add_rigid_workpiece) and let only the tool touch it (only_tool_touches "
                       "after plant.Finalize())")


def prime_start(systems: HybridSystems, root_context: Context, held_torque: ArrayLike,
                integrals: Optional[ArrayLike] = None) -> None:
    """Set the states of the systems around the plant for a start at the plant's present state (set it
    first: the arm at rest where it presses, or a gap away): the controller's integrals (``integrals``,
    default zero: [xi; e_p]) and, for a sampled controller, its held torque ``held_torque``
    (``holding_torque``); a discrete plant's sampled contact results and reaction forces primed with
    the start's contact (steps taken and undone); the contact sensor's sampled point; the fault
    injector's, the wrench filter's or the conditioner's output at the first reading; the contact
    supervisor's entry value of C.

    ``systems``: a ``station.loop.HybridSystems`` (``add_hybrid_controller``) or a built
    ``Scenario``; ``root_context``: the diagram's root context.

    ArgumentError (before any state is set) for ``systems`` that are not HybridSystems, a
    ``root_context`` that is not the root context of their diagram (e.g. the plant's context), a
    ``held_torque`` that is not a vector of the controller plant's number of finite actuations
    (checked for a sampled controller, the one that holds it), ``integrals`` that are not a vector of
    the controller's finite [xi; e_p] entries."""
    owner = "prime_start"
    systems_in_context(root_context, systems, owner)
    plant, controller = systems.plant, systems.controller
    assert plant is not None                       # found in root_context's diagram (systems_in_context)
    plant_context = plant.GetMyMutableContextFromRoot(root_context)
    q0 = plant.GetPositions(plant_context, systems.robot.arm)
    environment = plant.GetPositionsAndVelocities(plant_context)
    controller_context = controller.GetMyMutableContextFromRoot(root_context)
    xi_slice, e_p_slice = controller.integral_state_slices()
    size = xi_slice.stop + (e_p_slice.stop - e_p_slice.start)
    integrals = np.zeros(size) if integrals is None else vector(integrals, "integrals", owner, size,
                                                                unit="[xi; e_p] of the controller")
    if controller.control_period is None:
        controller_context.SetContinuousState(integrals)
    else:
        held_torque = joint_vector(held_torque, "held_torque", owner, systems.controller_plant, kind="actuators",
                                   unit="the controller plant's actuation, N m or N: holding_torque")
        controller_context.SetDiscreteState(0, np.concatenate([integrals, held_torque]))
    if plant.time_step() > 0 and plant.has_sampled_output_ports():
        # A discrete plant's contact results and reaction forces are sampled at its steps; before the
        # first step they are empty. Take steps from the initial state (with the held static torque)
        # and put the state back, so the sensors read the start's contact wrench at t = 0.
        # Several steps let compliant constraints (e.g. a SAP weld) build up the static force.
        try:
            for _ in range(PRIMING_STEPS):
                plant.ExecuteForcedEvents(plant_context, publish=False)
        except RuntimeError as error:          # a touching pair without a hydroelastic representation
            plant.SetPositionsAndVelocities(plant_context, environment)
            raise _contact_error(error, owner) from None
        plant.SetPositionsAndVelocities(plant_context, environment)
    sensor = cast(WrenchSensor, systems.sensor)    # a simulated station's (a real arm's has none)
    if getattr(sensor, "samples_point", False):        # the contact sensor on those sampled results
        sensor.set_sampled_point(sensor.GetMyMutableContextFromRoot(root_context))
    try:
        reading = sensor.get_output_port(0).Eval(sensor.GetMyContextFromRoot(root_context))
    except RuntimeError as error:
        raise _contact_error(error, owner) from None
    if systems.fault_injector is not None:
        injector = systems.fault_injector
        injector.set_initial_sample(injector.GetMyMutableContextFromRoot(root_context), reading)
        faulty = injector.GetOutputPort("faulty_wrench").Eval(injector.GetMyContextFromRoot(root_context))
        reading = faulty if np.all(np.isfinite(faulty)) else reading
    if systems.wrench_filter is not None:
        filter_context = systems.wrench_filter.GetMyMutableContextFromRoot(root_context)
        systems.wrench_filter.set_initial_output(filter_context, reading)
    if systems.conditioner is not None:
        systems.conditioner.set_initial_output(systems.conditioner.GetMyMutableContextFromRoot(root_context), reading)
    if systems.supervisor is not None:
        supervisor = systems.supervisor
        controller_plant_context = systems.controller_plant.CreateDefaultContext()
        systems.controller_plant.SetPositions(controller_plant_context, q0)
        start = controller.kinematics.evaluate(controller_plant_context).configuration
        supervisor.set_initial_state(supervisor.GetMyMutableContextFromRoot(root_context), supervisor.initial_phase,
                                     systems.constraint_space.constraint.value(start))


def holding_torque(systems: HybridSystems, q: ArrayLike, desired_force: ArrayLike) -> np.ndarray:
    """tau = g(q) - J^T E_f^T F_d (2.3-4 at rest): the actuation that holds the robot at rest at ``q``
    pressing with ``desired_force`` (m, in E_f's coordinates; zeros: gravity only), mapped to the
    actuators, on the controller's own model (``systems.controller_plant``).

    ArgumentError for ``systems`` that are not HybridSystems, a ``q`` that is not a vector of the
    controller plant's number of finite positions, a ``desired_force`` that is not a vector of m finite
    numbers."""
    owner = "holding_torque"
    plant = check_systems(systems, owner).controller_plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, joint_vector(q, "q", owner, plant))
    task = systems.controller.kinematics.evaluate(context)
    values = systems.constraint_space.evaluate(task.configuration, task.velocity)
    desired_force = vector(desired_force, "desired_force", owner, values.force_projection.shape[0],
                           unit="N, in E_f's coordinates")
    tau_g: Array = plant.CalcGravityGeneralizedForces(context)
    gravity = -tau_g
    torque = gravity - task.jacobian.T @ (values.force_projection.T @ desired_force)
    return np.linalg.solve(plant.MakeActuationMatrix(), torque)


def pressing_depth(pressing_force: Callable[[float], float], desired: ArrayLike, max_depth: float, who: str) -> float:
    """The depth s in [0, max_depth] (m) at which ``pressing_force(s)`` (F . F_d / |F_d| - |F_d|, the
    pressing force's excess over the desired one) is zero, by Brent's method; the starts root
    finding cannot fix are named with typed errors (``who`` begins each message): the surface's
    geometry beyond C = 0 (OffConstraintError), a pulling F_d (ForceSignError), nothing touched
    (OffConstraintError), too soft a contact (ConfigError: the pad's modulus or the desired force)."""
    magnitude = float(np.linalg.norm(desired))
    at_surface = pressing_force(0.0) + magnitude
    if at_surface > magnitude:
        raise OffConstraintError(
            f"{who}: at the start pose (C = 0, no penetration intended) the pad already presses with "
            f"{at_surface:.3g} N > |F_d| = {magnitude:.3g} N: the workpiece's geometry reaches beyond the surface "
            "that C describes (a penetration); move the workpiece or the start so that they agree")
    deepest = pressing_force(max_depth) + magnitude
    if deepest < magnitude:
        tiny = 1e-9 * max(magnitude, 1.0)
        against = deepest if deepest < -tiny else min(pressing_force(-max_depth) + magnitude, 0.0)
        if against < -tiny:
            raise ForceSignError(
                f"{who}: the desired force F_d(0) = {np.asarray(desired).tolist()} pulls: in contact the workpiece "
                f"pushes the pad with {against:.3g} N along F_d. F_d is the force ON the robot in E_f's coordinates "
                "(the rows of dC/dr), and a contact only pushes: flip the sign of desired_force")
        if abs(deepest) <= tiny:
            raise OffConstraintError(
                f"{who}: the pad touches nothing even {max_depth * 1000:.0f} mm beyond the start pose "
                "along the pressing direction: the workpiece's geometry is farther than the surface C = 0 (a gap); "
                "move the workpiece or the start so that they agree")
        raise ConfigError(
            f"{who}: even {max_depth * 1000:.0f} mm of penetration presses with only {deepest:.3g} N, "
            f"less than the desired {magnitude:.3g} N; raise contact.pad_modulus or lower the desired force")
    return brentq(pressing_force, 0.0, max_depth, xtol=1e-10)
