"""A task's closed loop from a ``ScenarioConfig``: the config validated once, then the station's blocks.

``build_scenario(config)`` validates the config (``prepare_config``: ``ScenarioConfig.validate`` and the
task's ``Task.options``, once) and composes the loop from the same blocks a user composes in their
own builder: the task's plant (``tasks.plant.build_plant``), ``station.loop.add_hybrid_controller``
(controller, wrench sensor, faults, filter or conditioner, command source or path job, contact
supervisor, all connected by ``connect_hybrid_loop``) and ``station.loggers.add_loggers``. It returns a
``tasks.task.Scenario`` (a ``HybridSystems`` with the config, the task and the diagram)::

    ProfileSource / DesiredFieldSource / PathSource ──desired_*──┐
    plant ──state────────────────────────────────────────────────├─► HybridController ──actuation──► plant
    plant ──contact_results / reaction_forces─► sensor ─► filter ┘
    loggers ◄── every named output

with, when the config asks for them, the fault injector, the conditioner, the contact supervisor
(``supervision``), a path job (``path``), the simulated plant's model error (``JointFriction``:
``model_error.joint_friction``), and a disc tool's contact patch (``station.sensing.add_contact_patch``,
logged). The same config builds the same diagram in a test, a notebook, the
CLI or a worker process.
"""

import dataclasses
from typing import Any, Dict, Optional

from pydrake.geometry import Meshcat, MeshcatVisualizer
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import DiagramBuilder

from drake_hybrid.control.baselines import make_baseline
from drake_hybrid.control.gains import ControlMode, ValidatedGains, gain_matrix
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.hints import Array
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.scenario.start import check_start_sizes
from drake_hybrid.station.loggers import add_loggers
from drake_hybrid.station.loop import add_hybrid_controller
from drake_hybrid.station.path_job import draw_path
from drake_hybrid.station.robot_model import RobotModel
from drake_hybrid.station.sensing import add_contact_patch
from drake_hybrid.systems.faults import JointFriction
from drake_hybrid.tasks.config import ScenarioConfig, check_scenario_config
from drake_hybrid.tasks.path import task_path_job, with_path_commands
from drake_hybrid.tasks.plant import build_controller_plant, build_plant
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.tasks.task import Scenario, Task, pad_kinematic_rows


@dataclasses.dataclass(frozen=True)
class PreparedConfig:
    """A config validated once, with what every diagram built from it starts from: the ``task``, the
    law's ``mode``, the ``constraint_space``, the ``config`` with its desired force padded with zeros on the
    kinematic rows (and a path job's commands at its first point), and the law's ``gains`` validated
    against the task's sizes and the control rate (None for a baseline law, which checks its own)."""

    task: Task
    mode: ControlMode
    constraint_space: ConstraintSpace
    config: ScenarioConfig
    gains: Optional[ValidatedGains] = None


def prepare_config(config: ScenarioConfig) -> PreparedConfig:
    """``config`` validated once (``config.validate``, the task's typed options, the gains against the
    task's sizes and rate): see ``PreparedConfig``. ConfigError naming the field."""
    check_scenario_config(config, "build_scenario")
    config.validate()
    task = get_task(config.task, where="task", error=ConfigError)
    mode = ControlMode.parse(config.mode)
    task.options(config)
    constraint_space = task.constraint_space(config)
    config = dataclasses.replace(config, desired_force=pad_kinematic_rows(
        config.desired_force, constraint_space.force_size, constraint_space.constraint.kinematic_rows))
    if config.path.active:
        config = with_path_commands(config, constraint_space, task_path_job(task, config))
    config.desired_force.validate(constraint_space.force_size, "desired_force")   # (a task may fill desired_velocity)
    if config.supervised:          # a guarded approach to a surface, which only pushes: over the whole course
        config.desired_force.check_keeps_sign("desired_force")
    gains = None
    if config.controller == "li-sastry":     # the gains against the task's sizes and the control rate
        gains = config.gains.matrices(constraint_space.velocity_size, constraint_space.force_size, mode,
                                      config.control_period if config.control_period > 0 else None)
    return PreparedConfig(task=task, mode=mode, constraint_space=constraint_space, config=config, gains=gains)


