"""Typed scenario configs and the builder that wires a whole closed loop.

A ``ScenarioConfig`` (a dataclass that loads from and dumps to YAML with
Drake's ``yaml_load_typed``) describes a run: task, mode, gains, contact,
sensor, desired profiles, start. ``build_scenario(config)`` returns a
``Scenario`` whose ``diagram`` is::

    ProfileSource / DesiredFieldSource ──desired_*──────────────┐
    plant ──state──────────────────────────────────────────────►├─► HybridController ──actuation──► plant
    plant ──contact_results / reaction_forces─► sensor ─► filter ┘
    loggers ◄── every named output

with named handles to every part. The same config builds the same diagram in
a test, a notebook, the CLI or a worker process.
"""

import dataclasses
from dataclasses import dataclass, field
from typing import Dict, List, Optional

import numpy as np
from scipy.optimize import brentq

from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed
from pydrake.geometry import CollisionFilterDeclaration, GeometrySet, ProximityProperties, Role, RoleAssign
from pydrake.multibody.plant import AddMultibodyPlant, CoulombFriction, MultibodyPlant, MultibodyPlantConfig
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from drake_hybrid.controller import HybridController
from drake_hybrid.gains import ControlMode, HybridGains
from drake_hybrid.kinematics import EndEffectorKinematics
from drake_hybrid.sensors import ContactWrenchSensor, LowPassFilter, WristForceTorqueSensor
from drake_hybrid.sources import Profile, ProfileSource


@dataclass
class ContactConfig:
    """Compliant hydroelastic contact between the tool's pad and the workpiece."""

    model: str = "hydroelastic"                  # or "hydroelastic_with_fallback"
    pad_modulus: float = 5.0e6                   # Pa, the pad's hydroelastic modulus
    pad_dissipation: float = 10.0                # s/m, Hunt-Crossley dissipation (continuous plants)
    relaxation_time: float = -1.0                # s, SAP's linear dissipation (discrete plants); < 0: Drake's default
    sap_near_rigid_threshold: float = 1.0        # SAP's beta: smaller = stiffer near-rigid constraints (Drake: 1.0)
    friction: float = 0.0                        # Coulomb mu (static = dynamic) of pad and workpiece
    pad_resolution: float = 0.003                # m, mesh resolution hint of the pad (see docs: tessellation torque)
    # Discrete plants: "sap" models dissipation with its own linear law and ignores pad_dissipation;
    # "similar" or "lagged" use Hunt-Crossley (pad_dissipation), like the continuous plant that
    # analysis.linearize_continuous linearizes (docs/drake_notes.md).
    discrete_approximation: str = "sap"


@dataclass
class SensorConfig:
    kind: str = "contact"                        # "contact" (ideal) or "wrist" (F/T sensor at the tool weld)
    bandwidth_hz: float = 0.0                    # first-order low-pass; 0 = none (a continuous plant needs one)


@dataclass
class StartConfig:
    """Start of the run: where on the constraint, and the controller's initial integrals."""

    configuration: List[float] = field(default_factory=list)   # task-specific start (see the task's docs)
    in_contact: bool = True                      # start pressing with the desired force
    tolerance: float = 5.0e-3                    # max |C(r)| allowed at the start (units of C's rows)
    force_integral: List[float] = field(default_factory=list)  # xi(0); empty = zeros
    position_error: List[float] = field(default_factory=list)  # e_p(0); empty = zeros


@dataclass
class ModelErrorConfig:
    """How the simulated robot differs from the controller's model (defaults: no error).

    The scales multiply masses and rotational inertias (same shape, same centre
    of mass) of the SIMULATION plant only; the controller keeps the nominal
    model. Drake stores masses as context parameters, so ``apply_model_error``
    sets them in a plant context; ``set_initial_conditions`` does it for every
    run and linearization.
    """

    payload_mass_scale: float = 1.0              # the tool: bodies of the robot's non-arm model instances
    link_inertia_scale: float = 1.0              # the arm's links


