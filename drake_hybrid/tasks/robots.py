"""Any arm from a URDF or SDF model package, ready for the hybrid law in one call.

``load_arm(path, flange=...)`` turns a model file as model packages ship it into one that Drake
parses and the law can use, and says what it changed (``LoadReport``)::

    arm = load_arm(share / "robots/ur_description/urdf/ur10_robot.urdf", flange="tool0")
    print(arm.report)                            # every change, one line each
    guess = arm.find_joint_guess(X_WE_start)     # inverse kinematics from several seeds
    task = CustomTask("ur10-plane", add_robot=arm.add_robot, ..., joint_guess=guess.positions)

What it fixes, once per file (the rewritten model is cached, keyed by content hash):

* mesh files Drake's SceneGraph cannot use (STL, DAE: ``MakeConvexHull`` takes only OBJ, VTK and
  glTF) are converted to OBJ with trimesh into ``cache_dir`` (``collision="drop"`` removes the
  arm's collision geometries instead: with the pad tool only the pad touches anything);
* ``package://`` and relative mesh URIs become absolute paths (the cached file needs no package map);
* a material name defined twice with different colours is renamed (Drake's URDF parser rejects it);

and every time ``add_robot(plant)`` parses it (the simulation plant and the controller's plant):

* the base is welded to the world at ``base_pose`` (a floating base, a floating or planar joint to the
  world, or a weld of the model's own);
* every joint that is not on the chain from the base to the flange (gripper fingers) is welded at
  its zero position, and multi-dof joints on the chain too (the law needs one actuator per joint
  and nq = nv);
* each chain joint gets an actuator with the model file's effort limit (Drake keeps a URDF's
  effort limits only for joints with a ``<transmission>``);
* the pad tool (``models/pad_tool.sdf``) is welded at ``tool_frame`` (default: the flange), its
  approach axis along the tool frame's ``tool_axis``.

Unknown frames raise ``UnknownFrameError`` listing the model's frames. The joint-guess finder
(``LoadedArm.find_joint_guess``) runs Drake's ``InverseKinematics`` from several seeds within the
joint limits and keeps the solution whose pad Jacobian is best conditioned.

Size: the file's rewriting, the plant-level fixes and the joint-guess finder are one idea (an arm
as a model package ships it, made usable) and write one report.
"""

import hashlib
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List
from xml.etree import ElementTree

import numpy as np
import trimesh

from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.multibody.parsing import PackageMap, Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.solvers import Solve
from pydrake.systems.framework import DiagramBuilder

from drake_hybrid.core.arguments import function, joint_vector, number, positive
from drake_hybrid.core.errors import ConfigError, UnreachablePoseError
from drake_hybrid.station.arm import mount_tool
from drake_hybrid.station.robot_model import get_frame

# Mesh formats Drake 1.51's SceneGraph takes for collision (convex hulls) and that Meshcat shows.
DRAKE_MESH_SUFFIXES = (".obj", ".vtk", ".gltf", ".glb")
# Bumped when the conversion changes, so cached files from an older conversion are not reused.
CONVERSION_VERSION = "1"
TOOL_AXES = {"+z": RotationMatrix(), "-z": RotationMatrix.MakeXRotation(np.pi),
             "+x": RotationMatrix.MakeYRotation(np.pi / 2), "-x": RotationMatrix.MakeYRotation(-np.pi / 2),
             "+y": RotationMatrix.MakeXRotation(-np.pi / 2), "-y": RotationMatrix.MakeXRotation(np.pi / 2)}


def default_cache_dir():
    """Where converted meshes and rewritten models are kept: ``$DRAKE_HYBRID_CACHE``, else the
    user's cache folder (``$XDG_CACHE_HOME`` or ~/.cache; ~/Library/Caches on macOS) /drake_hybrid."""
    if os.environ.get("DRAKE_HYBRID_CACHE"):
        return Path(os.environ["DRAKE_HYBRID_CACHE"])
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches" / "drake_hybrid"
    if sys.platform.startswith("win"):
        return Path(os.environ.get("LOCALAPPDATA", Path.home())) / "drake_hybrid" / "cache"
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "drake_hybrid"


