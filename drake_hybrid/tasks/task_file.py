"""A whole task in one YAML file: robot, workpiece, chart, constraint, start and run configuration.

``load_task_file(path)`` reads a task file with Drake's typed YAML (``yaml_load_typed`` on the
dataclasses below, after the schema pre-check that names the field) and returns a ``DataTask``
(a ``tasks.custom.CustomTask``, registered by its name) and its ``ScenarioConfig``, so that
every scenario tool (``simulate``, ``linearize_continuous``, the CLI's ``simulate|analyze
FILE.yaml``) runs it as a built-in task. The file::

    name: window-washing-file              # the task's name (not a built-in one)
    parameters: {window_height: 1.0}       # named numbers the expressions may use
    hooks: []                              # names of registered Python hooks (tasks/hooks.py)
    packages: {}                           # {name: folder} for package:// URLs (relative to the file)
    robot:
      directives:                          # Drake model directives (add_model, add_weld, add_frame, ...)
      - add_model: {name: arm, file: package://drake_hybrid/planar_3r.sdf}
      - add_weld: {parent: world, child: arm::base}
      arm: arm                             # the model instance whose joints the law drives
      tool: {flange_frame: link3, X_flange_tool: {translation: [0.25, 0, 0], rotation: !Rpy {deg: [0, 90, 0]}}}
      end_effector_frame: pad_center       # frame E (the pad tool's pad_center by default)
    # or an arm from a model package:
    #   robot: {loader: {path: package://example-robot-data/robots/ur_description/urdf/ur10_robot.urdf, flange: tool0}}
    workpiece:
      directives: [...]                    # models welded in the scene (all their collision geometries)
      shapes:                              # and/or shapes of the library (rigid hydroelastic)
      - {shape: box, size: [3.0, 0.5, 0.02], X_WG: {translation: [1.0, 0, 1.01]}}
    chart: {kind: planar}                  # planar | planar_point | euler_zxz | pose (core/charts.py)
    constraint:
      rows: ["y - (window_height - 0.02)"] # C(x) = 0 in the chart's coordinates (core/expressions.py)
      kinematic_rows: []                   # rows the controller holds itself (no force along them)
    velocity_projection:
      rows: ["1, 0, 0", "0, 0, 1"]         # E_p, one row per text; empty: a basis of ker E_f (kernel)
    start:
      configuration: ["0.9", "window_height - 0.02", "pi/2"]   # chart coordinates of the point, on C = 0
      joint_guess: [...]                   # where inverse kinematics starts
    config: {...}                          # a ScenarioConfig (tasks/config.py): mode, gains, profiles, ...

Size: one schema (the dataclasses) and the one function per section that turns it into the
CustomTask's pieces; splitting them would put the schema and its meaning in different files.

Expressions are parsed by the whitelisted grammar of ``core.expressions`` (never evaluated as
Python): a file from someone else cannot run code. They are taken by the constraint and E_p rows,
the start, and the number lists of poses outside ``config`` (``translation``, ``rotation: !Rpy
{deg}``: ``evaluate_pose_expressions``). Hooks (``tasks.hooks``) are looked up by name in a
registry, never imported from the file. Model files: ``package://`` URLs (``model_packages``) or
paths relative to the file (``resolve_model_file``). The start pose is given in the chart's
coordinates of the controlled point (``start.configuration``; or ``start.pose`` = [x, y, z, roll,
pitch, yaw] of frame E); it is stored in ``config.start.configuration`` as chart coordinates, and ``config.task`` is the file's name.
"""

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List

import numpy as np
import yaml

from pydrake.common.schema import Transform
from pydrake.common.yaml import yaml_load_typed
from pydrake.geometry import Box, Capsule, Cylinder, Ellipsoid, Sphere
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.parsing import ModelDirective, ModelDirectives, Parser, ProcessModelDirectives
from pydrake.multibody.tree import ModelInstanceIndex

