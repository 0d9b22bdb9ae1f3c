"""Stability maps and robustness sweeps, on this machine or a Dask cluster.

``run_sweep(task, spec, out_dir)`` evaluates every point of a sweep spec
(``drake_hybrid.experiments.sweep_spec``: grid and Monte Carlo over any scenario-config
field) and writes one row per point to ``out_dir/results.csv`` as soon as the
point finishes, so an interrupted or partly failed sweep keeps every finished
point and ``resume=True`` runs only the missing ones.

One point (``evaluate_point``, run on a worker from the point's config YAML:
Drake diagrams do not pickle, configs do)::

    config YAML ─► simulate (discrete plant, sampled controller, spec's horizon) ─► errors, settling, peak force
               ├─► linearize_continuous (continuous plant and controller)         ─► eigenvalues (sampling not seen)
               └─► linearize_sampled_loop (one control period, central differences)   ─► multipliers (sampling seen)

Per point it records the parameters, the verdicts, the metrics below and, on
failure, the error text of every stage that failed (never dropped):

* ``stable_simulation``: the run finished with finite values and, over the
  last ``steady_window`` of the horizon, every velocity and force row stayed
  within ``steady_tolerance`` of its own command, in its own units (the rows of
  summary.json, ``metrics.max_row_errors``; one unit of the row when it is
  commanded to zero): never a norm across m/s and rad/s. Contact loss,
  chatter, limit cycles and blow-up all fail it.
* ``steady_*_error``, ``steady_*_error_percent``, ``steady_*_row``: the row of
  the group furthest outside that tolerance (relative to its scale): its max
  |e_i| over the window in its units, in % of its command (empty when
  commanded to zero), and its name and units; ``final_*_error`` is that row's
  |e_i| at the end.
* ``peak_force``, ``peak_force_row``: the measured force's peak |F_i| over the run
  in its row's units, for the row whose peak is largest relative to its command
  (one unit where commanded to zero), and that row's name and units.
* ``path_*``: a job's figures (``experiments.path_report``): the settled path error in all and along
  the surface (mm), the normal force error (%), the time off the surface (s) and the fraction of the
  path run; a job's steady window ends at its lift-off.
* ``stable_continuous``: every eigenvalue of the continuous closed loop,
  except the k = d - m marginal ones the law leaves (unregulated positions,
  ``analysis.predicted_eigenvalues``), has Re(s) < ``eigenvalue_margin``. The
  continuous linearization sees neither the control period nor the plant's
  time step: it is the verdict for continuous loops only.
* ``stable_discrete``: the same test on log(mu) / h for the multipliers mu of
  the one-period map (``analysis.linearize_sampled_loop``): it sees the sampling.
  A map that looks unstable is differentiated again at a ten times larger step
  (``discrete_step_check``). A growth seen at both steps is an instability,
  whichever mode grows (a predicted zero's partner too): False. If a regulated
  mode's instability is not there at the larger step, the map has a kink at the
  equilibrium (SAP), the linearization cannot decide, and the verdict is empty
  (None): ``stable`` is then the simulation's. A kink on a predicted zero's
  partner alone leaves the regulated modes' verdict (``_discrete_verdict``).
* ``stable``: the simulation's verdict and the linearization that models the
  simulated loop (discrete when the controller is sampled, continuous when
  it is not), both True; if one of them is missing, the other.
* ``worst_*_real``: the largest Re(s) over the non-marginal eigenvalues (1/s);
  ``marginal_*_real``: the largest over the marginal ones (a slow drift of
  the unregulated positions; reported, part of the verdict only where the
  step check confirms a growth: ``_discrete_verdict``);
  ``spectral_radius``: the largest |mu| over all multipliers.

Execution: ``workers=N`` starts a Dask ``LocalCluster`` of N single-threaded
worker processes; ``scheduler=ADDRESS`` uses an existing Dask cluster (its
workers need drake_hybrid installed); ``workers=0`` runs in this process
without Dask (the reference the tests compare against).

Size: one sweep point (simulation, linearizations, verdicts), its Dask execution and the
incremental results table belong together: the table's columns are the point's outputs.
"""

import copy
import csv
import json
import logging
import math
import os
import socket
import time
import traceback
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import yaml
from tqdm import tqdm

from drake_hybrid.analysis.linearization import (STEP_CHECK_RATE, linearize_continuous, linearize_sampled_loop,
                                                 predicted_eigenvalues)
