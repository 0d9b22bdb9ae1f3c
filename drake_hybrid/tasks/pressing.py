"""The joint positions that press on a task's workpiece with the desired force (and, for a flat tool whose
orientation rows are force-controlled, with the desired moments).
"""

import numpy as np

from pydrake.common.eigen_geometry import AngleAxis
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import DiagramBuilder

from drake_hybrid.control.normal_force import normal_row, tool_axis_wrench
from drake_hybrid.core.errors import ConfigError, OffConstraintError
from drake_hybrid.core.kinematics import EndEffectorKinematics
from drake_hybrid.station.start import pressing_depth
from drake_hybrid.systems.contact_wrench_sensor import ContactWrenchSensor
from drake_hybrid.tasks.plant import build_plant

# A flat tool's start: its moment rows balanced to this (N m), by at most this many Newton steps on its tilt.
MOMENT_TOLERANCE = 1e-6
MOMENT_STEPS = 12
TILT_STEP = 1e-4          # rad, the finite differences of the moments' Jacobian


def _row_force_probe(scenario):
    """force_at(q, as_read=True) -> F: the rows' force [F_v; F] = E^-T w's F at the arm's positions q, on a static
    probe (a continuous copy of the plant, the same contact properties, and the ideal contact sensor), read as the
    scenario's controller reads it (its normal row along the tool's axis with ``normal_force_axis="tool"``), or,
    ``as_read=False``, the force the contact exerts in E's dual basis."""
    config, task = scenario.config, scenario.task
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

    along_tool_axis = reads_along_tool_axis(scenario)

    def force_at(q, as_read=True):
        plant.SetPositions(plant_context, robot.arm, q)
        task_kinematics = kinematics.evaluate(plant_context)
        x = task_kinematics.configuration
        values = space.evaluate(x, task_kinematics.velocity)
        spatial_wrench = sensor.get_output_port(0).Eval(sensor_context)
        if along_tool_axis and as_read:        # the normal row as the controller reads it (control.normal_force)
            spatial_wrench = tool_axis_wrench(space, x, task_kinematics.rotation, spatial_wrench, values)
        return space.split_wrench(values, space.chart.generalized_force(x, spatial_wrench))[1]
    return force_at


def reads_along_tool_axis(scenario):
    """Whether the scenario's controller reads its normal row along the tool's axis (control.normal_force)."""
    return getattr(scenario.controller, "normal_force_axis", "model") == "tool"


def held_force_integral(scenario, q, desired):
    """(F_h, xi) of an in-contact start at ``q`` pressing with ``desired`` (F_d(0)) as its controller reads it: the
    force the arm must hold in E_f's coordinates, and the force integral that makes the law hold it with a zero
    force error. Read along the model's normal they are F_d and 0. Read along the tool's axis (a flat tool turned
    off the model's normal, ``balanced_pressing_positions``), the contact's own normal-row force F_r differs
    from the F_d the row reads; the law's u_f = -F_d + K_fi xi (3.1-12, e_f = 0) holds -F_r when
    K_fi xi = F_d - F_r. ConfigError if no force integral can (a normal row without K_fi)."""
    desired = np.asarray(desired, dtype=float)
    if not reads_along_tool_axis(scenario):
        return desired, np.zeros(len(desired))
    contact = np.asarray(_row_force_probe(scenario)(q, as_read=False), dtype=float)
    held = desired.copy()
    row = normal_row(len(desired), tuple(scenario.constraint_space.constraint.kinematic_rows))
    held[row] = contact[row]
    gain = scenario.controller.validated_gains().force_integral
    shortfall = desired - held
    if shortfall[row] != 0 and not abs(gain[row, row]) > 0:
        raise ConfigError(f"task '{scenario.task.name}': the normal row reads the force along the tool's axis "
                          f"(tool.normal_force: tool), {desired[row]:.4g} N there being {held[row]:.4g} N in E's "
                          "dual basis at the start; holding it needs gains.force_integral > 0 on the normal row")
    return held, np.linalg.lstsq(gain, shortfall, rcond=None)[0]


def _max_depth(scenario, max_depth):
    """A disc tool is probed down to half its thickness at most: pushed through it, the workpiece's surface
    would leave the disc's volume and its hydroelastic contact with it (``station.tools``)."""
    tool = scenario.robot.tool
    return min(max_depth, 0.5 * float(tool.thickness)) if tool is not None and tool.is_disc else max_depth


