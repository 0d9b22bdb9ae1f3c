"""The station blocks (station.loop) on bad input in a user's own diagram: a one-line typed error
naming the argument (or the port), raised before anything reaches Drake, where Drake would end the
process (an input wired twice, a duplicate system name at Build) or raise its own untyped error.
Also: two arms, each with its tool and its controller, in one plant and one builder."""

import airo_models
import numpy as np
import pytest
import sympy

from pydrake.geometry import Box, Sphere
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, PassThrough

from drake_hybrid import ConstraintSpace, GivenVelocityProjection, PoseChart, surface_constraint
from drake_hybrid.control.baselines import JointServoHybridController
from drake_hybrid.control.gains import HybridGains
from drake_hybrid.core.errors import ArgumentError, ConfigError, DrakeHybridError, UnknownFrameError
from drake_hybrid.station.arm import (add_actuators, carried_bodies, mount_tool, robot_plant, urdf_effort_limits,
                                      weld_joints)
from drake_hybrid.station.contact import apply_contact_defaults, default_plant_config, only_tool_touches
from drake_hybrid.station.loggers import add_loggers, logged, read_log
from drake_hybrid.station.loop import add_hybrid_controller, connect_hybrid_loop
from drake_hybrid.station.sensing import add_wrench_sensor, wrench_lag
from drake_hybrid.station.workpieces import add_rigid_workpiece
from drake_hybrid.systems.sources import Profile, ProfileSource

CENTER, RADIUS, PAD = np.array([0.45, 0.0, 0.10]), 0.15, 0.02
GAINS = HybridGains(velocity=[10.0], force_proportional=[0.5], force_integral=[15.0])
ARGUMENTS = dict(gains=GAINS, control_period=1e-3, desired_velocity=[0, 0.02, 0, 0, 0], desired_force=[10.0])


def add_ur5e(plant, name="pad_tool", y=0.0, X_flange_tool=None):
    arm = Parser(plant, f"arm_at_{y:g}").AddModels(airo_models.get_urdf_path("ur5e"))[0]
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link", arm), RigidTransform([0, y, 0]))
    return mount_tool(plant, arm, "tool0", X_flange_tool=X_flange_tool, name=name)


@pytest.fixture(scope="module")
def space():
    chart = PoseChart()
    sphere = surface_constraint(chart, lambda p: sympy.sqrt(sum((p[i] - CENTER[i])**2 for i in range(3)))
                                - (RADIUS + PAD), name="sphere", normal_rows=False)
    return ConstraintSpace(sphere, GivenVelocityProjection(chart, np.delete(np.eye(6), 2, axis=0)))


@pytest.fixture(scope="module")
def controller_plant():
    return robot_plant(add_ur5e)


def station(finalize=True):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(), builder)
    robot = add_ur5e(plant)
    workpiece = add_rigid_workpiece(plant, Sphere(RADIUS), RigidTransform(CENTER))
    apply_contact_defaults(plant, scene_graph, robot, workpiece)
    if finalize:
        plant.Finalize()
        only_tool_touches(plant, scene_graph, robot, workpiece)
    return builder, plant, scene_graph, robot, workpiece


@pytest.fixture(scope="module")
def finalized():
    """One station for the calls refused before they add anything (each test checks that they did not)."""
    return station()


class NoPorts(PassThrough):
    def __init__(self):
        super().__init__(1)


