"""Per task: simulation speed, accuracy per mode, linearization time, and the task's own controller tick.

Every task in ``drake_hybrid.tasks.registry.TASKS`` is measured, so tasks added later
are included without touching this file.

* **Simulation speed.** ``rtf`` is the real-time factor (simulated / wall
  seconds of ``Simulator.AdvanceTo``, after ``Initialize``) of the task's 1 kHz
  closed loop as users run it: ``drake_hybrid.experiments.simulation.simulate`` with the
  task's default config (discrete SAP plant with hydroelastic contact, sampled
  controller, wrench sensor, desired-motion source, loggers). ``plant_rtf`` is
  the same plant and contact (``scenarios.build_plant`` with the same config)
  simulated alone from the same start, replaying the closed loop's logged
  torques through a C++ ``TrajectorySource`` (zero-order hold): the plant does
  the same work along the same motion and contact, with no controller, sensor,
  source or logger (``replay_drift`` is how far the replayed joint positions
  end from the closed loop's, max |q| difference in rad). The SAP step costs
  far more while pressing and sliding than in free motion, so this is the only
  plant-alone baseline that does the closed loop's plant work. For reference:
  ``plant_rtf_static_torque`` holds the start's static torque (gravity plus
  the desired push, ``scenarios.static_torque``: pressing at rest), and
  ``plant_rtf_zero_torque`` applies none (the arm falls away and loses
  contact, so its steps are cheap). ``rtf_ratio = rtf / plant_rtf``; medians
  of the repeats, run alternately.
* **Accuracy** (one simulation per mode, the task's default duration): final
  velocity and force errors in % of the command (``summary.json`` fields), the
  largest after five design time constants, constraint residual (max and
  final |C|), and the eigenvalue deviation from the design in % (the largest
  relative distance of a designed eigenvalue from its matched closed-loop one,
  ``analysis.linearize_continuous``).
* **Linearization**: wall time of Drake's ``Linearize`` on the continuous
  closed loop, and of the whole ``linearize_continuous`` (build, equilibrium,
  Linearize, eigenvalues).
* **Task tick**: the task's own continuous controller at the start, with the
  inputs the scenario feeds it there, against the InverseDynamicsController on
  the same controller plant (as in tick.py).
"""

import statistics
import time

import numpy as np
from robots import BenchmarkRobot
from tick import hybrid_evaluation, interleaved, inverse_dynamics_evaluation

from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from drake_hybrid.analysis.discrete_linearization import linearize_discrete
from drake_hybrid.analysis.linearization import linearize_continuous
from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.experiments.simulation import simulate
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions, static_torque
from drake_hybrid.tasks.plant import build_plant
from drake_hybrid.tasks.registry import TASKS, get_task

MODES = [mode.value for mode in ControlMode]


def plant_alone_rtf(config, torque="static", log=None, clock=time.perf_counter):
    """Real-time factor of the task's plant alone from the task's start.

    torque: "replay" (the torques of ``log``, a closed-loop run's log, through a
    zero-order hold), "static" (gravity + the desired push at the start, held)
    or "zero". ``clock``: wall time (default) or ``time.process_time`` (this process's CPU
    time, what a loaded shared machine distorts least). Returns (rtf, hydroelastic contacts at
    the end, max |q - q_log| at the end for "replay" else None)."""
    task = get_task(config.task)
    scenario = build_scenario(config, with_loggers=False)
    q0 = task.start_positions(scenario)
    builder = DiagramBuilder()
    plant, _, robot = build_plant(task, config, builder)
    if torque == "replay":
        times, first = np.unique(log["t"], return_index=True)
        source = builder.AddSystem(TrajectorySource(PiecewisePolynomial.ZeroOrderHold(times, log["torque"][first].T)))
        builder.Connect(source.get_output_port(), plant.get_actuation_input_port(robot.arm))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, robot.arm, q0)
    if torque != "replay":
        held = static_torque(scenario, q0) if torque == "static" else np.zeros(len(q0))
        plant.get_actuation_input_port(robot.arm).FixValue(plant_context, held)
    simulator.Initialize()
    start = clock()
    simulator.AdvanceTo(float(config.duration))
    wall = clock() - start
    contacts = plant.get_contact_results_output_port().Eval(plant_context).num_hydroelastic_contacts()
    drift = None
    if torque == "replay":
        drift = float(np.max(np.abs(plant.GetPositions(plant_context, robot.arm) - log["q"][-1])))
    return float(config.duration) / wall, int(contacts), drift


def closed_loop_cpu_rtf(config):
    """The closed loop's real-time factor by this process's CPU time (``simulate``'s diagram, loggers
    included, timed over ``AdvanceTo`` after ``Initialize``): on a shared machine the wall clock
    counts the other jobs' time too, the CPU time mostly not."""
    scenario = build_scenario(config)
    simulator = Simulator(scenario.diagram)
    context = simulator.get_mutable_context()
    set_initial_conditions(scenario, context)
    simulator.Initialize()
    start = time.process_time()
    simulator.AdvanceTo(float(config.duration))
    return float(config.duration) / (time.process_time() - start)


def _accuracy(summary, final_constraint):
    return {
        "final_velocity_error_percent": summary.final_velocity_error_percent,
        "final_force_error_percent": summary.final_force_error_percent,
        "max_velocity_error_percent_after_5_time_constants":
            summary.max_velocity_error_percent_after_5_time_constants,
        "max_force_error_percent_after_5_time_constants": summary.max_force_error_percent_after_5_time_constants,
        "max_constraint_residual": summary.max_constraint_residual,
        "final_constraint_residual": final_constraint,
    }