def pressing_positions(scenario, positions_at_depth, max_depth=0.01):
    """Joint positions that press on the workpiece with the desired force F_d(0).

    ``positions_at_depth(s)`` gives the arm's q with the pad pushed s metres into
    the workpiece along the task's normal (s = 0: touching). A static probe (a
    continuous copy of the plant, the same contact properties, and the ideal
    contact sensor) measures F at q(s) in the controller's E_f coordinates, and
    s is found by root finding so that F . F_d / |F_d| = |F_d|. A disc tool is probed
    down to half its thickness at most.
    """
    config, task = scenario.config, scenario.task
    config.desired_force.check_keeps_sign("desired_force")      # pushing at t = 0 (below), and on every row after
    desired = np.asarray(config.desired_force.evaluate(0.0)[0], dtype=float)
    magnitude = float(np.linalg.norm(desired))
    if magnitude == 0:
        return positions_at_depth(0.0)
    force_at = _row_force_probe(scenario)

    def pressing_force(depth):
        return float(force_at(positions_at_depth(depth)) @ desired) / magnitude - magnitude

    max_depth = _max_depth(scenario, max_depth)
    return positions_at_depth(pressing_depth(pressing_force, desired, max_depth, f"task '{task.name}'"))


def moment_rows(space):
    """The force-controlled rows of the constraint space ``space`` besides its first (the normal force's): a
    flat tool's orientation rows when they are force-controlled (``ToolConfig.orientation``); empty otherwise."""
    controlled = [i for i in range(space.force_size) if i not in space.constraint.kinematic_rows]
    return controlled[1:]


def balanced_pressing_positions(scenario, pose_at_depth, positions_of, max_depth=0.01):
    """Joint positions that press with F_d(0) on the normal row and with F_d(0)'s moments on the tool's
    force-controlled orientation rows (``moment_rows``): the start of a flat tool, whose moments are an
    equilibrium only where it lies as its pressure wants (on a curved or a misplaced surface, not at the
    model's normal). ``pose_at_depth(s)`` is the controlled point's pose s metres into the workpiece (the
    model's orientation; s from -max_depth / 2, a face resting on its rim over a hollow), ``positions_of(X)`` the
    arm's q there (inverse kinematics). The tool is turned about
    its controlled point, about its own x and y axes, by Newton's method on the moments (the depth solved
    again at each turn), to within ``MOMENT_TOLERANCE`` N m; OffConstraintError if it does not get there."""
    rows = moment_rows(scenario.constraint_space)
    desired = np.asarray(scenario.config.desired_force.evaluate(0.0)[0], dtype=float)
    force_at = _row_force_probe(scenario)
    magnitude = float(np.linalg.norm(desired))
    max_depth = _max_depth(scenario, max_depth)
    who = f"task '{scenario.task.name}'"
    axes = pose_at_depth(0.0).rotation().matrix()[:, :2].T            # the tool's x and y at the model's pose
    # Over a hollow a flat face rests on its rim above the surface: the depth is searched from this far above it.
    lift = 0.5 * max_depth

    def turned(angles):
        angle = float(np.linalg.norm(angles))
        turn = (RotationMatrix(AngleAxis(angle, (angles[0] * axes[0] + angles[1] * axes[1]) / angle)) if angle > 0
                else RotationMatrix())

        def positions_at_depth(depth):
            X = pose_at_depth(depth)
            return positions_of(RigidTransform(turn @ X.rotation(), X.translation()))

        def pressing_force(depth):
            return float(force_at(positions_at_depth(depth - lift)) @ desired) / magnitude - magnitude

        q = positions_at_depth(pressing_depth(pressing_force, desired, max_depth + lift, who) - lift)
        return q, force_at(q)[rows] - desired[rows]

    angles = np.zeros(2)
    q, residual = turned(angles)
    for _ in range(MOMENT_STEPS):
        if float(np.max(np.abs(residual))) <= MOMENT_TOLERANCE:
            return q
        jacobian = np.column_stack([(turned(angles + TILT_STEP * axis)[1] - residual) / TILT_STEP
                                    for axis in np.eye(2)])
        angles = angles - np.linalg.lstsq(jacobian, residual, rcond=None)[0]
        q, residual = turned(angles)
    if float(np.max(np.abs(residual))) <= MOMENT_TOLERANCE:
        return q
    raise OffConstraintError(f"{who}: the flat tool's start does not balance its moments: "
                             f"{np.round(residual, 6).tolist()} N m left after {MOMENT_STEPS} turns (tilted "
                             f"{np.degrees(np.linalg.norm(angles)):.2f} deg); start it off the surface "
                             "(start.in_contact: false) and let the guarded approach land it")