BAD_CONTROLLER_ARGUMENTS = [
    (dict(constraint_space=None), ArgumentError, "constraint_space"),
    (dict(constraint_space="sphere"), ArgumentError, "constraint_space"),
    (dict(initial_phase=7), ArgumentError, "initial_phase"),
    (dict(initial_phase=[2]), ArgumentError, "initial_phase"),
    (dict(initial_phase=True), ArgumentError, "initial_phase"),
    (dict(sensor_faults={"dropout_rate": 0.1}), ArgumentError, "sensor_faults"),
    (dict(supervision={"enabled": True}), ArgumentError, "supervision"),
    (dict(source="profile"), ArgumentError, "source"),
    (dict(source=NoPorts()), ArgumentError, "source .* has no output port 'desired_velocity'"),
    (dict(controller="li-sastry"), ArgumentError, "controller"),
    (dict(controller=NoPorts()), ArgumentError, "controller .* has no input port 'estimated_state'"),
    (dict(controller=NoPorts(), fast_law=False), ArgumentError, "fast_law .* not your controller"),
    (dict(colour="red"), ArgumentError, "unknown argument.* colour"),
    (dict(desired_velocity=Profile(value=[0.02])), DrakeHybridError, "desired_velocity"),
    (dict(desired_force=Profile(value=[1.0, 2.0])), DrakeHybridError, "desired_force"),
    (dict(desired_force=[1.0, 2.0]), ArgumentError, "desired_force"),
    (dict(desired_force=10.0), ArgumentError, "desired_force must be a vector of 1"),
    (dict(desired_velocity="fast"), ArgumentError, "desired_velocity"),
    (dict(sensor="contact"), ArgumentError, "sensor"),
    (dict(builder=None), ArgumentError, "builder"),
    (dict(plant=None), ArgumentError, "plant"),
    (dict(robot=None), ArgumentError, "robot"),
    (dict(controller_plant=None), ArgumentError, "controller_plant"),
    (dict(controller_plant=MultibodyPlant(0.0)), ConfigError, "controller_plant"),
]


@pytest.mark.parametrize("changes, error, words", BAD_CONTROLLER_ARGUMENTS,
                         ids=[next(iter(changes)) + f"-{index}" for index, (changes, _, _)
                              in enumerate(BAD_CONTROLLER_ARGUMENTS)])
def test_add_hybrid_controller_names_the_bad_argument(finalized, space, controller_plant, changes, error, words):
    builder, plant, _, robot, _ = finalized
    arguments = dict(builder=builder, plant=plant, robot=robot, constraint_space=space,
                     controller_plant=controller_plant, **ARGUMENTS)
    arguments.update(changes)
    systems = len(builder.GetSystems())
    with pytest.raises(error, match=f"add_hybrid_controller: .*{words}") as raised:
        add_hybrid_controller(**arguments)
    assert "\n" not in str(raised.value)
    assert len(builder.GetSystems()) == systems          # refused before adding anything


def test_a_second_controller_on_one_arm_is_refused_not_fatal(space, controller_plant):
    builder, plant, _, robot, _ = station()
    add_hybrid_controller(builder, plant, robot, space, controller_plant, **ARGUMENTS)
    with pytest.raises(ArgumentError, match="'plant.arm_at_0::ur5e_actuation' is already connected.*already has a "
                                            "hybrid controller on this arm"):
        add_hybrid_controller(builder, plant, robot, space, controller_plant, **ARGUMENTS)


def test_an_actuation_input_the_user_wired_is_refused(space, controller_plant):
    builder, plant, _, robot, _ = station()
    zero = builder.AddNamedSystem("my_torques", ConstantVectorSource(np.zeros(6)))
    builder.Connect(zero.get_output_port(), plant.get_actuation_input_port(robot.arm))
    with pytest.raises(ArgumentError, match="ur5e_actuation' is already connected in the builder by your system "
                                            "'my_torques'"):
        add_hybrid_controller(builder, plant, robot, space, controller_plant, **ARGUMENTS)


def test_a_second_wiring_of_the_loop_is_refused(space, controller_plant):
    """connect_hybrid_loop refuses a controller whose loop is already closed, naming the port (Drake would
    end the process at the second Connect)."""
    builder, plant, _, robot, _ = station()
    hybrid = add_hybrid_controller(builder, plant, robot, space, controller_plant, **ARGUMENTS)
    second = builder.AddSystem(ProfileSource(Profile(value=[0.0] * 5), Profile(value=[10.0]), 5, 1))
    with pytest.raises(ArgumentError, match="connect_hybrid_loop: the input port 'controller.desired_velocity' is "
                                            "already connected"):
        connect_hybrid_loop(builder, hybrid.controller, state=hybrid.state, wrench=hybrid.wrench_output,
                            actuation=plant.get_actuation_input_port(robot.arm), source=second)


def test_a_source_without_the_commands_is_refused(space, controller_plant):
    builder, plant, _, robot, _ = station()
    with pytest.raises(ArgumentError, match="add_hybrid_controller: source must be a System"):
        add_hybrid_controller(builder, plant, robot, space, controller_plant, source=Profile(),
                              **{k: v for k, v in ARGUMENTS.items() if k not in ("desired_velocity", "desired_force")})


