"""The diagram, its root context and the hybrid systems in it, checked to belong together.

The functions that take your built diagram (``station.contact_start.solve_contact_start``,
``station.clearance.robot_penetrations``, ``analysis.linearization.linearize_at_contact``) take the
diagram, its root context and the ``HybridSystems`` of ``station.loop.add_hybrid_controller`` (or
a built ``Scenario``). Given the context of another diagram, or a subsystem's, Drake answers with a
two-line RuntimeError deep in the call; ``check_root_context`` says which argument it is first.
"""

from typing import Tuple, TypeVar, cast

from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Context, Diagram, System

from drake_hybrid.core.arguments import describe, instance
from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.station.handles import HybridSystems

SYSTEMS_FIELDS = ("plant", "robot", "controller", "controller_plant", "constraint_space", "sensor")
_Systems = TypeVar("_Systems", bound=HybridSystems)


def check_root_context(diagram: Diagram, root_context: Context, systems: HybridSystems, owner: str) -> None:
    """ArgumentError naming ``owner`` and the argument unless ``diagram`` is a built Diagram,
    ``root_context`` its root context (not another diagram's, nor a subsystem's) and ``systems`` a
    ``HybridSystems`` (or a ``Scenario``) whose plant and controller are in that diagram."""
    instance(diagram, "diagram", owner, Diagram, what="a built Diagram (DiagramBuilder.Build())")
    instance(root_context, "root_context", owner, Context, what="the diagram's root Context")
    check_systems(systems, owner)
    check_system_context(diagram, root_context, owner, "diagram", "root_context", root=True)
    _systems_in(root_context, systems, owner)


def check_systems(systems: _Systems, owner: str, fields: Tuple[str, ...] = SYSTEMS_FIELDS,
                  name: str = "systems") -> _Systems:
    """ArgumentError naming ``owner`` and ``name`` unless ``systems`` is a ``HybridSystems`` (or a built
    ``Scenario``): it has every one of ``fields``."""
    missing = [field for field in fields if not hasattr(systems, field)]
    if missing:
        what = ("a built Scenario or the HybridSystems of add_hybrid_controller" if name == "scenario" else
                "the HybridSystems of station.loop.add_hybrid_controller (or a built Scenario)")
        raise ArgumentError(f"{owner}: {name} must be {what}, got {describe(systems)} (no {', '.join(missing)})")
    return systems


def systems_in_context(root_context: Context, systems: HybridSystems, owner: str) -> None:
    """ArgumentError naming ``owner`` unless ``root_context`` is the root context of the diagram that
    holds ``systems``' plant and controller (not a subsystem's context, e.g. the plant's)."""
    instance(root_context, "root_context", owner, Context, what="the diagram's root Context")
    check_systems(systems, owner)
    _systems_in(root_context, systems, owner)


def _systems_in(root_context, systems, owner):
    """``systems_in_context`` after its type checks: the plant and controller found in ``root_context``."""
    for name in ("plant", "controller"):
        try:
            getattr(systems, name).GetMyContextFromRoot(root_context)
        except RuntimeError:
            raise ArgumentError(f"{owner}: systems.{name} is not in diagram of root_context: root_context must be "
                                "the diagram's root context (diagram.CreateDefaultContext() or the Simulator's), not a "
                                "subsystem's, and systems what add_hybrid_controller returned for its builder") from None


def check_system_context(system: System, context: Context, owner: str, system_name: str = "diagram",
                         context_name: str = "context", root: bool = False) -> Context:
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


def subsystem_context(system: System, root_context: Context, owner: str, what: str) -> Context:
    """``system``'s context in ``root_context`` (``GetMyContextFromRoot``), where the diagram itself is not
    at hand (a logger's, ``station.loggers.read_log``); ArgumentError naming ``owner`` and root_context
    for a Context that is not a root context, or is the root context of a diagram without ``system``
    (``what`` says which diagram that is)."""
    instance(root_context, "root_context", owner, Context, what="the diagram's root Context")
    try:
        return system.GetMyContextFromRoot(root_context)
    except RuntimeError:
        raise ArgumentError(f"{owner}: root_context must be the root context of {what} (diagram.CreateDefaultContext() "
                            "or the Simulator's), got the context of another diagram or of a subsystem") from None


def check_systems_context(systems: HybridSystems, root_context: Context, owner: str) -> Context:
    """ArgumentError naming ``owner`` unless ``systems`` is a built Scenario (or the HybridSystems of
    ``add_hybrid_controller``) and ``root_context`` the root context of the diagram its plant is in
    (what ``analysis.environment`` and ``analysis.modes`` take as ``scenario`` and ``context``)."""
    check_systems(systems, owner, SYSTEMS_FIELDS + ("kinematics",), name="scenario")
    plant = cast(MultibodyPlant, systems.plant)        # a simulated station's (a real arm's has none)
    return subsystem_context(plant, root_context, owner, "the scenario's diagram")
