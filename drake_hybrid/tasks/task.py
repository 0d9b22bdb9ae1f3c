"""The Task protocol: what a task gives the scenario builder, and its typed options.

A task is a recipe for a closed loop: the robot and tool it adds to a plant, the workpiece, the
constraint space (chart, C, E_p), the desired-value source, the start, its default
``ScenarioConfig``, and its own options. Every task, built in (``tasks.registry``) or yours
(``tasks.custom.CustomTask``), subclasses ``Task``::

    Task.default_config(options=None, **changes) -> ScenarioConfig
        base_config(options)                       the task's defaults (subclass)
        options: {name: value} of Task.Options     into task_parameters / task_options
        changes: top-level ScenarioConfig fields   (desired_velocity / desired_force may be
                                                    lists: constant profiles)
    Task.options(config) -> Task.Options           typed; ConfigError for an unknown name or a
                                                    value of the wrong type or not allowed

Options live in the config file as ``task_parameters`` (numbers) and ``task_options`` (words),
because the file names the task by a string and a task registered at run time declares its own
options: the schema of the options is known only once the task is. ``Task.options`` is where
they get their types, once, for ``ScenarioConfig.validate``-time checking
(``scenario.builder.build_scenario`` calls it before building anything).
"""

import abc
import dataclasses
from dataclasses import dataclass
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, cast

import numpy as np

from pydrake.geometry import GeometryId, Meshcat, SceneGraph
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Context, DiagramBuilder, System

from drake_hybrid.core.arguments import instance, joint_rows
from drake_hybrid.core.constraints import SelectingConstraint
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.hints import Array
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.core.schema import unknown_field
from drake_hybrid.core.surfaces import Surface
from drake_hybrid.station.handles import HybridSystems
from drake_hybrid.station.path_job import path_events
from drake_hybrid.station.robot_model import RobotModel
from drake_hybrid.systems.sources import Profile, ProfileSource
from drake_hybrid.tasks.config import ScenarioConfig
from drake_hybrid.tasks.task_options import option_help


@dataclass
class EigenvalueShift:
    """A designed eigenvalue that the task's physics moves, and where it predicts it: the paper's model
    leaves something out (e.g. a massless constraint), the task knows what and by how much."""

    designed: complex       # the eigenvalue the gains design
    predicted: complex      # where the task's physics puts it
    reason: str             # one line: what moves it, and the formula


@dataclass
class NoOptions:
    """A task without options."""


_TRUE, _FALSE = ("true", "yes", "on", "1"), ("false", "no", "off", "0")


def _coerce(task_name, field, raw):
    """``raw`` (from task_parameters or task_options) as the type of ``field``; ConfigError otherwise."""
    where = f"task option '{field.name}' of task '{task_name}'"
    kind = field.type if isinstance(field.type, type) else type(field.default)
    if kind is bool:
        word = str(raw).strip().lower()
        if isinstance(raw, bool) or word in _TRUE + _FALSE:
            return raw if isinstance(raw, bool) else word in _TRUE
        raise ConfigError(f"{where} must be true or false, got {raw!r}")
    if kind in (int, float):
        try:
            number = float(raw)
        except (TypeError, ValueError):
            raise ConfigError(f"{where} must be a number, got {raw!r}") from None
        if kind is int:
            if number != int(number):
                raise ConfigError(f"{where} must be an integer, got {raw!r}")
            return int(number)
        return number
    allowed = field.metadata.get("allowed")
    word = str(raw)
    if allowed and word not in allowed:
        raise ConfigError(f"{where} must be one of {', '.join(allowed)}, got {raw!r}")
    return word


def pad_kinematic_rows(profile: Profile, force_size: int, kinematic_rows: Iterable[int]) -> Profile:
    """``profile`` (a desired force) with zeros inserted at ``kinematic_rows`` when it gives only the
    force-controlled rows (m - len(kinematic_rows) entries): rows held kinematically (e.g. the
    tool's orientation rows of ``surface_constraint(normal_rows=True)``) have no force to track.
    A profile with all m entries is returned as it is."""
    kinematic = sorted(kinematic_rows)
    if not kinematic or len(profile.value) != force_size - len(kinematic):
        return profile
    controlled = [i for i in range(force_size) if i not in kinematic]

    def padded(values):
        if len(values) != len(controlled):
            return list(values)
        full = [0.0] * force_size
        for row, value in zip(controlled, values):
            full[row] = float(value)
        return full

    return dataclasses.replace(profile, value=padded(profile.value), final_value=padded(profile.final_value),
                               amplitude=padded(profile.amplitude))


def as_profile(value: Any) -> Any:
    """A constant Profile from a list (a tuple, a 1-D array) of values; anything else as it is (its type
    is checked with the config's, ``ScenarioConfig.replace``)."""
    if isinstance(value, (list, tuple)) or (isinstance(value, np.ndarray) and value.ndim == 1):
        return Profile(kind="constant", value=list(value))
    return value


