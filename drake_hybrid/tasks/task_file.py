"""A whole task in one YAML file, built: ``load_task_file(path)`` reads a task file
(``tasks.task_file_schema``) and returns a ``DataTask`` (a ``tasks.custom.CustomTask``, registered
by its name) and its ``ScenarioConfig``, so that every scenario tool (``simulate``,
``linearize_continuous``, the CLI's ``simulate|analyze FILE.yaml``) runs it as a built-in task.

One function per section turns it into the CustomTask's pieces: the chart (``make_chart``), the
constraint space (``constraint_space_of``: the constraint and E_p rows, parsed by the whitelisted
grammar of ``core.expressions``, never evaluated as Python), the start (``start_configuration_of``),
the robot and the workpiece (``tasks.task_file_models``), a job's surface and fields
(``tasks.task_file_surface``). The start pose is given in the chart's coordinates of the controlled
point (``start.configuration``; or ``start.pose`` = [x, y, z, roll, pitch, yaw] of frame E); it is
stored in ``config.start.configuration`` as chart coordinates, and ``config.task`` is the file's
name.
"""

import dataclasses
import math
import os
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple, Union, cast

import numpy as np

from pydrake.geometry import GeometryId
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Context, System

from drake_hybrid.core.charts import Chart, EulerZXZChart, PlanarChart, PlanarPointChart, PoseChart
from drake_hybrid.core.constraints import Constraint
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.expressions import check_parameter_names, expression_row_to_sympy, expression_to_sympy
from drake_hybrid.core.hints import Array
from drake_hybrid.core.projections import (AnyVelocityProjection, ConstraintSpace, GivenVelocityProjection,
                                           KernelVelocityProjection)
from drake_hybrid.core.schema import read_yaml_file
from drake_hybrid.core.surfaces import Surface, view_projection
from drake_hybrid.station.path_job import path_on, start_pose_on, view_of
from drake_hybrid.station.robot_model import RobotModel
from drake_hybrid.systems.sources import Profile
from drake_hybrid.tasks.config import ScenarioConfig
from drake_hybrid.tasks.custom import CustomTask
from drake_hybrid.tasks.hooks import make_hooks
from drake_hybrid.tasks.path import path_start_positions
from drake_hybrid.tasks.registry import register_task
from drake_hybrid.tasks.surface_model import model_surface, surface_constraint_space
from drake_hybrid.tasks.task import EigenvalueShift, Scenario
from drake_hybrid.tasks.task_file_models import _robot_adder, _workpiece_adder, model_packages
from drake_hybrid.tasks.task_file_schema import CHARTS, MAX_FILE_SIZE, ChartSpec, TaskFile, read_task_file
from drake_hybrid.tasks.task_file_surface import field_expressions, field_source, surface_of


def make_chart(spec: ChartSpec, where: str) -> Chart:
    if spec.kind not in CHARTS:
        raise ConfigError(f"{where}chart.kind must be one of {', '.join(CHARTS)}, got '{spec.kind}'")
    if spec.kind == "euler_zxz":
        return EulerZXZChart()
    if spec.kind == "pose":
        return PoseChart()
    for name in ("origin", "axis_x", "axis_y"):
        values = getattr(spec, name)
        if len(values) != 3 or not all(math.isfinite(v) for v in values):
            raise ConfigError(f"{where}chart.{name} must be 3 finite numbers, got {values}")
    kind = PlanarChart if spec.kind == "planar" else PlanarPointChart
    try:
        return kind(origin=spec.origin, axis_x=spec.axis_x, axis_y=spec.axis_y)
    except ValueError as error:
        raise ConfigError(f"{where}chart: {error}") from None


