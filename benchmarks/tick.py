"""Controller tick: one fresh evaluation of the control law against Drake's InverseDynamicsController.

A "tick" is one evaluation of a controller's torque output (float) from a
state it has not seen: before every timed evaluation the ``estimated_state``
input is set to the nominal state plus a new perturbation of 1e-7 (outside
the timed region), which invalidates every cache entry downstream of it, so
neither Drake's caching nor ours can return a stored result. The timer
covers only ``output_port.Eval(context)``.

The hybrid controller and Drake's C++ ``InverseDynamicsController`` run on the
same plant, in the same process, interleaved sample by sample (so a noisy
moment of the shared machine hits both). ``tick_ratio`` is the ratio of the
medians (and of the 95th percentiles).

Also timed (in a separate loop): the sampled (1 kHz, discrete) controller's
periodic update, which is what a discrete closed loop pays per control period
(the law plus the integral update).
"""

import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from robots import BenchmarkRobot, make_inverse_dynamics_controller, make_robot

from drake_hybrid.control.controller import HybridController

PERTURBATION = 1e-7


@dataclass
class Timing:
    median_us: float
    p95_us: float
    samples: int
    p99_us: float = float("nan")
    max_us: float = float("nan")

    @classmethod
    def of(cls, nanoseconds):
        microseconds = np.asarray(nanoseconds, dtype=float) * 1e-3
        return cls(median_us=float(np.median(microseconds)), p95_us=float(np.percentile(microseconds, 95)),
                   samples=int(microseconds.size), p99_us=float(np.percentile(microseconds, 99)),
                   max_us=float(microseconds.max()))


def fix_inputs(system, context, inputs):
    for name, value in inputs.items():
        system.GetInputPort(name).FixValue(context, value)


class FreshEvaluation:
    """Times ``evaluate(context)`` after setting ``state_port`` to a new perturbed state."""

    def __init__(self, state_port, context, state, evaluate, rng):
        self.state_port, self.context, self.state, self.evaluate = state_port, context, np.array(state), evaluate
        self.rng = rng

    def __call__(self):
        self.state_port.FixValue(self.context, self.state + PERTURBATION * self.rng.standard_normal(self.state.size))
        start = time.perf_counter_ns()
        self.evaluate(self.context)
        return time.perf_counter_ns() - start


def hybrid_evaluation(robot, rng):
    controller = robot.controller
    context = controller.CreateDefaultContext()
    fix_inputs(controller, context, robot.inputs)
    actuation = controller.GetOutputPort("actuation")
    return FreshEvaluation(controller.get_estimated_state_input_port(), context, robot.state, actuation.Eval, rng)


def sampled_update_evaluation(robot, rng):
    """The periodic discrete update of the sampled controller (law + integrals + held torque)."""
    controller = robot.controller
    if controller.control_period is None:
        raise ValueError("sampled_update_evaluation needs a controller with a control_period")
    context = controller.CreateDefaultContext()
    fix_inputs(controller, context, robot.inputs)
    return FreshEvaluation(controller.get_estimated_state_input_port(), context, robot.state,
                           controller.EvalUniquePeriodicDiscreteUpdate, rng)


def inverse_dynamics_evaluation(robot, rng):
    """Drake's InverseDynamicsController on the robot's plant: desired state = nominal state,
    desired acceleration 0; times its ``generalized_force`` output."""
    idc = make_inverse_dynamics_controller(robot.plant)
    context = idc.CreateDefaultContext()
    n = robot.plant.num_velocities()
    idc.GetInputPort("desired_state").FixValue(context, robot.state)
    idc.GetInputPort("desired_acceleration").FixValue(context, np.zeros(n))
    output = idc.GetOutputPort("generalized_force")
    return FreshEvaluation(idc.GetInputPort("estimated_state"), context, robot.state, output.Eval, rng)


def interleaved(evaluations, samples, warmup):
    """Run every evaluation ``warmup`` times, then ``samples`` times in turn; one Timing each."""
    for _ in range(warmup):
        for evaluation in evaluations:
            evaluation()
    times = np.empty((len(evaluations), samples))
    for i in range(samples):
        for j, evaluation in enumerate(evaluations):
            times[j, i] = evaluation()
    return [Timing.of(row) for row in times]


