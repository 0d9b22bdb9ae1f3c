"""The diagram, its root context and the hybrid systems in it, checked to belong together.

The functions that take your built diagram (``scenario.contact_start.solve_contact_start``,
``scenario.clearance.robot_penetrations``, ``analysis.linearization.linearize_at_contact``) take the
diagram, its root context and the ``HybridSystems`` of ``scenario.station.add_hybrid_controller`` (or
a built ``Scenario``). Given the context of another diagram, or a subsystem's, Drake answers with a
two-line RuntimeError deep in the call; ``check_root_context`` says which argument it is first.
"""

from pydrake.systems.framework import Context, Diagram, System

from drake_hybrid.core.arguments import describe, instance
from drake_hybrid.core.errors import ArgumentError

SYSTEMS_FIELDS = ("plant", "robot", "controller", "controller_plant", "constraint_space", "sensor")


def check_root_context(diagram, root_context, systems, owner):
    """ArgumentError naming ``owner`` and the argument unless ``diagram`` is a built Diagram,
    ``root_context`` its root context (not another diagram's, nor a subsystem's) and ``systems`` a
    ``HybridSystems`` (or a ``Scenario``) whose plant and controller are in that diagram."""
    instance(diagram, "diagram", owner, Diagram, what="a built Diagram (DiagramBuilder.Build())")
    instance(root_context, "root_context", owner, Context, what="the diagram's root Context")
    missing = [name for name in SYSTEMS_FIELDS if not hasattr(systems, name)]
    if missing:
        raise ArgumentError(f"{owner}: systems must be the HybridSystems of scenario.station.add_hybrid_controller "
                            f"(or a built Scenario), got {describe(systems)} (no {', '.join(missing)})")
    check_system_context(diagram, root_context, owner, "diagram", "root_context", root=True)
    for name in ("plant", "controller"):
        try:
            getattr(systems, name).GetMyContextFromRoot(root_context)
        except RuntimeError:
            raise ArgumentError(f"{owner}: systems.{name} is not in diagram: systems must be what "
                                "add_hybrid_controller returned for this diagram's builder") from None


def check_system_context(system, context, owner, system_name="diagram", context_name="context", root=False):
    """ArgumentError naming ``owner`` and the argument unless ``system`` is a Drake System and ``context``
    its own Context (not another system's, nor a subsystem's: ``ValidateContext``)."""
    instance(system, system_name, owner, System, what="a Drake System (a built Diagram)")
    instance(context, context_name, owner, Context, what=f"the {'root ' if root else ''}Context of {system_name}")
    try:
        system.ValidateContext(context)
    except RuntimeError:
        raise ArgumentError(f"{owner}: {context_name} must be the {'root ' if root else ''}context of {system_name} "
                            f"({system_name}.CreateDefaultContext() or the Simulator's), got the context of another "
                            "diagram or of a subsystem") from None
    return context


def subsystem_context(system, root_context, owner, what):
    """``system``'s context in ``root_context`` (``GetMyContextFromRoot``), where the diagram itself is not
    at hand (a logger's, ``scenario.station.read_log``); ArgumentError naming ``owner`` and root_context
    for a Context that is not a root context, or is the root context of a diagram without ``system``
    (``what`` says which diagram that is)."""
    instance(root_context, "root_context", owner, Context, what="the diagram's root Context")
    try:
        return system.GetMyContextFromRoot(root_context)
    except RuntimeError:
        raise ArgumentError(f"{owner}: root_context must be the root context of {what} (diagram.CreateDefaultContext() "
                            "or the Simulator's), got the context of another diagram or of a subsystem") from None


def check_systems_context(systems, root_context, owner):
    """ArgumentError naming ``owner`` unless ``systems`` is a built Scenario (or the HybridSystems of
    ``add_hybrid_controller``) and ``root_context`` the root context of the diagram its plant is in
    (what ``analysis.environment`` and ``analysis.modes`` take as ``scenario`` and ``context``)."""
    missing = [name for name in SYSTEMS_FIELDS + ("kinematics",) if not hasattr(systems, name)]
    if missing:
        raise ArgumentError(f"{owner}: scenario must be a built Scenario or the HybridSystems of "
                            f"add_hybrid_controller, got {describe(systems)} (no {', '.join(missing)})")
    return subsystem_context(systems.plant, root_context, owner, "the scenario's diagram")
