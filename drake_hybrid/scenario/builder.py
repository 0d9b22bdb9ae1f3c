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

from drake_hybrid.control.baselines import make_baseline
from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.gains import ControlMode, gain_matrix
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.kinematics import EndEffectorKinematics
from drake_hybrid.scenario.start import check_start_sizes
from drake_hybrid.station.loggers import add_loggers
from drake_hybrid.station.loop import HybridSystems, add_contact_supervisor, connect_source
from drake_hybrid.station.path_job import add_path_loggers, connect_path, draw_path, lifts_off
from drake_hybrid.station.robot_model import RobotModel
from drake_hybrid.station.sensing import add_sensing, wrench_lag
from drake_hybrid.systems.faults import JointFriction
from drake_hybrid.tasks.config import ScenarioConfig, check_scenario_config
from drake_hybrid.tasks.path import make_path_source, with_path_commands
from drake_hybrid.tasks.plant import build_controller_plant, build_plant
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.tasks.task import pad_kinematic_rows


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
        wrench_lag=wrench_lag(config.sensor, plant, control_period),
        plant_time_step=plant.time_step() if plant_time_step is None else plant_time_step,
        path_position_error=config.path.active)


def prepare_config(config):
    """(task, mode, constraint space, config) with every field validated once (``config.validate``,
    the task's typed options) and the desired force padded with zeros on the kinematic rows (given
    for the force-controlled rows only): what every diagram built from a config starts from."""
    check_scenario_config(config, "build_scenario")
    config.validate()
    task = get_task(config.task, where="task", error=ConfigError)
    mode = ControlMode.parse(config.mode)
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


def build_scenario(config, meshcat=None, with_loggers=True, sampled_plant_outputs=None, controller_sample_lead=True):
    """Build the closed-loop diagram of ``config``. See the module docstring.

    ``sampled_plant_outputs``: see ``tasks.plant.build_plant`` (default: sampled only under a
    continuous controller). ``controller_sample_lead`` exists for ``analysis.linearize_discrete``."""
    task, mode, constraint_space, config = prepare_config(config)
    control_period = config.control_period if config.control_period > 0 else None

    builder = DiagramBuilder()
    plant, scene_graph, robot = build_plant(task, config, builder, sampled_outputs=sampled_plant_outputs)
    controller_plant, _ = build_controller_plant(task, config)
    controller = builder.AddNamedSystem("controller", make_controller(
        config, task, plant, controller_plant, robot, constraint_space, mode, control_period, controller_sample_lead,
        config.supervised, with_loggers))
    check_start_sizes(config, controller)

    supervised = config.supervised
    tare = supervised and config.supervision.tare_time > 0 and not config.start.in_contact
    sensor, true_wrench, wrench_output, injector, conditioner, wrench_filter = add_sensing(
        builder, plant, robot, controller, config.sensor, control_period, config.sensor_faults, tare)
    if config.model_error.joint_friction > 0:
        friction = builder.AddNamedSystem("joint_friction", JointFriction(
            plant, robot.arm, config.model_error.joint_friction, config.model_error.friction_speed))
        builder.Connect(plant.get_state_output_port(robot.arm), friction.get_input_port(0))
        builder.Connect(friction.get_output_port(0), plant.get_applied_generalized_force_input_port())
    task.connect_environment(builder, plant, config)
    builder.Connect(plant.get_state_output_port(robot.arm), controller.get_estimated_state_input_port())
    builder.Connect(controller.GetOutputPort("actuation"), plant.get_actuation_input_port(robot.arm))

    source = connect_source(builder, plant, robot, make_path_source(task, config, controller_plant, robot,
                                                                    constraint_space)
                            if config.path.active else task.make_source(config, controller_plant, robot,
                                                                        constraint_space), controller)
    supervisor = None
    if supervised:
        if config.start.in_contact:
            initial_phase = ContactPhase.CONTACT
        else:
            initial_phase = ContactPhase.TARE if tare else ContactPhase.APPROACH
        supervisor = add_contact_supervisor(builder, controller, wrench_output, config.supervision, control_period,
                                            initial_phase, source=source, conditioner=conditioner if tare else None,
                                            lift_off=lifts_off(config))
    if config.path.active:
        connect_path(builder, source, controller, supervisor)
    kinematics = EndEffectorKinematics(plant, robot.end_effector_frame, robot.end_effector_point,
                                       constraint_space.chart)
    systems = HybridSystems(plant=plant, robot=robot, controller_plant=controller_plant,
                            constraint_space=constraint_space, controller=controller, sensor=sensor,
                            kinematics=kinematics, wrench_output=wrench_output, true_wrench=true_wrench,
                            source=source, wrench_filter=wrench_filter, conditioner=conditioner,
                            fault_injector=injector, supervisor=supervisor)
    loggers = {}
    if with_loggers:
        loggers = add_loggers(builder, systems, config.log_period)
        if config.path.active:
            add_path_loggers(builder, source, supervisor, loggers, config.log_period)
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
        if config.path.active:
            draw_path(meshcat, source.path)
    diagram = builder.Build()
    diagram.set_name(f"hybrid_{task.name}")
    return Scenario(config=config, task=task, diagram=diagram, plant=plant, scene_graph=scene_graph, robot=robot,
                    controller_plant=controller_plant, controller=controller, sensor=sensor,
                    wrench_filter=wrench_filter, source=source, constraint_space=constraint_space,
                    kinematics=kinematics, loggers=loggers, meshcat=meshcat, fault_injector=injector,
                    conditioner=conditioner, supervisor=supervisor)


