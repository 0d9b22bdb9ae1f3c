"""The start of a run: where the robot is, what the controller's states hold, and the checks that
the hybrid law can start there.

``set_initial_conditions`` puts a built scenario at its task's start (pressing with F_d, or a gap
away for the guarded approach), primes a discrete plant's sampled outputs, and sets the
integrals, the held torque and the wrench filters; ``static_torque`` is the torque that holds the
arm there, ``pressing_positions`` the joint positions that press with F_d (root finding on a
static probe), ``check_start`` the typed errors for a start the law cannot use. ``prime_start``
and ``holding_torque`` work on any diagram's systems (``station.loop.HybridSystems``); a start
in your own diagram is ``station.contact_start.solve_contact_start``.
"""

from typing import cast

import numpy as np
from numpy.typing import ArrayLike

from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Context, Diagram

from drake_hybrid.control.controller import HybridController
from drake_hybrid.core.arguments import joint_vector
from drake_hybrid.core.errors import DimensionError, OffConstraintError
from drake_hybrid.core.hints import Array
from drake_hybrid.core.linalg import value
from drake_hybrid.station.clearance import check_robot_clearance
from drake_hybrid.station.root_context import check_systems
from drake_hybrid.station.start import holding_torque, prime_start
from drake_hybrid.tasks.config import ScenarioConfig
from drake_hybrid.tasks.plant import apply_model_error
from drake_hybrid.tasks.pressing import held_force_integral, moment_rows
from drake_hybrid.tasks.task import Scenario


def check_start_sizes(config: ScenarioConfig, controller: HybridController) -> None:
    """DimensionError if the start's integrals do not have the controller's sizes."""
    xi_slice, e_p_slice = controller.integral_state_slices()
    m, k = xi_slice.stop, e_p_slice.stop - e_p_slice.start
    if config.start.force_integral and len(config.start.force_integral) != m:
        raise DimensionError(f"start.force_integral must have m = {m} entries, got {len(config.start.force_integral)}")
    if config.start.position_error and k and len(config.start.position_error) != k:
        raise DimensionError(f"start.position_error must have k = {k} entries, got {len(config.start.position_error)}")


def set_initial_conditions(scenario: Scenario, root_context: Context) -> None:
    """Put the robot at the task's start, pressing with the desired force if ``start.in_contact``
    (else ``start.gap`` away, for the supervisor's approach); apply the model error to the
    simulated plant; then ``prime_start``: the controller's integrals (``start.force_integral``,
    ``start.position_error``) and held torque, the sensors' first reading."""
    config, task = scenario.config, scenario.task
    plant = cast(MultibodyPlant, scenario.plant)          # a built scenario's: build_scenario sets it
    plant_context = scenario.plant_context(root_context)
    apply_model_error(plant, plant_context, scenario.robot, config.model_error)
    q0 = task.start_positions(scenario)
    check_start(scenario, q0)
    check_robot_clearance(cast(Diagram, scenario.diagram), root_context, scenario, q0, f"task '{task.name}'")
    plant.SetPositions(plant_context, scenario.robot.arm, q0)
    at_rest: Array = np.zeros(len(q0))
    plant.SetVelocities(plant_context, scenario.robot.arm, at_rest)
    task.set_environment_state(scenario, plant_context)
    xi_slice, e_p_slice = scenario.controller.integral_state_slices()
    integrals = np.zeros(xi_slice.stop + (e_p_slice.stop - e_p_slice.start))
    if config.start.force_integral:
        integrals[xi_slice] = config.start.force_integral
    if config.start.position_error and e_p_slice.stop > e_p_slice.start:
        integrals[e_p_slice] = config.start.position_error
    desired = np.asarray(config.desired_force.evaluate(0.0)[0], dtype=float)
    if config.start.in_contact:
        # What the arm holds and the force integral that holds it (a normal row read along a turned tool's axis).
        held, xi = held_force_integral(scenario, q0, desired)
        integrals[xi_slice] = integrals[xi_slice] + xi
    else:
        held = 0 * desired
    prime_start(scenario, root_context, holding_torque(scenario, q0, held), integrals)


def check_start(scenario: Scenario, q: ArrayLike) -> None:
    """Raise a typed error if the arm at ``q`` is not a valid start of the hybrid law: off the
    constraint (OffConstraintError), on the wrong branch (BranchError), at a chart singularity
    (ChartSingularityError) or where E loses rank (ConstraintRankError); ArgumentError for a ``q`` that
    is not a vector of the controller plant's number of finite positions."""
    plant = check_systems(scenario, "check_start").controller_plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, joint_vector(q, "q", "check_start", plant))
    task = scenario.controller.kinematics.evaluate(context)
    x = task.configuration
    scenario.constraint_space.evaluate(x, task.velocity)
    constraint = scenario.constraint_space.constraint
    if scenario.config.start.in_contact:
        # A flat tool's force-controlled orientation rows read its tilt against the model's normal, which its
        # balanced start turns as the contact's pressure wants (tasks.pressing): not a residual to bound.
        free = moment_rows(scenario.constraint_space)
        residual = np.delete(np.atleast_1d(np.asarray(value(constraint.value(x)), dtype=float)), free)
        try:
            if free and residual.size and float(np.max(np.abs(residual))) > scenario.config.start.tolerance:
                raise OffConstraintError(f"the start is not on constraint '{constraint.name}': C without its moment "
                                         f"rows {free} = {np.round(residual, 6).tolist()} exceeds tolerance "
                                         f"{scenario.config.start.tolerance:g}")
            if not free:
                constraint.check_satisfied(x, scenario.config.start.tolerance)
        except OffConstraintError as error:
            raise OffConstraintError(f"{error}; to start off the surface and approach it, set start.in_contact: "
                                     "false (the contact supervisor's guarded move)") from None
    constraint.check_branch(x)


def static_torque(scenario: Scenario, q: ArrayLike, pressing: bool = True) -> Array:
    """tau = g(q) - J^T E_f^T F_d(0): the actuation that holds the robot at rest pressing with the
    config's F_d (``pressing=False``: g(q) only, in free space). ArgumentError for a ``q`` that is
    not a vector of the controller plant's number of finite positions."""
    q = joint_vector(q, "q", "static_torque", check_systems(scenario, "static_torque").controller_plant)
    desired = np.asarray(scenario.config.desired_force.evaluate(0.0)[0], dtype=float)
    return holding_torque(scenario, q, desired * (1.0 if pressing else 0.0))
