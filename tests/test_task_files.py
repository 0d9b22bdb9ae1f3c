"""A whole task in one YAML file (tasks/task_file.py): the window-washing task written as
models/tasks/window_washing.yaml runs as the built-in one, and a bad file is refused naming its field."""

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import bounded_work
import cloudpickle
import numpy as np
import pytest

from pydrake.geometry import Box
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.plant import MultibodyPlant

from drake_hybrid import ConstraintSpace, GivenVelocityProjection, PoseChart, surface_constraint
from drake_hybrid.analysis.linearization import linearize_continuous
from drake_hybrid.cli import main
from drake_hybrid.core.errors import ConfigError
from drake_hybrid.experiments.simulation import simulate
from drake_hybrid.experiments.sweep import run_sweep
from drake_hybrid.experiments.sweep_results import read_results
from drake_hybrid.experiments.sweep_spec import load_spec
from drake_hybrid.station.parsing import installed_model_packages, models_directory
from drake_hybrid.station.workpieces import add_rigid_workpiece
from drake_hybrid.tasks.config import dump_config
from drake_hybrid.tasks.custom import CustomTask
from drake_hybrid.tasks.registry import get_task, register_task
from drake_hybrid.tasks.robots import load_arm
from drake_hybrid.tasks.schema_doc import schema_markdown
from drake_hybrid.tasks.task_file import load_task_file
from drake_hybrid.tasks.task_file_schema import read_task_file

WINDOW_FILE = models_directory() / "tasks" / "window_washing.yaml"

REPOSITORY = Path(__file__).resolve().parents[1]     # the checkout (README, docs), not the installed package


@pytest.fixture(scope="module")
def window_file_task():
    return load_task_file(WINDOW_FILE)


def test_window_file_loads_as_the_built_in_config(window_file_task):
    task, config = window_file_task
    built_in = get_task("window-washing").default_config()
    assert config.task == task.name == "window-washing-file"
    assert config.gains == built_in.gains and config.mode == built_in.mode
    assert config.desired_velocity == built_in.desired_velocity and config.desired_force == built_in.desired_force
    np.testing.assert_allclose(config.start.configuration, [0.9, 0.98, np.pi / 2])
    assert config.start.force_integral == built_in.start.force_integral


def test_window_file_runs_as_the_built_in_task(window_file_task):
    """Same velocity and force errors (the logs agree to 1e-9) over 0.3 s of the discrete run."""
    _, config = window_file_task
    built_in = get_task("window-washing").default_config(duration=0.3)
    file_run = simulate(config.replace(duration=0.3))
    built_in_run = simulate(built_in)
    for name in ("velocity_error", "force_error", "q", "constraint"):
        np.testing.assert_allclose(file_run.log[name], built_in_run.log[name], rtol=0, atol=1e-9, err_msg=name)
    for rows in ("velocity_rows", "force_rows"):
        for ours, theirs in zip(getattr(file_run.summary, rows), getattr(built_in_run.summary, rows)):
            assert ours.final_error == pytest.approx(theirs.final_error, abs=1e-9)


def test_window_file_linearizes_to_the_designed_eigenvalues(window_file_task):
    _, config = window_file_task
    ours = linearize_continuous(config)
    theirs = linearize_continuous(get_task("window-washing").default_config())
    assert ours.match.matched
    np.testing.assert_allclose(np.sort_complex(ours.match.predicted), [-10, -10, -8])
    np.testing.assert_allclose(np.sort_complex(ours.match.partner), np.sort_complex(theirs.match.partner),
                               rtol=1e-6)


def _write(tmp_path, replace=None, append=""):
    text = WINDOW_FILE.read_text()
    for old, new in (replace or {}).items():
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "task.yaml"
    path.write_text(text + textwrap.dedent(append))
    return path


