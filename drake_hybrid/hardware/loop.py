"""The hardware-in-the-loop run: the controller's side and the simulated robot, each a diagram
with its own Simulator, exchanging only LCM messages over ``memq://`` in one process, advanced
in lock step::

    robot:       publish status_0, F/T_0 (the start)
    controller:  Initialize (takes them), publish u_0 if enabled
    robot:       Initialize (takes u_0)
    for k = 1, 2, ...:
        robot.AdvanceTo(k h - delta/2)      plant steps at (k-1) h with u_{k-1}; publishes status_k, F/T_k at k h - delta
        controller.AdvanceTo(k h + delta/2) ticks at k h - delta with them; the runner publishes u_k

(each stops half a lead away from its events, so round-off in k h never moves an event across a stop)

(delta = SAMPLE_LEAD h). So the controller uses each status in the tick it was sent, and the robot
applies each command at the next plant step, as in the directly wired loop (where the controller
ticks at k h - delta too). ``MessageFaultRelay`` sits between the robot's channels and the
controller's and changes, drops or delays messages for the fault tests.

``run_hardware_loop(config, ...)`` returns a ``HardwareRun``: the controller side's log and
summary (an ``experiments.summary.RunSummary``, as ``simulate``'s), the stop, and the message timing measured
(the simulated delay from a status's timestamp to the tick that used it; the wall-clock time
each phase of a tick took).
"""

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Dict, Optional, Tuple

import numpy as np
from drake import lcmt_force_torque, lcmt_panda_command, lcmt_panda_status

from pydrake.lcm import DrakeLcm
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator

from drake_hybrid.control.sampling import SAMPLE_LEAD
from drake_hybrid.core.hints import Array
from drake_hybrid.experiments.simulation import collect_log, simulate, summarize
from drake_hybrid.experiments.summary import RunSummary
from drake_hybrid.hardware.controller_side import build_controller_station, check_hardware_config
from drake_hybrid.hardware.messages import HardwareConfig, HardwareFault
from drake_hybrid.hardware.robot_side import build_robot_station
from drake_hybrid.hardware.tick import ControllerTick
from drake_hybrid.hardware.watchdog import ARRIVAL, LATENCY
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions, static_torque
from drake_hybrid.station.start import PRIMING_STEPS


def pump(lcm):
    """Deliver every queued message (memq: in this thread, now); returns how many."""
    handled = 0
    while True:
        count = lcm.HandleSubscriptions(0)
        if count <= 0:
            return handled
        handled += count


class MessageFaultRelay:
    """Forwards the robot's status and F/T messages to the controller's channels through
    ``fault(kind, message, time) -> message or None`` (None: dropped); ``kind`` is "status" or
    "force_torque", ``time`` the message's timestamp in s. Messages are decoded and re-encoded,
    so a fault is exactly what a broken driver or sensor would send."""

    def __init__(self, lcm, robot_hardware, controller_hardware, fault):
        self._lcm, self._fault = lcm, fault
        self.forwarded = {"status": 0, "force_torque": 0}
        self.dropped = {"status": 0, "force_torque": 0}
        self._subscriptions = [
            lcm.Subscribe(robot_hardware.status_channel,
                          lambda data: self._relay("status", lcmt_panda_status.decode(data),
                                                   controller_hardware.status_channel)),
            lcm.Subscribe(robot_hardware.force_torque_channel,
                          lambda data: self._relay("force_torque", lcmt_force_torque.decode(data),
                                                   controller_hardware.force_torque_channel))]

    def _relay(self, kind, message, channel):
        stamp = (message.utime if kind == "status" else message.timestamp) * 1e-6
        message = self._fault(kind, message, stamp)
        if message is None:
            self.dropped[kind] += 1
            return
        self.forwarded[kind] += 1
        self._lcm.Publish(channel, message.encode())


@dataclass
class HardwareRun:
    config: object
    log: dict
    summary: RunSummary
    controller: object                        # ControllerStation
    robot: object                             # RobotStation
    controller_context: object
    robot_context: object
    commands_published: int = 0
    first_command_time: Optional[float] = None
    stop: Optional[dict] = None               # {"fault", "time", "reason"}
    timing: Dict[str, object] = field(default_factory=dict)


# (plant state, arm q0, static torque, first wrench reading, controller integrals): ``start_state``'s.
StartState = Tuple[Array, Array, Array, Array, Array]


def start_state(config):
    """What the directly wired scenario starts from: (plant state, arm q0, static torque, first
    wrench reading, controller integrals) -- the same start for the hardware loop."""
    scenario = build_scenario(config, with_loggers=False)
    context = scenario.diagram.CreateDefaultContext()
    set_initial_conditions(scenario, context)
    plant_context = scenario.plant_context(context)
    q0 = scenario.plant.GetPositions(plant_context, scenario.robot.arm)
    held = static_torque(scenario, q0, pressing=config.start.in_contact)
    reading = scenario.sensor.get_output_port(0).Eval(scenario.sensor.GetMyContextFromRoot(context))
    controller_context = scenario.controller.GetMyContextFromRoot(context)
    xi_slice, e_p_slice = scenario.controller.integral_state_slices()
    integrals = controller_context.get_discrete_state(0).CopyToVector()[:e_p_slice.stop]
    return scenario.plant.GetPositionsAndVelocities(plant_context), q0, held, reading, integrals


