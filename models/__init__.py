"""Robot, tool and workpiece models of drake_hybrid (SI units).

The folder is a ROS-style package (``package.xml``) named ``drake_hybrid``;
models are referenced as ``package://drake_hybrid/<file>``::

    parser = Parser(plant)
    ConfigureParser(parser)
    parser.AddModelsFromUrl("package://drake_hybrid/planar_3r.sdf")
"""

from pathlib import Path

MODELS_DIRECTORY = Path(__file__).resolve().parent


def ConfigureParser(parser):
    """Make ``package://drake_hybrid/...`` resolve to this folder."""
    package_map = parser.package_map()
    if not package_map.Contains("drake_hybrid"):
        package_map.AddPackageXml(str(MODELS_DIRECTORY / "package.xml"))
    return parser


def model_url(file_name):
    """The package URL of a model file in this folder."""
    if not (MODELS_DIRECTORY / file_name).exists():
        available = sorted(p.name for p in MODELS_DIRECTORY.iterdir() if p.suffix in (".sdf", ".urdf"))
        raise FileNotFoundError(f"no model '{file_name}' in {MODELS_DIRECTORY}; available: {available}")
    return f"package://drake_hybrid/{file_name}"
