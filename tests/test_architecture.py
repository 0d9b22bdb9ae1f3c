"""The package's layers (docs/design.md): no import cycles, no imports hidden in functions, modules
of a readable size; and the theory it cites lives in the repository (docs/theory.md)."""

import ast
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "drake_hybrid"
# Imports allowed inside functions: optional dependencies (not installed by a plain install) ...
OPTIONAL = {"playwright", "numba"}   # numba: the fast law falls back to the generic one without it
# ... heavy modules that only some commands use, imported where they are first needed so that the others
# do not load them (issue 31: a first run in seconds): Dask for sweeps, scipy.signal for the impedance's
# driven response (about a second each) ...
LOADED_WHERE_USED = {"dask", "distributed", "scipy.signal"}
# ... and the command line, whose commands each import the package's modules they use when they run
# (drake_hybrid/cli.py's docstring), so that every --help answers at once.
IMPORTS_PER_COMMAND = {"cli.py"}
MAX_LINES = 500
THEORY = ROOT / "docs" / "theory.md"
# Files that may cite the theory: source, docs, notebooks, configuration.
CITING_SUFFIXES = {".py", ".md", ".ipynb", ".yaml", ".yml", ".toml"}
# Citations of the specification outside the repository (written so that this file does not match).
OUTSIDE_REFERENCES = re.compile(r"\.\./shared|\bspec(?:ification)?\s+(?:section|§)|\bcorrected\s+spec(?:ification)?\b",
                                re.IGNORECASE)
THEORY_REFERENCE = re.compile(r"theory\.md\s*§\s*(\d+)")


def modules():
    return sorted(PACKAGE.rglob("*.py"))


def test_the_layers_contract_holds():
    """import-linter's layers contract (pyproject.toml): cli > viz > experiments > analysis >
    scenario > systems > control > core; a layer imports only layers below it (so no cycles)."""
    lint_imports = shutil.which("lint-imports")
    if lint_imports is None:
        pytest.fail("lint-imports (import-linter, a test dependency) is not installed")
    result = subprocess.run([lint_imports], cwd=ROOT, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout[-3000:]


def _loaded_where_used(name):
    return name.split(".")[0] in OPTIONAL or any(name == heavy or name.startswith(heavy + ".")
                                                 for heavy in LOADED_WHERE_USED)


@pytest.mark.parametrize("path", modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_imports_inside_functions_except_optional_dependencies(path):
    """Imports at the top of the module, except optional dependencies, the few heavy modules only some
    commands use (``LOADED_WHERE_USED``) and the command line's per-command imports."""
    if str(path.relative_to(PACKAGE)) in IMPORTS_PER_COMMAND:
        return
    tree = ast.parse(path.read_text())
    top_level = set(map(id, tree.body))
    hidden = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.Import, ast.ImportFrom)) and id(node) not in top_level:
            names = [node.module] if isinstance(node, ast.ImportFrom) else [a.name for a in node.names]
            if not all(_loaded_where_used(name) for name in names):
                hidden.append(f"line {node.lineno}: {names}")
    assert not hidden, hidden


