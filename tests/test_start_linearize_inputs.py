"""Bad input to the start and linearization functions of a built diagram: one-line typed errors naming
the argument, before any Drake call that could abort the process; a state that is not an equilibrium
refused by the linearization with its likely cause; a start far off C = 0 without a guarded move
refused by the controller when the Simulator initializes."""

import math

import numpy as np
import pytest

from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator

from drake_hybrid.analysis.discrete_linearization import linearize_discrete
from drake_hybrid.analysis.linearization import (Linearization, equilibrium_config, linearize_at_contact,
                                                 linearize_continuous)
from drake_hybrid.analysis.matching import match_eigenvalues, predicted_match
from drake_hybrid.cli import main
from drake_hybrid.core.errors import ArgumentError, NotAtEquilibriumError, OffConstraintError, UnreachablePoseError
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.station.clearance import check_robot_clearance, robot_penetrations
from drake_hybrid.station.contact_start import rest_contact_wrench, solve_contact_start
from drake_hybrid.station.sensing import WristSensorConfig
from drake_hybrid.systems.sources import Profile
from drake_hybrid.tasks.registry import get_task

WINDOW = get_task("window-washing")


def started(config):
    scenario = build_scenario(config, with_loggers=False)
    context = scenario.diagram.CreateDefaultContext()
    set_initial_conditions(scenario, context)
    return scenario, context


@pytest.fixture(scope="module")
def discrete():
    """The window task's discrete station at its start."""
    return started(WINDOW.default_config(duration=0.1))


@pytest.fixture(scope="module")
def continuous():
    """The window task's continuous closed loop (what linearize_continuous builds) at its start."""
    return started(equilibrium_config(WINDOW.default_config()))


@pytest.fixture(scope="module")
def start(discrete):
    """(start_pose, joint_guess) of the discrete station's start: E's pose and the arm's positions."""
    scenario, context = discrete
    plant_context = scenario.plant.GetMyContextFromRoot(context)
    X_WE = scenario.plant.GetFrameByName(scenario.robot.end_effector_frame).CalcPoseInWorld(plant_context)
    return X_WE, scenario.plant.GetPositions(plant_context, scenario.robot.arm)


BAD_Q = ["short", "home", None, [[0.0] * 3] * 2, "nan"]
BAD_TOLERANCE = [-1.0, math.nan, math.inf, "x", None]


@pytest.mark.parametrize("q", BAD_Q)
@pytest.mark.parametrize("function, caller", [(robot_penetrations, "robot_penetrations"),
                                              (lambda d, c, s, q: check_robot_clearance(d, c, s, q, "a start"),
                                               "a start")])
def test_clearance_refuses_a_q_that_is_not_the_arms_finite_positions(discrete, function, caller, q):
    scenario, context = discrete
    size = scenario.plant.num_positions(scenario.robot.arm)
    q = {"nan": [math.nan] * size, "short": [0.0] * (size - 1)}.get(q, q) if isinstance(q, str) else q
    with pytest.raises(ArgumentError, match=rf"^{caller}: q must be a vector of \d+ finite numbers"):
        function(scenario.diagram, context, scenario, q)


@pytest.mark.parametrize("tolerance", BAD_TOLERANCE)
def test_clearance_refuses_a_tolerance_that_is_not_finite_and_nonnegative(discrete, start, tolerance):
    scenario, context = discrete
    with pytest.raises(ArgumentError, match=r"robot_penetrations: tolerance must be a finite number >= 0"):
        robot_penetrations(scenario.diagram, context, scenario, start[1], tolerance=tolerance)


def test_clearance_of_the_start_is_clear(discrete, start):
    scenario, context = discrete
    assert robot_penetrations(scenario.diagram, context, scenario, start[1]) == []


@pytest.mark.parametrize("p_WP", [[math.nan] * 3, [0.0, 0.0], "x", None, [[0.0] * 3]])
def test_rest_contact_wrench_refuses_a_point_that_is_not_three_finite_numbers(discrete, p_WP):
    scenario, context = discrete
    plant_context = scenario.plant.GetMyContextFromRoot(context)
    with pytest.raises(ArgumentError, match="rest_contact_wrench: p_WP must be a vector of 3 finite numbers"):
        rest_contact_wrench(scenario.plant, plant_context, scenario.robot.pad_geometries, p_WP)


