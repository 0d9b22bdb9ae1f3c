"""More bad input to the station blocks and the analysis functions, called directly in a user's own
diagram: contact geometries, a ContactConfig or sensor config built in Python, effort limits, a log read
with the wrong context, the checks other functions use (check_controller_plant, check_equilibrium,
get_task), every public function of analysis.design, matching, linearization, discrete_linearization,
derivatives, environment and modes, and names with a trailing newline. Each gives a one-line typed error
naming the callee and the argument."""

import dataclasses
import math

import airo_models
import numpy as np
import pytest
import sympy

from pydrake.geometry import GeometryId, Sphere
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, Integrator

from drake_hybrid import ConstraintSpace, GivenVelocityProjection, PoseChart, surface_constraint
from drake_hybrid.analysis.derivatives import (central_difference_jacobian, checked_state_jacobian, column_errors,
                                               state_names)
from drake_hybrid.analysis.design import designed_eigenvalues_by_row, predicted_eigenvalues, predicted_errors
from drake_hybrid.analysis.discrete_linearization import linearize_discrete, linearize_sampled_loop
from drake_hybrid.analysis.environment import (contact_environment, impedance_loop, impedance_matrix,
                                               impedance_response, mass_factor_within, root_pairs, row_forces)
from drake_hybrid.analysis.linearization import check_equilibrium, equilibrium_config, linearize_continuous
from drake_hybrid.analysis.matching import match_eigenvalues
from drake_hybrid.analysis.modes import diagnose_unstable_modes, drift_eigenvalues, explained_modes
from drake_hybrid.control.gains import HybridGains
from drake_hybrid.core.errors import ArgumentError, ConfigError, OffConstraintError, PathError
from drake_hybrid.core.surfaces import SphereSurface
from drake_hybrid.experiments.config_paths import config_value
from drake_hybrid.station.arm import add_actuators, mount_tool, robot_plant
from drake_hybrid.station.contact import ContactConfig, apply_contact_defaults, default_plant_config, only_tool_touches
from drake_hybrid.station.contact_start import rest_contact_wrench, solve_contact_start
from drake_hybrid.station.loggers import add_loggers, logged, read_log
from drake_hybrid.station.loop import add_hybrid_controller, check_controller_plant
from drake_hybrid.station.sensing import ContactSensorConfig, add_wrench_sensor
from drake_hybrid.station.workpieces import add_rigid_workpiece
from drake_hybrid.systems.sources import Profile
from drake_hybrid.tasks.registry import get_task

CENTER, RADIUS, PAD = np.array([0.45, 0.0, 0.10]), 0.15, 0.02
GAINS = HybridGains(velocity=[10.0], force_proportional=[0.5], force_integral=[15.0])
NORMAL = np.array([np.sin(0.35) * np.cos(0.3), np.sin(0.35) * np.sin(0.3), np.cos(0.35)])
START = RigidTransform(RotationMatrix.MakeFromOneVector(-NORMAL, 2), CENTER + (RADIUS + PAD) * NORMAL)
GUESS = [0.0, -1.9, 1.9, -1.6, -1.57, 0.0]
WINDOW = get_task("window-washing")


def add_ur5e(plant):
    arm = Parser(plant).AddModels(airo_models.get_urdf_path("ur5e"))[0]
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link", arm))
    return mount_tool(plant, arm, "tool0")