from drake_hybrid.core.charts import EulerZXZChart, PlanarChart, PlanarPointChart, PoseChart
from drake_hybrid.core.constraints import Constraint
from drake_hybrid.core.errors import ConfigError, UnknownFrameError
from drake_hybrid.core.expressions import check_parameter_names, expression_row_to_sympy, expression_to_sympy
from drake_hybrid.core.projections import ConstraintSpace, GivenVelocityProjection, KernelVelocityProjection
from drake_hybrid.core.schema import check_depth, check_yaml_against_schema, read_yaml_file
from drake_hybrid.core.surfaces import view_projection
from drake_hybrid.station.arm import mount_tool
from drake_hybrid.station.parsing import ConfigureParser, installed_model_packages, models_directory
from drake_hybrid.station.path_job import path_on, start_pose_on, view_of
from drake_hybrid.station.workpieces import add_rigid_workpiece
from drake_hybrid.systems.sources import Profile
from drake_hybrid.tasks.config import ScenarioConfig
from drake_hybrid.tasks.custom import CustomTask
from drake_hybrid.tasks.hooks import make_hooks
from drake_hybrid.tasks.path import path_start_positions
from drake_hybrid.tasks.registry import register_task
from drake_hybrid.tasks.robots import TOOL_AXES, load_arm
from drake_hybrid.tasks.task_file_surface import (FieldsSpec, SurfaceSpec, add_surface_geometry, field_expressions,
                                                  field_source, surface_of)

MAX_FILE_SIZE = 1_000_000      # characters of a task file
CHARTS = ("planar", "planar_point", "euler_zxz", "pose")
SHAPES = {"box": (Box, 3), "sphere": (Sphere, 1), "cylinder": (Cylinder, 2), "ellipsoid": (Ellipsoid, 3),
          "capsule": (Capsule, 2)}


@dataclass
class ToolSpec:
    """The pad tool (models/pad_tool.sdf) welded to ``flange_frame`` of the arm at ``X_flange_tool``
    (its +z the approach direction; the pad centre 0.05 m along it). Empty ``flange_frame``: no tool."""

    flange_frame: str = ""                       # frame of the arm the tool is welded to ("": no tool)
    X_flange_tool: Transform = field(default_factory=Transform)   # the tool frame in the flange frame (m, deg)


@dataclass
class LoaderSpec:
    """``tasks.robots.load_arm``'s options: an arm from a URDF/SDF file (relative to the task file)."""

    path: str = ""                               # URDF/SDF file: package:// URL, absolute or relative to the file
    flange: str = ""                             # the frame (link) that ends the actuated chain
    tool_frame: str = ""                         # default: the flange
    base_pose: Transform = field(default_factory=Transform)   # X_W_base, where the base is welded
    tool_axis: str = "+z"                        # the tool frame's axis the pad points along: +-x, +-y, +-z
    collision: str = "convert"                   # "convert" or "drop"


@dataclass
class RobotSpec:
    """The robot: Drake model directives (with ``arm`` and ``tool``), or ``loader`` (load_arm)."""

    directives: List[ModelDirective] = field(default_factory=list)   # Drake model directives of the robot
    arm: str = ""                                # model instance of the actuated arm (directives)
    tool: ToolSpec = field(default_factory=ToolSpec)           # the pad tool (directives)
    loader: LoaderSpec = field(default_factory=LoaderSpec)     # or the arm loader (then no directives)
    end_effector_frame: str = "pad_center"       # frame E whose point the constraint is on
    end_effector_point: List[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])   # p_EP (m), in E
    only_pad_contact: bool = True                # filter every robot contact but the pad's


@dataclass
class ShapeSpec:
    """A rigid hydroelastic shape on the world body (``custom.add_rigid_workpiece``).
    size: box [x, y, z], sphere [r], cylinder [r, length], ellipsoid [a, b, c], capsule [r, length] (m)."""

    shape: str = "box"                           # box, sphere, cylinder, ellipsoid or capsule
    size: List[float] = field(default_factory=list)   # m (see the class docstring)
    X_WG: Transform = field(default_factory=Transform)   # the shape's pose in the world (m, deg)
    name: str = "workpiece"                      # geometry name (the index is appended)
    resolution_hint: float = 0.0                 # m; 0: the library's, tied to the curvature (custom.default_resolution)


