"""A robot's clearance at its start: its parts other than the tool must not penetrate the scene.

``station.contact.only_tool_touches`` filters every contact of the robot but its tool's, so a link
through the workpiece passes unseen in the simulation; ``robot_penetrations`` asks SceneGraph for
those pairs' signed distances at a configuration, and ``check_robot_clearance`` refuses a start
where any is below -``PENETRATION_TOLERANCE`` (StartCollisionError naming the bodies).
"""

from typing import List, Tuple

from numpy.typing import ArrayLike

from pydrake.geometry import CollisionFilterDeclaration, GeometrySet, Role, SceneGraph
from pydrake.systems.framework import Context, Diagram

from drake_hybrid.core.arguments import joint_vector, nonnegative, text
from drake_hybrid.core.errors import StartCollisionError
from drake_hybrid.station.handles import HybridSystems
from drake_hybrid.station.root_context import check_root_context

PENETRATION_TOLERANCE = 1e-4      # m: a robot part this far inside another geometry at the start is a collision


def robot_penetrations(diagram: Diagram, root_context: Context, systems: HybridSystems, q: ArrayLike,
                       tolerance: float = PENETRATION_TOLERANCE) -> List[Tuple[str, str, float]]:
    """The robot's parts other than its tool (``systems.robot.pad_geometries``) that penetrate another
    geometry of the scene (the workpiece, a table) by more than ``tolerance`` (m) with the arm at ``q``:
    a list of (robot body, its geometry, the other geometry, depth in m), deepest first.

    ``only_tool_touches`` filters those pairs out of the simulation, so a link through the workpiece
    would pass unseen; this asks SceneGraph for each pair's signed distance in a copy of
    ``root_context`` whose filters allow them (``root_context`` is left as it was). Pairs whose
    shapes have no signed distance in Drake (e.g. two meshes) are skipped.

    ArgumentError (before any Drake call) for ``diagram``, ``root_context`` or ``systems`` that do not
    belong together (``station.root_context.check_root_context``), a ``q`` that is not a vector of the
    arm's number of finite positions, a ``tolerance`` that is not a finite number >= 0."""
    return _penetrations(diagram, root_context, systems, q, tolerance, "robot_penetrations")


def _penetrations(diagram, root_context, systems, q, tolerance, owner):
    """``robot_penetrations``, its errors naming ``owner``."""
    check_root_context(diagram, root_context, systems, owner)
    plant, robot = systems.plant, systems.robot
    q = joint_vector(q, "q", owner, plant, robot.arm, unit="the arm's joint positions, rad or m")
    tolerance = nonnegative(tolerance, "tolerance", owner, unit="m")
    scene_graph = next((system for system in diagram.GetSystems() if isinstance(system, SceneGraph)), None)
    if scene_graph is None:
        return []
    context = root_context.Clone()
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), robot.arm, q)
    scene_context = scene_graph.GetMyMutableContextFromRoot(context)
    inspector = scene_graph.get_query_output_port().Eval(scene_context).inspector()
    pad = set(robot.pad_geometries)
    mine = {geometry: plant.get_body(index).name() for instance in robot.model_instances
            for index in plant.GetBodyIndices(instance)
            for geometry in plant.GetCollisionGeometriesForBody(plant.get_body(index))
            if geometry not in pad and inspector.GetProximityProperties(geometry) is not None}
    others = [geometry for geometry in inspector.GetAllGeometryIds(Role.kProximity)
              if geometry not in mine and geometry not in pad]
    if not mine or not others:
        return []
    scene_graph.collision_filter_manager(scene_context).Apply(
        CollisionFilterDeclaration().AllowBetween(GeometrySet(list(mine)), GeometrySet(others)))
    query = scene_graph.get_query_output_port().Eval(scene_context)
    found = []
    for geometry, body in mine.items():
        for other in others:
            if inspector.GetFrameId(other) == inspector.GetFrameId(geometry):
                continue
            try:
                distance = query.ComputeSignedDistancePairClosestPoints(geometry, other).distance
            except RuntimeError:             # no signed distance for this pair of shapes in Drake
                continue
            if distance < -tolerance:
                found.append((body, inspector.GetName(geometry), inspector.GetName(other), -distance))
    return sorted(found, key=lambda item: -item[3])


def check_robot_clearance(diagram: Diagram, root_context: Context, systems: HybridSystems, q: ArrayLike,
                          who: str) -> None:
    """StartCollisionError naming the bodies if ``robot_penetrations`` finds any at ``q`` (``who``: the
    caller, which begins every message; its arguments are checked as ``robot_penetrations``'s)."""
    who = text(who, "who", "check_robot_clearance")
    found = _penetrations(diagram, root_context, systems, q, PENETRATION_TOLERANCE, who)
    if found:
        parts = "; ".join(f"body '{body}' ({geometry}) {depth * 1000:.1f} mm into {other}"
                          for body, geometry, other, depth in found[:4])
        raise StartCollisionError(
            f"{who}: at the start the robot penetrates the scene beyond its tool: {parts}"
            f"{' and more' if len(found) > 4 else ''}; the collision filters that let only the tool touch would "
            "hide it in the simulation: move the start, the workpiece or the base")
