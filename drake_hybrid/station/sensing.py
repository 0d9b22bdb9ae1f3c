"""The wrench the controller reads: a sensor on the plant, faults, a filter or a conditioner; and the pad's
contact patch measured (``add_contact_patch``: not read by the controller, logged).
"""

import math
from dataclasses import dataclass
from typing import List, Optional, Tuple, Union

from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import RigidBody
from pydrake.systems.framework import DiagramBuilder, OutputPort

from drake_hybrid.core.arguments import instance
from drake_hybrid.core.errors import ConfigError, check_fields, check_finite
from drake_hybrid.core.schema import check_types
from drake_hybrid.core.surfaces import Surface
from drake_hybrid.station.ports import add_named, guarded_connect
from drake_hybrid.station.robot_model import RobotModel, arm_model_name, check_station_parts
from drake_hybrid.systems.contact_patch import ContactPatchSensor
from drake_hybrid.systems.contact_wrench_sensor import ContactWrenchSensor, sampled_reading_age
from drake_hybrid.systems.faults import SensorFaultConfig, SensorFaultInjector
from drake_hybrid.systems.low_pass_filter import LowPassFilter, low_pass_lag
from drake_hybrid.systems.wrench_conditioner import WrenchConditioner
from drake_hybrid.systems.wrist_force_torque_sensor import WristForceTorqueSensor


@dataclass
class WrenchPathConfig:
    """What every sensor's wrench passes through before the controller."""

    bandwidth_hz: float = 0.0                    # Hz, first-order low-pass; 0 = none (a continuous plant needs one)
    condition: bool = False                      # a WrenchConditioner (dropout rejection, tare, the low-pass)
    max_hold_time: float = 0.01                  # s, how long the conditioner bridges a dropout by holding
    fault_time: float = 0.05                     # s, a wrench invalid (non-finite) this long is a sensor fault:
                                                 # the run stops there and reports it (inf = never)

    def validate(self, prefix: str = "sensor.") -> None:
        """As ``ContactConfig.validate`` (``fault_time`` may be inf: never)."""
        check_types(self, type(self), prefix.rstrip("."))
        check_finite(self, prefix, allow_infinite=("fault_time",))
        check_fields(self, prefix, nonnegative=("bandwidth_hz", "max_hold_time"), positive=("fault_time",))


@dataclass
class ContactSensorConfig(WrenchPathConfig):
    """The ideal sensor: Drake's contact results on the robot, shifted to the end-effector point
    (``systems.contact_wrench_sensor.ContactWrenchSensor``). YAML: ``sensor: !ContactSensorConfig {...}`` (the
    default, so the tag may be left out)."""


@dataclass
class WristSensorConfig(WrenchPathConfig):
    """A force/torque sensor in the weld between wrist and tool: the weld's reaction force minus the
    tool's weight (``systems.wrist_force_torque_sensor.WristForceTorqueSensor``). YAML:
    ``sensor: !WristSensorConfig {...}``.

    ``compensate_tool_inertia``: also remove the tool's inertial wrench (its spatial momentum rate,
    from the tool's model and the plant's body accelerations), so that the sensor reports the
    contact wrench during motion too. Off by default: the static compensation of the paper's
    setting (and of most real sensors' drivers)."""

    compensate_tool_inertia: bool = False


SensorConfig = Union[ContactSensorConfig, WristSensorConfig]
# The wrench sensor of a SensorConfig (``add_wrench_sensor``).
WrenchSensor = Union[ContactWrenchSensor, WristForceTorqueSensor]
# What ``add_sensing`` adds: (sensor, its own output, the output the controller reads, injector, conditioner, filter).
Sensing = Tuple[WrenchSensor, OutputPort, OutputPort, Optional[SensorFaultInjector], Optional[WrenchConditioner],
                Optional[LowPassFilter]]
CONTINUOUS_LOOP_BANDWIDTH = 200.0     # Hz: the wrench low-pass a continuous controller needs (no algebraic loop)


def robot_bodies(plant: MultibodyPlant, robot: RobotModel) -> List[RigidBody]:
    """The bodies of every model instance of ``robot``: what a contact sensor counts as the robot."""
    return [plant.get_body(index) for instance in robot.model_instances for index in plant.GetBodyIndices(instance)]


def add_wrench_sensor(builder: DiagramBuilder, plant: MultibodyPlant, robot: RobotModel,
                      sensor: Optional[SensorConfig] = None) -> WrenchSensor:
    """The wrench sensor of ``sensor`` (a ContactSensorConfig, default; or a WristSensorConfig) on your
    plant, its inputs wired: the environment's wrench on the robot at the end-effector point, in
    world (the contact results of the robot's bodies, or the wrist weld's reaction force). Returns it
    (named "wrench_sensor", or "wrench_sensor_<arm>" if the builder has one)."""
    owner = "add_wrench_sensor"
    check_station_parts(builder, plant, robot, owner)
    sensor = check_sensor_config(sensor if sensor is not None else ContactSensorConfig(), owner)
    return _add_wrench_sensor(builder, plant, robot, sensor, owner)


