"""The documentation: the front page, the examples, the reference's coverage, the generated pages.

* README.md is a front door (at most about 150 lines) whose links resolve;
* every ``python`` code block of README.md and of the Markdown pages in docs/ runs (one namespace
  per page, top to bottom), except a block preceded by ``<!-- not run: why -->``;
* every public name of the package gets a reference entry (the autosummary pages the site builds
  from the package, generated here as the build generates them; the build itself also fails on a
  missing one, docs/_ext/reference_coverage.py);
* the task-file page documents every field with a meaning and units, and the outputs page every
  key a run writes;
* the documentation's own machinery: the plain-docstring conversion, the port diagrams, the staging
  of the tutorials' executed copies.
"""

import json
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from docutils.core import publish_doctree

from drake_hybrid.analysis.design import designed_eigenvalues_by_row, predicted_eigenvalues
from drake_hybrid.control.gains import HybridGains
from drake_hybrid.experiments.simulation import simulate
from drake_hybrid.station.loggers import LOG_KEYS
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.tasks.schema_doc import schema_rows
from drake_hybrid.tasks.task_file_schema import TaskFile

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
sys.path.insert(0, str(DOCS / "_ext"))
sys.path.insert(0, str(DOCS))

import plain_docstrings  # noqa: E402  (docs/_ext, on the path above)
import pydrake_system  # noqa: E402
import reference_coverage  # noqa: E402
import tutorial_sources  # noqa: E402

GENERATED = ("_build", "reference/generated", "tutorials")
STAGED_TUTORIALS = DOCS / "tutorials"             # tutorials/*.ipynb as the site renders them
PAGES = sorted(path for path in DOCS.rglob("*.md")
               if not any(str(path.relative_to(DOCS)).startswith(folder) for folder in GENERATED))
CODE_BLOCK = re.compile(r"(<!-- not run: [^>]+-->\s*)?^```python\n(.*?)^```", re.S | re.M)


def _code_blocks(path):
    return [code for skip, code in CODE_BLOCK.findall(path.read_text()) if not skip]


def _runs_a_simulation(path):
    return any(word in code for code in _code_blocks(path) for word in ("simulate(", "AdvanceTo("))


def _page_params():
    params = []
    for path in [ROOT / "README.md", *PAGES]:
        if _code_blocks(path):
            marks = [pytest.mark.slow] if _runs_a_simulation(path) else []
            params.append(pytest.param(path, marks=marks, id=str(path.relative_to(ROOT))))
    return params


# ------------------------------------------------------------------------------------------------
# The front page
# ------------------------------------------------------------------------------------------------

def test_the_readme_is_a_front_door():
    text = (ROOT / "README.md").read_text()
    assert text.count("\n") <= 150, f"README.md has {text.count(chr(10))} lines; the front door is at most ~150"
    for heading in ("## Quick start", "## What it does", "## Documentation"):
        assert heading in text
    block = re.search(r"## Quick start.*?```bash\n(.*?)```", text, re.S).group(1)
    assert block.splitlines() == ["pip install . && drake-hybrid simulate window-washing",
                                  'pip install ".[test]" && pytest -q -n auto --dist loadscope']


def _slug(heading):
    """MyST's anchor of a heading (myst_heading_anchors): lower case, punctuation dropped, spaces to '-'."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(path):
    text = path.read_text()
    headings = {_slug(match) for match in re.findall(r"^#+ +(.*)$", text, re.M)}
    labels = set(re.findall(r"^\(([\w-]+)\)=$", text, re.M))
    return headings | labels


@pytest.mark.parametrize("path", [ROOT / "README.md", *PAGES], ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(path):
    """Every relative link and image of a page points at a file of the checkout, and a '#anchor' at a
    heading or label of the page it names (no network: external links are not fetched)."""
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
    targets = re.findall(r"\]\(([^)\s]+)\)", text) + re.findall(r'src="([^"]+)"', text)
    broken = []
    for target in targets:
        if re.match(r"[a-z]+:", target):
            continue
        file, _, anchor = target.partition("#")
        resolved = (path.parent / file).resolve() if file else path
        if STAGED_TUTORIALS in resolved.parents:       # the site stages tutorials/ there (docs/conf.py)
            resolved = ROOT / "tutorials" / resolved.relative_to(STAGED_TUTORIALS)
        if not resolved.exists():
            broken.append(target)
        elif anchor and resolved.suffix == ".md" and anchor not in _anchors(resolved):
            broken.append(target)
    assert not broken, f"{path.relative_to(ROOT)}: links that do not resolve: {broken}"


@pytest.mark.parametrize("path", _page_params())
def test_the_code_examples_run(path, tmp_path, monkeypatch):
    """A page's python blocks, in order, in one namespace (the working directory a temporary one)."""
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "__docs_example__"}
    for index, code in enumerate(_code_blocks(path)):
        exec(compile(code, f"{path.name}, python block {index + 1}", "exec"), namespace)