def test_heavy_modules_load_only_where_used():
    """The heavy modules of ``LOADED_WHERE_USED`` are imported at no module's top (else the rule above
    would buy nothing), and the command line's module imports none of the package's heavy layers at its
    top: importing drake_hybrid.cli loads neither Drake, numba, matplotlib nor Dask."""
    for path in modules():
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                names = [node.module] if isinstance(node, ast.ImportFrom) else [a.name for a in node.names]
                loaded = [name for name in names if name.split(".")[0] not in OPTIONAL and _loaded_where_used(name)]
                assert not loaded, f"{path.relative_to(PACKAGE)} imports {loaded} at its top"
    code = ("import sys, drake_hybrid.cli; print(sorted(m for m in ('pydrake', 'numba', 'matplotlib', 'dask', "
            "'distributed', 'scipy.signal', 'sympy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


@pytest.mark.parametrize("path", modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_a_module_over_the_limit_says_why_in_one_sentence(path):
    """A module is as long as its one concern needs; one over MAX_LINES says why in one sentence, in a comment
    under its docstring (``# Longer than 500 lines because ...``; a comment: the API reference renders
    docstrings, and a maintainers' note is not for its readers)."""
    text = path.read_text()
    if text.count("\n") <= MAX_LINES:
        return
    comment = re.search(r"^# Longer than %d lines because (.+?)(?=^[^#]|\Z)" % MAX_LINES, text, re.M | re.S)
    assert comment, f"{path.name} has {text.count(chr(10))} lines and no '# Longer than {MAX_LINES} lines because' comment"
    sentence = " ".join(line.lstrip("# ").strip() for line in comment.group(1).splitlines())
    assert sentence.endswith(".") and sentence.count(". ") == 0, f"{path.name}: say why in one sentence: {sentence}"


def test_no_module_docstring_holds_a_maintainers_size_note():
    """The old waiver ('Size: ...' in a module's docstring) rendered in the API reference: it is gone."""
    offenders = [str(path.relative_to(PACKAGE)) for path in modules()
                 if "Size:" in (ast.get_docstring(ast.parse(path.read_text())) or "")]
    assert not offenders, offenders


def repository_files():
    """Source, docs, notebooks and configuration of the repository (not .git, caches, build output)."""
    skipped = {"__pycache__", "build", "dist", "node_modules", "venv"}
    for path in sorted(ROOT.rglob("*")):
        parts = path.relative_to(ROOT).parts
        if any(part.startswith(".") or part.endswith(".egg-info") or part in skipped for part in parts[:-1]):
            continue
        if path.suffix in CITING_SUFFIXES and path.is_file():
            yield path


def theory_sections():
    """The numbers N of the '## N. Title' sections of docs/theory.md."""
    return {int(match) for match in re.findall(r"^## (\d+)\. ", THEORY.read_text(encoding="utf-8"), re.MULTILINE)}


def test_the_theory_is_in_the_repository():
    """No file cites the specification kept outside the repository (its directory beside the repository,
    its section numbers): the theory is docs/theory.md, cited as 'docs/theory.md §N'."""
    assert THEORY.is_file(), "docs/theory.md is missing"
    offending = []
    for path in repository_files():
        for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            if OUTSIDE_REFERENCES.search(line):
                offending.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()[:100]}")
    assert not offending, "cite docs/theory.md §N instead:\n" + "\n".join(offending)


def test_theory_citations_name_existing_sections():
    """Every 'theory.md §N' in the repository names a section '## N.' of docs/theory.md."""
    sections = theory_sections()
    assert sections >= set(range(13)), f"docs/theory.md sections: {sorted(sections)}"
    cited, dangling = 0, []
    for path in repository_files():
        for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            for match in THEORY_REFERENCE.finditer(line):
                cited += 1
                if int(match.group(1)) not in sections:
                    dangling.append(f"{path.relative_to(ROOT)}:{number}: §{match.group(1)}")
    assert cited > 0, "no file cites docs/theory.md"
    assert not dangling, f"citations of sections docs/theory.md does not have: {dangling}"


def _defined_names():
    """{module: the names its top level defines (functions, classes, assignments)} over the package."""
    defined = {}
    for path in modules():
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        parts = parts[:-1] if parts[-1] == "__init__" else parts
        names = set()
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                names.add(node.name)
            elif isinstance(node, (ast.Assign, ast.AnnAssign)):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                names |= {name.id for target in targets for name in ast.walk(target) if isinstance(name, ast.Name)}
        defined[".".join(parts)] = names
    return defined


def _python_sources():
    """(file, a piece of Python) of the package, the tests, the benchmarks, the docs' scripts and examples
    and the tutorials' code cells."""
    for folder, pattern in (("drake_hybrid", "**/*.py"), ("tests", "*.py"), ("benchmarks", "*.py"), ("docs", "*.py")):
        for path in sorted((ROOT / folder).glob(pattern)):
            yield path, path.read_text()
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        if "_build" not in path.parts:
            for block in re.findall(r"^```python\n(.*?)^```", path.read_text(), re.S | re.M):
                yield path, block
    for path in sorted((ROOT / "tutorials").glob("*.ipynb")):
        for cell in json.loads(path.read_text())["cells"]:
            if cell["cell_type"] == "code":
                yield path, "\n".join(line for line in "".join(cell["source"]).splitlines()
                                      if not line.lstrip().startswith(("%", "!")))


def test_every_name_is_imported_from_its_one_home():
    """One home per name: ``from drake_hybrid.M import name`` names a module M that defines ``name`` (or a
    submodule of it), everywhere a user or the package imports it; the front door ``drake_hybrid`` itself
    maps each of its names to its home (tests/test_one_composition.py)."""
    defined = _defined_names()
    elsewhere = []
    for path, source in _python_sources():
        try:
            tree = ast.parse(source)
        except SyntaxError:
            continue
        for node in ast.walk(tree):
            if not (isinstance(node, ast.ImportFrom) and node.level == 0 and node.module
                    and node.module.startswith("drake_hybrid.")):
                continue
            for alias in node.names:
                if f"{node.module}.{alias.name}" not in defined and alias.name not in defined.get(node.module, ()):
                    elsewhere.append(f"{path.relative_to(ROOT)}: from {node.module} import {alias.name}")
    assert not elsewhere, "\n".join(sorted(set(elsewhere)))