@dataclass
class WorkpieceSpec:
    """The workpiece: models (every collision geometry of their bodies) and library shapes."""

    directives: List[ModelDirective] = field(default_factory=list)   # Drake model directives (e.g. add_weld)
    shapes: List[ShapeSpec] = field(default_factory=list)            # rigid hydroelastic shapes on the world
    surface: SurfaceSpec = field(default_factory=SurfaceSpec)  # the surface a path lies on (tasks/task_file_surface.py)


@dataclass
class ChartSpec:
    """The chart (core/charts.py). The planar charts' plane: origin and in-plane axes (world)."""

    kind: str = "planar"                         # planar (x, y, theta), planar_point (x, y), euler_zxz, pose
    origin: List[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])   # m, the plane's origin (planar)
    axis_x: List[float] = field(default_factory=lambda: [1.0, 0.0, 0.0])   # the chart's x in the world (planar)
    axis_y: List[float] = field(default_factory=lambda: [0.0, 0.0, 1.0])   # the chart's y in the world (planar)


@dataclass
class ConstraintSpec:
    """C(x) = 0 in the chart's coordinates (core/constraints.py)."""

    rows: List[str] = field(default_factory=list)          # C(x), one expression per row
    kinematic_rows: List[int] = field(default_factory=list)   # rows the controller holds itself (no force)
    name: str = "constraint"                               # for messages
    branch: str = ""                                       # negative on the intended branch (checked at the start)
    branch_description: str = "the intended branch"        # for the message when the start is on another


@dataclass
class VelocityProjectionSpec:
    """E_p: the velocity-controlled rows (core/projections.py)."""

    rows: List[str] = field(default_factory=list)    # E_p's rows, "a, b, c" (d entries each); empty: kernel


@dataclass
class StartSpec:
    """Where the run starts: the controlled point on C = 0 (pressing with F_d(0) is found from it)."""

    configuration: List[str] = field(default_factory=list)  # chart coordinates of the point (expressions)
    pose: List[float] = field(default_factory=list)         # or [x, y, z, roll, pitch, yaw] of E (m, rad)
    joint_guess: List[float] = field(default_factory=list)  # arm joint positions IK starts from (rad, m)


@dataclass
class LabelsSpec:
    """Plot and summary labels of the velocity- and force-controlled rows.

    velocity_units: the velocity rows' units, one for all or one per row ("m/s | rad/s").
    force_units: the force rows' units, one for all or one per row ("N | N m").
    """

    velocity: List[str] = field(default_factory=list)       # one per E_p row (default r-dot_p[i])
    velocity_units: str = "SI"
    force: List[str] = field(default_factory=list)          # one per C row (default F[i])
    force_units: str = "SI"
    constraint_units: str = ""   # C(r)'s rows: "m", or one per row "m^2 | m | 1 | m" ("": not declared)


@dataclass
class TaskFile:
    """The schema of a task file (see the module docstring)."""

    name: str = ""                               # the task's name (ScenarioConfig.task; not a built-in one)
    description: str = "a task from a scenario file"   # shown by drake-hybrid tasks
    parameters: Dict[str, float] = field(default_factory=dict)   # named numbers the expressions may use
    hooks: List[str] = field(default_factory=list)     # names of registered Python hooks (tasks/hooks.py)
    packages: Dict[str, str] = field(default_factory=dict)   # {name: folder (relative to the file)} for package://
    robot: RobotSpec = field(default_factory=RobotSpec)
    workpiece: WorkpieceSpec = field(default_factory=WorkpieceSpec)
    chart: ChartSpec = field(default_factory=ChartSpec)
    constraint: ConstraintSpec = field(default_factory=ConstraintSpec)
    velocity_projection: VelocityProjectionSpec = field(default_factory=VelocityProjectionSpec)
    start: StartSpec = field(default_factory=StartSpec)
    labels: LabelsSpec = field(default_factory=LabelsSpec)
    fields: FieldsSpec = field(default_factory=FieldsSpec)   # Y_d(r), F_d(r) as expressions (tasks/task_file_surface.py)
    config: ScenarioConfig = field(default_factory=ScenarioConfig)   # the run (task is set to name)


