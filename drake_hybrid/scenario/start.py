"""The start of a run: where the robot is, what the controller's states hold, and the checks that
the hybrid law can start there.

``set_initial_conditions`` puts a built scenario at its task's start (pressing with F_d, or a gap
away for the guarded approach), primes a discrete plant's sampled outputs, and sets the
integrals, the held torque and the wrench filters; ``static_torque`` is the torque that holds the
arm there, ``pressing_positions`` the joint positions that press with F_d (root finding on a
static probe), ``check_start`` the typed errors for a start the law cannot use. ``prime_start``
and ``holding_torque`` work on any diagram's systems (``scenario.station.HybridSystems``); a start
in your own diagram is ``scenario.contact_start.solve_contact_start``.
"""

import numpy as np
from scipy.optimize import brentq

from pydrake.systems.framework import DiagramBuilder

from drake_hybrid.core.arguments import joint_vector, vector
from drake_hybrid.core.errors import DimensionError, ForceSignError, OffConstraintError
from drake_hybrid.core.kinematics import EndEffectorKinematics
from drake_hybrid.scenario.clearance import check_robot_clearance
from drake_hybrid.scenario.plant import apply_model_error, build_plant
from drake_hybrid.scenario.root_context import check_systems, systems_in_context
from drake_hybrid.systems.sensors import ContactWrenchSensor


def check_start_sizes(config, controller):
    """DimensionError if the start's integrals do not have the controller's sizes."""
    xi_slice, e_p_slice = controller.integral_state_slices()
    m, k = xi_slice.stop, e_p_slice.stop - e_p_slice.start
    if config.start.force_integral and len(config.start.force_integral) != m:
        raise DimensionError(f"start.force_integral must have m = {m} entries, got {len(config.start.force_integral)}")
    if config.start.position_error and k and len(config.start.position_error) != k:
        raise DimensionError(f"start.position_error must have k = {k} entries, got {len(config.start.position_error)}")



# ------------------------------------------------------------------------------------------------
# Initial conditions
# ------------------------------------------------------------------------------------------------

# Plant steps taken (and undone) at the start so that a discrete plant's sampled outputs hold the
# start's static contact or constraint wrench (see set_initial_conditions).
PRIMING_STEPS = 20


def set_initial_conditions(scenario, root_context):
    """Put the robot at the task's start, pressing with the desired force if ``start.in_contact``
    (else ``start.gap`` away, for the supervisor's approach); apply the model error to the
    simulated plant; then ``prime_start``: the controller's integrals (``start.force_integral``,
    ``start.position_error``) and held torque, the sensors' first reading."""
    config, task, plant = scenario.config, scenario.task, scenario.plant
    plant_context = scenario.plant_context(root_context)
    apply_model_error(plant, plant_context, scenario.robot, config.model_error)
    q0 = task.start_positions(scenario)
    check_start(scenario, q0)
    check_robot_clearance(scenario.diagram, root_context, scenario, q0, f"task '{task.name}'")
    plant.SetPositions(plant_context, scenario.robot.arm, q0)
    plant.SetVelocities(plant_context, scenario.robot.arm, np.zeros(len(q0)))
    task.set_environment_state(scenario, plant_context)
    xi_slice, e_p_slice = scenario.controller.integral_state_slices()
    integrals = np.zeros(xi_slice.stop + (e_p_slice.stop - e_p_slice.start))
    if config.start.force_integral:
        integrals[xi_slice] = config.start.force_integral
    if config.start.position_error and e_p_slice.stop > e_p_slice.start:
        integrals[e_p_slice] = config.start.position_error
    desired = np.asarray(config.desired_force.evaluate(0.0)[0], dtype=float)
    prime_start(scenario, root_context, holding_torque(scenario, q0, desired if config.start.in_contact else 0 * desired),
                integrals)


def prime_start(systems, root_context, held_torque, integrals=None):
    """Set the states of the systems around the plant for a start at the plant's present state (set it
    first: the arm at rest where it presses, or a gap away): the controller's integrals (``integrals``,
    default zero: [xi; e_p]) and, for a sampled controller, its held torque ``held_torque``
    (``holding_torque``); a discrete plant's sampled contact results and reaction forces primed with
    the start's contact (steps taken and undone); the contact sensor's sampled point; the fault
    injector's, the wrench filter's or the conditioner's output at the first reading; the contact
    supervisor's entry value of C.

    ``systems``: a ``scenario.station.HybridSystems`` (``add_hybrid_controller``) or a built
    ``Scenario``; ``root_context``: the diagram's root context.

    ArgumentError (before any state is set) for ``systems`` that are not HybridSystems, a
    ``root_context`` that is not the root context of their diagram (e.g. the plant's context), a
    ``held_torque`` that is not a vector of the controller plant's number of finite actuations
    (checked for a sampled controller, the one that holds it), ``integrals`` that are not a vector of
    the controller's finite [xi; e_p] entries."""
    owner = "prime_start"
    systems_in_context(root_context, systems, owner)
    plant, controller = systems.plant, systems.controller
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
        for _ in range(PRIMING_STEPS):
            plant.ExecuteForcedEvents(plant_context, publish=False)
        plant.SetPositionsAndVelocities(plant_context, environment)
    sensor = systems.sensor
    if getattr(sensor, "samples_point", False):        # the contact sensor on those sampled results
        sensor.set_sampled_point(sensor.GetMyMutableContextFromRoot(root_context))
    reading = sensor.get_output_port(0).Eval(sensor.GetMyContextFromRoot(root_context))
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


