"""Checks of the benchmark harness itself, run with the suite (pyproject's ``testpaths``; alone:
``pytest benchmarks/test_harness.py``, about 25 s; the UR5e and Panda cases need the test or bench
extra).

They guard the claims the figures rest on: every timed tick really evaluates
the law (no cached result), the plant-alone replay and python_floor.py's
floor replay do the closed loop's plant work (they reproduce the closed loop's
motion exactly), and the tick floor makes the Drake calls it claims to.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from pydrake.multibody.tree import MultibodyForces

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import realtime_tick  # noqa: E402
from robots import make_robot  # noqa: E402
from tick import hybrid_evaluation, inverse_dynamics_evaluation, sampled_update_evaluation  # noqa: E402


def _count_law_calls(controller):
    calls = []
    law = controller._evaluate_law

    def counted(*arguments):
        calls.append(1)
        return law(*arguments)

    controller._evaluate_law = counted
    return calls


@pytest.mark.parametrize("control_period", [None, 1e-3])
def test_every_timed_tick_evaluates_the_law_once(control_period):
    robot = make_robot("planar-3r", control_period=control_period)
    calls = _count_law_calls(robot.controller)
    rng = np.random.default_rng(0)
    evaluation = (hybrid_evaluation if control_period is None else sampled_update_evaluation)(robot, rng)
    for _ in range(25):
        evaluation()
    assert len(calls) == 25


def test_the_timed_tick_runs_the_compiled_law_without_falling_back():
    robot = make_robot("planar-3r")
    evaluation = hybrid_evaluation(robot, np.random.default_rng(0))
    for _ in range(25):
        evaluation()
    fast_law = robot.controller.fast_law
    assert fast_law is not None and fast_law.compile_seconds is not None and fast_law.fallbacks == 0


def test_every_timed_idc_tick_sees_a_new_state():
    robot = make_robot("planar-3r")
    evaluation = inverse_dynamics_evaluation(robot, np.random.default_rng(0))
    output_port = evaluation.evaluate.__self__            # the port whose Eval is timed
    torques = []
    for _ in range(5):
        evaluation()
        torques.append(output_port.Eval(evaluation.context).copy())
    assert all(np.any(a != b) for a, b in zip(torques, torques[1:]))


@pytest.fixture(scope="module")
def window_run():
    """(config, log) of 0.3 s of the window task's default closed loop."""
    from drake_hybrid.experiments.simulation import simulate
    from drake_hybrid.tasks.registry import get_task

    config = get_task("window-washing").default_config()
    config.duration = 0.3
    return config, simulate(config).log


@pytest.mark.slow
def test_torque_replay_reproduces_the_closed_loop_motion_exactly(window_run):
    from closed_loop import plant_alone_rtf

    config, log = window_run
    rtf, contacts, drift = plant_alone_rtf(config, "replay", log)
    assert drift == 0.0
    assert contacts >= 1 and rtf > 0


@pytest.mark.slow
def test_the_python_floor_replay_reproduces_the_closed_loop_motion_exactly(window_run):
    """python_floor.py's closed-loop floor (one Python update per tick reading the state and the contact
    results, holding the logged torque) does the closed loop's plant work: same motion, in contact."""
    from python_floor import replay_floor_rtf

    config, log = window_run
    for sampled_outputs in (False, True):
        rtf, drift = replay_floor_rtf(config, log, sampled_outputs)
        assert drift == 0.0 and rtf > 0


def test_the_tick_floor_makes_the_drake_calls_and_sees_a_new_state():
    """python_floor.py's tick floor returns the plant's inverse dynamics at the fresh state it was given."""
    from python_floor import floor_evaluation

    robot = make_robot("ur5e")
    evaluation = floor_evaluation(robot, np.random.default_rng(0))
    output_port = evaluation.evaluate.__self__
    torques = []
    for _ in range(3):
        evaluation()
        torques.append(output_port.Eval(evaluation.context).copy())
        plant_context = robot.plant.CreateDefaultContext()
        robot.plant.SetPositionsAndVelocities(plant_context, evaluation.state_port.Eval(evaluation.context))
        forces = MultibodyForces(robot.plant)
        robot.plant.CalcForceElementsContribution(plant_context, forces)
        expected = robot.plant.CalcInverseDynamics(plant_context, np.zeros(robot.plant.num_velocities()), forces)
        np.testing.assert_allclose(torques[-1], expected, rtol=1e-12, atol=1e-12)
    assert all(np.any(a != b) for a, b in zip(torques, torques[1:]))


def test_the_in_simulation_profile_times_one_law_evaluation_and_one_contact_read_per_step():
    """The closed loop's parts are timed where they run (one law evaluation per step with sampled
    diagnostics; the plant's sampled contact results read once a step, by the wrench logger after the
    step, the tick reusing the sensor's value), the parts do not exceed the step, and the timing
    wrappers are gone from the classes afterwards."""
    import in_simulation

    from drake_hybrid.control.controller import HybridController_

    original = HybridController_[float].__dict__["_calc_solution"]
    result = in_simulation.measure_task("window-washing", duration=0.05)
    parts = result["parts"]
    assert parts["law"]["per_step_calls"] == 1.0 and parts["update"]["per_step_calls"] == 1.0
    assert parts["contact results"]["per_step_calls"] == 1.0
    assert result["rest_per_step_us"] > 0
    assert HybridController_[float].__dict__["_calc_solution"] is original


def test_the_real_time_benchmark_writes_its_section(tmp_path):
    """realtime_tick.py on a short replay: every run it compares is there with its figures, and its
    section of RESULTS.md is replaced, not repeated, when it runs again."""
    pytest.importorskip("cmeel")      # the Panda
    result = realtime_tick.measure(seconds=0.03, compare=True, log=lambda line: None)
    assert set(result["runs"]) == set(realtime_tick.RUNS)
    for run in result["runs"].values():
        assert run["ticks_at_rate"] == 30 and run["commands_published"] == 31 and run["stop"] is None
        assert set(run["tick_parts_s"]) == set(realtime_tick.PARTS)
    path = tmp_path / "RESULTS.md"
    path.write_text("# drake_hybrid performance benchmarks\n\n## Targets\n\n| a | b |\n")
    realtime_tick.write_results_md(result, path)
    realtime_tick.write_results_md(result, path)
    text = path.read_text()
    assert text.count(realtime_tick.SECTION) == 1 and text.index("## Targets") < text.index(realtime_tick.SECTION)
    assert "| real-time settings |" in text and "| stepped by a Simulator |" in text
