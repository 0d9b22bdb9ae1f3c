"""The robot's side for testing: the simulated plant behind the same messages a real Panda's
driver (drake-franka-driver, torque mode) and an F/T sensor would exchange.

``build_robot_station(config, lcm, hardware)`` returns a ``RobotStation`` whose ``diagram`` is::

    LcmSubscriberSystem(lcmt_panda_command) ──► PandaCommandReceiver(kTorque) ──► SimulatedDriver ──► plant
    plant ──q, v, tau_contact──► PandaStatusSender ──► LcmPublisherSystem(PANDA_STATUS)      (period h)
    plant ──weld reaction──► ForceTorqueMessage ──► LcmPublisherSystem(FT_SENSOR)             (period h)

The publishers send at k h - SAMPLE_LEAD h (``control.sampling.tick_offset``): the state a
directly wired controller would read at its tick. ``SimulatedDriver`` is the driver's stand-in: it
holds ``hold_command`` until the first command arrives and adds g(q) (its own arm model) as the
Franka driver does. The plant, its environment and its model error are exactly the directly wired
scenario's (``tasks.plant.build_plant``).
"""

from dataclasses import dataclass, field
from typing import Dict

import numpy as np
from drake import lcmt_force_torque, lcmt_panda_command, lcmt_panda_status

from pydrake.common.cpp_param import List
from pydrake.common.value import AbstractValue, Value
from pydrake.manipulation import PandaCommandReceiver, PandaControlMode, PandaStatusSender
from pydrake.multibody.math import SpatialForce
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem
from pydrake.systems.lcm import LcmPublisherSystem, LcmSubscriberSystem
from pydrake.systems.primitives import Demultiplexer, LogVectorOutput

from drake_hybrid.control.sampling import tick_offset
from drake_hybrid.core.kinematics import declare_plant_context_cache
from drake_hybrid.hardware.controller_side import prepared
from drake_hybrid.hardware.messages import HardwareConfig, microseconds
from drake_hybrid.systems.faults import JointFriction
from drake_hybrid.systems.wrist_force_torque_sensor import reaction_force_slot
from drake_hybrid.tasks.plant import build_controller_plant, build_plant


@dataclass
class RobotStation:
    """The simulated robot's side and named handles to its parts."""

    config: object
    hardware: HardwareConfig
    task: object
    diagram: object
    plant: object
    scene_graph: object
    robot: object
    driver: object
    force_torque: object
    loggers: Dict[str, object] = field(default_factory=dict)

    def plant_context(self, root_context):
        return self.plant.GetMyMutableContextFromRoot(root_context)


class ForceTorqueMessage(LeafSystem):
    """An lcmt_force_torque from the reaction force of the weld between wrist and tool.

    .. pydrake_system::

        name: ForceTorqueMessage
        input_ports:
        - reaction_forces
        output_ports:
        - lcmt_force_torque

    The reading is the wrench the tool exerts on the wrist, at the weld's child frame S, in S
    (minus the plant's reaction on the tool, F_CJc_Jc), plus ``bias`` ([t; f]); timestamped with
    the simulation time in microseconds.
    """

    def __init__(self, plant, weld_joint, bias=None):
        LeafSystem.__init__(self)
        self._joint_index = reaction_force_slot(plant, weld_joint)
        self.bias = np.zeros(6) if bias is None else np.asarray(bias, dtype=float)
        self.DeclareAbstractInputPort("reaction_forces", Value[List[SpatialForce]]([]))
        self.DeclareAbstractOutputPort("lcmt_force_torque", lambda: AbstractValue.Make(lcmt_force_torque()),
                                       self._calc)

    def reading(self, context):
        """[t; f] in the sensor frame, bias included."""
        reaction = self.get_input_port(0).Eval(context)[self._joint_index]
        return -reaction.get_coeffs() + self.bias

    def _calc(self, context, output):
        message = lcmt_force_torque()
        message.timestamp = microseconds(context.get_time())
        message.tx, message.ty, message.tz, message.fx, message.fy, message.fz = self.reading(context).tolist()
        output.set_value(message)


class SimulatedDriver(LeafSystem):
    """The driver's stand-in: actuation = (commanded torque, or ``hold_command`` before the first
    command) + g(q) when the driver compensates gravity.

    .. pydrake_system::

        name: SimulatedDriver
        input_ports:
        - torque
        - lcmt_panda_command
        - estimated_state
        output_ports:
        - actuation
    """

    def __init__(self, arm_plant, compensates_gravity=True):
        LeafSystem.__init__(self)
        self._plant = arm_plant
        n = arm_plant.num_velocities()
        self.compensates_gravity = bool(compensates_gravity)
        self._torque_port = self.DeclareVectorInputPort("torque", n)
        self._command_port = self.DeclareAbstractInputPort("lcmt_panda_command", AbstractValue.Make(lcmt_panda_command()))
        self._state_port = self.DeclareVectorInputPort("estimated_state", 2 * n)
        self._context_cache = declare_plant_context_cache(self, arm_plant, self._state_port)
        self._hold = self.DeclareNumericParameter(BasicVector(np.zeros(n)))
        self.DeclareVectorOutputPort("actuation", n, self._calc)

    def set_hold_command(self, context, command):
        context.get_mutable_numeric_parameter(self._hold).SetFromVector(command)

    def commanded(self, context):
        return self._command_port.Eval(context).num_joint_torque > 0

    def gravity(self, context):
        return -self._plant.CalcGravityGeneralizedForces(self._context_cache.Eval(context))

    def _calc(self, context, output):
        torque = (self._torque_port.Eval(context) if self.commanded(context)
                  else context.get_numeric_parameter(self._hold).CopyToVector())
        output.SetFromVector(torque + (self.gravity(context) if self.compensates_gravity else 0.0))


