"""drake_hybrid: hybrid velocity/force control (Li & Sastry 1987) on Drake.

The names a user starts with, importable from here (each lives in the module named in ``_EXPORTS``):

* the geometry: charts (``PoseChart``, ``EulerZXZChart``, ``PlanarChart``), ``Constraint`` and the
  constraint space (``ConstraintSpace``, E_p), workpiece surfaces (``PlaneSurface``, ``SphereSurface``,
  ``CylinderSurface``, ``HeightMapSurface``), ``view_projection``, a flat tool's moment rows
  (``with_force_rows``) and a workpiece off its model (``surface_error_pose``, ``moved_surface``);
* the law: ``HybridController``, ``HybridGains``, ``ControlMode``, ``SupervisionConfig``, ``ContactPhase``;
* your own station: ``default_plant_config``, ``mount_tool`` (the ball pad or a disc: ``ToolConfig``),
  ``robot_plant``, ``add_rigid_workpiece``, ``add_contact_patch``,
  ``apply_contact_defaults``, ``only_tool_touches``, ``add_hybrid_controller``, ``add_loggers``,
  ``read_log``, ``solve_contact_start``, ``solve_approach_start``, a path job (``PathConfig``,
  ``PatternConfig``, ``path_job``, ``solve_path_start``) and ``linearize_at_contact``;
* the package's tasks: ``get_task``, ``simulate``, ``linearize_continuous``, ``load_task_file``, ``CustomTask``,
  ``register_task``, ``load_arm``;
* the typed errors (``DrakeHybridError`` and its subclasses).

The names are imported on first use (PEP 562), so that the ``drake-hybrid`` command
(``drake_hybrid.__main__``) prints its first line before Drake loads.
"""

import importlib

_EXPORTS = {
    "drake_hybrid.core.charts": ["EulerZXZChart", "PlanarChart", "PoseChart"],
    "drake_hybrid.core.constraints": ["Constraint", "SelectingConstraint", "crank_constraint", "sphere_constraint",
                                      "surface_constraint", "window_constraint", "with_force_rows"],
    "drake_hybrid.core.errors": ["ArgumentError", "BranchError", "ChartSingularityError", "ConfigError",
                                 "ConstraintRankError", "DimensionError", "DrakeHybridError", "ForceSignError",
                                 "GainError", "KinematicSingularityWarning", "OffConstraintError", "PathError",
                                 "UnknownVariableError"],
    "drake_hybrid.core.kinematics": ["EndEffectorKinematics", "TaskKinematics"],
    "drake_hybrid.core.projections": ["ConstraintSpace", "GivenVelocityProjection", "KernelVelocityProjection",
                                      "crank_paper_projection", "crank_true_velocity_projection",
                                      "sphere_paper_projection", "sphere_true_velocity_projection"],
    "drake_hybrid.core.surfaces": ["CylinderSurface", "PlaneSurface", "SphereSurface", "view_projection"],
    "drake_hybrid.core.height_map": ["HeightMap", "HeightMapSurface"],
    "drake_hybrid.core.surface_moves": ["moved_surface", "surface_error_pose"],
    "drake_hybrid.control.controller": ["HybridController"],
    "drake_hybrid.control.gains": ["ControlMode", "HybridGains"],
    "drake_hybrid.control.phases": ["ContactPhase"],
    "drake_hybrid.control.supervision": ["SupervisionConfig"],
    "drake_hybrid.systems.sources": ["Profile"],
    "drake_hybrid.station.arm": ["mount_tool", "robot_plant"],
    "drake_hybrid.station.contact": ["apply_contact_defaults", "default_plant_config", "only_tool_touches"],
    "drake_hybrid.station.workpieces": ["add_rigid_workpiece"],
    "drake_hybrid.station.sensing": ["ContactSensorConfig", "WristSensorConfig", "add_contact_patch"],
    "drake_hybrid.station.tools": ["ToolConfig"],
    "drake_hybrid.station.loop": ["add_hybrid_controller"],
    "drake_hybrid.station.handles": ["HybridSystems"],
    "drake_hybrid.station.loggers": ["LOG_KEYS", "add_loggers", "read_log"],
    "drake_hybrid.station.path_config": ["PathConfig", "PatternConfig", "WaypointConfig"],
    "drake_hybrid.station.path_job": ["PathJob", "path_job"],
    "drake_hybrid.station.contact_start": ["solve_approach_start", "solve_contact_start", "solve_path_start"],
    "drake_hybrid.tasks.config": ["ScenarioConfig", "load_config"],
    "drake_hybrid.tasks.registry": ["get_task", "register_task"],
    "drake_hybrid.tasks.custom": ["CustomTask"],
    "drake_hybrid.tasks.robots": ["load_arm"],
    "drake_hybrid.tasks.task_file": ["load_task_file"],
    "drake_hybrid.scenario.builder": ["build_scenario"],
    "drake_hybrid.analysis.linearization": ["linearize_at_contact", "linearize_continuous"],
    "drake_hybrid.experiments.simulation": ["simulate"],
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}
__all__ = sorted(_MODULE_OF)
__version__ = "0.1.0"


def __getattr__(name):
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'drake_hybrid' has no attribute '{name}'")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