class DataTask(CustomTask):
    """A CustomTask read from a task file (``load_task_file``); also keeps its ``spec`` (TaskFile)
    and ``path``. Its start is in the chart's coordinates of the controlled point (``config.start.configuration``
    with the chart's number of coordinates; six numbers [x, y, z, roll, pitch, yaw] of E otherwise)."""

    def __init__(self, spec: TaskFile, path: Union[str, os.PathLike], text: str,
                 hooks: Optional[Mapping[str, Callable[..., Any]]] = None, continuous_plant: bool = True,
                 surface: Optional[Tuple[Surface, float]] = None, fields: Optional[Tuple[List[Any], List[Any]]] = None,
                 **pieces: Any) -> None:
        super().__init__(**pieces)
        self.spec, self.path, self.text = spec, Path(path), text
        self.hooks = dict(hooks or {})            # {Task method: the hook's implementation} (tasks/hooks.py)
        self.continuous_plant = continuous_plant
        self.surface, self.fields = surface, fields   # (Surface, offset) or None; (Y_d, F_d) or None
        self._config: Optional[ScenarioConfig] = None     # set by load_task_file

    def _hook(self, method):
        return self.hooks.get(method)

    def __reduce__(self):
        """Pickled as the file's text (for Dask workers, other processes): rebuilt there by parsing it
        again (the compiled constraint and Drake's config structs do not pickle)."""
        return _task_from_text, (str(self.path), self.text, self.name)

    def base_config(self, options: Dict[str, Any]) -> ScenarioConfig:
        assert self._config is not None             # set by load_task_file, which makes every DataTask
        return dataclasses.replace(self._config, start=dataclasses.replace(self._config.start))

    # -- the Task methods a hook may provide (the CustomTask's otherwise) --------------------------
    def add_robot(self, plant: MultibodyPlant, config: ScenarioConfig) -> RobotModel:
        robot = self._add_robot(plant, config)              # the file's robot with config.tool, or a hook's
        if not isinstance(robot, RobotModel):
            raise TypeError(f"task '{self.name}': add_robot must return a RobotModel (see mount_tool), "
                            f"got {type(robot).__name__}")
        return robot

    def add_workpiece(self, plant: MultibodyPlant, config: ScenarioConfig) -> List[GeometryId]:
        return list(self._add_workpiece(plant, config))     # the file's workpiece, then a hook's

    def workpiece_surface(self, config: ScenarioConfig) -> Optional[Tuple[Surface, float]]:
        """The surface the controller is given (the file's, moved by ``config.model_error``'s workpiece error)
        and the tool's offset (``workpiece.surface.offset``; 0 for a disc, whose face is the controlled point)."""
        if self.surface is None:
            return None
        surface, offset = self.surface
        if config.tool.is_disc and offset != 0:
            raise ConfigError(f"{self.path}: workpiece.surface.offset is {offset:g} m; a disc's controlled point is "
                              "the centre of its face, on the surface: give offset: 0.0 with tool.kind: disc")
        return model_surface(surface, offset, config), offset

    def real_workpiece_surface(self, config: ScenarioConfig) -> Optional[Surface]:
        return self.surface[0] if self.surface is not None else None

    def constraint_space(self, config: ScenarioConfig) -> ConstraintSpace:
        """The file's constraint space; one laid on the model surface (``tasks.surface_model``) where the
        constraint comes from ``workpiece.surface`` and the config moves the model or force-controls the
        orientation rows (``tool``)."""
        from_surface = (self.surface is not None and not self.spec.constraint.rows and "constraint" not in self.hooks
                        and not self.spec.velocity_projection.rows)
        if config.tool.orientation == "force" and not from_surface:
            raise ConfigError(f"{self.path}: tool.orientation: force needs the constraint of workpiece.surface (no "
                              "constraint.rows, no constraint hook, no velocity_projection.rows); with rows of your "
                              "own, leave out the orientation rows from constraint.kinematic_rows instead")
        if not from_surface or not (config.tool.orientation_rows == "force" or config.model_error.workpiece_moved):
            return self.space
        surface = self.workpiece_surface(config)
        assert surface is not None                 # from_surface
        return surface_constraint_space(surface[0], surface[1], config, view_of(self.spec.config.path, surface[0]))

    def make_source(self, config: ScenarioConfig, controller_plant: MultibodyPlant, robot: RobotModel,
                    constraint_space: ConstraintSpace) -> System:
        if self.fields is not None:                # the paper's fields Y_d(r), F_d(r) (tasks/task_file_surface.py)
            return field_source(self.fields, controller_plant, robot, constraint_space, f"{self.path}: ")
        hook = self._hook("make_source") or super().make_source
        return hook(config, controller_plant, robot, constraint_space)

    def start_positions(self, scenario: Scenario) -> Array:
        if scenario.config.path.active and self._hook("start_positions") is None:   # a job: the path's first point
            return path_start_positions(self, scenario, self.joint_guess)
        return (self._hook("start_positions") or super().start_positions)(scenario)

    def set_environment_state(self, scenario: Scenario, plant_context: Context) -> None:
        (self._hook("set_environment_state") or super().set_environment_state)(scenario, plant_context)

    def velocity_row_inertia(self, plant: MultibodyPlant, config: ScenarioConfig,
                             constraint_space: ConstraintSpace) -> Array:
        return (self._hook("velocity_row_inertia") or super().velocity_row_inertia)(plant, config, constraint_space)

    def eigenvalue_shifts(self, scenario: Scenario, root_context: Context) -> List[EigenvalueShift]:
        return (self._hook("eigenvalue_shifts") or super().eigenvalue_shifts)(scenario, root_context)

    def run_notes(self, scenario: Scenario, log: Mapping[str, Array], design_time_constant: float) -> List[str]:
        return (self._hook("run_notes") or super().run_notes)(scenario, log, design_time_constant)

    def run_events(self, scenario: Scenario, log: Mapping[str, Array]) -> List[Dict[str, Any]]:
        return (self._hook("run_events") or super().run_events)(scenario, log)

    def start_field(self) -> Tuple[str, str]:
        """(the file, ``start.pose`` or ``start.configuration``: the field the start came from)."""
        return str(self.path), "start.configuration" if self.spec.start.configuration else "start.pose"

    def start_pose_of(self, config: ScenarioConfig) -> RigidTransform:
        values = list(config.start.configuration)
        if len(values) == self.space.chart.configuration_size:
            # The chart's coordinates are the controlled point's: X_WE = X_WP X_PE, p_PE = -p_EP.
            X_WP = self.space.chart.pose(np.asarray(values, dtype=float))
            p_PE: Array = -np.asarray(self.spec.robot.end_effector_point, dtype=float)
            return X_WP.multiply(RigidTransform(p_PE))
        return super().start_pose_of(config)