def test_the_synopses_and_pages_are_the_sites():
    """The README's pages are in the site's tables of contents (a page not in one is a build warning)."""
    index = (DOCS / "index.md").read_text()
    for page in ("getting_started", "idea", "tutorials", "howto/own_arm", "howto/own_diagram", "howto/task_file",
                 "howto/path", "howto/sweep_cluster", "howto/real_arm", "reference/api", "task_files",
                 "reference/outputs", "reference/command_line", "results", "theory"):
        assert f"\n{page}\n" in index, page


# ------------------------------------------------------------------------------------------------
# The reference
# ------------------------------------------------------------------------------------------------

@pytest.mark.slow          # imports every module and writes a page per module (about 15 s of CPU)
def test_every_public_name_has_a_reference_entry(tmp_path):
    """Generate the API pages as the site's build does (autosummary recursive over the package, with
    docs/_templates; Sphinx's own sphinx-autogen) and find every public name on its module's page."""
    subprocess.run([sys.executable, "-m", "sphinx.ext.autosummary.generate", "-o", str(tmp_path), "-t",
                    str(DOCS / "_templates"), str(DOCS / "reference" / "api.rst")],
                   check=True, capture_output=True, text=True, cwd=ROOT)
    documented = set()
    for page in tmp_path.glob("*.rst"):
        for name in re.findall(r"^\.\. auto(?:class|function|exception):: (\S+)$", page.read_text(), re.M):
            documented.add(f"{page.stem}.{name}")
    names = reference_coverage.public_names("drake_hybrid", exclude=("drake_hybrid.models",))
    assert len(names) > 300
    missing = sorted(name for name, entry in names.items() if entry not in documented)
    assert not missing, f"public names without a reference entry: {missing}"


def test_every_task_file_field_has_a_meaning_and_units():
    """docs/task_files.md: each field's meaning, and a unit for every number (or what it is a fraction,
    factor, count or probability of)."""
    unit = re.compile(r"(\b(m|s|N|Pa|Hz|rad|kg|deg)\b|1/s|m/s|rad/s|N m|dimensionless|fraction|factor|units|"
                      r"probability|samples|\bmu\b)")
    for name, kind, _, meaning in schema_rows(TaskFile):
        assert meaning, f"{name} has no meaning (a comment on its line or an entry in its class's docstring)"
        if kind in ("float", "List[float]"):
            assert unit.search(meaning), f"{name}: no unit in '{meaning}'"


@pytest.mark.slow          # a short simulation with faults and a supervisor
def test_the_outputs_page_documents_every_key_a_run_writes():
    config = get_task("window-washing").default_config(duration=0.2)
    config.sensor_faults.noise_std = 0.01             # true_wrench is logged
    config.supervision.enabled = True                 # contact_phase is logged
    result = simulate(config)
    page = (DOCS / "reference" / "outputs.md").read_text()
    documented = set(re.findall(r"`([a-z_0-9]+)`", page))
    summary = result.summary.as_dict()                # summary.json's dict
    keys = set(result.log) | set(summary) | set(summary["gains"]) | set(summary["command_scales"])
    for rows in (summary["velocity_rows"], summary["force_rows"]):
        keys |= set(rows[0])
    assert keys - documented == set()


def test_the_own_diagram_page_documents_every_log_key():
    """docs/howto/own_diagram.md's table of the log: every key of station.loggers.LOG_KEYS."""
    page = (DOCS / "howto" / "own_diagram.md").read_text()
    documented = set(re.findall(r"`([a-z_]+)`", page.split("## The log", 1)[1].split("\n## ", 1)[0]))
    assert set(LOG_KEYS) - documented == set()


# ------------------------------------------------------------------------------------------------
# simulate's eigenvalues by row
# ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("mode", ["velocity-force", "position-force", "impedance-force"])
def test_designed_eigenvalues_by_row_are_the_loops_eigenvalues(mode):
    gains = HybridGains(velocity=[10.0, 8.0], position=[21.0, 12.0], force_proportional=[0.5, 1.0],
                        force_integral=[15.0, 20.0], impedance_mass=[2.0, 1.0]).matrices(2, 2, mode)
    velocity, force, null_space = designed_eigenvalues_by_row(gains, mode, kinematic_rows=[1], redundancy=1)
    predicted = predicted_eigenvalues(gains, mode, [1], redundancy=1)
    assert np.allclose(np.sort_complex(np.concatenate(velocity + [null_space])), predicted.velocity)
    assert np.allclose(np.sort_complex(np.concatenate(force)), predicted.force)
    assert np.allclose(force[0], [-15.0 / 1.5]) and np.allclose(np.sort_complex(force[1]), [-30.0, -15.0])
    assert np.allclose(velocity[1], [-8.0] if mode == "velocity-force" else np.sort_complex(np.roots([1, 8, 12])))


def test_designed_eigenvalues_by_row_refuse_coupled_gains():
    gains = HybridGains(velocity=[10.0, 1.0, 1.0, 8.0]).matrices(2, 1, "velocity-force")
    assert designed_eigenvalues_by_row(gains, "velocity-force") is None