@pytest.mark.parametrize("replace, match", [
    ({'rows: ["y - (window_height - pad_radius)"]': 'rows: ["__import__(\'os\')"]'},
     r"constraint.rows\[0\]: names starting with '_' are not allowed: '__import__'"),
    ({'rows: ["y - (window_height - pad_radius)"]': 'rows: ["y.real"]'},
     r"constraint.rows\[0\]: not allowed in an expression \(attribute access\): 'y.real'"),
    ({'rows: ["y - (window_height - pad_radius)"]': 'rows: ["z - 1"]'}, r"constraint.rows\[0\]: unknown name"),
    ({'"1, 0, 0", "0, 0, 1"': '"1, 0", "0, 0, 1"'}, r"velocity_projection.rows\[0\]: expected 3 comma-separated"),
    ({'"pi/2"]': '"pi/2", "1"]'}, r"start.configuration must have 3 entries"),
    ({"kind: planar}": "kind: cylindrical}"}, r"chart.kind must be one of"),
    ({"arm: planar_3r": "arm: planar_4r"}, r"robot.arm must name a model instance"),
    ({"flange_frame: link3": "flange_frame: link9"}, r"robot.tool.flange_frame: .*link9"),
    ({"window_height: 1.0 ": "window_height: one "}, r"parameters.window_height: expected a number"),
    ({"name: window-washing-file": "name: window-washing"}, r"name: 'window-washing' is a built-in task"),
    ({"gains: {velocity": "gains: {speed"}, r"config.gains: unknown field 'speed'"),
])
def test_bad_files_are_refused_naming_the_field(tmp_path, replace, match):
    path = _write(tmp_path, replace)
    with pytest.raises(ConfigError, match=match) as error:
        task, config = load_task_file(path)
        # Frame and instance names are checked when the robot is added to a plant.
        task.add_robot(MultibodyPlant(0.0), config)
    assert str(error.value).startswith(str(path)) and "\n" not in str(error.value)


def test_kernel_projection_is_the_default(tmp_path):
    """Without velocity_projection rows, E_p is a basis of ker E_f at the start: E E^T = I for the window."""
    path = _write(tmp_path, {'rows: ["1, 0, 0", "0, 0, 1"]': "rows: []"}, "")
    task, config = load_task_file(path, register=False)
    E_p = task.space.velocity_projection.matrix(np.asarray(config.start.configuration))
    np.testing.assert_allclose(np.abs(E_p @ np.array([0.0, 1.0, 0.0])), 0, atol=1e-12)
    np.testing.assert_allclose(E_p @ E_p.T, np.eye(2), atol=1e-12)


def test_cli_runs_a_task_file(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["simulate", str(WINDOW_FILE), "--duration", "0.2", "--out", str(out), "--no-progress", "--no-plots",
                 "--quiet"]) == 0
    assert (out / "summary.json").exists()
    assert "window-washing-file" in capsys.readouterr().out
    assert main(["analyze", str(WINDOW_FILE), "--quiet"]) == 0
    assert "matched" in capsys.readouterr().out