from drake_hybrid.control import fast_compile
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.core.errors import GainError
from drake_hybrid.core.locks import process_alive
from drake_hybrid.core.progress import quiet
from drake_hybrid.experiments.config_paths import apply_parameters, set_config_value
from drake_hybrid.experiments.metrics import max_row_errors, row_scales
from drake_hybrid.experiments.path_report import before_lift_off
from drake_hybrid.experiments.simulation import RunStopped, simulate
from drake_hybrid.experiments.sweep_spec import StabilityCriteria, SweepSpecError, check_axis_values, parameters_digest
from drake_hybrid.tasks.config import dump_config, load_config
from drake_hybrid.tasks.registry import BUILT_IN_TASKS, TASKS, get_task, register_task

VERDICT_COLUMNS = ["stable", "stable_simulation", "stable_continuous", "stable_discrete"]
METRIC_COLUMNS = [
    "worst_continuous_real", "marginal_continuous_real",
    "worst_discrete_real", "marginal_discrete_real", "spectral_radius", "discrete_equilibrium_residual",
    "velocity_settling_time", "force_settling_time",
    "steady_velocity_error", "steady_force_error", "steady_velocity_error_percent", "steady_force_error_percent",
    "final_velocity_error", "final_force_error",
    "peak_force", "max_constraint_residual",
    "simulation_wall_time", "linearization_wall_time", "wall_time", "cpu_time",
    # A job's path (experiments.path_report; empty for other runs): settled path error in all and along
    # the surface (mm), normal force error (%), time off the surface (s), the fraction of the path run.
    "path_error_mm", "path_error_along_surface_mm", "path_force_error_percent", "path_time_off_surface",
    "path_fraction_run",
]
TEXT_COLUMNS = ["steady_velocity_row", "steady_force_row", "peak_force_row", "discrete_step_check", "worker", "error"]
RESULT_COLUMNS = VERDICT_COLUMNS + METRIC_COLUMNS + TEXT_COLUMNS
RESULTS_FILE = "results.csv"


# ------------------------------------------------------------------------------------------------
# One point
# ------------------------------------------------------------------------------------------------

def _worst_real(match):
    """(worst Re over the designed partners and the extra modes, worst Re over the marginal modes:
    the measured partners of the predicted zeros; see ``analysis.match_eigenvalues``)."""
    regulated = np.concatenate([np.asarray(match.partner), np.asarray(match.extra)])
    marginal = np.asarray(match.marginal_partners)
    worst = float(np.max(regulated.real)) if regulated.size else None
    return worst, (float(np.max(marginal.real)) if marginal.size else None)


def _discrete_verdict(worst_real, step_check, margin):
    """The sampled loop's verdict from the regulated modes' worst rate ``worst_real`` (stable below
    ``margin``) and the step check (``analysis.linearization.StepCheck``, made whenever any rate,
    marginal ones included, rose above STEP_CHECK_RATE at the step 1e-5):

    * a growth the check confirms, at or above ``margin`` at both steps, is an instability whichever
      mode grows (a predicted zero's partner too): False;
    * a regulated instability above STEP_CHECK_RATE that the check does not confirm is the SAP
      map's kink: no verdict (None);
    * otherwise the regulated modes' verdict: an unconfirmed growth of a predicted zero's partner
      alone leaves it (the window at 4 ms: +0.34 1/s at the step 1e-5, -1.7e-5 at 1e-4; the UR10
      plate: +3.86 and +1e-4)."""
    stable = worst_real < margin
    if step_check is None:
        return stable
    if step_check.confirmed and min(step_check.worst_real, step_check.larger_worst_real) >= margin:
        return False
    if not stable and worst_real > STEP_CHECK_RATE and not step_check.confirmed:
        return None
    return stable