def _add_wrench_sensor(builder, plant, robot, sensor, owner):
    """``add_wrench_sensor`` of arguments already checked."""
    arm = arm_model_name(plant, robot)
    if isinstance(sensor, WristSensorConfig):
        if robot.tool_weld is None:
            raise ConfigError("sensor: the robot has no wrist weld (mount_tool makes one) for a WristSensorConfig; "
                              "use ContactSensorConfig")
        system = add_named(builder, "wrench_sensor", WristForceTorqueSensor(
            plant, robot.tool_weld, robot.end_effector_frame, robot.end_effector_point,
            compensate_tool_inertia=sensor.compensate_tool_inertia), arm)
        guarded_connect(builder, plant.get_reaction_forces_output_port(), system.get_input_port(0), owner)
        if system.compensate_tool_inertia:
            guarded_connect(builder, plant.get_body_spatial_velocities_output_port(),
                    system.GetInputPort("body_spatial_velocities"), owner)
            guarded_connect(builder, plant.get_body_spatial_accelerations_output_port(),
                    system.GetInputPort("body_spatial_accelerations"), owner)
    else:
        system = add_named(builder, "wrench_sensor", ContactWrenchSensor(
            plant, robot_bodies(plant, robot), robot.end_effector_frame, robot.end_effector_point), arm)
        guarded_connect(builder, plant.get_contact_results_output_port(), system.get_input_port(0), owner)
    guarded_connect(builder, plant.get_body_poses_output_port(), system.get_input_port(1), owner)
    return system


def add_wrench_path(builder: DiagramBuilder, wrench_output: OutputPort, sensor: SensorConfig, period: Optional[float],
                    sequence: Optional[OutputPort] = None, tare: bool = False, suffix: str = "wrench"
                    ) -> Tuple[OutputPort, Optional[WrenchConditioner], Optional[LowPassFilter]]:
    """The wrench's way to the controller (``sensor``: a ContactSensorConfig or WristSensorConfig): a
    WrenchConditioner with ``sensor.condition`` (fed the sample ``sequence`` output when given;
    ``tare``), else a low-pass filter when ``sensor.bandwidth_hz`` > 0, else nothing (``suffix``: what
    their names end with when the builder already has a system of that name). Returns (the output
    port the controller reads, the conditioner or None, the filter or None)."""
    owner = "add_wrench_path"
    instance(builder, "builder", owner, DiagramBuilder)
    instance(wrench_output, "wrench_output", owner, OutputPort, what="an OutputPort (the wrench sensor's)")
    instance(sequence, "sequence", owner, OutputPort, allow_none=True)
    check_sensor_config(sensor, owner)
    return _add_wrench_path(builder, wrench_output, sensor, period, sequence, tare, suffix, owner)


def _add_wrench_path(builder, wrench_output, sensor, period, sequence, tare, suffix, owner):
    """``add_wrench_path`` of arguments already checked."""
    conditioner = wrench_filter = None
    if sensor.condition:
        conditioner = add_named(builder, "wrench_conditioner", WrenchConditioner(
            period, sensor.bandwidth_hz, sensor.max_hold_time, use_sequence=sequence is not None, tare=tare), suffix)
        guarded_connect(builder, wrench_output, conditioner.GetInputPort("raw_wrench"), owner)
        if sequence is not None:
            guarded_connect(builder, sequence, conditioner.GetInputPort("sequence"), owner)
        wrench_output = conditioner.GetOutputPort("wrench")
    elif sensor.bandwidth_hz > 0:
        wrench_filter = add_named(builder, "wrench_filter", LowPassFilter(6, sensor.bandwidth_hz, period), suffix)
        guarded_connect(builder, wrench_output, wrench_filter.get_input_port(0), owner)
        wrench_output = wrench_filter.get_output_port(0)
    return wrench_output, conditioner, wrench_filter


def wrench_lag(sensor: SensorConfig, plant: MultibodyPlant, control_period: Optional[float]) -> float:
    """How late the wrench reaches the law (s), which splits it where it was exerted (the controller's
    ``wrench_lag``): the low-pass of ``sensor`` (``systems.low_pass_filter.low_pass_lag``), plus, for the
    contact sensor on a discrete plant's sampled results, their one step of age
    (``systems.contact_wrench_sensor.sampled_reading_age``; the wrist sensor's reaction force is read as current,
    as a real sensor's)."""
    instance(sensor, "sensor", "wrench_lag", (ContactSensorConfig, WristSensorConfig))
    instance(plant, "plant", "wrench_lag", MultibodyPlant)
    age = sampled_reading_age(plant) if isinstance(sensor, ContactSensorConfig) else 0.0
    return low_pass_lag(sensor.bandwidth_hz, control_period) + age


