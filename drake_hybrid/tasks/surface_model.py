"""The surface a task's controller is given, and its constraint with the task's tool.

A task whose workpiece names its surface (``Task.workpiece_surface``) simulates the real geometry; its
controller is given a model of it: the real surface moved by the config's model error
(``ModelErrorConfig.workpiece_*``: tilted about a pivot, shifted; ``core.surface_moves``), the same
surface without one. On the model the task lays its constraint (``surface_constraint_space``: the surface
offset by the tool's controlled point, ``ToolConfig.offset``; its orientation rows held or
force-controlled as ``ToolConfig.orientation_rows`` says; E_p the view's rows) and its path
(``tasks.path.task_path_job``).
"""

from typing import Dict, Optional, Tuple

from pydrake.math import RigidTransform

from drake_hybrid.core.charts import PoseChart
from drake_hybrid.core.constraints import with_force_rows
from drake_hybrid.core.errors import ConfigError, PathError
from drake_hybrid.core.projections import ConstraintSpace
from drake_hybrid.core.surface_moves import moved_surface, surface_error_pose
from drake_hybrid.core.surfaces import Surface, ViewPlane, view_projection
from drake_hybrid.station.path_job import path_on
from drake_hybrid.tasks.config import ScenarioConfig

_MODELS: Dict[Tuple, Surface] = {}
_SPACES: Dict[Tuple, ConstraintSpace] = {}


def _error_key(config: ScenarioConfig) -> Tuple:
    error = config.model_error
    key = (error.workpiece_tilt, tuple(error.workpiece_tilt_axis), tuple(error.workpiece_pivot),
           tuple(error.workpiece_shift))
    return key + ((repr(config.path),) if not error.workpiece_pivot else ())


def workpiece_error_pose(surface: Surface, offset: float, config: ScenarioConfig) -> RigidTransform:
    """X_real_model of ``config.model_error``: the real workpiece ``surface`` is the model turned by
    ``workpiece_tilt`` about ``workpiece_tilt_axis`` through ``workpiece_pivot`` (empty: the first point of the
    path of ``config.path`` on the real surface, for a tool ``offset`` m off it) and moved by
    ``workpiece_shift``. ConfigError naming the field."""
    error = config.model_error
    pivot = list(error.workpiece_pivot)
    if not pivot:
        if not config.path.active:
            raise ConfigError("model_error.workpiece_pivot: give the point the real workpiece is turned about "
                              "(world, m): the config has no path whose first point it could be")
        centre, normal = path_on(surface, offset, config.path).first_point()
        pivot = list(centre - offset * normal)
    try:
        return surface_error_pose(error.workpiece_tilt, error.workpiece_tilt_axis, pivot, error.workpiece_shift)
    except PathError as failure:
        raise ConfigError(f"model_error: {failure}") from None


def model_surface(surface: Surface, offset: float, config: ScenarioConfig) -> Surface:
    """The surface the controller is given for the real workpiece ``surface`` (``surface`` itself without a
    model error; cached). ConfigError naming the field for an error that cannot be applied."""
    if not config.model_error.workpiece_moved:
        return surface
    key = (id(surface), float(offset)) + _error_key(config)
    if key not in _MODELS:
        X_real_model = workpiece_error_pose(surface, offset, config)
        try:
            _MODELS[key] = moved_surface(surface, X_real_model.inverse(), name=f"{surface.name} (model)")
        except PathError as failure:
            raise ConfigError(f"model_error.workpiece_tilt: {failure}") from None
    return _MODELS[key]


def surface_constraint_space(surface: Surface, offset: float, config: ScenarioConfig,
                             view: Optional[ViewPlane] = None) -> ConstraintSpace:
    """The ConstraintSpace on ``surface`` (the model) for the tool of ``config``: ``offset_constraint`` at the
    tool's ``offset`` (the PoseChart), its orientation rows force-controlled when ``config.tool`` says so, E_p the
    rows of ``view`` (default the surface's). Compiled once per surface, offset, view and orientation."""
    orientation = config.tool.orientation_rows
    view = view or surface.default_view()
    key = (id(surface), float(offset), orientation, view)
    if key not in _SPACES:
        chart = PoseChart()
        constraint = surface.offset_constraint(chart, offset)
        if orientation == "force":
            constraint = with_force_rows(constraint)
        _SPACES[key] = ConstraintSpace(constraint, view_projection(chart, view))
    return _SPACES[key]


def orientation_labels(config: ScenarioConfig) -> Dict[str, object]:
    """The force rows' labels of a surface constraint with the tool of ``config``: the normal force and the
    orientation rows, held (1) or moments (N m about o_2 and -o_1, the tool's y and -x axes)."""
    if config.tool.orientation_rows == "force":
        return {"force": ["normal force", "moment about o_2", "moment about -o_1"], "force_units": "N | N m | N m",
                "constraint_units": "m | 1 | 1",
                "constraint_note": "C_1: the distance of the controlled point from the offset surface (the "
                                   "compliant contact's compression while it presses); C_2, C_3: the approach "
                                   "vector's orientation rows, force-controlled (their force: the moment on the "
                                   "tool about the controlled point)"}
    return {"force": ["normal force", "orientation row 1", "orientation row 2"], "force_units": "N | N m | N m",
            "constraint_units": "m | 1 | 1",
            "constraint_note": "C_1: the distance of the pad centre from the offset surface (the compliant "
                               "contact's compression while it presses); C_2, C_3: the approach vector's "
                               "orientation rows, held by the controller"}
