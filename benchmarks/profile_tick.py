"""Where a controller tick's time goes, alone and inside a closed-loop simulation step.

    python benchmarks/profile_tick.py [--robots planar-3r ur5e panda] [--tasks window-washing ...]
                                      [--samples 3000] [--duration 0.5] [--json FILE]

1. **The tick alone** (the continuous float controller of ``robots.py``, fresh state before every
   call, as ``tick.py`` times it): each part of the compiled path timed on its own by the median of
   ``samples`` calls, in the order the tick makes them. Drake calls: the state set into the
   controller's plant context (with its finite check), the force elements, the end-effector pose,
   J_g, the bias acceleration, the inverse dynamics (each after a fresh state, so they pay for the
   kinematics as in a tick); compiled calls: the constraint module (``terms_into``), the law
   (``law_from_terms``) and ``finish_inverse_dynamics``; the rest of the tick (the tick minus these)
   is the systems framework and the controller's Python glue (the two Python callbacks, five input
   reads, the integrals, the solution object, the output copy).
2. **Inside a simulation** (``in_simulation.py``): the task's default closed loop with its Python
   systems' calculations timed, per step: the law, the controller's update, the sensor, the contact
   results the sensor reads, the source and the rest (the plant step, the simulator, the loggers);
   and the law per evaluation against the same controller's law timed alone.

Findings and what is left: PROFILE.md.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import in_simulation  # noqa: E402
from robots import make_robot  # noqa: E402
from tick import fix_inputs, hybrid_evaluation, interleaved, inverse_dynamics_evaluation  # noqa: E402

from pydrake.multibody.tree import JacobianWrtVariable  # noqa: E402

from drake_hybrid.core.kinematics import set_plant_state  # noqa: E402

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


def tick_parts(name, samples=3000, seed=0):
    """{part: median us} of robot ``name``'s tick (module docstring, section 1)."""
    rng = np.random.default_rng(seed)
    robot = make_robot(name)
    controller = robot.controller
    fast = controller.fast_law
    if fast is None:
        raise RuntimeError(f"{name}: the controller runs the generic law (numba unavailable?)")
    context = controller.CreateDefaultContext()
    fix_inputs(controller, context, robot.inputs)
    controller.GetOutputPort("actuation").Eval(context)                # compile or load the kernels
    tick, idc = interleaved([hybrid_evaluation(robot, rng), inverse_dynamics_evaluation(robot, rng)], samples,
                            samples // 10)
    plant = controller.plant()
    cache = controller._solution_cache.Eval(context)
    plant_context, forces = cache.plant_context, cache.forces
    n = plant.num_velocities()

    def fresh():
        plant.SetPositionsAndVelocities(plant_context, robot.state + PERTURBATION * rng.standard_normal(2 * n))

    world, frame, point = plant.world_frame(), fast._frame, fast._point
    port = controller.get_estimated_state_input_port()
    parts = {
        "state into the plant context": median_us(
            lambda: set_plant_state(controller, plant, port, context, plant_context), samples),
        "force elements": median_us(lambda: plant.CalcForceElementsContribution(plant_context, forces), samples,
                                    fresh),
        "pose X_WE": median_us(lambda: plant.CalcRelativeTransform(plant_context, world, frame).GetAsMatrix34(),
                               samples, fresh),
        "J_g": median_us(lambda: plant.CalcJacobianSpatialVelocity(
            plant_context, JacobianWrtVariable.kV, frame, point, world, world), samples, fresh),
        "bias acceleration": median_us(lambda: plant.CalcBiasSpatialAcceleration(
            plant_context, JacobianWrtVariable.kV, frame, point, world, world).get_coeffs(), samples, fresh),
        "inverse dynamics": median_us(lambda: plant.CalcInverseDynamics(plant_context, np.zeros(n), forces),
                                      samples, fresh),
    }
    fresh()
    X = plant.CalcRelativeTransform(plant_context, world, frame).GetAsMatrix34()
    J_g = plant.CalcJacobianSpatialVelocity(plant_context, JacobianWrtVariable.kV, frame, point, world, world)
    A = plant.CalcBiasSpatialAcceleration(plant_context, JacobianWrtVariable.kV, frame, point, world,
                                          world).get_coeffs()
    v = robot.state[n:].copy()
    inputs = robot.inputs
    integrals = controller._integrals(context)
    phase = int(controller._contact_phase(context))
    M, base = fast._empty_matrix, fast._empty_vector
    if fast._needs_mass_matrix:
        M = plant.CalcMassMatrix(plant_context)
    if fast._redundant:
        base = plant.CalcInverseDynamics(plant_context, np.zeros(n), forces)
    if fast._needs_mass_matrix or fast._redundant:
        parts["mass matrix / h + g"] = median_us(lambda: plant.CalcMassMatrix(plant_context), samples, fresh)
    parts["compiled: constraint terms"] = median_us(
        lambda: fast._terms_into(fast._terms, X, J_g, A, v, fast.reals, fast.ints), samples)

    def law():
        return fast._law(fast._terms, v, inputs["desired_velocity"], inputs["desired_acceleration"],
                         inputs["desired_force"], inputs["measured_wrench"], integrals, phase, M, base, fast.reals,
                         fast.ints)

    parts["compiled: law"] = median_us(law, samples)
    status, out = law()
    if not fast._redundant:
        torque = np.zeros(n)
        parts["compiled: finish"] = median_us(lambda: fast._finish(out, torque, base, fast.reals, fast.ints),
                                              samples)
    accounted = sum(parts.values())
    return {"robot": name, "tick_us": tick.median_us, "idc_us": idc.median_us, "ratio": tick.median_us / idc.median_us,
            "parts_us": parts, "framework_and_glue_us": tick.median_us - accounted}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", nargs="+", default=["planar-3r", "ur5e", "panda"])
    parser.add_argument("--tasks", nargs="+", default=["window-washing", "sphere-polishing", "crank-turning",
                                                       "grinding"])
    parser.add_argument("--samples", type=int, default=3000)
    parser.add_argument("--duration", type=float, default=0.5, help="simulated seconds per task")
    parser.add_argument("--json", type=Path, help="also write the figures to this file")
    args = parser.parse_args(argv)
    results = {"tick": {}, "in_simulation": {}}
    for name in args.robots:
        r = results["tick"][name] = tick_parts(name, args.samples)
        print(f"\n{name}: tick {r['tick_us']:.1f} us, IDC {r['idc_us']:.1f} us, ratio {r['ratio']:.1f}")
        for part, us in r["parts_us"].items():
            print(f"  {part:32s} {us:6.2f} us")
        print(f"  {'framework and glue (the rest)':32s} {r['framework_and_glue_us']:6.2f} us")
    for name in args.tasks:
        results["in_simulation"][name] = in_simulation.measure_task(name, duration=args.duration)
    print()
    print("\n".join(in_simulation.table(results["in_simulation"])))
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    return results


if __name__ == "__main__":
    main()
