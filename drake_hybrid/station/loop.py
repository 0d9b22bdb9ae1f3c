"""The hybrid controller in your station: the closed loop, connected in one place.

``add_hybrid_controller(builder, plant, robot, space, controller_plant, ...)`` adds the controller and
everything that feeds it to YOUR builder and plant, wired, and returns the loop's handle
(``station.handles.HybridSystems``)::

    plant ─contact_results / reaction_forces, body_poses─► wrench_sensor ─► [faults] ─► [filter or conditioner] ─┐
    plant ─state (robot.arm)───────────────────────────────────────────────────────────────────────────┼─► controller
    source (a ProfileSource, the PathSource of ``path=``, or yours) ─desired_*────────────────────────────┘    │
    plant (robot.arm) ◄─actuation─────────────────────────────────────────────────────────────────────────────────┘
    [supervisor: controller ─force, constraint_value─► supervisor ─contact_phase, approach_reference─► controller]
    [path: source ─path_position_error─► controller; supervisor ─contact_phase─► source ─path_done─► supervisor]

It is the one composition of the loop: the package's own runs (``scenario.builder.build_scenario``)
and a real arm's controller side (``hardware.controller_side``) are made of the same pieces, and every
connection to or from the controller's ports is made by ``connect_hybrid_loop``, whatever feeds the
loop (a simulated plant's ports, or a real arm's messages). ``make_hybrid_controller`` is the one
place a HybridController is made for a loop (the wrench's lag, the plant's step, the guarded move, the
path's position error).

A whole station, from your own arm to the log (``docs/howto/own_diagram.md``)::

    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(), builder)
    robot = add_robot(plant)                                   # your arm, mount_tool(plant, arm, "tool0")
    workpiece = add_rigid_workpiece(plant, Ellipsoid(0.3, 0.2, 0.1), X_WG)
    apply_contact_defaults(plant, scene_graph, robot, workpiece)
    plant.Finalize()
    only_tool_touches(plant, scene_graph, robot, workpiece)
    hybrid = add_hybrid_controller(builder, plant, robot, space, robot_plant(add_robot), gains=gains,
                                   control_period=1e-3, desired_velocity=[0.05, 0, 0, 0, 0], desired_force=[8.0])
    loggers = add_loggers(builder, hybrid)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    solve_contact_start(diagram, context, hybrid, start_pose=X_WE, joint_guess=q_guess)
    Simulator(diagram, context).AdvanceTo(5.0)
    log = read_log(loggers, context)

Every connection checks the input port first (``builder.IsConnectedOrExported``): Drake ends the
process at an input connected twice, these raise an ArgumentError naming the port.
"""

import inspect
import numbers
from typing import Any, List, Optional, Sequence, Union

import numpy as np

from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import DiagramBuilder, InputPort, OutputPort, System

from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.gains import ControlMode, HybridGains, ValidatedGains
from drake_hybrid.control.normal_force import normal_row
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.supervision import ContactSupervisor, SupervisionConfig
from drake_hybrid.core.arguments import describe, instance, vector
from drake_hybrid.core.errors import ArgumentError, ConfigError
from drake_hybrid.core.hints import Array
from drake_hybrid.core.kinematics import EndEffectorKinematics
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.station.handles import HybridSystems
from drake_hybrid.station.path_job import PathJob
from drake_hybrid.station.ports import add_named, guarded_connect, port_label, port_of
from drake_hybrid.station.robot_model import (RobotModel, arm_model_name, check_finalized_robot_plant,
                                              check_station_parts)
from drake_hybrid.station.sensing import (CONTINUOUS_LOOP_BANDWIDTH, ContactSensorConfig, WristSensorConfig,
                                          check_sensor_config, sensing_of_checked, wrench_lag)
from drake_hybrid.systems.faults import SensorFaultConfig
from drake_hybrid.systems.path_source import PathSource
from drake_hybrid.systems.sources import Profile, ProfileSource