@dataclass
class LoadReport:
    """What ``load_arm`` changed to make the model usable; ``str(report)`` lists ``changes``."""

    source: str                                    # the model file as given
    model: str                                     # the rewritten (cached) model file
    changes: List[str] = field(default_factory=list)
    converted_meshes: Dict[str, str] = field(default_factory=dict)   # original -> OBJ
    dropped_geometries: List[str] = field(default_factory=list)      # "<link>: <mesh>"
    renamed_materials: List[str] = field(default_factory=list)
    welded_joints: List[str] = field(default_factory=list)
    arm_joints: List[str] = field(default_factory=list)              # the actuated chain, base to flange
    effort_limits: Dict[str, float] = field(default_factory=dict)    # actuated joint -> N m (or N)
    base: str = ""
    flange: str = ""
    tool_frame: str = ""

    def __str__(self):
        return "\n".join([f"{self.source}:"] + [f"  - {line}" for line in self.changes])


@dataclass
class JointGuess:
    """The result of ``LoadedArm.find_joint_guess``."""

    positions: np.ndarray                          # the chosen joint positions
    condition_number: float                        # LoadedArm.condition_number there (translation scaled)
    seeds: int                                     # inverse-kinematics problems solved
    solutions: int                                 # of them, how many reached the pose (within the limits, clear)
    limit_margin: float                            # smallest distance to a joint limit (rad or m)


# ------------------------------------------------------------------------------------------------
# The file: meshes, URIs, materials
# ------------------------------------------------------------------------------------------------

def _package_map(path, packages):
    """A PackageMap with every package.xml above ``path`` (by its name, and by its folder's name, as
    model packages installed under another name refer to themselves) and ``packages`` {name: folder}."""
    package_map = PackageMap.MakeEmpty()
    for folder in Path(path).resolve().parents:
        if (folder / "package.xml").exists():
            try:
                package_map.AddPackageXml(str(folder / "package.xml"))
            except RuntimeError:
                pass                               # the same package name twice: the nearest wins
            if not package_map.Contains(folder.name):
                package_map.Add(folder.name, str(folder))
    for name, folder in (packages or {}).items():
        if package_map.Contains(name):
            package_map.Remove(name)
        package_map.Add(name, str(folder))
    return package_map


def _resolve(uri, model_folder, package_map):
    """The absolute file of a mesh URI (package://, file:// or relative)."""
    if uri.startswith("package://"):
        name, _, rest = uri[len("package://"):].partition("/")
        if not package_map.Contains(name):
            raise ConfigError(f"mesh '{uri}': package '{name}' is unknown; pass load_arm(..., packages={{'{name}': "
                              f"folder}}) (known: {', '.join(sorted(package_map.GetPackageNames()))})")
        return Path(package_map.GetPath(name)) / rest
    if uri.startswith("file://"):
        return Path(uri[len("file://"):])
    return (model_folder / uri).resolve()


def _collada_unit(path):
    """Metres per unit of a COLLADA file (``<unit meter=...>``; 1 if absent). trimesh ignores it."""
    try:
        root = ElementTree.parse(path).getroot()
    except ElementTree.ParseError:
        return 1.0
    for element in root.iter():
        if element.tag.endswith("unit") and element.get("meter"):
            return float(element.get("meter"))
    return 1.0


def convert_mesh(path, cache_dir):
    """An OBJ copy of mesh ``path`` (STL, DAE, PLY, ... as trimesh reads them) in ``cache_dir``,
    named by the hash of the file's content; converted once. COLLADA units are applied."""
    data = Path(path).read_bytes()
    digest = hashlib.sha256(data + CONVERSION_VERSION.encode()).hexdigest()[:20]
    target = Path(cache_dir) / "meshes" / f"{Path(path).stem}-{digest}.obj"
    if target.exists():
        return target
    mesh = trimesh.load(str(path), force="mesh", process=False)
    if Path(path).suffix.lower() == ".dae":
        mesh.apply_scale(_collada_unit(path))
    if len(mesh.faces) == 0:
        raise ConfigError(f"mesh '{path}' has no triangles that trimesh could read")
    target.parent.mkdir(parents=True, exist_ok=True)
    partial = target.with_suffix(f".{os.getpid()}.tmp")
    partial.write_text(trimesh.exchange.obj.export_obj(mesh, include_normals=False, include_color=False,
                                                      include_texture=False))
    partial.replace(target)                        # atomic: parallel workers never see half a file
    return target