def test_cli_refuses_a_bad_task_file_in_one_line(tmp_path, capsys):
    path = _write(tmp_path, {'rows: ["y - (window_height - pad_radius)"]': 'rows: ["(lambda: 0)()"]'})
    assert main(["analyze", str(path)]) == 2
    error = capsys.readouterr().err.strip()
    assert "\n" not in error and "constraint.rows[0]" in error and "lambda" in error
    assert main(["simulate", str(tmp_path / "missing.yaml")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_workpiece_from_the_library_shapes(tmp_path):
    """The pane as a library box (custom.add_rigid_workpiece) instead of window.sdf: the same
    linearized closed loop (the same rigid hydroelastic box, 3 m x 0.5 m x 20 mm, its lower face at 1 m)."""
    path = _write(tmp_path, {
        "  directives:\n  - add_model: {name: window,": "  shapes:\n  - {shape: box, size: [3.0, 0.5, 0.02], "
        "X_WG: {translation: [1.0, 0.0, 1.01]}}\n  #",
        "  - add_weld: {parent: world, child: window::pane": "  #"}, "")
    task, config = load_task_file(path, register=False)
    assert task.spec.workpiece.shapes[0].shape == "box" and not task.spec.workpiece.directives
    task.name = config.task = "window-washing-box"
    register_task(task)
    ours = linearize_continuous(config)
    theirs = linearize_continuous(get_task("window-washing").default_config())
    np.testing.assert_allclose(np.sort_complex(ours.match.partner), np.sort_complex(theirs.match.partner),
                               rtol=1e-6)


def test_cli_refuses_options_for_a_task_file(capsys):
    assert main(["analyze", str(WINDOW_FILE), "--option", "joints=4"]) == 2
    assert "a task file has no task options" in capsys.readouterr().err


def test_cli_tasks_lists_the_task_files(capsys):
    assert main(["tasks"]) == 0
    out = capsys.readouterr().out
    assert "window_washing.yaml" in out and "from a task file" in out


def test_robot_from_the_arm_loader(tmp_path):
    """robot.loader (tasks.robots.load_arm) instead of directives: the planar 3R arm with the pad
    tool at its tip along +x, so the pad centre is 0.05 m beyond the tip (end_effector_point); the
    linearized closed loop has the designed eigenvalues."""
    robot = textwrap.dedent(f"""\
        robot:
          loader: {{path: {models_directory() / "planar_3r.sdf"}, flange: link3, tool_frame: tip, tool_axis: "+x",
                   collision: drop}}
          end_effector_frame: tip
          end_effector_point: [0.05, 0.0, 0.0]
          only_pad_contact: true
        workpiece:""")
    text = WINDOW_FILE.read_text()
    start, end = text.index("robot:\n"), text.index("workpiece:")
    path = tmp_path / "loader.yaml"
    path.write_text((text[:start] + robot + text[end + len("workpiece:"):]).replace(
        "name: window-washing-file", "name: window-washing-loader"))
    task, config = load_task_file(path)
    result = linearize_continuous(config)
    assert result.match.matched, result.match.as_dict()
    np.testing.assert_allclose(np.sort_complex(result.match.predicted), [-10, -10, -8])


def test_start_as_a_pose_of_the_end_effector_frame(tmp_path):
    """start.pose (of frame E = tip) gives the same chart start as start.configuration."""
    path = _write(tmp_path, {'configuration: ["0.9", "window_height - pad_radius", "pi/2"]':
                             "pose: [0.9, 0.0, 0.98, 0.0, -1.5707963267948966, 0.0]"})
    task, config = load_task_file(path, register=False)
    np.testing.assert_allclose(config.start.configuration, [0.9, 0.98, np.pi / 2], atol=1e-12)


def test_task_file_pickles_as_its_text(window_file_task):
    """Shipped to Dask workers by its text: the copy rebuilt from it has the same constraint space."""
    task, config = window_file_task
    copy = cloudpickle.loads(cloudpickle.dumps(task))
    assert copy is not task and copy.name == task.name and copy.text == task.text
    x, nu = np.asarray(config.start.configuration), np.array([0.1, 0.02, -0.3])
    ours, theirs = copy.space.evaluate(x, nu), task.space.evaluate(x, nu)
    np.testing.assert_array_equal(ours.matrix, theirs.matrix)
    assert dump_config(copy.default_config()) == dump_config(task.default_config())


SWEEP = """
base:
  duration: 0.15
parameters:
  gains.force_proportional: {values: [0.5, 2.0]}
  control_period: {values: [0.001, 0.004]}
"""
TIMING_COLUMNS = {"wall_time", "simulation_wall_time", "linearization_wall_time", "cpu_time", "worker",
                  "discrete_step_check"}  # its text quotes rates near the resolution; stable_discrete is compared


# What central differences (step 1e-5) of the one-period map resolve of a rate near zero: a
# multiplier mu near 1 to about 1e-7, so log(mu) / h to about 1e-4 1/s at h = 1 ms.
DISCRETE_RATE_RESOLUTION = 1.0e-4


def _assert_same_rows(ours, theirs, marginal_noise=0.0):
    """The same verdicts, and the numbers to 1e-6 relative (the file's start comes from numeric
    inverse kinematics, the built-in task's from the closed form: equal to ~1e-11). With
    ``marginal_noise`` > 0, the marginal modes' real parts (zero in theory; what central differences
    of the one-period map leave) are only checked to be below it in both, or, in the discrete map, to
    be the SAP map's kink that the step check did not confirm. A discrete real part (the worst
    regulated partner's and the marginal modes') is compared to the map's resolution
    (DISCRETE_RATE_RESOLUTION): on the UR10 plate the worst regulated partner sits at -1.2e-4 1/s,
    and two starts 1e-11 apart gave -1.2207e-4 and -1.2062e-4; on the window the marginal modes,
    7.1e-8 and 8.9e-8 1/s from the two starts with the plant's sampled contact results."""
    assert len(ours) == len(theirs)
    for a, b in zip(ours, theirs):
        for name in a:
            if name in TIMING_COLUMNS:
                continue
            if marginal_noise and name.startswith("marginal_"):
                for row in (a, b):   # or the SAP map's kink, which the step check finds (sweep_point._discrete_verdict)
                    kink = name == "marginal_discrete_real" and "NOT confirmed" in (row["discrete_step_check"] or "")
                    assert abs(row[name]) < marginal_noise or kink, (row["point"], name)
                continue
            if isinstance(a[name], float) and isinstance(b[name], float):
                resolution = DISCRETE_RATE_RESOLUTION if name.endswith("_discrete_real") else 1e-8
                assert a[name] == pytest.approx(b[name], rel=1e-6, abs=resolution), (a["point"], name)
            else:
                assert a[name] == b[name], (a["point"], name)


@pytest.fixture(scope="module")
def built_in_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("built_in")
    run_sweep("window-washing", load_spec(text=SWEEP), out, workers=0, progress=False)
    return read_results(out / "results.csv")


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_cli_sweeps_a_task_file_serially_as_the_built_in_task(built_in_sweep, tmp_path, capsys):
    spec = tmp_path / "spec.yaml"
    spec.write_text(SWEEP)
    assert main(["sweep", str(WINDOW_FILE), "--grid", str(spec), "--out", str(tmp_path / "out"), "--workers", "0",
                 "--no-progress"]) == 0
    assert "4 of 4 points evaluated" in capsys.readouterr().out
    _assert_same_rows(read_results(tmp_path / "out" / "results.csv"), built_in_sweep)


@pytest.mark.slow
def test_task_file_sweep_on_a_local_dask_cluster(built_in_sweep, tmp_path):
    """The task travels to two worker processes (by its text) and gives the built-in task's results."""
    task, _ = load_task_file(WINDOW_FILE)
    run = run_sweep(task.name, load_spec(text=SWEEP), tmp_path, workers=2, progress=False)
    rows = read_results(tmp_path / "results.csv")
    assert run.workers == "local:2" and len({row["worker"] for row in rows}) == 2
    _assert_same_rows(rows, built_in_sweep)


def test_the_task_file_guide_shows_the_task_file_as_it_is():
    """docs/howto/task_file.md includes the file itself (literalinclude), so it shows it as it is."""
    guide = (REPOSITORY / "docs" / "howto" / "task_file.md").read_text()
    assert "```{literalinclude} ../../models/tasks/window_washing.yaml" in guide
    included = (REPOSITORY / "docs" / "howto" / "../../models/tasks/window_washing.yaml").resolve()
    assert included.read_text() == WINDOW_FILE.read_text()      # the repository's file is the package's


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_a_task_that_is_not_built_in_tilted_pane_with_a_redundant_arm():
    """models/tasks/tilted_pane_4r.yaml: the 4R arm on a library box tilted by 20 degrees, kernel E_p.
    The linearized loop has the designed eigenvalues; the run tracks 0.05 m/s along the face and 10 N
    to 1 % within five design time constants of contact."""
    task, config = load_task_file(models_directory() / "tasks" / "tilted_pane_4r.yaml")
    E_p = task.space.velocity_projection.matrix(np.asarray(config.start.configuration))
    tilt = task.spec.parameters["tilt"]
    np.testing.assert_allclose(np.abs(E_p[0]), [np.cos(tilt), np.sin(tilt), 0], atol=1e-12)
    result = linearize_continuous(config)
    assert result.match.matched, result.match.as_dict()
    np.testing.assert_allclose(np.sort_complex(result.match.predicted), [-10, -10, -10, -8])
    run = simulate(config.replace(duration=1.0))
    summary = run.summary
    along, turning = summary.velocity_rows
    for row in (along, summary.force_rows[0]):
        assert row.settling_time_1_percent is not None and row.settling_time_1_percent < 5 * 0.125, row
    assert turning.max_error_after_5_time_constants < 1e-3        # rad/s, commanded 0
    assert abs(summary.velocity_rows[0].final_error) < 0.01 * 0.05
    assert abs(summary.force_rows[0].final_error) < 0.01 * 10.0


def test_schema_page_is_generated_from_the_types():
    """docs/task_files.md is the output of tasks.schema_doc (regenerate it after changing a field)."""
    page = (REPOSITORY / "docs" / "task_files.md").read_text()
    assert page == schema_markdown()
    assert "| `constraint.rows` | List[str] | [] | C(x), one expression per row |" in page
    assert "`config.gains.velocity`" in page and "`workpiece.shapes[].X_WG`" in page


# Hostile files, each made at a size n: (how to make it, n, what the refusal says). "Quickly" means bounded
# work (tests/bounded_work.py): twice the input costs at most about twice the calls, and refusing it costs
# fewer calls than loading a real task file; no clock.
HOSTILE_FILES = {
    "nested lists": (lambda n: "parameters: " + "[" * n + "]" * n, 1500, "nests too deeply"),
    "nested mappings": (lambda n: "parameters: " + "{a: " * n + "1" + "}" * n, 1500, "nests too deeply"),
    "a huge file": (lambda n: "name: x\n" + "# padding\n" * n, 200_000, "larger than 1000 kB"),
    "aliases of aliases": (lambda n: "a0: &a0 [x, x, x, x, x, x, x, x]\n" + "".join(
        f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 8)}]\n" for i in range(1, n)), 3, "unknown field 'a0'"),
    "an alias where a word belongs": (lambda n: "constraint: {rows: &r [" + ", ".join(["[y, y, y]"] * n) + "]}\n"
                                      "start: {configuration: *r}", 2, r"constraint.rows\[0\]: expected a word"),
}


@pytest.fixture(scope="module")
def real_file_calls():
    """The calls that loading a real task file (the window's) makes: what a refusal must stay below."""
    count, raised = bounded_work.calls(lambda: load_task_file(models_directory() / "tasks" / "window_washing.yaml",
                                                              register=False))
    assert raised is None
    return count


@pytest.mark.parametrize("case", sorted(HOSTILE_FILES))
def test_hostile_yaml_is_refused_with_bounded_work(tmp_path, case, real_file_calls):
    make, size, match = HOSTILE_FILES[case]
    counts = []
    for n in (size, 2 * size):
        path = tmp_path / f"hostile-{n}.yaml"
        path.write_text(make(n))
        count, raised = bounded_work.calls(lambda: load_task_file(path))
        assert isinstance(raised, ConfigError) and re.search(match, str(raised)), raised
        counts.append(count)
    assert counts[0] < real_file_calls, (counts, real_file_calls)
    assert bounded_work.at_most_linear(*counts), counts


# -- package:// URLs and paths relative to the task file -------------------------------------------

PACKAGE_ARM = """\
name: {name}
packages: {{mine: arms}}                       # relative to this file
robot:
  loader: {{path: "{path}", flange: {flange}, collision: drop}}
workpiece:
  shapes:
  - {{shape: box, size: [1.0, 1.0, 0.02], X_WG: {{translation: [0.6, 0.0, 0.09]}}}}
chart: {{kind: pose}}
constraint: {{rows: ["z - 0.12"]}}
start: {{pose: [0.6, 0.0, 0.12, 3.14159, 0.0, 0.0], joint_guess: {guess}}}
config: {{desired_force: {{kind: constant, value: [-5.0]}}}}
"""


def _package_task(tmp_path, path, flange="link3", guess="[0.0, 0.5, 0.5]"):
    (tmp_path / "arms").mkdir(exist_ok=True)
    (tmp_path / "arms" / "planar_3r.sdf").write_text((models_directory() / "planar_3r.sdf").read_text())
    task_file = tmp_path / "tasks" / "arm.yaml"
    task_file.parent.mkdir(exist_ok=True)
    task_file.write_text(PACKAGE_ARM.format(name="package-arm", path=path, flange=flange, guess=guess).replace(
        "packages: {mine: arms}", "packages: {mine: ../arms}"))
    return task_file


@pytest.mark.parametrize("path", ["package://mine/planar_3r.sdf", "../arms/planar_3r.sdf",
                                  "package://drake_hybrid/planar_3r.sdf"])
def test_robot_loader_finds_package_urls_and_relative_paths(tmp_path, path):
    task, config = load_task_file(_package_task(tmp_path, path), register=False)
    plant = MultibodyPlant(0.0)
    robot = task.add_robot(plant, config)
    plant.Finalize()
    assert plant.num_actuators() == 3 and robot.end_effector_frame == "pad_center"


def test_robot_loader_from_an_installed_model_package(tmp_path, monkeypatch):
    """package://example-robot-data/... (installed with pip in the cmeel layout) without a packages entry."""
    monkeypatch.setenv("DRAKE_HYBRID_CACHE", str(tmp_path / "cache"))
    path = "package://example-robot-data/robots/ur_description/urdf/ur10_robot.urdf"
    task, config = load_task_file(_package_task(tmp_path, path, flange="tool0",
                                                guess="[0.0, -1.5, 1.5, -1.5, -1.5, 0.0]"), register=False)
    plant = MultibodyPlant(0.0)
    robot = task.add_robot(plant, config)
    plant.Finalize()
    assert plant.num_actuators() == 6 and plant.HasFrameNamed("tool0", robot.arm)


@pytest.mark.parametrize("path, match", [
    ("package://nowhere/arm.urdf", r"robot.loader.path: unknown package 'nowhere' in 'package://nowhere/arm.urdf'; "
                                   r"known packages: .*drake_hybrid, .*example-robot-data, .*mine \("),
    ("package://mine/missing.sdf", r"robot.loader.path: no file '.*arms/missing.sdf' \(from 'package://mine/"),
    ("https://example.com/arm.urdf", r"robot.loader.path: 'https://example.com/arm.urdf': give a package:// or "
                                     r"file:// URL or a path"),
])
def test_bad_model_urls_are_refused_naming_the_field(tmp_path, path, match):
    with pytest.raises(ConfigError, match=match):
        load_task_file(_package_task(tmp_path, path), register=False)


def test_directives_take_paths_relative_to_the_task_file(tmp_path):
    """add_model.file: a plain path is relative to the task file (Drake's directives take URLs only)."""
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "window.sdf").write_text((models_directory() / "window.sdf").read_text())
    path = tmp_path / "task.yaml"
    path.write_text(WINDOW_FILE.read_text().replace("package://drake_hybrid/window.sdf", "models/window.sdf"))
    task, config = load_task_file(path, register=False)
    plant = MultibodyPlant(0.0)
    task.add_workpiece(plant, config)
    assert plant.HasModelInstanceNamed("window")