SOURCE_OUTPUTS = ("desired_velocity", "desired_acceleration", "desired_force")
CONTROLLER_INPUTS = ("estimated_state", "measured_wrench") + SOURCE_OUTPUTS
SUPERVISED_INPUTS = ("contact_phase", "approach_reference")
SUPERVISED_OUTPUTS = ("force", "constraint_value")
# The HybridController arguments add_hybrid_controller passes on as given (the others it sets itself).
CONTROLLER_OPTIONS = tuple(name for name in inspect.signature(HybridController._construct).parameters
                           if name not in ("self", "plant", "end_effector_frame", "end_effector_point",
                                           "constraint_space", "gains", "mode", "control_period", "guarded_move",
                                           "path_position_error", "converter"))


def connect_hybrid_loop(builder: DiagramBuilder, controller: System, *, state: OutputPort, wrench: OutputPort,
                        actuation: InputPort, source: Optional[System] = None,
                        supervisor: Optional[ContactSupervisor] = None, conditioner: Optional[System] = None,
                        owner: str = "connect_hybrid_loop", actuation_output: str = "actuation",
                        held_actuation: Optional[InputPort] = None) -> None:
    """Every connection of the hybrid loop to and from ``controller``'s ports, in one place::

        state ─► controller.estimated_state (and the source's first input, if it has one: the arm's state)
        wrench ─► controller.measured_wrench (and supervisor.measured_wrench)
        controller.actuation (or actuation_output) ─► actuation
        source ─desired_velocity, desired_acceleration, desired_force─► controller (desired_force ─► supervisor)
        controller ─force, constraint_value─► supervisor ─contact_phase, approach_reference─► controller
        supervisor ─contact_phase─► conditioner (a taring WrenchConditioner)
        source ─path_position_error─► controller;  supervisor ─contact_phase─► source
        source ─path_done─► supervisor.lift_off

    ``state`` is the arm's [q; v] (a plant's state output, or a real arm's watchdog), ``wrench`` the
    port the controller reads the wrench from, ``actuation`` the input port its torque drives (the
    plant's actuation, or a real arm's command path) from the controller's ``actuation_output``
    ("actuation"; a real arm's command path, which ticks with the law, reads "computed_actuation",
    the tick's own torque; ``held_actuation``, if given, takes the held ``actuation`` then: what a log
    of the applied torque reads). The path's connections are made when the source
    has them (a ``PathSource``): the controller must then take the path's position error, and a source
    that waits for the first contact needs a supervisor. Every input is checked unwired first
    (ArgumentError naming it and ``owner``)."""
    if source is not None:
        if source.num_input_ports():          # its first input is the arm's state (DesiredFieldSource, PathSource)
            _connect_shared(builder, state, source.get_input_port(0), owner)
        for name in SOURCE_OUTPUTS:
            guarded_connect(builder, source.GetOutputPort(name), controller.GetInputPort(name), owner)
    guarded_connect(builder, state, controller.GetInputPort("estimated_state"), owner)
    guarded_connect(builder, wrench, controller.GetInputPort("measured_wrench"), owner)
    guarded_connect(builder, controller.GetOutputPort(actuation_output), actuation, owner)
    if held_actuation is not None:
        guarded_connect(builder, controller.GetOutputPort("actuation"), held_actuation, owner)
    if supervisor is not None:
        for name in SUPERVISED_OUTPUTS:
            guarded_connect(builder, controller.GetOutputPort(name), supervisor.GetInputPort(name), owner)
        for name in SUPERVISED_INPUTS:
            guarded_connect(builder, supervisor.GetOutputPort(name), controller.GetInputPort(name), owner)
        guarded_connect(builder, wrench, supervisor.GetInputPort("measured_wrench"), owner)
        if source is not None:
            guarded_connect(builder, source.GetOutputPort("desired_force"), supervisor.GetInputPort("desired_force"),
                            owner)
        if conditioner is not None:
            guarded_connect(builder, supervisor.GetOutputPort("contact_phase"),
                            conditioner.GetInputPort("contact_phase"), owner)
    if isinstance(source, PathSource):
        if not controller.HasInputPort("path_position_error"):
            raise ArgumentError(f"{owner}: the source runs a path, but controller '{controller.get_name()}' has no "
                                "path_position_error input (build it with path_position_error=True)")
        guarded_connect(builder, source.GetOutputPort("path_position_error"),
                        controller.GetInputPort("path_position_error"), owner)
        if source.get_contact_phase_input_port() is not None:
            if supervisor is None:
                raise ConfigError(f"{owner}: the path's source waits for the first contact, but the loop has no "
                                  "contact supervisor (give supervision=SupervisionConfig(...))")
            guarded_connect(builder, supervisor.GetOutputPort("contact_phase"), source.get_contact_phase_input_port(),
                            owner)
        if supervisor is not None and supervisor.lift_off:
            guarded_connect(builder, source.GetOutputPort("path_done"), supervisor.GetInputPort("lift_off"), owner)


