"""The files of a run: log.npz, summary.json, config.yaml, the plots and, when asked, the animation."""

from pathlib import Path

import numpy as np

from drake_hybrid.experiments.simulation import effort_limits, predicted_tracking
from drake_hybrid.tasks.config import dump_config
from drake_hybrid.viz.patch_plots import save_patch_plots
from drake_hybrid.viz.path_plots import save_path_plots
from drake_hybrid.viz.run_plots import save_run_plots, save_tracking_plots


def write_run(result, out_dir, plots=True, html_path=None):
    """Write log.npz, summary.json, config.yaml and the plots (tracking, constraint residual, torques;
    a job's path; a disc's contact patch) to ``out_dir``, and the recorded animation (``result.html``, if any)
    to ``html_path``
    when one is given (``--html FILE``; the animation's only copy). Returns the paths written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(out / "log.npz", **result.log)
    (out / "summary.json").write_text(result.summary.to_json())
    (out / "config.yaml").write_text(dump_config(result.config))
    files = [out / "log.npz", out / "summary.json", out / "config.yaml"]
    if plots and len(result.log["t"]) >= 2:
        predicted_velocity, predicted_force = predicted_tracking(result.scenario, result.config, result.log)
        labels = result.scenario.task.labels(result.config)
        # The tracking plots read the summary as summary.json holds it (a dict).
        files += save_tracking_plots(result.log, result.summary.as_dict(), predicted_velocity, predicted_force, out,
                                     labels=labels)
        files += save_run_plots(result.log, effort_limits(result.scenario), out,
                                constraint_units=labels.get("constraint_units", "units of C"),
                                constraint_note=labels.get("constraint_note"))
        if "path_progress" in result.log:                   # a job's path (station.path_job)
            files += save_path_plots(result.log, result.summary, out)
        if "patch" in result.log and result.scenario.diagram is not None:    # a disc's contact patch
            files += save_patch_plots(result, out)
    if html_path and result.html:
        Path(html_path).write_text(result.html)
        files.append(Path(html_path))
    return files
