"""The builder that wires a whole closed loop from a ``ScenarioConfig`` (scenario.config).

``build_scenario(config)`` validates the config (``ScenarioConfig.validate`` and the task's
``Task.options``, once) and returns a
``Scenario`` whose ``diagram`` is::

    ProfileSource / DesiredFieldSource ──desired_*──────────────┐
    plant ──state──────────────────────────────────────────────►├─► HybridController ──actuation──► plant
    plant ──contact_results / reaction_forces─► sensor ─► filter ┘
    loggers ◄── every named output

and, when the config asks for them (parts in brackets are optional)::

    sensor ─► [SensorFaultInjector] ─faulty_wrench, sequence─► [WrenchConditioner] ─► controller
    controller ─force, constraint_value─► [ContactSupervisor] ─contact_phase─► controller, conditioner
                                          [ContactSupervisor] ─approach_reference─► controller
    plant ─state─► [JointFriction] ─generalized_force─► plant (model error, simulation only)

with named handles to every part. The same config builds the same diagram in
a test, a notebook, the CLI or a worker process.
"""

import dataclasses
from dataclasses import dataclass, field
from typing import Dict, Optional

from pydrake.geometry import MeshcatVisualizer
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from drake_hybrid.control.baselines import make_baseline
from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.gains import ControlMode, gain_matrix
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.supervision import ContactSupervisor
from drake_hybrid.core.arguments import instance
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.kinematics import EndEffectorKinematics
from drake_hybrid.scenario.config import ContactSensorConfig, ScenarioConfig, WristSensorConfig
from drake_hybrid.scenario.path_job import (add_path_loggers, connect_path, draw_path, lifts_off, make_path_source,
                                             with_path_commands)
from drake_hybrid.scenario.plant import RobotModel, build_controller_plant, build_plant
from drake_hybrid.scenario.start import check_start_sizes
from drake_hybrid.scenario.task import pad_kinematic_rows
from drake_hybrid.scenario.tasks import get_task
from drake_hybrid.systems.faults import JointFriction, SensorFaultInjector
from drake_hybrid.systems.sensors import (ContactWrenchSensor, LowPassFilter, WrenchConditioner, WristForceTorqueSensor,
                                          low_pass_lag, sampled_reading_age)


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



def velocity_row_inertia(config, task, plant, constraint_space):
    """I_v of ``config.mechanism`` (None for the paper's massless constraint): given, or the task's
    reading of the simulation plant (``Task.velocity_row_inertia``)."""
    source = config.mechanism.source
    if source == "none":
        return None
    if source == "given":
        return gain_matrix(config.mechanism.velocity_row_inertia, constraint_space.velocity_size,
                           "mechanism.velocity_row_inertia", semidefinite=True)
    return task.velocity_row_inertia(plant, config, constraint_space)


def make_controller(config, task, plant, controller_plant, robot, constraint_space, mode, control_period,
                    sample_lead, supervised, with_loggers, plant_time_step=None):
    """The law of ``config.controller``: Li & Sastry's HybridController or a baseline (control.baselines).
    ``plant_time_step``: the step of the plant the law drives, for its joint damping (``control.damping``;
    default ``plant.time_step()``; 0 for a real arm). The law splits the wrench where it was measured:
    the low-pass of ``config.sensor`` (``add_wrench_path``) late (``systems.sensors.low_pass_lag``), the
    contact sensor's reading of a sampled plant one step old (``systems.sensors.sampled_reading_age``)."""
    # The contact sensor's sampled results are one step old, and the law splits them where they were
    # exerted; the wrist sensor's reaction force acts at a frame of the tool (read as current, as the
    # hardware path reads a real sensor's: the crank's figures are the same either way).
    contact_reading_age = sampled_reading_age(plant) if isinstance(config.sensor, ContactSensorConfig) else 0.0
    if config.controller != "li-sastry":
        return make_baseline(config.controller, controller_plant, robot.end_effector_frame, robot.end_effector_point,
                             constraint_space, gains=config.gains, baseline=config.baseline,
                             control_period=control_period,
                             sample_lead=sample_lead)
    return HybridController(
        controller_plant, robot.end_effector_frame, robot.end_effector_point, constraint_space,
        gains=config.gains, mode=mode, control_period=control_period, sample_lead=sample_lead,
        safety=config.safety, guarded_move=config.supervision if supervised else None,
        sampled_diagnostics=with_loggers and control_period is not None,
        velocity_row_inertia=velocity_row_inertia(config, task, plant, constraint_space),
        compensate_tangential_force=config.compensate_tangential_force,
        wrench_lag=low_pass_lag(config.sensor.bandwidth_hz, control_period) + contact_reading_age,
        plant_time_step=plant.time_step() if plant_time_step is None else plant_time_step,
        path_position_error=config.path.active)