@pytest.mark.parametrize("robot_change, words", [
    (dict(X_flange_tool=RigidTransform([0, 0, 0.01])), "end-effector frame 'pad_center' is 0.01 m"),
    (dict(y=0.2), "0.2 m"),
])
def test_a_controller_plant_of_another_robot_is_refused(finalized, space, robot_change, words):
    builder, plant, _, robot, _ = finalized
    other = robot_plant(lambda model: add_ur5e(model, **robot_change))
    with pytest.raises(ArgumentError, match=f"add_hybrid_controller: controller_plant does not model the plant's "
                                            f"arm .*{words}"):
        add_hybrid_controller(builder, plant, robot, space, other, **ARGUMENTS)


def test_a_controller_plant_with_other_joints_is_refused(finalized, space):
    builder, plant, _, robot, _ = finalized

    def add_two_arms(model):
        add_ur5e(model, y=0.0)
        return add_ur5e(model, name="second", y=1.0)

    with pytest.raises(ArgumentError, match="controller_plant has 12 positions, the plant's arm 'arm_at_0::ur5e' 6"):
        add_hybrid_controller(builder, plant, robot, space, robot_plant(add_two_arms), **ARGUMENTS)


def arm_alone():
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(), builder)
    return plant, Parser(plant).AddModels(airo_models.get_urdf_path("ur5e"))[0]


def test_mount_tool_names_the_bad_argument():
    plant, arm = arm_alone()
    other, _ = arm_alone()
    bad = [
        (lambda: mount_tool(plant, "ur5e", "tool0"), ArgumentError, "arm must be a ModelInstanceIndex"),
        (lambda: mount_tool(plant, None, "tool0"), ArgumentError, "arm must be a ModelInstanceIndex"),
        (lambda: mount_tool(None, arm, "tool0"), ArgumentError, "plant must be a MultibodyPlant"),
        (lambda: mount_tool(plant, arm, plant.world_frame()), ArgumentError, "flange_frame 'world'.* not moved by"),
        (lambda: mount_tool(plant, arm, other.GetFrameByName("tool0")), ArgumentError,
         "flange_frame 'tool0' is a frame of another plant"),
        (lambda: mount_tool(plant, arm, 5), ArgumentError, "flange_frame must be a Frame"),
        (lambda: mount_tool(plant, arm, "no_such_frame"), UnknownFrameError, "flange_frame 'no_such_frame'"),
        (lambda: mount_tool(plant, arm, "tool0", gripper_joints=5), ArgumentError, "gripper_joints"),
        (lambda: mount_tool(plant, arm, "tool0", X_flange_tool=[0, 0, 1]), ArgumentError, "X_flange_tool"),
        (lambda: mount_tool(plant, arm, "tool0", name=""), ArgumentError, "name must be a model name"),
        (lambda: mount_tool(plant, arm, "tool0", name="a b"), ArgumentError, "name must be a model name"),
        (lambda: mount_tool(plant, arm, "tool0", name=3), ArgumentError, "name must be a string"),
    ]
    for call, error, words in bad:
        with pytest.raises(error, match=f"mount_tool: {words}") as raised:
            call()
        assert "\n" not in str(raised.value)
    assert not plant.HasModelInstanceNamed("pad_tool")      # nothing was mounted by a refused call
    mount_tool(plant, arm, "tool0")
    with pytest.raises(ArgumentError, match="mount_tool: the plant already has a model 'pad_tool'.*Pass name="):
        mount_tool(plant, arm, "wrist_3_link")
    plant.Finalize()
    with pytest.raises(ConfigError, match="mount_tool: the plant is finalized"):
        mount_tool(plant, arm, "tool0", name="late")


def test_a_frame_on_a_part_the_arm_carries_is_a_flange():
    plant, arm = arm_alone()
    mount_tool(plant, arm, "tool0", name="adapter")
    carried = plant.GetFrameByName("adapter_center")
    robot = mount_tool(plant, arm, carried, name="second")        # on the first tool: moved by the arm
    assert robot.end_effector_frame == "second_center"