def add_sensing(builder: DiagramBuilder, plant: MultibodyPlant, robot: RobotModel, sensor: Optional[SensorConfig],
                control_period: Optional[float], sensor_faults: Optional[SensorFaultConfig] = None,
                tare: bool = False) -> Sensing:
    """The wrench sensor (``add_wrench_sensor``), a SensorFaultInjector when ``sensor_faults`` is active,
    and the wrench path (``add_wrench_path``): the wrench a controller reads (``station.loop`` connects
    it). Returns (sensor, its own output, the output the controller reads, injector, conditioner, filter)."""
    owner = "add_sensing"
    check_station_parts(builder, plant, robot, owner)
    sensor = check_sensor_config(sensor if sensor is not None else ContactSensorConfig(), owner)
    instance(sensor_faults, "sensor_faults", owner, SensorFaultConfig, allow_none=True)
    return sensing_of_checked(builder, plant, robot, sensor, control_period, sensor_faults, tare, owner)


def sensing_of_checked(builder: DiagramBuilder, plant: MultibodyPlant, robot: RobotModel, sensor: SensorConfig,
                       control_period: Optional[float], sensor_faults: Optional[SensorFaultConfig], tare: bool,
                       owner: str) -> Sensing:
    """``add_sensing`` of arguments already checked (by ``add_sensing`` or ``station.loop.add_hybrid_controller``,
    naming ``owner``)."""
    arm = arm_model_name(plant, robot)
    wrench_sensor = _add_wrench_sensor(builder, plant, robot, sensor, owner)
    true_wrench = wrench_output = wrench_sensor.get_output_port(0)
    injector = None
    if sensor_faults is not None and sensor_faults.active():
        injector = add_named(builder, "sensor_faults", SensorFaultInjector(sensor_faults, control_period), arm)
        guarded_connect(builder, wrench_output, injector.GetInputPort("wrench"), owner)
        wrench_output = injector.GetOutputPort("faulty_wrench")
    wrench_output, conditioner, wrench_filter = _add_wrench_path(
        builder, wrench_output, sensor, control_period, injector.GetOutputPort("sequence") if injector is not None
        else None, tare, arm, owner)
    return wrench_sensor, true_wrench, wrench_output, injector, conditioner, wrench_filter


def check_sensor_config(sensor: SensorConfig, owner: str) -> SensorConfig:
    """``sensor`` (a ContactSensorConfig or WristSensorConfig) with its fields checked, naming ``owner``."""
    instance(sensor, "sensor", owner, (ContactSensorConfig, WristSensorConfig))
    sensor.validate(f"{owner}: sensor.")
    return sensor


PATCH_PERIOD = 0.01           # s between the contact patch's measurements (its pressure integrated in Python)


def add_contact_patch(builder: DiagramBuilder, plant: MultibodyPlant, robot: RobotModel,
                      period: float = PATCH_PERIOD, real_surface: Optional[Surface] = None) -> ContactPatchSensor:
    """A ``systems.contact_patch.ContactPatchSensor`` on ``plant``'s contact results for ``robot``'s pad (its
    centre of pressure, area, pressures and tilt, every ``period`` s), wired to the plant and named
    ``contact_patch`` (with the arm's model name for a second arm). The face of a disc tool
    (``RobotModel.tool``) gives its area fraction; the workpiece's ``real_surface`` (a ``core.surfaces.Surface``:
    where its geometry is, not the controller's model of it) the tilt's reference normal. Not part of the loop:
    ``station.loggers.add_loggers`` logs it (``patch``) when the loop's ``HybridSystems.patch`` holds it."""
    owner = "add_contact_patch"
    check_station_parts(builder, plant, robot, owner)
    tool = robot.tool
    face = math.pi * float(tool.radius) ** 2 if tool is not None and tool.is_disc else None
    sensor = add_named(builder, "contact_patch", ContactPatchSensor(
        plant, robot.pad_geometries, robot.end_effector_frame, robot.end_effector_point, face, period, real_surface),
        arm_model_name(plant, robot))
    guarded_connect(builder, plant.get_contact_results_output_port(), sensor.GetInputPort("contact_results"), owner)
    guarded_connect(builder, plant.get_body_poses_output_port(), sensor.GetInputPort("body_poses"), owner)
    return sensor
