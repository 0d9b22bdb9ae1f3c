"""The law's preconditions, refused before the first step in a user's own diagram (core.preconditions).

A constraint whose rows are dependent everywhere is refused when the ConstraintSpace and the
HybridController are built; a desired force that pulls, or a surface beyond the guarded move's reach, is
refused when the controller first ticks (its initialization event, at ``Simulator.Initialize``), in a
diagram built by hand from Drake's primitives, without the package's Scenario. A force profile that
changes sign over its course is refused where the run's contact is known to push (a guarded approach,
a pressing start), and the diagnostic ports never read a dropout as a perfect match.
"""

import math

import numpy as np
import pytest
from test_api_inputs import window

from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from drake_hybrid import (Constraint, ConstraintRankError, ConstraintSpace, GivenVelocityProjection,
                          KernelVelocityProjection, OffConstraintError, PlanarChart, PoseChart)
from drake_hybrid.control.controller import HybridController
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.control.supervision import SupervisionConfig
from drake_hybrid.core.errors import ConfigError, ForceSignError
from drake_hybrid.core.preconditions import check_generic_rank, check_pushing_force
from drake_hybrid.experiments.metrics import invalid_samples, last_valid, row_errors
from drake_hybrid.scenario.builder import build_scenario, prepare_config
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.systems.sources import Profile
from drake_hybrid.tasks.config import load_config
from drake_hybrid.tasks.registry import TASKS, get_task

PUSHING_WRENCH = [0.0, 0.0, 0.0, 0.0, 0.0, -10.0]     # the pane pushes the pad down: F = -10 along E_f
START = np.array([0.3, 0.5, 0.4])                       # the window arm's joints: the pad at C = +0.169 m
# The window task's start (WINDOW.start_positions, pressing 10 N: C = +0.8 mm): a start in contact without a
# guarded move must be near C = 0 (HybridController refuses one beyond START_CONSTRAINT_LIMIT).
IN_CONTACT = np.array([-0.11392, 1.801882, -0.117166])


def user_diagram(desired_force, wrench, guarded_move=None, phase=ContactPhase.CONTACT, q=START):
    """The window's controller in a diagram of Drake's own primitives: constant state, wrench and commands."""
    plant, robot, space = window()
    builder = DiagramBuilder()
    controller = builder.AddSystem(HybridController(plant, robot.end_effector_frame, robot.end_effector_point, space,
                                                    control_period=1e-3, guarded_move=guarded_move))

    def constant(value, port):
        source = builder.AddSystem(ConstantVectorSource(np.asarray(value, dtype=float)))
        builder.Connect(source.get_output_port(), port)

    constant(np.concatenate([q, np.zeros(3)]), controller.get_estimated_state_input_port())
    constant(wrench, controller.get_measured_wrench_input_port())
    constant([0.0, 0.0], controller.get_desired_velocity_input_port())
    constant([0.0, 0.0], controller.get_desired_acceleration_input_port())
    constant(desired_force, controller.get_desired_force_input_port())
    if guarded_move is not None:
        constant([float(phase)], controller.get_contact_phase_input_port())
        constant([0.0], controller.get_approach_reference_input_port())
    return builder.Build(), controller


# -- a constraint whose rows are dependent everywhere: refused when built ----------------------------------

@pytest.mark.parametrize("rows, match", [
    (lambda x, y, z: [z - 0.1, z - 0.1], "rows 0 and 1 are dependent"),
    (lambda x, y, z: [z - 0.1, 3 * (z - 0.1) + 2], "rows 0 and 1 are dependent"),
    (lambda x, y, z: [x, y, x + y], "its rows are dependent everywhere"),
    (lambda x, y, z: [x * y, 2 * x * y], "rows 0 and 1 are dependent"),
])
def test_dependent_rows_are_refused_when_the_space_is_built(rows, match):
    chart = PoseChart()
    constraint = Constraint(chart, rows(*chart.position))
    with pytest.raises(ConstraintRankError, match=match):
        check_generic_rank(constraint)
    anchor = np.concatenate([[0.3, 0.2, 0.1], np.eye(3).reshape(-1)])
    with pytest.raises(ConstraintRankError):
        ConstraintSpace(constraint, KernelVelocityProjection(constraint, anchor))


