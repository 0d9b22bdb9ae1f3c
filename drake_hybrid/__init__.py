"""drake_hybrid: hybrid velocity/force control (Li & Sastry 1987) on Drake.

Layers (each imports only the ones above it):

* ``charts``       coordinate charts of the end-effector configuration (section 2.1)
* ``constraints``  C(r) = 0 and its derivatives E_f, E_f-dot r-dot (sections 2.2, 3.0)
* ``projections``  E_p and the constraint space E = [E_p; E_f] (sections 3.0, 3.3)
* ``kinematics``   chart quantities (r, r-dot, J, J-dot q-dot) from a MultibodyPlant

The names below are imported on first use (PEP 562), so that the ``drake-hybrid`` command
(``drake_hybrid.__main__``) prints its first line before Drake loads.
"""

import importlib

_EXPORTS = {
    "drake_hybrid.core.charts": ["EulerZXZChart", "PlanarChart", "PoseChart"],
    "drake_hybrid.core.constraints": ["Constraint", "SelectingConstraint", "crank_constraint", "sphere_constraint",
                                      "surface_constraint", "window_constraint"],
    "drake_hybrid.core.errors": ["BranchError", "ChartSingularityError", "ConstraintRankError", "DimensionError",
                                 "DrakeHybridError", "GainError", "KinematicSingularityWarning", "OffConstraintError",
                                 "UnknownVariableError"],
    "drake_hybrid.core.kinematics": ["EndEffectorKinematics", "TaskKinematics"],
    "drake_hybrid.core.projections": ["ConstraintSpace", "GivenVelocityProjection", "KernelVelocityProjection",
                                      "crank_paper_projection", "crank_true_velocity_projection",
                                      "sphere_paper_projection", "sphere_true_velocity_projection"],
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
