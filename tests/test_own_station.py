"""A user's own station (issue 30): an arm the package does not ship (Unitree Z1 from
example-robot-data, its gripper removed), an ellipsoid of the user's, the constraint in sympy, the
package's blocks (station.loop) in the user's DiagramBuilder and plant, Drake's Simulator and the
package's linearization. Public names only; tutorial 8 is the same station."""

import importlib.metadata
from pathlib import Path

import numpy as np
import pytest
import sympy

from pydrake.geometry import Box, Cylinder, Ellipsoid
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_hybrid import ConstraintSpace, GivenVelocityProjection, PoseChart, surface_constraint
from drake_hybrid.analysis.design import design_time_constant
from drake_hybrid.analysis.linearization import linearize_at_contact
from drake_hybrid.control.gains import ControlMode, HybridGains
from drake_hybrid.core.errors import ArgumentError, ConfigError, ForceSignError, OffConstraintError, StartCollisionError
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.station.arm import mount_tool, robot_plant
from drake_hybrid.station.contact import apply_contact_defaults, default_plant_config, only_tool_touches
from drake_hybrid.station.contact_start import rest_contact_wrench, solve_contact_start
from drake_hybrid.station.loggers import LOG_KEYS, add_loggers, read_log
from drake_hybrid.station.loop import add_hybrid_controller
from drake_hybrid.station.sensing import WristSensorConfig
from drake_hybrid.station.workpieces import add_rigid_workpiece
from drake_hybrid.systems.sources import Profile
from drake_hybrid.systems.wrist_force_torque_sensor import WristForceTorqueSensor
from drake_hybrid.tasks.model_files import prepare_model
from drake_hybrid.tasks.registry import get_task

SHARE = Path(importlib.metadata.distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data"))
CENTER, AXES, PAD = np.array([0.26, 0.0, 0.253]), np.array([0.12, 0.08, 0.06]), 0.02
A = AXES + PAD                  # the pad centre's surface: the ellipsoid grown by the pad's radius
SPEED, FORCE = 0.03, 8.0
GUESS = [0.0, 1.5, -1.5, 1.2, 0.0, 0.0]
GAINS = HybridGains(velocity=[16.0], position=[48.0], force_proportional=[0.5], force_integral=[15.0])


@pytest.fixture(scope="module")
def z1():
    return prepare_model(SHARE / "robots/z1_description/urdf/z1.urdf")


def start_pose(dx=-0.03, dy=0.007):
    """The pad centre on the grown ellipsoid at (dx, dy) from its top, the tool tilted 21 degrees."""
    return RigidTransform(RotationMatrix.MakeYRotation(np.pi - 0.37),
                          CENTER + [dx, dy, A[2] * np.sqrt(1 - (dx / A[0])**2 - (dy / A[1])**2)])


def build(z1, time_step, control_period, speed=SPEED, force=FORCE, finalize=True, obstacle=None):
    def add_robot(plant):
        arm = Parser(plant).AddModels(z1.model)[0]
        return mount_tool(plant, arm, "link06", RigidTransform(RotationMatrix.MakeYRotation(np.pi / 2), [0.02, 0, 0]),
                          gripper_joints=["jointGripper"], gripper="remove")

    chart = PoseChart()
    surface = surface_constraint(chart, lambda p: A[2] * (sympy.sqrt(sum(((p[i] - CENTER[i]) / A[i])**2
                                                                          for i in range(3))) - 1),
                                 name="ellipsoid", normal_rows=False)
    space = ConstraintSpace(surface, GivenVelocityProjection(chart, np.delete(np.eye(6), 2, axis=0)))
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(time_step), builder)
    robot = add_robot(plant)
    workpiece = add_rigid_workpiece(plant, Ellipsoid(*AXES), RigidTransform(CENTER))
    if obstacle is not None:                      # a fixture elsewhere in the scene, e.g. where a link passes
        workpiece += add_rigid_workpiece(plant, Box(0.05, 0.05, 0.05), obstacle, name="fixture")
    apply_contact_defaults(plant, scene_graph, robot, workpiece)
    if not finalize:
        return builder, plant, robot, space, add_robot
    plant.Finalize()
    only_tool_touches(plant, scene_graph, robot, workpiece)
    hybrid = add_hybrid_controller(builder, plant, robot, space, robot_plant(add_robot), gains=GAINS,
                                   mode=ControlMode.POSITION_FORCE, control_period=control_period,
                                   desired_velocity=Profile(value=[speed, 0, 0, 0, 0]),
                                   desired_force=Profile(value=[force]))
    loggers = add_loggers(builder, hybrid)
    return builder.Build(), hybrid, loggers


