"""A task file's models: its ``package://`` URLs and relative paths resolved (``model_packages``,
``resolve_model_file``), its Drake model directives processed, and from them the robot (directives
with the pad tool, the arm loader ``tasks.robots.load_arm``, or a hook) and the workpiece
(directives, library shapes, the surface, a hook) as a ``CustomTask``'s ``add_robot`` and
``add_workpiece``. Hooks (``tasks.hooks``) are looked up by name in a registry, never imported from
the file.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np

from pydrake.multibody.parsing import ModelDirectives, Parser, ProcessModelDirectives
from pydrake.multibody.tree import ModelInstanceIndex

from drake_hybrid.core.errors import ConfigError, UnknownFrameError
from drake_hybrid.station.arm import mount_tool
from drake_hybrid.station.parsing import ConfigureParser, installed_model_packages, models_directory
from drake_hybrid.station.workpieces import add_rigid_workpiece
from drake_hybrid.tasks.robots import TOOL_AXES, load_arm
from drake_hybrid.tasks.task_file_schema import SHAPES
from drake_hybrid.tasks.task_file_surface import add_surface_geometry


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


def _robot_adder(spec, path, where, hooks, packages):
    robot = spec.robot
    if "add_robot" in hooks:
        if robot.directives or robot.loader.path:
            raise ConfigError(f"{where}robot: a hook adds the robot; give neither directives nor loader")
        add_by_hook = hooks["add_robot"]
        return _with_end_effector(lambda plant, config=None: add_by_hook(plant, config), robot, where)
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
        return _with_end_effector(lambda plant, config=None: loaded.add_robot(plant, tool=_tool(config)), robot,
                                  where)
    if not robot.directives:
        raise ConfigError(f"{where}robot: give directives (with arm and tool) or loader.path")
    add_models = _directives_adder(robot.directives, f"{where}robot", path, packages)

    def add_robot(plant, config=None):
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
            model = mount_tool(plant, arm, robot.tool.flange_frame, robot.tool.X_flange_tool.GetDeterministicValue(),
                               tool=_tool(config))
        except UnknownFrameError as error:
            raise ConfigError(f"{where}robot.tool.flange_frame: {error}") from None
        return model
    return _with_end_effector(add_robot, robot, where)


def _tool(config):
    """The pad tool of a run's config (``config.tool``; None without a config: the ball)."""
    return config.tool if config is not None else None


def _with_end_effector(add_robot, robot, where):
    """``add_robot(plant, config=None)`` whose RobotModel has the file's end-effector frame and point and
    contact filter (the tool mounted is ``config.tool``, where the robot's section mounts one)."""
    point = np.asarray(robot.end_effector_point, dtype=float)
    if point.shape != (3,) or not np.all(np.isfinite(point)):
        raise ConfigError(f"{where}robot.end_effector_point must be 3 finite numbers (m), got "
                          f"{robot.end_effector_point}")

    def add(plant, config=None):
        model = add_robot(plant, config)
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
