"""Run a scenario and turn its logs into arrays, a summary and files.

``simulate(config)`` builds the scenario, sets the start, runs Drake's
Simulator (with an optional progress bar and Meshcat recording) and returns a
``SimulationResult`` with the log (arrays keyed as in ``log.npz``) and the
summary (a ``summary.RunSummary``, whose ``to_json()`` is ``summary.json``); ``viz.outputs.write_run(result,
out_dir)`` writes both plus the tracking plots.

A run that stops early is never reported as a success: a sensor fault (the measured wrench
non-finite for longer than ``sensor.fault_time``), an error raised inside the simulation, or an
interrupt (Ctrl-C) ends it at that time and ``simulate`` raises ``RunStopped``, whose ``result``
holds the log up to the stop and a summary with ``status`` ("fault", "error" or "interrupted"),
``stop_time`` and ``stop_reason`` (a completed run has ``status`` "completed").

The result also holds the built ``scenario`` (its ``diagram``, ``plant``, ``controller``, ...),
the ``simulator`` and its root ``context`` after the run. To act during the run (a monitor, a
visualizer, a changed parameter), pass ``setup``: it is called as ``setup(scenario, simulator,
context)`` after the start is set and before ``Simulator.Initialize``::

    def watch(scenario, simulator, context):        # stop the run if the force gets too large
        force = scenario.controller.GetOutputPort("force")
        simulator.set_monitor(lambda root: EventStatus.ReachedTermination(None, "too hard")
                              if abs(force.Eval(scenario.controller.GetMyContextFromRoot(root))[0]) > 50
                              else EventStatus.Succeeded())

    result = simulate(config, setup=watch)

A monitor set in ``setup`` runs after the sensor-fault monitor (both are kept; a termination
the user's monitor asks for ends the run as a completed run, at that time).
"""

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, Mapping, Optional, Tuple, Union, cast

import numpy as np
from tqdm import tqdm

from pydrake.geometry import Meshcat
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator
from pydrake.systems.framework import Context, EventStatus

from drake_hybrid.analysis.design import controller_prediction, design_time_constant, predicted_errors
from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.core.hints import Array
from drake_hybrid.core.progress import StagesLike, quiet
from drake_hybrid.experiments.metrics import (ForceRowFigures, contact_time, impedance_check, invalid_samples,
                                              last_valid, max_after, row_errors, row_units, run_scale, worst)
from drake_hybrid.experiments.patch_report import patch_report
from drake_hybrid.experiments.path_report import before_lift_off, path_report
from drake_hybrid.experiments.summary import RunSummary
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.station.handles import HybridSystems
from drake_hybrid.station.loggers import read_log
from drake_hybrid.systems.path_source import PathSource
from drake_hybrid.systems.sources import PseudoVelocitySource
from drake_hybrid.tasks.config import ScenarioConfig, check_scenario_config
from drake_hybrid.tasks.task import Scenario

# The run's note when its controller ran the generic law while numba compiled the fast one (control/fast_compile.py).
COMPILING_NOTE = ("this run used the generic law (the compiled one gives the same to 1e-12): the compiled law was "
                  "not on this machine yet, and numba compiles it in the background for the next runs (once, "
                  "30-65 s on 2 cores)")


# A Simulator monitor: called with the root context at every step, it may end the run.
Monitor = Callable[[Context], EventStatus]


@dataclass
class SimulationResult:
    config: ScenarioConfig
    log: Dict[str, Array]
    summary: RunSummary
    scenario: Optional[Scenario] = None          # the built Scenario: diagram, plant, controller, ...
    html: Optional[str] = None
    extra: Dict[str, Any] = field(default_factory=dict)
    simulator: Optional[Simulator] = None        # Drake's Simulator after the run
    context: Optional[Context] = None            # its root context (the diagram's) at the end


