"""What any controller written as a Python LeafSystem costs, before it computes anything.

    python benchmarks/python_floor.py [--robots planar-3r ur5e panda] [--tasks window-washing ...]
                                      [--samples 3000] [--repeats 3] [--json FILE]

The performance targets are a tick within 4x of Drake's C++ ``InverseDynamicsController`` and a closed
loop at 0.8 of the plant alone's real-time factor. This script measures the floor under both: the
same figures for Python systems that do only what a force controller cannot avoid, and no law.

1. **Tick floor.** ``FloorController``: one Python output callback that reads the estimated state
   and the four command ports and makes the Drake calls the law needs (the state into a plant
   context, the force elements, the end-effector pose, J_g, the bias acceleration J_g-dot v and one
   inverse dynamics), then writes the inverse dynamics' torque; no numerics of its own. Timed as
   ``tick.py`` times the controller: a fresh state before every evaluation, interleaved sample by
   sample with the IDC and the library's controller on the same plant. Two lighter variants show
   the framework alone: the five port reads without the Drake calls, and the state read alone.
2. **Closed-loop floor.** ``ReplayController``: one Python periodic update per control period that
   reads the plant's state and its contact results (summing the hydroelastic forces: the least a
   contact wrench sensor does) and holds the torque the library's closed loop applied at that tick
   (replayed from its log, so the plant does the same work along the same motion; ``drift`` checks
   it), output by a state output port (no Python callback). Its real-time factor against the plant
   alone replaying the same torques through a C++ ``TrajectorySource`` (``closed_loop.plant_alone_rtf``),
   with the plant's output ports unsampled (a second contact solve per step, docs/drake_notes.md)
   and sampled (what the library uses: one solve per step).

Results: printed, and written to ``results/python_floor.json``; PROFILE.md section 0d discusses them.
"""

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from closed_loop import plant_alone_rtf  # noqa: E402
from robots import make_robot  # noqa: E402
from tick import FreshEvaluation, hybrid_evaluation, interleaved, inverse_dynamics_evaluation  # noqa: E402

from pydrake.common.value import AbstractValue  # noqa: E402
from pydrake.multibody.plant import ContactResults  # noqa: E402
from pydrake.multibody.tree import JacobianWrtVariable, MultibodyForces  # noqa: E402
from pydrake.systems.analysis import Simulator  # noqa: E402
from pydrake.systems.framework import DiagramBuilder, LeafSystem  # noqa: E402

from drake_hybrid.control.sampling import SAMPLE_LEAD  # noqa: E402
from drake_hybrid.experiments.simulation import simulate  # noqa: E402
from drake_hybrid.scenario.builder import build_scenario  # noqa: E402
from drake_hybrid.tasks.plant import build_plant
from drake_hybrid.tasks.registry import get_task

COMMAND_PORTS = ("desired_velocity", "desired_acceleration", "desired_force", "measured_wrench")


class FloorController(LeafSystem):
    """The Drake calls of a law tick and nothing else.

    ::

                          +-----------------+
        estimated_state ->|                 |
        desired_velocity->|                 |
        desired_accel.  ->| FloorController |-> actuation (inverse dynamics at zero acceleration)
        desired_force   ->|                 |
        measured_wrench ->|                 |
                          +-----------------+

    ``drake_calls`` False: the port reads only; ``commands`` False: the state port only."""

    def __init__(self, plant, frame, point, drake_calls=True, commands=True):
        super().__init__()
        n = plant.num_velocities()
        self._plant, self._frame, self._point, self._world = plant, frame, point, plant.world_frame()
        self._plant_context = plant.CreateDefaultContext()
        self._forces = MultibodyForces(plant)
        self._zero = np.zeros(n)
        self._drake_calls, self._n = drake_calls, n
        self._state = self.DeclareVectorInputPort("estimated_state", 2 * n)
        self._commands = [self.DeclareVectorInputPort(name, 6) for name in COMMAND_PORTS] if commands else []
        self.DeclareVectorOutputPort("actuation", n, self._calc)

    def _calc(self, context, output):
        state = self._state.Eval(context)
        for port in self._commands:
            port.Eval(context)
        if not self._drake_calls:
            output.SetFromVector(state[:self._n])
            return
        plant, plant_context, world, frame, point = (self._plant, self._plant_context, self._world, self._frame,
                                                     self._point)
        plant.SetPositionsAndVelocities(plant_context, state)
        plant.CalcForceElementsContribution(plant_context, self._forces)
        plant.CalcRelativeTransform(plant_context, world, frame).GetAsMatrix34()
        plant.CalcJacobianSpatialVelocity(plant_context, JacobianWrtVariable.kV, frame, point, world, world)
        plant.CalcBiasSpatialAcceleration(plant_context, JacobianWrtVariable.kV, frame, point, world, world)
        output.SetFromVector(plant.CalcInverseDynamics(plant_context, self._zero, self._forces))


