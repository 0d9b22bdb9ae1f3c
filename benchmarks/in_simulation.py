"""Where a closed-loop simulation step's time goes: the law, the sensor, the source and the plant.

``measure_task(name)`` runs the task's default closed loop (``experiments.simulation``'s diagram:
discrete SAP plant, sampled controller, wrench sensor, source, loggers) with the Python systems'
calculations timed by wrappers installed on their classes before the diagram is built:

* ``law``: the controller's cache calculation (``HybridController._calc_solution``: the state set
  into its plant context, the force elements, the compiled law and its Drake calls), exclusive of
  the input ports it pulls (the sensor and the source are timed on their own);
* ``update``: the rest of the controller's periodic discrete update (integrals, held torque,
  diagnostics), exclusive of the law;
* ``sensor``: the wrench sensor's calculation, exclusive of ``contact results`` (the plant's
  contact results it reads, see below);
* ``source``: the desired-motion source's outputs;
* ``rest``: the step's wall time minus all of these (the plant's own discrete step with its SAP
  solve, the simulator, the loggers).

Each wrapper measures its call's inclusive time and subtracts the nested wrapped calls, so the
parts add up to the step. Timing costs about 0.3 us per wrapped call, charged to the caller.
``law_us`` (median per evaluation) against the isolated tick's ``_calc_solution`` on the same
controller at the same state shows how much a simulation step's cold caches cost the law.

The plant's contact results are sampled (Drake's default output ports): each step's own solve,
read once a step by the sensor (at k h by the wrench logger, after the step; the controller's tick
at (k+1) h - delta reuses that value), so ``contact results`` is a read of stored results, not a
solve; the plant's one SAP solve a step is in ``rest`` (docs/drake_notes.md, "Sampled plant output
ports").
"""

import time

import numpy as np

from pydrake.systems.analysis import Simulator

from drake_hybrid.control.controller import HybridController_
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.systems import sources
from drake_hybrid.systems.contact_wrench_sensor import ContactWrenchSensor_
from drake_hybrid.systems.wrist_force_torque_sensor import WristForceTorqueSensor_
from drake_hybrid.tasks.registry import TASKS

_STACK = []


class _Recorder:
    """Exclusive times (ns) per part."""

    def __init__(self):
        self.samples = {}

    def add(self, part, nanoseconds):
        self.samples.setdefault(part, []).append(nanoseconds)


def _timed(function, part, recorder):
    def wrapper(*arguments):
        _STACK.append(0)
        start = time.perf_counter_ns()
        try:
            return function(*arguments)
        finally:
            inclusive = time.perf_counter_ns() - start
            nested = _STACK.pop()
            recorder.add(part, inclusive - nested)
            if _STACK:
                _STACK[-1] += inclusive
    return wrapper


class _TimedPort:
    """An input port whose Eval is timed as ``part`` (the sensor's contact results)."""

    def __init__(self, port, part, recorder):
        self.Eval = _timed(port.Eval, part, recorder)


def _patches():
    controller = HybridController_[float]
    patches = [(controller, "_calc_solution", "law"), (controller, "_discrete_update", "update"),
               (ContactWrenchSensor_[float], "_calc_wrench_float", "sensor"),
               (ContactWrenchSensor_[float], "_calc_wrench", "sensor"),
               (WristForceTorqueSensor_[float], "_calc_wrench_float", "sensor"),
               (WristForceTorqueSensor_[float], "_calc_wrench", "sensor")]
    for name in ("ProfileSource_", "PseudoVelocitySource_", "DesiredFieldSource_"):
        cls = getattr(sources, name)[float]
        patches += [(cls, method, "source") for method in ("_calc_velocity", "_calc_acceleration", "_calc_force")]
    return patches


def _percentiles(nanoseconds):
    values = np.asarray(nanoseconds, dtype=float) * 1e-3
    return {"median_us": float(np.median(values)), "p99_us": float(np.percentile(values, 99)),
            "max_us": float(values.max()), "count": int(values.size)}