def _mesh_elements(root, urdf):
    """(geometry role 'collision' or 'visual', owner link name, element holding the URI, URI attribute or None)."""
    found = []
    for link in root.iter("link"):
        for role in ("collision", "visual"):
            for owner in link.iter(role):
                for mesh in owner.iter("mesh"):
                    if urdf:
                        found.append((role, link.get("name"), owner, mesh, "filename"))
                    else:
                        uri = mesh.find("uri")
                        if uri is not None:
                            found.append((role, link.get("name"), owner, uri, None))
    return found


def _parents(root):
    return {child: parent for parent in root.iter() for child in parent}


def _fix_materials(root, report):
    """Rename a URDF material defined again with another colour (Drake's parser rejects it)."""
    colours = {}
    for material in root.iter("material"):
        name, colour = material.get("name"), material.find("color")
        if name is None or colour is None:
            continue
        rgba = tuple(float(v) for v in colour.get("rgba", "").split()) or None
        if name not in colours:
            colours[name] = rgba
        elif colours[name] != rgba:
            new = f"{name}__{len(report.renamed_materials) + 1}"
            material.set("name", new)
            colours[new] = rgba
            report.renamed_materials.append(f"{name} -> {new}")
    for name in sorted({line.split(" -> ")[0] for line in report.renamed_materials}):
        renamed = [line.split(" -> ")[1] for line in report.renamed_materials if line.startswith(f"{name} -> ")]
        report.changes.append(f"material '{name}' defined again with other colours: renamed {', '.join(renamed)}")


def _drop_what_drake_ignores(root, report):
    """Remove from a URDF what Drake's parser warns it ignores, once per element, and say so once:
    Coulomb joint friction, mechanical reductions, safety controllers, transmissions of fixed joints."""
    parents = _parents(root)
    fixed = {joint.get("name") for joint in root.iter("joint") if joint.get("type") == "fixed"}
    friction = []
    for joint in root.iter("joint"):
        for dynamics in joint.iter("dynamics"):
            if float(dynamics.get("friction", 0) or 0) != 0:
                friction.append(f"{joint.get('name')} {dynamics.get('friction')}")
                del dynamics.attrib["friction"]
    if friction:
        report.changes.append(f"removed Coulomb joint friction Drake ignores (N m): {', '.join(friction)}")
    reductions = [element for element in root.iter("mechanicalReduction") if float(element.text or 1) != 1]
    for element in reductions:
        parents[element].remove(element)
    if reductions:
        report.changes.append(f"removed {len(reductions)} mechanical reductions Drake ignores (the effort limits are "
                              "joint torques)")
    safety = list(root.iter("safety_controller"))
    for element in safety:
        parents[element].remove(element)
    if safety:
        report.changes.append(f"removed {len(safety)} <safety_controller> tags Drake ignores")
    dead = [transmission for transmission in root.iter("transmission")
            if any(joint.get("name") in fixed for joint in transmission.iter("joint"))]
    for transmission in dead:
        parents[transmission].remove(transmission)
    if dead:
        report.changes.append(f"removed {len(dead)} transmissions of fixed joints")