def floor_evaluation(robot, rng, **variant):
    controller = robot.controller
    floor = FloorController(robot.plant, controller.kinematics.frame, controller._end_effector_point, **variant)
    context = floor.CreateDefaultContext()
    for name in COMMAND_PORTS if variant.get("commands", True) else ():
        floor.GetInputPort(name).FixValue(context, np.zeros(6))
    return FreshEvaluation(floor.GetInputPort("estimated_state"), context, robot.state,
                           floor.GetOutputPort("actuation").Eval, rng)


def measure_tick_floor(name, samples=3000, warmup=300, seed=0):
    rng = np.random.default_rng(seed)
    robot = make_robot(name)
    timings = interleaved([hybrid_evaluation(robot, rng), inverse_dynamics_evaluation(robot, rng),
                           floor_evaluation(robot, rng), floor_evaluation(robot, rng, drake_calls=False),
                           floor_evaluation(robot, rng, drake_calls=False, commands=False)], samples, warmup)
    controller, idc, floor, ports, state = (t.median_us for t in timings)
    return {"controller_us": controller, "idc_us": idc, "floor_us": floor, "ports_only_us": ports,
            "state_only_us": state, "controller_ratio": controller / idc, "floor_ratio": floor / idc,
            "budget_left_at_4x_us": 4 * idc - floor}


class ReplayController(LeafSystem):
    """One Python update per control period: reads the state and the contact results, holds a logged torque.

    ::

                         +------------------+
        state          ->|                  |
        contact_results->| ReplayController |-> actuation (discrete state: the torque of this tick)
                         +------------------+
    """

    def __init__(self, times, torques, state_size, period):
        super().__init__()
        self._times, self._torques, self._period = times, torques, period
        self._state = self.DeclareVectorInputPort("state", state_size)
        self._contact = self.DeclareAbstractInputPort("contact_results", AbstractValue.Make(ContactResults()))
        held = self.DeclareDiscreteState(torques.shape[1])
        # Ticks at k h - delta, as the library's sampled controller (control/sampling.py), so the plant's
        # step at k h applies the torque of tick k, as in the closed loop the log comes from.
        self.DeclarePeriodicDiscreteUpdateEvent(period, period * (1.0 - SAMPLE_LEAD), self._tick)
        self.DeclareInitializationDiscreteUpdateEvent(self._tick)
        self.DeclareStateOutputPort("actuation", held)

    def _tick(self, context, discrete_state):
        self._state.Eval(context)
        results = self._contact.Eval(context)
        force = np.zeros(3)
        for i in range(results.num_hydroelastic_contacts()):
            force += results.hydroelastic_contact_info(i).F_Ac_W().translational()
        k = np.searchsorted(self._times, context.get_time() + 0.5 * self._period, side="right") - 1
        discrete_state.get_mutable_vector(0).SetFromVector(self._torques[min(max(k, 0), len(self._times) - 1)])