def read_task_file(path, text=None):
    """The TaskFile of ``path`` (or of ``text``, read as if from ``path``; types checked, every field
    named in errors)."""
    path = Path(path)
    if text is None:
        text = read_yaml_file(path, "task file", max_size=MAX_FILE_SIZE)
    if len(text) > MAX_FILE_SIZE:
        raise ConfigError(f"{path}: the task file is larger than {MAX_FILE_SIZE // 1000} kB")
    check_depth(text, f"{path}: ")
    try:
        text = evaluate_pose_expressions(text, f"{path}: ")
        check_yaml_against_schema(text, TaskFile, f"{path}: ")
    except RecursionError:
        raise ConfigError(f"{path}: the YAML nests too deeply to be a task file") from None
    try:
        return yaml_load_typed(schema=TaskFile, data=text, defaults=TaskFile())
    except (AssertionError, RuntimeError, ValueError, TypeError) as error:
        raise ConfigError(f"{path}: {str(error).splitlines()[0]}") from None


POSE_LISTS = ("translation", "deg", "rpy")     # the number lists of Drake's Transform (and our X_WG, ...)


def evaluate_pose_expressions(text, where=""):
    """``text`` with every expression in a pose's number lists (``translation: [...]`` and
    ``rotation: !Rpy {deg: [...]}`` anywhere but in ``config``: model directives' ``X_PC``, ``X_PF``,
    library shapes' ``X_WG``, the tool's and the loader's poses) replaced by its value, from the
    file's ``parameters`` (core/expressions.py: parsed, never evaluated as Python); the text
    unchanged if there is none (or if the YAML is not a mapping: the typed loader says why). E.g.
    ``X_PC: {translation: [crank_center_x, crank_center_y, crank_height]}``."""
    root = yaml.compose(text, Loader=yaml.SafeLoader)
    if not isinstance(root, yaml.MappingNode):
        return text
    sections = {key.value: value for key, value in root.value if isinstance(key, yaml.ScalarNode)}
    parameters = {}
    if isinstance(sections.get("parameters"), yaml.MappingNode):
        for key, value in sections["parameters"].value:
            try:
                parameters[key.value] = float(value.value)
            except (TypeError, ValueError):
                return text                        # the typed loader names the parameter
    changed, seen = False, set()

    def visit(node, field):
        nonlocal changed
        if id(node) in seen:                       # an alias: visited once (no exponential walks)
            return
        seen.add(id(node))
        if isinstance(node, yaml.MappingNode):
            for key, value in node.value:
                if isinstance(key, yaml.ScalarNode) and not (field == "" and key.value == "config"):
                    visit(value, f"{field}.{key.value}" if field else str(key.value))
        elif isinstance(node, yaml.SequenceNode):
            numbers = field.rsplit(".", 1)[-1] in POSE_LISTS
            for index, item in enumerate(node.value):
                if numbers and isinstance(item, yaml.ScalarNode) and item.tag == "tag:yaml.org,2002:str":
                    value = expression_to_sympy(item.value, (), parameters, f"{where}{field}[{index}]")
                    item.value, item.tag, item.style = repr(float(value.evalf())), "tag:yaml.org,2002:float", None
                    changed = True
                else:
                    visit(item, f"{field}[{index}]")

    visit(root, "")
    return yaml.serialize(root, Dumper=yaml.SafeDumper) if changed else text


def make_chart(spec, where):
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


