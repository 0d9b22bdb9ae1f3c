"""The controller's side of the diagram on a real arm: the HybridController (unchanged, built as
``scenario.builder`` builds it) fed from LCM messages, its torque sent as Panda torque commands.

``build_controller_station(config, lcm, hardware)`` returns a ``ControllerStation`` whose
``diagram`` is::

    LcmSubscriberSystem(lcmt_panda_status) ──► MessageWatchdog ──estimated_state──────────────┬──► HybridController
    LcmSubscriberSystem(lcmt_force_torque) ──►      │  ──sensor_wrench──► ForceTorqueConditioning ─►[filter]─┘   │
                                                    │  (or torque_external ──► ExternalTorqueWrench)              │
    ProfileSource / the task's source ──desired_*───┼────────────────────────────────────────────► (controller)  │
                                   [with gain_changes: a HybridController per gain set ─► GainSelector ─► actuation]
                                                    └──watchdog_status──► TorqueCommandSafety ◄── DriverGravityCompensation ◄── actuation
                                                                               │ torque
                                                          PandaCommandSender(kTorque) ──► LcmPublisherSystem (forced only)

The command publisher publishes only when the runner asks (``ControllerStation.publish_command``),
and the runner asks only while ``TorqueCommandSafety``'s ``enabled`` output is 1: nothing is sent
before the first valid status. Loggers carry the same names as the directly wired scenario's, so
``experiments.simulation.collect_log`` and ``summarize`` read them unchanged ("state" is the
*measured* state here).
"""

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Dict, List, Optional

import numpy as np
from drake import lcmt_force_torque, lcmt_panda_command, lcmt_panda_status

from pydrake.manipulation import PandaCommandSender, PandaControlMode
from pydrake.systems.framework import DiagramBuilder, TriggerType
from pydrake.systems.lcm import LcmPublisherSystem, LcmSubscriberSystem
from pydrake.systems.primitives import LogVectorOutput

from drake_hybrid.core.errors import ConfigError
from drake_hybrid.hardware.command import DriverGravityCompensation, TorqueCommandSafety
from drake_hybrid.hardware.gain_change import GainSelector, bumpless_integrals
from drake_hybrid.hardware.messages import HardwareConfig
from drake_hybrid.hardware.watchdog import MessageWatchdog
from drake_hybrid.hardware.wrench import ExternalTorqueWrench, ForceTorqueConditioning
from drake_hybrid.scenario.builder import make_controller, prepare_config
from drake_hybrid.station.sensing import add_wrench_path
from drake_hybrid.tasks.config import ScenarioConfig
from drake_hybrid.tasks.plant import build_controller_plant


@dataclass
class ControllerStation:
    """The controller's side and named handles to its parts (``plant`` is the controller's plant:
    ``summarize`` reads the effort limits from it)."""

    config: ScenarioConfig
    hardware: HardwareConfig
    task: object
    diagram: object
    plant: object
    robot: object
    controller: object
    watchdog: object
    safety: object
    command_publisher: object
    source: object
    constraint_space: object
    wrench_filter: Optional[object] = None
    conditioner: Optional[object] = None
    loggers: Dict[str, object] = field(default_factory=dict)
    lcm: object = None
    controllers: List[object] = field(default_factory=list)     # one law per gain set (gain_changes)
    gain_selector: Optional[object] = None
    transfers: List[dict] = field(default_factory=list)          # the bumpless transfers made
    bumpless: bool = True                                        # False: keep the integrals (for comparison)

    def before_tick(self, root_context, tick):
        """Make the bumpless transfer to the law that becomes active at ``tick`` (call before the
        controller advances to it; a no-op without gain changes)."""
        if self.gain_selector is None or tick not in self.gain_selector.change_ticks:
            return
        index = self.gain_selector.change_ticks.index(tick) + 1
        old, new = self.controllers[index - 1], self.controllers[index]
        old_context = old.GetMyContextFromRoot(root_context)
        new_context = new.GetMyMutableContextFromRoot(root_context)
        state = old_context.get_discrete_state(0).CopyToVector()
        xi_slice, e_p_slice = old.integral_state_slices()
        errors = {name: old.GetOutputPort(name).Eval(old_context) for name in ("velocity_error", "force_error")}
        if self.bumpless:
            xi, e_p = bumpless_integrals(old.validated_gains(), new.validated_gains(), state[xi_slice],
                                         state[e_p_slice], errors["force_error"], errors["velocity_error"],
                                         old.mode.integrates_position)
        else:                                          # the naive switch: the old integrals as they are
            xi, e_p = state[xi_slice], state[e_p_slice]
        new_context.SetDiscreteState(0, np.concatenate([xi, e_p, state[e_p_slice.stop:]]))
        self.transfers.append({"tick": tick, "time": tick * float(self.config.control_period), "xi": xi.tolist(),
                               "position_error": e_p.tolist()})

    @property
    def controller_plant(self):
        return self.plant

    def enabled(self, root_context):
        """True once a command may be published (a valid status has arrived)."""
        return self.safety.GetOutputPort("enabled").Eval(self.safety.GetMyContextFromRoot(root_context))[0] > 0.5

    def publish_command(self, root_context, utime=None):
        """Publish the command of this tick if ``enabled``; returns whether it did.

        ``utime`` (int us) stamps the message with another clock than the diagram's: a real
        drake-franka-driver drops commands whose utime is more than --expire_sec from its
        wall clock (epoch us), so ``run_controller(wall_clock_stamps=True)`` passes it."""
        if not self.enabled(root_context):
            return False
        if utime is None:
            self.command_publisher.ForcedPublish(self.command_publisher.GetMyContextFromRoot(root_context))
            return True
        torque = self.safety.GetOutputPort("torque").Eval(self.safety.GetMyContextFromRoot(root_context))
        message = lcmt_panda_command()
        message.utime = int(utime)
        message.num_joint_position = message.num_joint_velocity = 0
        message.num_joint_torque = len(torque)
        message.joint_torque = [float(x) for x in torque]
        message.control_mode_expected = int(PandaControlMode.kTorque)
        self.lcm.Publish(self.hardware.command_channel, message.encode())
        return True

    def stop_reason(self, root_context):
        return self.safety.stop_reason(self.safety.GetMyContextFromRoot(root_context))