def replay_floor_rtf(config, log, sampled_outputs):
    """(real-time factor, max |q - q_log| at the end) of the plant with a ReplayController."""
    task = get_task(config.task)
    q0 = task.start_positions(build_scenario(config, with_loggers=False))
    builder = DiagramBuilder()
    plant, _, robot = build_plant(task, config, builder, sampled_outputs=sampled_outputs)
    times, first = np.unique(log["t"], return_index=True)
    replay = builder.AddSystem(ReplayController(times, log["torque"][first], plant.num_multibody_states(),
                                                float(config.control_period)))
    builder.Connect(plant.get_state_output_port(), replay.GetInputPort("state"))
    builder.Connect(plant.get_contact_results_output_port(), replay.GetInputPort("contact_results"))
    builder.Connect(replay.get_output_port(), plant.get_actuation_input_port(robot.arm))
    simulator = Simulator(builder.Build())
    plant_context = plant.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    plant.SetPositions(plant_context, robot.arm, q0)
    simulator.Initialize()
    start = time.perf_counter()
    simulator.AdvanceTo(float(config.duration))
    wall = time.perf_counter() - start
    drift = float(np.max(np.abs(plant.GetPositions(plant_context, robot.arm) - log["q"][-1])))
    return float(config.duration) / wall, drift


def measure_rtf_floor(name, repeats=3):
    config = get_task(name).default_config()
    log = simulate(config).log
    samples = {"closed_loop": [], "plant_alone": [], "floor_unsampled": [], "floor_sampled": []}
    drifts = {"plant_alone": 0.0, "floor_unsampled": 0.0, "floor_sampled": 0.0}
    for _ in range(repeats):                                       # alternated, so load hits all alike
        samples["closed_loop"].append(simulate(config).summary.real_time_factor)
        rtf, _, drifts["plant_alone"] = plant_alone_rtf(config, "replay", log)
        samples["plant_alone"].append(rtf)
        for key, sampled in (("floor_unsampled", False), ("floor_sampled", True)):
            rtf, drifts[key] = replay_floor_rtf(config, log, sampled)
            samples[key].append(rtf)
    medians = {key: statistics.median(values) for key, values in samples.items()}
    alone = medians["plant_alone"]
    return {"rtf": medians, "ratio": {key: value / alone for key, value in medians.items()}, "drift": drifts,
            "samples": samples}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--robots", nargs="+", default=["planar-3r", "ur5e", "panda"])
    parser.add_argument("--tasks", nargs="+", default=["window-washing", "sphere-polishing", "grinding",
                                                        "crank-turning"])
    parser.add_argument("--samples", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--json", type=Path, default=HERE / "results" / "python_floor.json")
    args = parser.parse_args(argv)
    results = {"ticks": {}, "closed_loops": {}}
    print("tick (us, medians of interleaved samples): controller / IDC / floor (Drake calls + ports) / "
          "ports only / state only; ratios to the IDC")
    for name in args.robots:
        r = measure_tick_floor(name, args.samples)
        results["ticks"][name] = r
        print(f"  {name}: {r['controller_us']:.1f} / {r['idc_us']:.1f} / {r['floor_us']:.1f} / "
              f"{r['ports_only_us']:.1f} / {r['state_only_us']:.1f}; controller {r['controller_ratio']:.1f}x, "
              f"floor {r['floor_ratio']:.1f}x; at 4x the law and its glue would have "
              f"{r['budget_left_at_4x_us']:.1f} us")
    print("closed loop (real-time factor / plant alone's, medians): library / floor, unsampled ports / floor, "
          "sampled ports")
    for name in args.tasks:
        r = measure_rtf_floor(name, args.repeats)
        results["closed_loops"][name] = r
        ratio = r["ratio"]
        print(f"  {name}: plant alone {r['rtf']['plant_alone']:.3g}; library {ratio['closed_loop']:.2f}, "
              f"floor {ratio['floor_unsampled']:.2f} / {ratio['floor_sampled']:.2f} "
              f"(replay drift {max(r['drift'].values()):.3g} rad)")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
