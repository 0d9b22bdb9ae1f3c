"""Typed scenario configs and the builder that wires a whole closed loop.

A ``ScenarioConfig`` (a dataclass that loads from and dumps to YAML with
Drake's ``yaml_load_typed``) describes a run: task, mode, gains, contact,
sensor, desired profiles, start, and the faults and protections (model error,
sensor faults, contact supervision, safety). ``build_scenario(config)`` returns a
``Scenario`` whose ``diagram`` is::

    ProfileSource / DesiredFieldSource ──desired_*──────────────┐
    plant ──state──────────────────────────────────────────────►├─► HybridController ──actuation──► plant
    plant ──contact_results / reaction_forces─► sensor ─► filter ┘
    loggers ◄── every named output

and, when the config asks for them (parts in brackets are optional)::

    sensor ─► [SensorFaultInjector] ─faulty_wrench, sequence─► [WrenchConditioner] ─► controller
    controller ─force, constraint_value─► [ContactSupervisor] ─contact_phase─► controller, conditioner
    plant ─state─► [JointFriction] ─generalized_force─► plant (model error, simulation only)

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
from drake_hybrid.errors import DimensionError, OffConstraintError, check_fields
from drake_hybrid.faults import JointFriction, SensorFaultConfig, SensorFaultInjector
from drake_hybrid.gains import ControlMode, HybridGains
from drake_hybrid.kinematics import EndEffectorKinematics
from drake_hybrid.safety import ContactPhase, SafetyConfig
from drake_hybrid.sensors import ContactWrenchSensor, LowPassFilter, WrenchConditioner, WristForceTorqueSensor
from drake_hybrid.sources import Profile, ProfileSource
from drake_hybrid.supervision import ContactSupervisor, SupervisionConfig


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
    condition: bool = False                      # a WrenchConditioner (dropout rejection, tare, the low-pass)
    max_hold_time: float = 0.01                  # s, how long the conditioner bridges a dropout by holding


@dataclass
class StartConfig:
    """Start of the run: where on the constraint, and the controller's initial integrals."""

    configuration: List[float] = field(default_factory=list)   # task-specific start (see the task's docs)
    in_contact: bool = True                      # start pressing with the desired force; else approach (supervision)
    gap: float = 0.01                            # m from the surface along the pressing direction when not in contact
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

    payload_mass_scale: the tool (the bodies of the robot's non-arm model instances): mass and
        rotational inertia together.
    link_mass_scale: the arm's links, mass and rotational inertia together (a uniformly denser
        link: gravity changes too).
    link_inertia_scale: the rotational inertia about the centre of mass of every arm link only
        (masses and centres of mass kept: gravity stays exact).
    joint_damping: viscous friction (N m s/rad) added to every arm joint (set when the plant is built).
    joint_friction: Coulomb friction tau_c (N m) in every arm joint (``faults.JointFriction``),
        regularized over ``friction_speed`` (rad/s).
    """

    payload_mass_scale: float = 1.0
    link_mass_scale: float = 1.0
    link_inertia_scale: float = 1.0
    joint_damping: float = 0.0
    joint_friction: float = 0.0
    friction_speed: float = 0.05

    def validate(self):
        return check_fields(self, "model_error.", positive=("payload_mass_scale", "link_mass_scale",
                                                            "link_inertia_scale", "friction_speed"),
                            nonnegative=("joint_damping", "joint_friction"))


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
    sensor_faults: SensorFaultConfig = field(default_factory=SensorFaultConfig)
    supervision: SupervisionConfig = field(default_factory=SupervisionConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)

    def replace(self, **changes):
        """A copy with some top-level fields changed."""
        return dataclasses.replace(self, **changes)

    @property
    def supervised(self):
        """True if the run has a contact supervisor: asked for, or needed by a start off the surface."""
        return bool(self.supervision.enabled or not self.start.in_contact)


def load_config(path=None, data=None, defaults=None):
    """A ScenarioConfig from a YAML file or string, on top of ``defaults``."""
    return yaml_load_typed(schema=ScenarioConfig, filename=path, data=data,
                           defaults=defaults if defaults is not None else ScenarioConfig())


def dump_config(config):
    return yaml_dump_typed(config)


CONTACT_MODELS = ("hydroelastic", "hydroelastic_with_fallback", "point")
DISCRETE_APPROXIMATIONS = ("sap", "tamsi", "similar", "lagged")


def validate_config(config):
    """Check the fields of ``config`` that no constructor checks; ValueError (or DimensionError)
    naming the field. The gains, profiles and safety limits are checked by the systems that use
    them, the start by ``check_start``."""
    if not isinstance(config, ScenarioConfig):
        raise TypeError(f"expected a ScenarioConfig, got {type(config).__name__}")
    if config.time_step < 0 or config.control_period < 0:
        raise ValueError("time_step and control_period must be >= 0 (0 means continuous)")
    check_fields(config, "", positive=("duration", "log_period"))
    contact = config.contact
    if contact.model not in CONTACT_MODELS:
        raise ValueError(f"contact.model must be one of {CONTACT_MODELS}, got '{contact.model}'")
    if contact.discrete_approximation not in DISCRETE_APPROXIMATIONS:
        raise ValueError(f"contact.discrete_approximation must be one of {DISCRETE_APPROXIMATIONS}, "
                         f"got '{contact.discrete_approximation}'")
    check_fields(contact, "contact.", positive=("pad_modulus", "pad_resolution", "sap_near_rigid_threshold"),
                 nonnegative=("pad_dissipation", "friction"))
    check_fields(config.sensor, "sensor.", nonnegative=("bandwidth_hz", "max_hold_time"))
    check_fields(config.start, "start.", positive=("tolerance", "gap"))
    config.model_error.validate()
    config.sensor_faults.validate()
    config.supervision.validate()
    sampled_parts = [name for name, used in (("supervision (or a start off the surface)", config.supervised),
                                             ("sensor_faults", config.sensor_faults.active()),
                                             ("sensor.condition", config.sensor.condition)) if used]
    if sampled_parts and not config.control_period > 0:
        raise ValueError(f"{', '.join(sampled_parts)} need a sampled controller: set control_period > 0")
    if config.supervision.tare_time > 0 and not config.start.in_contact and not config.sensor.condition:
        raise ValueError("supervision.tare_time > 0 tares the sensor in the wrench conditioner: set sensor.condition")


def _check_start_sizes(config, controller):
    xi_slice, e_p_slice = controller.integral_state_slices()
    m, k = xi_slice.stop, e_p_slice.stop - e_p_slice.start
    if config.start.force_integral and len(config.start.force_integral) != m:
        raise DimensionError(f"start.force_integral must have m = {m} entries, got {len(config.start.force_integral)}")
    if config.start.position_error and k and len(config.start.position_error) != k:
        raise DimensionError(f"start.position_error must have k = {k} entries, got {len(config.start.position_error)}")


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
    loggers: Dict[str, object] = field(default_factory=dict)   # name -> VectorLogSink or (sink, columns)
    meshcat: Optional[object] = None
    fault_injector: Optional[object] = None      # SensorFaultInjector
    conditioner: Optional[object] = None         # WrenchConditioner
    supervisor: Optional[object] = None          # ContactSupervisor

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
    if config.model_error.joint_damping > 0:
        for index in plant.GetJointIndices(robot.arm):
            joint = plant.get_joint(index)
            if joint.num_velocities() == 1:          # viscous friction of the simulated joints only
                joint.set_default_damping(joint.default_damping() + float(config.model_error.joint_damping))
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
    validate_config(config)
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
    supervised = config.supervised
    controller = builder.AddNamedSystem("controller", HybridController(
        controller_plant, robot.end_effector_frame, robot.end_effector_point, constraint_space,
        gains=config.gains, mode=mode, control_period=control_period, sample_lead=controller_sample_lead,
        safety=config.safety, guarded_move=config.supervision if supervised else None,
        sampled_diagnostics=with_loggers and control_period is not None))
    _check_start_sizes(config, controller)

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
    true_wrench = wrench_output
    injector = conditioner = wrench_filter = supervisor = None
    if config.sensor_faults.active():
        injector = builder.AddNamedSystem("sensor_faults", SensorFaultInjector(config.sensor_faults, control_period))
        builder.Connect(wrench_output, injector.GetInputPort("wrench"))
        wrench_output = injector.GetOutputPort("faulty_wrench")
    tare = supervised and config.supervision.tare_time > 0 and not config.start.in_contact
    if config.sensor.condition:
        conditioner = builder.AddNamedSystem("wrench_conditioner", WrenchConditioner(
            control_period, bandwidth, config.sensor.max_hold_time, use_sequence=injector is not None, tare=tare))
        builder.Connect(wrench_output, conditioner.GetInputPort("raw_wrench"))
        if injector is not None:
            builder.Connect(injector.GetOutputPort("sequence"), conditioner.GetInputPort("sequence"))
        wrench_output = conditioner.GetOutputPort("wrench")
    elif bandwidth > 0:
        wrench_filter = builder.AddNamedSystem("wrench_filter", LowPassFilter(6, bandwidth, control_period))
        builder.Connect(wrench_output, wrench_filter.get_input_port(0))
        wrench_output = wrench_filter.get_output_port(0)
    builder.Connect(wrench_output, controller.get_measured_wrench_input_port())
    if config.model_error.joint_friction > 0:
        friction = builder.AddNamedSystem("joint_friction", JointFriction(
            plant, robot.arm, config.model_error.joint_friction, config.model_error.friction_speed))
        builder.Connect(plant.get_state_output_port(robot.arm), friction.get_input_port(0))
        builder.Connect(friction.get_output_port(0), plant.get_applied_generalized_force_input_port())
    if hasattr(task, "connect_environment"):
        task.connect_environment(builder, plant, config)
    builder.Connect(plant.get_state_output_port(robot.arm), controller.get_estimated_state_input_port())
    builder.Connect(controller.GetOutputPort("actuation"), plant.get_actuation_input_port(robot.arm))

    source = builder.AddNamedSystem("desired", task.make_source(config, controller_plant, robot, constraint_space))
    if source.num_input_ports():
        builder.Connect(plant.get_state_output_port(robot.arm), source.get_input_port(0))
    for name in ("desired_velocity", "desired_acceleration", "desired_force"):
        builder.Connect(source.GetOutputPort(name), controller.GetInputPort(name))
    if supervised:
        if config.start.in_contact:
            initial_phase = ContactPhase.CONTACT
        else:
            initial_phase = ContactPhase.TARE if tare else ContactPhase.APPROACH
        supervisor = builder.AddNamedSystem("contact_supervisor", ContactSupervisor(
            config.supervision, constraint_space.force_size, controller.kinematic_rows, control_period,
            initial_phase))
        for name in ("force", "constraint_value"):
            builder.Connect(controller.GetOutputPort(name), supervisor.GetInputPort(name))
        builder.Connect(source.GetOutputPort("desired_force"), supervisor.GetInputPort("desired_force"))
        builder.Connect(wrench_output, supervisor.GetInputPort("measured_wrench"))
        builder.Connect(supervisor.GetOutputPort("contact_phase"), controller.get_contact_phase_input_port())
        if tare:
            builder.Connect(supervisor.GetOutputPort("contact_phase"), conditioner.GetInputPort("contact_phase"))

    loggers = {}
    if with_loggers:
        period = config.log_period
        if controller.sampled_diagnostics:
            # What each tick computed (one logger; no re-evaluation of the law after the tick).
            diagnostics = LogVectorOutput(controller.GetOutputPort("diagnostics"), builder, period)
            for name, columns in controller.diagnostic_slices().items():
                loggers[name] = (diagnostics, columns)
        else:
            for name in controller.diagnostic_slices():
                loggers[name] = LogVectorOutput(controller.GetOutputPort(name), builder, period)
        for name in ("position_error", "actuation"):
            loggers[name] = LogVectorOutput(controller.GetOutputPort(name), builder, period)
        for name in ("desired_velocity", "desired_force"):
            loggers[name] = LogVectorOutput(source.GetOutputPort(name), builder, period)
        loggers["state"] = LogVectorOutput(plant.get_state_output_port(robot.arm), builder, period)
        loggers["wrench"] = LogVectorOutput(wrench_output, builder, period)
        if true_wrench is not wrench_output:
            loggers["true_wrench"] = LogVectorOutput(true_wrench, builder, period)
        if supervisor is not None:
            loggers["contact_phase"] = LogVectorOutput(supervisor.GetOutputPort("contact_phase"), builder, period)
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
                    kinematics=kinematics, loggers=loggers, meshcat=meshcat, fault_injector=injector,
                    conditioner=conditioner, supervisor=supervisor)


# ------------------------------------------------------------------------------------------------
# Initial conditions
# ------------------------------------------------------------------------------------------------

# Plant steps taken (and undone) at the start so that a discrete plant's sampled outputs hold the
# start's static contact or constraint wrench (see set_initial_conditions).
PRIMING_STEPS = 20


def set_initial_conditions(scenario, root_context):
    """Put the robot at the task's start, pressing with the desired force if ``start.in_contact``
    (else ``start.gap`` away, for the supervisor's approach); apply the model error to the
    simulated plant; set the controller's integrals and the filter's (or conditioner's) output
    to the first sensor reading."""
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
        held = static_torque(scenario, q0, pressing=config.start.in_contact)
        controller_context.SetDiscreteState(0, np.concatenate([integrals, held]))
    if plant.time_step() > 0 and plant.has_sampled_output_ports():
        # A discrete plant's contact results and reaction forces are sampled at its steps; before the
        # first step they are empty. Take steps from the initial state (with the held static torque)
        # and put the state back, so the sensors read the start's contact wrench at t = 0.
        # Several steps let compliant constraints (e.g. a SAP weld) build up the static force.
        for _ in range(PRIMING_STEPS):
            plant.ExecuteForcedEvents(plant_context, publish=False)
        plant.SetPositionsAndVelocities(plant_context, environment)
    reading = scenario.sensor.get_output_port(0).Eval(scenario.sensor.GetMyContextFromRoot(root_context))
    if scenario.fault_injector is not None:
        injector = scenario.fault_injector
        injector.set_initial_sample(injector.GetMyMutableContextFromRoot(root_context), reading)
        faulty = injector.GetOutputPort("faulty_wrench").Eval(injector.GetMyContextFromRoot(root_context))
        reading = faulty if np.all(np.isfinite(faulty)) else reading
    if scenario.wrench_filter is not None:
        filter_context = scenario.wrench_filter.GetMyMutableContextFromRoot(root_context)
        scenario.wrench_filter.set_initial_output(filter_context, reading)
    if scenario.conditioner is not None:
        scenario.conditioner.set_initial_output(scenario.conditioner.GetMyMutableContextFromRoot(root_context), reading)
    if scenario.supervisor is not None:
        supervisor = scenario.supervisor
        controller_plant_context = scenario.controller_plant.CreateDefaultContext()
        scenario.controller_plant.SetPositions(controller_plant_context, q0)
        start = controller.kinematics.evaluate(controller_plant_context).configuration
        supervisor.set_initial_state(supervisor.GetMyMutableContextFromRoot(root_context), supervisor.initial_phase,
                                     scenario.constraint_space.constraint.value(start))


def apply_model_error(plant, plant_context, robot, model_error):
    """Scale the simulated payload's and links' inertias in ``plant_context`` (see ModelErrorConfig)."""
    from pydrake.multibody.tree import SpatialInertia

    for name in ("payload_mass_scale", "link_mass_scale", "link_inertia_scale"):
        scale = getattr(model_error, name)
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"model_error.{name} must be a positive number, got {scale}")
    for instance in robot.model_instances:
        on_arm = instance == robot.arm
        mass_scale = model_error.link_mass_scale if on_arm else model_error.payload_mass_scale
        inertia_scale = model_error.link_inertia_scale if on_arm else 1.0
        if mass_scale == 1.0 and inertia_scale == 1.0:
            continue
        for index in plant.GetBodyIndices(instance):
            body = plant.get_body(index)
            M_BBo_B = body.default_spatial_inertia()         # nominal (the model's), so applying twice is safe
            mass, com = M_BBo_B.get_mass(), M_BBo_B.get_com()
            if mass == 0:
                continue
            # Rotational inertia about the centre of mass: scaled with the mass, and by inertia_scale.
            central = M_BBo_B.Shift(com).CalcRotationalInertia() * (mass_scale * inertia_scale)
            body.SetSpatialInertiaInBodyFrame(plant_context,
                                              SpatialInertia.MakeFromCentralInertia(mass_scale * mass, com, central))


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
    if scenario.config.start.in_contact:
        try:
            constraint.check_satisfied(x, scenario.config.start.tolerance)
        except OffConstraintError as error:
            raise OffConstraintError(f"{error}; to start off the surface and approach it, set start.in_contact: "
                                     "false (the contact supervisor's guarded move)") from None
    constraint.check_branch(x)


def static_torque(scenario, q, pressing=True):
    """tau = g(q) - J^T E_f^T F_d: the actuation that holds the robot at rest pressing with F_d
    (``pressing=False``: g(q) only, in free space)."""
    controller = scenario.controller
    plant = scenario.controller_plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    kinematics = controller.kinematics
    task = kinematics.evaluate(context)
    values = scenario.constraint_space.evaluate(task.configuration, task.velocity)
    desired_force = np.asarray(scenario.config.desired_force.evaluate(0.0)[0]) * (1.0 if pressing else 0.0)
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