class RunStopped(RuntimeError):
    """The run stopped before its duration; ``result`` holds its log and summary up to the stop
    (an error raised inside the run is the ``__cause__``)."""

    def __init__(self, result: SimulationResult) -> None:
        summary = result.summary
        super().__init__(f"the run stopped at t = {summary.stop_time:.4g} s ({summary.status}): "
                         f"{summary.stop_reason}")
        self.result = result


def sensor_fault_monitor(scenario: HybridSystems, fault_time: float, stop: Dict[str, Any]) -> Monitor:
    """A Simulator monitor that ends the run when the wrench the controller reads has been
    non-finite for longer than ``fault_time`` (s); it fills ``stop`` (status, time, reason)."""
    controller = scenario.controller
    port = controller.get_measured_wrench_input_port()
    invalid_since = [None]

    def monitor(root_context):
        time_now = root_context.get_time()
        if np.all(np.isfinite(port.Eval(controller.GetMyContextFromRoot(root_context)))):
            invalid_since[0] = None
            return EventStatus.Succeeded()
        if invalid_since[0] is None:
            invalid_since[0] = time_now
        if time_now - invalid_since[0] > fault_time:
            stop.update(status="fault", time=time_now, reason=(
                f"sensor fault: the measured wrench has been non-finite since t = {invalid_since[0]:.4g} s, longer "
                f"than sensor.fault_time = {fault_time:g} s"))
            return EventStatus.ReachedTermination(controller, stop["reason"])
        return EventStatus.Succeeded()

    return monitor


def chain_monitors(first: Monitor, second: Optional[Monitor]) -> Monitor:
    """A monitor that runs ``first`` and, unless it ends the run, ``second`` (None: only ``first``)."""
    if second is None:
        return first

    def monitor(root_context):
        status = first(root_context)
        return status if status.severity() != EventStatus.Severity.kSucceeded else second(root_context)

    return monitor


def simulate(config: ScenarioConfig, progress: bool = False, meshcat: Optional[Meshcat] = None,
             record_html: bool = False, setup: Optional[Callable[[Scenario, Simulator, Context], Any]] = None,
             stages: Optional[StagesLike] = None) -> SimulationResult:
    """Simulate ``config``; returns a SimulationResult (log arrays, summary, scenario, simulator and
    context). ``setup(scenario, simulator, context)``, if given, runs after the start is set and
    before ``Simulator.Initialize`` (e.g. ``simulator.set_monitor``). ``progress``: a progress bar
    while simulating; ``stages`` (``core.progress.Stages``): one line per setup stage with its time,
    printed before the bar (default: silent).

    Raises RunStopped (with the result up to the stop) if the run ends early: see the module
    docstring."""
    check_scenario_config(config, "simulate")
    stages = stages or quiet()
    with stages(f"{config.task}: building the diagram (plant, constraint, controller)"):
        scenario = build_scenario(config, meshcat=meshcat)
        assert scenario.diagram is not None          # build_scenario returns it built
        simulator = Simulator(scenario.diagram)
        ApplySimulatorConfig(config.simulator, simulator)
        context = simulator.get_mutable_context()
    with stages(f"{config.task}: solving the start (inverse kinematics, contact equilibrium)"):
        set_initial_conditions(scenario, context)
    if setup is not None:
        setup(scenario, simulator, context)
    stop: Dict[str, Any] = {}
    if scenario.fault_injector is not None or scenario.conditioner is not None:
        # Only these make the wrench non-finite (a dropout, a hold run out): the check costs a Python call a step.
        simulator.set_monitor(chain_monitors(sensor_fault_monitor(scenario, float(config.sensor.fault_time), stop),
                                             simulator.get_monitor()))
    if meshcat is not None and record_html:
        meshcat.StartRecording(set_visualizations_while_recording=False)
    with stages(f"{config.task}: initializing the simulator"):
        simulator.Initialize()
    start = time.perf_counter()
    duration = float(config.duration)
    try:
        if progress:
            steps = 100
            with tqdm(total=steps, desc=f"simulating {config.task}", unit="%", leave=False) as bar:
                for i in range(1, steps + 1):
                    simulator.AdvanceTo(duration * i / steps)
                    bar.update(1)
                    if stop:
                        break
        else:
            simulator.AdvanceTo(duration)
    except KeyboardInterrupt:
        stop.update(status="interrupted", time=context.get_time(), reason="interrupted (Ctrl-C)")
    except Exception as error:   # noqa: BLE001 -- any error inside the run: keep what was logged
        message = str(error).strip().splitlines()[0] if str(error).strip() else ""
        stop.update(status="error", time=context.get_time(), reason=f"{type(error).__name__}: {message}",
                    error=error)
    wall = time.perf_counter() - start
    html = None
    if meshcat is not None and record_html:
        meshcat.StopRecording()
        meshcat.PublishRecording()
        html = meshcat.StaticHtml()
    log = collect_log(scenario, context)
    if stop and len(log["t"]) < 2:
        summary = RunSummary(task=config.task, mode=scenario.controller.mode.value, duration=duration)
    else:
        summary = summarize(scenario, log, wall)
    summary.status = stop.get("status", "completed")
    summary.stop_time = float(stop.get("time", context.get_time()))
    summary.stop_reason = stop.get("reason")
    if summary.status == "fault":
        without_force_figures(summary)
    if getattr(getattr(scenario.controller, "fast_law", None), "compiling", False):
        summary.notes = (summary.notes or []) + [COMPILING_NOTE]
    result = SimulationResult(config=config, log=log, summary=summary, scenario=scenario, html=html,
                              simulator=simulator, context=context)
    if stop:
        raise RunStopped(result) from stop.get("error")
    return result


