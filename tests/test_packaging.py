"""The wheel must ship every subpackage and the models (CI installs non-editable)."""

import fnmatch
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _setuptools_config():
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]


def _model_files():
    """Every file the models folder holds for the wheel (relative to models/), without caches."""
    return sorted(p.relative_to(ROOT / "models") for p in (ROOT / "models").rglob("*")
                  if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc")


def test_every_subpackage_is_listed_in_pyproject():
    config = _setuptools_config()
    listed = set(config["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "drake_hybrid").rglob("__init__.py")}
    assert found <= listed, f"add {sorted(found - listed)} to [tool.setuptools] packages in pyproject.toml"
    assert config["package-dir"]["drake_hybrid.models"] == "models"


def test_every_model_folder_and_file_is_shipped():
    """A folder under models/ (e.g. tasks/) is a package of its own for setuptools: unlisted, it is left
    out of the wheel (with a "Package would be ignored" warning); a file no package-data pattern matches
    is left out silently."""
    config = _setuptools_config()
    for path in _model_files():
        package = ".".join(("drake_hybrid", "models") + path.parent.parts)
        assert package in config["packages"], f"add '{package}' to [tool.setuptools] packages (for models/{path})"
        if path.suffix == ".py":
            continue
        patterns = config["package-data"].get(package, [])
        assert any(fnmatch.fnmatch(path.name, pattern) for pattern in patterns), \
            f"models/{path} matches no [tool.setuptools.package-data] pattern of '{package}': {patterns}"


@pytest.mark.slow          # about 10 s: pip builds the wheel in an isolated environment (setuptools from the index)
def test_the_wheel_holds_every_module_and_model_file(tmp_path):
    source = tmp_path / "source"
    source.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, source / name)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    shutil.copytree(ROOT / "drake_hybrid", source / "drake_hybrid", ignore=ignore)
    shutil.copytree(ROOT / "models", source / "models", ignore=ignore)
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-w", str(tmp_path / "dist"),
                            str(source)], capture_output=True, text=True)
    assert built.returncode == 0, built.stderr[-2000:]
    assert "would be ignored" not in built.stdout + built.stderr
    (wheel,) = (tmp_path / "dist").glob("*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {str(p.relative_to(ROOT)) for p in (ROOT / "drake_hybrid").rglob("*.py") if "__pycache__" not in p.parts}
    models = {f"drake_hybrid/models/{path.as_posix()}" for path in _model_files()}
    assert not modules - names, f"missing from the wheel: {sorted(modules - names)}"
    assert not models - names, f"missing from the wheel: {sorted(models - names)}"


def test_models_are_found_and_resolve():
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    from drake_hybrid.station.parsing import ConfigureParser, model_url, models_directory

    assert (models_directory() / "package.xml").exists()
    plant = MultibodyPlant(0.0)
    parser = ConfigureParser(Parser(plant))
    for sdf in sorted(models_directory().glob("*.sdf")):
        parser.AddModelsFromUrl(model_url(sdf.name))