def prepare_config(config):
    """(task, mode, constraint space, config) with every field validated once (``config.validate``,
    the task's typed options) and the desired force padded with zeros on the kinematic rows (given
    for the force-controlled rows only): what every diagram built from a config starts from."""
    instance(config, "config", "build_scenario", ScenarioConfig,
             what="a ScenarioConfig (e.g. get_task('window-washing').default_config())")
    task = get_task(config.task)
    mode = ControlMode.parse(config.mode)
    config.validate()
    task.options(config)
    constraint_space = task.constraint_space(config)
    config = dataclasses.replace(config, desired_force=pad_kinematic_rows(
        config.desired_force, constraint_space.force_size, constraint_space.constraint.kinematic_rows))
    if config.path.active:
        config = with_path_commands(config, constraint_space)
    config.desired_force.validate(constraint_space.force_size, "desired_force")   # (a task may fill desired_velocity)
    if config.supervised:          # a guarded approach to a surface, which only pushes: over the whole course
        config.desired_force.check_keeps_sign("desired_force")
    if config.controller == "li-sastry":     # the gains against the task's sizes and the control rate
        config.gains.matrices(constraint_space.velocity_size, constraint_space.force_size, mode,
                              config.control_period if config.control_period > 0 else None)
    return task, mode, constraint_space, config


def add_wrench_path(builder, wrench_output, sensor, period, sequence=None, tare=False):
    """The wrench's way to the controller (``sensor``: a ScenarioConfig.sensor): a WrenchConditioner
    with ``sensor.condition`` (fed the sample ``sequence`` output when given; ``tare``), else a
    low-pass filter when ``sensor.bandwidth_hz`` > 0, else nothing. Returns (the output port the
    controller reads, the conditioner or None, the filter or None)."""
    conditioner = wrench_filter = None
    if sensor.condition:
        conditioner = builder.AddNamedSystem("wrench_conditioner", WrenchConditioner(
            period, sensor.bandwidth_hz, sensor.max_hold_time, use_sequence=sequence is not None, tare=tare))
        builder.Connect(wrench_output, conditioner.GetInputPort("raw_wrench"))
        if sequence is not None:
            builder.Connect(sequence, conditioner.GetInputPort("sequence"))
        wrench_output = conditioner.GetOutputPort("wrench")
    elif sensor.bandwidth_hz > 0:
        wrench_filter = builder.AddNamedSystem("wrench_filter", LowPassFilter(6, sensor.bandwidth_hz, period))
        builder.Connect(wrench_output, wrench_filter.get_input_port(0))
        wrench_output = wrench_filter.get_output_port(0)
    return wrench_output, conditioner, wrench_filter