def check_start(scenario, q):
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
        try:
            constraint.check_satisfied(x, scenario.config.start.tolerance)
        except OffConstraintError as error:
            raise OffConstraintError(f"{error}; to start off the surface and approach it, set start.in_contact: "
                                     "false (the contact supervisor's guarded move)") from None
    constraint.check_branch(x)


def static_torque(scenario, q, pressing=True):
    """tau = g(q) - J^T E_f^T F_d(0): the actuation that holds the robot at rest pressing with the
    config's F_d (``pressing=False``: g(q) only, in free space). ArgumentError for a ``q`` that is
    not a vector of the controller plant's number of finite positions."""
    q = joint_vector(q, "q", "static_torque", check_systems(scenario, "static_torque").controller_plant)
    desired = np.asarray(scenario.config.desired_force.evaluate(0.0)[0], dtype=float)
    return holding_torque(scenario, q, desired * (1.0 if pressing else 0.0))


def holding_torque(systems, q, desired_force):
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
    gravity = -plant.CalcGravityGeneralizedForces(context)
    torque = gravity - task.jacobian.T @ (values.force_projection.T @ desired_force)
    return np.linalg.solve(plant.MakeActuationMatrix(), torque)


def pressing_positions(scenario, positions_at_depth, max_depth=0.01):
    """Joint positions that press on the workpiece with the desired force F_d(0).

    ``positions_at_depth(s)`` gives the arm's q with the pad pushed s metres into
    the workpiece along the task's normal (s = 0: touching). A static probe (a
    continuous copy of the plant, the same contact properties, and the ideal
    contact sensor) measures F at q(s) in the controller's E_f coordinates, and
    s is found by root finding so that F . F_d / |F_d| = |F_d|.
    """
    config, task = scenario.config, scenario.task
    config.desired_force.check_keeps_sign("desired_force")      # pushing at t = 0 (below), and on every row after
    desired = np.asarray(config.desired_force.evaluate(0.0)[0], dtype=float)
    magnitude = float(np.linalg.norm(desired))
    if magnitude == 0:
        return positions_at_depth(0.0)
    builder = DiagramBuilder()
    plant, _, robot = build_plant(task, config, builder, time_step=0.0)
    robot_bodies = [plant.get_body(i) for instance in robot.model_instances for i in plant.GetBodyIndices(instance)]
    sensor = builder.AddSystem(ContactWrenchSensor(plant, robot_bodies, robot.end_effector_frame,
                                                   robot.end_effector_point))
    builder.Connect(plant.get_contact_results_output_port(), sensor.get_input_port(0))
    builder.Connect(plant.get_body_poses_output_port(), sensor.get_input_port(1))
    probe = builder.Build()
    context = probe.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    sensor_context = sensor.GetMyContextFromRoot(context)
    kinematics = EndEffectorKinematics(plant, robot.end_effector_frame, robot.end_effector_point,
                                       scenario.constraint_space.chart)
    space = scenario.constraint_space

    def pressing_force(depth):
        plant.SetPositions(plant_context, robot.arm, positions_at_depth(depth))
        task_kinematics = kinematics.evaluate(plant_context)
        values = space.evaluate(task_kinematics.configuration, task_kinematics.velocity)
        wrench = space.chart.generalized_force(task_kinematics.configuration, sensor.get_output_port(0).Eval(sensor_context))
        force = space.split_wrench(values, wrench)[1]
        return float(force @ desired) / magnitude - magnitude

    return positions_at_depth(pressing_depth(pressing_force, desired, max_depth, f"task '{task.name}'"))


def pressing_depth(pressing_force, desired, max_depth, who):
    """The depth s in [0, max_depth] (m) at which ``pressing_force(s)`` (F . F_d / |F_d| - |F_d|, the
    pressing force's excess over the desired one) is zero, by Brent's method; the starts root
    finding cannot fix are named with typed errors (``who`` begins each message): the surface's
    geometry beyond C = 0 (OffConstraintError), a pulling F_d (ForceSignError), nothing touched
    (OffConstraintError), too soft a contact (ValueError)."""
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
        raise ValueError(
            f"{who}: even {max_depth * 1000:.0f} mm of penetration presses with only {deepest:.3g} N, "
            f"less than the desired {magnitude:.3g} N; raise contact.pad_modulus or lower the desired force")
    return brentq(pressing_force, 0.0, max_depth, xtol=1e-10)