def build_robot_station(config, lcm, hardware=None, sensor_bias=None):
    """The simulated robot of ``config`` behind LCM messages on ``lcm``. See the module docstring.
    ``sensor_bias`` ([t; f], sensor frame) is added to every F/T reading (a real sensor's offset)."""
    hardware = (hardware or HardwareConfig()).validate()
    ready = prepared(config)
    task, config = ready.task, ready.config
    period = float(config.control_period)
    builder = DiagramBuilder()
    plant, scene_graph, robot = build_plant(task, config, builder)
    arm_plant, _ = build_controller_plant(task, config)
    n = arm_plant.num_velocities()
    arm_state = plant.get_state_output_port(robot.arm)
    joints = builder.AddNamedSystem("joints", Demultiplexer([n, n]))
    builder.Connect(arm_state, joints.get_input_port(0))

    command_subscriber = builder.AddNamedSystem("command_subscriber", LcmSubscriberSystem.Make(
        hardware.command_channel, lcmt_panda_command, lcm, use_cpp_serializer=True))
    command_message = builder.AddNamedSystem("command_message", LcmSubscriberSystem.Make(
        hardware.command_channel, lcmt_panda_command, lcm))
    receiver = builder.AddNamedSystem("command_receiver", PandaCommandReceiver(n, PandaControlMode.kTorque))
    builder.Connect(command_subscriber.get_output_port(), receiver.get_message_input_port())
    builder.Connect(joints.get_output_port(0), receiver.get_position_measured_input_port())
    driver = builder.AddNamedSystem("driver", SimulatedDriver(arm_plant, hardware.driver_compensates_gravity))
    builder.Connect(receiver.get_commanded_torque_output_port(), driver.GetInputPort("torque"))
    builder.Connect(command_message.get_output_port(), driver.GetInputPort("lcmt_panda_command"))
    builder.Connect(arm_state, driver.GetInputPort("estimated_state"))
    builder.Connect(driver.GetOutputPort("actuation"), plant.get_actuation_input_port(robot.arm))

    status = builder.AddNamedSystem("status_sender", PandaStatusSender(n))
    builder.Connect(joints.get_output_port(0), status.GetInputPort("position_measured"))
    builder.Connect(joints.get_output_port(1), status.GetInputPort("velocity_measured"))
    builder.Connect(receiver.get_commanded_torque_output_port(), status.GetInputPort("torque_commanded"))
    builder.Connect(driver.GetOutputPort("actuation"), status.GetInputPort("torque_measured"))
    builder.Connect(plant.get_generalized_contact_forces_output_port(robot.arm), status.GetInputPort("torque_external"))
    for name in ("position_commanded", "velocity_commanded", "acceleration_commanded"):
        source = joints.get_output_port(0) if name == "position_commanded" else joints.get_output_port(1)
        builder.Connect(source, status.GetInputPort(name))
    offset = tick_offset(period)
    status_publisher = builder.AddNamedSystem("status_publisher", LcmPublisherSystem.Make(
        hardware.status_channel, lcmt_panda_status, lcm, period, use_cpp_serializer=True, publish_offset=offset))
    builder.Connect(status.get_output_port(), status_publisher.get_input_port())

    force_torque = None
    if robot.tool_weld is not None:
        force_torque = builder.AddNamedSystem("force_torque", ForceTorqueMessage(plant, robot.tool_weld, sensor_bias))
        builder.Connect(plant.get_reaction_forces_output_port(), force_torque.get_input_port(0))
        force_torque_publisher = builder.AddNamedSystem("force_torque_publisher", LcmPublisherSystem.Make(
            hardware.force_torque_channel, lcmt_force_torque, lcm, period, publish_offset=offset))
        builder.Connect(force_torque.get_output_port(0), force_torque_publisher.get_input_port())

    if config.model_error.joint_friction > 0:
        friction = builder.AddNamedSystem("joint_friction", JointFriction(
            plant, robot.arm, config.model_error.joint_friction, config.model_error.friction_speed))
        builder.Connect(arm_state, friction.get_input_port(0))
        builder.Connect(friction.get_output_port(0), plant.get_applied_generalized_force_input_port())
    task.connect_environment(builder, plant, config)
    loggers = {"true_state": LogVectorOutput(arm_state, builder, config.log_period),
               "applied_actuation": LogVectorOutput(driver.GetOutputPort("actuation"), builder, config.log_period)}
    diagram = builder.Build()
    diagram.set_name(f"hardware_robot_{task.name}")
    return RobotStation(config=config, hardware=hardware, task=task, diagram=diagram, plant=plant,
                        scene_graph=scene_graph, robot=robot, driver=driver, force_torque=force_torque,
                        loggers=loggers)
