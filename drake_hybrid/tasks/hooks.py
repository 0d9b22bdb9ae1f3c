"""Python hooks for task files, safe by construction: a file names hooks, it never imports code.

A task file (tasks/task_file.py) may list ``hooks: [crank]``: names looked up in a registry of
``TaskHook`` objects that the package defines below, that installed packages add through the entry
point group ``drake_hybrid.task_hooks`` (each entry point an object ``TaskHook``), or that
``register_hook`` adds in the running process. A name is a lower-case word (``[a-z][a-z0-9_]*``):
``module:function`` strings, dotted paths and file names are refused before any lookup, so a
file from someone else can run only code that is already installed and registered under a name.

A hook supplies what the paper's task needs in Python and a file cannot say as data (a weld
constraint, a start found by inverse kinematics to a mechanism's pose, a switching constraint,
the massless-mechanism eigenvalue shifts). ``TaskHook.make(spec)`` builds the hook's
implementation from the file (``spec``: its TaskFile; numbers from ``spec.parameters``, whose
names the hook lists in ``parameters`` and the loader checks); the task file's DataTask calls the
implementation for the Task methods the hook ``provides`` (tasks/task.py), with Task's signatures
but two:

* ``add_workpiece(plant, config)``: geometries added after the file's own workpiece;
* ``constraint(chart)``: the Constraint, instead of ``constraint.rows``.

Two hooks of one file may not provide the same method.
"""

import importlib.metadata
import re
from dataclasses import dataclass
from typing import Callable, Tuple

import numpy as np

from drake_hybrid.core.constraints import sphere_constraint
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.core.projections import crank_true_velocity_projection
from drake_hybrid.systems.sources import PseudoVelocitySource
from drake_hybrid.tasks.builtin.crank_turning import CrankTurning
from drake_hybrid.tasks.builtin.grinding import (add_window_with_rough_patch, pad_positions, rough_patch_events,
                                                 rough_patch_notes)
from drake_hybrid.tasks.builtin.robots import add_ur5e_with_pad

ENTRY_POINT_GROUP = "drake_hybrid.task_hooks"
HOOK_METHODS = ("add_robot", "add_workpiece", "constraint", "make_source", "start_positions",
                "set_environment_state", "velocity_row_inertia", "eigenvalue_shifts", "run_notes", "run_events")
NAME = re.compile(r"[a-z][a-z0-9_]{0,63}")


@dataclass(frozen=True)
class TaskHook:
    """A named hook (see the module docstring)."""

    name: str                           # what a task file writes in ``hooks``
    description: str                    # one line, shown by ``drake-hybrid tasks``
    make: Callable                      # make(spec: TaskFile) -> the implementation
    provides: Tuple[str, ...]           # the methods of HOOK_METHODS the implementation has
    parameters: Tuple[str, ...] = ()    # the file's parameters it reads (all required)
    continuous_plant: bool = True       # False: the task needs a discrete plant (e.g. a SAP weld constraint)

    def __post_init__(self):
        if not NAME.fullmatch(self.name):
            raise ValueError(f"TaskHook: name must match {NAME.pattern}, got {self.name!r}")
        unknown = sorted(set(self.provides) - set(HOOK_METHODS))
        if unknown:
            raise ValueError(f"TaskHook '{self.name}': provides {unknown}, not among {list(HOOK_METHODS)}")


_HOOKS = {}


def register_hook(hook):
    """Make ``hook`` (a TaskHook) known by its name in this process (other processes, such as Dask
    workers, see only the package's hooks and the entry point group's). Returns it."""
    if not isinstance(hook, TaskHook):
        raise TypeError(f"register_hook: expected a TaskHook, got {type(hook).__name__}")
    _HOOKS[hook.name] = hook
    return hook


def _entry_point_hooks():
    hooks = {}
    for entry_point in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        hooks[entry_point.name] = entry_point
    return hooks


def hook_names():
    """Every known hook name: the package's, registered ones and the entry point group's."""
    return sorted(set(_HOOKS) | set(_entry_point_hooks()))


def get_hook(name, where="hooks"):
    """The TaskHook called ``name``; ConfigError naming ``where`` and the known hooks otherwise."""
    if not isinstance(name, str) or not NAME.fullmatch(name):
        raise ConfigError(f"{where} must be the name of a registered hook (a lower-case word, not a module path), "
                          f"got {name!r}; known hooks: {hook_names()}")
    if name in _HOOKS:
        return _HOOKS[name]
    entry_point = _entry_point_hooks().get(name)
    if entry_point is None:
        raise ConfigError(f"{where}: unknown hook '{name}'; known hooks: {hook_names()}")
    hook = entry_point.load()
    if not isinstance(hook, TaskHook) or hook.name != name:
        raise ConfigError(f"{where}: the entry point '{name}' of group {ENTRY_POINT_GROUP} is not a TaskHook "
                          f"named '{name}'")
    return hook


def _parameter(spec, name):
    return float(spec.parameters[name])


# ------------------------------------------------------------------------------------------------
# The package's hooks: what the paper's tasks need in Python
# ------------------------------------------------------------------------------------------------

class _UR5eWithPad:
    """The UR5e of airo-models, base at the world origin, the pad tool at tool0 (tasks/builtin/robots.py)."""

    def __init__(self, spec):
        pass

    def add_robot(self, plant, config):
        return add_ur5e_with_pad(plant, tool=config.tool if config is not None else None)


CRANK_PARAMETERS = ("crank_center_x", "crank_center_y", "crank_radius", "crank_height", "start_angle")