def test_two_arms_with_their_tools_and_controllers_build_one_diagram(space):
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlant(default_plant_config(), builder)
    left = add_ur5e(plant, y=0.0)
    right = add_ur5e(plant, name="right_pad", y=1.0)
    assert (left.end_effector_frame, right.end_effector_frame) == ("pad_center", "right_pad_center")
    workpiece = add_rigid_workpiece(plant, Sphere(RADIUS), RigidTransform(CENTER))
    with pytest.raises(ArgumentError, match="add_rigid_workpiece: the plant already has a geometry named "
                                            "'workpiece'.*pass name="):
        add_rigid_workpiece(plant, Box(0.1, 0.1, 0.1), RigidTransform([1.0, 1.0, 0.0]))
    workpiece += add_rigid_workpiece(plant, Box(0.1, 0.1, 0.1), RigidTransform([1.0, 1.0, 0.0]), name="second")
    for robot in (left, right):
        apply_contact_defaults(plant, scene_graph, robot, workpiece)
    plant.Finalize()
    for robot in (left, right):
        only_tool_touches(plant, scene_graph, robot, workpiece)
    left_systems = add_hybrid_controller(builder, plant, left, space, robot_plant(add_ur5e), **ARGUMENTS)
    # The left arm's model for the right arm: no frame right_pad_center (and its base 1 m off).
    with pytest.raises(ArgumentError, match="controller_plant has no end-effector frame 'right_pad_center'"):
        add_hybrid_controller(builder, plant, right, space, robot_plant(add_ur5e), **ARGUMENTS)
    right_systems = add_hybrid_controller(
        builder, plant, right, space, robot_plant(lambda model: add_ur5e(model, name="right_pad", y=1.0)),
        **ARGUMENTS)
    assert left_systems.controller.get_name() == "controller"
    assert right_systems.controller.get_name() == "controller_arm_at_1::ur5e"
    loggers = [add_loggers(builder, systems) for systems in (left_systems, right_systems)]
    diagram = builder.Build()                   # unique names: Drake ends the process at Build otherwise
    context = diagram.CreateDefaultContext()
    assert read_log(loggers[1], context)["state"].shape[1] == 12
    with pytest.raises(ArgumentError, match="logged: no logger 'torque'"):
        logged(loggers[0], context, "torque")


def test_add_wrench_sensor_refuses_a_plant_not_finalized():
    builder, plant, _, robot, _ = station(finalize=False)
    with pytest.raises(ConfigError, match="add_wrench_sensor: finalize the plant first"):
        add_wrench_sensor(builder, plant, robot)


def test_add_loggers_names_the_bad_argument():
    with pytest.raises(ArgumentError, match="add_loggers: builder must be a DiagramBuilder"):
        add_loggers(None, None)
    with pytest.raises(ArgumentError, match="add_loggers: systems must be the HybridSystems"):
        add_loggers(DiagramBuilder(), "hybrid")


def test_weld_joints_and_add_actuators_name_the_bad_argument():
    plant, arm = arm_alone()
    for call, words in [(lambda: weld_joints(plant, 5, arm), "weld_joints: joint_names must be a joint name"),
                        (lambda: weld_joints(plant, [5], arm), r"weld_joints: joint_names\[\] must be a string"),
                        (lambda: weld_joints(None, "x"), "weld_joints: plant must be a MultibodyPlant"),
                        (lambda: weld_joints(plant, "x", "ur5e"), "weld_joints: model_instance must be a "
                                                                  "ModelInstanceIndex"),
                        (lambda: add_actuators(plant, None), "add_actuators: model_instance must be a "
                                                             "ModelInstanceIndex")]:
        with pytest.raises(ArgumentError, match=words):
            call()


