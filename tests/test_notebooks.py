"""The tutorials run: every notebook in tutorials/ executes top to bottom without a cell error.

Part of the normal suite (``pytest -q``); ``pytest -m notebook`` selects only
these, ``-m "not notebook"`` skips them. The kernel sees
DRAKE_HYBRID_NOTEBOOK_TEST=1, which the notebooks' standard first cell turns
into ``running_as_notebook = False``: shorter simulations, the same physics and
the same checks (the notebooks assert what they show). As RussTedrake/manipulation
does, this keeps the notebooks honest without making the suite slow. Each executed notebook is saved
in docs/_build/executed_tutorials/ (DRAKE_HYBRID_EXECUTED_TUTORIALS moves it): the documentation site
renders those outputs without executing the tutorials a second time.
"""

import os
import re
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient
from nbclient.exceptions import CellExecutionError

ROOT = Path(__file__).resolve().parents[1]
TUTORIALS = ROOT / "tutorials"
NOTEBOOKS = sorted(TUTORIALS.glob("*.ipynb"))
# Where the executed notebooks are saved for the documentation site (docs/tutorial_sources.py reads them).
EXECUTED = Path(os.environ.get("DRAKE_HYBRID_EXECUTED_TUTORIALS", ROOT / "docs" / "_build" / "executed_tutorials"))

STANDARD_FIRST_CELL = """\
# Standard first cell of the drake_hybrid tutorials.
# tests/test_notebooks.py runs every notebook with DRAKE_HYBRID_NOTEBOOK_TEST=1: then
# running_as_notebook is False and the runs are shorter; the physics and the checks are the same.
import os

import matplotlib.pyplot as plt
import numpy as np

running_as_notebook = os.environ.get("DRAKE_HYBRID_NOTEBOOK_TEST") != "1"
np.set_printoptions(precision=4, suppress=True, linewidth=110)
%matplotlib inline"""


def _ids(path):
    return path.stem


def test_the_tutorials_are_there():
    names = [path.name for path in NOTEBOOKS]
    assert names, f"no notebooks in {TUTORIALS}"
    for name in names:
        assert re.fullmatch(r"\d\d_[a-z0-9_]+\.ipynb", name), f"tutorial '{name}' is not named NN_words.ipynb"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=_ids)
def test_notebook_is_committed_clean(path):
    """Outputs cleared, no execution counts, and the standard first cell."""
    notebook = nbformat.read(path, as_version=4)
    nbformat.validate(notebook)
    code_cells = [cell for cell in notebook.cells if cell.cell_type == "code"]
    assert code_cells and code_cells[0] is notebook.cells[0], f"{path.name}: the first cell must be code"
    assert notebook.cells[0].source == STANDARD_FIRST_CELL, f"{path.name}: the first cell is not the standard one"
    for index, cell in enumerate(code_cells):
        assert cell.outputs == [], f"{path.name}: code cell {index} has outputs; clear them before committing"
        assert cell.execution_count is None, f"{path.name}: code cell {index} has an execution count"


def test_readme_and_the_tutorials_page_link_every_tutorial():
    for page in (ROOT / "README.md", ROOT / "docs" / "tutorials.md"):
        text = page.read_text()
        for path in NOTEBOOKS:
            assert f"tutorials/{path.name}" in text, f"{page.relative_to(ROOT)} does not link tutorials/{path.name}"


@pytest.mark.notebook
@pytest.mark.slow         # each notebook runs for up to two minutes: not in the fast loop
@pytest.mark.parametrize("path", NOTEBOOKS, ids=_ids)
def test_notebook_runs(path, tmp_path, monkeypatch):
    """Execute every cell in a fresh kernel (working directory: a temporary folder); any cell
    error fails the test with the cell's traceback."""
    monkeypatch.setenv("DRAKE_HYBRID_NOTEBOOK_TEST", "1")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    notebook = nbformat.read(path, as_version=4)
    client = NotebookClient(notebook, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}})
    try:
        client.execute()
    except CellExecutionError as error:
        pytest.fail(f"{path.name} failed:\n{error}", pytrace=False)
    # The documentation renders this executed copy (docs/tutorial_sources.py) instead of running it again.
    EXECUTED.mkdir(parents=True, exist_ok=True)
    nbformat.write(notebook, EXECUTED / path.name)
