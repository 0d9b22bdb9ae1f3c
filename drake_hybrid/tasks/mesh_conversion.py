"""Meshes of model packages that Drake's SceneGraph cannot use (STL, DAE, PLY, ...: ``MakeConvexHull``
takes only OBJ, VTK and glTF) converted to OBJ with trimesh, once per file: the copy is named by the
hash of the file's content, so a converted mesh is reused and parallel workers never see half a file.
"""

import hashlib
import os
from pathlib import Path
from xml.etree import ElementTree

import trimesh

from drake_hybrid.core.errors import ConfigError

# Mesh formats Drake 1.51's SceneGraph takes for collision (convex hulls) and that Meshcat shows.
DRAKE_MESH_SUFFIXES = (".obj", ".vtk", ".gltf", ".glb")
# Bumped when the conversion changes, so cached files from an older conversion are not reused.
CONVERSION_VERSION = "1"


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