# -- an external Dask scheduler -------------------------------------------------------------------

def _stop(process, timeout=10.0):
    """Stop a process this test started and its children (its own session), SIGKILL if it lingers."""
    if process.poll() is not None:
        return
    try:
        os.killpg(process.pid, signal.SIGTERM)
        process.wait(timeout=timeout)
    except (ProcessLookupError, subprocess.TimeoutExpired):
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait(timeout=timeout)


@pytest.mark.slow                # starts a scheduler and two worker processes (~10-20 s)
def test_cli_sweeps_a_task_file_on_an_external_dask_scheduler(ur10_python_sweep, tmp_path):
    """``dask scheduler`` and ``dask worker --nworkers 2`` on 127.0.0.1 (no dashboards), then
    ``drake-hybrid sweep models/tasks/ur10_plate.yaml --scheduler tcp://...`` (a task that is not
    built in: the UR10 of a model package on a plate): the results of the same task built in Python. Every
    wait has a timeout and the processes are stopped in ``finally``, so a stuck cluster fails the
    test instead of hanging CI."""
    distributed = pytest.importorskip("distributed")
    dask_cli = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    scheduler_file = tmp_path / "scheduler.json"
    started = []
    common = dict(cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        started.append(subprocess.Popen(dask_cli + ["--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                                    "--scheduler-file", str(scheduler_file)], **common))
        deadline = time.monotonic() + 600          # a guard against a hang, not a time limit
        while not scheduler_file.exists() or not scheduler_file.read_text().strip():
            assert started[0].poll() is None, "the dask scheduler exited"
            assert time.monotonic() < deadline, "no scheduler file after 10 minutes: the scheduler hangs"
            time.sleep(0.2)
        address = json.loads(scheduler_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        started.append(subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                         "--nworkers", "2", "--nthreads", "1", "--host", "127.0.0.1",
                                         "--no-dashboard", "--memory-limit", "0", "--death-timeout", "60",
                                         "--local-directory", str(tmp_path / "workers")], **common))
        with distributed.Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=90)
        spec_text, python_rows = ur10_python_sweep
        spec = tmp_path / "spec.yaml"
        spec.write_text(spec_text)
        sweep = subprocess.run(
            [sys.executable, "-c", "import sys; from drake_hybrid.cli import main; sys.exit(main(sys.argv[1:]))",
             "sweep", str(UR10_FILE), "--grid", str(spec), "--out", str(tmp_path / "out"), "--scheduler", address,
             "--no-progress"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert sweep.returncode == 0, sweep.stderr[-2000:]
        assert "4 of 4 points evaluated" in sweep.stdout
    finally:
        for process in reversed(started):
            _stop(process)
    rows = read_results(tmp_path / "out" / "results.csv")
    assert len({row["worker"] for row in rows}) == 2          # both worker processes took points
    _assert_same_rows(rows, python_rows, marginal_noise=1e-3)


# -- expressions in poses (model directives, library shapes) ---------------------------------------

def test_poses_take_expressions_of_the_parameters():
    """The crank's weld pose is [crank_center_x, crank_center_y, crank_height]; the tilted pane's box
    pose is written with sin, cos and the tilt."""
    task, _ = load_task_file(models_directory() / "tasks" / "crank_turning.yaml", register=False)
    weld = task.spec.workpiece.directives[1].add_weld
    np.testing.assert_array_equal(weld.X_PC.translation, [0.45, 0.2, 0.3])
    task, _ = load_task_file(models_directory() / "tasks" / "tilted_pane_4r.yaml", register=False)
    X_WG = task.spec.workpiece.shapes[0].X_WG.GetDeterministicValue()
    tilt = task.spec.parameters["tilt"]
    np.testing.assert_allclose(X_WG.translation(), [1 + 0.01 * np.sin(tilt), 0, 1 + 0.01 * np.cos(tilt)], atol=1e-15)
    np.testing.assert_allclose(X_WG.rotation().matrix(), RotationMatrix.MakeYRotation(tilt).matrix(), atol=1e-15)


@pytest.mark.parametrize("value, match", [
    ('"__import__(\'os\').system(\'true\')"', r"workpiece.directives\[1\].add_weld.X_PC.translation\[0\]: only the "
                                              r"functions .* may be called, not '__import__"),
    ("crank_center_x.real", r"workpiece.directives\[1\].add_weld.X_PC.translation\[0\]: not allowed in an "
                            r"expression \(attribute access\)"),
    ("crank_centre_x", r"workpiece.directives\[1\].add_weld.X_PC.translation\[0\]: unknown name"),
    ('"9 ** 9 ** 9"', r"translation\[0\]"),
])
def test_bad_pose_expressions_are_refused_naming_the_field(tmp_path, value, match):
    text = (models_directory() / "tasks" / "crank_turning.yaml").read_text()
    path = tmp_path / "crank.yaml"
    path.write_text(text.replace("translation: [crank_center_x,", f"translation: [{value},"))
    count, raised = bounded_work.calls(lambda: load_task_file(path, register=False))
    assert isinstance(raised, ConfigError) and re.search(match, str(raised)), raised
    assert str(raised).startswith(str(path))
    # Refused before anything is evaluated (9 ** 9 ** 9 is never computed): fewer calls than the real file takes.
    real, _ = bounded_work.calls(lambda: load_task_file(models_directory() / "tasks" / "crank_turning.yaml",
                                                        register=False))
    assert count < real, (count, real)


def test_config_takes_no_expressions(tmp_path):
    """Only pose lists outside ``config`` are evaluated; elsewhere a word is a type error."""
    path = _write(tmp_path, {"desired_velocity: {kind: constant, value: [0.1, 0.0]}":
                             "desired_velocity: {kind: constant, value: [window_height, 0.0]}"})
    with pytest.raises(ConfigError, match=r"config.desired_velocity.value"):
        load_task_file(path, register=False)


# -- a task that is not built in, with an arm from a model package ----------------------------------

UR10_FILE = models_directory() / "tasks" / "ur10_plate.yaml"


@pytest.fixture(scope="module")
def ur10_plate_tasks(tmp_path_factory):
    """models/tasks/ur10_plate.yaml and the same task built in Python (load_arm, CustomTask)."""
    task, config = load_task_file(UR10_FILE)
    share = installed_model_packages()["example-robot-data"]
    arm = load_arm(f"{share}/robots/ur_description/urdf/ur10_robot.urdf", "tool0", collision="drop",
                   cache_dir=tmp_path_factory.mktemp("ur10_cache"))
    chart = PoseChart()
    plate = surface_constraint(chart, lambda p: p[2] - 0.12, name="plate", normal_rows=False)
    python_task = register_task(CustomTask(
        "ur10-plate-python", add_robot=arm.add_robot,
        add_workpiece=lambda plant: add_rigid_workpiece(plant, Box(0.6, 0.6, 0.05), RigidTransform([0.7, 0.0, 0.075]),
                                                        name="plate"),
        constraint_space=ConstraintSpace(plate, GivenVelocityProjection(chart, np.delete(np.eye(6), 2, axis=0))),
        start_pose=RigidTransform(RotationMatrix.MakeXRotation(np.pi), [0.7, 0.0, 0.12]),
        joint_guess=task.spec.start.joint_guess, labels=task.labels()))
    python_config = python_task.default_config(desired_velocity=[0.05, 0, 0, 0, 0], desired_force=[10.0],
                                               duration=config.duration)
    return config, python_config


@pytest.mark.slow                # about 5 s
def test_a_file_with_an_arm_from_a_model_package_runs_as_the_same_task_in_python(ur10_plate_tasks):
    """The UR10 of example-robot-data by package:// URL on a library box: 0.2 s of the run (logs to
    1e-9) and the linearized loop (the designed -10 1/s six times) equal the Python CustomTask's."""
    config, python_config = ur10_plate_tasks
    ours, theirs = simulate(config.replace(duration=0.2)), simulate(python_config.replace(duration=0.2))
    for name in ("velocity_error", "force_error", "q", "v", "constraint"):
        np.testing.assert_allclose(ours.log[name], theirs.log[name], rtol=0, atol=1e-9, err_msg=name)
    ours, theirs = linearize_continuous(config), linearize_continuous(python_config)
    assert ours.match.matched
    np.testing.assert_allclose(np.sort_complex(ours.match.predicted), [-10] * 6)
    np.testing.assert_allclose(np.sort_complex(ours.match.partner), np.sort_complex(theirs.match.partner), rtol=1e-8)


@pytest.fixture(scope="module")
def ur10_python_sweep(ur10_plate_tasks, tmp_path_factory):
    """(sweep spec text, results) of the UR10 plate task built in Python, swept serially.

    The Python task's defaults have no desired values: the base gives the file's. With K_fp = 2 the
    force error of this loop does not settle and runs that start equal to 1e-15 part by percents:
    points with K_fp <= 0.5."""
    text = SWEEP.replace("base:\n", "base:\n  desired_velocity.value[0]: 0.05\n"
                         "  desired_force.value[0]: 10.0\n").replace("[0.5, 2.0]", "[0.25, 0.5]")
    out = tmp_path_factory.mktemp("ur10_python")
    run_sweep("ur10-plate-python", load_spec(text=text), out, workers=0, progress=False)
    return text, read_results(out / "results.csv")


@pytest.mark.slow
def test_a_file_with_an_arm_from_a_model_package_sweeps_on_two_workers(ur10_python_sweep, tmp_path):
    """The file's 4-point sweep on two worker processes (which know the UR10 only from the file's
    text) equals the Python task's serial sweep (a task registered in Python never reaches a worker)."""
    spec_text, python_rows = ur10_python_sweep
    run = run_sweep("ur10-plate", load_spec(text=spec_text), tmp_path / "file", workers=2, progress=False)
    assert run.workers == "local:2"
    rows = read_results(tmp_path / "file" / "results.csv")
    assert all(not row["error"] for row in rows) and len({row["worker"] for row in rows}) == 2
    # The marginal modes (zero in theory) of the one-period map come out between 1e-8 and 1.4e-4 1/s,
    # different in the two runs: central differences (step 1e-5) resolve a multiplier mu near 1 to
    # about 1e-7, log(mu)/h to about 1e-4 1/s at h = 1 ms (more for a repeated eigenvalue). Checked
    # to be below ten times that in both, not compared.
    _assert_same_rows(rows, python_rows, marginal_noise=1e-3)


def test_task_files_declare_cs_units_as_their_built_in_tasks_do(tmp_path):
    """Every shipped file names its C rows' units (the summary's max |C(r)| reads "m", not "in the units of
    C's rows"), the built-in task's where there is one; a file that declares none gets none."""
    built_in = {"window_washing": "window-washing", "grinding": "grinding", "crank_turning": "crank-turning",
                "sphere_polishing": "sphere-polishing"}
    for path in sorted((models_directory() / "tasks").glob("*.yaml")):
        units = read_task_file(path).labels.constraint_units
        assert units, path.name
        if path.stem in built_in:
            assert units == get_task(built_in[path.stem]).labels()["constraint_units"], path.name
    assert load_task_file(WINDOW_FILE)[0].labels()["constraint_units"] == "m"
    path = _write(tmp_path, {"  constraint_units: m\n": ""}, "")
    assert "constraint_units" not in load_task_file(path, register=False)[0].labels()