def _linearization(config):
    """The continuous closed loop's linearization, or for a task whose plant exists only in discrete
    time (the crank's SAP weld) the sampled loop's one-period map (``analysis.linearize_discrete``,
    after 0.5 s at rest so the weld's force settles, as in tutorial 2)."""
    start = time.perf_counter()
    discrete = not TASKS[config.task].continuous_plant
    result = linearize_discrete(config, settle_time=0.5) if discrete else linearize_continuous(config)
    total = time.perf_counter() - start
    match = result.match
    designed = len(result.predicted.designed)
    deviation = 100.0 * float(np.max(match.relative_error[:designed]))
    return {
        "linearization": "discrete map" if discrete else "continuous",
        "eigenvalue_deviation_percent": deviation,
        "eigenvalues_matched_within_5_percent": bool(match.matched),
        "unstable_extra_modes": [[float(v.real), float(v.imag)] for v in match.unstable_extra],
        "equilibrium_residual": result.equilibrium_residual,
        "linearize_wall_s": result.wall_time,
        "linearize_total_wall_s": total,
        "states": int(result.A.shape[0]),
    }


def task_tick(config, samples, rng):
    """The task's continuous controller at its start, with the inputs the scenario gives it there."""
    scenario = build_scenario(config, with_loggers=False)
    context = scenario.diagram.CreateDefaultContext()
    set_initial_conditions(scenario, context)
    sampled = scenario.controller
    controller_context = sampled.GetMyContextFromRoot(context)
    inputs = {sampled.get_input_port(i).get_name(): sampled.get_input_port(i).Eval(controller_context).copy()
              for i in range(sampled.num_input_ports())}
    controller = HybridController(scenario.controller_plant, scenario.robot.end_effector_frame,
                                  scenario.robot.end_effector_point, scenario.constraint_space, gains=config.gains,
                                  mode=config.mode)
    robot = BenchmarkRobot(name=config.task, description=scenario.task.description, plant=scenario.controller_plant,
                           controller=controller, state=inputs["estimated_state"], inputs=inputs)
    ours, idc = interleaved([hybrid_evaluation(robot, rng), inverse_dynamics_evaluation(robot, rng)], samples,
                            samples // 10)
    return {"joints": robot.joints, "task_size": controller.task_size, "force_rows": controller.force_size,
            "controller_tick_us": ours.median_us,
            "controller_tick_p95_us": ours.p95_us, "idc_tick_us": idc.median_us,
            "tick_ratio": ours.median_us / idc.median_us}


def measure_task(name, repeats=3, modes=MODES, tick_samples=2000, log=print):
    """All figures of one task (see the module docstring)."""
    task = TASKS[name]
    default = task.default_config()
    rng = np.random.default_rng(0)
    result = {"description": task.description, "duration_s": float(default.duration),
              "time_step_s": float(default.plant.time_step), "control_period_s": float(default.control_period),
              "default_mode": default.mode, "modes": {}}
    closed, replay, static, zero = [], [], [], []
    default_log = None
    for mode in modes:
        config = default.replace(mode=mode)
        entry = {}
        try:
            run = simulate(config)
            entry.update(_accuracy(run.summary, float(np.max(np.abs(run.log["constraint"][-1])))))
            entry["rtf"] = run.summary.real_time_factor
            if mode == default.mode:
                closed.append(entry["rtf"])
                default_log = run.log
        except Exception as error:                                   # reported, not hidden
            entry["simulation_error"] = f"{type(error).__name__}: {error}"
        try:
            entry.update(_linearization(config))
        except Exception as error:
            entry["linearization_error"] = f"{type(error).__name__}: {error}"
        result["modes"][mode] = entry
        log(f"  {name} {mode}: " + ", ".join(f"{k}={v:.4g}" for k, v in entry.items() if isinstance(v, float)))
    if default_log is None:
        default_log = simulate(default).log
    drift = contacts_end = None
    closed_cpu, replay_cpu = [], []
    for _ in range(repeats):
        rtf, contacts_end, drift = plant_alone_rtf(default, "replay", default_log)
        replay.append(rtf)
        if len(closed) < repeats:
            closed.append(simulate(default).summary.real_time_factor)
        replay_cpu.append(plant_alone_rtf(default, "replay", default_log, clock=time.process_time)[0])
        closed_cpu.append(closed_loop_cpu_rtf(default))
    static.append(plant_alone_rtf(default, "static")[0])
    zero.append(plant_alone_rtf(default, "zero")[0])
    result["rtf"] = statistics.median(closed)
    result["plant_rtf"] = statistics.median(replay)
    result["rtf_ratio"] = result["rtf"] / result["plant_rtf"]
    result["cpu_rtf"], result["plant_cpu_rtf"] = statistics.median(closed_cpu), statistics.median(replay_cpu)
    result["cpu_rtf_ratio"] = result["cpu_rtf"] / result["plant_cpu_rtf"]
    result["plant_rtf_static_torque"] = statistics.median(static)
    result["plant_rtf_zero_torque"] = statistics.median(zero)
    result["rtf_samples"] = closed
    result["plant_rtf_samples"] = replay
    result["replay_drift"] = drift
    result["replay_contacts_at_end"] = contacts_end
    result["tick"] = task_tick(default, tick_samples, rng)
    return result
