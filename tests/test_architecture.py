"""The package's layers (docs/design.md): no import cycles, no imports hidden in functions, modules
of a readable size."""

import ast
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "drake_hybrid"
# Imports allowed inside functions: optional dependencies only (not installed by a plain install).
OPTIONAL = {"playwright"}
MAX_LINES = 400


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


@pytest.mark.parametrize("path", modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_no_imports_inside_functions_except_optional_dependencies(path):
    tree = ast.parse(path.read_text())
    top_level = set(map(id, tree.body))
    hidden = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.Import, ast.ImportFrom)) and id(node) not in top_level:
            names = [node.module] if isinstance(node, ast.ImportFrom) else [a.name for a in node.names]
            if not all(name.split(".")[0] in OPTIONAL for name in names):
                hidden.append(f"line {node.lineno}: {names}")
    assert not hidden, hidden


@pytest.mark.parametrize("path", modules(), ids=lambda p: str(p.relative_to(PACKAGE)))
def test_long_modules_say_why(path):
    """A module over MAX_LINES lines states the reason at its top (a 'Size:' paragraph)."""
    text = path.read_text()
    if text.count("\n") > MAX_LINES:
        docstring = ast.get_docstring(ast.parse(text)) or ""
        assert "Size:" in docstring, f"{path.name} has {text.count(chr(10))} lines and no 'Size:' reason"
