"""Task-file hooks (tasks/hooks.py): the crank-turning, sphere-polishing and grinding tasks written
as files in models/tasks/ run as the built-in Python tasks (logs agree to 1e-9, same linearized
eigenvalues), and a file can name only registered hooks, never code."""

import importlib.metadata
import textwrap

import cloudpickle
import numpy as np
import pytest

from drake_hybrid.analysis.discrete_linearization import linearize_discrete
from drake_hybrid.analysis.linearization import linearize_continuous
from drake_hybrid.cli import main
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.experiments.simulation import simulate
from drake_hybrid.station.parsing import models_directory
from drake_hybrid.tasks import hooks
from drake_hybrid.tasks.hooks import ENTRY_POINT_GROUP, TaskHook, get_hook, register_hook
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.tasks.task_file import load_task_file

TASKS = models_directory() / "tasks"
LOGS = ("velocity_error", "force_error", "q", "v", "constraint")


def _assert_same_run(file_config, built_in_config, duration):
    """The file's run and the built-in task's agree to 1e-9 in every logged array the law acts on."""
    ours = simulate(file_config.replace(duration=duration))
    theirs = simulate(built_in_config.replace(duration=duration))
    for name in LOGS:
        assert ours.log[name].shape == theirs.log[name].shape, name
        np.testing.assert_allclose(ours.log[name], theirs.log[name], rtol=0, atol=1e-9, err_msg=name)
    assert ours.summary.notes == theirs.summary.notes
    assert ours.summary.events == theirs.summary.events
    return ours


def _assert_same_eigenvalues(ours, theirs, shifted=False):
    """Both loops match their design (``shifted``: with the task's predicted shifts) and their
    eigenvalues agree."""
    for match in ("shifted_match", "match") if shifted else ("match",):
        a, b = getattr(ours, match), getattr(theirs, match)
        assert a.matched == b.matched
        np.testing.assert_allclose(np.sort_complex(a.predicted), np.sort_complex(b.predicted), rtol=1e-9)
        np.testing.assert_allclose(np.sort_complex(a.partner), np.sort_complex(b.partner), rtol=1e-8)
    assert (ours.shifted_match if shifted else ours.match).matched


# -- the built-in tasks as files ------------------------------------------------------------------

def test_crank_file_runs_as_the_built_in_task():
    """0.05 s of the crank (weld constraint, wrist sensor, start at the handle by the hook)."""
    task, config = load_task_file(TASKS / "crank_turning.yaml")
    assert not task.continuous_plant and sorted(task.hooks) == sorted(
        ["add_robot", "add_workpiece", "start_positions", "set_environment_state", "velocity_row_inertia",
         "eigenvalue_shifts", "run_notes"])
    _assert_same_run(config, get_task("crank-turning").default_config(), 0.05)


@pytest.mark.slow
def test_crank_file_with_the_papers_rows_runs_as_the_built_in_task(tmp_path):
    """The paper's (3.3-6) E_p as the file's rows and the crank_paper_rows hook (pseudo-velocity
    source) give the built-in task's ``velocity_rows=paper`` run."""
    text = (TASKS / "crank_turning.yaml").read_text()
    rows = ("  - -(y - crank_center_y) / crank_radius**2, (x - crank_center_x) / crank_radius**2, 0, 0, 0, 0\n")
    assert rows in text and "hooks: [ur5e_with_pad, crank]" in text
    text = text.replace(rows, "  - -(y - crank_center_y), x - crank_center_x, 0, 1, 0, 0\n").replace(
        "hooks: [ur5e_with_pad, crank]", "hooks: [ur5e_with_pad, crank_paper_rows]").replace(
        "name: crank-turning-file", "name: crank-turning-paper-file")
    path = tmp_path / "crank_paper.yaml"
    path.write_text(text)
    _, config = load_task_file(path)
    _assert_same_run(config, get_task("crank-turning").default_config(options={"velocity_rows": "paper"}), 0.05)


@pytest.mark.slow
def test_crank_file_linearizes_as_the_built_in_task():
    """The discrete loop's eigenvalues and the handle-inertia shift (the crank hook's eigenvalue_shifts)."""
    _, config = load_task_file(TASKS / "crank_turning.yaml")
    ours = linearize_discrete(config, settle_time=0.5)
    theirs = linearize_discrete(get_task("crank-turning").default_config(), settle_time=0.5)
    _assert_same_eigenvalues(ours, theirs, shifted=True)
    assert ours.shifts and len(ours.shifts) == len(theirs.shifts)
    for a, b in zip(ours.shifts, theirs.shifts):
        assert a.reason == b.reason and a.predicted == pytest.approx(b.predicted, rel=1e-9)


@pytest.mark.slow
def test_sphere_file_runs_and_linearizes_as_the_built_in_task():
    """The switching (2.2-8) constraint from the hook, the true-velocity rows as expressions."""
    task, config = load_task_file(TASKS / "sphere_polishing.yaml")
    assert task.space.constraint.kinematic_rows == (1, 2)
    built_in = get_task("sphere-polishing").default_config()
    _assert_same_run(config, built_in, 0.03)
    _assert_same_eigenvalues(linearize_continuous(config), linearize_continuous(built_in))


@pytest.mark.slow
def test_grinding_file_runs_and_linearizes_as_the_built_in_task():
    """The rough patch from the hook, impedance/force with friction: 0.3 s and the eigenvalues."""
    _, config = load_task_file(TASKS / "grinding.yaml")
    built_in = get_task("grinding").default_config()
    _assert_same_run(config, built_in, 0.3)
    _assert_same_eigenvalues(linearize_continuous(config), linearize_continuous(built_in))


