"""The tutorials as the documentation renders them: the executed copies of the test run.

``tests/test_notebooks.py`` executes every notebook of ``tutorials/`` (the suite's own run, with
``running_as_notebook = False``: shorter simulations, the same checks) and saves each executed
notebook in ``docs/_build/executed_tutorials/`` (``DRAKE_HYBRID_EXECUTED_TUTORIALS`` moves it). The
documentation build never executes a notebook: ``stage_tutorials`` copies each tutorial into
``docs/tutorials/`` (generated, git-ignored), taking the executed copy when its code is the committed
notebook's, else the notebook without outputs. So the site shows the outputs without running the
tutorials a second time (CI runs the tests, then builds the site).
"""

import json
import shutil
from pathlib import Path

NOTE_EXECUTED = ("*Rendered with the outputs of the test suite's run of this notebook "
                 "(`tests/test_notebooks.py`, where `running_as_notebook` is False: shorter simulations, the "
                 "same checks). Run it yourself: `jupyter lab tutorials/`.*")
NOTE_CLEAN = ("*Shown without outputs: this build found no executed copy of the notebook (run "
              "`pytest -m notebook` before building the site to render them).*")


def code_sources(notebook):
    """The code cells' sources, which decide whether an executed copy is of this notebook."""
    return ["".join(cell["source"]) if isinstance(cell["source"], list) else cell["source"]
            for cell in notebook["cells"] if cell["cell_type"] == "code"]


def _with_note(notebook, note):
    """The notebook with a note after its title cell (the first Markdown cell)."""
    cells = notebook["cells"]
    title = next((index for index, cell in enumerate(cells) if cell["cell_type"] == "markdown"), -1)
    cells.insert(title + 1, {"cell_type": "markdown", "metadata": {}, "source": note})
    return notebook


def stage_tutorials(source, destination, executed, require_outputs=False):
    """Copy every ``source/NN_*.ipynb`` to ``destination``, with outputs where ``executed`` has a
    current executed copy. ``require_outputs``: a tutorial without one is an error (CI)."""
    source, destination, executed = Path(source), Path(destination), Path(executed)
    if destination.exists():
        shutil.rmtree(destination)
    destination.mkdir(parents=True)
    missing = []
    for path in sorted(source.glob("[0-9][0-9]_*.ipynb")):
        committed = json.loads(path.read_text())
        copy = executed / path.name
        run = json.loads(copy.read_text()) if copy.exists() else None
        if run is not None and code_sources(run) == code_sources(committed):
            notebook = _with_note(run, NOTE_EXECUTED)
        else:
            missing.append(path.name)
            notebook = _with_note(committed, NOTE_CLEAN)
        for index, cell in enumerate(notebook["cells"]):      # nbformat 4.5 wants every cell to have an id
            cell.setdefault("id", f"cell-{index}")
        notebook["nbformat_minor"] = max(notebook.get("nbformat_minor", 0), 5)
        (destination / path.name).write_text(json.dumps(notebook, indent=1))
    if require_outputs and missing:
        raise RuntimeError(f"no current executed copy of {', '.join(missing)} in {executed} (run the notebook tests "
                           "first: pytest -m notebook)")
    return missing
