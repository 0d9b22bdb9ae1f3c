"""Sweeps: the spec, dotted config paths, model error, the results table, and a small sweep on
a local Dask cluster checked against the same points run serially."""

import csv
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from drake_hybrid.analysis.discrete_linearization import linearize_sampled_loop
from drake_hybrid.cli import main, make_parser
from drake_hybrid.core.errors import MissingExtraError
from drake_hybrid.experiments.config_paths import apply_parameters, set_config_value
from drake_hybrid.experiments.metrics import row_errors
from drake_hybrid.experiments.summary import RunSummary
from drake_hybrid.experiments.sweep import run_sweep
from drake_hybrid.experiments.sweep_point import RESULT_COLUMNS, simulation_metrics
from drake_hybrid.experiments.sweep_results import read_results
from drake_hybrid.experiments.sweep_spec import StabilityCriteria, SweepSpecError, load_spec
from drake_hybrid.experiments.theory_verdict import rigid_contact_theory_stable
from drake_hybrid.scenario.builder import build_scenario
from drake_hybrid.scenario.start import set_initial_conditions
from drake_hybrid.tasks.config import dump_config, load_config
from drake_hybrid.tasks.registry import get_task

WINDOW = "window-washing"


def default_config():
    return get_task(WINDOW).default_config()


# -- spec ------------------------------------------------------------------------------------------

def test_grid_points_are_the_cartesian_product_in_order():
    spec = load_spec(text="""
parameters:
  contact.pad_modulus: {logspace: [1e5, 1e9, 3]}     # YAML 1.1 reads 1e5 as a string: accepted
  gains.force_proportional: {values: [0.5, 2]}
""")
    points = spec.points()
    assert [p["contact.pad_modulus"] for p in points] == pytest.approx([1e5, 1e5, 1e7, 1e7, 1e9, 1e9])
    assert [p["gains.force_proportional"] for p in points] == [0.5, 2.0] * 3


def test_random_points_are_reproducible_and_within_bounds():
    text = """
parameters:
  control_period: {values: [0.001, 0.004]}
  model_error.payload_mass_scale: {uniform: [0.8, 1.2]}
  contact.pad_modulus: {loguniform: [1e6, 1e8]}
samples: 25
seed: 11
"""
    points = load_spec(text=text).points()
    assert len(points) == 50 and points == load_spec(text=text).points()
    scales = np.array([p["model_error.payload_mass_scale"] for p in points])
    moduli = np.array([p["contact.pad_modulus"] for p in points])
    assert np.all((0.8 <= scales) & (scales <= 1.2)) and np.all((1e6 <= moduli) & (moduli <= 1e8))
    assert [p["control_period"] for p in points[:25]] == [0.001] * 25
    other_seed = load_spec(text=text.replace("seed: 11", "seed: 12")).points()
    assert other_seed[0]["model_error.payload_mass_scale"] != points[0]["model_error.payload_mass_scale"]


@pytest.mark.parametrize("text, message", [
    ("parameters: {}", "needs 'parameters'"),
    ("parameters: {plant.time_step: {gaussian: [1, 2]}}", "unknown field 'gaussian'; its fields are"),
    ("parameters: {plant.time_step: [0.001]}", r"parameters.plant.time_step: expected a section \(a mapping of fields\), got \[0.001\]"),
    ("parameters: {plant.time_step: {values: [0.001], uniform: [1, 2]}}", "give exactly one non-empty kind"),
    ("parameters: {plant.time_step: {values: [0.001]}}\nsamples: 2.5", "samples: expected an integer, got 2.5"),
    ("parameters: {plant.time_step: {linspace: [1, 2]}}", "expected 3 numbers"),
    ("parameters: {plant.time_step: {logspace: [0, 1, 3]}}", "bounds must be positive"),
    ("parameters: {plant.time_step: {uniform: [2, 1]}}", "lower bound 2 exceeds upper 1"),
    ("parameters: {plant.time_step: {values: [0.001]}}\nsamples: 3", "no parameter has a distribution"),
    ("parameters: {plant.time_step: {values: [0.001]}}\nmap: {x: duration}",
     "map.x = 'duration' is not one of the parameters"),
    ("parameters: {plant.time_step: {values: [0.001]}}\ngrid: 3", "unknown field 'grid'"),
    ("parameters: {plant.time_step: {values: [0.001]}}\nstability: {steady_window: 2}", "steady_window must be in"),
])
def test_bad_specs_raise_naming_the_problem(text, message):
    with pytest.raises(SweepSpecError, match=message):
        load_spec(text=text)


