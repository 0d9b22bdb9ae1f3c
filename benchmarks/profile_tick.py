"""Where the controller tick's time goes: a stage-by-stage breakdown, a cProfile by category,
and the cost of the numpy and Drake calls the law is made of.

    python benchmarks/profile_tick.py [--robots planar-3r ur5e] [--samples 3000] [--json FILE]

Every stage is timed on its own (no profiler attached), by the median of
``samples`` fresh calls: before each timed call the plant context gets a new
perturbed state, so Drake's kinematics caches are cold exactly as they are in
a tick. The plant calls are timed in the order the law makes them (the first
position-dependent call pays for the forward kinematics, the first
velocity-dependent one for the velocity kinematics). The stages add up to the
law; the rest of the tick (tick minus law) is the systems framework: the
input ports, the plant-context and solution cache entries and the output.

The cProfile section sums the profiler's own-time by category; it inflates
functions that make many small calls, so read it for shares, and the stage
table for microseconds. Findings and the optimization plan: PROFILE.md.
"""

import argparse
import cProfile
import json
import pstats
import sys
import time
from pathlib import Path

import numpy as np
from numpy.linalg import _umath_linalg

sys.path.insert(0, str(Path(__file__).resolve().parent))

from robots import make_robot  # noqa: E402
from tick import fix_inputs, hybrid_evaluation, interleaved, inverse_dynamics_evaluation  # noqa: E402

from pydrake.multibody.tree import JacobianWrtVariable  # noqa: E402

from drake_hybrid.core.linalg import rank_margin, solve  # noqa: E402
from drake_hybrid.core.projections import KernelVelocityProjection  # noqa: E402

PERTURBATION = 1e-7


def median_us(function, samples, setup=None):
    """Median wall time (us) of ``function()``, each call after an untimed ``setup()``."""
    times = np.empty(samples)
    for i in range(samples):
        if setup is not None:
            setup()
        start = time.perf_counter_ns()
        function()
        times[i] = time.perf_counter_ns() - start
    return float(np.median(times)) * 1e-3


class LawParts:
    """The controller's pieces at the robot's nominal state, with a plant context to perturb."""

    def __init__(self, robot, rng):
        self.robot = robot
        self.controller = controller = robot.controller
        self.plant = controller.plant()
        self.context = controller.CreateDefaultContext()
        fix_inputs(controller, self.context, robot.inputs)
        self.plant_context = self.plant.CreateDefaultContext()
        self.rng = rng
        self.fresh_state()
        self.kinematics = controller.kinematics
        self.task = self.kinematics.evaluate(self.plant_context)
        self.space = controller.constraint_space
        self.x, self.nu = self.task.configuration, self.task.velocity
        self.values = self.space.evaluate(self.x, self.nu)

    def fresh_state(self):
        state = self.robot.state + PERTURBATION * self.rng.standard_normal(self.robot.state.size)
        self.plant.SetPositionsAndVelocities(self.plant_context, state)

    def fresh_state_with_kinematics(self):
        """New state, then the kinematics the law computes before its inverse dynamics call."""
        self.fresh_state()
        self.kinematics.evaluate(self.plant_context)