def _connect_shared(builder, output_port, input_port, owner):
    """``guarded_connect``, except that an input already fed by ``output_port`` is left as it is: a source
    shared by several laws (a real arm's gain sets) reads the state once."""
    connection = builder.connection_map().get((input_port.get_system(), input_port.get_index()))
    if connection == (output_port.get_system(), output_port.get_index()):
        return
    guarded_connect(builder, output_port, input_port, owner)


def make_hybrid_controller(controller_plant: MultibodyPlant, robot: RobotModel, constraint_space: ConstraintSpace, *,
                           sensor: Union[ContactSensorConfig, WristSensorConfig], plant: Optional[MultibodyPlant],
                           gains: Union[HybridGains, ValidatedGains, None] = None,
                           mode: Union[ControlMode, str] = ControlMode.VELOCITY_FORCE,
                           control_period: Optional[float] = None, supervision: Optional[SupervisionConfig] = None,
                           path: bool = False, **options: Any) -> HybridController:
    """The HybridController of a loop (the one place a loop's controller is made): on ``controller_plant``
    at ``robot``'s end-effector frame and point, reading the wrench of ``sensor`` measured on ``plant``
    (the simulated plant, whose step the law's joint damping compensates and whose sampled contact results
    are one step old; None: a real arm's, read as current, its ``plant_time_step`` given in ``options``),
    with the guarded move of ``supervision`` and the path's position error input when ``path``.
    ``options``: further HybridController arguments (``CONTROLLER_OPTIONS``); ``sampled_diagnostics``
    defaults to a sampled controller's."""
    defaults = dict(sampled_diagnostics=control_period is not None,
                    plant_time_step=plant.time_step() if plant is not None else 0.0,
                    wrench_lag=wrench_lag(sensor, plant if plant is not None else controller_plant, control_period))
    defaults.update(options)
    return HybridController(controller_plant, robot.end_effector_frame, robot.end_effector_point, constraint_space,
                            gains=gains, mode=mode, control_period=control_period, guarded_move=supervision,
                            path_position_error=path, **defaults)


def path_source(job: PathJob, controller_plant: MultibodyPlant, robot: RobotModel, constraint_space: ConstraintSpace,
                control_period: Optional[float], supervised: bool) -> PathSource:
    """The PathSource that runs ``job`` for a controller on ``controller_plant`` (it waits for the first
    contact when ``supervised``, unless the job holds one point)."""
    force_row = normal_row(constraint_space.force_size, tuple(constraint_space.constraint.kinematic_rows))
    return PathSource(controller_plant, robot.end_effector_frame, robot.end_effector_point, constraint_space,
                      job.path, heading=job.heading, force_row=force_row,
                      dwell=0.0 if job.holding else job.settings.dwell,
                      wait_for_contact=supervised and not job.holding, period=control_period,
                      moments=job.settings.moments)