class Task(abc.ABC):
    """Base class of every task (see the module docstring). Attributes: ``name``,
    ``description``, ``camera`` (Meshcat view: position, target), ``Options`` (a dataclass)."""

    name = "task"
    description = ""
    camera: Optional[Tuple[Sequence[float], Sequence[float]]] = None
    Options = NoOptions

    # -- configuration -----------------------------------------------------------------------------
    continuous_plant = True        # the task runs on a continuous plant too (linearize_continuous)

    @abc.abstractmethod
    def base_config(self, options: Dict[str, Any]) -> ScenarioConfig:
        """The task's default ScenarioConfig before ``options`` and changes are applied (``options``,
        the dict the caller gave, for tasks whose defaults depend on an option)."""

    def default_config(self, options: Optional[Dict[str, Any]] = None, **changes: Any) -> ScenarioConfig:
        """The task's default ScenarioConfig with ``options`` (names of ``Options``) and ``changes``
        (top-level ScenarioConfig fields; desired_velocity and desired_force may be lists), validated
        (``ScenarioConfig.validate``: ConfigError naming the field)."""
        options = dict(instance(options, "options", f"{self.name}.default_config", dict, allow_none=True,
                                what="a dict {option name: value}", error=ConfigError) or {})
        config = self.base_config(options)
        for name, raw in options.items():
            self._set_option(config, name, raw)
        for name in ("desired_velocity", "desired_force"):
            if name in changes:
                changes[name] = as_profile(changes[name])
        unknown = unknown_field(ScenarioConfig, changes, f"{self.name}.default_config")
        if unknown:
            raise ConfigError(unknown)
        config = config.replace(**changes) if changes else config
        self.options(config)
        return config.validate()

    def _set_option(self, config, name, raw):
        """Store option ``name`` in task_parameters (numbers) or task_options (words and booleans)."""
        fields = {f.name: f for f in dataclasses.fields(self.Options)}
        if name not in fields:
            raise ConfigError(f"task '{self.name}' has no option '{name}'; its options: "
                              f"{', '.join(sorted(fields)) or 'none'}")
        value = _coerce(self.name, fields[name], raw)
        config.task_parameters.pop(name, None)
        config.task_options.pop(name, None)
        if isinstance(value, bool):
            config.task_options[name] = "true" if value else "false"
        elif isinstance(value, (int, float)):
            config.task_parameters[name] = float(value)
        else:
            config.task_options[name] = value

    def option_help(self) -> List[str]:
        """One line per option for help texts: ``name=VALUE`` with its type or allowed values and default
        (``tasks.task_options.option_help``)."""
        return option_help(self.Options)

    def options(self, config: ScenarioConfig) -> Any:
        """The task's typed options from ``config.task_parameters`` and ``config.task_options``."""
        fields = {f.name: f for f in dataclasses.fields(self.Options)}
        values = {}
        for section in ("task_parameters", "task_options"):
            for name, raw in getattr(config, section).items():
                if name not in fields:
                    raise ConfigError(f"{section}.{name}: task '{self.name}' has no such option; its options: "
                                      f"{', '.join(sorted(fields)) or 'none'}")
                values[name] = _coerce(self.name, fields[name], raw)
        return self.Options(**values)

    def eigenvalue_shifts(self, scenario: "Scenario", root_context: Context) -> List[EigenvalueShift]:
        """Designed eigenvalues this task's physics moves (``EigenvalueShift``), at the linearization
        point ``root_context`` of ``scenario``. Default: none (the paper's model is the plant's)."""
        return []

    def run_notes(self, scenario: "Scenario", log: Mapping[str, Array], design_time_constant: float) -> List[str]:
        """Lines the run's summary should carry about where the run ends (e.g. in a transient the
        task causes on purpose). Default: none."""
        return []

    def run_events(self, scenario: "Scenario", log: Mapping[str, Array]) -> List[Dict[str, Any]]:
        """Phases of the run the plots mark and the summary names where a row's worst error falls
        (e.g. the pad on a rough patch): a list of ``{"start": t0, "end": t1 or None, "label": ...}``
        (s; ``end`` None: an instant; ``"explains_errors": False`` for a phase the plots mark but that
        causes no row's error, e.g. a change of basis of held rows). Default: where a switching
        constraint changes piece (``piece_switches``), none for a constraint of one piece; and a job's
        phases (``path_job.path_events``: approach, dwell, line changes, lift-off)."""
        return piece_switches(scenario, log) + path_events(log)

    def labels(self, config: Optional[ScenarioConfig] = None) -> Dict[str, Any]:
        """Plot labels of the velocity- and force-controlled coordinates (``config``: the run's, for a
        task whose rows depend on its options). Optional: ``constraint_units`` (C's rows),
        ``constraint_note`` (what the simulated C measures: a compliant contact's compression, a weld's
        give, rows the controller holds; under the constraint residual plot's title), and
        ``velocity_error`` / ``velocity_error_units`` where the velocity error is not in the rows' own
        terms (the paper's pseudo-velocity rows, whose error is the true rows')."""
        return {"velocity": [], "velocity_units": "SI", "force": [], "force_units": "SI"}

    # -- models ------------------------------------------------------------------------------------
    @abc.abstractmethod
    def add_robot(self, plant: MultibodyPlant, config: ScenarioConfig) -> RobotModel:
        """Add the robot and its tool to ``plant``; return a ``station.robot_model.RobotModel``."""

    @abc.abstractmethod
    def add_workpiece(self, plant: MultibodyPlant, config: ScenarioConfig) -> List[GeometryId]:
        """Add the workpiece to ``plant``; return its collision geometry ids."""

    def connect_environment(self, builder: DiagramBuilder, plant: MultibodyPlant, config: ScenarioConfig) -> None:
        """Wire systems that drive the environment (e.g. a moving window). Default: none."""

    # -- the law's task ----------------------------------------------------------------------------
    @abc.abstractmethod
    def constraint_space(self, config: ScenarioConfig) -> ConstraintSpace:
        """The ConstraintSpace (chart, C, E_p) of the task."""

    def velocity_row_inertia(self, plant: MultibodyPlant, config: ScenarioConfig,
                             constraint_space: ConstraintSpace) -> Array:
        """I_v (k x k): the inertia of the task's mechanism along the velocity rows, read from the
        simulation ``plant`` (``mechanism.source: plant``). Default: the task has no mechanism."""
        raise ConfigError(f"mechanism.source: task '{self.name}' has no mechanism to read from the plant; "
                          "use source 'given' with mechanism.velocity_row_inertia, or 'none'")

    def workpiece_surface(self, config: ScenarioConfig) -> Optional[Tuple[Surface, float]]:
        """(surface, pad offset): the workpiece's surface (a ``core.surfaces.Surface``) and how far the
        controlled point is held off it along the normal (a ball pad's radius), for a job's path
        (``config.path``, ``station.path_job``). Default: None (the task has no path over a surface).
        A task that honours ``config.model_error``'s workpiece error returns the surface the controller is
        given (``tasks.surface_model.model_surface``) and its real one from ``real_workpiece_surface``."""
        return None

    def real_workpiece_surface(self, config: ScenarioConfig) -> Optional[Surface]:
        """The surface of the workpiece's simulated geometry (where it really is; what a disc's contact patch
        is measured against). Default: ``workpiece_surface``'s (a task without a workpiece error), or None."""
        surface = self.workpiece_surface(config)
        return surface[0] if surface is not None else None

    def make_source(self, config: ScenarioConfig, controller_plant: MultibodyPlant, robot: RobotModel,
                    constraint_space: ConstraintSpace) -> System:
        """The system producing desired_velocity, desired_acceleration and desired_force.
        Default: the config's profiles."""
        return ProfileSource(config.desired_velocity, config.desired_force, constraint_space.velocity_size,
                             constraint_space.force_size)

    # -- the start ---------------------------------------------------------------------------------
    @abc.abstractmethod
    def start_positions(self, scenario: "Scenario") -> Array:
        """The arm's joint positions at the start of ``scenario``."""

    def set_environment_state(self, scenario: "Scenario", plant_context: Context) -> None:
        """Set the environment's own state at the start (e.g. the crank's angle). Default: none."""