def prepare_model(path, collision="convert", packages=None, cache_dir=None):
    """The model file rewritten for Drake (see the module docstring) and its LoadReport."""
    path = Path(path)
    if not path.exists():
        raise ConfigError(f"load_arm: model file '{path}' does not exist")
    suffix = path.suffix.lower()
    if suffix not in (".urdf", ".sdf"):
        raise ConfigError(f"load_arm: the model must be a .urdf or .sdf file, got '{path.name}'")
    if collision not in ("convert", "drop"):
        raise ConfigError(f"load_arm: collision must be 'convert' or 'drop', got {collision!r}")
    cache_dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    report = LoadReport(source=str(path), model="")
    text = path.read_text()
    root = ElementTree.fromstring(text)
    urdf = suffix == ".urdf"
    package_map = _package_map(path, packages)
    parents = _parents(root)
    for role, link, owner, element, attribute in _mesh_elements(root, urdf):
        uri = element.get(attribute) if attribute else (element.text or "").strip()
        mesh_path = _resolve(uri, path.parent, package_map)
        if mesh_path.suffix.lower() in DRAKE_MESH_SUFFIXES:
            new_uri = f"file://{mesh_path}"
        elif role == "collision" and collision == "drop":
            parents[owner].remove(owner)
            report.dropped_geometries.append(f"{link}: {mesh_path.name}")
            continue
        else:
            if not mesh_path.exists():
                raise ConfigError(f"mesh '{uri}' of link '{link}' resolves to '{mesh_path}', which does not exist")
            obj = convert_mesh(mesh_path, cache_dir)
            report.converted_meshes[str(mesh_path)] = str(obj)
            new_uri = f"file://{obj}"
        if attribute:
            element.set(attribute, new_uri)
        else:
            element.text = new_uri
    if report.converted_meshes:
        report.changes.append(f"converted {len(report.converted_meshes)} mesh files Drake cannot use "
                              f"({', '.join(sorted({Path(p).suffix for p in report.converted_meshes}))}) to OBJ "
                              f"in {cache_dir / 'meshes'}")
    if report.dropped_geometries:
        report.changes.append(f"dropped {len(report.dropped_geometries)} collision meshes Drake cannot use "
                              "(collision='drop': only the pad touches anything)")
    if urdf:
        _fix_materials(root, report)
        _drop_what_drake_ignores(root, report)
    rewritten = ElementTree.tostring(root, encoding="unicode")
    digest = hashlib.sha256((str(path.resolve()) + rewritten).encode()).hexdigest()[:20]
    target = cache_dir / "models" / f"{path.stem}-{digest}{suffix}"
    if not target.exists():
        target.parent.mkdir(parents=True, exist_ok=True)
        partial = target.with_suffix(f".{os.getpid()}.tmp")
        partial.write_text(rewritten)
        partial.replace(target)
    report.model = str(target)
    return report


def model_effort_limits(path):
    """{joint name: effort limit} from a URDF's ``<limit effort=...>`` or an SDF's ``<axis><limit><effort>``."""
    root = ElementTree.parse(path).getroot()
    limits = {}
    for joint in root.iter("joint"):
        if joint.get("name") is None:
            continue                                 # a <transmission>'s joint reference
        for limit in joint.iter("limit"):
            value = limit.get("effort")
            if value is None and limit.find("effort") is not None:
                value = limit.find("effort").text
            if value is not None:
                limits[joint.get("name")] = float(value)
    return limits


# ------------------------------------------------------------------------------------------------
# The plant: base, chain, welds, actuators, tool
# ------------------------------------------------------------------------------------------------

def _inboard_joints(plant, model_instance):
    """{child body index: joint} for the joints of ``model_instance``."""
    return {plant.get_joint(index).child_body().index(): plant.get_joint(index)
            for index in plant.GetJointIndices(model_instance)}


def _chain(plant, body, inboard):
    """The joints from the world (or a free root) to ``body``, base first."""
    joints = []
    while body.index() in inboard:
        joint = inboard[body.index()]
        joints.append(joint)
        body = joint.parent_body()
    return joints[::-1], body


def _weld(plant, joint, X_PC=None):
    """Replace ``joint`` by a weld (at its zero position, or ``X_PC`` between the bodies' frames)."""
    for index in plant.GetJointActuatorIndices():
        if plant.get_joint_actuator(index).joint().index() == joint.index():
            plant.RemoveJointActuator(plant.get_joint_actuator(index))
    parent, child = joint.frame_on_parent(), joint.frame_on_child()
    plant.RemoveJoint(joint)
    if X_PC is None:
        return plant.WeldFrames(parent, child, RigidTransform())
    return plant.WeldFrames(parent.body().body_frame(), child.body().body_frame(), X_PC)