def constraint_space_of(spec: TaskFile, chart: Chart, where: str, anchor: Array,
                        hooks: Optional[Mapping[str, Callable[..., Any]]] = None,
                        surface: Optional[Tuple[Surface, float]] = None) -> ConstraintSpace:
    """The ConstraintSpace of the file: C from ``constraint.rows`` (or a hook's ``constraint``, or the
    ``workpiece.surface`` offset by the pad's radius), E_p from ``velocity_projection`` (the view's rows
    with a surface, else the kernel of E_f at ``anchor``, when no rows are given)."""
    symbols, parameters = chart.configuration_symbols, spec.parameters
    if hooks and "constraint" in hooks:
        if spec.constraint.rows or spec.constraint.kinematic_rows or spec.constraint.branch:
            raise ConfigError(f"{where}constraint: a hook gives the constraint; give no rows, kinematic_rows or "
                              "branch")
        constraint = hooks["constraint"](chart)
    elif surface is not None and not spec.constraint.rows:
        try:
            # A file may name any chart: offset_constraint refuses one that is not 3-D (PathError).
            constraint = surface[0].offset_constraint(cast(Union[PoseChart, EulerZXZChart], chart), surface[1])
        except TypeError as error:
            raise ConfigError(f"{where}workpiece.surface: {error} (chart.kind: pose)") from None
    else:
        constraint = _constraint_of_rows(spec, chart, where)
    d = chart.velocity_size
    given = spec.velocity_projection.rows
    try:
        if given:
            matrix = [expression_row_to_sympy(text, d, symbols, parameters, f"{where}velocity_projection.rows[{i}]")
                      for i, text in enumerate(given)]
            projection: AnyVelocityProjection = GivenVelocityProjection(chart, matrix, name="E_p")
        elif surface is not None:
            projection = view_projection(cast(Union[PoseChart, EulerZXZChart], chart),   # refuses a planar one
                                         view_of(spec.config.path, surface[0]))
        else:
            projection = KernelVelocityProjection(constraint, anchor)
        return ConstraintSpace(constraint, projection)
    except ConfigError:
        raise
    except (ValueError, TypeError) as error:
        raise ConfigError(f"{where}velocity_projection: {error}") from None


def _constraint_of_rows(spec, chart, where):
    symbols, parameters = chart.configuration_symbols, spec.parameters
    if not spec.constraint.rows:
        raise ConfigError(f"{where}constraint.rows: give C(x) as one expression per row")
    rows = [expression_to_sympy(text, symbols, parameters, f"{where}constraint.rows[{i}]")
            for i, text in enumerate(spec.constraint.rows)]
    branch = (expression_to_sympy(spec.constraint.branch, symbols, parameters, f"{where}constraint.branch")
              if spec.constraint.branch else None)
    try:
        return Constraint(chart, rows, name=spec.constraint.name, kinematic_rows=spec.constraint.kinematic_rows,
                          branch=branch, branch_description=spec.constraint.branch_description)
    except ValueError as error:
        raise ConfigError(f"{where}constraint: {error}") from None


