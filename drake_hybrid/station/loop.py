"""Building blocks for your own Drake diagram: the hybrid controller as a part of your station.

Each block takes YOUR ``MultibodyPlant`` or ``DiagramBuilder`` and adds one part, returning what it
added, as the manipulation course's station helpers (``AddIiwa``, ``AddWsg``) and Drake's
``ApplyMultibodyPlantConfig`` do. ``scenario.builder.build_scenario`` is one composition of them
(the package's own tasks); yours can be any other::

    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(), builder)

    def add_robot(plant):                       # your arm and its tool: called for both plants
        arm = Parser(plant).AddModels(my_arm_urdf)[0]
        plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link", arm))
        return mount_tool(plant, arm, "tool0", X_flange_tool=RigidTransform([0, 0, 0.02]),
                          gripper_joints=["finger_joint"])

    robot = add_robot(plant)
    workpiece = add_rigid_workpiece(plant, Ellipsoid(0.3, 0.2, 0.1), X_WG)
    apply_contact_defaults(plant, scene_graph, robot, workpiece)
    plant.Finalize()
    only_tool_touches(plant, scene_graph, robot, workpiece)
    hybrid = add_hybrid_controller(builder, plant, robot, space, robot_plant(add_robot), gains=gains,
                                   control_period=1e-3, desired_velocity=Profile(value=[0.05, 0, 0, 0, 0]),
                                   desired_force=Profile(value=[8.0]))   # on the robot, along grad C
    loggers = add_loggers(builder, hybrid)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    solve_contact_start(diagram, context, hybrid, start_pose=X_WE, joint_guess=q_guess)
    Simulator(diagram, context).AdvanceTo(5.0)
    log = read_log(loggers, context)

and ``analysis.linearization.linearize_at_contact(diagram, context, hybrid)`` checks the closed
loop's eigenvalues against the design on the same station built with ``time_step=0`` and no
``control_period`` (Drake's ``Linearize`` needs a continuous loop).

The blocks:

``default_plant_config``     the package's MultibodyPlantConfig: 1 ms SAP steps, hydroelastic contact
``mount_tool``               the compliant pad on a frame of any arm, at an offset; a gripper's joints
                             welded (its geometry kept, or removed); ``name=`` for a further tool in the
                             plant; returns a ``RobotModel``
``add_rigid_workpiece``      a rigid hydroelastic shape at a pose, its mesh as fine as its curvature needs
``apply_contact_defaults``   the pad's modulus, dissipation and mesh, SAP's relaxation times, friction
``only_tool_touches``        collision filters: the robot touches the workpiece with its tool only
``robot_plant``              the controller's own model: your robot alone, in a continuous plant
``add_hybrid_controller``    controller, wrench sensor, wrench filter, command source (and contact
                             supervisor) in one call, wired (one per arm); returns a ``HybridSystems``
``add_loggers``, ``read_log``  every signal of the run, keyed by ``LOG_KEYS`` (the ports' names)

and ``station.contact_start.solve_contact_start`` (pressing with F_d, in your context).

Every block checks each input port it wires before ``Connect`` (``builder.IsConnectedOrExported``):
Drake ends the process at an input connected twice, the blocks raise an ArgumentError naming the port.

Size: the blocks share one vocabulary (the RobotModel of the mounted tool, the HybridSystems of the
controller) and each is a few lines; apart they would import each other.
"""

import inspect
import numbers
from dataclasses import dataclass
from typing import Optional

import numpy as np

from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import DiagramBuilder, OutputPort, System

from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.supervision import ContactSupervisor, SupervisionConfig
from drake_hybrid.core.arguments import describe, instance, vector
from drake_hybrid.core.errors import ArgumentError, ConfigError
from drake_hybrid.core.kinematics import EndEffectorKinematics
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.station.ports import add_named, guarded_connect, port_label, port_of, refuse_wired
from drake_hybrid.station.robot_model import (RobotModel, arm_model_name, check_finalized_robot_plant,
                                              check_station_parts)
from drake_hybrid.station.sensing import (CONTINUOUS_LOOP_BANDWIDTH, ContactSensorConfig, add_sensing,
                                          check_sensor_config, wrench_lag)
from drake_hybrid.systems.faults import SensorFaultConfig
from drake_hybrid.systems.sources import Profile, ProfileSource