def without_force_figures(summary: RunSummary) -> RunSummary:
    """``summary`` with its force error figures None (a sensor fault: the controller took F = F_d while the
    wrench was invalid, so its force error is not a measurement): the worst row's, and each force row's
    figures but its name, units, command and whether it is held."""
    for name in [f.name for f in dataclasses.fields(summary)
                 if "force_error" in f.name or f.name == "force_settling_time_1_percent"]:
        setattr(summary, name, None)
    kept = ("name", "units", "command", "held")
    for row in summary.force_rows or []:
        for name in [f.name for f in dataclasses.fields(row) if f.name not in kept]:
            setattr(row, name, None)
    return summary


# log.npz's names for the loggers' keys (station.loggers.LOG_KEYS) that it calls otherwise.
LOG_NAMES = {"projected_velocity": "velocity", "constraint_value": "constraint", "actuation": "torque"}


def collect_log(scenario: HybridSystems, context: Context) -> Dict[str, Array]:
    """The logged signals as arrays (the keys of log.npz: ``station.loggers.read_log``'s, a few renamed
    by ``LOG_NAMES``, the state split into q and v)."""
    logged = read_log(scenario.loggers, context)
    log = {LOG_NAMES.get(key, key): values for key, values in logged.items() if key != "state"}
    n = logged["state"].shape[1] // 2
    log["q"], log["v"] = logged["state"][:, :n], logged["state"][:, n:]
    if getattr(scenario.source, "true_projection", None) is not None:   # the paper's pseudo-velocity: its
        # velocity_error is E_t r-dot - r-dot_td (PseudoVelocitySource), the true rows'; r-dot_td is their command
        profile = cast(PseudoVelocitySource, scenario.source).velocity_profile
        log["true_desired_velocity"] = np.array([profile.evaluate(float(s))[0] for s in log["t"]])
    return log


def effort_limits(systems: HybridSystems) -> Array:
    """The effort limits of the arm's actuators (N m for revolute joints), in actuation order: the
    controller's own model's (the robot alone, built as the simulated arm)."""
    plant = systems.controller_plant
    return np.array([plant.get_joint_actuator(i).effort_limit() for i in plant.GetJointActuatorIndices()])


