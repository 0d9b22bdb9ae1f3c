"""Figures used by the CLI, the tutorials and the docs (matplotlib, Agg-safe).

* ``tracking_figure``: velocity and force tracking against the designed
  (predicted) exponential response.
* ``save_tracking_plots``: the two PNGs a run writes.
* ``eigenvalue_figure``: predicted against measured closed-loop eigenvalues.
"""

from pathlib import Path

import numpy as np


def _pyplot():
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "module://matplotlib_inline.backend_inline"):
        try:
            matplotlib.use("Agg")
        except Exception:  # pragma: no cover - backend already fixed by the caller
            pass
    import matplotlib.pyplot as plt

    return plt


def _tracking_axes(ax_values, ax_errors, t, actual, desired, predicted, labels, what):
    for i in range(actual.shape[1]):
        label = labels[i] if i < len(labels) else f"{what} {i + 1}"
        line, = ax_values.plot(t, actual[:, i], lw=1.6, label=f"{label}: measured")
        ax_values.plot(t, desired[:, i], color=line.get_color(), ls=":", lw=1.2, label=f"{label}: commanded")
        ax_values.plot(t, predicted[:, i], color="k", ls="--", lw=0.9, label=f"{label}: predicted" if i == 0 else None)
        ax_errors.semilogy(t, np.abs(actual[:, i] - desired[:, i]) + 1e-12, color=line.get_color(), lw=1.4,
                           label=f"|error| {label}")
        ax_errors.semilogy(t, np.abs(predicted[:, i] - desired[:, i]) + 1e-12, color="k", ls="--", lw=0.9,
                           label="predicted" if i == 0 else None)
    ax_values.legend(fontsize=7, loc="best")
    ax_errors.legend(fontsize=7, loc="best")
    ax_errors.set_xlabel("time t (s)")
    ax_values.grid(alpha=0.3)
    ax_errors.grid(alpha=0.3, which="both")


def tracking_figure(log, summary, predicted, what, labels=(), units=""):
    """Measured, commanded and predicted ``what`` ("velocity" or "force") and the error on a log scale."""
    plt = _pyplot()
    fig, (ax_values, ax_errors) = plt.subplots(2, 1, figsize=(7.5, 6.0), sharex=True)
    actual, desired = log[what], log[f"desired_{what}"]
    _tracking_axes(ax_values, ax_errors, log["t"], actual, desired, predicted, labels, what)
    ax_values.set_ylabel(f"{what} ({units})" if units else what)
    ax_errors.set_ylabel(f"|{what} error| ({units})" if units else f"|{what} error|")
    one_percent = 0.01 * summary["command_scales"]["speed" if what == "velocity" else "force"]
    ax_errors.axhline(one_percent, color="gray", lw=0.8, ls="-.", label="1 % of command")
    ax_errors.axvline(5 * summary["design_time_constant"], color="gray", lw=0.8, ls=":")
    ax_values.set_title(f"{summary['task']} ({summary['mode']}): {what} tracking vs. the designed exponential")
    fig.tight_layout()
    return fig


def save_tracking_plots(log, summary, predicted_velocity, predicted_force, out_dir, labels=None):
    """Write velocity_tracking.png and force_tracking.png; returns their paths."""
    plt = _pyplot()
    labels = labels or {}
    out = Path(out_dir)
    paths = []
    for what, predicted in (("velocity", predicted_velocity), ("force", predicted_force)):
        fig = tracking_figure(log, summary, predicted, what, labels.get(what, ()),
                              units=labels.get(f"{what}_units", ""))
        path = out / f"{what}_tracking.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        paths.append(path)
    return paths


def eigenvalue_figure(match, title="closed-loop eigenvalues", zoom=None):
    """Predicted (crosses) and measured (dots) eigenvalues in the complex plane."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    measured, predicted = np.asarray(match.measured), np.asarray(match.predicted)
    ax.scatter(measured.real, measured.imag, s=22, color="tab:blue", label="linearized closed loop")
    ax.scatter(predicted.real, predicted.imag, s=80, marker="x", color="tab:red", label="designed (gains)")
    ax.axvline(0, color="k", lw=0.8)
    ax.set_xlabel("Re(s) (1/s)")
    ax.set_ylabel("Im(s) (rad/s)")
    if zoom is not None:
        ax.set_xlim(*zoom[0])
        ax.set_ylim(*zoom[1])
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(title)
    fig.tight_layout()
    return fig