def add_hybrid_controller(builder: DiagramBuilder, plant: MultibodyPlant, robot: RobotModel,
                          constraint_space: ConstraintSpace, controller_plant: MultibodyPlant,
                          gains: Optional[HybridGains] = None,
                          mode: Union[ControlMode, str] = ControlMode.VELOCITY_FORCE,
                          control_period: Optional[float] = None,
                          desired_velocity: Union[Profile, Sequence[float], None] = None,
                          desired_force: Union[Profile, Sequence[float], None] = None,
                          source: Union[System, bool, None] = None,
                          sensor: Union[ContactSensorConfig, WristSensorConfig, None] = None,
                          supervision: Optional[SupervisionConfig] = None,
                          initial_phase: Union[ContactPhase, int, str, None] = None,
                          sensor_faults: Optional[SensorFaultConfig] = None, controller: Optional[System] = None,
                          path: Optional[PathJob] = None, **controller_options: Any) -> HybridSystems:
    """Add the hybrid controller and what feeds it to your builder, wired to your plant (the module
    docstring draws the loop; ``connect_hybrid_loop`` makes its connections).

    One controller per arm: the arm's actuation input must not be wired yet (ArgumentError naming the
    port otherwise). The systems are named controller, wrench_sensor, desired, ... ; a second arm's
    (a second call with another ``robot``) get its model instance name appended.

    Args:
        builder: your DiagramBuilder; ``plant``: your finalized MultibodyPlant in it (with its SceneGraph).
        robot: the RobotModel of ``mount_tool``.
        constraint_space: a ConstraintSpace (chart, C, E_p).
        controller_plant: the controller's own model of the robot (``robot_plant(add_robot)``): checked
            against the plant's arm (positions, velocities, actuators, the end-effector pose at three
            configurations).
        gains, mode, control_period: of the HybridController (None: continuous, for linearization).
        desired_velocity, desired_force: Profiles (time profiles, k and m entries; a list of numbers is a
            constant one, ``[10.0]`` for one force row; default zero) for a ProfileSource; or ``source``: a
            system of your own with the output ports desired_velocity, desired_acceleration and
            desired_force (wired here), or False: you wire the controller's desired_* input ports yourself.
        path: a PathJob (``station.path_job.path_job``): a job over a surface instead of profiles. Its
            PathSource gives the commands and the position error against the path (the controller
            takes it); with ``supervision`` it waits for the first contact to start the path, and lifts
            off at its end (``settings.lift_off``).
        sensor: a ContactSensorConfig (default) or WristSensorConfig: which wrench, and its path (a
            low-pass of ``bandwidth_hz``, a conditioner). A continuous controller needs a low-pass
            (default then ``CONTINUOUS_LOOP_BANDWIDTH``): its actuation feeds through to the wrench.
        supervision: a SupervisionConfig: a ContactSupervisor (guarded approach, contact loss, a job's
            lift-off) starting in ``initial_phase`` (a ContactPhase; default CONTACT; APPROACH for a
            start above the surface: ``station.contact_start.solve_path_start``, ``solve_approach_start``).
        sensor_faults: a SensorFaultConfig: its injector between the sensor and the wrench path.
        controller: a controller system of your own with the HybridController's ports (e.g. a baseline
            of ``control.baselines``) instead of building one.
        controller_options: further HybridController arguments (``CONTROLLER_OPTIONS``: safety,
            velocity_row_inertia, compensate_tangential_force, sample_lead, sampled_diagnostics,
            plant_time_step, fast_law, normal_force_axis ("tool" for a flat tool whose orientation rows are
            force rows: its normal force along its own axis), ...); only when ``controller`` is None.

    Returns the HybridSystems of the loop. Every port stays reachable by name for wiring by hand.
    """
    owner = "add_hybrid_controller"
    check_station_parts(builder, plant, robot, owner)
    _controller_model(controller_plant, owner)
    instance(constraint_space, "constraint_space", owner, ConstraintSpace,
             what="a ConstraintSpace (a constraint with its velocity projection)")
    unknown = sorted(set(controller_options) - set(CONTROLLER_OPTIONS))
    if unknown:
        raise ArgumentError(f"{owner}: unknown argument(s) {', '.join(unknown)}; the HybridController options are "
                            f"{', '.join(CONTROLLER_OPTIONS)}")
    if controller is not None and controller_options:
        raise ArgumentError(f"{owner}: {', '.join(sorted(controller_options))} configure the HybridController "
                            f"built here, not your controller: pass them to your controller")
    if sensor is None:
        sensor = ContactSensorConfig(bandwidth_hz=CONTINUOUS_LOOP_BANDWIDTH if control_period is None else 0.0)
    check_sensor_config(sensor, owner)
    if control_period is None and not (sensor.bandwidth_hz > 0):
        raise ConfigError("sensor.bandwidth_hz: a continuous controller (control_period None) needs a wrench "
                          "low-pass (> 0 Hz): its actuation feeds through to the measured wrench")
    instance(supervision, "supervision", owner, SupervisionConfig, allow_none=True)
    if supervision is not None and control_period is None:
        raise ArgumentError(f"{owner}: a contact supervisor (supervision) runs at the control period: give "
                            "control_period (s)")
    instance(sensor_faults, "sensor_faults", owner, SensorFaultConfig, allow_none=True)
    instance(path, "path", owner, PathJob, allow_none=True, what="a PathJob (station.path_job.path_job) or None")
    phase = _contact_phase(initial_phase, owner)
    k, m = constraint_space.velocity_size, constraint_space.force_size
    if path is not None:
        given = [name for name, value in (("source", source), ("desired_velocity", desired_velocity),
                                          ("desired_force", desired_force)) if value is not None]
        if given:
            raise ArgumentError(f"{owner}: path gives the commands; do not give {', '.join(given)} too")
        source = path_source(path, controller_plant, robot, constraint_space, control_period, supervision is not None)
    elif source is None:
        source = ProfileSource(as_profile(desired_velocity, k, "desired_velocity"),
                               as_profile(desired_force, m, "desired_force"), k, m)
    elif source is not False:
        _check_source(source, owner)
    if controller is not None:
        instance(controller, "controller", owner, System, what="a controller System with the HybridController's "
                 "ports (e.g. a baseline of control.baselines) or None")
        for name in CONTROLLER_INPUTS + (SUPERVISED_INPUTS if supervision is not None else ()):
            port_of(controller, name, "input", owner, "controller")
        for name in ("actuation",) + (SUPERVISED_OUTPUTS if supervision is not None else ()):
            port_of(controller, name, "output", owner, "controller")
    check_controller_plant(plant, robot, controller_plant, owner)
    _check_actuation_free(builder, plant, robot, owner)
    if controller is None:
        controller = make_hybrid_controller(controller_plant, robot, constraint_space, sensor=sensor, plant=plant,
                                            gains=gains, mode=mode, control_period=control_period,
                                            supervision=supervision, path=path is not None, **controller_options)
    arm = arm_model_name(plant, robot)
    # The law made above, or yours (a baseline: the HybridController's ports and sizes).
    law: HybridController = add_named(builder, "controller", controller, arm)
    tare = supervision is not None and supervision.tare_time > 0 and phase == ContactPhase.TARE
    wrench_sensor, true_wrench, wrench_output, injector, conditioner, wrench_filter = sensing_of_checked(
        builder, plant, robot, sensor, control_period, sensor_faults, tare, owner)
    if source is not False:
        assert isinstance(source, System)          # made above, or checked by _check_source
        source = add_named(builder, "desired", source, arm)
    supervisor = None
    if supervision is not None:
        supervisor = add_named(builder, "contact_supervisor", ContactSupervisor(
            supervision, law.force_size, law.kinematic_rows, control_period, phase,
            lift_off=path is not None and path.lifts_off(supervised=True)), arm)
    connect_hybrid_loop(builder, law, state=plant.get_state_output_port(robot.arm), wrench=wrench_output,
                        actuation=plant.get_actuation_input_port(robot.arm), source=source or None,
                        supervisor=supervisor, conditioner=conditioner if tare else None, owner=owner)
    kinematics = EndEffectorKinematics(plant, robot.end_effector_frame, robot.end_effector_point,
                                       constraint_space.chart)
    return HybridSystems(plant=plant, robot=robot, controller_plant=controller_plant,
                         constraint_space=constraint_space, controller=law, sensor=wrench_sensor,
                         kinematics=kinematics, state=plant.get_state_output_port(robot.arm),
                         wrench_output=wrench_output, actuation=law.GetOutputPort("actuation"),
                         true_wrench=true_wrench, source=source or None, wrench_filter=wrench_filter,
                         conditioner=conditioner, fault_injector=injector, supervisor=supervisor, path=path)