@dataclass
class ScenarioConfig:
    """Everything that defines a run. Loads from YAML (``load_config``)."""

    task: str = "window-washing"
    mode: str = "velocity-force"
    duration: float = 3.0
    time_step: float = 1.0e-3                    # plant: 0 = continuous, else discrete SAP
    control_period: float = 1.0e-3               # controller: 0 = continuous
    log_period: float = 1.0e-3
    gains: HybridGains = field(default_factory=HybridGains)
    contact: ContactConfig = field(default_factory=ContactConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    desired_velocity: Profile = field(default_factory=Profile)
    desired_force: Profile = field(default_factory=Profile)
    start: StartConfig = field(default_factory=StartConfig)
    task_parameters: Dict[str, float] = field(default_factory=dict)
    task_options: Dict[str, str] = field(default_factory=dict)
    model_error: ModelErrorConfig = field(default_factory=ModelErrorConfig)

    def replace(self, **changes):
        """A copy with some top-level fields changed."""
        return dataclasses.replace(self, **changes)


def load_config(path=None, data=None, defaults=None):
    """A ScenarioConfig from a YAML file or string, on top of ``defaults``."""
    return yaml_load_typed(schema=ScenarioConfig, filename=path, data=data,
                           defaults=defaults if defaults is not None else ScenarioConfig())


def dump_config(config):
    return yaml_dump_typed(config)


@dataclass
class RobotModel:
    """What a task's ``add_robot`` added to a plant."""

    arm: object                                  # ModelInstanceIndex of the actuated arm
    model_instances: list                        # arm and tool instances
    end_effector_frame: str                      # name of frame E
    end_effector_point: np.ndarray               # p_EP
    tool_weld: object = None                     # WeldJoint wrist -> tool (for the wrist sensor)
    pad_geometries: list = field(default_factory=list)
    passive_geometries: list = field(default_factory=list)   # collision geometries to drop (arm links)
    only_pad_contact: bool = False               # filter every contact of the robot but the pad's


@dataclass
class Scenario:
    """A built closed loop and named handles to its parts."""

    config: ScenarioConfig
    task: object
    diagram: object
    plant: object
    scene_graph: object
    robot: RobotModel
    controller_plant: object
    controller: object
    sensor: object
    wrench_filter: Optional[object]
    source: object
    constraint_space: object
    kinematics: EndEffectorKinematics            # on the simulation plant
    loggers: Dict[str, object] = field(default_factory=dict)
    meshcat: Optional[object] = None

    def plant_context(self, root_context):
        return self.plant.GetMyMutableContextFromRoot(root_context)


def _set_contact_properties(plant, scene_graph, geometry_ids, config, pad):
    inspector = scene_graph.model_inspector()
    for geometry_id in geometry_ids:
        properties = ProximityProperties(inspector.GetProximityProperties(geometry_id))
        if pad:
            properties.UpdateProperty("hydroelastic", "hydroelastic_modulus", float(config.pad_modulus))
            properties.UpdateProperty("hydroelastic", "resolution_hint", float(config.pad_resolution))
            properties.UpdateProperty("material", "hunt_crossley_dissipation", float(config.pad_dissipation))
            if config.relaxation_time >= 0:
                properties.UpdateProperty("material", "relaxation_time", float(config.relaxation_time))
        properties.UpdateProperty("material", "coulomb_friction",
                                  CoulombFriction(float(config.friction), float(config.friction)))
        scene_graph.AssignRole(plant.get_source_id(), geometry_id, properties, RoleAssign.kReplace)


def build_plant(task, config, builder, time_step=None, sampled_outputs=True):
    """Add the task's plant (robot, tool, workpiece, contact properties) to ``builder``.

    ``sampled_outputs=False`` makes a discrete plant's contact results and reaction forces those
    of the step being taken (used by the discrete-time linearization)."""
    time_step = config.time_step if time_step is None else time_step
    plant, scene_graph = AddMultibodyPlant(
        MultibodyPlantConfig(time_step=time_step, contact_model=config.contact.model,
                             discrete_contact_approximation=config.contact.discrete_approximation,
                             use_sampled_output_ports=sampled_outputs,
                             sap_near_rigid_threshold=config.contact.sap_near_rigid_threshold),
        builder)
    robot = task.add_robot(plant, config)
    workpiece_geometries = task.add_workpiece(plant, config)
    for geometry_id in robot.passive_geometries:
        scene_graph.RemoveRole(plant.get_source_id(), geometry_id, Role.kProximity)
    _set_contact_properties(plant, scene_graph, robot.pad_geometries, config.contact, pad=True)
    _set_contact_properties(plant, scene_graph, workpiece_geometries, config.contact, pad=False)
    plant.Finalize()
    if robot.only_pad_contact:
        # Arm models made for motion planning (spheres and cylinders around the links) overlap
        # between non-adjacent links, and AutoDiffXd point-contact queries (Linearize) reject most
        # shape pairs even out of contact: let only the pad touch the workpiece.
        arm_geometries = [geometry for instance in robot.model_instances for index in plant.GetBodyIndices(instance)
                          for geometry in plant.GetCollisionGeometriesForBody(plant.get_body(index))
                          if geometry not in robot.pad_geometries]
        scene_graph.collision_filter_manager().Apply(
            CollisionFilterDeclaration()
            .ExcludeWithin(GeometrySet(arm_geometries + list(robot.pad_geometries)))
            .ExcludeBetween(GeometrySet(arm_geometries), GeometrySet(workpiece_geometries)))
    return plant, scene_graph, robot


def build_controller_plant(task, config):
    """The controller's own model: the robot and tool only, no workpiece."""
    plant = MultibodyPlant(0.0)
    robot = task.add_robot(plant, config)
    plant.Finalize()
    return plant, robot


def build_scenario(config, meshcat=None, with_loggers=True, sampled_plant_outputs=True, controller_sample_lead=True):
    """Build the closed-loop diagram of ``config``. See the module docstring.

    The last two arguments exist for ``analysis.linearize_discrete`` (see there)."""
    from drake_hybrid.tasks import get_task

    task = get_task(config.task)
    mode = ControlMode.parse(config.mode)
    if config.time_step < 0 or config.control_period < 0:
        raise ValueError("time_step and control_period must be >= 0 (0 means continuous)")
    continuous_plant = config.time_step == 0
    control_period = config.control_period if config.control_period > 0 else None
    bandwidth = config.sensor.bandwidth_hz
    if continuous_plant and control_period is None and not bandwidth > 0:
        raise ValueError(
            "a continuous plant with a continuous controller needs sensor.bandwidth_hz > 0: the contact wrench is "
            "direct feedthrough of the actuation, so plant -> sensor -> controller -> plant is an algebraic loop "
            "that the low-pass filter breaks")

    builder = DiagramBuilder()
    plant, scene_graph, robot = build_plant(task, config, builder, sampled_outputs=sampled_plant_outputs)
    controller_plant, _ = build_controller_plant(task, config)
    constraint_space = task.constraint_space(config)
    controller = builder.AddNamedSystem("controller", HybridController(
        controller_plant, robot.end_effector_frame, robot.end_effector_point, constraint_space,
        gains=config.gains, mode=mode, control_period=control_period, sample_lead=controller_sample_lead))

    robot_bodies = [plant.get_body(index) for instance in robot.model_instances
                    for index in plant.GetBodyIndices(instance)]
    if config.sensor.kind == "contact":
        sensor = builder.AddNamedSystem("wrench_sensor", ContactWrenchSensor(
            plant, robot_bodies, robot.end_effector_frame, robot.end_effector_point))
        builder.Connect(plant.get_contact_results_output_port(), sensor.get_input_port(0))
    elif config.sensor.kind == "wrist":
        if robot.tool_weld is None:
            raise ValueError(f"task '{task.name}' has no wrist weld; use sensor.kind = 'contact'")
        sensor = builder.AddNamedSystem("wrench_sensor", WristForceTorqueSensor(
            plant, robot.tool_weld, robot.end_effector_frame, robot.end_effector_point))
        builder.Connect(plant.get_reaction_forces_output_port(), sensor.get_input_port(0))
    else:
        raise ValueError(f"unknown sensor kind '{config.sensor.kind}' (use 'contact' or 'wrist')")
    builder.Connect(plant.get_body_poses_output_port(), sensor.get_input_port(1))
    wrench_output = sensor.get_output_port(0)
    wrench_filter = None
    if bandwidth > 0:
        wrench_filter = builder.AddNamedSystem("wrench_filter", LowPassFilter(6, bandwidth, control_period))
        builder.Connect(wrench_output, wrench_filter.get_input_port(0))
        wrench_output = wrench_filter.get_output_port(0)
    builder.Connect(wrench_output, controller.get_measured_wrench_input_port())
    builder.Connect(plant.get_state_output_port(robot.arm), controller.get_estimated_state_input_port())
    builder.Connect(controller.GetOutputPort("actuation"), plant.get_actuation_input_port(robot.arm))

    source = builder.AddNamedSystem("desired", task.make_source(config, controller_plant, robot, constraint_space))
    if source.num_input_ports():
        builder.Connect(plant.get_state_output_port(robot.arm), source.get_input_port(0))
    for name in ("desired_velocity", "desired_acceleration", "desired_force"):
        builder.Connect(source.GetOutputPort(name), controller.GetInputPort(name))

    loggers = {}
    if with_loggers:
        period = config.log_period
        for name in ("velocity_error", "force_error", "constraint_value", "projected_velocity", "force",
                     "tangential_force", "position_error", "actuation"):
            loggers[name] = LogVectorOutput(controller.GetOutputPort(name), builder, period)
        for name in ("desired_velocity", "desired_force"):
            loggers[name] = LogVectorOutput(source.GetOutputPort(name), builder, period)
        loggers["state"] = LogVectorOutput(plant.get_state_output_port(robot.arm), builder, period)
        loggers["wrench"] = LogVectorOutput(wrench_output, builder, period)
    if meshcat is not None:
        from pydrake.geometry import MeshcatVisualizer

        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
    diagram = builder.Build()
    diagram.set_name(f"hybrid_{task.name}")
    kinematics = EndEffectorKinematics(plant, robot.end_effector_frame, robot.end_effector_point,
                                       constraint_space.chart)
    return Scenario(config=config, task=task, diagram=diagram, plant=plant, scene_graph=scene_graph, robot=robot,
                    controller_plant=controller_plant, controller=controller, sensor=sensor,
                    wrench_filter=wrench_filter, source=source, constraint_space=constraint_space,
                    kinematics=kinematics, loggers=loggers, meshcat=meshcat)


# ------------------------------------------------------------------------------------------------
# Initial conditions
# ------------------------------------------------------------------------------------------------

# Plant steps taken (and undone) at the start so that a discrete plant's sampled outputs hold the
# start's static contact or constraint wrench (see set_initial_conditions).
PRIMING_STEPS = 20


def set_initial_conditions(scenario, root_context):
    """Put the robot at the task's start, pressing with the desired force if ``start.in_contact``;
    set the controller's integrals and the filter's output to the first sensor reading. The
    simulated plant's masses get ``config.model_error`` (the controller's model stays nominal)."""
    config, task, plant = scenario.config, scenario.task, scenario.plant
    plant_context = scenario.plant_context(root_context)
    apply_model_error(plant, plant_context, scenario.robot, config.model_error)
    q0 = task.start_positions(scenario)
    check_start(scenario, q0)
    plant.SetPositions(plant_context, scenario.robot.arm, q0)
    plant.SetVelocities(plant_context, scenario.robot.arm, np.zeros(len(q0)))
    if hasattr(task, "set_environment_state"):
        task.set_environment_state(scenario, plant_context)
    environment = plant.GetPositionsAndVelocities(plant_context)
    controller = scenario.controller
    controller_context = controller.GetMyMutableContextFromRoot(root_context)
    xi_slice, e_p_slice = controller.integral_state_slices()
    integrals = np.zeros(xi_slice.stop + (e_p_slice.stop - e_p_slice.start))
    if config.start.force_integral:
        integrals[xi_slice] = config.start.force_integral
    if config.start.position_error and e_p_slice.stop > e_p_slice.start:
        integrals[e_p_slice] = config.start.position_error
    if controller.control_period is None:
        controller_context.SetContinuousState(integrals)
    else:
        held = static_torque(scenario, q0)
        controller_context.SetDiscreteState(0, np.concatenate([integrals, held]))
    if plant.time_step() > 0 and plant.has_sampled_output_ports():
        # A discrete plant's contact results and reaction forces are sampled at its steps; before the
        # first step they are empty. Take steps from the initial state (with the held static torque)
        # and put the state back, so the sensors read the start's contact wrench at t = 0.
        # Several steps let compliant constraints (e.g. a SAP weld) build up the static force.
        for _ in range(PRIMING_STEPS):
            plant.ExecuteForcedEvents(plant_context, publish=False)
        plant.SetPositionsAndVelocities(plant_context, environment)
    if scenario.wrench_filter is not None:
        filter_context = scenario.wrench_filter.GetMyMutableContextFromRoot(root_context)
        reading = scenario.sensor.get_output_port(0).Eval(scenario.sensor.GetMyContextFromRoot(root_context))
        scenario.wrench_filter.set_initial_output(filter_context, reading)


def apply_model_error(plant, plant_context, robot, model_error):
    """Scale the simulated payload's and links' inertias in ``plant_context`` (see ModelErrorConfig)."""
    from pydrake.multibody.tree import SpatialInertia

    for name in ("payload_mass_scale", "link_inertia_scale"):
        scale = getattr(model_error, name)
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"model_error.{name} must be a positive number, got {scale}")
    for instance in robot.model_instances:
        scale = model_error.link_inertia_scale if instance == robot.arm else model_error.payload_mass_scale
        if scale == 1.0:
            continue
        for index in plant.GetBodyIndices(instance):
            body = plant.get_body(index)
            M_BBo_B = body.default_spatial_inertia()         # nominal (the model's), so applying twice is safe
            body.SetSpatialInertiaInBodyFrame(plant_context, SpatialInertia(
                scale * M_BBo_B.get_mass(), M_BBo_B.get_com(), M_BBo_B.get_unit_inertia()))