def model_packages(spec, path, where):
    """{package name: folder} a task file's ``package://`` URLs resolve with: drake_hybrid (models/),
    the model packages installed with pip (``parsing.installed_model_packages``: example-robot-data)
    and the file's ``packages`` (folders relative to the file)."""
    packages = {"drake_hybrid": str(models_directory()), **installed_model_packages()}
    for name, folder in spec.packages.items():
        folder = Path(folder) if Path(folder).is_absolute() else Path(path).parent / folder
        if not folder.is_dir():
            raise ConfigError(f"{where}packages.{name}: no folder '{folder}'")
        packages[name] = str(folder)
    return packages


def resolve_model_file(url, path, packages, where):
    """The file of ``url``: ``package://<name>/<file>`` (``packages``), ``file://<absolute path>``,
    an absolute path, or a path relative to the task file ``path``; ConfigError naming ``where``."""
    if url.startswith("package://"):
        name, _, rest = url[len("package://"):].partition("/")
        if name not in packages:
            raise ConfigError(f"{where}: unknown package '{name}' in '{url}'; known packages: "
                              f"{', '.join(sorted(packages))} "
                              "(add it to the file's packages: {name: folder})")
        file = Path(packages[name]) / rest
    elif url.startswith("file://"):
        file = Path(url[len("file://"):])
    elif "://" in url:
        raise ConfigError(f"{where}: '{url}': give a package:// or file:// URL or a path")
    else:
        file = Path(url) if Path(url).is_absolute() else Path(path).parent / url
    if not file.is_file():
        raise ConfigError(f"{where}: no file '{file}' (from '{url}')")
    return file


def _directives_adder(directives, what, path=".", packages=None):
    """add(plant) -> [ModelInstanceInfo]: process the directives with the package's parser, its
    ``package://`` URLs resolved with ``packages`` and plain file names relative to the task file."""
    for index, directive in enumerate(directives):
        model = directive.add_model
        if model is not None and "://" not in model.file:
            file = resolve_model_file(model.file, path, {}, f"{what}.directives[{index}].add_model.file")
            model.file = f"file://{file.resolve()}"

    def add(plant):
        parser = ConfigureParser(Parser(plant), packages)
        try:
            return ProcessModelDirectives(ModelDirectives(directives=directives), plant, parser)
        except RuntimeError as error:
            raise ConfigError(f"{what}.directives: {str(error).splitlines()[0]}") from None
    return add


class DataTask(CustomTask):
    """A CustomTask read from a task file (``load_task_file``); also keeps its ``spec`` (TaskFile)
    and ``path``. Its start is in the chart's coordinates of the controlled point (``config.start.configuration``
    with the chart's number of coordinates; six numbers [x, y, z, roll, pitch, yaw] of E otherwise)."""

    def __init__(self, spec, path, text, hooks=None, continuous_plant=True, surface=None, fields=None, **pieces):
        super().__init__(**pieces)
        self.spec, self.path, self.text = spec, Path(path), text
        self.hooks = dict(hooks or {})            # {Task method: the hook's implementation} (tasks/hooks.py)
        self.continuous_plant = continuous_plant
        self.surface, self.fields = surface, fields   # (Surface, offset) or None; (Y_d, F_d) or None
        self._config = None

    def _hook(self, method):
        return self.hooks.get(method)

    def __reduce__(self):
        """Pickled as the file's text (for Dask workers, other processes): rebuilt there by parsing it
        again (the compiled constraint and Drake's config structs do not pickle)."""
        return _task_from_text, (str(self.path), self.text, self.name)

    def base_config(self, options):
        return dataclasses.replace(self._config, start=dataclasses.replace(self._config.start))

    # -- the Task methods a hook may provide (the CustomTask's otherwise) --------------------------
    def add_workpiece(self, plant, config):
        return list(self._add_workpiece(plant, config))     # the file's workpiece, then a hook's

    def workpiece_surface(self, config):
        return self.surface

    def make_source(self, config, controller_plant, robot, constraint_space):
        if self.fields is not None:                # the paper's fields Y_d(r), F_d(r) (tasks/task_file_surface.py)
            return field_source(self.fields, controller_plant, robot, constraint_space, f"{self.path}: ")
        hook = self._hook("make_source") or super().make_source
        return hook(config, controller_plant, robot, constraint_space)

    def start_positions(self, scenario):
        if scenario.config.path.active and self._hook("start_positions") is None:   # a job: the path's first point
            return path_start_positions(self, scenario, self.joint_guess)
        return (self._hook("start_positions") or super().start_positions)(scenario)

    def set_environment_state(self, scenario, plant_context):
        return (self._hook("set_environment_state") or super().set_environment_state)(scenario, plant_context)

    def velocity_row_inertia(self, plant, config, constraint_space):
        return (self._hook("velocity_row_inertia") or super().velocity_row_inertia)(plant, config, constraint_space)

    def eigenvalue_shifts(self, scenario, root_context):
        return (self._hook("eigenvalue_shifts") or super().eigenvalue_shifts)(scenario, root_context)

    def run_notes(self, scenario, log, design_time_constant):
        return (self._hook("run_notes") or super().run_notes)(scenario, log, design_time_constant)

    def run_events(self, scenario, log):
        return (self._hook("run_events") or super().run_events)(scenario, log)

    def start_pose_of(self, config):
        values = list(config.start.configuration)
        if len(values) == self.space.chart.configuration_size:
            # The chart's coordinates are the controlled point's: X_WE = X_WP X_PE, p_PE = -p_EP.
            X_WP = self.space.chart.pose(np.asarray(values, dtype=float))
            return X_WP.multiply(RigidTransform(-np.asarray(self.spec.robot.end_effector_point, dtype=float)))
        return super().start_pose_of(config)


def _robot_adder(spec, path, where, hooks, packages):
    robot = spec.robot
    if "add_robot" in hooks:
        if robot.directives or robot.loader.path:
            raise ConfigError(f"{where}robot: a hook adds the robot; give neither directives nor loader")
        add_by_hook = hooks["add_robot"]
        return _with_end_effector(lambda plant: add_by_hook(plant, None), robot, where)
    if robot.loader.path:
        if robot.directives:
            raise ConfigError(f"{where}robot: give either directives or loader, not both")
        if robot.loader.tool_axis not in TOOL_AXES:
            raise ConfigError(f"{where}robot.loader.tool_axis must be one of {', '.join(TOOL_AXES)}, "
                              f"got '{robot.loader.tool_axis}'")
        file = resolve_model_file(robot.loader.path, path, packages, f"{where}robot.loader.path")
        loaded = load_arm(str(file), robot.loader.flange, tool_frame=robot.loader.tool_frame or None,
                          base_pose=robot.loader.base_pose.GetDeterministicValue(),
                          tool_axis=robot.loader.tool_axis, collision=robot.loader.collision,
                          packages=packages)
        return _with_end_effector(loaded.add_robot, robot, where)
    if not robot.directives:
        raise ConfigError(f"{where}robot: give directives (with arm and tool) or loader.path")
    add_models = _directives_adder(robot.directives, f"{where}robot", path, packages)

    def add_robot(plant):
        add_models(plant)
        if not robot.arm or not plant.HasModelInstanceNamed(robot.arm):
            names = _instance_names(plant)
            raise ConfigError(f"{where}robot.arm must name a model instance of the directives, got "
                              f"'{robot.arm}'; the instances: {names}")
        arm = plant.GetModelInstanceByName(robot.arm)
        if not robot.tool.flange_frame:
            raise ConfigError(f"{where}robot.tool.flange_frame: the frame of '{robot.arm}' the pad tool is welded "
                              "to must be given")
        try:
            model = mount_tool(plant, arm, robot.tool.flange_frame,
                                    robot.tool.X_flange_tool.GetDeterministicValue())
        except UnknownFrameError as error:
            raise ConfigError(f"{where}robot.tool.flange_frame: {error}") from None
        return model
    return _with_end_effector(add_robot, robot, where)


