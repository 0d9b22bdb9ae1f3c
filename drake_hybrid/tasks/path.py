"""A task's path: the path of a config on the task's workpiece, its start and its duration.
"""

import dataclasses
import math

import numpy as np

from pydrake.math import RigidTransform, RotationMatrix

from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.kinematics import inverse_kinematics
from drake_hybrid.core.schema import unknown_field
from drake_hybrid.station.path_config import PathConfig
from drake_hybrid.station.path_job import check_heading_along, heading_of, lifts_off, path_on, start_pose_on
from drake_hybrid.systems.path_source import PathSource, reference_rotation
from drake_hybrid.systems.sources import Profile
from drake_hybrid.tasks.config import check_scenario_config
from drake_hybrid.tasks.pressing import pressing_positions

_PATHS = {}


def workpiece_surface(task, config):
    """(surface, pad offset) of the task's workpiece; ConfigError if the task names none."""
    surface = task.workpiece_surface(config)
    if surface is None:
        raise ConfigError(f"path: task '{task.name}' does not name its workpiece's surface (Task.workpiece_surface), "
                          "so a path cannot be laid on it")
    return surface


def build_path(task, config):
    """The SurfacePath of ``config.path`` on the task's workpiece (cached per task and config); held at
    one point when ``path.hold_at`` >= 0. PathError (one line) for a path the job cannot follow."""
    key = (task.name, repr(config.path), repr(sorted(config.task_parameters.items())),
           repr(sorted(config.task_options.items())))
    if key not in _PATHS:
        surface, offset = workpiece_surface(task, config)
        path = path_on(surface, offset, config.path)
        if config.path.heading:
            check_heading_along(path, heading_of(config.path, surface))
        _PATHS[key] = path
    return _PATHS[key]


def path_start_pose(task, config):
    """``start_pose_on`` the task's workpiece for ``config.path``."""
    return start_pose_on(workpiece_surface(task, config)[0], build_path(task, config), config.path)


def make_path_source(task, config, controller_plant, robot, constraint_space):
    """The PathSource of ``config.path`` (it waits for the first contact when the start is off the surface)."""
    surface, _ = workpiece_surface(task, config)
    path = build_path(task, config)
    kinematic = constraint_space.constraint.kinematic_rows
    force_row = next(i for i in range(constraint_space.force_size) if i not in kinematic)
    holding = config.path.holding
    period = config.control_period if config.control_period > 0 else None
    return PathSource(controller_plant, robot.end_effector_frame, robot.end_effector_point, constraint_space, path,
                      heading=heading_of(config.path, surface), force_row=force_row,
                      dwell=0.0 if holding else config.path.dwell,
                      wait_for_contact=config.supervised and not holding, period=period)


def path_start_positions(task, scenario, joint_guess):
    """The arm's start for a path job: the pad centre at the path's first point in its reference
    orientation (frame E turned as the reference, its point P there), pressing with F_d(0)
    (``start.in_contact``) or ``start.gap`` above along the normal (IK from ``joint_guess``)."""
    config = scenario.config
    X_WP, normal = path_start_pose(task, config)
    surface, offset = workpiece_surface(task, config)
    heading = heading_of(config.path, surface)
    kinematics = scenario.controller.kinematics
    context = kinematics.plant.CreateDefaultContext()
    seed = [np.asarray(joint_guess, dtype=float)]

    def positions_at_depth(depth):
        # The orientation the constraint's held rows want there (Surface.held_normal), not the surface point's.
        centre = X_WP.translation() - depth * normal
        rotation = RotationMatrix(reference_rotation(surface.held_normal(centre, offset), heading))
        X_target = RigidTransform(rotation, centre)
        seed[0] = inverse_kinematics(kinematics, context, X_target, seed[0])
        return seed[0]

    if not config.start.in_contact:
        return positions_at_depth(-config.start.gap)
    return pressing_positions(scenario, positions_at_depth)


def job_duration(task, config):
    """The simulated time a job needs (s, rounded up to 0.1 s): the guarded approach from ``start.gap``
    (when the start is off the surface) and 0.2 s, the dwell, the path, the lift-off and 0.3 s."""
    supervision = config.supervision
    approach = config.start.gap / supervision.approach_speed + 0.2 if not config.start.in_contact else 0.0
    lift = supervision.lift_height / supervision.approach_speed + 0.3 if lifts_off(config) else 0.0
    return math.ceil(10 * (approach + config.path.dwell + build_path(task, config).duration + lift)) / 10


def with_path_commands(config, constraint_space):
    """``config`` with desired_velocity zero and desired_force F(0) on the force row, constant: what the
    start (pressing with F_d(0)), the static torque and the summaries read; the run's commands come
    from the path."""
    kinematic = constraint_space.constraint.kinematic_rows
    force_row = next(i for i in range(constraint_space.force_size) if i not in kinematic)
    force = [0.0] * constraint_space.force_size
    force[force_row] = config.path.initial_force()
    return dataclasses.replace(config, desired_velocity=Profile(kind="constant",
                                                                value=[0.0] * constraint_space.velocity_size),
                               desired_force=Profile(kind="constant", value=force))


def with_path(config, **changes):
    """A copy of ``config`` with ``config.path`` fields changed (e.g. ``hold_at=0.5``); ConfigError (one
    line, as for a YAML file) for a name that is not a PathConfig field or a value not of its type."""
    check_scenario_config(config, "with_path")
    unknown = unknown_field(PathConfig, changes, "path")
    if unknown:
        raise ConfigError(unknown)
    return config.replace(path=dataclasses.replace(config.path, **changes))
