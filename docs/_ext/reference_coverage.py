"""Sphinx extension: every public name of the package has a reference entry, or the build fails.

The public names (``public_names``): in every module of the package, the classes and functions it
defines whose names do not start with ``_`` (``__all__`` where a module declares it), and its Drake
``TemplateSystem`` templates (documented with their default instantiation: ``HybridController_``
with ``HybridController``; the mangled names Drake binds its instantiations under are the same
classes, not names of their own). After the build has read every page, each must be a Python object of
the site (the autosummary pages of ``docs/reference/api.rst`` document them); a missing one is a
warning naming it, an error under ``-W``. So a name added to the code by anyone later either appears
in the reference or stops the documentation build. ``reference_coverage_exclude`` names packages
that are not the API (``drake_hybrid.models``: the robot models, installed as a data package, with
the script that generates two of them), left out of the check and of autosummary's recursion (``docs/_templates``, through
``autosummary_context``). ``tests/test_docs.py`` runs ``public_names``
against the pages autosummary generates.
"""

import importlib
import inspect
import pkgutil

from pydrake.common.cpp_template import TemplateBase
from pydrake_system import MANGLED_INSTANTIATION
from sphinx.util import logging

logger = logging.getLogger(__name__)


def _excluded(name, exclude):
    return any(name == prefix or name.startswith(f"{prefix}.") for prefix in exclude)


def package_modules(package_name, exclude=()):
    """The package and every module under it (imported), but those in ``exclude`` (and below them)."""
    package = importlib.import_module(package_name)
    modules = [package]
    for info in pkgutil.walk_packages(package.__path__, f"{package_name}.",
                                      onerror=lambda name: None):
        if not info.name.rsplit(".", 1)[-1].startswith("_") and not _excluded(info.name, exclude):
            modules.append(importlib.import_module(info.name))      # __main__, _private: not the API
    return modules


def public_names(package_name, exclude=()):
    """{dotted name: what documents it} of the package's public classes, functions and templates
    (modules whose name starts with ``_``, such as ``__main__``, are not part of the API).

    A template ``Name_`` is documented by its default instantiation ``Name`` (the same module)."""
    names = {}
    for module in package_modules(package_name, exclude):
        declared = getattr(module, "__all__", None)
        for name, value in vars(module).items():
            if name.startswith("_") or (declared is not None and name not in declared) or MANGLED_INSTANTIATION in name:
                continue
            if isinstance(value, TemplateBase):
                if getattr(value, "_scope", None) is module and inspect.isclass(getattr(module, name[:-1], None)):
                    names[f"{module.__name__}.{name}"] = f"{module.__name__}.{name[:-1]}"
            elif (inspect.isclass(value) or inspect.isfunction(value)) and value.__module__ == module.__name__:
                names[f"{module.__name__}.{name}"] = f"{module.__name__}.{name}"
    return names


def check_coverage(app, env):
    """Warn for every public name without a Python object in the built site."""
    documented = set(env.get_domain("py").objects)
    names = public_names(app.config.reference_coverage_package, app.config.reference_coverage_exclude)
    for name, entry in sorted(names.items()):
        if entry not in documented:
            logger.warning(f"public name {name} has no reference entry ({entry} is not documented)",
                           type="reference", subtype="coverage")


def setup(app):
    app.add_config_value("reference_coverage_package", "", "env")
    app.add_config_value("reference_coverage_exclude", (), "env")
    app.connect("env-check-consistency", check_coverage)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
