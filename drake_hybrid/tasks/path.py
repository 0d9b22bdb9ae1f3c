"""A task's path: the path of a config on the task's workpiece, its start and its duration.
"""

import dataclasses
from typing import Any, Dict, Tuple

import numpy as np
from numpy.typing import ArrayLike

from pydrake.math import RigidTransform

from drake_hybrid.control.normal_force import normal_row
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.hints import Array
from drake_hybrid.core.kinematics import inverse_kinematics
from drake_hybrid.core.paths import SurfacePath
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.core.schema import unknown_field
from drake_hybrid.core.surfaces import Surface
from drake_hybrid.station.path_config import PathConfig
from drake_hybrid.station.path_job import PathJob, path_job
from drake_hybrid.systems.sources import Profile
from drake_hybrid.tasks.config import ScenarioConfig, check_scenario_config
from drake_hybrid.tasks.pressing import balanced_pressing_positions, moment_rows, pressing_positions
from drake_hybrid.tasks.task import Scenario, Task

_JOBS: Dict[Tuple[str, ...], PathJob] = {}


def workpiece_surface(task: Task, config: ScenarioConfig) -> Tuple[Surface, float]:
    """(surface, pad offset) of the task's workpiece; ConfigError if the task names none."""
    surface = task.workpiece_surface(config)
    if surface is None:
        raise ConfigError(f"path: task '{task.name}' does not name its workpiece's surface (Task.workpiece_surface), "
                          "so a path cannot be laid on it")
    return surface


def task_path_job(task: Task, config: ScenarioConfig) -> PathJob:
    """The PathJob of ``config.path`` on the task's workpiece (``station.path_job.path_job``; cached per
    task and config): what ``build_scenario`` runs. PathError (one line) for a path the job cannot follow."""
    key = (task.name, repr(config.path), repr(sorted(config.task_parameters.items())),
           repr(sorted(config.task_options.items())), repr(config.tool), repr(config.model_error))
    if key not in _JOBS:
        surface, offset = workpiece_surface(task, config)
        _JOBS[key] = path_job(surface, offset, config.path)
    return _JOBS[key]


def build_path(task: Task, config: ScenarioConfig) -> SurfacePath:
    """The SurfacePath of ``config.path`` on the task's workpiece (``task_path_job``'s); held at one point
    when ``path.hold_at`` >= 0."""
    return task_path_job(task, config).path


def path_start_pose(task: Task, config: ScenarioConfig) -> Tuple[RigidTransform, np.ndarray]:
    """(X_WP, normal): the pad centre's pose at the first point of the task's path and the normal there."""
    return task_path_job(task, config).start_pose()


def path_start_positions(task: Task, scenario: Scenario, joint_guess: ArrayLike) -> Array:
    """The arm's start for a path job: the pad centre at the path's first point in its reference
    orientation (frame E turned as the reference, its point P there), pressing with F_d(0)
    (``start.in_contact``) or ``start.gap`` above along the normal (IK from ``joint_guess``)."""
    config = scenario.config
    job = task_path_job(task, config)
    kinematics = scenario.controller.kinematics
    context = kinematics.plant.CreateDefaultContext()
    seed = [np.asarray(joint_guess, dtype=float)]

    def positions_at_depth(depth):
        seed[0] = inverse_kinematics(kinematics, context, job.pose_at_depth(depth), seed[0])
        return seed[0]

    if not config.start.in_contact:
        return positions_at_depth(-config.start.gap)
    if moment_rows(scenario.constraint_space):        # a flat tool's moment rows: turned until they read their F_d too
        return balanced_pressing_positions(scenario, job.pose_at_depth,
                                           lambda X: inverse_kinematics(kinematics, context, X, seed[0]))
    return pressing_positions(scenario, positions_at_depth)


def job_duration(task: Task, config: ScenarioConfig) -> float:
    """The simulated time a job needs (s, rounded up to 0.1 s; ``PathJob.duration``): the guarded approach
    from ``start.gap`` (when the start is off the surface), the dwell, the path and the lift-off."""
    supervision = config.supervision if config.supervised else None
    return task_path_job(task, config).duration(supervision, None if config.start.in_contact else config.start.gap)


def with_path_commands(config: ScenarioConfig, constraint_space: ConstraintSpace, job: PathJob) -> ScenarioConfig:
    """``config`` with desired_velocity zero and desired_force constant, the force ``job`` (the config's
    ``task_path_job``) commands where it starts on the force row: at the path's first point, or at the
    point it holds (``path.hold_at``: per waypoint or by arc length, the force there). What the start
    (pressing with that force), the static torque and the summaries read; the run's commands come from
    the path."""
    force_row = normal_row(constraint_space.force_size, tuple(constraint_space.constraint.kinematic_rows))
    force = [0.0] * constraint_space.force_size
    force[force_row] = float(job.path.force(0.0))
    moment_row_indices = moment_rows(constraint_space)
    if config.path.moments and len(config.path.moments) != len(moment_row_indices):
        raise ConfigError(f"path.moments: {len(config.path.moments)} given, but the constraint has "
                          f"{len(moment_row_indices)} force-controlled rows besides the normal force "
                          "(its orientation rows are held: tool.orientation)")
    for row, moment in zip(moment_row_indices, config.path.moments):
        force[row] = float(moment)
    return dataclasses.replace(config, desired_velocity=Profile(kind="constant",
                                                                value=[0.0] * constraint_space.velocity_size),
                               desired_force=Profile(kind="constant", value=force))


def with_path(config: ScenarioConfig, **changes: Any) -> ScenarioConfig:
    """A copy of ``config`` with ``config.path`` fields changed (e.g. ``hold_at=0.5``); ConfigError (one
    line, as for a YAML file) for a name that is not a PathConfig field or a value not of its type."""
    check_scenario_config(config, "with_path")
    unknown = unknown_field(PathConfig, changes, "path")
    if unknown:
        raise ConfigError(unknown)
    return config.replace(path=dataclasses.replace(config.path, **changes))