@pytest.mark.slow
def test_own_station_tracks_and_linearizes_as_designed(z1):
    """Every row within 2 % of its command scale after 5 design time constants (the rows commanded zero
    against the speed), eigenvalues within 5 % of the design, AutoDiffXd's A within 1e-3 of central
    differences."""
    diagram, hybrid, loggers = build(z1, 1e-3, 1e-3)
    context = diagram.CreateDefaultContext()
    solve_contact_start(diagram, context, hybrid, start_pose(), GUESS)
    Simulator(diagram, context).AdvanceTo(2.0)
    log = read_log(loggers, context)
    assert set(log) <= set(LOG_KEYS)
    controller = hybrid.controller
    tau = design_time_constant(controller.validated_gains(), controller.mode, controller.kinematic_rows)
    settled = log["t"] >= 5 * tau
    velocity = 100 * np.abs(log["velocity_error"][settled]).max(axis=0) / SPEED
    force = 100 * np.abs(log["force_error"][settled]).max(axis=0) / FORCE
    assert np.all(velocity < 2.0) and np.all(force < 2.0), (velocity, force)

    diagram, hybrid, _ = build(z1, 0.0, None, speed=0.0)
    context = diagram.CreateDefaultContext()
    solve_contact_start(diagram, context, hybrid, start_pose(), GUESS)
    linearization = linearize_at_contact(diagram, context, hybrid)
    assert linearization.equilibrium_residual < 1e-6
    assert linearization.match.matched and max(linearization.match.relative_error) < 0.05
    assert linearization.jacobian_check.max_relative_error < 1e-3 and linearization.jacobian_check.used == "autodiff"
    assert not linearization.unstable_modes


def test_a_pulling_force_is_refused_before_the_first_step(z1):
    diagram, hybrid, _ = build(z1, 1e-3, 1e-3, force=-FORCE)
    with pytest.raises(ForceSignError, match="pulls"):
        solve_contact_start(diagram, diagram.CreateDefaultContext(), hybrid, start_pose(), GUESS)


def test_a_start_off_the_surface_is_refused(z1):
    diagram, hybrid, _ = build(z1, 1e-3, 1e-3)
    off = RigidTransform(start_pose().rotation(), start_pose().translation() + [0, 0, 0.01])
    with pytest.raises(OffConstraintError, match="solve_contact_start: start_pose"):
        solve_contact_start(diagram, diagram.CreateDefaultContext(), hybrid, off, GUESS)


def test_a_start_with_a_link_through_the_scene_is_refused(z1):
    """The collision filters let only the tool touch; a link through a fixture at the start is named."""
    diagram, hybrid, _ = build(z1, 1e-3, 1e-3)
    context = diagram.CreateDefaultContext()
    q0 = solve_contact_start(diagram, context, hybrid, start_pose(), GUESS)
    plant = hybrid.plant
    elbow = plant.GetBodyByName("link03").EvalPoseInWorld(plant.GetMyContextFromRoot(context))
    diagram, hybrid, _ = build(z1, 1e-3, 1e-3, obstacle=elbow)
    with pytest.raises(StartCollisionError, match="body 'link0[2-4]'.* mm into fixture"):
        solve_contact_start(diagram, diagram.CreateDefaultContext(), hybrid, start_pose(), GUESS)
    assert q0 is not None


def test_blocks_name_what_is_wrong(z1):
    builder, plant, robot, space, add_robot = build(z1, 1e-3, 1e-3, finalize=False)
    with pytest.raises(ConfigError, match="finalize the plant first"):
        add_hybrid_controller(builder, plant, robot, space, robot_plant(add_robot), control_period=1e-3)
    plant.Finalize()
    with pytest.raises(ArgumentError, match="sensor"):
        add_hybrid_controller(builder, plant, robot, space, robot_plant(add_robot), control_period=1e-3,
                              sensor="contact")
    with pytest.raises(ConfigError, match="gripper must be one of weld, remove"):
        mount_tool(plant, robot.arm, "link06", gripper="keep")


def test_linearize_at_contact_needs_a_continuous_loop(z1):
    diagram, hybrid, _ = build(z1, 1e-3, 1e-3, speed=0.0)
    context = diagram.CreateDefaultContext()
    with pytest.raises(ValueError, match="purely continuous"):
        linearize_at_contact(diagram, context, hybrid)


