"""The controller's side of the diagram on a real arm: the HybridController (unchanged, built as
``scenario.builder`` builds it) fed from LCM messages, its torque sent as Panda torque commands.

``build_controller_station(config, lcm, hardware)`` returns a ``ControllerStation`` whose
``diagram`` is::

    (input) lcmt_panda_status ──► MessageWatchdog ──estimated_state──────────────────────┬──► HybridController
    (input) lcmt_force_torque ──►      │  ──sensor_wrench──► ForceTorqueConditioning ─►[filter]─┘   │
                                       │  (or torque_external ──► ExternalTorqueWrench)              │
    ProfileSource / the task's source ──desired_*─────────────────────────────────► (controller)    │
                        [with gain_changes: a HybridController per gain set ─► GainSelector ─► actuation]
                                       └─watchdog_status─► TorqueCommandSafety ◄─ DriverGravityCompensation ◄─ computed_actuation
                                                                  │ torque
                                             PandaCommandSender(kTorque) ──► LcmPublisherSystem (forced only)

The watchdog, the law and the command's safety tick together (at k h - SAMPLE_LEAD h): the safety
reads the torque the law computes in that tick (its ``computed_actuation``, which the law's update
stores), so each tick is one event, and its command goes out in the tick.

The messages come in on the diagram's input ports ``lcmt_panda_status`` and (with an F/T sensor)
``lcmt_force_torque``, as decoded ``drake.lcmt_*`` objects: ``hardware.tick.ControllerTick``
subscribes to the channels on ``lcm``, decodes each message once and sets the newest on the ports
(an LcmSubscriberSystem would copy the Python message into its state and again into its output:
three deep copies of a Panda status, 28 us each). The command publisher publishes only when the
runner asks (``ControllerStation.publish_command``), and the runner asks only while
``TorqueCommandSafety``'s ``enabled`` output is 1: nothing is sent before the first valid status.
Loggers carry the same names as the directly wired scenario's, so
``experiments.simulation.collect_log`` and ``summarize`` read them unchanged ("state" is the
*measured* state here).
"""

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple, cast

import numpy as np
from drake import lcmt_force_torque, lcmt_panda_command, lcmt_panda_status
from numpy.typing import ArrayLike

from pydrake.lcm import DrakeLcmInterface
from pydrake.manipulation import PandaCommandSender, PandaControlMode
from pydrake.systems.framework import Context, DiagramBuilder, TriggerType
from pydrake.systems.lcm import LcmPublisherSystem
from pydrake.systems.primitives import LogVectorOutput

from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.gains import HybridGains
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.hints import Array
from drake_hybrid.hardware.command import DriverGravityCompensation, TorqueCommandSafety
from drake_hybrid.hardware.gain_change import GainSelector, bumpless_integrals
from drake_hybrid.hardware.messages import HardwareConfig
from drake_hybrid.hardware.watchdog import MessageWatchdog
from drake_hybrid.hardware.wrench import ExternalTorqueWrench, ForceTorqueConditioning
from drake_hybrid.scenario.builder import PreparedConfig, controller_options, prepare_config
from drake_hybrid.station.handles import HybridSystems
from drake_hybrid.station.loggers import add_loggers
from drake_hybrid.station.loop import connect_hybrid_loop, make_hybrid_controller
from drake_hybrid.station.sensing import add_wrench_path
from drake_hybrid.tasks.config import ScenarioConfig
from drake_hybrid.tasks.plant import build_controller_plant
from drake_hybrid.tasks.task import Task

# The diagram's input ports the messages come in on (decoded drake.lcmt_* objects).
STATUS_INPUT, FORCE_TORQUE_INPUT = "lcmt_panda_status", "lcmt_force_torque"


