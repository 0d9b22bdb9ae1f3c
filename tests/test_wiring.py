"""Your own robot and constraint (drake_hybrid.tasks.custom): a CustomTask is wired exactly like a built-in task."""

import dataclasses
import math
import os

import numpy as np
import pytest
from distributed import LocalCluster

from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import DiscreteContactApproximation, MultibodyPlant

from drake_hybrid.experiments.simulation import simulate
from drake_hybrid.experiments.sweep import run_sweep
from drake_hybrid.experiments.sweep_results import read_results
from drake_hybrid.experiments.sweep_spec import load_spec
from drake_hybrid.station.arm import add_actuators, urdf_effort_limits, weld_joints
from drake_hybrid.tasks.custom import CustomTask
from drake_hybrid.tasks.registry import TASKS, get_task, register_task

ARM_WITH_GRIPPER = """<?xml version="1.0"?>
<robot name="arm_with_gripper">
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="link1"><inertial><origin xyz="0.2 0 0"/><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="finger_a"><inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="finger_b"><inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="link1"/><axis xyz="0 0 1"/>
    <limit effort="42.0" lower="-3" upper="3" velocity="2"/>
  </joint>
  <joint name="finger_joint_a" type="prismatic">
    <origin xyz="0.4 0 0"/><parent link="link1"/><child link="finger_a"/><axis xyz="0 1 0"/>
    <limit effort="20" lower="0" upper="0.04" velocity="0.2"/>
  </joint>
  <joint name="finger_joint_b" type="prismatic">
    <origin xyz="0.4 0 0"/><parent link="link1"/><child link="finger_b"/><axis xyz="0 -1 0"/>
    <limit effort="20" lower="0" upper="0.04" velocity="0.2"/>
    <mimic joint="finger_joint_a"/>
  </joint>
</robot>
"""


@pytest.fixture
def arm_urdf(tmp_path):
    path = tmp_path / "arm_with_gripper.urdf"
    path.write_text(ARM_WITH_GRIPPER)
    return path


def test_urdf_effort_limits(arm_urdf):
    assert urdf_effort_limits(arm_urdf) == {"shoulder": 42.0, "finger_joint_a": 20.0, "finger_joint_b": 20.0}


def test_weld_the_mimic_fingers_and_add_the_missing_actuators(arm_urdf):
    plant = MultibodyPlant(1e-3)
    plant.set_discrete_contact_approximation(DiscreteContactApproximation.kSap)    # parses <mimic> as a coupler
    arm = Parser(plant).AddModels(str(arm_urdf))[0]
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base", arm))
    assert plant.num_constraints() == 1 and plant.num_actuators() == 0
    welds = weld_joints(plant, ["finger_joint_a", "finger_joint_b"], arm)
    names = add_actuators(plant, arm, urdf_effort_limits(arm_urdf))
    plant.Finalize()
    assert [weld.name() for weld in welds] and names == ["shoulder_actuator"]
    assert plant.num_positions() == plant.num_velocities() == 1 and plant.num_constraints() == 0
    assert plant.get_joint_actuator(plant.GetJointActuatorIndices()[0]).effort_limit() == 42.0
    # The welded fingers sit where the joints' zero put them.
    context = plant.CreateDefaultContext()
    p_finger = plant.CalcRelativeTransform(context, plant.GetFrameByName("link1"), plant.GetFrameByName("finger_a"))
    assert np.allclose(p_finger.translation(), [0.4, 0, 0])


def test_weld_joints_names_an_unknown_joint(arm_urdf):
    plant = MultibodyPlant(0.0)
    arm = Parser(plant).AddModels(str(arm_urdf))[0]
    with pytest.raises(ValueError, match="has no joint 'elbow'"):
        weld_joints(plant, ["elbow"], arm)
    with pytest.raises(ValueError, match="has no joint 'elbow'"):
        weld_joints(plant, ["elbow"])


# ------------------------------------------------------------------------------------------------
# A CustomTask rebuilt from the window task's pieces must reproduce the built-in task
# ------------------------------------------------------------------------------------------------