def fix_arm(plant, model_instance, flange, tool_frame, base_pose, effort_limits, report=None):
    """Weld the base at ``base_pose`` and every joint off the base-to-flange chain, add the chain's
    actuators; returns (flange frame, tool frame). ``report`` (a LoadReport) gets the changes."""
    note = (lambda line: report.changes.append(line)) if report is not None else (lambda line: None)
    flange_frame = get_frame(plant, flange, model_instance, "flange")
    tool = get_frame(plant, tool_frame, model_instance, "tool_frame")
    inboard = _inboard_joints(plant, model_instance)
    chain, root = _chain(plant, flange_frame.body(), inboard)
    tool_chain, _ = _chain(plant, tool.body(), inboard)
    if not set(j.index() for j in chain) <= set(j.index() for j in tool_chain):
        raise ConfigError(f"tool_frame '{tool_frame}' is not carried by the flange '{flange}' (it is on body "
                          f"'{tool.body().name()}', not downstream of '{flange_frame.body().name()}')")
    world = plant.world_body()
    X_WB = base_pose if base_pose is not None else RigidTransform()
    # The base: the first chain joint from the world that is not a one-dof joint, or a free root.
    if root.index() != world.index():
        plant.WeldFrames(plant.world_frame(), root.body_frame(), X_WB)
        note(f"floating base '{root.name()}': welded to the world at base_pose")
        base = root
    else:
        first = chain[0]
        base = first.child_body()
        if first.num_velocities() == 1:
            base = first.parent_body()                 # the model's own world link holds a one-dof joint
            if base_pose is not None:
                note(f"base_pose not applied: the model attaches its first joint '{first.name()}' to the world itself")
        else:
            kind = first.type_name()
            # The model's own weld to the world, kept under base_pose: X_W_child = X_WB X_WF X_FM X_CM^-1.
            X_PC = X_WB if kind != "weld" else X_WB.multiply(
                first.frame_on_parent().GetFixedPoseInBodyFrame().multiply(first.X_FM()).multiply(
                    first.frame_on_child().GetFixedPoseInBodyFrame().inverse()))
            _weld(plant, first, X_PC)
            chain = chain[1:]
            note(f"base '{base.name()}': its {kind} joint '{first.name()}' to the world replaced by a weld at "
                 "base_pose" + (" (times the model's own weld)" if kind == "weld" else ""))
    if report is not None:
        report.base = base.name()
    on_chain = {joint.index() for joint in chain}
    welded = []
    movable = [plant.get_joint(index) for index in plant.GetJointIndices(model_instance)
               if plant.get_joint(index).num_velocities() > 0]
    if any(joint.index() not in on_chain or joint.num_velocities() != 1 for joint in movable):
        for constraint_id in plant.GetConstraintIds():  # couplers (<mimic>) block RemoveJoint
            plant.RemoveConstraint(constraint_id)
    for joint in movable:
        if joint.index() not in on_chain or joint.num_velocities() != 1:
            welded.append(f"{joint.name()} ({joint.type_name()})")
            _weld(plant, joint)
    if welded:
        note(f"welded {len(welded)} joints off the chain to '{flange}' (or not one-dof) at zero: {', '.join(welded)}")
        if report is not None:
            report.welded_joints = welded
    arm_joints = [joint for joint in chain if joint.num_velocities() == 1]
    # (GetJointActuatorIndices(model_instance) is empty before Finalize: filter all of them.)
    actuated = {int(plant.get_joint_actuator(index).joint().index()): plant.get_joint_actuator(index)
                for index in plant.GetJointActuatorIndices()
                if plant.get_joint_actuator(index).model_instance() == model_instance}
    added, unlimited = [], []
    for joint in arm_joints:
        limit = float(effort_limits.get(joint.name(), np.inf))
        if not limit > 0:
            limit = np.inf
        if int(joint.index()) in actuated:
            actuator = actuated[int(joint.index())]
            if not np.isfinite(actuator.effort_limit()) and np.isfinite(limit):
                actuator.set_effort_limit(limit)
        else:
            actuator = plant.AddJointActuator(f"{joint.name()}_actuator", joint, limit)
            added.append(joint.name())
        if not np.isfinite(actuator.effort_limit()):
            unlimited.append(joint.name())
        if report is not None:
            report.effort_limits[joint.name()] = float(actuator.effort_limit())
    if added:
        note(f"added actuators to {len(added)} joints without a transmission, effort limits from the model file")
    kept = len(arm_joints) - len(added)
    if kept:
        note(f"kept the model's actuators (transmissions) of {kept} joints")
    if unlimited:
        note(f"no effort limit in the model for {', '.join(unlimited)}: unlimited")
    damped = [f"{joint.name()} {joint.default_damping():g}" for joint in arm_joints if joint.default_damping() > 0]
    if damped:
        note(f"kept the model's joint damping (N m s/rad): {', '.join(damped)}")
    if report is not None:
        report.arm_joints = [joint.name() for joint in arm_joints]
    return flange_frame, tool


