"""The joint positions that press on a task's workpiece with the desired force.
"""

import numpy as np

from pydrake.systems.framework import DiagramBuilder

from drake_hybrid.core.kinematics import EndEffectorKinematics
from drake_hybrid.station.start import pressing_depth
from drake_hybrid.systems.contact_wrench_sensor import ContactWrenchSensor
from drake_hybrid.tasks.plant import build_plant


def pressing_positions(scenario, positions_at_depth, max_depth=0.01):
    """Joint positions that press on the workpiece with the desired force F_d(0).

    ``positions_at_depth(s)`` gives the arm's q with the pad pushed s metres into
    the workpiece along the task's normal (s = 0: touching). A static probe (a
    continuous copy of the plant, the same contact properties, and the ideal
    contact sensor) measures F at q(s) in the controller's E_f coordinates, and
    s is found by root finding so that F . F_d / |F_d| = |F_d|. A disc tool is probed down to half its
    thickness at most: pushed through it, the workpiece's surface would leave the disc's volume and its
    hydroelastic contact with it (``station.tools``).
    """
    config, task = scenario.config, scenario.task
    tool = scenario.robot.tool
    if tool is not None and tool.is_disc:
        max_depth = min(max_depth, 0.5 * float(tool.thickness))
    config.desired_force.check_keeps_sign("desired_force")      # pushing at t = 0 (below), and on every row after
    desired = np.asarray(config.desired_force.evaluate(0.0)[0], dtype=float)
    magnitude = float(np.linalg.norm(desired))
    if magnitude == 0:
        return positions_at_depth(0.0)
    builder = DiagramBuilder()
    plant, _, robot = build_plant(task, config, builder, time_step=0.0)
    robot_bodies = [plant.get_body(i) for instance in robot.model_instances for i in plant.GetBodyIndices(instance)]
    sensor = builder.AddSystem(ContactWrenchSensor(plant, robot_bodies, robot.end_effector_frame,
                                                   robot.end_effector_point))
    builder.Connect(plant.get_contact_results_output_port(), sensor.get_input_port(0))
    builder.Connect(plant.get_body_poses_output_port(), sensor.get_input_port(1))
    probe = builder.Build()
    context = probe.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    sensor_context = sensor.GetMyContextFromRoot(context)
    kinematics = EndEffectorKinematics(plant, robot.end_effector_frame, robot.end_effector_point,
                                       scenario.constraint_space.chart)
    space = scenario.constraint_space

    def pressing_force(depth):
        plant.SetPositions(plant_context, robot.arm, positions_at_depth(depth))
        task_kinematics = kinematics.evaluate(plant_context)
        values = space.evaluate(task_kinematics.configuration, task_kinematics.velocity)
        wrench = space.chart.generalized_force(task_kinematics.configuration, sensor.get_output_port(0).Eval(sensor_context))
        force = space.split_wrench(values, wrench)[1]
        return float(force @ desired) / magnitude - magnitude

    return positions_at_depth(pressing_depth(pressing_force, desired, max_depth, f"task '{task.name}'"))