def test_a_velocity_projection_dependent_on_the_constraint_everywhere_is_refused():
    chart = PlanarChart()
    x, y, theta = chart.symbols
    window = Constraint(chart, [y - 1.0], name="window")
    with pytest.raises(ConstraintRankError, match=r"E = \[E_p; E_f\] .* is singular at every one of"):
        ConstraintSpace(window, GivenVelocityProjection(chart, [[0, 1, 0], [0, 0, 1]]))
    ConstraintSpace(window, GivenVelocityProjection(chart, [[1, 0, 0], [0, 0, 1]]))       # independent: built


@pytest.mark.parametrize("name", sorted(TASKS))
def test_every_task_constraint_has_full_generic_rank(name):
    task = get_task(name)
    check_generic_rank(task.constraint_space(task.default_config()))


def test_a_rank_deficient_constraint_is_refused_by_the_controller():
    """Also a constraint space that skipped its own check (a user's subclass) is refused when the
    controller is built, not at Simulator.Initialize."""
    plant, robot, space = window()
    chart = space.chart
    x, y, theta = chart.symbols
    doubled = Constraint(chart, [y - 1.0, 2 * y - 2.0], name="doubled")

    class Unchecked(ConstraintSpace):
        def __init__(self, constraint, velocity_projection):
            self.constraint, self.velocity_projection, self.chart = constraint, velocity_projection, constraint.chart
            self.force_size, self.velocity_size, self.invertibility_tolerance = 2, 1, 1e-3

    with pytest.raises(ConstraintRankError, match="constraint 'doubled'"):
        ConstraintSpace(doubled, GivenVelocityProjection(chart, [[1, 0, 0]]))
    with pytest.raises(ConstraintRankError, match="constraint 'doubled': E_f = dC has rank below m = 2"):
        HybridController(plant, robot.end_effector_frame, robot.end_effector_point,
                         Unchecked(doubled, GivenVelocityProjection(chart, [[1, 0, 0]])))


# -- a pulling force: refused at the controller's first tick, in a user's own diagram ----------------------

def test_a_pushing_force_in_contact_starts():
    diagram, _ = user_diagram([-10.0], PUSHING_WRENCH, q=IN_CONTACT)
    Simulator(diagram).Initialize()


def test_a_pulling_force_in_contact_is_refused_at_initialize():
    diagram, _ = user_diagram([10.0], PUSHING_WRENCH, q=IN_CONTACT)
    with pytest.raises(ForceSignError, match=r"F_d = \[10.0\] pulls at the controller's first tick .*CONTACT"):
        Simulator(diagram).Initialize()


def test_check_start_on_a_context_the_user_set_up():
    diagram, controller = user_diagram([10.0], PUSHING_WRENCH, q=IN_CONTACT)
    context = diagram.CreateDefaultContext()
    with pytest.raises(ForceSignError, match="flip the sign of the desired force"):
        controller.check_start(controller.GetMyContextFromRoot(context))


@pytest.mark.parametrize("desired_force, max_travel, error, match", [
    ([10.0], 5.0, None, None),                  # C = +0.169: -F_d = -10 leads to C = 0
    ([-10.0], 5.0, ForceSignError, r"leads away from C = 0 \(the surface is 0.169 behind\)"),
    ([10.0], 0.05, OffConstraintError, r"0.169 \(units of C\) .* beyond the guarded move's max_travel = 0.05"),
])
def test_the_guarded_approach_is_checked_at_initialize(desired_force, max_travel, error, match):
    diagram, _ = user_diagram(desired_force, np.zeros(6), SupervisionConfig(max_travel=max_travel),
                              ContactPhase.APPROACH)
    if error is None:
        Simulator(diagram).Initialize()
    else:
        with pytest.raises(error, match=match):
            Simulator(diagram).Initialize()