def steady_rows(log, summary, what, after, tolerance):
    """The steady-window verdict of one group of rows (``what``: "velocity" or "force"), per row in
    its own units (``metrics.max_row_errors``, as summary.json's rows): each row's max |e_i| over
    t >= ``after`` within ``tolerance`` times its scale (``metrics.row_scales``: its command, or where
    it is commanded to zero the largest command in its units, else one of its units). Returns (settled, the worst row's (max |e_i|, % of its command or None,
    "name (units)", index)), the worst row being the one furthest out relative to its scale."""
    desired = log.get(f"true_desired_{what}", log[f"desired_{what}"])     # the true rows' command (pseudo-velocity)
    rows = getattr(summary, f"{what}_rows")
    units = [row.units for row in rows]
    figures = max_row_errors(log["t"], log[f"{what}_error"], desired, after, units, fallback="unit")
    scales = row_scales(desired, units, fallback="unit")[0]
    ratios = [error / scale for (error, _), scale in zip(figures, scales)]
    worst = int(np.argmax(ratios))
    row = rows[worst]
    return (all(ratio <= tolerance for ratio in ratios),
            (figures[worst][0], figures[worst][1], f"{row.name} ({row.units})", worst))


def peak_row_force(log, summary):
    """The force row whose peak |F_i| over the run is largest relative to its scale (``metrics.row_scales``,
    as ``steady_rows``'s): (that peak in the row's units,
    "name (units)"). Per row, never a norm across rows (the crank's mix N and N m)."""
    force = np.abs(np.asarray(log["force"], dtype=float)).reshape(len(log["t"]), -1)
    peaks = np.max(force, axis=0)
    scales = row_scales(log["desired_force"], [row.units for row in summary.force_rows], fallback="unit")[0]
    worst = int(np.argmax(peaks / scales))
    row = summary.force_rows[worst]
    return float(peaks[worst]), f"{row.name} ({row.units})"


def simulation_metrics(result, criteria):
    """The simulation's columns from a SimulationResult (see the module docstring). A job's run ends, for
    the steady window, at its lift-off (leaving the surface is not an error)."""
    log, summary = before_lift_off(result.log), result.summary
    t = log["t"]
    finite = all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in log.values())
    after = t[-1] - criteria.steady_window * (t[-1] - t[0])
    velocity_settled, velocity = steady_rows(log, summary, "velocity", after, criteria.steady_tolerance)
    force_settled, force = steady_rows(log, summary, "force", after, criteria.steady_tolerance)
    peak_force, peak_force_row = peak_row_force(log, summary)
    return {
        "stable_simulation": bool(finite and velocity_settled and force_settled),
        "velocity_settling_time": summary.velocity_settling_time_1_percent,
        "force_settling_time": summary.force_settling_time_1_percent,
        "steady_velocity_error": velocity[0],
        "steady_force_error": force[0],
        "steady_velocity_error_percent": velocity[1],
        "steady_force_error_percent": force[1],
        "steady_velocity_row": velocity[2],
        "steady_force_row": force[2],
        "final_velocity_error": float(abs(log["velocity_error"][-1, velocity[3]])),
        "final_force_error": float(abs(log["force_error"][-1, force[3]])),
        "peak_force": peak_force,
        "peak_force_row": peak_force_row,
        "max_constraint_residual": summary.max_constraint_residual,
        "simulation_wall_time": summary.wall_time,
        **path_columns(summary.path),
    }


def path_columns(report):
    """The path columns of a job's ``summary.path`` (a ``PathReport``; none for another run: None)."""
    if report is None:
        return {}
    return {"path_error_mm": report.max_path_error_mm,
            "path_error_along_surface_mm": report.max_path_error_along_surface_mm,
            "path_force_error_percent": report.max_force_error_percent,
            "path_time_off_surface": report.time_off_surface_s,
            "path_fraction_run": report.arc_length_reached_m / report.length_m if report.length_m else None}


def _stage_error(stage, error):
    text = f"{type(error).__name__}: {error}".strip()
    if not str(error).strip():      # an error without a message: keep where it came from
        text += " | " + traceback.format_exc(limit=-3).replace("\n", " | ")
    return f"{stage}: {text}"


def evaluate_point(config_yaml, criteria=None, continuous=True, discrete=True, task=None, stages=None):
    """Evaluate one sweep point from its config YAML; returns the result columns as a dict.

    ``task``: a task object that is not built in (a ``CustomTask``), registered in this process
    first: Dask workers are other processes and do not share the registry of the one that
    registered it, so the task is shipped with the point (pickled with cloudpickle).

    Each stage (simulation, continuous and discrete linearization) runs on its
    own: a failing stage leaves its columns empty and adds its error text to
    ``error``; the others still run. ``stages`` (``core.progress.Stages``, default silent) times
    them: the config, the simulation's own stages (building, the start, initializing, with the
    simulated run as "simulation"), each linearization (benchmarks/sweep_throughput.py reads
    ``stages.times``).

    Every point runs the compiled law (``fast_compile.foreground``: compiled at a worker's first point
    where its machine has none yet), so that no figure depends on when a background compile finished."""
    with fast_compile.foreground():
        return _evaluate_point(config_yaml, criteria, continuous, discrete, task, stages or quiet())