def build_timed(config, recorder):
    """The task's closed loop with its Python systems' calculations timed into ``recorder``."""
    saved = [(cls, name, cls.__dict__[name]) for cls, name, _ in _patches()]
    try:
        for cls, name, part in _patches():
            setattr(cls, name, _timed(cls.__dict__[name], part, recorder))
        scenario = build_scenario(config)
    finally:
        for cls, name, original in saved:
            setattr(cls, name, original)
    sensor = scenario.sensor
    for attribute in ("_results_port", "_reactions_port"):
        if hasattr(sensor, attribute):
            setattr(sensor, attribute, _TimedPort(getattr(sensor, attribute), "contact results", recorder))
    return scenario


def isolated_law_us(scenario, context, samples=2000):
    """The same controller's ``_calc_solution`` at the simulation's final state, timed alone in a
    loop (each call sets the state into the plant context, which invalidates its kinematics, as in
    a tick; the input ports' values are cached)."""
    controller = scenario.controller
    controller_context = controller.GetMyContextFromRoot(context)
    cache = controller._solution_cache.Eval(controller_context)

    class Holder:
        def get_mutable_value(self):
            return cache

    holder = Holder()
    times = np.empty(samples)
    for i in range(samples):
        start = time.perf_counter_ns()
        controller._calc_solution(controller_context, holder)
        times[i] = time.perf_counter_ns() - start
    return float(np.median(times)) * 1e-3


def measure_task(name, duration=None, warmup=0.05):
    """Per-step time of the task's default closed loop, by part (module docstring)."""
    config = TASKS[name].default_config()
    duration = float(config.duration if duration is None else duration)
    recorder = _Recorder()
    scenario = build_timed(config, recorder)
    simulator = Simulator(scenario.diagram)
    set_initial_conditions(scenario, simulator.get_mutable_context())
    simulator.Initialize()
    simulator.AdvanceTo(warmup)                                        # compile or load the law, settle
    recorder.samples.clear()
    start = time.perf_counter()
    simulator.AdvanceTo(warmup + duration)
    wall = time.perf_counter() - start
    steps = int(round(duration / float(config.plant.time_step)))
    step_us = wall / steps * 1e6
    parts = {part: {**_percentiles(values), "per_step_us": float(np.sum(values)) * 1e-3 / steps,
                    "per_step_calls": len(values) / steps}
             for part, values in recorder.samples.items()}
    accounted = sum(entry["per_step_us"] for entry in parts.values())
    law = parts.get("law", {})
    return {"duration_s": duration, "steps": steps, "plant_time_step_s": float(config.plant.time_step),
            "control_period_s": float(config.control_period), "rtf": duration / wall, "step_us": step_us,
            "parts": parts, "rest_per_step_us": step_us - accounted,
            "law_us": law.get("median_us"), "law_share_of_step": (law.get("per_step_us", 0.0) / step_us),
            "law_isolated_us": isolated_law_us(scenario, simulator.get_context())}


def table(results):
    """Markdown lines of ``{task: measure_task(...)}``."""
    lines = ["| task | step us | law us per evaluation (median / p99) | law isolated us | law per step us (share) | "
             "contact results us | sensor us | source us | update us | rest us (plant step, "
             "simulator, loggers) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in results.items():
        p = r["parts"]

        def per_step(part):
            return f"{p[part]['per_step_us']:.1f}" if part in p else "-"

        law = p.get("law", {})
        lines.append(f"| {name} | {r['step_us']:.0f} | {law.get('median_us', float('nan')):.1f} / "
                     f"{law.get('p99_us', float('nan')):.0f} | {r['law_isolated_us']:.1f} | {per_step('law')} "
                     f"({100 * r['law_share_of_step']:.0f} %) | {per_step('contact results')} | {per_step('sensor')} | "
                     f"{per_step('source')} | {per_step('update')} | {r['rest_per_step_us']:.0f} |")
    return lines