def test_hooked_task_pickles_as_its_text():
    """Dask workers rebuild the hooks from the names in the file's text."""
    task, _ = load_task_file(TASKS / "grinding.yaml")
    copy = cloudpickle.loads(cloudpickle.dumps(task))
    assert copy is not task and sorted(copy.hooks) == sorted(task.hooks) == ["add_workpiece", "run_events", "run_notes"]


def test_cli_tasks_lists_every_file_and_hook(capsys):
    assert main(["tasks"]) == 0
    out = capsys.readouterr().out
    for name in ("window_washing.yaml", "crank_turning.yaml", "sphere_polishing.yaml", "grinding.yaml",
                 "tilted_pane_4r.yaml", "ur5e_with_pad", "crank_paper_rows", "sphere_paper_constraint",
                 "rough_patch"):
        assert name in out, name


# -- a file names hooks, it never imports code ----------------------------------------------------

GRINDING = (TASKS / "grinding.yaml").read_text()


def _write(tmp_path, old, new, text=GRINDING):
    assert old in text
    path = tmp_path / "task.yaml"
    path.write_text(text.replace(old, new))
    return path


@pytest.mark.parametrize("hook, match", [
    ("os:system", r"hooks\[0\] must be the name of a registered hook .*not a module path.*'os:system'"),
    ("os.system", r"hooks\[0\] must be the name of a registered hook.*'os.system'"),
    ("__import__", r"hooks\[0\] must be the name of a registered hook.*'__import__'"),
    ("../../evil.py", r"hooks\[0\] must be the name"),
    ("Rough_Patch", r"hooks\[0\] must be the name"),
    ("rough_pach", r"hooks\[0\]: unknown hook 'rough_pach'; known hooks: \[.*'rough_patch'"),
])
def test_hook_names_that_are_not_registered_are_refused(tmp_path, hook, match):
    path = _write(tmp_path, "hooks: [rough_patch]", f"hooks: ['{hook}']")
    with pytest.raises(ConfigError, match=match) as error:
        load_task_file(path, register=False)
    assert str(error.value).startswith(str(path)) and "\n" not in str(error.value)


@pytest.mark.parametrize("old, new, match", [
    ("  rough_friction: 0.9       # mu of the pad on the patch\n", "",
     r"hooks\[0\]: hook 'rough_patch' needs the parameters .*missing rough_friction"),
    ("hooks: [rough_patch]", "hooks: [rough_patch, rough_patch]",
     r"hooks\[1\]: hook 'rough_patch' provides add_workpiece, as hook 'rough_patch' does"),
    ("hooks: [rough_patch]", "hooks: [rough_patch, ur5e_with_pad]",
     r"robot: a hook adds the robot; give neither directives nor loader"),
    ("hooks: [rough_patch]", "hooks: [rough_patch, sphere_paper_constraint]", r"needs the parameters"),
])
def test_hooks_that_do_not_fit_the_file_are_refused(tmp_path, old, new, match):
    path = _write(tmp_path, old, new)
    with pytest.raises(ConfigError, match=match):
        load_task_file(path, register=False)


def test_a_hook_constraint_and_rows_are_refused_together(tmp_path):
    path = _write(tmp_path, "hooks: [ur5e_with_pad, sphere_paper_constraint]",
                  "hooks: [ur5e_with_pad, sphere_paper_constraint]\nconstraint: {rows: [x]}",
                  (TASKS / "sphere_polishing.yaml").read_text())
    with pytest.raises(ConfigError, match=r"constraint: a hook gives the constraint; give no rows"):
        load_task_file(path, register=False)


EXTRA = TaskHook("extra_notes", "a test hook from an entry point", lambda spec: _Notes(), ("run_notes",))


class _Notes:
    def run_notes(self, scenario, log, design_time_constant):
        return ["a note from an installed hook"]


def test_installed_packages_add_hooks_through_the_entry_point_group(tmp_path, monkeypatch):
    """A hook of an installed package (entry point group drake_hybrid.task_hooks) is found by its
    name; an entry point that is not a TaskHook of that name is refused."""
    points = [importlib.metadata.EntryPoint("extra_notes", f"{__name__}:EXTRA", ENTRY_POINT_GROUP),
              importlib.metadata.EntryPoint("not_a_hook", f"{__name__}:_Notes", ENTRY_POINT_GROUP)]
    monkeypatch.setattr(hooks.importlib.metadata, "entry_points",
                        lambda group: [p for p in points if p.group == group])
    assert get_hook("extra_notes") is EXTRA and "extra_notes" in hooks.hook_names()
    with pytest.raises(ConfigError, match="not a TaskHook named 'not_a_hook'"):
        get_hook("not_a_hook")
    path = _write(tmp_path, "hooks: [rough_patch]", "hooks: [rough_patch]")
    text = path.read_text().replace("hooks: [rough_patch]", "hooks: [extra_notes]").replace(
        "chart: {kind: planar}", textwrap.dedent("""\
            workpiece:
              shapes:
              - {shape: box, size: [3.0, 0.5, 0.02], X_WG: {translation: [1.0, 0.0, 1.01]}}
            chart: {kind: planar}"""))
    path.write_text(text)
    task, _ = load_task_file(path, register=False)
    assert task.run_notes(None, {}, 0.1) == ["a note from an installed hook"]


def test_hook_definitions_are_checked():
    with pytest.raises(ValueError, match="name must match"):
        TaskHook("pkg:function", "", object, ())
    with pytest.raises(ValueError, match=r"provides \['exec'\], not among"):
        TaskHook("ok", "", object, ("exec",))
    with pytest.raises(TypeError, match="expected a TaskHook"):
        register_hook("rough_patch")