def _evaluate_point(config_yaml, criteria, continuous, discrete, task, stages):
    criteria = StabilityCriteria(**(criteria or {}))
    start, cpu_start = time.perf_counter(), time.process_time()
    row = {column: None for column in RESULT_COLUMNS}
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    errors = []
    if task is not None and TASKS.get(task.name) is not task:
        register_task(task)
    try:
        with stages("config"):
            config = load_config(data=config_yaml)
    except Exception as error:
        row.update(error=_stage_error("config", error), wall_time=time.perf_counter() - start)
        return row
    try:
        with stages("simulation"):
            result = simulate(config, stages=stages)
        row.update(simulation_metrics(result, criteria))
    except RunStopped as stopped:            # a fault or an error mid-run: never a stable point
        row["stable_simulation"] = False
        errors.append(f"simulation: {stopped}")
    except Exception as error:
        errors.append(_stage_error("simulation", error))
    linearization_start = time.perf_counter()
    if continuous:
        try:
            with stages("continuous linearization"):
                linear = linearize_continuous(config)
            row["worst_continuous_real"], row["marginal_continuous_real"] = _worst_real(linear.match)
            row["stable_continuous"] = row["worst_continuous_real"] < criteria.eigenvalue_margin
        except Exception as error:
            errors.append(_stage_error("continuous linearization", error))
    if discrete and config.control_period > 0:
        try:
            with stages("discrete linearization"):
                linear = linearize_sampled_loop(config)
            row["worst_discrete_real"], row["marginal_discrete_real"] = _worst_real(linear.match)
            row["spectral_radius"] = float(np.max(np.abs(linear.multipliers)))
            row["discrete_equilibrium_residual"] = linear.equilibrium_residual
            row["stable_discrete"] = _discrete_verdict(row["worst_discrete_real"], linear.step_check,
                                                       criteria.eigenvalue_margin)
            if linear.step_check is not None:
                row["discrete_step_check"] = linear.step_check.summary()
        except Exception as error:
            errors.append(_stage_error("discrete linearization", error))
    row["linearization_wall_time"] = time.perf_counter() - linearization_start
    linear_verdict = row["stable_discrete"] if config.control_period > 0 else row["stable_continuous"]
    verdicts = [v for v in (row["stable_simulation"], linear_verdict) if v is not None]
    row["stable"] = all(verdicts) if verdicts else None
    row["error"] = " || ".join(errors) or None
    row["wall_time"] = time.perf_counter() - start
    row["cpu_time"] = time.process_time() - cpu_start      # well below wall_time: the core was shared
    return row


# ------------------------------------------------------------------------------------------------
# The results table (CSV, appended point by point)
# ------------------------------------------------------------------------------------------------

def _cell(value):
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, (bool, np.bool_)):
        return "True" if value else "False"
    if isinstance(value, (float, np.floating)):
        return repr(float(value))            # round-trips exactly
    return str(value)


def _parse_cell(column, text):
    if text == "":
        return None
    if column in VERDICT_COLUMNS:
        return text == "True"
    if column in TEXT_COLUMNS:
        return text
    try:
        return int(text) if column == "point" else float(text)
    except ValueError:
        return text                           # a non-numeric parameter value (e.g. a mode name)


class ResultsTable:
    """``results.csv``: a header, then one row per finished point, flushed as it arrives."""

    def __init__(self, path, columns):
        self.path = Path(path)
        self.columns = list(columns)
        if self.path.exists():
            self.repair()
            with self.path.open(newline="") as f:
                header = next(csv.reader(f), None)
            if header != self.columns:
                raise SweepSpecError(f"{self.path} has columns {header}, this sweep writes {self.columns}")
        else:
            with self.path.open("w", newline="") as f:
                csv.writer(f).writerow(self.columns)

    def repair(self):
        """Drop a torn last line (a write cut off mid-row: no final newline, or too few cells); its
        point is then missing and runs again. Returns the number of lines dropped."""
        data = self.path.read_bytes()
        if not data:
            return 0
        lines = data.split(b"\n")
        dropped = 0
        if lines[-1] != b"":                     # no final newline: the last row was cut off
            lines, dropped = lines[:-1] + [b""], 1
        if len(lines) > 2:
            last = next(csv.reader([lines[-2].decode(errors="replace")]), [])
            if len(last) != len(self.columns):
                lines, dropped = lines[:-2] + [b""], dropped + 1
        if dropped:
            self.path.write_bytes(b"\n".join(lines))
        return dropped

    def append(self, row):
        with self.path.open("a", newline="") as f:
            csv.writer(f).writerow([_cell(row.get(column)) for column in self.columns])
            f.flush()
            os.fsync(f.fileno())