def _check_source(source, owner):
    instance(source, "source", owner, System, what="a System with the output ports " + ", ".join(SOURCE_OUTPUTS)
             + " (or None: a ProfileSource of desired_velocity and desired_force; False: you wire them)")
    for name in SOURCE_OUTPUTS:
        port_of(source, name, "output", owner, "source")


def as_profile(command: Union[Profile, Sequence[float], None], size: int, name: str = "command",
               owner: str = "add_hybrid_controller") -> Profile:
    """``command`` as a Profile of ``size`` entries: a Profile as it is (checked), a sequence of ``size``
    numbers as a constant one, None as zeros. Typed errors name ``name``."""
    if command is None:
        return Profile(value=[0.0] * size)
    if isinstance(command, Profile):
        command.validate(size, f"{owner}: {name}")
        return command
    return Profile(value=vector(command, name, owner, size).tolist())


def _controller_model(controller_plant, owner):
    instance(controller_plant, "controller_plant", owner, MultibodyPlant,
             what="a finalized MultibodyPlant of the robot alone (robot_plant(add_robot))")
    if not controller_plant.is_finalized():
        raise ConfigError(f"{owner}: controller_plant must be finalized (robot_plant(add_robot) does it)")
    return controller_plant


def _contact_phase(initial_phase, owner):
    """``initial_phase`` (a ContactPhase or its value; None: CONTACT) as a ContactPhase; ArgumentError otherwise."""
    if initial_phase is None:
        return ContactPhase.CONTACT
    if isinstance(initial_phase, str) and initial_phase.upper() in ContactPhase.__members__:
        return ContactPhase[initial_phase.upper()]
    if (isinstance(initial_phase, (bool, np.bool_)) or not isinstance(initial_phase, numbers.Integral)
            or int(initial_phase) not in {phase.value for phase in ContactPhase}):
        allowed = ", ".join(f"ContactPhase.{phase.name} ({phase.value})" for phase in ContactPhase)
        raise ArgumentError(f"{owner}: initial_phase must be one of {allowed} or None, got {describe(initial_phase)}")
    return ContactPhase(initial_phase)