def test_dotted_paths_set_nested_list_and_dict_fields():
    config = default_config()
    set_config_value(config, "contact.pad_modulus", 2e7)
    set_config_value(config, "gains.force_proportional", 1.5)          # a scalar gain becomes [1.5]
    set_config_value(config, "desired_velocity.value[0]", 0.2)
    set_config_value(config, "task_parameters.window_height", 0.95)
    assert config.contact.pad_modulus == 2e7 and config.gains.force_proportional == [1.5]
    assert config.desired_velocity.value[0] == 0.2 and config.task_parameters["window_height"] == 0.95
    with pytest.raises(ValueError, match="contact has no field 'stiffness'; its fields are"):
        set_config_value(config, "contact.stiffness", 1.0)
    with pytest.raises(ValueError, match=r"has 2 entries, no \[5\]"):
        set_config_value(config, "desired_velocity.value[5]", 1.0)
    with pytest.raises(ValueError, match="is a value, not a section"):
        set_config_value(config, "duration.seconds", 1.0)


def test_applied_parameters_round_trip_through_yaml_and_type_errors_are_named():
    point = apply_parameters(default_config(), {"control_period": 0.004, "model_error.payload_mass_scale": 1.2})
    assert dump_config(load_config(data=dump_config(point))) == dump_config(point) and point.control_period == 0.004
    with pytest.raises(ValueError, match="do not give a valid scenario config"):
        apply_parameters(default_config(), {"duration": "long"})


def test_sweep_rejects_a_spec_for_another_task_and_bad_base_paths(tmp_path):
    with pytest.raises(SweepSpecError, match="for task 'crank'"):
        run_sweep(WINDOW, load_spec(text="task: crank\nparameters: {plant.time_step: {values: [0.001]}}"), tmp_path,
                  workers=0)
    with pytest.raises(SweepSpecError, match="base: .*has no field 'horizon'"):
        run_sweep(WINDOW, load_spec(text="base: {horizon: 1}\nparameters: {plant.time_step: {values: [0.001]}}"),
                  tmp_path, workers=0)


@pytest.mark.parametrize("changes, message", [
    ({"plant.time_step": 0.0}, "needs a discrete plant"),
    ({"control_period": 0.0}, "needs a discrete plant"),
    ({"control_period": 0.0025}, "whole number of plant steps"),
    ({"sensor.bandwidth_hz": 200.0}, "needs sensor.bandwidth_hz = 0"),
])
def test_discrete_linearization_names_what_it_cannot_handle(changes, message):
    config = default_config()
    for path, value in changes.items():
        set_config_value(config, path, value)
    with pytest.raises(ValueError, match=message):
        linearize_sampled_loop(config)


# -- model error ---------------------------------------------------------------------------------

def test_payload_error_scales_the_simulated_tool_only():
    config = default_config()
    config.model_error.payload_mass_scale = 1.2
    config.model_error.link_mass_scale = 0.9
    config.model_error.link_inertia_scale = 1.1
    scenario = build_scenario(config, with_loggers=False)
    context = scenario.diagram.CreateDefaultContext()
    set_initial_conditions(scenario, context)
    set_initial_conditions(scenario, context)           # applying twice does not compound
    plant, plant_context = scenario.plant, scenario.plant_context(context)
    tool = plant.GetBodyByName("tool")
    link = plant.GetBodyByName("link2")
    assert tool.get_mass(plant_context) == pytest.approx(1.2 * 0.2, rel=1e-14)
    assert link.get_mass(plant_context) == pytest.approx(0.9 * 1.5, rel=1e-14)
    nominal = tool.default_rotational_inertia().get_moments()
    scaled = tool.CalcSpatialInertiaInBodyFrame(plant_context).CalcRotationalInertia().get_moments()
    assert scaled == pytest.approx(1.2 * nominal, rel=1e-12)
    # The link: centre of mass kept, central inertia scaled by mass x inertia scale.
    nominal_link = link.default_spatial_inertia()
    simulated_link = link.CalcSpatialInertiaInBodyFrame(plant_context)
    np.testing.assert_allclose(simulated_link.get_com(), nominal_link.get_com(), atol=1e-15)
    central = simulated_link.Shift(simulated_link.get_com()).CalcRotationalInertia().get_moments()
    nominal_central = nominal_link.Shift(nominal_link.get_com()).CalcRotationalInertia().get_moments()
    np.testing.assert_allclose(central, 0.9 * 1.1 * nominal_central, rtol=1e-12)
    controller_plant = scenario.controller_plant
    assert controller_plant.GetBodyByName("tool").get_mass(controller_plant.CreateDefaultContext()) == 0.2
    config.model_error.payload_mass_scale = -1.0
    with pytest.raises(ValueError, match="model_error.payload_mass_scale must be positive"):
        build_scenario(config, with_loggers=False)