def read_results(path):
    """The rows of a results.csv as dicts (numbers as float, verdicts as bool, empty cells as None),
    sorted by point index."""
    path = Path(path)
    if path.is_dir():
        path = path / RESULTS_FILE
    latest = {}
    with path.open(newline="") as f:
        for row in csv.DictReader(f):
            if None in row or None in row.values():   # a torn row (too many or too few cells): not a result
                continue
            row = {k: _parse_cell(k, v) for k, v in row.items()}
            latest[row["point"]] = row             # a retried point's last row wins
    return [latest[i] for i in sorted(latest)]


def column(rows, name):
    """One column of ``rows`` as a float array (None -> nan; verdicts as 1.0 / 0.0)."""
    return np.array([np.nan if row.get(name) is None else float(row[name]) for row in rows])


# ------------------------------------------------------------------------------------------------
# Running a sweep
# ------------------------------------------------------------------------------------------------

class SweepLock:
    """``out/.lock``: one sweep at a time writes a results table. A lock whose process is gone
    (killed) is taken over; one held by a live process is a SweepSpecError naming it."""

    def __init__(self, out):
        self.path = Path(out) / ".lock"

    def __enter__(self):
        self.path.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(2):
            try:
                descriptor = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                holder = self._holder()
                if holder is not None and process_alive(holder):
                    raise SweepSpecError(f"{self.path.parent} is being written by another sweep (process {holder}); "
                                         "wait for it or use another output directory") from None
                self.path.unlink(missing_ok=True)    # the holder died: take the lock over
                continue
            with os.fdopen(descriptor, "w") as f:
                f.write(str(os.getpid()))
            return self
        raise SweepSpecError(f"could not take the lock {self.path}")

    def __exit__(self, *exc):
        self.path.unlink(missing_ok=True)
        return False

    def _holder(self):
        try:
            return int(self.path.read_text().strip())
        except (OSError, ValueError):
            return None


def _check_scheduler(address, timeout=10.0):
    """SweepSpecError (one line) if no Dask scheduler answers at ``address`` within ``timeout`` s."""
    from distributed import Client  # Dask only where a sweep runs on it (tests/test_architecture.py)

    try:
        client = Client(address, timeout=timeout)
    except (OSError, TimeoutError) as error:
        raise SweepSpecError(f"--scheduler {address}: no Dask scheduler answers there ({type(error).__name__}); "
                             "nothing was written") from None
    client.close()


@dataclass
class SweepRun:
    out_dir: Path
    results_path: Path
    points: int            # in the spec
    evaluated: int         # in this run
    failures: int          # rows with an error, in the whole table
    wall_time: float       # of this run (s)
    workers: str           # "serial", "local:N" or the scheduler address


def sweep_points(task_name, spec):
    """(base config, [(index, parameters, point config YAML)]) for ``spec`` on ``task_name``."""
    if spec.task is not None and spec.task != task_name:
        raise SweepSpecError(f"the sweep spec is for task '{spec.task}', not '{task_name}'")
    task = get_task(task_name)
    try:
        base = apply_parameters(task.default_config(), spec.base)
    except ValueError as error:
        raise SweepSpecError(f"base: {error}") from None
    check_axis_values(spec, base)              # every value given, checked like a config field
    points = []
    for index, parameters in enumerate(spec.points()):
        try:
            config = apply_parameters(base, parameters)
        except ValueError as error:
            raise SweepSpecError(f"point {index}: {error}") from None
        points.append((index, parameters, dump_config(config)))
    return base, points