def _percent(error, scale):
    return float(100.0 * error / scale) if scale > 0 else float("nan")


def summarize(scenario: Scenario, log: Mapping[str, Array], wall_time: float) -> RunSummary:
    """The run's summary (a ``RunSummary``, summary.json): gains, mode, designed eigenvalues, errors. Its
    ``status`` is None: ``simulate`` sets it, with the stop's time and reason."""
    config = scenario.config
    controller = scenario.controller
    gains = controller.validated_gains()
    k, m = controller.velocity_size, controller.force_size
    predicted = controller_prediction(controller)
    tau = design_time_constant(gains, controller.mode, controller.kinematic_rows)
    speed_scale, force_scale = run_scale(log["desired_velocity"]), run_scale(log["desired_force"])
    labels = scenario.task.labels(scenario.config)
    start = contact_time(log)
    settle_after = start + 5 * tau
    # A job's lift-off (station.path_job) leaves the surface on purpose: the rows' figures end there.
    job = before_lift_off(log)
    # With the paper's pseudo-velocity rows the error is the true rows' (collect_log): as those, against their command.
    velocity_rows = row_errors(job["t"], job["velocity_error"],
                               job.get("true_desired_velocity", job["desired_velocity"]),
                               labels.get("velocity_error", labels.get("velocity", [])),
                               row_units(labels.get("velocity_error_units", labels.get("velocity_units", "SI")), k),
                               start, settle_after)
    force_figures = row_errors(job["t"], job["force_error"], job["desired_force"], labels.get("force", []),
                               row_units(labels.get("force_units", "SI"), m), start, settle_after)
    measured = max_after(job["force"], job["t"] >= start)
    force_rows = [ForceRowFigures(**dataclasses.asdict(row), held=i in controller.kinematic_rows,
                                  max_measured_force_after_contact=measured[i])
                  for i, row in enumerate(force_figures)]    # a held row (controller.kinematic_rows): no force loop
    for row in force_rows:
        if row.held:                           # no command, so no error: its figures are null, not 0
            for name in [f.name for f in dataclasses.fields(row)
                         if "error" in f.name or f.name == "settling_time_1_percent"]:
                setattr(row, name, None)
    constraint_units = row_units(labels["constraint_units"], log["constraint"].shape[1]) \
        if "constraint_units" in labels else None
    torque_ratio = np.max(np.abs(log["torque"]) / effort_limits(scenario), axis=0)
    final_force_error = last_valid(log["force_error"])         # the last sample with a valid wrench
    pairs = lambda values: [[float(np.real(v)), float(np.imag(v))] for v in values]
    path_source = cast(PathSource, scenario.source)          # a job's, when its path_progress is logged
    return RunSummary(
        task=config.task,
        mode=controller.mode.value,
        duration=float(config.duration),
        time_step=float(config.plant.time_step),
        control_period=float(config.control_period),
        velocity_dim=k,
        force_dim=m,
        gains=config.gains.as_lists(k, m, controller.mode),
        predicted_eigenvalues=pairs(predicted.designed),
        design_time_constant=float(tau),
        final_velocity_error=log["velocity_error"][-1].tolist(),
        final_force_error=None if final_force_error is None else final_force_error.tolist(),
        # Samples taken while the measured wrench was invalid: F, e_f and F_v read NaN there (no figure).
        invalid_wrench_samples=invalid_samples(log["force_error"]),
        # Headline figures: the worst row, each row in % of its own command (rows commanded to zero
        # are in velocity_rows / force_rows, in their own units); settling counted from contact.
        contact_time=start,
        final_velocity_error_percent=worst(velocity_rows, "final_error_percent"),
        final_force_error_percent=worst(force_rows, "final_error_percent"),
        max_velocity_error_percent_after_5_time_constants=worst(velocity_rows,
                                                                "max_error_percent_after_5_time_constants"),
        max_force_error_percent_after_5_time_constants=worst(force_rows, "max_error_percent_after_5_time_constants"),
        velocity_settling_time_1_percent=worst(velocity_rows, "settling_time_1_percent"),
        force_settling_time_1_percent=worst(force_rows, "settling_time_1_percent"),
        velocity_rows=velocity_rows,
        force_rows=force_rows,
        # impedance-force: the run against the designed impedance driven by its measured F_v (None otherwise,
        # and with a mechanism's inertia in the law, whose F_m drives the impedance too)
        impedance=impedance_check(log, gains, start, settle_after)
        if controller.mode is ControlMode.IMPEDANCE_FORCE and controller.velocity_row_inertia is None else None,
        max_constraint_residual=float(np.max(np.abs(log["constraint"]))),
        # From contact on (to a job's lift-off): before it, C is the start's gap, not a residual.
        max_constraint_residual_after_contact=float(np.max(np.abs(job["constraint"][job["t"] >= start])))
        if np.any(job["t"] >= start) else None,
        max_constraint_residual_rows_after_contact=max_after(job["constraint"], job["t"] >= start),
        constraint_units=constraint_units,       # per row of C (None where the task names none)
        held=[row.name for row in force_rows if row.held],    # no force commanded: see force_rows
        max_torque_to_effort_limit=torque_ratio.tolist(),
        wall_time=float(wall_time),
        real_time_factor=float(config.duration / wall_time) if wall_time > 0 else None,
        command_scales={"speed": speed_scale, "force": force_scale},
        notes=list(scenario.task.run_notes(scenario, log, tau)),
        events=list(scenario.task.run_events(scenario, log)),
        # The start in contact presses with F_d (the start is solved for it); xi(0) then steps the first
        # force command by K_fi xi(0), per row (N in the row's units): the plots mark that step.
        start_in_contact=bool(config.start.in_contact),
        start_force_command_step=(np.asarray(gains.force_integral, dtype=float) @ np.asarray(
            config.start.force_integral, dtype=float)).tolist() if config.start.force_integral else [0.0] * m,
        # A job's path (station.path_job): path and force errors per segment, time off the surface.
        path=path_report(log, tau, path_source.path.duration, path_source.path.length,
                         path_source.force_row) if "path_progress" in log else None,
        # A disc's contact patch (station.sensing.add_contact_patch): centred, flat, even, and the normal force.
        patch=patch_report(log, tau, start, next(i for i in range(m) if i not in controller.kinematic_rows))
        if "patch" in log else None,
    )


