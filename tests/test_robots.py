"""The robot loader (tasks/robots.py) on arms from the example-robot-data model package that the
package does not use otherwise: the UR10 (6 joints, STL and COLLADA meshes), the xArm7 (7 joints,
STL, URDF joint damping as shipped), the Kinova Jaco 2 (6 joints, COLLADA, repeated material names,
a free base) and the Panda's full URDF (STL meshes, gripper fingers); the joint-guess finder; the
typed errors of a start the law cannot use; simulate()'s handles; kinematic rows padded."""

import importlib.metadata
import logging
from pathlib import Path

import numpy as np
import pytest
import trimesh

from pydrake.geometry import Box
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_hybrid import ConstraintSpace, GivenVelocityProjection, PoseChart, surface_constraint
from drake_hybrid.core.errors import (ConfigError, ForceSignError, OffConstraintError, UnknownFrameError,
                                      UnreachablePoseError)
from drake_hybrid.experiments.simulation import simulate
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.station.arm import mount_tool
from drake_hybrid.station.workpieces import add_rigid_workpiece
from drake_hybrid.systems.sources import Profile
from drake_hybrid.tasks.custom import CustomTask
from drake_hybrid.tasks.registry import get_task, register_task
from drake_hybrid.tasks.robots import load_arm
from drake_hybrid.tasks.task import pad_kinematic_rows

# Drake notes, once per joint, what it ignores in these URDFs (mechanical reductions, joint friction).
logging.getLogger("drake").setLevel(logging.ERROR)