def test_rigid_contact_theory_is_the_force_rate_sign():
    config = default_config()
    assert rigid_contact_theory_stable(config) is True
    config.gains.force_proportional = [-0.5]           # outside the admissible set (K_fp must be PSD)
    assert rigid_contact_theory_stable(config) is None


# -- the sweep ------------------------------------------------------------------------------------

SMALL_SWEEP = """
task: window-washing
base:
  duration: 0.15
parameters:
  contact.pad_modulus: {values: [1e5, 5e6, 1e9]}     # 1e5 Pa: the start is not found (recorded, not dropped)
  gains.force_proportional: {values: [0.5, 2.0]}
  control_period: {values: [0.001, 0.004]}
map: {x: contact.pad_modulus, y: gains.force_proportional, facet: control_period}
"""
TIMING_COLUMNS = {"wall_time", "simulation_wall_time", "linearization_wall_time", "cpu_time", "worker"}


@pytest.fixture(scope="module")
def serial_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("serial")
    run = run_sweep(WINDOW, load_spec(text=SMALL_SWEEP), out, workers=0, progress=False)
    return run, read_results(out)


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_small_sweep_on_a_local_dask_cluster_matches_serial(serial_sweep, tmp_path):
    serial_run, serial = serial_sweep
    run = run_sweep(WINDOW, load_spec(text=SMALL_SWEEP), tmp_path, workers=2, progress=False)
    parallel = read_results(tmp_path)
    assert run.workers == "local:2" and run.evaluated == 12 and len(parallel) == len(serial) == 12
    assert len({row["worker"] for row in parallel}) == 2          # both worker processes took points
    for a, b in zip(serial, parallel):
        for name in a:
            if name not in TIMING_COLUMNS:
                assert a[name] == b[name], (a["point"], name)     # the same numbers, bit for bit
    # Every point is in the table: the four 1e5 Pa points are recorded with the start's error.
    failed = [row for row in serial if row["error"]]
    assert [row["contact.pad_modulus"] for row in failed] == [1e5] * 4
    assert all("OffConstraintError" in row["error"] and row["stable"] is None for row in failed)
    assert serial_run.failures == run.failures == 4