def check_start(scenario, q):
    """Raise a typed error if the arm at ``q`` is not a valid start of the hybrid law: off the
    constraint (OffConstraintError), on the wrong branch (BranchError), at a chart singularity
    (ChartSingularityError) or where E loses rank (ConstraintRankError)."""
    plant = scenario.controller_plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    task = scenario.controller.kinematics.evaluate(context)
    x = task.configuration
    scenario.constraint_space.evaluate(x, task.velocity)
    constraint = scenario.constraint_space.constraint
    constraint.check_satisfied(x, scenario.config.start.tolerance)
    constraint.check_branch(x)


def static_torque(scenario, q):
    """tau = g(q) - J^T E_f^T F_d: the actuation that holds the robot at rest pressing with F_d."""
    controller = scenario.controller
    plant = scenario.controller_plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    kinematics = controller.kinematics
    task = kinematics.evaluate(context)
    values = scenario.constraint_space.evaluate(task.configuration, task.velocity)
    desired_force = np.asarray(scenario.config.desired_force.evaluate(0.0)[0])
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

    if pressing_force(max_depth) < 0:
        raise ValueError(
            f"task '{task.name}': even {max_depth * 1000:.0f} mm of penetration presses with less than the desired "
            f"{magnitude:.3g} N; raise contact.pad_modulus or lower the desired force")
    depth = brentq(pressing_force, 0.0, max_depth, xtol=1e-10)
    return positions_at_depth(depth)