def _prepare_out_dir(out, task_name, spec, base, points, resume):
    out.mkdir(parents=True, exist_ok=True)
    # The digest covers everything that changes a row: the task, every point's config and the verdicts' settings.
    settings = {"stability": asdict(spec.stability), "continuous": spec.linearize_continuous,
                "discrete": spec.linearize_discrete}
    manifest = {"task": task_name, "points": len(points),
                "digest": parameters_digest([task_name, settings] + [[p, y] for _, p, y in points]),
                "parameters": spec.paths}
    manifest_path = out / "manifest.json"
    results_path = out / RESULTS_FILE
    if results_path.exists() and not resume:
        raise SweepSpecError(f"{results_path} exists: pass --resume to continue it, "
                             "or choose another output directory")
    if resume and results_path.exists() and not manifest_path.exists():
        raise SweepSpecError(f"--resume: {out} has results but no manifest.json, so its sweep cannot be checked; "
                             "use another output directory")
    if resume and manifest_path.exists():
        previous = json.loads(manifest_path.read_text())
        if previous.get("digest") != manifest["digest"]:
            raise SweepSpecError(f"--resume: {out} holds a different sweep ({previous.get('task')}, "
                                 f"{previous.get('points')} points, parameters {previous.get('parameters')}); "
                                 "use the same spec and task, or another output directory")
    manifest_path.write_text(json.dumps(manifest, indent=2))
    (out / "spec.yaml").write_text(yaml.safe_dump(spec.source, sort_keys=False))
    (out / "base_config.yaml").write_text(dump_config(base))
    return results_path


WORKER_MEMORY = "4GB"


def _start_client(scheduler, workers, worker_memory=WORKER_MEMORY):
    """A client of the cluster at ``scheduler``, or of a new LocalCluster of ``workers`` processes.

    Drake 1.51 never frees a diagram that holds Python LeafSystems (drake#22515,
    drake#23161): a worker grows by about 10 to 30 MB per point here. The local
    cluster's nannies therefore restart a worker whose memory passes 95 % of
    ``worker_memory`` (no spilling, no pausing: a paused worker would never
    shrink); the point it was running is run again elsewhere."""
    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        return Client(scheduler), None, scheduler
    memory = {"target": False, "spill": False, "pause": False, "terminate": 0.95}
    # The nannies read the terminate threshold when they start; a restarted worker gets ``config``.
    with dask.config.set({f"distributed.worker.memory.{key}": value for key, value in memory.items()}):
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                               memory_limit=worker_memory, silence_logs=logging.ERROR,
                               config=copy.deepcopy(dask.config.config))
    return Client(cluster), cluster, f"local:{workers}"


def run_sweep(task_name, spec, out_dir, scheduler=None, workers=2, resume=False, retry_failed=False,
              progress=True, worker_memory=WORKER_MEMORY):
    """Evaluate the points of ``spec`` missing from ``out_dir/results.csv`` and append them.

    ``workers``: worker processes of the local Dask cluster (0: this process,
    no Dask); ignored with ``scheduler`` (an existing cluster's address).
    ``resume``: continue a table from the same spec and task (checked by a
    digest of the points); ``retry_failed`` also re-runs points whose row
    has an error (the new row is appended; ``read_results`` keeps the last
    row of a point). ``worker_memory``: memory limit of each local worker
    (restarted past 95 %; see ``_start_client``)."""
    if not (isinstance(workers, int) and workers >= 0):
        raise ValueError(f"workers must be a non-negative integer, got {workers!r}")
    out = Path(out_dir)
    base, points = sweep_points(task_name, spec)
    if scheduler:
        _check_scheduler(scheduler)                 # before anything is written
    with SweepLock(out):
        return _run_locked(task_name, spec, out, base, points, scheduler, workers, resume, retry_failed, progress,
                           worker_memory)