_MATCH_TOLERANCE = 1e-6      # m and rad: the controller plant's end-effector pose against the plant's
_MATCH_CONFIGURATIONS = 3    # the default positions and two random ones within the limits


def check_controller_plant(plant: MultibodyPlant, robot: RobotModel, controller_plant: MultibodyPlant,
                           owner: str = "check_controller_plant") -> None:
    """ArgumentError naming ``controller_plant`` if it does not model ``plant``'s arm ``robot.arm``: the
    numbers of positions, velocities and actuators, and the end-effector pose (``robot``'s frame and
    point) at the arm's default positions and two random ones within the joint limits (to
    1e-6 m and rad). Checked first: ``plant`` a finalized MultibodyPlant, ``robot`` the RobotModel of
    ``mount_tool`` on it, ``controller_plant`` a finalized MultibodyPlant (ArgumentError, ConfigError)."""
    check_finalized_robot_plant(plant, robot, owner)
    _controller_model(controller_plant, owner)
    arm, arm_name = robot.arm, plant.GetModelInstanceName(robot.arm)
    counts = {"positions": (plant.num_positions(arm), controller_plant.num_positions()),
              "velocities": (plant.num_velocities(arm), controller_plant.num_velocities()),
              "actuators": (plant.num_actuated_dofs(arm), controller_plant.num_actuated_dofs())}
    for what, (simulated, model) in counts.items():
        if simulated != model:
            raise ArgumentError(f"{owner}: controller_plant has {model} {what}, the plant's arm '{arm_name}' "
                                f"{simulated}: pass the controller's model of this arm (robot_plant(add_robot))")
    frame = robot.end_effector_frame
    for name, model_plant in (("plant", plant), ("controller_plant", controller_plant)):
        if not model_plant.HasFrameNamed(frame):
            raise ArgumentError(f"{owner}: {name} has no end-effector frame '{frame}' (robot.end_effector_frame): "
                                f"pass the controller's model of this arm (robot_plant(add_robot))")
    context, model_context = plant.CreateDefaultContext(), controller_plant.CreateDefaultContext()
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    default = plant.GetPositions(context, arm)
    positions: Array = np.arange(plant.num_positions(), dtype=float)
    in_arm = plant.GetPositionsFromArray(arm, positions).astype(int)
    low = np.where(np.isfinite(lower[in_arm]), lower[in_arm], -np.pi)
    high = np.where(np.isfinite(upper[in_arm]), upper[in_arm], np.pi)
    generator = np.random.default_rng(0)
    configurations: List[Array] = [default] + [generator.uniform(low, high) for _ in range(_MATCH_CONFIGURATIONS - 1)]
    point = np.asarray(robot.end_effector_point, dtype=float)
    for number, q in enumerate(configurations):
        plant.SetPositions(context, arm, q)
        controller_plant.SetPositions(model_context, q)
        X_sim = plant.GetFrameByName(frame).CalcPoseInWorld(context)
        X_model = controller_plant.GetFrameByName(frame).CalcPoseInWorld(model_context)
        distance = float(np.linalg.norm(X_sim.multiply(point) - X_model.multiply(point)))
        angle = float(X_sim.rotation().InvertAndCompose(X_model.rotation()).ToAngleAxis().angle())
        if distance > _MATCH_TOLERANCE or angle > _MATCH_TOLERANCE:
            where = "the arm's default positions" if number == 0 else f"q = {np.round(q, 3).tolist()}"
            raise ArgumentError(f"{owner}: controller_plant does not model the plant's arm '{arm_name}': its "
                                f"end-effector frame '{frame}' is {distance:.3g} m and {angle:.3g} rad from the "
                                f"plant's at {where}; pass robot_plant(add_robot) of the add_robot that built the "
                                f"plant's arm")


def _check_actuation_free(builder, plant, robot, owner):
    port = plant.get_actuation_input_port(robot.arm)
    if not builder.IsConnectedOrExported(port):
        return
    source = builder.connection_map().get((plant, port.get_index()))
    driver = source[0] if source is not None else None
    if driver is not None and driver.HasInputPort("estimated_state") and driver.HasOutputPort("actuation"):
        hint = (f" by '{driver.get_name()}': the builder already has a hybrid controller on this arm (one "
                f"controller per arm)")
    elif driver is not None:
        hint = f" by your system '{driver.get_name()}': leave the arm's actuation input to the hybrid controller"
    else:
        hint = " (exported): leave the arm's actuation input to the hybrid controller"
    raise ArgumentError(f"{owner}: the input port {port_label(port)} is already connected in the builder{hint}")