def test_check_pushing_force_leaves_an_unknown_case_alone():
    check_pushing_force([0.0], force=[5.0])                                  # no force commanded
    check_pushing_force([-10.0], force=[math.nan])                           # no valid measurement
    check_pushing_force([0.0, -10.0], force=[3.0, -9.0], force_controlled=[0.0, 1.0])
    with pytest.raises(ForceSignError):
        check_pushing_force([0.0, 10.0], force=[-3.0, -9.0], force_controlled=[0.0, 1.0])


# -- force profiles over their whole course ------------------------------------------------------------

@pytest.mark.parametrize("profile, changes", [
    (Profile(kind="constant", value=[-10.0]), False),
    (Profile(kind="smooth_step", value=[-10.0], final_value=[-2.0]), False),
    (Profile(kind="smooth_step", value=[-10.0], final_value=[0.0]), False),
    (Profile(kind="smooth_step", value=[-10.0], final_value=[10.0], start_time=0.5), True),
    (Profile(kind="sine", value=[-10.0], amplitude=[5.0], frequency=1.0), False),
    (Profile(kind="sine", value=[-10.0], amplitude=[-12.0], frequency=1.0), True),
    (Profile(kind="sine", value=[-10.0], amplitude=[12.0], frequency=0.0), False),     # never moves
    (Profile(kind="constant", value=[10.0, 0.0, -3.0]), False),
])
def test_a_force_profile_that_changes_sign_is_refused(profile, changes):
    low, high = profile.bounds()
    samples = np.array([profile.evaluate(t)[0] for t in np.linspace(0, 5, 2001)])
    assert np.all(samples >= low - 1e-12) and np.all(samples <= high + 1e-12)   # the bounds hold every sample
    if changes:
        with pytest.raises(ForceSignError, match="desired_force: row 0 changes sign over its course"):
            profile.check_keeps_sign("desired_force")
    else:
        profile.check_keeps_sign("desired_force")


def test_a_guarded_approach_with_a_force_that_turns_into_a_pull_is_refused():
    config = get_task("window-washing").default_config()
    config.start.in_contact = False
    config.desired_force = Profile(kind="smooth_step", value=[-10.0], final_value=[10.0], start_time=0.5)
    with pytest.raises(ForceSignError, match="row 0 changes sign"):
        prepare_config(config)


def test_a_start_gap_beyond_the_guarded_moves_reach_is_refused():
    task = get_task("window-washing")
    config = load_config(data="task: window-washing\nstart: {in_contact: false, gap: 1.0}",
                         defaults=task.default_config())
    with pytest.raises(ConfigError, match=r"start.gap \(1 m\) must be shorter than supervision.max_travel"):
        config.validate()


@pytest.mark.slow                # builds the window scenario and its static contact probe
def test_a_pressing_start_with_a_force_that_turns_into_a_pull_is_refused():
    config = get_task("window-washing").default_config()
    config.desired_force = Profile(kind="smooth_step", value=[-10.0], final_value=[10.0], start_time=0.5)
    scenario = build_scenario(config, with_loggers=False)
    with pytest.raises(ForceSignError, match="row 0 changes sign"):
        set_initial_conditions(scenario, scenario.diagram.CreateDefaultContext())


# -- the run's figures leave out the samples whose wrench was invalid --------------------------------------

def test_figures_leave_out_samples_read_while_the_wrench_was_invalid():
    t = np.linspace(0.0, 1.0, 11)
    error = np.full((11, 1), 0.05)
    error[5] = math.nan                                   # a dropout
    error[-1] = math.nan                                  # at the very end, too
    desired = np.full((11, 1), 10.0)
    row, = row_errors(t, error, desired, ["F"], ["N"], since=0.0, settle_after=0.3)
    assert row.max_error_after_5_time_constants == pytest.approx(0.05)
    assert row.final_error == pytest.approx(0.05) and row.final_error_percent == pytest.approx(0.5)
    assert row.settling_time_1_percent == 0.0
    assert invalid_samples(error) == 2 and last_valid(error)[0] == pytest.approx(0.05)
    assert last_valid(np.full((3, 2), math.nan)) is None