def _run_locked(task_name, spec, out, base, points, scheduler, workers, resume, retry_failed, progress,
                worker_memory):
    results_path = _prepare_out_dir(out, task_name, spec, base, points, resume)
    columns = ["point"] + spec.paths + RESULT_COLUMNS
    table = ResultsTable(results_path, columns)
    finished = {row["point"]: row for row in read_results(results_path)}
    expected = {index: parameters for index, parameters, _ in points}
    for index, row in finished.items():
        if index not in expected or any(_parse_cell(path, _cell(value)) != row.get(path)
                                        for path, value in expected[index].items()):
            raise SweepSpecError(f"{results_path}: the row of point {index} has parameters "
                                 f"{ {path: row.get(path) for path in spec.paths} }, not this sweep's "
                                 f"{expected.get(index)}; use another output directory")
    done = {i for i, row in finished.items() if not (retry_failed and row.get("error"))}
    pending = [p for p in points if p[0] not in done]
    failures = sum(1 for i in done if finished[i].get("error"))
    options = {"criteria": asdict(spec.stability), "continuous": spec.linearize_continuous,
               "discrete": spec.linearize_discrete}
    if task_name not in BUILT_IN_TASKS:
        options["task"] = get_task(task_name)   # a registered custom task travels with its points (cloudpickle)
    start = time.perf_counter()
    bar = tqdm(total=len(points), initial=len(done), desc=f"sweep {task_name}", unit="pt", disable=not progress,
               dynamic_ncols=True)
    bar.set_postfix(failures=failures)

    def record(index, parameters, row):
        nonlocal failures
        row = dict(row, point=index, **parameters)
        table.append(row)
        failures += bool(row.get("error"))
        bar.update(1)
        bar.set_postfix(failures=failures)

    where = "serial" if pending else "nothing to run"
    try:
        if workers == 0 and not scheduler:
            for index, parameters, config_yaml in pending:
                record(index, parameters, evaluate_point(config_yaml, **options))
        elif pending:
            from distributed import as_completed

            client, cluster, where = _start_client(scheduler, workers, worker_memory)
            try:
                futures = {client.submit(evaluate_point, config_yaml, pure=False, **options): (index, parameters)
                           for index, parameters, config_yaml in pending}
                for future in as_completed(futures):
                    index, parameters = futures.pop(future)
                    try:
                        row = future.result()
                    except Exception as error:   # the worker died (e.g. a crash in C++): keep the point
                        row = {"error": _stage_error("worker", error)}
                    future.release()             # the worker may drop the result (a restart will not redo it)
                    record(index, parameters, row)
            finally:
                client.close()
                if cluster is not None:
                    cluster.close()
    finally:
        bar.close()
    return SweepRun(out_dir=out, results_path=results_path, points=len(points), evaluated=len(pending),
                    failures=failures, wall_time=time.perf_counter() - start, workers=where)


# ------------------------------------------------------------------------------------------------
# The theory's verdict (for the stability map's overlay)
# ------------------------------------------------------------------------------------------------

def rigid_contact_theory_stable(config, sizes=None):
    """The paper's verdict on ``config``: with rigid contact, an exact model and a continuous
    controller the errors obey (3.1-14), (3.1-15) (Remark 3, (3.2-11) in the other modes), so the
    loop is stable iff the designed eigenvalues (-eig(K_v) or the roots of s^2 + K_v s + K_p, and
    eig(-(I + K_fp)^-1 K_fi)) are in the open left half-plane. None when the gains are outside the
    law's admissible set (GainError). The theory sees no contact stiffness and no sampling.
    ``sizes``: (d - m, m) if known (saves building the task's constraint)."""
    velocity_size, force_size = sizes or constraint_sizes(config)
    mode = ControlMode.parse(config.mode)
    try:
        gains = config.gains.matrices(velocity_size, force_size, mode)
    except GainError:
        return None
    return bool(np.all(predicted_eigenvalues(gains, mode).designed.real < 0))


def constraint_sizes(config):
    """(d - m, m): the velocity- and force-controlled dimensions of ``config``'s task."""
    space = get_task(config.task).constraint_space(config)
    return space.velocity_size, space.force_size


def theory_on_plane(base_config, x_path, y_path, x_values, y_values, fixed=None):
    """``rigid_contact_theory_stable`` over the (x, y) plane (other fields from ``fixed`` and the base):
    an array (len(y_values) x len(x_values)) of 1.0 (stable), 0.0 (unstable) and nan (not admissible)."""
    sizes = constraint_sizes(base_config)
    verdict = np.full((len(y_values), len(x_values)), np.nan)
    for i, y in enumerate(y_values):
        for j, x in enumerate(x_values):
            config = copy.deepcopy(base_config)
            for path, value in {**(fixed or {}), x_path: x, y_path: y}.items():
                set_config_value(config, path, value)
            stable = rigid_contact_theory_stable(config, sizes)
            verdict[i, j] = np.nan if stable is None else float(stable)
    return verdict