# ------------------------------------------------------------------------------------------------
# The documentation's machinery
# ------------------------------------------------------------------------------------------------

def _docutils_warnings(lines):
    import io
    stream = io.StringIO()
    publish_doctree("\n".join(lines), settings_overrides={"warning_stream": stream, "report_level": 2})
    return stream.getvalue()


@pytest.mark.parametrize("docstring", [
    ["A gain.", "", "velocity: K_v (1/s), the velocity rows' gain: in velocity-force mode each",
     "    row decays as e^(-K_v t).", "position: K_p (1/s^2).", "", "After |x| the end."],
    ["Sums over |F_i| and", "  continues here, indented", "back again."],
    ["Example::", "", "    a = |b|", "      indented more", "", "text |x|"],
    ["* a bullet", "  its continuation", "* another", "then a paragraph"],
    ["=====  =====", "a      b", "=====  =====", "|x|    y", "=====  ====="],
])
def test_plain_docstrings_become_warning_free_rest(docstring):
    assert _docutils_warnings(docstring) != "" or docstring[0].startswith("=")   # the raw text needs the help
    assert _docutils_warnings(plain_docstrings.plain_to_rst(docstring)) == ""


def test_plain_docstrings_keep_literal_blocks_as_written():
    lines = ["Law::", "", "    a_p = r-ddot - K_v |e|", "        - K_p e", "", "Done."]
    assert plain_docstrings.plain_to_rst(lines)[2:4] == lines[2:4]


def test_the_port_diagram_parses_drakes_yaml_and_refuses_other_text():
    name, inputs, outputs = pydrake_system.parse_system_yaml(
        "name: Sensor\ninput_ports:\n- contact_results\n- body_poses (only with x)\noutput_ports:\n- wrench\n")
    assert (name, inputs, outputs) == ("Sensor", [("contact_results", ""), ("body_poses", "only with x")],
                                       [("wrench", "")])
    html = pydrake_system.system_html(name, inputs, outputs)
    assert html.index("contact_results") < html.index("Sensor") < html.index("wrench")
    for bad in ("input_ports: [a]", "name: S\nports: [a]", "name: S\ninput_ports:\n- a (note: with a colon)"):
        with pytest.raises(ValueError):
            pydrake_system.parse_system_yaml(bad)


def _port_blocks(text):
    """The YAML of every ``.. pydrake_system::`` block of a source file: the lines indented below the
    directive, up to the first line that is not."""
    lines, blocks = text.splitlines(), []
    for index, line in enumerate(lines):
        if line.strip() == ".. pydrake_system::":
            indent, body = len(line) - len(line.lstrip()), []
            for following in lines[index + 1:]:
                if following.strip() and len(following) - len(following.lstrip()) <= indent:
                    break
                body.append(following)
            blocks.append("\n".join(body))
    return blocks


def test_the_package_docstrings_port_blocks_parse():
    """Every pydrake_system block in the package is Drake's YAML (a colon inside a port's note makes it
    a mapping: the block would not draw)."""
    blocks = [block for path in (ROOT / "drake_hybrid").rglob("*.py") for block in _port_blocks(path.read_text())]
    assert len(blocks) >= 15
    for block in blocks:
        pydrake_system.parse_system_yaml(textwrap.dedent(block))


def test_the_site_renders_current_executed_tutorials_only(tmp_path):
    source, executed, staged = tmp_path / "tutorials", tmp_path / "executed", tmp_path / "staged"
    source.mkdir(), executed.mkdir()
    notebook = {"cells": [{"cell_type": "markdown", "metadata": {}, "source": "# 1. Title"},
                          {"cell_type": "code", "metadata": {}, "source": "x = 1", "outputs": [],
                           "execution_count": None}], "metadata": {}, "nbformat": 4, "nbformat_minor": 5}
    (source / "01_a.ipynb").write_text(json.dumps(notebook))
    (source / "02_b.ipynb").write_text(json.dumps(notebook))
    run = json.loads(json.dumps(notebook))
    run["cells"][1]["outputs"] = [{"output_type": "stream", "name": "stdout", "text": "ran"}]
    (executed / "01_a.ipynb").write_text(json.dumps(run))
    stale = json.loads(json.dumps(run))
    stale["cells"][1]["source"] = "x = 2"                   # an older version of the notebook: not shown
    (executed / "02_b.ipynb").write_text(json.dumps(stale))
    assert tutorial_sources.stage_tutorials(source, staged, executed) == ["02_b.ipynb"]
    shown = json.loads((staged / "01_a.ipynb").read_text())
    assert shown["cells"][2]["outputs"][0]["text"] == "ran" and "test suite" in shown["cells"][1]["source"]
    assert json.loads((staged / "02_b.ipynb").read_text())["cells"][2]["outputs"] == []
    with pytest.raises(RuntimeError, match="02_b.ipynb"):
        tutorial_sources.stage_tutorials(source, staged, executed, require_outputs=True)