@pytest.mark.parametrize("task", ["window-washing", "sphere-polishing"])
def test_rest_contact_wrench_is_the_sensors_reading_at_a_start(task):
    """The start's static contact from SceneGraph's surfaces equals the package's contact sensor's
    reading of the primed plant (the same wrench, two ways)."""
    scenario = build_scenario(get_task(task).default_config(duration=0.1), with_loggers=False)
    context = scenario.diagram.CreateDefaultContext()
    set_initial_conditions(scenario, context)
    plant_context = scenario.plant.GetMyContextFromRoot(context)
    X_WE = scenario.plant.GetFrameByName(scenario.robot.end_effector_frame).CalcPoseInWorld(plant_context)
    wrench = rest_contact_wrench(scenario.plant, plant_context, scenario.robot.pad_geometries,
                                 X_WE.multiply(np.asarray(scenario.robot.end_effector_point, dtype=float)))
    reading = scenario.sensor.get_output_port(0).Eval(scenario.sensor.GetMyContextFromRoot(context))
    assert np.allclose(wrench, reading, rtol=0, atol=1e-3 * np.linalg.norm(reading))



@pytest.mark.slow
def test_another_arm_with_a_wrist_sensor_on_a_drum():
    """A UR5 (example-robot-data, as its URDF is) on a drum of the user's, the wrist force/torque sensor at
    the tool's weld: the same blocks, the same figures (every row within 2 % after 5 time constants,
    eigenvalues within 5 %, AD-vs-FD within 1e-3)."""
    ur5 = prepare_model(SHARE / "robots/ur_description/urdf/ur5_robot.urdf")
    axis, radius, speed, force = np.array([0.5, 0.0, 0.2]), 0.12, 0.04, 10.0
    start = RigidTransform(RotationMatrix.MakeXRotation(np.pi),
                           axis + [0.03, 0.0, np.sqrt((radius + PAD)**2 - 0.03**2)])
    guess = [-0.207, 4.793, 1.602, -1.683, -1.571, -1.778]     # LoadedArm.find_joint_guess, links clear of the drum
    chart = PoseChart()
    drum = surface_constraint(chart, lambda p: sympy.sqrt((p[0] - axis[0])**2 + (p[2] - axis[2])**2) - (radius + PAD),
                              name="drum", normal_rows=False)
    space = ConstraintSpace(drum, GivenVelocityProjection(chart, np.delete(np.eye(6), 2, axis=0)))

    def add_robot(plant):
        return mount_tool(plant, Parser(plant).AddModels(ur5.model)[0], "tool0")

    def build_drum(time_step, control_period, command):
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlant(default_plant_config(time_step), builder)
        robot = add_robot(plant)
        workpiece = add_rigid_workpiece(plant, Cylinder(radius, 0.5),
                                        RigidTransform(RotationMatrix.MakeXRotation(np.pi / 2), axis))
        apply_contact_defaults(plant, scene_graph, robot, workpiece)
        plant.Finalize()
        only_tool_touches(plant, scene_graph, robot, workpiece)
        hybrid = add_hybrid_controller(builder, plant, robot, space, robot_plant(add_robot), gains=GAINS,
                                       mode="position-force", control_period=control_period,
                                       desired_velocity=[command, 0, 0, 0, 0], desired_force=[force],
                                       sensor=WristSensorConfig() if control_period else None)
        loggers = add_loggers(builder, hybrid)
        return builder.Build(), hybrid, loggers

    diagram, hybrid, loggers = build_drum(1e-3, 1e-3, speed)
    assert isinstance(hybrid.sensor, WristForceTorqueSensor)
    context = diagram.CreateDefaultContext()
    solve_contact_start(diagram, context, hybrid, start, guess)
    Simulator(diagram, context).AdvanceTo(1.5)
    log = read_log(loggers, context)
    controller = hybrid.controller
    settled = log["t"] >= 5 * design_time_constant(controller.validated_gains(), controller.mode,
                                                   controller.kinematic_rows)
    velocity = 100 * np.abs(log["velocity_error"][settled]).max(axis=0) / speed
    assert np.all(velocity < 2.0) and 100 * np.abs(log["force_error"][settled]).max() / force < 2.0, velocity

    diagram, hybrid, _ = build_drum(0.0, None, 0.0)
    context = diagram.CreateDefaultContext()
    solve_contact_start(diagram, context, hybrid, start, guess)
    linearization = linearize_at_contact(diagram, context, hybrid)
    assert linearization.match.matched and max(linearization.match.relative_error) < 0.05
    assert linearization.jacobian_check.max_relative_error < 1e-3