def controller_options(prepared: PreparedConfig, plant: MultibodyPlant, controller_plant: MultibodyPlant,
                       robot: RobotModel, control_period: Optional[float],
                       with_loggers: bool, sample_lead: bool = True) -> Dict[str, Any]:
    """The controller's arguments that ``prepared.config`` sets beyond the loop's own (``gains``, ``mode``,
    ``safety``, the mechanism's inertia, the tangential force's compensation), for
    ``station.loop.add_hybrid_controller`` and the real arm's ``make_hybrid_controller``; with a baseline
    law (``config.controller``) the baseline itself as ``controller``."""
    config, task, space = prepared.config, prepared.task, prepared.constraint_space
    if config.controller != "li-sastry":
        return dict(controller=make_baseline(config.controller, controller_plant, robot.end_effector_frame,
                                             robot.end_effector_point, space, gains=config.gains,
                                             baseline=config.baseline, control_period=control_period,
                                             sample_lead=sample_lead))
    return dict(gains=prepared.gains, mode=prepared.mode, safety=config.safety, sample_lead=sample_lead,
                sampled_diagnostics=with_loggers and control_period is not None,
                velocity_row_inertia=velocity_row_inertia(config, task, plant, space),
                compensate_tangential_force=config.compensate_tangential_force,
                normal_force_axis=config.tool.normal_force_axis)


def velocity_row_inertia(config: ScenarioConfig, task: Task, plant: MultibodyPlant,
                         constraint_space: ConstraintSpace) -> Optional[Array]:
    """I_v of ``config.mechanism`` (None for the paper's massless constraint): given, or the task's
    reading of the simulation plant (``Task.velocity_row_inertia``)."""
    source = config.mechanism.source
    if source == "none":
        return None
    if source == "given":
        return gain_matrix(config.mechanism.velocity_row_inertia, constraint_space.velocity_size,
                           "mechanism.velocity_row_inertia", semidefinite=True)
    return task.velocity_row_inertia(plant, config, constraint_space)


def initial_phase(config: ScenarioConfig) -> ContactPhase:
    """The contact supervisor's first phase: CONTACT for a start in contact, TARE for a start that tares
    the sensor first, else APPROACH."""
    if config.start.in_contact:
        return ContactPhase.CONTACT
    return ContactPhase.TARE if config.supervision.tare_time > 0 else ContactPhase.APPROACH


def build_scenario(config: ScenarioConfig, meshcat: Optional[Meshcat] = None, with_loggers: bool = True,
                   sampled_plant_outputs: Optional[bool] = None, controller_sample_lead: bool = True) -> Scenario:
    """Build the closed-loop diagram of ``config``. See the module docstring.

    ``sampled_plant_outputs``: see ``tasks.plant.build_plant`` (default: sampled only under a
    continuous controller). ``controller_sample_lead`` exists for ``analysis.linearize_discrete``."""
    prepared = prepare_config(config)
    task, space, config = prepared.task, prepared.constraint_space, prepared.config
    control_period = config.control_period if config.control_period > 0 else None

    builder = DiagramBuilder()
    plant, scene_graph, robot = build_plant(task, config, builder, sampled_outputs=sampled_plant_outputs)
    controller_plant, _ = build_controller_plant(task, config)
    options = controller_options(prepared, plant, controller_plant, robot, control_period, with_loggers,
                                 controller_sample_lead)
    job = task_path_job(task, config) if config.path.active else None
    systems = add_hybrid_controller(
        builder, plant, robot, space, controller_plant, control_period=control_period,
        source=None if job is not None else task.make_source(config, controller_plant, robot, space),
        path=job, sensor=config.sensor, sensor_faults=config.sensor_faults,
        supervision=config.supervision if config.supervised else None,
        initial_phase=initial_phase(config) if config.supervised else None, **options)
    check_start_sizes(config, systems.controller)
    if with_loggers and robot.tool is not None and robot.tool.is_disc:    # the disc's patch, measured and logged
        systems.patch = add_contact_patch(builder, plant, robot, real_surface=task.real_workpiece_surface(config))
    if config.model_error.joint_friction > 0:
        friction = builder.AddNamedSystem("joint_friction", JointFriction(
            plant, robot.arm, config.model_error.joint_friction, config.model_error.friction_speed))
        builder.Connect(plant.get_state_output_port(robot.arm), friction.get_input_port(0))
        builder.Connect(friction.get_output_port(0), plant.get_applied_generalized_force_input_port())
    task.connect_environment(builder, plant, config)
    scenario = Scenario(config=config, task=task, scene_graph=scene_graph, meshcat=meshcat,
                        **{f.name: getattr(systems, f.name) for f in dataclasses.fields(systems)})
    if with_loggers:
        add_loggers(builder, scenario, config.log_period)
    if meshcat is not None:
        MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat)
        if job is not None:
            draw_path(meshcat, job.path)
    scenario.diagram = builder.Build()
    scenario.diagram.set_name(f"hybrid_{task.name}")
    return scenario