def measure_robot(name, samples=3000, warmup=300, seed=0, mode="velocity-force"):
    """Tick timings of robot ``name``: controller (continuous law), sampled update, IDC, ratios."""
    rng = np.random.default_rng(seed)
    robot = make_robot(name, mode)
    sampled = make_robot(name, mode, control_period=1e-3)
    # The pair that makes the ratio is interleaved on its own: a third evaluation in the loop evicts
    # the others' code and data from the CPU caches and slows the IDC by ~15 %.
    controller, idc = interleaved([hybrid_evaluation(robot, rng), inverse_dynamics_evaluation(robot, rng)],
                                  samples, warmup)
    (update,) = interleaved([sampled_update_evaluation(sampled, rng)], samples, warmup)
    # The same controller on the generic law (control/law.py), for the fast path's gain.
    generic = BenchmarkRobot(name=robot.name, description=robot.description, plant=robot.plant,
                             controller=HybridController(**dict(robot.controller._arguments, fast_law=False)),
                             state=robot.state, inputs=robot.inputs)
    (generic_tick,) = interleaved([hybrid_evaluation(generic, rng)], samples // 3, warmup // 3)
    return {
        "description": robot.description,
        "joints": robot.joints,
        "task_size": robot.task_size,
        "force_rows": robot.force_rows,
        "mode": mode,
        "controller_tick_us": asdict(controller),
        "idc_tick_us": asdict(idc),
        "sampled_update_us": asdict(update),
        "generic_tick_us": asdict(generic_tick),
        "fast_law": robot.controller.fast_law is not None,
        "tick_ratio": {"median": controller.median_us / idc.median_us, "p95": controller.p95_us / idc.p95_us},
    }


def measure_rows(name, rows, samples=1500, warmup=150, seed=0):
    """Tick of the arm ``name`` with m = ``rows`` generic constraint rows (and the IDC on the same plant)."""
    from robots import surface_rows_controller

    rng = np.random.default_rng(seed)
    robot = surface_rows_controller(name, rows)
    controller, idc = interleaved([hybrid_evaluation(robot, rng), inverse_dynamics_evaluation(robot, rng)],
                                  samples, warmup)
    return {"robot": name, "joints": robot.joints, "force_rows": rows, "controller_tick_us": asdict(controller),
            "idc_tick_us": asdict(idc), "tick_ratio": controller.median_us / idc.median_us}


COMPILE_SCRIPT = """
import json, sys, time
sys.path.insert(0, {here!r})
import numpy as np
from robots import make_robot
result = {{}}
for name in {names!r}:
    robot = make_robot(name)
    context = robot.controller.CreateDefaultContext()
    for port, value in robot.inputs.items():
        robot.controller.GetInputPort(port).FixValue(context, value)
    start = time.perf_counter()
    robot.controller.GetOutputPort("actuation").Eval(context)
    result[name] = {{"first_tick_s": time.perf_counter() - start,
                    "compile_or_load_s": robot.controller.fast_law.compile_seconds}}
print(json.dumps(result))
"""


def compile_times(names=("ur5e", "planar-3r")):
    """First-tick times of the fast path in fresh processes with an empty numba cache (cold: the
    kernels and the first constraint compile; the second constraint compiles only its generated
    module) and again with the cache they left (cached re-run)."""
    here = str(Path(__file__).resolve().parent)
    script = COMPILE_SCRIPT.format(here=here, names=list(names))
    with tempfile.TemporaryDirectory() as folder:
        environment = dict(os.environ, NUMBA_CACHE_DIR=folder, DRAKE_HYBRID_CACHE=folder)
        runs = []
        for _ in range(2):
            output = subprocess.run([sys.executable, "-c", script], env=environment, capture_output=True, text=True,
                                    check=True).stdout
            runs.append(json.loads(output.strip().splitlines()[-1]))
    return {"cold": runs[0], "cached": runs[1]}