@pytest.fixture
def custom_window():
    """The window task as a CustomTask: the same arm, tool and pane, the controlled point given as the
    tool's pad_center frame (which coincides with the arm's tip), the start as a pose and IK."""
    builtin = get_task("window-washing")
    reference = builtin.default_config()
    reference.duration = 0.5

    def add_robot(plant):
        return dataclasses.replace(builtin.add_robot(plant, reference), end_effector_frame="pad_center")

    plant = MultibodyPlant(0.0)
    add_robot(plant)
    plant.Finalize()
    context = plant.CreateDefaultContext()
    q_touch = builtin.three_link_inverse_kinematics((1.0, 0.8, 0.3), 0.9, 0.98, math.pi / 2)
    plant.SetPositions(context, q_touch)
    X_WE = plant.CalcRelativeTransform(context, plant.world_frame(), plant.GetFrameByName("pad_center"))
    task = register_task(CustomTask(
        "custom-window", add_robot=add_robot, add_workpiece=lambda plant: builtin.add_workpiece(plant, reference),
        constraint_space=builtin.constraint_space(reference), start_pose=X_WE, joint_guess=q_touch + [0.05, -0.1, 0.05]))
    config = task.default_config(desired_velocity=[0.1, 0.0], desired_force=[-10.0], mode="velocity-force",
                                 duration=reference.duration, gains=reference.gains)
    config.contact = reference.contact
    config.start.force_integral = reference.start.force_integral
    yield task, config, reference
    TASKS.pop(task.name)


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_custom_task_reproduces_the_built_in_task(custom_window):
    task, config, reference = custom_window
    custom, builtin = simulate(config), simulate(reference)
    assert np.allclose(custom.log["q"][0], builtin.log["q"][0], atol=1e-8)      # the same pressing start
    for key in ("q", "velocity", "force", "torque"):
        assert np.allclose(custom.log[key], builtin.log[key], atol=1e-6), key
    assert custom.summary.force_settling_time_1_percent == pytest.approx(
        builtin.summary.force_settling_time_1_percent, abs=2e-3)


def test_custom_task_pressing_direction(custom_window):
    task, config, _ = custom_window
    # C = y - h with F_d = -10 (the force on the robot is down): the robot pushes up, world +z.
    assert np.allclose(task.pressing_direction(config, task.start_pose), [0, 0, 1])
    config.desired_force.value = [0.0]
    with pytest.raises(ValueError, match="pushes along no position direction"):
        task.pressing_direction(config, task.start_pose)


def test_custom_task_checks_its_inputs(custom_window):
    task, config, _ = custom_window
    config.start.configuration = [0.9, 0.98]
    with pytest.raises(ValueError, match=r"\[x, y, z, roll, pitch, yaw\]"):
        task.start_pose_of(config)
    bad = CustomTask("bad-robot", add_robot=lambda plant: None, add_workpiece=lambda plant: [],
                     constraint_space=task.space, start_pose=task.start_pose, joint_guess=task.joint_guess)
    with pytest.raises(TypeError, match="must return a RobotModel"):
        bad.add_robot(MultibodyPlant(0.0), config)


def test_register_task_keeps_the_built_in_tasks(custom_window):
    task, _, _ = custom_window
    with pytest.raises(ValueError, match="built-in task"):
        register_task(type("Impostor", (), {"name": "window-washing"})())
    assert get_task("custom-window") is task
    again = register_task(task)                       # re-running a notebook cell replaces it
    assert get_task("custom-window") is again


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_a_custom_task_is_swept_on_a_dask_cluster_of_other_processes(custom_window, tmp_path):
    """Workers are other processes without the registry of this one: the task travels with its points."""
    task, config, _ = custom_window
    spec = load_spec(text=f"""
task: {task.name}
base:
  duration: 0.05
  desired_force.value[0]: -10.0
  desired_velocity.value[0]: 0.1
parameters:
  gains.force_proportional: {{values: [0.5, 1.0]}}
linearize: {{continuous: false, discrete: false}}
""")
    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0",
                           host="127.0.0.1")
    try:
        run = run_sweep(task.name, spec, tmp_path, scheduler=cluster.scheduler_address, progress=False)
    finally:
        cluster.close()
    rows = read_results(run.results_path)
    assert [row["error"] for row in rows] == [None, None]
    assert all(row["worker"] and str(os.getpid()) not in row["worker"] for row in rows)   # run elsewhere