@pytest.mark.slow                # the serial sweep fixture (15 s): not in the fast loop
def test_sweep_verdicts_agree_with_the_physics(serial_sweep):
    """K_fp = 2 on a stiff pad: the sampled force loop diverges (multiplier outside the unit circle,
    the simulation's force error does not settle); K_fp = 0.5 is stable at both rates. The map is the
    simulated loop's, whose wrench is the plant's last step's (sampled ports): its largest multiplier
    measured 1.33 at 1 ms and 1.73 at 4 ms (1.60 and 1.77 with the current step's wrench, unsampled
    ports; docs/drake_notes.md)."""
    _, rows = serial_sweep
    by_key = {(r["contact.pad_modulus"], r["gains.force_proportional"], r["control_period"]): r for r in rows}
    for period in (0.001, 0.004):
        stiff_high_gain = by_key[(1e9, 2.0, period)]
        assert stiff_high_gain["stable_discrete"] is False and stiff_high_gain["spectral_radius"] > 1.25
        assert stiff_high_gain["stable_simulation"] is False and stiff_high_gain["steady_force_error"] > 5.0
        nominal = by_key[(5e6, 0.5, period)]
        assert nominal["stable_discrete"] is True and nominal["spectral_radius"] < 1.01
        assert nominal["peak_force"] == pytest.approx(12.0, abs=1.5)   # |F_d| = 10 N plus the designed 2 N transient
        assert nominal["steady_force_error"] < 1.0
        assert rigid_contact_theory_stable(apply_parameters(default_config(), {"gains.force_proportional": 2.0}))


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_resume_runs_only_the_missing_points(serial_sweep, tmp_path):
    serial_run, serial = serial_sweep
    source = serial_run.results_path
    with source.open(newline="") as f:
        lines = list(csv.reader(f))
    spec = load_spec(text=SMALL_SWEEP)
    # An interrupted sweep: the same out dir with only some rows written.
    for name in ("manifest.json", "spec.yaml", "base_config.yaml"):
        (tmp_path / name).write_text((source.parent / name).read_text())
    kept = [lines[0]] + [line for line in lines[1:] if line[0] not in ("6", "9")]
    with (tmp_path / "results.csv").open("w", newline="") as f:
        csv.writer(f).writerows(kept)
    with pytest.raises(SweepSpecError, match="exists: pass --resume"):
        run_sweep(WINDOW, spec, tmp_path, workers=0, progress=False)
    run = run_sweep(WINDOW, spec, tmp_path, workers=0, resume=True, progress=False)
    assert run.evaluated == 2
    resumed = read_results(tmp_path)
    assert [row["point"] for row in resumed] == list(range(12))
    for a, b in zip(serial, resumed):
        assert {k: v for k, v in a.items() if k not in TIMING_COLUMNS} == \
               {k: v for k, v in b.items() if k not in TIMING_COLUMNS}
    other = load_spec(text=SMALL_SWEEP.replace("[0.5, 2.0]", "[0.5, 3.0]"))
    with pytest.raises(SweepSpecError, match="holds a different sweep"):
        run_sweep(WINDOW, other, tmp_path, workers=0, resume=True, progress=False)


@pytest.mark.slow                # the serial sweep fixture (15 s): not in the fast loop
def test_results_table_has_every_column_and_the_map_plots(serial_sweep, tmp_path):
    from drake_hybrid.viz.sweep_plots import save_sweep_plots

    serial_run, rows = serial_sweep
    assert set(RESULT_COLUMNS) <= set(rows[0])
    paths = save_sweep_plots(rows, load_spec(text=SMALL_SWEEP), tmp_path,
                             base_config=load_config(path=serial_run.out_dir / "base_config.yaml"))
    assert [p.name for p in paths] == ["stability_map.png"] and paths[0].stat().st_size > 10_000


def test_cli_parses_the_sweep_command():
    args = make_parser().parse_args(["sweep", WINDOW, "--grid", "spec.yaml", "--workers", "3", "--resume",
                                     "--scheduler", "tcp://127.0.0.1:8786"])
    assert (args.grid, args.workers, args.resume, args.scheduler) == ("spec.yaml", 3, True, "tcp://127.0.0.1:8786")
    with pytest.raises(SystemExit):
        make_parser().parse_args(["sweep", WINDOW])            # --grid is required


# -- a sweep is safe by construction: lock, torn rows, manifest, digest, row checks ----------------

FAST_SWEEP = """
task: window-washing
base: {duration: 0.06}
parameters:
  gains.force_proportional: {values: [0.5, 1.0, 1.5, 2.0, 2.5, 3.0]}
linearize: {continuous: false, discrete: false}
"""


def _rows_per_point(path):
    with (path / "results.csv").open(newline="") as f:
        points = [line[0] for line in list(csv.reader(f))[1:]]
    return {point: points.count(point) for point in points}


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_a_sweep_killed_mid_run_resumes_with_every_point_once(tmp_path):
    spec_path = tmp_path / "spec.yaml"
    spec_path.write_text(FAST_SWEEP)
    out = tmp_path / "out"
    script = ("from drake_hybrid.experiments.sweep import run_sweep\n"
              "from drake_hybrid.experiments.sweep_spec import load_spec\n"
              f"run_sweep('{WINDOW}', load_spec(path='{spec_path}'), '{out}', workers=0, progress=False)\n")
    process = subprocess.Popen([sys.executable, "-c", script])
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(_rows_per_point(out) if (out / "results.csv").exists() else {}) < 2:
        time.sleep(0.05)
    process.send_signal(signal.SIGKILL)
    process.wait()
    finished = _rows_per_point(out)
    assert 2 <= len(finished) < 6 and (out / ".lock").exists()         # killed mid-sweep, its lock left behind
    with (out / "results.csv").open("a") as f:
        f.write("5,3.0,Tr")                                              # and a torn last line
    run = run_sweep(WINDOW, load_spec(text=FAST_SWEEP), out, workers=0, resume=True, progress=False)
    assert run.evaluated == 6 - len(finished)
    assert _rows_per_point(out) == {str(i): 1 for i in range(6)}         # every point exactly once
    assert not (out / ".lock").exists()