def test_rest_contact_wrench_refuses_a_context_that_is_not_the_plants(discrete):
    scenario, context = discrete
    with pytest.raises(ArgumentError, match="rest_contact_wrench: plant_context must be the plant's own context"):
        rest_contact_wrench(scenario.plant, context, scenario.robot.pad_geometries, np.zeros(3))


def mismatched(discrete, continuous, which):
    """(diagram, root_context, systems) with ``which`` of them wrong, and the argument the error names."""
    scenario, context = discrete
    other, other_context = continuous
    return {"systems_none": ((scenario.diagram, context, None), "systems must be the HybridSystems"),
            "diagram_none": ((None, context, scenario), "diagram must be a built Diagram"),
            "context_none": ((scenario.diagram, None, scenario), "root_context must be the diagram's root Context"),
            "other_context": ((scenario.diagram, other_context, scenario), "root_context must be the root context of"),
            "subsystem_context": ((scenario.diagram, scenario.plant.GetMyContextFromRoot(context), scenario),
                                  "root_context must be the root context of"),
            "other_systems": ((scenario.diagram, context, other), "systems.plant is not in diagram")}[which]


WRONG = ["systems_none", "diagram_none", "context_none", "other_context", "subsystem_context", "other_systems"]


@pytest.mark.parametrize("which", WRONG)
def test_solve_contact_start_and_clearance_refuse_parts_that_do_not_belong_together(discrete, continuous, start,
                                                                                     which):
    (diagram, context, systems), words = mismatched(discrete, continuous, which)
    with pytest.raises(ArgumentError, match=f"solve_contact_start: {words}"):
        solve_contact_start(diagram, context, systems, *start)
    with pytest.raises(ArgumentError, match=f"robot_penetrations: {words}"):
        robot_penetrations(diagram, context, systems, start[1])


@pytest.mark.parametrize("which", WRONG)
def test_linearize_at_contact_refuses_parts_that_do_not_belong_together(discrete, continuous, which):
    # the continuous loop with the discrete one's parts swapped in
    (diagram, context, systems), words = mismatched(continuous, discrete, which)
    with pytest.raises(ArgumentError, match=rf"linearize_at_contact\(your diagram\): {words}"):
        linearize_at_contact(diagram, context, systems)


def test_solve_contact_start_names_start_pose_when_the_inverse_kinematics_fails(discrete, start):
    scenario, _ = discrete
    X_WE, guess = start
    far = RigidTransform(X_WE.rotation(), X_WE.translation() + [0.0, 0.0, 3.0])
    with pytest.raises(UnreachablePoseError, match="solve_contact_start: start_pose is not reached from joint_guess"):
        solve_contact_start(scenario.diagram, scenario.diagram.CreateDefaultContext(), scenario, far, guess)


def test_solve_contact_start_names_desired_force_when_the_contact_cannot_give_it(discrete, start):
    scenario, _ = discrete
    huge = 1e6 * np.sign(scenario.config.desired_force.evaluate(0.0)[0])       # pushing, far beyond the pad
    with pytest.raises(ArgumentError, match=r"solve_contact_start: max_depth = 0.001 m of penetration presses with only .* "
                                           r"less than \|desired_force\|"):
        solve_contact_start(scenario.diagram, scenario.diagram.CreateDefaultContext(), scenario, *start,
                            desired_force=huge, max_depth=1e-3)


def test_solve_contact_start_refuses_a_wrist_sensor_on_a_continuous_plant(start):
    config = equilibrium_config(WINDOW.default_config())
    config.sensor = WristSensorConfig(bandwidth_hz=200.0, compensate_tool_inertia=True)
    scenario = build_scenario(config, with_loggers=False)
    with pytest.raises(ArgumentError, match="solve_contact_start: systems has a WristForceTorqueSensor on a "
                                            "continuous plant"):
        solve_contact_start(scenario.diagram, scenario.diagram.CreateDefaultContext(), scenario, *start)


@pytest.mark.parametrize("name, bad", [("tolerance", value) for value in (math.nan, -1.0, 0.0, 1.5, "0.05", None)]
                         + [("jacobian_tolerance", value) for value in (math.nan, -1.0, 0.0, "x", None)]
                         + [("require_equilibrium", value) for value in ("yes", 1, None)])
def test_linearize_at_contact_refuses_bad_tolerances_and_flags(continuous, name, bad):
    scenario, context = continuous
    with pytest.raises(ArgumentError, match=rf"linearize_at_contact\(your diagram\): {name} must be"):
        linearize_at_contact(scenario.diagram, context, scenario, **{name: bad})


