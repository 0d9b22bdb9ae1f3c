"""Where the models live and how Drake's Parser finds them.

The top-level ``models/`` folder is a ROS-style package (``package.xml``)
named ``drake_hybrid``; models are referenced as
``package://drake_hybrid/<file>``. In a source checkout (or an editable
install) it is ``<repo>/models``; a regular install ships it as
``drake_hybrid/models``. ::

    parser = Parser(plant)
    ConfigureParser(parser)
    add_model(parser, "planar_3r.sdf")         # = parser.AddModelsFromUrl(model_url("planar_3r.sdf")), faster

Model packages installed with pip in the cmeel layout (``<site-packages>/cmeel.prefix/share/<name>/
package.xml``, e.g. ``example-robot-data``) are known by name too (``installed_model_packages``), so
a task file may write ``package://example-robot-data/robots/...``.
"""

import functools
import sys
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Union

from pydrake.multibody.parsing import Parser
from pydrake.multibody.tree import ModelInstanceIndex

_PACKAGE = Path(__file__).resolve().parent.parent          # drake_hybrid/


def models_directory() -> Path:
    """The folder holding package.xml and the model files."""
    for candidate in (_PACKAGE / "models", _PACKAGE.parent / "models"):
        if (candidate / "package.xml").exists():
            return candidate
    raise FileNotFoundError(f"drake_hybrid's models folder (with package.xml) is missing next to {_PACKAGE}")


def installed_model_packages() -> Dict[str, str]:
    """{package name: folder} of the model packages pip installed in the cmeel layout: every
    ``<sys.path entry>/cmeel.prefix/share/<folder>/package.xml`` (named by the folder, as
    example-robot-data's URDFs name themselves). Read from the disk, nothing is downloaded."""
    packages: Dict[str, str] = {}
    for entry in sys.path:
        share = Path(entry or ".") / "cmeel.prefix" / "share"
        if share.is_dir():
            for manifest in sorted(share.glob("*/package.xml")):
                packages.setdefault(manifest.parent.name, str(manifest.parent))
    return packages


def ConfigureParser(parser: Parser, packages: Optional[Mapping[str, Union[str, Path]]] = None) -> Parser:
    """Make ``package://drake_hybrid/...`` resolve to the models folder and ``package://<name>/...``
    to ``packages`` {name: folder} (e.g. a task file's, with ``installed_model_packages``). Returns
    the parser."""
    package_map = parser.package_map()
    if not package_map.Contains("drake_hybrid"):
        package_map.AddPackageXml(models_directory() / "package.xml")
    for name, folder in (packages or {}).items():
        if package_map.Contains(name):
            package_map.Remove(name)
        package_map.Add(name, Path(folder))
    return parser


def model_url(file_name: str) -> str:
    """The package URL of a model file; FileNotFoundError naming the available ones."""
    folder = models_directory()
    if not (folder / file_name).exists():
        available = sorted(p.name for p in folder.iterdir() if p.suffix in (".sdf", ".urdf"))
        raise FileNotFoundError(f"no model '{file_name}' in {folder}; available: {available}")
    return f"package://drake_hybrid/{file_name}"


@functools.lru_cache(maxsize=None)
def _model_text(file_name):
    return (models_directory() / file_name).read_text()


def add_model(parser: Parser, file_name: str) -> List[ModelInstanceIndex]:
    """``parser.AddModelsFromUrl(model_url(file_name))`` for a model of this package: the same models,
    parsed from the file's text, which is read once per process. libsdformat reloads its whole
    specification for every file it opens (about 0.1 s a model, most of a diagram's build), not for
    a string (about 1 ms); the package's models refer to nothing by a relative path. Returns the
    model instances."""
    model_url(file_name)                     # FileNotFoundError naming the available models
    return parser.AddModelsFromString(_model_text(file_name), Path(file_name).suffix.lstrip("."))
