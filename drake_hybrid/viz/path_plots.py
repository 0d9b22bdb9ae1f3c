"""Figures of a job's path (``station.path_job``): the path on the workpiece seen from above, and
the path and force errors along it with the contact supervisor's phases.

* ``path_top_view_figure``: the reference path of the pad centre and where the pad centre went, in
  the world's x-y plane (the view patterns are drawn in), coloured by the distance along the surface
  from the reference (mm); the first contact and the lift-off marked.
* ``path_error_figure``: over time, the path error (along the surface, along the normal: the pad's
  compression) in mm and the normal force error in % of the command; the phases (approach, dwell,
  path, lift-off) shaded, each segment's start and its five design time constants marked.
* ``save_path_plots``: writes both (path_top_view.png, path_errors.png); ``write_run`` calls it for a
  job.

Each takes the run's log and its summary (an ``experiments.summary.RunSummary``: its task's name, its
``path`` report's segments).
"""

from pathlib import Path

import numpy as np

from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.experiments.path_report import error_parts, lift_off_time
from drake_hybrid.viz.figure_base import _pyplot


def _phases(log):
    """[(start, end, label)] of the job's phases from the log (supervisor, path progress, lift-off)."""
    t = np.asarray(log["t"], dtype=float)
    t_path = np.asarray(log["path_progress"], dtype=float)[:, 2]
    end = float(t[-1])
    lift = lift_off_time(log)
    spans = []
    if "contact_phase" in log:
        contact = np.nonzero(np.asarray(log["contact_phase"])[:, 0] == float(ContactPhase.CONTACT))[0]
        first = float(t[contact[0]]) if contact.size else end
        if first > t[0]:
            spans.append((float(t[0]), first, "guarded approach"))
    else:
        first = float(t[0])
    started = np.nonzero(t_path >= 0)[0]
    path_start = float(t[started[0]]) if started.size else end
    if path_start > first:
        spans.append((first, path_start, "pressing at the first point (dwell)"))
    done = lift if lift is not None else end
    spans.append((path_start, done, "path"))
    if lift is not None:
        spans.append((lift, end, "lift-off"))
    return spans


def path_top_view_figure(log, summary=None, title=None):
    """The reference path and the pad centre's, from above (module docstring)."""
    plt = _pyplot()
    reference = np.asarray(log["reference_position"], dtype=float)
    actual = reference + np.asarray(log["path_error"], dtype=float)
    t_path = np.asarray(log["path_progress"], dtype=float)[:, 2]
    _, along, _ = error_parts(log)
    fig, ax = plt.subplots(figsize=(6.5, 6.0))
    ax.plot(reference[:, 0], reference[:, 1], color="0.6", lw=2.5, label="reference (pad centre)")
    running = t_path >= 0
    points = ax.scatter(actual[running, 0], actual[running, 1], c=1000.0 * along[running], s=2, cmap="viridis",
                        label="pad centre on the path")
    ax.plot(actual[~running, 0], actual[~running, 1], color="tab:orange", lw=1.0, label="before the path (approach)")
    lift = lift_off_time(log)
    if lift is not None:
        after = np.asarray(log["t"]) >= lift
        ax.plot(actual[after, 0], actual[after, 1], "x", color="tab:red", ms=4, label="lift-off")
    ax.plot(*actual[0, :2], "o", color="tab:orange", label="start (above the first point)")
    fig.colorbar(points, ax=ax, label="distance from the reference along the surface (mm)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    name = f"{summary.task}: " if summary is not None else ""
    ax.set_title(title or f"{name}the path from above (world x-y)", fontsize=10)
    fig.tight_layout()
    return fig


def path_error_figure(log, summary):
    """Path and force errors over the job, its phases shaded (module docstring)."""
    plt = _pyplot()
    t = np.asarray(log["t"], dtype=float)
    total, along, normal = (1000.0 * e for e in error_parts(log))
    force, desired = np.asarray(log["force"])[:, 0], np.asarray(log["desired_force"])[:, 0]
    fig, (ax_path, ax_force) = plt.subplots(2, 1, figsize=(8.0, 6.0), sharex=True)
    ax_path.semilogy(t, np.maximum(along, 1e-6), lw=0.9, label="along the surface")
    ax_path.semilogy(t, np.maximum(normal, 1e-6), lw=0.9, label="along the normal (the pad's compression)")
    ax_path.semilogy(t, np.maximum(total, 1e-6), lw=0.6, color="k", alpha=0.5, label="in all")
    ax_path.axhline(1.0, color="tab:red", lw=0.8, ls="-.", label="1 mm")
    ax_path.set_ylabel("path error (mm)")
    percent = 100.0 * np.abs(force - desired) / np.maximum(np.abs(desired), 1e-12)
    ax_force.semilogy(t, np.maximum(percent, 1e-6), lw=0.9, color="tab:purple", label="|F - F_d| / F_d")
    ax_force.axhline(2.0, color="tab:red", lw=0.8, ls="-.", label="2 %")
    ax_force.set_ylabel("normal force error (% of F_d)")
    ax_force.set_xlabel("time t (s)")
    spans = _phases(log)
    colors = {"guarded approach": "tab:orange", "pressing at the first point (dwell)": "tab:olive",
              "path": "tab:green", "lift-off": "tab:red"}
    report = summary.path if summary is not None else None
    settle = report.settle_time_per_segment_s if report is not None else None
    for ax in (ax_path, ax_force):
        for start, end, label in spans:
            ax.axvspan(start, end, color=colors.get(label, "0.8"), alpha=0.08, lw=0,
                       label=label if ax is ax_path else None)
        for segment in report.segments if report is not None else ():
            ax.axvline(segment.start, color="0.5", lw=0.5, ls=":")
            if settle:
                ax.axvspan(segment.start, min(segment.start + settle, segment.end), color="0.5", alpha=0.06, lw=0)
        ax.grid(alpha=0.3, which="both")
    ax_path.legend(fontsize=7, loc="upper right")
    ax_force.legend(fontsize=7, loc="upper right")
    title = f"{summary.task}: path and force errors along the job" if summary is not None else "path and force errors"
    if settle:
        title += (f"\ndotted: each segment's start; grey: its first five design time constants ({settle:.2f} s), "
                  "the transient at a line change")
    ax_path.set_title(title, fontsize=9)
    fig.tight_layout()
    return fig


def save_path_plots(log, summary, out_dir):
    """Write path_top_view.png and path_errors.png; returns their paths."""
    plt = _pyplot()
    paths = []
    for name, fig in (("path_top_view", path_top_view_figure(log, summary)),
                      ("path_errors", path_error_figure(log, summary))):
        path = Path(out_dir) / f"{name}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths
