"""The schema of a task file (a whole task in one YAML file: robot, workpiece, chart, constraint, start
and run configuration): the dataclasses below, which Drake's typed YAML (``yaml_load_typed``) loads a
file into, and ``read_task_file``, which reads one after the schema pre-check that names the field.
``tasks.task_file.load_task_file`` builds the task from them. The file::

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

Expressions are parsed by the whitelisted grammar of ``core.expressions`` (never evaluated as
Python): a file from someone else cannot run code. In a pose's number lists outside ``config``
(``translation``, ``rotation: !Rpy {deg}``) ``evaluate_pose_expressions`` replaces them by their
values before the file is loaded.
"""

from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List

import yaml

from pydrake.common.schema import Transform
from pydrake.common.yaml import yaml_load_typed
from pydrake.geometry import Box, Capsule, Cylinder, Ellipsoid, Sphere
from pydrake.multibody.parsing import ModelDirective

from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.expressions import expression_to_sympy
from drake_hybrid.core.schema import check_depth, check_yaml_against_schema, read_yaml_file
from drake_hybrid.tasks.config import ScenarioConfig
from drake_hybrid.tasks.task_file_surface import FieldsSpec, SurfaceSpec

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
