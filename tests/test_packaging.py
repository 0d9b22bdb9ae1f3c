"""The wheel must ship every subpackage and the models (CI installs non-editable)."""

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_every_subpackage_is_listed_in_pyproject():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(config["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "drake_hybrid").rglob("__init__.py")}
    assert found <= listed, f"add {sorted(found - listed)} to [tool.setuptools] packages in pyproject.toml"
    assert config["package-dir"]["drake_hybrid.models"] == "models"


def test_models_are_found_and_resolve():
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    from drake_hybrid.scenario.parsing import ConfigureParser, model_url, models_directory

    assert (models_directory() / "package.xml").exists()
    plant = MultibodyPlant(0.0)
    parser = ConfigureParser(Parser(plant))
    for sdf in sorted(models_directory().glob("*.sdf")):
        parser.AddModelsFromUrl(model_url(sdf.name))