def test_a_live_lock_refuses_a_second_writer(tmp_path):
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        tmp_path.mkdir(exist_ok=True)
        (tmp_path / ".lock").write_text(str(holder.pid))
        with pytest.raises(SweepSpecError, match=f"being written by another sweep \\(process {holder.pid}\\)"):
            run_sweep(WINDOW, load_spec(text=FAST_SWEEP), tmp_path, workers=0, progress=False)
        assert not (tmp_path / "results.csv").exists()
    finally:
        holder.kill()
        holder.wait()


def test_resume_refuses_changed_settings_missing_manifest_and_foreign_rows(tmp_path):
    run_sweep(WINDOW, load_spec(text=FAST_SWEEP.replace("[0.5, 1.0, 1.5, 2.0, 2.5, 3.0]", "[0.5]")), tmp_path,
              workers=0, progress=False)
    one_point = FAST_SWEEP.replace("[0.5, 1.0, 1.5, 2.0, 2.5, 3.0]", "[0.5]")
    changed = load_spec(text=one_point + "stability: {steady_tolerance: 0.2}\n")
    with pytest.raises(SweepSpecError, match="holds a different sweep"):                # verdict settings changed
        run_sweep(WINDOW, changed, tmp_path, workers=0, resume=True, progress=False)
    manifest = (tmp_path / "manifest.json").read_text()
    (tmp_path / "manifest.json").unlink()
    with pytest.raises(SweepSpecError, match="no manifest.json"):
        run_sweep(WINDOW, load_spec(text=one_point), tmp_path, workers=0, resume=True, progress=False)
    (tmp_path / "manifest.json").write_text(manifest)
    text = (tmp_path / "results.csv").read_text().replace("\n0,0.5,", "\n0,0.75,")   # a row from another sweep
    (tmp_path / "results.csv").write_text(text)
    with pytest.raises(SweepSpecError, match="the row of point 0 has parameters"):
        run_sweep(WINDOW, load_spec(text=one_point), tmp_path, workers=0, resume=True, progress=False)


@pytest.mark.parametrize("text, message", [
    ("parameters:\n  gains.velocity: {values: [1]}\n  gains.velocity[0]: {values: [2]}", "set the same field"),
    ("base:\n  gains.velocity[0]: 3\nparameters:\n  gains.velocity: {values: [1]}", "overlaps a field set in 'base'"),
    ("parameters: {duration: {linspace: [1, 2, 20000]}}", "20000 points, more than max_points = 10000"),
    ("parameters: {duration: {values: [1]}}\nlinearize: {continuous: maybe}", "continuous"),
])
def test_overlaps_counts_and_strict_booleans_are_refused(text, message):
    with pytest.raises(SweepSpecError, match=re.escape(message)):
        load_spec(text=text)


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_an_unreachable_scheduler_leaves_nothing_behind(tmp_path):
    with pytest.raises(SweepSpecError, match="no Dask scheduler answers there"):
        run_sweep(WINDOW, load_spec(text=FAST_SWEEP), tmp_path / "out", scheduler="tcp://127.0.0.1:1",
                  progress=False)
    assert not (tmp_path / "out").exists()


# -- without the cluster extra: Dask not installed -------------------------------------------------

@pytest.fixture
def without_dask(monkeypatch):
    """Dask and distributed as if not installed (a plain ``pip install .``): importing either raises ImportError."""
    for name in ("dask", "distributed"):
        monkeypatch.setitem(sys.modules, name, None)