# ------------------------------------------------------------------------------------------------
# The loaded arm
# ------------------------------------------------------------------------------------------------

class LoadedArm:
    """An arm made usable by ``load_arm``: ``add_robot(plant)`` for ``CustomTask``, the ``report``,
    the joint limits and ``find_joint_guess``."""

    def __init__(self, report, flange, tool_frame, base_pose, tool_axis, effort_limits, name):
        self.report = report
        self.flange = flange
        self.tool_frame = tool_frame
        self.base_pose = base_pose
        self.tool_axis = tool_axis
        self.effort_limits = effort_limits
        self.name = name
        self._plant = None

    def add_robot(self, plant, report=None):
        """Parse the arm into ``plant`` (before Finalize), fix it and attach the pad tool; returns the
        RobotModel that ``CustomTask``'s ``add_robot`` returns."""
        parser = Parser(plant)
        parser.SetAutoRenaming(True)
        arm = parser.AddModels(self.report.model)[0]
        flange, tool = fix_arm(plant, arm, self.flange, self.tool_frame, self.base_pose, self.effort_limits, report)
        return mount_tool(plant, arm, tool, RigidTransform(TOOL_AXES[self.tool_axis], np.zeros(3)))

    @property
    def plant(self):
        """A finalized continuous plant of the arm and pad (no SceneGraph), built once."""
        if self._plant is None:
            plant = MultibodyPlant(0.0)
            self.robot = self.add_robot(plant)
            plant.Finalize()
            self._plant = plant
        return self._plant

    @property
    def num_joints(self):
        return self.plant.num_positions()

    def joint_limits(self):
        """(lower, upper) position limits of the arm's joints (rad; +-inf for continuous joints)."""
        return self.plant.GetPositionLowerLimits(), self.plant.GetPositionUpperLimits()

    def pad_jacobian(self, q):
        """The 6 x n spatial Jacobian (angular; translational, world frame) of the pad centre at ``q``
        (ArgumentError unless a vector of the arm's number of finite positions)."""
        plant = self.plant
        context = plant.CreateDefaultContext()
        plant.SetPositions(context, joint_vector(q, "q", "LoadedArm.pad_jacobian", plant))
        frame = plant.GetFrameByName(self.robot.end_effector_frame)
        return plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kV, frame, np.zeros(3),
                                                 plant.world_frame(), plant.world_frame())

    def condition_number(self, q, length_scale=None):
        """cond(S J) of the pad's spatial Jacobian at ``q``, its translational rows divided by
        ``length_scale`` (m; default: the distance from the base to the pad, at least 0.1 m) so that
        the number does not depend on the unit of length. ArgumentError for a ``q`` that is not a
        vector of the arm's number of finite positions or a ``length_scale`` that is not a positive
        finite number or None."""
        q = joint_vector(q, "q", "LoadedArm.condition_number", self.plant)
        length_scale = positive(length_scale, "length_scale", "LoadedArm.condition_number", unit="m",
                                allow_none=True)
        J = self.pad_jacobian(q)
        if length_scale is None:
            base = self.base_pose.translation() if self.base_pose is not None else np.zeros(3)
            length_scale = max(float(np.linalg.norm(self.pad_pose(q).translation() - base)), 0.1)
        singular = np.linalg.svd(np.vstack([J[:3], J[3:] / length_scale]), compute_uv=False)
        return float(singular[0] / singular[-1]) if singular[-1] > 0 else float("inf")

    def pad_pose(self, q):
        """X_WE of the pad centre frame at joint positions ``q`` (ArgumentError unless a vector of the
        arm's number of finite positions)."""
        plant = self.plant
        context = plant.CreateDefaultContext()
        plant.SetPositions(context, joint_vector(q, "q", "LoadedArm.pad_pose", plant))
        return plant.GetFrameByName(self.robot.end_effector_frame).CalcPoseInWorld(context)

    def workpiece_penetrations(self, add_workpiece, q):
        """Names of the arm's bodies (the pad excepted) whose collision shapes penetrate the
        workpiece of ``add_workpiece(plant) -> geometry ids`` (CustomTask's) at joint positions ``q``
        (ArgumentError unless a vector of the arm's number of finite positions)."""
        owner = "LoadedArm.workpiece_penetrations"
        function(add_workpiece, "add_workpiece", owner, "add_workpiece(plant) -> geometry ids")
        q = joint_vector(q, "q", owner, self.plant)
        if getattr(self, "_clearance_probe", (None,))[0] is not add_workpiece:
            builder = DiagramBuilder()
            plant, scene_graph = AddMultibodyPlant(MultibodyPlantConfig(time_step=0.0), builder)
            robot = self.add_robot(plant)
            workpiece = set(add_workpiece(plant))
            plant.Finalize()
            diagram = builder.Build()
            self._clearance_probe = (add_workpiece, diagram, plant, scene_graph, robot, workpiece)
        _, diagram, plant, scene_graph, robot, workpiece = self._clearance_probe
        context = diagram.CreateDefaultContext()
        plant.SetPositions(plant.GetMyMutableContextFromRoot(context), robot.arm, q)
        query = scene_graph.get_query_output_port().Eval(scene_graph.GetMyContextFromRoot(context))
        inspector = query.inspector()
        pad = set(robot.pad_geometries)
        touching = set()
        for pair in query.ComputePointPairPenetration():
            ids = {pair.id_A, pair.id_B}
            if ids & workpiece and not ids & pad and not ids <= workpiece:
                (other,) = ids - workpiece
                touching.add(plant.GetBodyFromFrameId(inspector.GetFrameId(other)).name())
        return sorted(touching)

    def find_joint_guess(self, X_WE, seeds=12, rng=0, near=None, add_workpiece=None, position_tolerance=1e-6,
                         angle_tolerance=1e-6, limit_margin=0.05):
        """Joint positions that put the pad centre frame at ``X_WE`` (a RigidTransform: e.g. the
        start pose of a CustomTask, its point on the surface), from Drake's InverseKinematics.

        Solves from ``seeds`` starts: ``near`` (if given), the middle of the joint limits, and
        uniform random positions within the limits (continuous joints within +-pi; ``rng`` a seed
        or numpy Generator), each held ``limit_margin`` inside the limits. With ``add_workpiece``
        (CustomTask's), solutions where an arm link (not the pad) penetrates the workpiece are
        rejected. Of the solutions left, the one whose pad Jacobian is best conditioned
        (``condition_number``: translation rows scaled by the base-to-pad distance) is returned
        (a JointGuess). UnreachablePoseError if none is left."""
        plant = self.plant
        lower, upper = self.joint_limits()
        low = np.where(np.isfinite(lower), lower, -np.pi) + limit_margin
        high = np.where(np.isfinite(upper), upper, np.pi) - limit_margin
        generator = np.random.default_rng(rng)
        if near is not None:
            near = joint_vector(near, "near", "LoadedArm.find_joint_guess", self.plant, unit="rad, m: one per arm joint")
        seeds = number(seeds, "seeds", "LoadedArm.find_joint_guess", low=1, integer=True)
        starts = ([np.clip(near, low, high)] if near is not None else []) + [(low + high) / 2]
        starts += [generator.uniform(low, high) for _ in range(max(seeds - len(starts), 0))]
        frame = plant.GetFrameByName(self.robot.end_effector_frame)
        best, solutions = None, 0
        for start in starts:
            ik = InverseKinematics(plant, with_joint_limits=False)
            q = ik.q()
            ik.prog().AddBoundingBoxConstraint(low, high, q)
            p = X_WE.translation()
            ik.AddPositionConstraint(frame, np.zeros(3), plant.world_frame(), p - position_tolerance,
                                     p + position_tolerance)
            ik.AddOrientationConstraint(plant.world_frame(), X_WE.rotation(), frame, RotationMatrix(),
                                        angle_tolerance)
            ik.prog().AddQuadraticErrorCost(1e-3 * np.eye(len(start)), start, q)
            # SNOPT often reports "infeasible" at a solution within 1e-6 of the pose: judge by the pose itself.
            solution = Solve(ik.prog(), start).GetSolution(q)
            if np.any(solution < low - 1e-9) or np.any(solution > high + 1e-9):
                continue
            X = self.pad_pose(solution)
            error = max(np.linalg.norm(X.translation() - X_WE.translation()),
                        X.rotation().inverse().multiply(X_WE.rotation()).ToAngleAxis().angle())
            if error > 10 * max(position_tolerance, angle_tolerance):
                continue
            if add_workpiece is not None and self.workpiece_penetrations(add_workpiece, solution):
                continue
            solutions += 1
            condition = self.condition_number(solution)
            if best is None or condition < best[1]:
                best = (solution, condition)
        if best is None:
            raise UnreachablePoseError(
                f"arm '{self.name}': no joint positions within the limits put the pad centre at "
                f"p = {np.round(X_WE.translation(), 4).tolist()} m with the requested orientation"
                f"{' clear of the workpiece' if add_workpiece is not None else ''} ({len(starts)} inverse-kinematics "
                "seeds); move the workpiece or the base (base_pose), change the tool axis, or try more seeds")
        margin = float(np.min(np.minimum(best[0] - lower, upper - best[0])))
        return JointGuess(positions=best[0], condition_number=best[1], seeds=len(starts), solutions=solutions,
                          limit_margin=margin)