class _Crank(CrankTurning):
    """The crank of Example 2.2 (tasks/builtin/crank_turning.py) with the file's geometry and start
    angle: the pad welded to the handle, the start at the handle, the crank's state, its inertia."""

    def __init__(self, spec):
        super().__init__(center=(_parameter(spec, "crank_center_x"), _parameter(spec, "crank_center_y")),
                         radius=_parameter(spec, "crank_radius"), height=_parameter(spec, "crank_height"),
                         seed=spec.start.joint_guess)
        self._start_angle = _parameter(spec, "start_angle")

    def _rows(self, config):
        return "true"

    def start_angle(self, config):
        return self._start_angle

    def add_workpiece(self, plant, config):
        return self.weld_pad_to_handle(plant)


class _CrankPaperRows(_Crank):
    """The paper's (3.3-6) E_p (the file's velocity_projection rows): the desired pseudo-velocity
    (3.3-8) from the true-velocity command (PseudoVelocitySource)."""

    def _rows(self, config):
        return "paper"

    def make_source(self, config, controller_plant, robot, constraint_space):
        true_rows = crank_true_velocity_projection(constraint_space.chart, center=self.center, radius=self.radius)
        return PseudoVelocitySource(controller_plant, robot.end_effector_frame, robot.end_effector_point,
                                    constraint_space.velocity_projection, true_rows, config.desired_velocity,
                                    config.desired_force, constraint_space.force_size)


SPHERE_PARAMETERS = ("sphere_center_x", "sphere_center_y", "sphere_center_z", "constraint_radius")


class _SphereConstraint:
    """(2.2-8) with the equator fix (at each evaluation the component of P x a with the largest |a_k|
    is dropped: a constraint that switches between three pieces) and the radial row in newtons."""

    def __init__(self, spec):
        self.center = np.array([_parameter(spec, f"sphere_center_{axis}") for axis in "xyz"])
        self.radius = _parameter(spec, "constraint_radius")

    def constraint(self, chart):
        return sphere_constraint(chart, center=self.center, radius=self.radius, form="paper",
                                 dropped_component="auto", force_in_newtons=True)


ROUGH_PATCH_PARAMETERS = ("window_height", "rough_start", "rough_end", "rough_friction")


class _RoughPatch:
    """The grinding task's pane (tasks/builtin/grinding.py): three boxes, the middle one a rough
    patch whose friction with the pad is rough_friction whatever config.contact.friction is."""

    def __init__(self, spec):
        self.height, self.start, self.end, self.friction = (_parameter(spec, name) for name in ROUGH_PATCH_PARAMETERS)

    def add_workpiece(self, plant, config):
        return add_window_with_rough_patch(plant, self.height, self.start, self.end, float(config.contact.friction),
                                           self.friction)

    def run_notes(self, scenario, log, design_time_constant):
        return rough_patch_notes(scenario, log, design_time_constant, self.start, self.end, self.friction)

    def run_events(self, scenario, log):
        if "q" not in log or scenario.config.controller != "li-sastry":
            return []
        return rough_patch_events(log["t"], pad_positions(scenario, log), self.start, self.end, self.friction)


_CRANK_METHODS = ("add_workpiece", "start_positions", "set_environment_state", "velocity_row_inertia",
                  "eigenvalue_shifts", "run_notes")
PACKAGE_HOOKS = (
        TaskHook("ur5e_with_pad", "the UR5e (airo-models) at the origin with the pad tool at tool0; its links "
                 "make no contact", _UR5eWithPad, ("add_robot",)),
        TaskHook("crank", "Example 2.2's crank: pad welded to the handle (SAP), start at the handle, crank state, "
                 "handle-inertia eigenvalue shifts", _Crank, _CRANK_METHODS, CRANK_PARAMETERS,
                 continuous_plant=False),
        TaskHook("crank_paper_rows", "the crank hook with the paper's (3.3-6) E_p: desired pseudo-velocity (3.3-8) "
                 "from the true-velocity command", _CrankPaperRows, _CRANK_METHODS + ("make_source",),
                 CRANK_PARAMETERS, continuous_plant=False),
        TaskHook("sphere_paper_constraint", "Example 2.3's (2.2-8) sphere constraint with the equator fix (switching "
                 "pieces), radial row in N", _SphereConstraint, ("constraint",), SPHERE_PARAMETERS),
        TaskHook("rough_patch", "the grinding pane: smooth, rough (rough_friction), smooth boxes; run notes on the "
                 "patch", _RoughPatch, ("add_workpiece", "run_notes", "run_events"), ROUGH_PATCH_PARAMETERS))
for _hook in PACKAGE_HOOKS:
    register_hook(_hook)


def make_hooks(spec, where):
    """{method: implementation} for the hooks ``spec.hooks`` names, and whether the task runs on a
    continuous plant; ConfigError naming the field for an unknown hook, a missing parameter or two
    hooks providing one method."""
    methods, continuous = {}, True
    for index, name in enumerate(spec.hooks):
        field = f"{where}hooks[{index}]"
        hook = get_hook(name, field)
        missing = [p for p in hook.parameters if p not in spec.parameters]
        if missing:
            raise ConfigError(f"{field}: hook '{name}' needs the parameters {', '.join(hook.parameters)}; missing "
                              f"{', '.join(missing)}")
        implementation = hook.make(spec)
        for method in hook.provides:
            if method in methods:
                raise ConfigError(f"{field}: hook '{name}' provides {method}, as hook '{methods[method][0]}' does")
            methods[method] = (name, getattr(implementation, method))
        continuous = continuous and hook.continuous_plant
    return {method: function for method, (_, function) in methods.items()}, continuous