def simulated_robot_hardware(config, hardware=None):
    """``hardware`` (validated; default HardwareConfig()) for a controller side whose robot is
    ``config``'s simulated discrete plant: the law compensates that plant's implicit joint damping
    (``damping_time_step``: its time step), as the directly wired loop's does."""
    hardware = (hardware or HardwareConfig()).validate()
    return dataclasses.replace(hardware, damping_time_step=float(config.plant.time_step))


def run_hardware_loop(config, hardware=None, duration=None, lcm_url="memq://drake_hybrid_hil", fault=None,
                      robot_hardware=None, connect_robot=True, record=False, sensor_bias=None, gain_changes=(),
                      stepping="direct", timed_every=1):
    """Run ``config`` as controller side + simulated robot over LCM in lock step (module docstring).

    ``fault`` (kind, message, time) -> message or None puts a ``MessageFaultRelay`` between the
    robot's channels (``robot_hardware``, default: the controller's names + "_ROBOT") and the
    controller's. ``connect_robot=False`` runs the controller side alone (no status ever arrives).
    The controller side ticks as it does at real-time rate (``tick.ControllerTick``, ``stepping``
    "direct"; "simulator": advanced by a Simulator, the reference the direct stepping equals;
    ``timed_every``: ControllerTick's, which changes what is timed, never what is computed).
    """
    if not lcm_url.startswith("memq://"):
        raise ValueError(f"run_hardware_loop runs in one process over memq:// only, got {lcm_url!r}")
    check_hardware_config(config)
    hardware = simulated_robot_hardware(config, hardware)
    if fault is not None and robot_hardware is None:
        robot_hardware = dataclasses.replace(hardware, status_channel=hardware.status_channel + "_ROBOT",
                                             force_torque_channel=hardware.force_torque_channel + "_ROBOT")
    robot_hardware = robot_hardware or hardware
    duration = float(config.duration if duration is None else duration)
    lcm = DrakeLcm(lcm_url)
    plant_state, q0, held, reading, integrals = start_state(config)

    controller = build_controller_station(config, lcm, hardware, initial_positions=q0, gain_changes=gain_changes)
    robot = build_robot_station(config, lcm, robot_hardware, sensor_bias=sensor_bias)
    relay = MessageFaultRelay(lcm, robot_hardware, hardware, fault) if fault is not None else None
    bucket, recorded = [], []
    recorders = [lcm.Subscribe(channel, lambda data, channel=channel: bucket.append((channel, data)))
                 for channel in (hardware.status_channel, hardware.force_torque_channel)] if record else []
    wire = []                                              # every command as it went out: (utime s, torques)
    listener = lcm.Subscribe(hardware.command_channel, lambda data: wire.append(
        (lcmt_panda_command.decode(data).utime * 1e-6, list(lcmt_panda_command.decode(data).joint_torque))))
    period = float(controller.config.control_period)

    # The robot at the start, held by its driver with the static torque until the first command.
    robot_context = robot.diagram.CreateDefaultContext()
    plant_context = robot.plant_context(robot_context)
    robot.plant.SetPositionsAndVelocities(plant_context, plant_state)
    driver_context = robot.driver.GetMyMutableContextFromRoot(robot_context)
    gravity = robot.driver.gravity(driver_context) if robot.driver.compensates_gravity else 0.0
    hold_command = held - gravity
    robot.driver.set_hold_command(driver_context, hold_command)
    if robot.plant.time_step() > 0:
        for _ in range(PRIMING_STEPS):                     # as set_initial_conditions primes the direct loop
            robot.plant.ExecuteForcedEvents(plant_context, publish=False)
        robot.plant.SetPositionsAndVelocities(plant_context, plant_state)

    controller_context = controller.diagram.CreateDefaultContext()
    law_context = controller.controller.GetMyMutableContextFromRoot(controller_context)
    law_context.SetDiscreteState(0, np.concatenate([integrals, held]))
    safety_context = controller.safety.GetMyMutableContextFromRoot(controller_context)
    controller.safety.set_initial_command(safety_context, hold_command)
    for part in (controller.wrench_filter, controller.conditioner):
        if part is not None:
            part.set_initial_output(part.GetMyMutableContextFromRoot(controller_context), reading)

    robot_simulator = Simulator(robot.diagram, robot_context)
    ApplySimulatorConfig(config.simulator, robot_simulator)
    tick = ControllerTick(controller, controller_context, stepping, timed_every)
    published, first_command = 0, None
    wall = {"robot": [], "controller": [], "messages": []}
    status_delay = []

    if connect_robot:
        robot.diagram.ForcedPublish(robot_context)
    pump(lcm)
    recorded.append(bucket[:]), bucket.clear()
    tick.initialize()
    if tick.publish():
        published, first_command = 1, 0.0
    pump(lcm)
    robot_simulator.Initialize()
    watchdog_context = controller.watchdog.GetMyContextFromRoot(controller_context)
    steps = int(round(duration / period))
    lead = SAMPLE_LEAD * period       # robot and controller stop half a lead from the events: no round-off misses
    start = time.perf_counter()
    for k in range(1, steps + 1):
        t0 = time.perf_counter()
        if connect_robot:
            robot_simulator.AdvanceTo(k * period - 0.5 * lead)
        t1 = time.perf_counter()
        pump(lcm)
        t2 = time.perf_counter()
        recorded.append(bucket[:]), bucket.clear()
        tick.advance(k)
        if tick.publish():
            published += 1
            first_command = k * period if first_command is None else first_command
        t3 = time.perf_counter()
        pump(lcm)
        t4 = time.perf_counter()
        wall["robot"].append(t1 - t0)
        wall["controller"].append(t3 - t2)
        wall["messages"].append((t2 - t1) + (t4 - t3))
        status_record = watchdog_context.get_discrete_state(0).CopyToVector()
        if status_record[0] > 0 and abs(status_record[ARRIVAL] - (k * period - lead)) < 0.5 * period:
            status_delay.append(status_record[LATENCY])
    elapsed = time.perf_counter() - start

    log = collect_log(controller, controller_context)
    summary = summarize(controller, log, elapsed)
    stop_vector = controller.safety.GetOutputPort("stop").Eval(controller.safety.GetMyContextFromRoot(controller_context))
    stop = None
    if stop_vector[0] > 0:
        stop = {"fault": HardwareFault(int(stop_vector[0])), "time": float(stop_vector[1]),
                "reason": controller.stop_reason(controller_context)}
    percentiles = lambda values: {"p50": float(np.percentile(values, 50)), "p99": float(np.percentile(values, 99)),
                                  "max": float(np.max(values))} if len(values) else None
    timing = {"status_delay_simulated_s": percentiles(status_delay),
              "wall_robot_step_s": percentiles(wall["robot"]), "wall_controller_step_s": percentiles(wall["controller"]),
              "wall_message_delivery_s": percentiles(wall["messages"]), "wall_total_s": elapsed,
              "relay": None if relay is None else {"forwarded": relay.forwarded, "dropped": relay.dropped}}
    del listener, recorders
    tick.close()
    if record:
        timing["recorded"] = recorded
    log["wire_t"] = np.array([stamp for stamp, _ in wire])
    log["wire_command"] = np.array([torque for _, torque in wire]) if wire else np.zeros((0, controller.controller_plant.num_actuators()))
    return HardwareRun(config=controller.config, log=log, summary=summary, controller=controller, robot=robot,
                       controller_context=controller_context, robot_context=robot_context,
                       commands_published=published, first_command_time=first_command, stop=stop, timing=timing)