def predicted_tracking(scenario_or_controller: Union[HybridSystems, HybridController], config: ScenarioConfig,
                       log: Mapping[str, Array]) -> Tuple[Array, Array]:
    """Predicted (velocity, force) trajectories: the desired ones plus the designed error decay from
    contact on (``contact_time``), from the logged velocity error at contact and the configured
    initial integrals (frozen until contact); NaN before contact, where the design predicts nothing."""
    controller: HybridController = getattr(scenario_or_controller, "controller", scenario_or_controller)
    gains = controller.validated_gains()
    m = controller.force_size
    xi0 = np.asarray(config.start.force_integral, dtype=float) if config.start.force_integral else np.zeros(m)
    e_p0 = np.asarray(config.start.position_error, dtype=float) if config.start.position_error else None
    t = log["t"]
    velocity = np.full_like(log["desired_velocity"], np.nan, dtype=float)
    force = np.full_like(log["desired_force"], np.nan, dtype=float)
    start = contact_time(log)
    if np.isfinite(start):
        after = t >= start
        first = int(np.argmax(after))
        velocity_error, force_error, _ = predicted_errors(gains, controller.mode, t[after] - start,
                                                          log["velocity_error"][first], xi0, e_p0,
                                                          controller.kinematic_rows)
        velocity[after] = log["desired_velocity"][after] + velocity_error
        force[after] = log["desired_force"][after] + force_error
    return velocity, force