def parts():
    """builder, plant, scene_graph, robot, workpiece: not finalized, contact material not applied."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(), builder)
    robot = add_ur5e(plant)
    workpiece = add_rigid_workpiece(plant, Sphere(RADIUS), RigidTransform(CENTER))
    return builder, plant, scene_graph, robot, workpiece


def built():
    builder, plant, scene_graph, robot, workpiece = parts()
    apply_contact_defaults(plant, scene_graph, robot, workpiece)
    plant.Finalize()
    only_tool_touches(plant, scene_graph, robot, workpiece)
    chart = PoseChart()
    sphere = surface_constraint(chart, lambda p: sympy.sqrt(sum((p[i] - CENTER[i])**2 for i in range(3)))
                                - (RADIUS + PAD), name="sphere", normal_rows=False)
    space = ConstraintSpace(sphere, GivenVelocityProjection(chart, np.delete(np.eye(6), 2, axis=0)))
    systems = add_hybrid_controller(builder, plant, robot, space, robot_plant(add_ur5e), gains=GAINS,
                                    control_period=1e-3, desired_velocity=Profile(value=[0.0] * 5),
                                    desired_force=Profile(value=[10.0]))
    loggers = add_loggers(builder, systems)
    return builder.Build(), systems, loggers


@pytest.fixture(scope="module")
def station():
    return built()


@pytest.fixture(scope="module")
def other_station():
    return built()


# ------------------------------------------------------------------------------------------------
# station.contact_start
# ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("geometries", ["pad", [1, 2], None, 5, [], "unregistered"])
def test_rest_contact_wrench_refuses_what_is_not_the_plants_geometry_ids(station, geometries):
    diagram, systems, _ = station
    context = diagram.CreateDefaultContext()
    plant_context = systems.plant.GetMyContextFromRoot(context)
    geometries = [GeometryId.get_new_id()] if geometries == "unregistered" else geometries
    with pytest.raises(ArgumentError, match=r"^rest_contact_wrench: robot_geometries [^\n]*$"):
        rest_contact_wrench(systems.plant, plant_context, geometries, [0.0, 0.0, 0.0])


def test_rest_contact_wrench_takes_a_single_geometry_id(station):
    diagram, systems, _ = station
    plant_context = systems.plant.GetMyContextFromRoot(diagram.CreateDefaultContext())
    wrench = rest_contact_wrench(systems.plant, plant_context, systems.robot.pad_geometries[0], np.zeros(3))
    assert wrench.shape == (6,) and np.all(np.isfinite(wrench))


def test_solve_contact_start_names_a_max_depth_too_small_to_reach_the_contact(station):
    diagram, systems, _ = station
    with pytest.raises(OffConstraintError, match=r"^solve_contact_start: the pad touches nothing down to "
                                                 r"max_depth = 1e-09 m [^\n]*max_depth is too small"):
        solve_contact_start(diagram, diagram.CreateDefaultContext(), systems, START, GUESS, max_depth=1e-9)


# ------------------------------------------------------------------------------------------------
# station.loop
# ------------------------------------------------------------------------------------------------

BAD_CONTACT = [("friction", "x"), ("relaxation_time", "x"), ("friction", True), ("relaxation_time", math.nan),
               ("pad_modulus", math.inf), ("workpiece_relaxation_time", None), ("pad_resolution", [0.003])]


@pytest.mark.parametrize("field, value", BAD_CONTACT)
def test_apply_contact_defaults_checks_a_contact_config_built_in_python(field, value):
    _, plant, scene_graph, robot, workpiece = parts()
    contact = dataclasses.replace(ContactConfig(), **{field: value})
    with pytest.raises(ConfigError, match=rf"^apply_contact_defaults: contact\.{field}[^\n]*$"):
        apply_contact_defaults(plant, scene_graph, robot, workpiece, contact)


@pytest.mark.parametrize("field, value", [("bandwidth_hz", "x"), ("bandwidth_hz", math.nan), ("condition", 1),
                                          ("fault_time", -math.inf)])
def test_add_wrench_sensor_checks_a_sensor_config_built_in_python(field, value):
    builder, plant, _, robot, _ = parts()
    plant.Finalize()
    sensor = dataclasses.replace(ContactSensorConfig(), **{field: value})
    with pytest.raises(ConfigError, match=rf"^add_wrench_sensor: sensor\.{field}[^\n]*$"):
        add_wrench_sensor(builder, plant, robot, sensor)


ONE_JOINT = """<robot name="one"><link name="base"/><link name="l1"><inertial><mass value="1"/>
<inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
<limit lower="-3" upper="3" effort="10" velocity="1"/></joint></robot>"""


def one_joint_plant():
    plant = MultibodyPlant(0.0)
    return plant, Parser(plant).AddModelsFromString(ONE_JOINT, "urdf")[0]


@pytest.mark.parametrize("limit", ["x", math.nan, -5.0, 0.0, True, None, [5.0]])
def test_add_actuators_refuses_an_effort_limit_that_is_not_a_positive_number(limit):
    plant, arm = one_joint_plant()
    with pytest.raises(ArgumentError, match=r"^add_actuators: effort_limits\['j1'\] must be a number > 0"):
        add_actuators(plant, arm, {"j1": limit})
    assert plant.num_actuators() == 0


def test_add_actuators_refuses_a_misspelt_joint_name_that_would_leave_a_joint_unlimited():
    plant, arm = one_joint_plant()
    with pytest.raises(ArgumentError, match=r"^add_actuators: effort_limits names 'J1', not a joint of model_instance, "
                                            r"and gives no limit for 'j1'"):
        add_actuators(plant, arm, {"J1": 5.0})
    with pytest.raises(ArgumentError, match=r"^add_actuators: effort_limits: a key must be a string"):
        add_actuators(plant, arm, {1: 5.0})


@pytest.mark.parametrize("limits, expected", [({"j1": 5.0, "welded_finger": 2.0}, 5.0), ({"j1": math.inf}, math.inf)])
def test_add_actuators_takes_the_limits_of_removed_joints_and_inf(limits, expected):
    plant, arm = one_joint_plant()
    assert add_actuators(plant, arm, limits) == ["j1_actuator"]
    assert plant.get_joint_actuator(plant.GetJointActuatorIndices()[0]).effort_limit() == expected


@pytest.mark.parametrize("which", ["plant", "other", "none"])
def test_read_log_and_logged_refuse_a_context_that_is_not_the_loggers_root_context(station, other_station, which):
    diagram, systems, loggers = station
    context = {"plant": lambda: systems.plant.GetMyContextFromRoot(diagram.CreateDefaultContext()),
               "other": lambda: other_station[0].CreateDefaultContext(), "none": lambda: None}[which]()
    with pytest.raises(ArgumentError, match=r"^read_log: root_context must be the [^\n]*$"):
        read_log(loggers, context)
    with pytest.raises(ArgumentError, match=r"^logged: root_context must be the [^\n]*$"):
        logged(loggers, context, "wrench")


def test_read_log_reads_the_right_context(station):
    diagram, _, loggers = station
    log = read_log(loggers, diagram.CreateDefaultContext())
    assert "t" in log and log["wrench"].shape[1] == 6


@pytest.mark.parametrize("which, words", [("plant", "plant must be a MultibodyPlant"),
                                          ("robot", "robot must be the RobotModel"),
                                          ("controller_plant", "controller_plant must be a finalized"),
                                          ("unfinalized", "controller_plant must be finalized")])
def test_check_controller_plant_checks_its_arguments(station, which, words):
    _, systems, _ = station
    arguments = dict(plant=systems.plant, robot=systems.robot, controller_plant=systems.controller_plant)
    arguments.update({"plant": dict(plant=None), "robot": dict(robot="robot"),
                      "controller_plant": dict(controller_plant="x"),
                      "unfinalized": dict(controller_plant=MultibodyPlant(0.0))}[which])
    with pytest.raises((ArgumentError, ConfigError), match=rf"^check_controller_plant: {words}"):
        check_controller_plant(**arguments)


@pytest.mark.parametrize("name", ["tool\n", "tool\n_2", " tool", "1tool", ""])
def test_mount_tool_refuses_a_name_that_is_not_a_whole_model_name(name):
    plant = MultibodyPlant(0.0)
    arm = Parser(plant).AddModels(airo_models.get_urdf_path("ur5e"))[0]
    with pytest.raises(ArgumentError, match=r"^mount_tool: name must be a model name"):
        mount_tool(plant, arm, "tool0", name=name)
    assert not plant.HasModelInstanceNamed(name)


def test_config_paths_match_whole_segments():
    config = WINDOW.default_config()
    assert config_value(config, "duration") == config.duration
    with pytest.raises(ValueError, match="is not a field name"):
        config_value(config, "duration\n")


# ------------------------------------------------------------------------------------------------
# The checks other functions use, called directly
# ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("which, words", [("diagram", "diagram must be a built Diagram"),
                                          ("context", "root_context must be the root context of diagram"),
                                          ("systems", "systems must be the HybridSystems"),
                                          ("what", "what must be a string")])
def test_check_equilibrium_checks_its_arguments(station, other_station, which, words):
    diagram, systems, _ = station
    arguments = dict(diagram=diagram, root_context=diagram.CreateDefaultContext(), systems=systems)
    arguments.update({"diagram": dict(diagram=None), "context": dict(root_context=other_station[0].CreateDefaultContext()),
                      "systems": dict(systems=None), "what": dict(what=5)}[which])
    with pytest.raises(ArgumentError, match=rf"^check_equilibrium[^:]*: {words}[^\n]*$"):
        check_equilibrium(**arguments)


@pytest.mark.parametrize("arguments, words", [(dict(where=5), "where must be a string"),
                                              (dict(error="oops"), "error must be a DrakeHybridError subclass"),
                                              (dict(error=None), "error must be a DrakeHybridError subclass"),
                                              (dict(error=ValueError), ("error must be a DrakeHybridError subclass "
                                                                        r"\(.*\), got ValueError"))])
def test_get_task_checks_where_and_error(arguments, words):
    with pytest.raises(ArgumentError, match=rf"^get_task: {words}"):
        get_task("no-such-task", **arguments)


def test_get_task_names_the_config_field_with_the_error_asked_for():
    with pytest.raises(ConfigError, match=r"^task: unknown task 'x'"):
        get_task("x", where="task", error=ConfigError)


# ------------------------------------------------------------------------------------------------
# analysis
# ------------------------------------------------------------------------------------------------

DESIGNED = [-10.0, -8.0]


@pytest.mark.parametrize("arguments, name", [
    (dict(designed=[math.nan]), "designed"), (dict(designed="x"), "designed"), (dict(designed=[0.0]), "designed"),
    (dict(designed=[[-1.0]]), "designed"), (dict(measured="x"), "measured"), (dict(measured=[math.inf, -1]), "measured"),
    (dict(measured=[-1.0]), "measured"), (dict(marginal=-1), "marginal"), (dict(marginal="x"), "marginal"),
    (dict(marginal=1.5), "marginal"), (dict(marginal=True), "marginal"), (dict(marginal_real="x"), "marginal_real"),
    (dict(tolerance=0), "tolerance")])
def test_match_eigenvalues_checks_its_arguments(arguments, name):
    values = dict(designed=DESIGNED, measured=[-10.0, -8.0, 0.0], tolerance=0.05, marginal=1)
    values.update(arguments)
    with pytest.raises(ArgumentError, match=rf"^match_eigenvalues: {name} [^\n]*$"):
        match_eigenvalues(**values)


def test_match_eigenvalues_takes_complex_eigenvalues():
    match = match_eigenvalues([-1 + 2j, -1 - 2j], np.array([-1 - 2j, -1 + 2j, 1e-9]), marginal=1)
    assert match.matched and match.marginal_partners.size == 1


@pytest.mark.parametrize("periods", [0, 1.5, "2", True, -1, None])
def test_linearize_sampled_loop_checks_periods_before_building(periods):
    with pytest.raises(ArgumentError, match=r"^linearize_sampled_loop: periods must be a finite integer >= 1"):
        linearize_sampled_loop(WINDOW.default_config(), periods=periods)


@pytest.mark.parametrize("function", [linearize_continuous, linearize_discrete, linearize_sampled_loop,
                                      equilibrium_config])
def test_the_config_functions_refuse_what_is_not_a_scenario_config(function):
    with pytest.raises(ArgumentError, match=rf"^{function.__name__}: config must be a ScenarioConfig"):
        function({"task": "window-washing"})


@pytest.mark.parametrize("function", [linearize_continuous, linearize_discrete])
def test_the_linearizations_refuse_stages_that_are_not_callable(function):
    with pytest.raises(ArgumentError, match=rf"^{function.__name__}: stages must be a callable"):
        function(WINDOW.default_config(), stages="x")


def validated_gains():
    return GAINS.matrices(1, 1, "velocity-force")


@pytest.mark.parametrize("function", [predicted_eigenvalues, designed_eigenvalues_by_row])
@pytest.mark.parametrize("arguments, name", [(dict(gains=None), "gains"), (dict(gains=GAINS), "gains"),
                                             (dict(mode="sideways"), "mode"), (dict(mode=3), "mode"),
                                             (dict(kinematic_rows=[5]), "kinematic_rows"),
                                             (dict(kinematic_rows="x"), "kinematic_rows"),
                                             (dict(kinematic_rows=[0, 0]), "kinematic_rows"),
                                             (dict(redundancy=-1), "redundancy"), (dict(redundancy=0.5), "redundancy")])
def test_the_designed_eigenvalues_check_gains_mode_and_rows(function, arguments, name):
    values = dict(gains=validated_gains(), mode="velocity-force")
    values.update(arguments)
    with pytest.raises(ArgumentError, match=rf"^{function.__name__}: {name} [^\n]*$"):
        function(**values)


@pytest.mark.parametrize("arguments, name", [(dict(times="x"), "times"), (dict(velocity_error0=[1.0, 2.0]),
                                                                          "velocity_error0"),
                                             (dict(force_integral0=[math.nan]), "force_integral0")])
def test_predicted_errors_checks_its_vectors(arguments, name):
    values = dict(gains=validated_gains(), mode="velocity-force", times=[0.0, 0.1], velocity_error0=[1.0],
                  force_integral0=[0.0])
    values.update(arguments)
    with pytest.raises(ArgumentError, match=rf"^predicted_errors: {name} [^\n]*$"):
        predicted_errors(**values)


@pytest.fixture(scope="module")
def integrator():
    builder = DiagramBuilder()
    integrator = builder.AddSystem(Integrator(2))
    builder.Connect(builder.AddSystem(ConstantVectorSource([1.0, 2.0])).get_output_port(), integrator.get_input_port())
    diagram = builder.Build()
    return diagram, diagram.CreateDefaultContext()


@pytest.mark.parametrize("call, words", [
    (lambda d, c, o: central_difference_jacobian(d, o), "central_difference_jacobian: context must be the context"),
    (lambda d, c, o: central_difference_jacobian(None, c), "central_difference_jacobian: diagram must be a Drake"),
    (lambda d, c, o: central_difference_jacobian(d, c, epsilon=0), "central_difference_jacobian: epsilon"),
    (lambda d, c, o: central_difference_jacobian(d, c, columns=[2]), "central_difference_jacobian: columns"),
    (lambda d, c, o: central_difference_jacobian(d, c, columns="x"), "central_difference_jacobian: columns"),
    (lambda d, c, o: column_errors("x", np.eye(2)), "column_errors: A_autodiff"),
    (lambda d, c, o: column_errors(np.eye(2), np.eye(3)), "column_errors: A_differences"),
    (lambda d, c, o: state_names(d, "context"), "state_names: context"),
    (lambda d, c, o: checked_state_jacobian(d, c, np.eye(3)), "checked_state_jacobian: A_autodiff"),
    (lambda d, c, o: checked_state_jacobian(d, c, np.eye(2), tolerance=-1), "checked_state_jacobian: tolerance"),
    (lambda d, c, o: checked_state_jacobian(d, c, np.eye(2), what=None), "checked_state_jacobian: what")])
def test_the_derivative_functions_check_their_arguments(integrator, call, words):
    diagram, context = integrator
    other = Integrator(2).CreateDefaultContext()
    with pytest.raises(ArgumentError, match=rf"^{words}[^\n]*$"):
        call(diagram, context, other)


def test_the_derivative_functions_still_differentiate(integrator):
    diagram, context = integrator
    assert np.allclose(central_difference_jacobian(diagram, context), 0.0)
    A, check = checked_state_jacobian(diagram, context, np.zeros((2, 2)))
    assert np.allclose(A, 0.0) and check.used == "autodiff"


@pytest.mark.parametrize("call, words", [
    (lambda: impedance_matrix("x", np.eye(1)), "impedance_matrix: velocity_gain"),
    (lambda: impedance_matrix(np.eye(2), np.eye(1)), "impedance_matrix: position_gain"),
    (lambda: impedance_matrix(np.eye(1), np.eye(1), stiffness=[[math.nan]]), "impedance_matrix: stiffness"),
    (lambda: impedance_loop(np.eye(1), np.eye(1), inverse_mass="m"), "impedance_matrix: inverse_mass"),
    (lambda: root_pairs([0.0], [-1.0]), "root_pairs: designed"),
    (lambda: root_pairs([-1.0], "x"), "root_pairs: moved"),
    (lambda: mass_factor_within(np.eye(1), np.eye(1), np.eye(1), np.eye(1), np.eye(1), 2.0, 1),
     "mass_factor_within: tolerance"),
    (lambda: mass_factor_within(np.eye(1), np.eye(1), np.eye(1), np.eye(1), np.eye(1), 0.05, 3),
     "mass_factor_within: velocity_rows"),
    (lambda: impedance_response(np.eye(1), np.eye(1), "t", [[0.0]], [0.0], [0.0]), "impedance_response: t"),
    (lambda: impedance_response(np.eye(1), np.eye(1), [0.0, 1.0], [[0.0]], [0.0], [0.0]),
     "impedance_response: tangential_force"),
    (lambda: impedance_response(np.eye(1), np.eye(1), [0.0, 1.0], [[0.0], [0.0]], [0.0, 1.0], [0.0]),
     "impedance_response: position_error0"),
    (lambda: drift_eigenvalues("x", np.eye(1), np.eye(1)), "drift_eigenvalues: mobility"),
    (lambda: drift_eigenvalues(np.ones((1, 2)), np.eye(2), np.eye(1)), "drift_eigenvalues: stiffness"),
    (lambda: drift_eigenvalues(np.eye(1), np.eye(1), np.eye(1), position_gain=[[math.nan]]),
     "drift_eigenvalues: position_gain"),
    (lambda: explained_modes([0.1], "x", 0.05), "explained_modes: diagnoses"),
    (lambda: explained_modes("x", [], 0.05), "explained_modes: unstable")])
def test_the_environment_and_mode_functions_check_their_arguments(call, words):
    with pytest.raises(ArgumentError, match=rf"^{words}[^\n]*$"):
        call()


@pytest.mark.parametrize("function, arguments", [(row_forces, ()), (contact_environment, ([0],)),
                                                 (diagnose_unstable_modes, (np.zeros((1, 1)), "velocity-force", []))])
def test_the_scenario_functions_check_scenario_and_context(station, other_station, function, arguments):
    diagram, systems, _ = station
    name = function.__name__
    with pytest.raises(ArgumentError, match=rf"^{name}: scenario must be a built Scenario"):
        function(None, diagram.CreateDefaultContext(), *arguments)
    with pytest.raises(ArgumentError, match=rf"^{name}: root_context must be the root context"):
        function(systems, other_station[0].CreateDefaultContext(), *arguments)


def test_contact_environment_checks_rows_and_step(station):
    diagram, systems, _ = station
    context = diagram.CreateDefaultContext()
    with pytest.raises(ArgumentError, match=r"^contact_environment: rows must be a finite integer"):
        contact_environment(systems, context, [6])
    with pytest.raises(ArgumentError, match=r"^contact_environment: step must be a finite number > 0"):
        contact_environment(systems, context, [0], step=0.0)


# ------------------------------------------------------------------------------------------------
# core.surfaces
# ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("chart", ["pose", None, 5])
def test_offset_constraint_refuses_what_is_not_a_chart(chart):
    with pytest.raises(PathError, match=r"^sphere\.offset_constraint: chart must be a PoseChart or an EulerZXZChart"):
        SphereSurface(center=[0.0, 0.0, 0.0], radius=0.1).offset_constraint(chart, 0.02)