def test_without_dask_a_cluster_sweep_names_the_extra_and_writes_nothing(without_dask, tmp_path, capsys):
    message = ("sweeps on a Dask cluster need the cluster extra: pip install 'drake-hybrid[cluster]' "
               "(or run serially: workers=0, --workers 0)")
    for where in ({"workers": 2}, {"scheduler": "tcp://127.0.0.1:8786"}):
        with pytest.raises(MissingExtraError) as raised:
            run_sweep(WINDOW, load_spec(text=FAST_SWEEP), tmp_path / "out", progress=False, **where)
        assert str(raised.value) == message and isinstance(raised.value, ImportError)
        assert not (tmp_path / "out").exists()
    (tmp_path / "spec.yaml").write_text(FAST_SWEEP)
    assert main(["sweep", WINDOW, "--grid", str(tmp_path / "spec.yaml"), "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err == f"drake-hybrid sweep: {message}\n"      # one line, no traceback
    assert not (tmp_path / "out").exists()


def test_without_dask_a_serial_sweep_runs(without_dask, tmp_path):
    one_point = load_spec(text=FAST_SWEEP.replace("[0.5, 1.0, 1.5, 2.0, 2.5, 3.0]", "[0.5]"))
    run = run_sweep(WINDOW, one_point, tmp_path, workers=0, progress=False)
    (row,) = read_results(tmp_path)
    assert run.workers == "serial" and run.evaluated == 1 and row["error"] is None


def _window_result(x_dot_error, theta_dot_error):
    """A settled window-washing result: x-dot commanded 0.1 m/s, theta-dot 0 rad/s, 10 N; constant errors."""
    from types import SimpleNamespace

    t = np.linspace(0.0, 1.0, 101)
    log = {"t": t, "desired_velocity": np.tile([0.1, 0.0], (t.size, 1)),
           "velocity_error": np.tile([x_dot_error, theta_dot_error], (t.size, 1)),
           "desired_force": np.full((t.size, 1), 10.0), "force_error": np.full((t.size, 1), 0.01),
           "force": np.full((t.size, 1), 10.01)}
    summary = RunSummary(task="window-washing", mode="velocity-force", duration=1.0,
                         velocity_rows=row_errors(t, log["velocity_error"], log["desired_velocity"],
                                                  ["x-dot", "theta-dot"], ["m/s", "rad/s"], 0.0, 0.5),
                         force_rows=row_errors(t, log["force_error"], log["desired_force"], ["normal force"], ["N"],
                                               0.0, 0.5),
                         velocity_settling_time_1_percent=0.1, force_settling_time_1_percent=0.1,
                         max_constraint_residual=1e-3, wall_time=1.0)
    return SimpleNamespace(log=log, summary=summary)


def test_the_steady_verdict_is_per_row_in_each_rows_units_never_a_norm_across_units():
    """2 mm/s on 0.1 m/s (2 %) and 0.01 rad/s on a row commanded to zero: each within 5 % of its scale, so
    settled -- a norm of the two (0.0102 'units' > 5 mm/s) called it unsettled."""
    criteria = StabilityCriteria(steady_window=0.2, steady_tolerance=0.05)
    dut = simulation_metrics(_window_result(0.002, 0.01), criteria)
    assert dut["stable_simulation"] is True
    # the row furthest out relative to its scale: x-dot at 2 % (theta-dot is at 1 % of one rad/s)
    assert dut["steady_velocity_row"] == "x-dot (m/s)" and dut["steady_velocity_error_percent"] == pytest.approx(2.0)
    assert dut["steady_velocity_error"] == pytest.approx(0.002) and dut["final_velocity_error"] == pytest.approx(0.002)
    assert dut["steady_force_row"] == "normal force (N)" and dut["steady_force_error_percent"] == pytest.approx(0.1)
    # 6 mm/s is 6 % of that row's command: unsettled, and named
    late = simulation_metrics(_window_result(0.006, 0.0), criteria)
    assert late["stable_simulation"] is False and late["steady_velocity_row"] == "x-dot (m/s)"
    assert late["steady_velocity_error_percent"] == pytest.approx(6.0)
    # 0.06 rad/s of twist on the row commanded to zero: beyond 5 % of one rad/s, and no % for it
    twist = simulation_metrics(_window_result(0.0, 0.06), criteria)
    assert twist["stable_simulation"] is False and twist["steady_velocity_row"] == "theta-dot (rad/s)"
    assert twist["steady_velocity_error"] == pytest.approx(0.06) and twist["steady_velocity_error_percent"] is None


def test_peak_force_is_per_row_in_its_units_and_names_the_row():
    """The crank's four force rows (N, N, N m, N m here; commanded 0, 5 N, 0, 0): the reported peak is the
    row whose peak is largest relative to its command (one unit where commanded to zero), in its units,
    named -- not the norm across N and N m."""
    from types import SimpleNamespace

    t = np.linspace(0.0, 1.0, 101)
    desired = np.tile([0.0, 5.0, 0.0, 0.0], (t.size, 1))
    force = np.tile([0.2, 5.5, 0.3, 0.1], (t.size, 1))
    force[10] = [0.5, 6.0, 0.9, 0.1]                              # the transient's peaks
    names, units = ["F_x", "F_y", "M_x", "M_y"], ["N", "N", "N m", "N m"]
    log = {"t": t, "desired_velocity": np.tile([0.5, 0.0], (t.size, 1)), "velocity_error": np.zeros((t.size, 2)),
           "desired_force": desired, "force_error": force - desired, "force": force}
    summary = RunSummary(task="crank-turning", mode="velocity-force", duration=1.0,
                         velocity_rows=row_errors(t, log["velocity_error"], log["desired_velocity"], ["spin", "crank"],
                                                  ["rad/s", "rad/s"], 0.0, 0.5),
                         force_rows=row_errors(t, log["force_error"], desired, names, units, 0.0, 0.5),
                         velocity_settling_time_1_percent=0.1, force_settling_time_1_percent=0.1,
                         max_constraint_residual=1e-3, wall_time=1.0)
    metrics = simulation_metrics(SimpleNamespace(log=log, summary=summary), StabilityCriteria())
    assert metrics["peak_force"] == pytest.approx(6.0) and metrics["peak_force_row"] == "F_y (N)"   # 1.2 x 5 N
    force[10, 2] = 1.5                                            # 1.5 N m on a row commanded to zero: 1.5 units
    metrics = simulation_metrics(SimpleNamespace(log=log, summary=summary), StabilityCriteria())
    assert metrics["peak_force"] == pytest.approx(1.5) and metrics["peak_force_row"] == "M_x (N m)"
    assert "peak_force_row" in RESULT_COLUMNS


@pytest.mark.slow
def test_an_unstable_looking_one_period_map_is_checked_at_a_larger_step():
    """The UR10 on a plate at rest: at the default step 1e-5 the sampled loop's map shows +3.87 1/s
    (multiplier 1.0039), at 1e-4 nothing above 1e-4 1/s (docs/drake_notes.md): a kink of the SAP
    map, not a mode (a kicked simulation decays). The check says so; the sweep then keeps the
    regulated modes' verdict where the kink is on a predicted zero's partner, and gives none where it
    is on a regulated mode (sweep_point._discrete_verdict)."""
    from drake_hybrid.station.parsing import models_directory
    from drake_hybrid.tasks.task_file import load_task_file

    task, _ = load_task_file(models_directory() / "tasks" / "ur10_plate.yaml")
    linear = linearize_sampled_loop(task.default_config())
    check = linear.step_check
    assert check is not None and check.worst_real > 1.0 and check.larger_worst_real < 0.01
    assert not check.confirmed and "NOT confirmed" in check.summary()


@pytest.mark.parametrize("worst, check, margin, verdict", [
    (-1.0, None, 0.0, True),                       # no rate above 0.01 1/s anywhere: no check made
    (0.005, None, 0.0, False),                     # a slow regulated growth below the check's rate
    (-1.0, (3.86, 1e-4), 0.0, True),               # a kink on a predicted zero's partner alone
    (3.86, (3.86, 1e-4), 0.0, None),               # a kink on a regulated mode: no verdict
    (0.005, (0.3, 1e-5), 0.0, False),              # a regulated growth the margin refuses, not the kink's
    (-0.3, (0.3, 1e-5), -0.5, False),              # the user's margin refuses the regulated modes
    (-1.0, (0.109, 0.107), 0.0, False),            # a predicted zero's partner grows at both steps
    (0.03, (0.03, 0.03), 0.05, True),              # a confirmed growth inside the user's margin
    (3.0, (3.0, 2.9), 0.0, False),                 # a regulated instability, confirmed
])
def test_the_discrete_verdict_weighs_the_step_check(worst, check, margin, verdict):
    """experiments.sweep_point._discrete_verdict: the sampled loop's verdict from the regulated modes'
    worst rate and the step check at a ten times larger step (figures from docs/stability.md)."""
    from drake_hybrid.analysis.discrete_linearization import StepCheck
    from drake_hybrid.experiments.sweep_point import _discrete_verdict

    step_check = None if check is None else StepCheck(1e-5, check[0], 1e-4, check[1])
    assert _discrete_verdict(worst, step_check, margin) is verdict