SHARE = Path(importlib.metadata.distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data"))
UR10 = SHARE / "robots/ur_description/urdf/ur10_robot.urdf"
XARM7 = SHARE / "robots/xarm_description/urdf/xarm7.urdf"
KINOVA = SHARE / "robots/kinova_description/robots/kinova.urdf"
PANDA = SHARE / "robots/panda_description/urdf/panda.urdf"

PAD_RADIUS, PLANE_HEIGHT = 0.02, 0.1


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("drake_hybrid_cache")


@pytest.fixture(scope="module")
def ur10(cache):
    return load_arm(UR10, flange="tool0", cache_dir=cache)


@pytest.fixture(scope="module")
def kinova(cache):
    return load_arm(KINOVA, flange="j2s6s200_end_effector", cache_dir=cache)


def simulation_plant(arm):
    """The arm in a discrete plant with a SceneGraph (where Drake rejects STL and DAE collision meshes)."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=1e-3, contact_model="hydroelastic_with_fallback"),
                                 builder)
    robot = arm.add_robot(plant)
    plant.Finalize()
    return plant, robot


# ------------------------------------------------------------------------------------------------
# Loading
# ------------------------------------------------------------------------------------------------

def test_ur10_loads_in_one_call(ur10, cache):
    report = ur10.report
    assert report.arm_joints == ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
                                 "wrist_2_joint", "wrist_3_joint"]
    assert report.effort_limits == {"shoulder_pan_joint": 330.0, "shoulder_lift_joint": 330.0, "elbow_joint": 150.0,
                                    "wrist_1_joint": 54.0, "wrist_2_joint": 54.0, "wrist_3_joint": 54.0}
    assert {Path(p).suffix for p in report.converted_meshes} == {".stl", ".dae"}
    assert all(Path(obj).parent == cache / "meshes" and Path(obj).exists() for obj in report.converted_meshes.values())
    assert any("converted 14 mesh files" in line for line in report.changes)
    assert str(report).count("\n  - ") == len(report.changes)
    plant, robot = simulation_plant(ur10)
    assert plant.num_positions() == plant.num_velocities() == plant.num_actuators() == 6
    limits = [plant.get_joint_actuator(i).effort_limit() for i in plant.GetJointActuatorIndices(robot.arm)]
    assert limits == [330.0, 330.0, 150.0, 54.0, 54.0, 54.0]
    assert robot.end_effector_frame == "pad_center" and robot.only_pad_contact
    # The COLLADA visual and the STL collision mesh of the forearm agree once converted (units applied).
    visual = report.converted_meshes[str(SHARE / "robots/ur_description/meshes/ur10/visual/forearm.dae")]
    collision = report.converted_meshes[str(SHARE / "robots/ur_description/meshes/ur10/collision/forearm.stl")]
    extents = [np.ptp(np.loadtxt([line[2:] for line in Path(f).read_text().splitlines() if line.startswith("v ")]),
                      axis=0) for f in (visual, collision)]
    np.testing.assert_allclose(extents[0], extents[1], atol=2e-3)


def test_seven_dof_arm_with_transmissions(cache):
    arm = load_arm(XARM7, flange="link7", cache_dir=cache)
    assert len(arm.report.arm_joints) == 7
    assert list(arm.report.effort_limits.values()) == [50.0, 50.0, 30.0, 30.0, 30.0, 20.0, 20.0]
    assert any("kept the model's actuators" in line for line in arm.report.changes)
    assert any(line.startswith("removed Coulomb joint friction") for line in arm.report.changes)
    assert any(line.startswith("kept the model's joint damping (N m s/rad): joint1 10") for line in arm.report.changes)
    plant, _ = simulation_plant(arm)
    assert plant.num_positions() == plant.num_actuators() == 7


def test_repeated_materials_and_free_base(kinova):
    report = kinova.report
    assert report.renamed_materials and any("material 'carbon_fiber'" in line for line in report.changes)
    assert any(line.startswith("floating base 'base'") for line in report.changes)
    plant, _ = simulation_plant(kinova)
    assert plant.num_positions() == plant.num_velocities() == 6          # no quaternion floating joint


def test_gripper_welded_and_tool_frame(cache):
    arm = load_arm(PANDA, flange="panda_link8", tool_frame="panda_hand_tcp", cache_dir=cache)
    assert [w.split()[0] for w in arm.report.welded_joints] == ["panda_finger_joint1", "panda_finger_joint2"]
    plant, _ = simulation_plant(arm)
    assert plant.num_positions() == plant.num_actuators() == 7
    # The pad points along the TCP's +z: its centre 5 cm out along that axis.
    context = arm.plant.CreateDefaultContext()
    X_WT = arm.plant.GetFrameByName("panda_hand_tcp").CalcPoseInWorld(context)
    X_WP = arm.plant.GetFrameByName("pad_center").CalcPoseInWorld(context)
    np.testing.assert_allclose(X_WT.inverse().multiply(X_WP).translation(), [0, 0, 0.05], atol=1e-12)


SDF_ARM = """<?xml version="1.0"?>
<sdf version="1.9">
  <model name="two_link">
    <link name="base">
      <inertial><mass>2.0</mass><inertia><ixx>0.01</ixx><iyy>0.01</iyy><izz>0.01</izz></inertia></inertial>
      <collision name="base_collision"><geometry><mesh><uri>block.stl</uri></mesh></geometry></collision>
    </link>
    <link name="link1">
      <pose>0 0 0.1 0 0 0</pose>
      <inertial><mass>1.0</mass><inertia><ixx>0.01</ixx><iyy>0.01</iyy><izz>0.01</izz></inertia></inertial>
      <visual name="link1_visual"><geometry><mesh><uri>block.stl</uri></mesh></geometry></visual>
    </link>
    <link name="link2">
      <pose>0 0 0.4 0 0 0</pose>
      <inertial><mass>1.0</mass><inertia><ixx>0.01</ixx><iyy>0.01</iyy><izz>0.01</izz></inertia></inertial>
    </link>
    <joint name="joint1" type="revolute">
      <parent>base</parent><child>link1</child>
      <axis><xyz>0 0 1</xyz><limit><lower>-2</lower><upper>2</upper><effort>40</effort></limit></axis>
    </joint>
    <joint name="joint2" type="revolute">
      <parent>link1</parent><child>link2</child>
      <axis><xyz>0 1 0</xyz><limit><lower>-2</lower><upper>2</upper><effort>25</effort></limit></axis>
    </joint>
  </model>
</sdf>
"""


def test_sdf_model(cache, tmp_path):
    trimesh.creation.box((0.1, 0.1, 0.1)).export(tmp_path / "block.stl")
    (tmp_path / "two_link.sdf").write_text(SDF_ARM)
    arm = load_arm(tmp_path / "two_link.sdf", flange="link2", cache_dir=cache)
    assert len(arm.report.converted_meshes) == 1 and arm.report.effort_limits == {"joint1": 40.0, "joint2": 25.0}
    assert any(line.startswith("floating base 'base'") for line in arm.report.changes)
    plant, _ = simulation_plant(arm)
    assert plant.num_positions() == plant.num_actuators() == 2


WELDED_URDF = """<robot name="one_joint">
  <link name="world"/>
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="mount" type="fixed"><parent link="world"/><child link="base"/><origin xyz="0 0 0.5"/></joint>
  <link name="link1"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="joint1" type="revolute"><parent link="base"/><child link="link1"/><axis xyz="0 0 1"/>
    <limit effort="5" lower="-1" upper="1" velocity="1"/></joint>
</robot>
"""


def test_base_pose_composes_with_the_models_own_weld(cache, tmp_path):
    (tmp_path / "one_joint.urdf").write_text(WELDED_URDF)
    arm = load_arm(tmp_path / "one_joint.urdf", flange="link1", base_pose=RigidTransform([1.0, 0.0, 0.0]),
                   cache_dir=cache)
    X_WB = arm.plant.GetFrameByName("base").CalcPoseInWorld(arm.plant.CreateDefaultContext())
    np.testing.assert_allclose(X_WB.translation(), [1.0, 0.0, 0.5], atol=1e-15)
    assert arm.report.base == "base" and arm.report.effort_limits == {"joint1": 5.0}


def test_collision_meshes_dropped(cache):
    arm = load_arm(UR10, flange="tool0", collision="drop", cache_dir=cache)
    assert len(arm.report.dropped_geometries) == 7
    assert all("/collision/" not in source for source in arm.report.converted_meshes)
    plant, _ = simulation_plant(arm)
    assert plant.num_positions() == 6


def test_unknown_frame_lists_the_frames(cache):
    with pytest.raises(UnknownFrameError, match=r"flange 'tool1' is not a frame of model .*its frames: .*tool0") as info:
        load_arm(UR10, flange="tool1", cache_dir=cache)
    assert "\n" not in str(info.value)
    with pytest.raises(UnknownFrameError, match="tool_frame 'tcp'"):
        load_arm(UR10, flange="tool0", tool_frame="tcp", cache_dir=cache)


def test_bad_arguments(cache, tmp_path):
    with pytest.raises(ConfigError, match="tool_axis must be one of"):
        load_arm(UR10, flange="tool0", tool_axis="z", cache_dir=cache)
    with pytest.raises(ConfigError, match="does not exist"):
        load_arm(tmp_path / "missing.urdf", flange="tool0", cache_dir=cache)


# ------------------------------------------------------------------------------------------------
# The joint-guess finder
# ------------------------------------------------------------------------------------------------

def on_plane(x):
    """The pad centre on a horizontal plane at PLANE_HEIGHT, tool pointing down."""
    return RigidTransform(RotationMatrix.MakeXRotation(np.pi), [x, 0.0, PLANE_HEIGHT + PAD_RADIUS])


def plate_at(x, height=PLANE_HEIGHT):
    """add_workpiece of a 60 cm square plate, 5 cm thick, its top at ``height``, centred at (x, 0)."""
    def add_plate(plant):
        return add_rigid_workpiece(plant, Box(0.6, 0.6, 0.05), RigidTransform([x, 0.0, height - 0.025]), name="plate")
    return add_plate


@pytest.mark.parametrize("name, x", [("ur10", 0.7), ("kinova", 0.45)])
def test_joint_guess_on_the_surface(name, x, request):
    arm = request.getfixturevalue(name)
    target = on_plane(x)
    plate = plate_at(x)
    guess = arm.find_joint_guess(target, seeds=8, add_workpiece=plate)
    assert guess.solutions >= 1 and arm.workpiece_penetrations(plate, guess.positions) == []
    X = arm.pad_pose(guess.positions)
    np.testing.assert_allclose(X.translation(), target.translation(), atol=1e-5)
    assert X.rotation().inverse().multiply(target.rotation()).ToAngleAxis().angle() < 1e-5
    lower, upper = arm.joint_limits()
    assert np.all(guess.positions >= lower) and np.all(guess.positions <= upper) and guess.limit_margin >= 0.05 - 1e-6
    assert guess.condition_number == pytest.approx(arm.condition_number(guess.positions))
    assert guess.condition_number < 20


def test_joint_guess_keeps_the_links_off_the_workpiece(ur10):
    # The best-conditioned solution from these seeds puts the UR10's forearm through the plate.
    plate = plate_at(0.7)
    free = ur10.find_joint_guess(on_plane(0.7), seeds=12)
    assert ur10.workpiece_penetrations(plate, free.positions) == ["forearm_link"]
    clear = ur10.find_joint_guess(on_plane(0.7), seeds=12, add_workpiece=plate)
    assert ur10.workpiece_penetrations(plate, clear.positions) == [] and clear.solutions < free.solutions


def test_unreachable_pose(ur10):
    with pytest.raises(UnreachablePoseError, match="no joint positions within the limits"):
        ur10.find_joint_guess(on_plane(3.0), seeds=3)


# ------------------------------------------------------------------------------------------------
# The loaded arm in a CustomTask: typed start errors, simulate's handles, the closed loop
# ------------------------------------------------------------------------------------------------

def plane_task(arm, name, x, plate_height=PLANE_HEIGHT, start_height=PLANE_HEIGHT, normal_rows=False):
    """A CustomTask: the pad on a plate whose top is at plate_height, C: the plane z = start_height."""
    add_plate = plate_at(x, plate_height)
    chart = PoseChart()
    plane = surface_constraint(chart, lambda p: p[2] - (start_height + PAD_RADIUS), name="plane",
                               normal_rows=normal_rows)
    if normal_rows:                              # the tool held along the normal: (vx, vy, wz) controlled
        E_p = GivenVelocityProjection(chart, np.eye(6)[[0, 1, 5]], name="(vx, vy, wz)")
    else:
        E_p = GivenVelocityProjection(chart, np.delete(np.eye(6), 2, axis=0), name="(vx, vy, wx, wy, wz)")
    start = on_plane(x)
    guess = arm.find_joint_guess(start, seeds=8, add_workpiece=plate_at(x))
    return register_task(CustomTask(name, add_robot=arm.add_robot, add_workpiece=add_plate,
                                    constraint_space=ConstraintSpace(plane, E_p), start_pose=start,
                                    joint_guess=guess.positions))


def start(config):
    scenario = build_scenario(config, with_loggers=False)
    set_initial_conditions(scenario, scenario.diagram.CreateDefaultContext())


def test_custom_task_defaults_to_velocity_force(ur10):
    task = plane_task(ur10, "ur10-defaults", 0.7)
    assert task.default_config().mode == "velocity-force"


@pytest.mark.parametrize("start_height, words", [(PLANE_HEIGHT - 0.02, "a gap: the surface is 20.0 mm"),
                                                 (PLANE_HEIGHT + 0.02, "a penetration: the pad centre is 20.0 mm")])
def test_start_pose_off_the_constraint(ur10, start_height, words):
    # C says the surface is at start_height; the start pose puts the pad on PLANE_HEIGHT (above it: a gap).
    task = plane_task(ur10, "ur10-off", 0.7, start_height=start_height)
    with pytest.raises(OffConstraintError, match=words):
        start(task.default_config(desired_force=[10.0]))


@pytest.mark.parametrize("plate_height, words", [(PLANE_HEIGHT - 0.03, r"touches nothing .* \(a gap\)"),
                                                 (PLANE_HEIGHT + 0.01, r"reaches beyond .* \(a penetration\)")])
def test_workpiece_off_the_constraint(ur10, plate_height, words):
    # C and the start pose agree; the workpiece's geometry is elsewhere.
    task = plane_task(ur10, "ur10-plate-off", 0.7, plate_height=plate_height)
    with pytest.raises(OffConstraintError, match=words):
        start(task.default_config(desired_force=[10.0]))


def test_pulling_force_names_the_sign_convention(ur10):
    task = plane_task(ur10, "ur10-pull", 0.7)
    with pytest.raises(ForceSignError, match="pulls: .*F_d is the force ON the robot"):
        start(task.default_config(desired_force=[-10.0]))


def test_pulling_force_on_a_built_in_task():
    # The arm presses up on the pane: F_d = -10 N (the pane pushes the robot down). +10 N would pull; the
    # window's start moves up along its fixed normal whatever the sign of F_d, and the contact pushes back.
    config = get_task("window-washing").default_config()
    config.desired_force = Profile(value=[10.0])
    with pytest.raises(ForceSignError, match="pulls: in contact the workpiece pushes the pad with -"):
        start(config)


def test_mount_tool_names_an_unknown_frame(ur10):
    plant = MultibodyPlant(0.0)
    instance = Parser(plant).AddModels(ur10.report.model)[0]
    with pytest.raises(UnknownFrameError, match="flange_frame 'flange' is not a frame of model 'ur10'; its frames: "):
        mount_tool(plant, instance, "flange")


def test_kinematic_rows_padded(ur10):
    profile = pad_kinematic_rows(Profile(kind="sine", value=[10.0], amplitude=[1.0], frequency=1.0), 3, (1, 2))
    assert profile.value == [10.0, 0.0, 0.0] and profile.amplitude == [1.0, 0.0, 0.0]
    full = Profile(value=[10.0, 0.0, 0.0])
    assert pad_kinematic_rows(full, 3, (1, 2)) is full
    task = plane_task(ur10, "ur10-normal-rows", 0.7, normal_rows=True)
    scenario = build_scenario(task.default_config(desired_force=[10.0]), with_loggers=False)
    assert scenario.config.desired_force.value == [10.0, 0.0, 0.0]


def test_simulate_hands_back_simulator_and_context(ur10):
    task = plane_task(ur10, "ur10-handles", 0.7)
    seen = {}

    def setup(scenario, simulator, context):
        seen["time"] = context.get_time()
        seen["diagram"] = scenario.diagram

    result = simulate(task.default_config(desired_velocity=[0.05, 0, 0, 0, 0], desired_force=[10.0], duration=0.02),
                      setup=setup)
    assert isinstance(result.simulator, Simulator)
    assert result.context.get_time() == pytest.approx(0.02)
    assert seen == {"time": 0.0, "diagram": result.scenario.diagram}


def tracking(arm, name, x):
    task = plane_task(arm, name, x)
    config = task.default_config(desired_velocity=[0.05, 0, 0, 0, 0], desired_force=[10.0], duration=1.0)
    summary = simulate(config).summary
    assert summary.mode == "velocity-force" and summary.design_time_constant == pytest.approx(0.1)
    return summary


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_loaded_six_dof_arm_tracks_on_a_plane(ur10):
    # Five time constants: 0.5 s; measured 0.66 % (velocity, the transient's tail) and 1e-4 % (force).
    summary = tracking(ur10, "ur10-plane", 0.7)
    assert summary.max_velocity_error_percent_after_5_time_constants <= 2.0
    assert summary.max_force_error_percent_after_5_time_constants <= 2.0


@pytest.mark.slow
def test_loaded_kinova_tracks_on_a_plane(kinova):
    summary = tracking(kinova, "kinova-plane", 0.45)
    assert summary.max_velocity_error_percent_after_5_time_constants <= 2.0
    assert summary.max_force_error_percent_after_5_time_constants <= 2.0


@pytest.mark.slow
def test_loaded_seven_dof_arm_with_shipped_damping_tracks_on_a_plane(cache):
    """The xArm7's URDF joint damping (2-10 N m s/rad) as shipped: the law compensates the damping the
    discrete solver applies implicitly (control.damping); without that, about 75 % velocity error."""
    summary = tracking(load_arm(XARM7, flange="link7", cache_dir=cache), "xarm7-plane", 0.45)
    assert summary.max_force_error_percent_after_5_time_constants <= 2.0
    assert summary.max_velocity_error_percent_after_5_time_constants <= 2.0