def check_hardware_config(config):
    """ConfigError for what the hardware loop does not support (yet)."""
    if not isinstance(config, ScenarioConfig):
        raise TypeError(f"expected a ScenarioConfig, got {type(config).__name__}")
    if not config.control_period > 0:
        raise ConfigError("control_period: a real arm needs a sampled controller (> 0 s, e.g. 0.001), got "
                          f"{config.control_period}")
    if config.supervised:
        raise ConfigError("supervision: the contact supervisor is not wired in the hardware loop yet; start in "
                          "contact (start.in_contact: true) with supervision.enabled: false")
    if config.sensor_faults.active():
        raise ConfigError("sensor_faults: inject faults through the messages in the hardware loop "
                          "(drake_hybrid.hardware.loop.MessageFaultRelay), not with sensor_faults")
    if config.controller != "li-sastry":
        raise ConfigError(f"controller: the hardware loop runs the li-sastry law, got {config.controller!r}")


def prepared(config):
    """(task, mode, constraint space, config with the desired force padded) as build_scenario has them."""
    check_hardware_config(config)
    return prepare_config(config)


def build_controller_station(config, lcm, hardware=None, initial_positions=None, with_loggers=True, gain_changes=()):
    """The controller's side of ``config`` on ``lcm`` (a DrakeLcm). See the module docstring.

    ``gain_changes``: [(time s, HybridGains), ...] in increasing time: a law per gain set, the
    actuation taken from the one active at each tick, switched bumplessly (``gain_change``)."""
    hardware = (hardware or HardwareConfig()).validate()
    task, mode, constraint_space, config = prepared(config)
    period = float(config.control_period)
    plant, robot = build_controller_plant(task, config)
    n = plant.num_velocities()
    use_force_torque = hardware.wrench_source == "force_torque"
    if use_force_torque and robot.tool_weld is None:
        raise ConfigError(f"hardware.wrench_source: task '{task.name}' has no wrist weld for an F/T sensor; use "
                          "'external_torque'")

    builder = DiagramBuilder()
    controller = builder.AddNamedSystem("controller", make_controller(
        config, task, plant, plant, robot, constraint_space, mode, period, True, False, with_loggers,
        plant_time_step=hardware.damping_time_step))
    status_subscriber = builder.AddNamedSystem("status_subscriber", LcmSubscriberSystem.Make(
        hardware.status_channel, lcmt_panda_status, lcm))
    watchdog = builder.AddNamedSystem("watchdog", MessageWatchdog(
        n, period, hardware.max_status_age, hardware.max_force_torque_age, use_force_torque,
        initial_positions=initial_positions, status_type=lcmt_panda_status, force_torque_type=lcmt_force_torque))
    builder.Connect(status_subscriber.get_output_port(), watchdog.get_status_input_port())
    state = watchdog.GetOutputPort("estimated_state")
    if use_force_torque:
        force_torque_subscriber = builder.AddNamedSystem("force_torque_subscriber", LcmSubscriberSystem.Make(
            hardware.force_torque_channel, lcmt_force_torque, lcm))
        builder.Connect(force_torque_subscriber.get_output_port(), watchdog.get_force_torque_input_port())
        wrench = builder.AddNamedSystem("force_torque_conditioning", ForceTorqueConditioning(
            plant, robot.tool_weld, robot.end_effector_frame, robot.end_effector_point, hardware.force_torque_bias))
        builder.Connect(watchdog.GetOutputPort("sensor_wrench"), wrench.GetInputPort("sensor_wrench"))
    else:
        wrench = builder.AddNamedSystem("external_torque_wrench", ExternalTorqueWrench(
            plant, robot.end_effector_frame, robot.end_effector_point))
        builder.Connect(watchdog.GetOutputPort("torque_external"), wrench.GetInputPort("torque_external"))
    builder.Connect(state, wrench.GetInputPort("estimated_state"))
    wrench_output = wrench.GetOutputPort("wrench")
    wrench_output, conditioner, wrench_filter = add_wrench_path(builder, wrench_output, config.sensor, period)
    builder.Connect(wrench_output, controller.get_measured_wrench_input_port())
    builder.Connect(state, controller.get_estimated_state_input_port())

    source = builder.AddNamedSystem("desired", task.make_source(config, plant, robot, constraint_space))
    if source.num_input_ports():
        builder.Connect(state, source.get_input_port(0))
    for name in ("desired_velocity", "desired_acceleration", "desired_force"):
        builder.Connect(source.GetOutputPort(name), controller.GetInputPort(name))

    controllers, selector = [controller], None
    torque = controller.GetOutputPort("actuation")
    if gain_changes:
        times = [float(time) for time, _ in gain_changes]
        if not all(time > 0 and math.isfinite(time) for time in times) or times != sorted(set(times)):
            raise ConfigError(f"gain_changes: times must be positive, finite and increasing, got {times}")
        selector = builder.AddNamedSystem("gain_selector", GainSelector(n, period, [round(t / period) for t in times]))
        builder.Connect(torque, selector.GetInputPort("actuation_0"))
        for index, (_, gains) in enumerate(gain_changes, start=1):
            law = builder.AddNamedSystem(f"controller_{index}", make_controller(
                dataclasses.replace(config, gains=gains), task, plant, plant, robot, constraint_space, mode, period,
                True, False, False, plant_time_step=hardware.damping_time_step))
            builder.Connect(wrench_output, law.get_measured_wrench_input_port())
            builder.Connect(state, law.get_estimated_state_input_port())
            for name in ("desired_velocity", "desired_acceleration", "desired_force"):
                builder.Connect(source.GetOutputPort(name), law.GetInputPort(name))
            builder.Connect(law.GetOutputPort("actuation"), selector.GetInputPort(f"actuation_{index}"))
            controllers.append(law)
        torque = selector.GetOutputPort("actuation")
    actuation = torque
    if hardware.driver_compensates_gravity:
        gravity = builder.AddNamedSystem("driver_gravity", DriverGravityCompensation(plant, -1))
        builder.Connect(torque, gravity.GetInputPort("torque"))
        builder.Connect(state, gravity.GetInputPort("estimated_state"))
        torque = gravity.GetOutputPort("torque")
    limits = (hardware.torque_limits if hardware.torque_limits is not None else
              [plant.get_joint_actuator(i).effort_limit() for i in plant.GetJointActuatorIndices()])
    if len(limits) != n:
        raise ConfigError(f"hardware.torque_limits must have {n} entries (one per joint), got {len(limits)}")
    safety = builder.AddNamedSystem("command_safety", TorqueCommandSafety(
        n, period, limits, hardware.torque_rate_limit, hardware.hold_stiffness, hardware.hold_damping))
    builder.Connect(torque, safety.GetInputPort("torque"))
    builder.Connect(state, safety.GetInputPort("estimated_state"))
    builder.Connect(watchdog.GetOutputPort("watchdog_status"), safety.GetInputPort("watchdog_status"))
    sender = builder.AddNamedSystem("command_sender", PandaCommandSender(n, PandaControlMode.kTorque))
    builder.Connect(safety.GetOutputPort("torque"), sender.get_input_port())
    publisher = builder.AddNamedSystem("command_publisher", LcmPublisherSystem.Make(
        hardware.command_channel, lcmt_panda_command, lcm, use_cpp_serializer=True,
        publish_triggers={TriggerType.kForced}))
    builder.Connect(sender.get_output_port(), publisher.get_input_port())

    loggers = {}
    if with_loggers:
        log_period = config.log_period
        diagnostics = LogVectorOutput(controller.GetOutputPort("diagnostics"), builder, log_period)
        for name, columns in controller.diagnostic_slices().items():
            loggers[name] = (diagnostics, columns)
        loggers["position_error"] = LogVectorOutput(controller.GetOutputPort("position_error"), builder, log_period)
        loggers["actuation"] = LogVectorOutput(actuation, builder, log_period)
        for name in ("desired_velocity", "desired_force"):
            loggers[name] = LogVectorOutput(source.GetOutputPort(name), builder, log_period)
        loggers["state"] = LogVectorOutput(state, builder, log_period)
        loggers["wrench"] = LogVectorOutput(wrench_output, builder, log_period)
        loggers["command"] = LogVectorOutput(safety.GetOutputPort("torque"), builder, log_period)
        loggers["stop"] = LogVectorOutput(safety.GetOutputPort("stop"), builder, log_period)
        loggers["watchdog_status"] = LogVectorOutput(watchdog.GetOutputPort("watchdog_status"), builder, log_period)
    diagram = builder.Build()
    diagram.set_name(f"hardware_controller_{task.name}")
    return ControllerStation(config=config, hardware=hardware, task=task, diagram=diagram, plant=plant, robot=robot,
                             controller=controller, watchdog=watchdog, safety=safety, command_publisher=publisher,
                             source=source, constraint_space=constraint_space, wrench_filter=wrench_filter,
                             conditioner=conditioner, loggers=loggers, lcm=lcm, controllers=controllers,
                             gain_selector=selector)