@dataclass
class HybridSystems:
    """What ``add_hybrid_controller`` added to your builder, with what analysis needs to read it.

    ``controller`` (HybridController), ``sensor`` (ContactWrenchSensor or WristForceTorqueSensor),
    ``wrench_filter`` (LowPassFilter or None), ``conditioner`` (WrenchConditioner or None),
    ``fault_injector`` (SensorFaultInjector or None), ``source`` (the command source or None: you wire
    the controller's desired_* ports), ``supervisor`` (ContactSupervisor or None), ``wrench_output``
    (the port the controller reads the wrench from), ``true_wrench`` (the sensor's own output); the
    ``plant``, ``robot`` (RobotModel), ``controller_plant``, ``constraint_space`` and ``kinematics``
    (EndEffectorKinematics on the simulation plant) they were built for; ``diagram``: set by the
    functions that take the built diagram.
    """

    plant: object
    robot: RobotModel
    controller_plant: object
    constraint_space: object
    controller: object
    sensor: object
    kinematics: EndEffectorKinematics
    wrench_output: object = None
    true_wrench: object = None
    source: Optional[object] = None
    wrench_filter: Optional[object] = None
    conditioner: Optional[object] = None
    fault_injector: Optional[object] = None
    supervisor: Optional[object] = None
    diagram: Optional[object] = None

    def plant_context(self, root_context):
        return self.plant.GetMyMutableContextFromRoot(root_context)


def _controller_model(controller_plant, owner):
    instance(controller_plant, "controller_plant", owner, MultibodyPlant,
             what="a finalized MultibodyPlant of the robot alone (robot_plant(add_robot))")
    if not controller_plant.is_finalized():
        raise ConfigError(f"{owner}: controller_plant must be finalized (robot_plant(add_robot) does it)")
    return controller_plant


_SOURCE_OUTPUTS = ("desired_velocity", "desired_acceleration", "desired_force")
_CONTROLLER_INPUTS = ("estimated_state", "measured_wrench") + _SOURCE_OUTPUTS
_SUPERVISED_INPUTS = ("contact_phase", "approach_reference")
_SUPERVISED_OUTPUTS = ("force", "constraint_value")


def _check_source(source, owner):
    instance(source, "source", owner, System, what="a System with the output ports " + ", ".join(_SOURCE_OUTPUTS)
             + " (or None: a ProfileSource of desired_velocity and desired_force; False: you wire them)")
    for name in _SOURCE_OUTPUTS:
        port_of(source, name, "output", owner, "source")


def connect_source(builder, plant, robot, source, controller):
    """Add the command source ``source`` (a system with the output ports desired_velocity,
    desired_acceleration and desired_force; if it has inputs, its first is the arm's state, as
    ``DesiredFieldSource``'s and ``PathSource``'s) to ``builder`` as "desired" (or "desired_<arm>" if the
    builder has one) and wire it to ``controller``. Returns it."""
    owner = "connect_source"
    check_station_parts(builder, plant, robot, owner)
    _check_source(source, owner)
    instance(controller, "controller", owner, System)
    inputs = [port_of(controller, name, "input", owner, "controller") for name in _SOURCE_OUTPUTS]
    for port in inputs:
        refuse_wired(builder, port, owner, " (the controller already has a command source)")
    source = add_named(builder, "desired", source, arm_model_name(plant, robot))
    if source.num_input_ports():
        guarded_connect(builder, plant.get_state_output_port(robot.arm), source.get_input_port(0), owner)
    for name, port in zip(_SOURCE_OUTPUTS, inputs):
        guarded_connect(builder, source.GetOutputPort(name), port, owner)
    return source


