"""A URDF or SDF file as model packages ship it, rewritten once into one Drake parses
(``prepare_model``, the first stage of ``tasks.robots.load_arm``), and what it changed (``LoadReport``).

The rewritten model is cached, keyed by content hash, in ``default_cache_dir()``:

* mesh files Drake's SceneGraph cannot use are converted to OBJ (``tasks.mesh_conversion``), or,
  with ``collision="drop"``, the arm's collision meshes are removed (with the pad tool only the pad
  touches anything);
* ``package://`` and relative mesh URIs become absolute paths (the cached file needs no package map);
* a material name defined twice with different colours is renamed (Drake's URDF parser rejects it);
* what Drake's URDF parser ignores with a warning is removed (Coulomb joint friction, mechanical
  reductions, safety controllers, transmissions of fixed joints).

``model_effort_limits`` reads the file's effort limits, which Drake keeps for a URDF's joints only
where they have a ``<transmission>``.
"""

import hashlib
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List
from xml.etree import ElementTree

from pydrake.multibody.parsing import PackageMap

from drake_hybrid.core.errors import ConfigError
from drake_hybrid.tasks.mesh_conversion import DRAKE_MESH_SUFFIXES, convert_mesh


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