SCORES = ("max_velocity_error_percent_after_5_time_constants", "max_force_error_percent_after_5_time_constants")


def compare_with_direct(config, hardware=None):
    """Run ``config`` directly wired and through the hardware loop; the figures docs/hardware.md reports: both
    runs' errors after five time constants (%), their differences (percentage points), the largest
    joint and force differences over the run, the measured message delay and the stop (None)."""
    direct = simulate(config)
    run = run_hardware_loop(config, hardware)
    figures = {"task": config.task, "duration": float(config.duration),
               "wrench_source": (hardware or HardwareConfig()).wrench_source,
               "design_time_constant": direct.summary.design_time_constant}
    for score in SCORES:
        name = score.replace("max_", "").replace("_percent_after_5_time_constants", "")
        wired, looped = getattr(direct.summary, score), getattr(run.summary, score)
        figures[f"{name}_direct_percent"] = wired
        figures[f"{name}_hardware_loop_percent"] = looped
        figures[f"{name}_difference_points"] = None if wired is None else abs(looped - wired)
    figures["max_joint_difference_rad"] = float(np.max(np.abs(run.log["q"] - direct.log["q"])))
    figures["max_force_difference_N"] = float(np.max(np.abs(run.log["force"] - direct.log["force"])))
    figures["status_delay_simulated_s"] = run.timing["status_delay_simulated_s"]
    figures["commands_published"] = run.commands_published
    figures["stop"] = None if run.stop is None else run.stop["reason"]
    if getattr(direct.summary, SCORES[0]) is None:
        figures["note"] = (f"the errors are measured after five design time constants "
                           f"({5 * figures['design_time_constant']:.3g} s); this run is shorter")
    return figures, direct, run