def _with_end_effector(add_robot, robot, where):
    """``add_robot`` whose RobotModel has the file's end-effector frame and point and contact filter."""
    point = np.asarray(robot.end_effector_point, dtype=float)
    if point.shape != (3,) or not np.all(np.isfinite(point)):
        raise ConfigError(f"{where}robot.end_effector_point must be 3 finite numbers (m), got "
                          f"{robot.end_effector_point}")

    def add(plant):
        model = add_robot(plant)
        if not plant.HasFrameNamed(robot.end_effector_frame):
            raise ConfigError(f"{where}robot.end_effector_frame: no frame '{robot.end_effector_frame}' in the plant")
        return dataclasses.replace(model, end_effector_frame=robot.end_effector_frame, end_effector_point=point,
                                   only_pad_contact=robot.only_pad_contact)
    return add


def _instance_names(plant):
    return [plant.GetModelInstanceName(ModelInstanceIndex(i)) for i in range(plant.num_model_instances())]


def _workpiece_adder(spec, path, where, hooks, packages, surface=None):
    workpiece = spec.workpiece
    add_by_hook = hooks.get("add_workpiece")
    with_surface = surface is not None and workpiece.surface.geometry
    if not workpiece.directives and not workpiece.shapes and add_by_hook is None and not with_surface:
        raise ConfigError(f"{where}workpiece: give directives, shapes or a surface")
    add_models = (_directives_adder(workpiece.directives, f"{where}workpiece", path, packages)
                  if workpiece.directives else None)
    for index, shape in enumerate(workpiece.shapes):
        name = f"{where}workpiece.shapes[{index}]"
        if shape.shape not in SHAPES:
            raise ConfigError(f"{name}.shape must be one of {', '.join(sorted(SHAPES))}, got '{shape.shape}'")
        size = SHAPES[shape.shape][1]
        if len(shape.size) != size or not all(0 < v < math.inf for v in shape.size):
            raise ConfigError(f"{name}.size: a {shape.shape} needs {size} positive numbers (m), got {shape.size}")
        if not 0 <= shape.resolution_hint < math.inf:
            raise ConfigError(f"{name}.resolution_hint must be positive (m), or 0 for the library's default, "
                              f"got {shape.resolution_hint}")

    def add_workpiece(plant, config):
        geometries = []
        if add_models is not None:
            for info in add_models(plant):
                for body in plant.GetBodyIndices(info.model_instance):
                    geometries += list(plant.GetCollisionGeometriesForBody(plant.get_body(body)))
        for index, shape in enumerate(workpiece.shapes):
            kind = SHAPES[shape.shape][0]
            geometries += add_rigid_workpiece(plant, kind(*shape.size), shape.X_WG.GetDeterministicValue(),
                                              name=f"{shape.name}_{index}",
                                              resolution_hint=shape.resolution_hint or None)
        if with_surface:
            geometries += add_surface_geometry(plant, surface[0], workpiece.surface, name="surface")
        if add_by_hook is not None:
            geometries += list(add_by_hook(plant, config))
        return geometries
    return add_workpiece


def constraint_space_of(spec, chart, where, anchor, hooks=None, surface=None):
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
            constraint = surface[0].offset_constraint(chart, surface[1])
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
            projection = GivenVelocityProjection(chart, matrix, name="E_p")
        elif surface is not None:
            projection = view_projection(chart, view_of(spec.config.path, surface[0]))
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


def start_configuration_of(spec, chart, where):
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
    X_WE = RigidTransform(RollPitchYaw(start.pose[3:]), start.pose[:3])
    return chart.configuration_of_pose(X_WE.multiply(RigidTransform(np.asarray(spec.robot.end_effector_point,
                                                                               dtype=float))))


def _task_from_text(path, text, name):
    task = load_task_file(path, register=False, text=text)[0]
    task.name = task._config.task = name
    return task


def load_task_file(path, register=True, text=None):
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
    surface = surface_of(spec.workpiece.surface, path, where)
    job = spec.config.path
    if job.active:
        job.validate(f"{where}config.path.")
        if surface is None:
            raise ConfigError(f"{where}config.path: a path needs workpiece.surface (the surface it lies on)")
    if job.active and not (spec.start.configuration or spec.start.pose):
        # A job starts at its path's first point (station.path_job).
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