def add_contact_supervisor(builder, controller, wrench_output, supervision, control_period, initial_phase,
                           source=None, conditioner=None, lift_off=False, suffix="supervisor"):
    """Add a ContactSupervisor (``supervision``: a SupervisionConfig; starting in ``initial_phase``)
    between ``controller`` (a HybridController built with ``guarded_move=supervision``) and the
    wrench it reads (``wrench_output``), wired both ways::

        controller ─force, constraint_value─► supervisor ─contact_phase, approach_reference─► controller
        wrench_output ─► supervisor;  source ─desired_force─► supervisor;  supervisor ─contact_phase─► conditioner

    (``source``: the command source; ``conditioner``: a taring WrenchConditioner; ``lift_off``: the
    supervisor takes a ``path_done`` input and lifts off). Returns it."""
    owner = "add_contact_supervisor"
    instance(builder, "builder", owner, DiagramBuilder)
    instance(supervision, "supervision", owner, SupervisionConfig)
    instance(wrench_output, "wrench_output", owner, OutputPort, what="an OutputPort (the wrench the controller reads)")
    instance(controller, "controller", owner, System)
    phase = _contact_phase(initial_phase, owner)
    inputs = [port_of(controller, name, "input", owner, "controller") for name in _SUPERVISED_INPUTS]
    outputs = [port_of(controller, name, "output", owner, "controller") for name in _SUPERVISED_OUTPUTS]
    for port in inputs:
        refuse_wired(builder, port, owner, " (the controller already has a contact supervisor)")
    for name in ("force_size", "kinematic_rows"):
        if not hasattr(controller, name):
            raise ArgumentError(f"{owner}: controller must be a HybridController (or have its {name}), got "
                                f"{describe(controller)}")
    supervisor = add_named(builder, "contact_supervisor", ContactSupervisor(
        supervision, controller.force_size, controller.kinematic_rows, control_period, phase,
        lift_off=lift_off), suffix)
    for name, port in zip(_SUPERVISED_OUTPUTS, outputs):
        guarded_connect(builder, port, supervisor.GetInputPort(name), owner)
    if source is not None:
        guarded_connect(builder, port_of(source, "desired_force", "output", owner, "source"),
                supervisor.GetInputPort("desired_force"), owner)
    guarded_connect(builder, wrench_output, supervisor.GetInputPort("measured_wrench"), owner)
    for name, port in zip(("contact_phase", "approach_reference"), inputs):
        guarded_connect(builder, supervisor.GetOutputPort(name), port, owner)
    if conditioner is not None:
        guarded_connect(builder, supervisor.GetOutputPort("contact_phase"),
                port_of(conditioner, "contact_phase", "input", owner, "conditioner"), owner)
    return supervisor


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


def as_profile(command, size, name="command", owner="add_hybrid_controller"):
    """``command`` as a Profile of ``size`` entries: a Profile as it is (checked), a sequence of ``size``
    numbers as a constant one, None as zeros. Typed errors name ``name``."""
    if command is None:
        return Profile(value=[0.0] * size)
    if isinstance(command, Profile):
        command.validate(size, f"{owner}: {name}")
        return command
    return Profile(value=vector(command, name, owner, size).tolist())


CONTROLLER_OPTIONS = tuple(name for name in inspect.signature(HybridController._construct).parameters
                           if name not in ("self", "plant", "end_effector_frame", "end_effector_point",
                                           "constraint_space", "gains", "mode", "control_period", "guarded_move",
                                           "converter"))
_MATCH_TOLERANCE = 1e-6      # m and rad: the controller plant's end-effector pose against the plant's
_MATCH_CONFIGURATIONS = 3    # the default positions and two random ones within the limits


def check_controller_plant(plant, robot, controller_plant, owner="check_controller_plant"):
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
    for name, model in (("plant", plant), ("controller_plant", controller_plant)):
        if not model.HasFrameNamed(frame):
            raise ArgumentError(f"{owner}: {name} has no end-effector frame '{frame}' (robot.end_effector_frame): "
                                f"pass the controller's model of this arm (robot_plant(add_robot))")
    context, model_context = plant.CreateDefaultContext(), controller_plant.CreateDefaultContext()
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    default = plant.GetPositions(context, arm)
    in_arm = plant.GetPositionsFromArray(arm, np.arange(plant.num_positions(), dtype=float)).astype(int)
    low = np.where(np.isfinite(lower[in_arm]), lower[in_arm], -np.pi)
    high = np.where(np.isfinite(upper[in_arm]), upper[in_arm], np.pi)
    generator = np.random.default_rng(0)
    configurations = [default] + [generator.uniform(low, high) for _ in range(_MATCH_CONFIGURATIONS - 1)]
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