def start_configuration_of(spec: TaskFile, chart: Chart, where: str) -> Array:
    """The start's chart coordinates (numbers) from ``start.configuration`` or ``start.pose``."""
    start = spec.start
    if start.configuration and start.pose:
        raise ConfigError(f"{where}start: give configuration (chart coordinates) or pose, not both")
    if start.configuration:
        if len(start.configuration) != chart.configuration_size:
            raise ConfigError(f"{where}start.configuration must have {chart.configuration_size} entries "
                              f"({[str(s) for s in chart.configuration_symbols]}), got {len(start.configuration)}")
        values = []
        for i, text in enumerate(start.configuration):
            expression = expression_to_sympy(text, (), spec.parameters, f"{where}start.configuration[{i}]")
            values.append(float(expression.evalf()))
        return np.array(values)
    if len(start.pose) != 6:
        raise ConfigError(f"{where}start: give configuration (chart coordinates) or pose [x, y, z, roll, pitch, "
                          f"yaw] of the end-effector frame, got pose {start.pose}")
    rpy: Array = np.asarray(start.pose[3:], dtype=float)     # Array: what pydrake's stubs take (core.hints.Array)
    p_WE: Array = np.asarray(start.pose[:3], dtype=float)
    p_EP: Array = np.asarray(spec.robot.end_effector_point, dtype=float)
    X_WE = RigidTransform(RollPitchYaw(rpy), p_WE)
    return chart.configuration_of_pose(X_WE.multiply(RigidTransform(p_EP)))


def _task_from_text(path, text, name):
    task = load_task_file(path, register=False, text=text)[0]
    task.name = task._config.task = name
    return task


def load_task_file(path: Union[str, os.PathLike], register: bool = True,
                   text: Optional[str] = None) -> Tuple[DataTask, ScenarioConfig]:
    """(DataTask, ScenarioConfig) of the task file ``path``; the task is registered by its name
    (``register_task``: known to ``simulate``, ``linearize_continuous``, the CLI) unless ``register``
    is False. ConfigError naming the file and the field for anything the file gets wrong."""
    text = read_yaml_file(path, "task file", max_size=MAX_FILE_SIZE) if text is None else text
    spec = read_task_file(path, text)
    where = f"{path}: "
    if not spec.name:
        raise ConfigError(f"{where}name: give the task a name")
    check_parameter_names(spec.parameters, (), f"{where}parameters")
    chart = make_chart(spec.chart, where)
    check_parameter_names(spec.parameters, chart.configuration_symbols, f"{where}parameters")
    surface: Optional[Tuple[Surface, float]] = surface_of(spec.workpiece.surface, path, where)
    job = spec.config.path
    if job.active:
        job.validate(f"{where}config.path.")
        if surface is None:
            raise ConfigError(f"{where}config.path: a path needs workpiece.surface (the surface it lies on)")
    if job.active and not (spec.start.configuration or spec.start.pose):
        # A job starts at its path's first point (station.path_job).
        assert surface is not None                  # a job without one was refused above
        start = chart.configuration_of_pose(start_pose_on(surface[0], path_on(*surface, job), job)[0])
    else:
        start = start_configuration_of(spec, chart, where)
    hooks, continuous_plant = make_hooks(spec, where)
    packages = model_packages(spec, path, where)
    space = constraint_space_of(spec, chart, where, anchor=start, hooks=hooks, surface=surface)
    fields = field_expressions(spec.fields, chart, spec.parameters, where, space.force_size)
    if fields is not None and job.active:
        raise ConfigError(f"{where}fields: a job's path gives the desired motion and force; give fields or "
                          "config.path, not both")
    if len(spec.start.joint_guess) == 0:
        raise ConfigError(f"{where}start.joint_guess: give the arm's joint positions inverse kinematics starts from")
    labels = dataclasses.asdict(spec.labels)
    k, m = space.velocity_size, space.force_size
    labels["velocity"] = labels["velocity"] or [f"r-dot_p[{i}]" for i in range(k)]
    labels["force"] = labels["force"] or [f"F[{i}]" for i in range(m)]
    if not labels["constraint_units"]:
        del labels["constraint_units"]         # the summary then says "in the units of C's rows"
    task = DataTask(spec, path, text, hooks=hooks, continuous_plant=continuous_plant, name=spec.name,
                    add_robot=_robot_adder(spec, path, where, hooks, packages),
                    add_workpiece=_workpiece_adder(spec, path, where, hooks, packages, surface),
                    constraint_space=space, start_pose=chart.pose(start), joint_guess=spec.start.joint_guess,
                    labels=labels, description=spec.description, surface=surface, fields=fields)
    config = dataclasses.replace(spec.config, task=spec.name)
    config.start = dataclasses.replace(config.start, configuration=[float(v) for v in start])
    if fields is not None:
        # The fields' commands at the start (what the start presses with, scenario.start): F_d(r_0) and Y_d(r_0).
        values = {symbol: value for symbol, value in zip(chart.configuration_symbols, start)}
        config.desired_force = Profile(kind="constant", value=[float(f.evalf(subs=values)) for f in fields[1]])
        config.desired_velocity = Profile(kind="constant", value=[0.0] * space.velocity_size)
    config.validate()
    task._config = config
    if register:
        try:
            register_task(task)
        except ValueError as error:
            raise ConfigError(f"{where}name: {error}") from None
    return task, task.default_config()