def test_apply_contact_defaults_names_the_bad_argument():
    _, plant, scene_graph, robot, workpiece = station(finalize=False)
    _, other_scene_graph = AddMultibodyPlant(default_plant_config(), DiagramBuilder())
    for arguments, words in [((plant, scene_graph, robot, None), "workpiece_geometries must be the GeometryIds"),
                             ((plant, scene_graph, robot, ["workpiece"]), "workpiece_geometries"),
                             ((plant, scene_graph, None, workpiece), "robot must be the RobotModel"),
                             ((plant, None, robot, workpiece), "scene_graph must be the SceneGraph"),
                             ((plant, other_scene_graph, robot, workpiece), "scene_graph is not the plant's"),
                             ((None, scene_graph, robot, workpiece), "plant must be a MultibodyPlant")]:
        with pytest.raises(ArgumentError, match=f"apply_contact_defaults: {words}"):
            apply_contact_defaults(*arguments)
    with pytest.raises(ArgumentError, match="apply_contact_defaults: the plant has no SceneGraph"):
        apply_contact_defaults(MultibodyPlant(0.0), scene_graph, robot, workpiece)


def test_add_rigid_workpiece_refuses_a_plant_without_scene_graph():
    # Drake's RegisterCollisionGeometry ends the process on a plant without a SceneGraph.
    with pytest.raises(ArgumentError, match="add_rigid_workpiece: plant must be a MultibodyPlant with a SceneGraph"):
        add_rigid_workpiece(MultibodyPlant(0.0), Box(0.1, 0.1, 0.1), RigidTransform())


def test_robot_plant_names_add_robot_and_keeps_the_cause():
    def broken(plant):
        return {}["arm"]

    with pytest.raises(ArgumentError, match="robot_plant: add_robot\\(plant\\) raised KeyError: 'arm'") as raised:
        robot_plant(broken)
    assert isinstance(raised.value.__cause__, KeyError)

    def wrong_frame(plant):
        arm = Parser(plant).AddModels(airo_models.get_urdf_path("ur5e"))[0]
        return mount_tool(plant, arm, "flange_that_is_not")

    with pytest.raises(UnknownFrameError, match="robot_plant: add_robot\\(plant\\) raised UnknownFrameError: "
                                                "mount_tool: flange_frame 'flange_that_is_not'"):
        robot_plant(wrong_frame)
    with pytest.raises(ArgumentError, match="robot_plant: add_robot must be a callable"):
        robot_plant(None)


def test_the_tools_frame_names_are_distinct_in_both_plants():
    """The controller plant built by the same add_robot names the second tool's frame as the plant does."""
    def two(plant):
        add_ur5e(plant, y=0.0)
        return add_ur5e(plant, name="right_pad", y=1.0)

    model = robot_plant(two)
    assert model.HasFrameNamed("pad_center") and model.HasFrameNamed("right_pad_center")
    frame = model.GetFrameByName("right_pad_center")
    assert model.GetModelInstanceName(frame.model_instance()) == "right_pad"
    context = model.CreateDefaultContext()
    tool0 = model.GetFrameByName("tool0", model.GetModelInstanceByName("arm_at_1::ur5e"))
    np.testing.assert_allclose(frame.CalcPoseInWorld(context).translation(),
                               tool0.CalcPoseInWorld(context).multiply([0.0, 0.0, 0.05]), atol=1e-12)


def test_the_other_public_helpers_name_the_bad_argument(tmp_path):
    plant, arm = arm_alone()
    broken = tmp_path / "broken.urdf"
    broken.write_text("<robot><joint")
    for call, words in [(lambda: urdf_effort_limits(None), "urdf_effort_limits: path must be the path"),
                        (lambda: urdf_effort_limits(tmp_path / "none.urdf"), "urdf_effort_limits: path: no file"),
                        (lambda: urdf_effort_limits(broken), "urdf_effort_limits: path: .* is not XML"),
                        (lambda: wrench_lag("contact", plant, 1e-3), "wrench_lag: sensor must be"),
                        (lambda: carried_bodies(plant, "ur5e", plant.world_body()), "carried_bodies: model_instance"),
                        (lambda: carried_bodies(plant, arm, "tool0"), "carried_bodies: body must be a RigidBody")]:
        with pytest.raises(ArgumentError, match=words):
            call()


def test_a_baseline_controller_of_its_own_is_wired(space, controller_plant):
    builder, plant, _, robot, _ = station()
    baseline = JointServoHybridController(controller_plant, robot.end_effector_frame, robot.end_effector_point, space,
                                          control_period=1e-3)
    hybrid = add_hybrid_controller(builder, plant, robot, space, controller_plant, controller=baseline,
                                   **ARGUMENTS)
    assert hybrid.controller is baseline
    builder.Build()