def build_scenario(config, meshcat=None, with_loggers=True, sampled_plant_outputs=None, controller_sample_lead=True):
    """Build the closed-loop diagram of ``config``. See the module docstring.

    ``sampled_plant_outputs``: see ``scenario.plant.build_plant`` (default: sampled only under a
    continuous controller). ``controller_sample_lead`` exists for ``analysis.linearize_discrete``."""
    if not isinstance(config, ScenarioConfig):
        raise TypeError(f"build_scenario: expected a ScenarioConfig, got {type(config).__name__}")
    task, mode, constraint_space, config = prepare_config(config)
    control_period = config.control_period if config.control_period > 0 else None

    builder = DiagramBuilder()
    plant, scene_graph, robot = build_plant(task, config, builder, sampled_outputs=sampled_plant_outputs)
    controller_plant, _ = build_controller_plant(task, config)
    supervised = config.supervised
    controller = builder.AddNamedSystem("controller", make_controller(
        config, task, plant, controller_plant, robot, constraint_space, mode, control_period, controller_sample_lead,
        supervised, with_loggers))
    check_start_sizes(config, controller)

    robot_bodies = [plant.get_body(index) for instance in robot.model_instances
                    for index in plant.GetBodyIndices(instance)]
    if isinstance(config.sensor, WristSensorConfig):
        if robot.tool_weld is None:
            raise ConfigError(f"sensor: task '{task.name}' has no wrist weld for a WristSensorConfig; "
                              "use !ContactSensorConfig")
        sensor = builder.AddNamedSystem("wrench_sensor", WristForceTorqueSensor(
            plant, robot.tool_weld, robot.end_effector_frame, robot.end_effector_point,
            compensate_tool_inertia=config.sensor.compensate_tool_inertia))
        builder.Connect(plant.get_reaction_forces_output_port(), sensor.get_input_port(0))
        if sensor.compensate_tool_inertia:
            builder.Connect(plant.get_body_spatial_velocities_output_port(),
                            sensor.GetInputPort("body_spatial_velocities"))
            builder.Connect(plant.get_body_spatial_accelerations_output_port(),
                            sensor.GetInputPort("body_spatial_accelerations"))
    else:                                                # ContactSensorConfig (ScenarioConfig.validate)
        sensor = builder.AddNamedSystem("wrench_sensor", ContactWrenchSensor(
            plant, robot_bodies, robot.end_effector_frame, robot.end_effector_point))
        builder.Connect(plant.get_contact_results_output_port(), sensor.get_input_port(0))
    builder.Connect(plant.get_body_poses_output_port(), sensor.get_input_port(1))
    wrench_output = sensor.get_output_port(0)
    true_wrench = wrench_output
    injector = supervisor = None
    if config.sensor_faults.active():
        injector = builder.AddNamedSystem("sensor_faults", SensorFaultInjector(config.sensor_faults, control_period))
        builder.Connect(wrench_output, injector.GetInputPort("wrench"))
        wrench_output = injector.GetOutputPort("faulty_wrench")
    tare = supervised and config.supervision.tare_time > 0 and not config.start.in_contact
    wrench_output, conditioner, wrench_filter = add_wrench_path(
        builder, wrench_output, config.sensor, control_period,
        sequence=injector.GetOutputPort("sequence") if injector is not None else None, tare=tare)
    builder.Connect(wrench_output, controller.get_measured_wrench_input_port())
    if config.model_error.joint_friction > 0:
        friction = builder.AddNamedSystem("joint_friction", JointFriction(
            plant, robot.arm, config.model_error.joint_friction, config.model_error.friction_speed))
        builder.Connect(plant.get_state_output_port(robot.arm), friction.get_input_port(0))
        builder.Connect(friction.get_output_port(0), plant.get_applied_generalized_force_input_port())
    task.connect_environment(builder, plant, config)
    builder.Connect(plant.get_state_output_port(robot.arm), controller.get_estimated_state_input_port())
    builder.Connect(controller.GetOutputPort("actuation"), plant.get_actuation_input_port(robot.arm))

    if config.path.active:                          # a job's path (scenario.path_job)
        source = make_path_source(task, config, controller_plant, robot, constraint_space)
    else:
        source = task.make_source(config, controller_plant, robot, constraint_space)
    source = builder.AddNamedSystem("desired", source)
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
            initial_phase, lift_off=lifts_off(config)))
        for name in ("force", "constraint_value"):
            builder.Connect(controller.GetOutputPort(name), supervisor.GetInputPort(name))
        builder.Connect(source.GetOutputPort("desired_force"), supervisor.GetInputPort("desired_force"))
        builder.Connect(wrench_output, supervisor.GetInputPort("measured_wrench"))
        builder.Connect(supervisor.GetOutputPort("contact_phase"), controller.get_contact_phase_input_port())
        builder.Connect(supervisor.GetOutputPort("approach_reference"), controller.get_approach_reference_input_port())
        if tare:
            builder.Connect(supervisor.GetOutputPort("contact_phase"), conditioner.GetInputPort("contact_phase"))
    if config.path.active:
        connect_path(builder, source, controller, supervisor)

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
        if config.path.active:
            add_path_loggers(builder, source, supervisor, loggers, period)
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
        if config.path.active:
            draw_path(meshcat, source.path)
    diagram = builder.Build()
    diagram.set_name(f"hybrid_{task.name}")
    kinematics = EndEffectorKinematics(plant, robot.end_effector_frame, robot.end_effector_point,
                                       constraint_space.chart)
    return Scenario(config=config, task=task, diagram=diagram, plant=plant, scene_graph=scene_graph, robot=robot,
                    controller_plant=controller_plant, controller=controller, sensor=sensor,
                    wrench_filter=wrench_filter, source=source, constraint_space=constraint_space,
                    kinematics=kinematics, loggers=loggers, meshcat=meshcat, fault_injector=injector,
                    conditioner=conditioner, supervisor=supervisor)