def test_linearize_at_contact_refuses_a_start_that_was_not_solved(continuous):
    scenario, _ = continuous
    with pytest.raises(NotAtEquilibriumError, match=r"not an equilibrium: max \|x-dot\| = .*solve_contact_start"):
        linearize_at_contact(scenario.diagram, scenario.diagram.CreateDefaultContext(), scenario)


@pytest.fixture(scope="module")
def sliding():
    """The continuous window loop at its start, but commanded to slide at 3 cm/s."""
    config = equilibrium_config(WINDOW.default_config())
    size = len(config.desired_velocity.evaluate(0.0)[0])
    config.desired_velocity = Profile(kind="constant", value=[0.03] + [0.0] * (size - 1))
    return started(config)


def test_linearize_at_contact_names_a_commanded_motion(sliding):
    scenario, context = sliding
    with pytest.raises(NotAtEquilibriumError, match="likely cause: the controller is commanded to move "
                                                    r"\(desired_velocity = \[0.03"):
        linearize_at_contact(scenario.diagram, context, scenario)


def test_linearize_at_contact_linearizes_off_equilibrium_only_when_asked(sliding):
    scenario, context = sliding
    result = linearize_at_contact(scenario.diagram, context, scenario, require_equilibrium=False)
    assert isinstance(result, Linearization) and result.equilibrium_residual > 0.01


@pytest.mark.parametrize("kwargs, name", [({"tolerance": math.nan}, "tolerance"), ({"tolerance": 2.0}, "tolerance"),
                                          ({"bandwidth_hz": -1.0}, "bandwidth_hz"), ({"tolerance": "0.05"}, "tolerance")])
def test_linearize_continuous_checks_its_arguments_before_building(kwargs, name):
    with pytest.raises(ArgumentError, match=f"linearize_continuous: {name} must be"):
        linearize_continuous(WINDOW.default_config(), **kwargs)


def test_linearize_continuous_refuses_a_config_that_is_not_one():
    with pytest.raises(ArgumentError, match="linearize_continuous: config must be a ScenarioConfig"):
        linearize_continuous({"task": "window-washing"})


@pytest.mark.parametrize("kwargs, name", [({"tolerance": -1.0}, "tolerance"), ({"epsilon": 0.0}, "epsilon"),
                                          ({"settle_time": math.nan}, "settle_time")])
def test_linearize_discrete_checks_its_arguments_before_building(kwargs, name):
    with pytest.raises(ArgumentError, match=f"linearize_discrete: {name} must be"):
        linearize_discrete(get_task("crank-turning").default_config(), **kwargs)


@pytest.mark.parametrize("tolerance", [math.nan, -0.1, 0.0, 3.0, "0.05"])
def test_eigenvalue_matching_takes_a_relative_tolerance(tolerance):
    with pytest.raises(ArgumentError, match="match_eigenvalues: tolerance must be a finite number > 0 and <= 1"):
        match_eigenvalues([-10.0], [-10.0, 0.0], tolerance=tolerance)
    with pytest.raises(ArgumentError, match="predicted_match: tolerance must be a finite number > 0 and <= 1"):
        predicted_match(object(), tolerance=tolerance)


@pytest.mark.parametrize("tolerance", ["nan", "-1", "0", "2"])
def test_analyze_refuses_the_same_tolerances(capsys, tolerance):
    assert main(["analyze", "window-washing", "--tolerance", tolerance]) == 2
    assert "--tolerance must be a finite number > 0 and <= 1" in capsys.readouterr().err


def test_the_controller_refuses_a_start_far_off_the_constraint_without_a_guarded_move(discrete):
    """A Simulator on a default context (the start never solved): the arm at its default positions, the pad
    far from C = 0, no supervisor."""
    scenario, _ = discrete
    simulator = Simulator(scenario.diagram, scenario.diagram.CreateDefaultContext())
    with pytest.raises(OffConstraintError, match=r"HybridController: the start is off the constraint: C = .* "
                                                 r"with no guarded move.*solve_contact_start"):
        simulator.Initialize()


def test_the_controller_starts_at_a_solved_start_and_at_a_gap_with_a_guarded_move(discrete):
    scenario, context = discrete
    Simulator(scenario.diagram, context.Clone()).Initialize()
    config = WINDOW.default_config(duration=0.1)
    config.start.in_contact = False               # a gap away, the supervisor's guarded approach
    gap, gap_context = started(config)
    assert gap.supervisor is not None
    Simulator(gap.diagram, gap_context).Initialize()