def stage_table(robot_name, samples, rng):
    robot = make_robot(robot_name)
    parts = LawParts(robot, rng)
    controller, plant, plant_context = parts.controller, parts.plant, parts.plant_context
    kinematics, space, x, nu, values = parts.kinematics, parts.space, parts.x, parts.nu, parts.values
    frame, point, world = kinematics.frame, kinematics.point_in_frame, plant.world_frame()
    constraint, projection = space.constraint, space.velocity_projection
    chart = space.chart
    forces = controller._solution_cache.Eval(parts.context).forces
    wrench = robot.inputs["measured_wrench"]

    tick, idc = interleaved([hybrid_evaluation(robot, rng), inverse_dynamics_evaluation(robot, rng)], samples,
                            samples // 10)
    law = median_us(lambda: controller._evaluate_law(parts.context, plant_context, forces), samples, parts.fresh_state)

    rows = []

    def stage(label, category, function, setup=None):
        rows.append({"stage": label, "category": category, "us": median_us(function, samples, setup)})

    # Plant calls, in the law's order, each on a cold cache where the law has one.
    stage("CalcRelativeTransform (+ forward kinematics)", "plant",
          lambda: plant.CalcRelativeTransform(plant_context, world, frame), parts.fresh_state)
    warm_position = lambda: (parts.fresh_state(), plant.CalcRelativeTransform(plant_context, world, frame))
    stage("CalcJacobianSpatialVelocity", "plant",
          lambda: plant.CalcJacobianSpatialVelocity(plant_context, JacobianWrtVariable.kV, frame, point, world, world),
          warm_position)
    stage("CalcBiasSpatialAcceleration (+ velocity kinematics)", "plant",
          lambda: plant.CalcBiasSpatialAcceleration(plant_context, JacobianWrtVariable.kV, frame, point, world,
                                                    world).get_coeffs(), warm_position)
    stage("GetVelocities", "plant", lambda: plant.GetVelocities(plant_context))
    stage("CalcForceElementsContribution", "plant",
          lambda: plant.CalcForceElementsContribution(plant_context, forces), parts.fresh_state_with_kinematics)
    qdd = np.zeros(plant.num_velocities())
    stage("CalcInverseDynamics", "plant", lambda: plant.CalcInverseDynamics(plant_context, qdd, forces),
          parts.fresh_state_with_kinematics)
    if controller.mode.value == "impedance-force" or controller.num_joints > controller.task_size:
        stage("CalcMassMatrix", "plant", lambda: plant.CalcMassMatrix(plant_context), parts.fresh_state_with_kinematics)
    plant_total = sum(r["us"] for r in rows)
    kinematics_total = median_us(lambda: kinematics.evaluate(plant_context), samples, parts.fresh_state)
    plant_in_kinematics = sum(r["us"] for r in rows[:4])
    rows.append({"stage": "kinematics.evaluate minus its plant calls (chart maps, TaskKinematics)",
                 "category": "python", "us": kinematics_total - plant_in_kinematics})

    # Compiled symbolic functions (through CompiledFunction.__call__, and the bare generated code).
    compiled = [("C", constraint._value, (x,)), ("E_f", constraint._force_projection, (x,)),
                ("E_f-dot nu", constraint._curvature, (x, nu))]
    if isinstance(projection, KernelVelocityProjection):
        constraint.force_projection_rate(x, nu)
        compiled.append(("E_f-dot", constraint._force_projection_rate, (x, nu)))
    else:
        compiled += [("E_p", projection._matrix, (x,)), ("E_p-dot nu", projection._rate, (x, nu))]
    bare_total = 0.0
    for name, function, arguments in compiled:
        stage(f"compiled {name}", "symbolic", lambda f=function, a=arguments: f(*a))
        bare_total += median_us(lambda f=function, a=arguments: f._float(*a), samples)
    symbolic_total = sum(r["us"] for r in rows if r["category"] == "symbolic")

    # Rank checks (three rank_margin calls per tick with a kernel E_p, two with a given one).
    stage("rank check of E_f (Constraint.check_rank)", "numpy", lambda: constraint.check_rank(x, values.force_projection))
    stage("rank check of E (rank_margin)", "numpy", lambda: rank_margin(values.matrix))
    if isinstance(projection, KernelVelocityProjection):
        E_f = values.force_projection
        E_f_dot = constraint.force_projection_rate(x, nu)
        kernel = median_us(lambda: projection.evaluate(x, nu, E_f, E_f_dot), samples)
        Y = values.velocity_projection                      # same shape as G P_N
        margin = median_us(lambda: rank_margin(Y), samples)
        rows.append({"stage": "rank check of G P_N inside the kernel E_p (rank_margin)", "category": "numpy",
                     "us": margin})
        rows.append({"stage": "kernel E_p and E_p-dot (inv, cholesky, tril, ~25 small products)", "category": "numpy",
                     "us": kernel - margin})
    stage("E = vstack([E_p, E_f])", "numpy", lambda: np.vstack([values.velocity_projection, values.force_projection]))
    stage("wrench validity (np.all(np.isfinite(value(w))))", "numpy", lambda: bool(np.all(np.isfinite(wrench))))
    stage("chart.generalized_force + split_wrench (solve E^T)", "numpy",
          lambda: space.split_wrench(values, chart.generalized_force(x, wrench)))
    a_p = np.zeros(controller.velocity_size)
    stage("task_acceleration (concatenate + solve E)", "numpy", lambda: space.task_acceleration(values, a_p))
    J = parts.task.jacobian
    if controller.num_joints == controller.task_size:
        stage("solve(J, r-ddot* - J-dot q-dot)", "numpy", lambda: solve(J, parts.task.bias))

    space_total = median_us(lambda: space.evaluate(x, nu), samples)
    accounted_in_space = sum(r["us"] for r in rows if r["category"] in ("symbolic",) or r["stage"].startswith(
        ("rank check", "kernel E_p", "E = vstack")))
    rows.append({"stage": "ConstraintSpace.evaluate glue (chart.check, dataclass, isinstance)", "category": "python",
                 "us": space_total - accounted_in_space})
    accounted = sum(r["us"] for r in rows)
    rows.append({"stage": "rest of the law (small products, ControlSolution, port reads)", "category": "python",
                 "us": law - accounted})
    rows.append({"stage": "systems framework (tick minus law: ports, 2 cache entries, output)", "category": "framework",
                 "us": tick.median_us - law})
    # The framework's pieces, timed directly (not part of the sum above).
    state_port = controller.get_estimated_state_input_port()
    context = parts.context
    new_input = lambda: state_port.FixValue(context, robot.state + PERTURBATION * rng.standard_normal(robot.state.size))
    actuation = controller.GetOutputPort("actuation")

    def new_input_and_solution():
        new_input()
        controller._solution_cache.Eval(context)

    framework = {
        "actuation output Eval with the solution already cached (Python calc, copy)":
            median_us(lambda: actuation.Eval(context), samples, new_input_and_solution),
        "solution cache entry Eval (plant state, force elements, law; one Python calc)": median_us(
            lambda: controller._solution_cache.Eval(context), samples, new_input),
    }
    return {"robot": robot_name, "joints": robot.joints, "force_rows": robot.force_rows,
            "tick_us": tick.median_us, "idc_tick_us": idc.median_us, "law_us": law,
            "plant_calls_us": plant_total, "compiled_functions_us": symbolic_total,
            "compiled_functions_bare_us": bare_total, "stages": rows, "framework_direct_us": framework}


def cprofile_categories(robot_name, calls, rng):
    """cProfile own-time of ``calls`` ticks, summed by category (us per tick)."""
    robot = make_robot(robot_name)
    evaluation = hybrid_evaluation(robot, rng)
    for _ in range(200):
        evaluation()
    profiler = cProfile.Profile()
    profiler.enable()
    for _ in range(calls):
        evaluation()
    profiler.disable()
    stats = pstats.Stats(profiler).stats
    categories = {}
    top = []
    for (file_name, line, function), (_, total_calls, own, cumulative, _) in stats.items():
        if file_name.startswith("<drake_hybrid.core.symbolic"):
            category = "compiled symbolic functions"
        elif "numpy" in file_name or function.startswith(("<method 'reduce' of 'numpy", "<built-in method numpy")):
            category = "numpy (wrappers and kernels)"
        elif "pydrake" in function:
            category = "Drake bindings (plant calls, ports, caches)"
        elif "drake_hybrid" in file_name:
            category = "drake_hybrid Python"
        elif "benchmarks" in file_name:
            category = "benchmark harness"
        else:
            category = "other built-ins (isinstance, getattr, ...)"
        categories[category] = categories.get(category, 0.0) + own * 1e6 / calls
        top.append((own * 1e6 / calls, total_calls / calls, f"{Path(file_name).name}:{line}({function})"))
    top.sort(reverse=True)
    return {"robot": robot_name, "calls": calls,
            "categories_us_per_tick": dict(sorted(categories.items(), key=lambda kv: -kv[1])),
            "top_functions": [{"own_us_per_tick": round(t, 2), "calls_per_tick": round(c, 1), "function": f}
                              for t, c, f in top[:20]]}


def numpy_costs(samples):
    """The price of one small numpy / LAPACK call on this machine (us), with the cheaper routes."""
    A6 = np.eye(6) * 6 + np.random.default_rng(1).random((6, 6))
    b6 = np.ones(6)
    A3 = A6[:3, :3].copy()
    S3 = A3 @ A3.T
    entries = [
        ("6x6 @ 6 (matrix-vector)", lambda: A6 @ b6),
        ("6x6 @ 6x6", lambda: A6 @ A6),
        ("np.linalg.solve 6x6", lambda: np.linalg.solve(A6, b6)),
        ("_umath_linalg.solve1 6x6 (no wrapper)", lambda: _umath_linalg.solve1(A6, b6)),
        ("np.linalg.inv 6x6", lambda: np.linalg.inv(A6)),
        ("_umath_linalg.inv 6x6 (no wrapper)", lambda: _umath_linalg.inv(A6)),
        ("np.linalg.inv 3x3", lambda: np.linalg.inv(A3)),
        ("np.linalg.det 6x6", lambda: np.linalg.det(A6)),
        ("np.linalg.cholesky 3x3", lambda: np.linalg.cholesky(S3)),
        ("np.tril 3x3", lambda: np.tril(A3)),
        ("np.eye(6)", lambda: np.eye(6)),
        ("np.vstack of two", lambda: np.vstack([A3, A3])),
        ("np.concatenate of two", lambda: np.concatenate([b6, b6])),
        ("np.all(np.isfinite(6))", lambda: np.all(np.isfinite(b6))),
        ("np.array from a 6-tuple", lambda: np.array((1.0, 2.0, 3.0, 4.0, 5.0, 6.0), float)),
        ("empty lambda (timer floor)", lambda: None),
    ]
    return [{"operation": name, "us": median_us(function, samples)} for name, function in entries]


def markdown(result):
    lines = []
    for table in result["stages"]:
        lines += [f"### {table['robot']} (n = {table['joints']}, m = {table['force_rows']})", "",
                  f"tick {table['tick_us']:.1f} us (IDC {table['idc_tick_us']:.1f} us), law {table['law_us']:.1f} us, "
                  f"plant calls {table['plant_calls_us']:.1f} us, compiled functions {table['compiled_functions_us']:.1f}"
                  f" us ({table['compiled_functions_bare_us']:.1f} us of generated code)", "",
                  "| stage | category | us | % of tick |", "|---|---|---:|---:|"]
        for row in table["stages"]:
            lines.append(f"| {row['stage']} | {row['category']} | {row['us']:.1f} | "
                         f"{100 * row['us'] / table['tick_us']:.0f} |")
        lines += ["", "Framework pieces timed directly:", "", "| piece | us |", "|---|---:|"]
        lines += [f"| {k} | {v:.1f} |" for k, v in table["framework_direct_us"].items()]
        lines.append("")
    for profile in result["cprofile"]:
        lines += [f"### cProfile own time by category, {profile['robot']} (us per tick, profiler-inflated)", "",
                  "| category | us |", "|---|---:|"]
        lines += [f"| {k} | {v:.1f} |" for k, v in profile["categories_us_per_tick"].items()]
        lines += ["", "| own us | calls/tick | function |", "|---:|---:|---|"]
        lines += [f"| {t['own_us_per_tick']} | {t['calls_per_tick']} | `{t['function']}` |"
                  for t in profile["top_functions"][:12]]
        lines.append("")
    lines += ["### Small-matrix costs on this machine", "", "| operation | us |", "|---|---:|"]
    lines += [f"| {row['operation']} | {row['us']:.2f} |" for row in result["numpy"]]
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", nargs="+", default=["planar-3r", "ur5e"])
    parser.add_argument("--samples", type=int, default=3000)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(0)
    result = {"stages": [stage_table(name, args.samples, rng) for name in args.robots],
              "cprofile": [cprofile_categories(name, args.samples, rng) for name in args.robots],
              "numpy": numpy_costs(args.samples * 3)}
    print(markdown(result))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