@dataclass(kw_only=True)
class ControllerStation(HybridSystems):
    """The controller's side: the loop's ``HybridSystems`` (``state`` is the watchdog's measured state,
    ``plant`` None: the arm is real) and what a real arm's loop adds: the ``config``, the ``hardware``
    settings, the ``task``, the ``watchdog``, the command's ``safety`` and ``command_publisher``, the
    ``lcm``; with gain changes one law per gain set (``controllers``), the ``gain_selector`` and the
    bumpless ``transfers`` made."""

    config: ScenarioConfig
    hardware: HardwareConfig
    task: Task
    watchdog: MessageWatchdog
    safety: TorqueCommandSafety
    command_publisher: LcmPublisherSystem
    lcm: Optional[DrakeLcmInterface] = None
    controllers: List[HybridController] = field(default_factory=list)     # one law per gain set (gain_changes)
    gain_selector: Optional[GainSelector] = None
    transfers: List[Dict[str, Any]] = field(default_factory=list)        # the bumpless transfers made
    bumpless: bool = True                                        # False: keep the integrals (for comparison)

    def changes_gains_at(self, tick: int) -> bool:
        """Whether another law becomes active at ``tick`` (a gain change)."""
        return self.gain_selector is not None and tick in self.gain_selector.change_ticks

    def before_tick(self, root_context: Context, tick: int) -> None:
        """Make the bumpless transfer to the law that becomes active at ``tick`` (call before the
        controller advances to it; a no-op without gain changes)."""
        if not self.changes_gains_at(tick):
            return
        assert self.gain_selector is not None
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

    def enabled(self, root_context: Context) -> bool:
        """True once a command may be published (a valid status has arrived)."""
        safety_context = self.safety.GetMyContextFromRoot(root_context)
        enabled = cast(Array, self.safety.get_enabled_output_port().Eval(safety_context))
        return enabled[0] > 0.5

    def publish_command(self, root_context: Context, utime: Optional[int] = None,
                        enabled: Optional[bool] = None) -> bool:
        """Publish the command of this tick if ``enabled``; returns whether it did.

        ``utime`` (int us) stamps the message with another clock than the diagram's: a real
        drake-franka-driver drops commands whose utime is more than --expire_sec from its
        wall clock (epoch us), so ``run_controller(wall_clock_stamps=True)`` passes it.
        ``enabled``: ``self.enabled`` as already evaluated in this tick (None: evaluated here)."""
        if not (self.enabled(root_context) if enabled is None else enabled):
            return False
        if utime is None:
            self.command_publisher.ForcedPublish(self.command_publisher.GetMyContextFromRoot(root_context))
            return True
        torque = cast(Array, self.safety.GetOutputPort("torque").Eval(self.safety.GetMyContextFromRoot(root_context)))
        message = lcmt_panda_command()
        message.utime = int(utime)
        message.num_joint_position = message.num_joint_velocity = 0
        message.num_joint_torque = len(torque)
        message.joint_torque = [float(x) for x in torque]
        message.control_mode_expected = int(PandaControlMode.kTorque)
        assert self.lcm is not None                 # build_controller_station gives the station its lcm
        self.lcm.Publish(self.hardware.command_channel, message.encode())
        return True

    def stop_reason(self, root_context: Context) -> Optional[str]:
        return self.safety.stop_reason(self.safety.GetMyContextFromRoot(root_context))


def check_hardware_config(config: ScenarioConfig) -> None:
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


def prepared(config: ScenarioConfig) -> PreparedConfig:
    """The config validated once (``scenario.builder.prepare_config``) for the hardware loop."""
    check_hardware_config(config)
    return prepare_config(config)