@dataclass(kw_only=True)
class Scenario(HybridSystems):
    """The closed loop a task's config builds (``scenario.builder.build_scenario`` returns it): the loop's
    ``HybridSystems`` (plant, controller, sensor, source, supervisor, path, loggers, ...) and the
    ``config`` (validated, with its commands as the run uses them), the ``task``, the built ``diagram``,
    the plant's ``scene_graph`` and the ``meshcat`` it draws in (or None)."""

    config: ScenarioConfig
    task: Task
    scene_graph: Optional[SceneGraph] = None
    meshcat: Optional[Meshcat] = None


def piece_switches(scenario: Scenario, log: Mapping[str, Array]) -> List[Dict[str, Any]]:
    """The instants a switching constraint (core.constraints.SelectingConstraint, e.g. (2.2-8) with the
    equator fix, which drops the component of (p - c) x a along the largest |a_k|) changes piece along
    the logged run: its rows change basis there, so the held rows' forces jump while the pad does not.
    None for a constraint of one piece."""
    constraint = scenario.constraint_space.constraint
    if not hasattr(constraint, "pieces") or "q" not in log:
        return []
    select = cast(SelectingConstraint, constraint).select        # the constraint of pieces
    plant = scenario.controller_plant
    context = plant.CreateDefaultContext()
    pieces = []
    for q in joint_rows(log["q"], "log['q']", "piece_switches", plant):
        plant.SetPositions(context, q)
        pieces.append(select(scenario.controller.kinematics.evaluate(context).configuration))
    changes = np.nonzero(np.diff(pieces))[0] + 1
    # The pad's motion and the normal force do not see the switch: it names no row's error (explains_errors).
    return [{"start": float(log["t"][i]), "end": None, "explains_errors": False,
             "label": "the constraint switches piece: its held rows change basis"} for i in changes]
