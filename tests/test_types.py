"""Type hints on the public API (docs/design.md, "Types"): mypy, reading pydrake's and numpy's stubs, passes on
the public modules (``[tool.mypy]`` of pyproject.toml: its ``files``), and every public function and method of
those modules has a hint on each parameter and on its return."""

import glob
import importlib
import importlib.util
import inspect
import subprocess
import sys
import textwrap
import tomllib
import types
from pathlib import Path

import pytest

from drake_hybrid import _EXPORTS

ROOT = Path(__file__).resolve().parent.parent
MYPY = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["mypy"]
# Beyond the front door's modules (drake_hybrid._EXPORTS), the station's and the report's: every module of them.
WHOLE_PACKAGES = ("drake_hybrid/station", "drake_hybrid/report")


def typed_files():
    """The files mypy checks (``[tool.mypy] files``, globs expanded), relative to the repository."""
    return sorted({Path(path).relative_to(ROOT) for pattern in MYPY["files"]
                   for path in glob.glob(str(ROOT / pattern))})


def module_name(path):
    parts = list(path.with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


PUBLIC_MODULES = [module_name(path) for path in typed_files()]


def public_functions(module):
    """[(name, function)] of every public function and method ``module`` defines: its functions and its classes'
    methods, static and class methods and properties whose names have no leading underscore (and ``__init__``,
    a class's constructor), each once. What another module defines (an import, pydrake's scalar conversions of
    a TemplateSystem, a dataclass's generated methods of another module) is not this module's."""
    found, classes = [], set()
    for name, value in sorted(vars(module).items(), key=lambda item: (not item[0].isascii(), item[0])):
        if name.startswith("_"):
            continue
        if inspect.isfunction(value) and value.__module__ == module.__name__:
            found.append((name, value))
        elif inspect.isclass(value) and value.__module__ == module.__name__ and id(value) not in classes:
            classes.add(id(value))           # a TemplateSystem's instantiation is bound under two names
            for attribute, member in vars(value).items():
                if attribute.startswith("_") and attribute != "__init__":
                    continue
                if isinstance(member, (staticmethod, classmethod)):
                    member = member.__func__
                elif isinstance(member, property):
                    member = member.fget
                if inspect.isfunction(member) and member.__module__ == module.__name__:
                    found.append((f"{name}.{attribute}", member))
    return found


def missing_hints(function):
    """What ``function`` leaves without a hint: its parameters (but self, cls, *args and **kwargs) and its
    return ("return")."""
    signature = inspect.signature(function)
    missing = [name for name, parameter in signature.parameters.items()
               if parameter.annotation is inspect.Parameter.empty and name not in ("self", "cls")
               and parameter.kind not in (parameter.VAR_POSITIONAL, parameter.VAR_KEYWORD)]
    if signature.return_annotation is inspect.Signature.empty:
        missing.append("return")
    return missing


def unannotated(module):
    """'name: what is missing' for every public function of ``module`` without complete hints."""
    return [f"{name}: {', '.join(missing)}" for name, function in public_functions(module)
            if (missing := missing_hints(function))]


def test_mypy_checks_the_public_modules():
    """mypy's ``files`` hold every module of the front door (``drake_hybrid._EXPORTS``) and every module of the
    station and the report: a module added to them is typed and checked."""
    checked = set(PUBLIC_MODULES)
    wanted = set(_EXPORTS)
    for package in WHOLE_PACKAGES:
        wanted |= {module_name(path.relative_to(ROOT)) for path in (ROOT / package).glob("*.py")}
    assert wanted <= checked, f"add to [tool.mypy] files in pyproject.toml: {sorted(wanted - checked)}"
    assert MYPY.get("disallow_incomplete_defs") and MYPY.get("warn_unused_ignores")


@pytest.mark.parametrize("name", PUBLIC_MODULES)
def test_every_public_function_is_annotated(name):
    """Every public function and method of a public module has a hint on each parameter and its return."""
    offenders = unannotated(importlib.import_module(name))
    assert not offenders, f"{name}: public functions without type hints:\n  " + "\n  ".join(offenders)


def test_the_check_finds_a_function_without_hints():
    """The check above on a module of its own: it names each unannotated public function and method (its
    missing parameters, its return), and leaves alone the annotated, the private and the imported."""
    module = types.ModuleType("synthetic_module")
    exec(textwrap.dedent('''
        from typing import Optional
        from os.path import join                  # another module's: not checked

        def annotated(a: int, *args, b: Optional[str] = None, **kwargs) -> str:
            return ""

        def bare(a, b: int = 0):
            return a

        def _private(a):
            return a

        class Thing:
            def __init__(self, size):
                self.size = size

            def method(self, x: float) -> float:
                return x

            def unhinted_return(self, x: float):
                return x

            @staticmethod
            def static(a):
                return a

            @classmethod
            def make(cls, a: int) -> "Thing":
                return cls(a)

            @property
            def area(self):
                return self.size

            def _helper(self, a):
                return a
        '''), module.__dict__)
    assert sorted(unannotated(module)) == ["Thing.__init__: size, return", "Thing.area: return",
                                           "Thing.static: a, return", "Thing.unhinted_return: return",
                                           "bare: a, return"]


@pytest.mark.slow        # about 10 s from a cold cache (.mypy_cache; 0.3 s warm) on an idle 2-core machine
def test_mypy_passes():
    """``python -m mypy`` with the project's configuration (pyproject.toml's [tool.mypy]) from the repository's
    root: no error in the public modules (pydrake's stubs read)."""
    if importlib.util.find_spec("mypy") is None:
        pytest.fail("mypy (a test dependency) is not installed")
    result = subprocess.run([sys.executable, "-m", "mypy"], cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, f"mypy found errors:\n{result.stdout[-6000:]}{result.stderr[-2000:]}"