def load_arm(path, flange, tool_frame=None, base_pose=None, tool_axis="+z", collision="convert", packages=None,
             cache_dir=None):
    """Make the arm of URDF/SDF ``path`` usable by the hybrid law (see the module docstring).

    Args:
        path: the model file (``package://`` mesh URIs are resolved from the package.xml files above
            it and ``packages``).
        flange: the frame (link) that ends the actuated chain; joints beyond it are welded.
        tool_frame: the frame the pad tool is welded to, its approach axis along ``tool_axis``
            (default: ``flange``); it must be carried by the flange (e.g. a TCP frame on the hand).
        base_pose: X_W_base, where the arm's base is welded to the world (default: identity).
        tool_axis: the tool frame's axis the pad points along: one of +z, -z, +x, -x, +y, -y.
        collision: "convert" (STL/DAE collision meshes to OBJ) or "drop" (remove them).
        packages: {package name: folder} for ``package://`` URIs not found by package.xml.
        cache_dir: where converted files go (default: ``default_cache_dir()``).

    Returns a LoadedArm; its ``report`` lists every change.
    """
    if tool_axis not in TOOL_AXES:
        raise ConfigError(f"load_arm: tool_axis must be one of {', '.join(TOOL_AXES)}, got {tool_axis!r}")
    report = prepare_model(path, collision=collision, packages=packages, cache_dir=cache_dir)
    tool_frame = tool_frame or flange
    report.flange, report.tool_frame = flange, tool_frame
    name = Path(path).stem
    arm = LoadedArm(report, flange, tool_frame, base_pose, tool_axis, model_effort_limits(path), name)
    # Parse once into a plant without SceneGraph to check the frames and record the plant-level changes.
    plant = MultibodyPlant(0.0)
    arm.robot = arm.add_robot(plant, report)
    plant.Finalize()
    arm._plant = plant
    report.changes.append(f"pad tool welded at '{tool_frame}' along its {tool_axis} axis; the controlled point is "
                          "its centre (frame 'pad_center')")
    return arm
