"""One point of a sweep: its simulation, its linearizations, its verdicts and metrics, as the row
of the results table (``experiments.sweep_results``) that ``experiments.sweep.run_sweep`` writes.

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
* ``patch_*``: a disc's contact patch at the end of the run (``experiments.patch_report``): the centre of
  pressure's distance from the tool's axis (mm), its tilt against the real surface (deg), the share of its face
  in contact and the pressure's normal force (N); ``path_contact_losses``: how often the contact was lost.
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
"""

import os
import socket
import time
import traceback

import numpy as np

from drake_hybrid.analysis.discrete_linearization import STEP_CHECK_RATE, linearize_sampled_loop
from drake_hybrid.analysis.linearization import linearize_continuous
from drake_hybrid.control import fast_compile
from drake_hybrid.core.progress import quiet
from drake_hybrid.experiments.metrics import max_row_errors, row_scales
from drake_hybrid.experiments.path_report import before_lift_off
from drake_hybrid.experiments.simulation import RunStopped, simulate
from drake_hybrid.experiments.sweep_spec import StabilityCriteria
from drake_hybrid.tasks.config import load_config
from drake_hybrid.tasks.registry import TASKS, register_task

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
    "path_fraction_run", "path_contact_losses",
    # A disc's contact patch (experiments.patch_report; empty for other runs): at the end, the centre of pressure
    # from the axis (mm), the tilt against the real surface (deg), the face in contact (1), the normal force (N).
    "patch_cop_offset_mm", "patch_tilt_deg", "patch_area_fraction", "patch_normal_force",
]
TEXT_COLUMNS = ["steady_velocity_row", "steady_force_row", "peak_force_row", "discrete_step_check", "worker", "error"]
RESULT_COLUMNS = VERDICT_COLUMNS + METRIC_COLUMNS + TEXT_COLUMNS


def _worst_real(match):
    """(worst Re over the designed partners and the extra modes, worst Re over the marginal modes:
    the measured partners of the predicted zeros; see ``analysis.match_eigenvalues``)."""
    regulated = np.concatenate([np.asarray(match.partner), np.asarray(match.extra)])
    marginal = np.asarray(match.marginal_partners)
    worst = float(np.max(regulated.real)) if regulated.size else None
    return worst, (float(np.max(marginal.real)) if marginal.size else None)


def _discrete_verdict(worst_real, step_check, margin):
    """The sampled loop's verdict from the regulated modes' worst rate ``worst_real`` (stable below
    ``margin``) and the step check (``analysis.discrete_linearization.StepCheck``, made whenever any rate,
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
    it is commanded to zero the largest command in its units, else one of its units). Returns (settled,
    the worst row's (max |e_i|, % of its command or None, "name (units)", index)), the worst row being
    the one furthest out relative to its scale."""
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
        **patch_columns(summary.patch),
    }


def path_columns(report):
    """The path columns of a job's ``summary.path`` (a ``PathReport``; none for another run: None)."""
    if report is None:
        return {}
    return {"path_error_mm": report.max_path_error_mm,
            "path_error_along_surface_mm": report.max_path_error_along_surface_mm,
            "path_force_error_percent": report.max_force_error_percent,
            "path_time_off_surface": report.time_off_surface_s,
            "path_fraction_run": report.arc_length_reached_m / report.length_m if report.length_m else None,
            "path_contact_losses": report.contact_losses}


def patch_columns(report):
    """The patch columns of a disc's ``summary.patch`` (a ``PatchReport``; none for another run: None)."""
    if report is None:
        return {}
    return {"patch_cop_offset_mm": report.final_cop_offset_mm, "patch_tilt_deg": report.final_tilt_deg,
            "patch_area_fraction": report.final_area_fraction, "patch_normal_force": report.final_normal_force}


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