def add_hybrid_controller(builder, plant, robot, constraint_space, controller_plant, gains=None,
                          mode=ControlMode.VELOCITY_FORCE, control_period=None, desired_velocity=None,
                          desired_force=None, source=None, sensor=None, supervision=None, initial_phase=None,
                          sensor_faults=None, controller=None, **controller_options):
    """Add the hybrid controller and what feeds it to your builder, wired to your plant.

    ::

        plant ─contact_results / reaction_forces, body_poses─► wrench_sensor ─► [filter or conditioner] ─┐
        plant ─state (robot.arm)──────────────────────────────────────────────────────────────────────┼─► controller
        source ─desired_velocity, desired_acceleration, desired_force─────────────────────────────────┘      │
        controller ─actuation─► plant (robot.arm)  ◄───────────────────────────────────────────────────────────┘
        [supervisor: controller ─force, constraint_value─► supervisor ─contact_phase, approach_reference─► controller]

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
        sensor: a ContactSensorConfig (default) or WristSensorConfig: which wrench, and its path (a
            low-pass of ``bandwidth_hz``, a conditioner). A continuous controller needs a low-pass
            (default then ``CONTINUOUS_LOOP_BANDWIDTH``): its actuation feeds through to the wrench.
        supervision: a SupervisionConfig: a ContactSupervisor (guarded approach, contact loss) starting
            in ``initial_phase`` (a ContactPhase; default CONTACT).
        sensor_faults: a SensorFaultConfig: its injector between the sensor and the wrench path.
        controller: a controller system of your own with the HybridController's ports (e.g. a baseline
            of ``control.baselines``) instead of building one.
        controller_options: further HybridController arguments (``CONTROLLER_OPTIONS``: safety,
            velocity_row_inertia, compensate_tangential_force, sample_lead, sampled_diagnostics,
            plant_time_step, fast_law, ...); only when ``controller`` is None.

    Returns a HybridSystems. Every port stays reachable by name for wiring by hand.
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
    instance(sensor_faults, "sensor_faults", owner, SensorFaultConfig, allow_none=True)
    phase = _contact_phase(initial_phase, owner)
    k, m = constraint_space.velocity_size, constraint_space.force_size
    if source is None:
        source = ProfileSource(as_profile(desired_velocity, k, "desired_velocity"),
                               as_profile(desired_force, m, "desired_force"), k, m)
    elif source is not False:
        _check_source(source, owner)
    if controller is not None:
        instance(controller, "controller", owner, System, what="a controller System with the HybridController's "
                 "ports (e.g. a baseline of control.baselines) or None")
        for name in _CONTROLLER_INPUTS + (_SUPERVISED_INPUTS if supervision is not None else ()):
            port_of(controller, name, "input", owner, "controller")
        for name in ("actuation",) + (_SUPERVISED_OUTPUTS if supervision is not None else ()):
            port_of(controller, name, "output", owner, "controller")
    check_controller_plant(plant, robot, controller_plant, owner)
    _check_actuation_free(builder, plant, robot, owner)
    if controller is None:
        options = dict(sampled_diagnostics=control_period is not None, plant_time_step=plant.time_step(),
                       wrench_lag=wrench_lag(sensor, plant, control_period))
        options.update(controller_options)
        controller = HybridController(controller_plant, robot.end_effector_frame, robot.end_effector_point,
                                      constraint_space, gains=gains, mode=mode, control_period=control_period,
                                      guarded_move=supervision, **options)
    arm = arm_model_name(plant, robot)
    controller = add_named(builder, "controller", controller, arm)
    tare = supervision is not None and supervision.tare_time > 0 and phase == ContactPhase.TARE
    wrench_sensor, true_wrench, wrench_output, injector, conditioner, wrench_filter = add_sensing(
        builder, plant, robot, controller, sensor, control_period, sensor_faults, tare)
    guarded_connect(builder, plant.get_state_output_port(robot.arm), controller.GetInputPort("estimated_state"), owner)
    guarded_connect(builder, controller.GetOutputPort("actuation"), plant.get_actuation_input_port(robot.arm), owner)
    source = connect_source(builder, plant, robot, source, controller) if source is not False else None
    supervisor = None
    if supervision is not None:
        supervisor = add_contact_supervisor(builder, controller, wrench_output, supervision, control_period, phase,
                                            source=source, conditioner=conditioner if tare else None, suffix=arm)
    kinematics = EndEffectorKinematics(plant, robot.end_effector_frame, robot.end_effector_point,
                                       constraint_space.chart)
    return HybridSystems(plant=plant, robot=robot, controller_plant=controller_plant,
                         constraint_space=constraint_space, controller=controller, sensor=wrench_sensor,
                         kinematics=kinematics, wrench_output=wrench_output, true_wrench=true_wrench, source=source,
                         wrench_filter=wrench_filter, conditioner=conditioner, fault_injector=injector,
                         supervisor=supervisor)