def build_controller_station(config: ScenarioConfig, lcm: DrakeLcmInterface, hardware: Optional[HardwareConfig] = None,
                             initial_positions: Optional[ArrayLike] = None, with_loggers: bool = True,
                             gain_changes: Sequence[Tuple[float, HybridGains]] = ()) -> "ControllerStation":
    """The controller's side of ``config`` on ``lcm`` (a DrakeLcm). See the module docstring.

    ``gain_changes``: [(time s, HybridGains), ...] in increasing time: a law per gain set, the
    actuation taken from the one active at each tick, switched bumplessly (``gain_change``)."""
    hardware = (hardware or HardwareConfig()).validate()
    ready = prepared(config)
    task, space, config = ready.task, ready.constraint_space, ready.config
    period = float(config.control_period)
    plant, robot = build_controller_plant(task, config)
    n = plant.num_velocities()
    use_force_torque = hardware.wrench_source == "force_torque"
    if use_force_torque and robot.tool_weld is None:
        raise ConfigError(f"hardware.wrench_source: task '{task.name}' has no wrist weld for an F/T sensor; use "
                          "'external_torque'")
    # Each gain set validated here, once, against the task's sizes and the rate (as prepare_config the first).
    gain_sets = [ready]
    if gain_changes:
        times = [float(time) for time, _ in gain_changes]
        if not all(time > 0 and math.isfinite(time) for time in times) or times != sorted(set(times)):
            raise ConfigError(f"gain_changes: times must be positive, finite and increasing, got {times}")
        gain_sets += [dataclasses.replace(ready, config=dataclasses.replace(config, gains=gains), gains=gains.matrices(
            space.velocity_size, space.force_size, ready.mode, period)) for _, gains in gain_changes]
    limits = (hardware.torque_limits if hardware.torque_limits is not None else
              [plant.get_joint_actuator(i).effort_limit() for i in plant.GetJointActuatorIndices()])
    if len(limits) != n:
        raise ConfigError(f"hardware.torque_limits must have {n} entries (one per joint), got {len(limits)}")

    builder = DiagramBuilder()
    # The arm's messages (the diagram's inputs): its state and the wrench the law reads.
    watchdog = MessageWatchdog(n, period, hardware.max_status_age, hardware.max_force_torque_age, use_force_torque,
                               initial_positions=initial_positions, status_type=lcmt_panda_status,
                               force_torque_type=lcmt_force_torque)
    builder.AddNamedSystem("watchdog", watchdog)
    builder.ExportInput(watchdog.get_status_input_port(), STATUS_INPUT)
    state = watchdog.GetOutputPort("estimated_state")
    if use_force_torque:
        builder.ExportInput(watchdog.get_force_torque_input_port(), FORCE_TORQUE_INPUT)
        wrench = builder.AddNamedSystem("force_torque_conditioning", ForceTorqueConditioning(
            plant, robot.tool_weld, robot.end_effector_frame, robot.end_effector_point, hardware.force_torque_bias))
        builder.Connect(watchdog.GetOutputPort("sensor_wrench"), wrench.GetInputPort("sensor_wrench"))
    else:
        wrench = builder.AddNamedSystem("external_torque_wrench", ExternalTorqueWrench(
            plant, robot.end_effector_frame, robot.end_effector_point))
        builder.Connect(watchdog.GetOutputPort("torque_external"), wrench.GetInputPort("torque_external"))
    builder.Connect(state, wrench.GetInputPort("estimated_state"))
    wrench_output, conditioner, wrench_filter = add_wrench_path(builder, wrench.GetOutputPort("wrench"), config.sensor,
                                                                period)
    source = builder.AddNamedSystem("desired", task.make_source(config, plant, robot, space))

    # The command's way to the arm: [gain selector] -> [the driver's gravity] -> limits and stops -> LCM.
    safety = TorqueCommandSafety(n, period, limits, hardware.torque_rate_limit, hardware.hold_stiffness,
                                 hardware.hold_damping)
    builder.AddNamedSystem("command_safety", safety)
    builder.Connect(state, safety.GetInputPort("estimated_state"))
    builder.Connect(watchdog.GetOutputPort("watchdog_status"), safety.GetInputPort("watchdog_status"))
    command = safety.GetInputPort("torque")
    if hardware.driver_compensates_gravity:
        gravity = builder.AddNamedSystem("driver_gravity", DriverGravityCompensation(plant, -1))
        builder.Connect(state, gravity.GetInputPort("estimated_state"))
        builder.Connect(gravity.GetOutputPort("torque"), command)
        command = gravity.GetInputPort("torque")
    selector = held_selector = None
    if gain_changes:
        change_ticks = [round(t / period) for t in times]
        selector = GainSelector(n, period, change_ticks)
        builder.AddNamedSystem("gain_selector", selector)
        builder.Connect(selector.GetOutputPort("actuation"), command)
        if with_loggers:           # the held torque of the active law, for the "actuation" log
            held_selector = builder.AddNamedSystem("held_gain_selector", GainSelector(n, period, change_ticks))
    sender = builder.AddNamedSystem("command_sender", PandaCommandSender(n, PandaControlMode.kTorque))
    builder.Connect(safety.GetOutputPort("torque"), sender.get_input_port())
    publisher = LcmPublisherSystem.Make(hardware.command_channel, lcmt_panda_command, lcm, use_cpp_serializer=True,
                                        publish_triggers={TriggerType.kForced})
    builder.AddNamedSystem("command_publisher", publisher)
    builder.Connect(sender.get_output_port(), publisher.get_input_port())

    # The law (one per gain set), each closed by the loop's one wiring.
    controllers = []
    for index, gain_set in enumerate(gain_sets):
        options = controller_options(gain_set, plant, plant, robot, period, with_loggers and index == 0)
        law = builder.AddNamedSystem("controller" if index == 0 else f"controller_{index}", make_hybrid_controller(
            plant, robot, space, sensor=config.sensor, plant=None, control_period=period,
            plant_time_step=hardware.damping_time_step, **options))
        # The command's safety ticks with the law and acts on the torque the law computes in that tick.
        connect_hybrid_loop(builder, law, state=state, wrench=wrench_output, source=source,
                            actuation=selector.GetInputPort(f"actuation_{index}") if selector is not None else command,
                            owner="build_controller_station", actuation_output="computed_actuation",
                            held_actuation=(held_selector.GetInputPort(f"actuation_{index}")
                                            if held_selector is not None else None))
        controllers.append(law)
    station = ControllerStation(
        config=config, hardware=hardware, task=task, robot=robot, controller_plant=plant, constraint_space=space,
        controller=controllers[0], state=state, wrench_output=wrench_output,
        actuation=(held_selector.GetOutputPort("actuation") if held_selector is not None
                   else controllers[0].GetOutputPort("actuation")),
        source=source, wrench_filter=wrench_filter, conditioner=conditioner, watchdog=watchdog, safety=safety,
        command_publisher=publisher, lcm=lcm, controllers=controllers, gain_selector=selector)
    if with_loggers:
        loggers = add_loggers(builder, station, config.log_period)
        loggers["command"] = LogVectorOutput(safety.GetOutputPort("torque"), builder, config.log_period)
        loggers["stop"] = LogVectorOutput(safety.GetOutputPort("stop"), builder, config.log_period)
        loggers["watchdog_status"] = LogVectorOutput(watchdog.GetOutputPort("watchdog_status"), builder,
                                                     config.log_period)
        station.loggers.update(loggers)
    station.diagram = builder.Build()
    station.diagram.set_name(f"hardware_controller_{task.name}")
    return station
