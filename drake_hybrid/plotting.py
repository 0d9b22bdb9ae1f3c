"""Figures used by the CLI, the tutorials and the docs (matplotlib, Agg-safe).

* ``tracking_figure``: velocity and force tracking against the designed
  (predicted) exponential response.
* ``save_tracking_plots``: the tracking PNGs a run writes; ``save_run_plots``
  adds the constraint residual and the torques.
* ``eigenvalue_figure``: predicted against measured closed-loop eigenvalues
  (all of them, and a zoom on the designed ones).
* ``eigenvalue_sweep_figure``: how the measured eigenvalues move with a
  parameter (contact stiffness, a gain), against the design.
* ``constraint_residual_figure``: |C(r)| along the run (the pad's compression).
* ``torque_figure``: joint torques against the actuators' effort limits.

Every axis says its unit.
"""

from pathlib import Path

import numpy as np


# Backends that need no display: kept as they are (Jupyter's inline backend reports "inline" or its
# module name, depending on the matplotlib version).
_HEADLESS_BACKENDS = ("agg", "pdf", "svg", "ps", "cairo", "inline", "module://matplotlib_inline.backend_inline",
                      "widget", "ipympl", "module://ipympl.backend_nbagg", "nbagg")


def _pyplot():
    import matplotlib

    if matplotlib.get_backend().lower() not in _HEADLESS_BACKENDS:
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


def save_run_plots(log, effort_limits, out_dir, constraint_units="m", joint_names=None):
    """Write constraint_residual.png and torques.png; returns their paths."""
    plt = _pyplot()
    out = Path(out_dir)
    paths = []
    for name, fig in (("constraint_residual", constraint_residual_figure(log, units=constraint_units)),
                      ("torques", torque_figure(log, effort_limits, joint_names=joint_names))):
        path = out / f"{name}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


def _complex_axes(ax, title):
    ax.axvline(0, color="k", lw=0.8)
    ax.axhline(0, color="k", lw=0.4)
    ax.set_xlabel("Re(s) (1/s)")
    ax.set_ylabel("Im(s) (rad/s)")
    ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=10)


def _designed_window(predicted, margin=0.35):
    """Axis limits around the designed eigenvalues (and the origin)."""
    predicted = np.asarray(predicted, dtype=complex)
    radius = max(1.0, float(np.max(np.abs(predicted)))) if predicted.size else 1.0
    return (-(1 + margin) * radius, margin * radius), (-(0.6 + margin) * radius, (0.6 + margin) * radius)


def eigenvalue_figure(match, title="closed-loop eigenvalues", zoom=None):
    """Predicted (crosses) and measured (dots) eigenvalues in the complex plane.

    Left: every eigenvalue of the linearized closed loop (symmetric-log real
    axis: the contact, filter and joint-space modes are 100 times faster than
    the designed ones). Right: a zoom on the designed eigenvalues (``zoom`` =
    ((re_min, re_max), (im_min, im_max)), default: around them), each joined
    to the measured eigenvalue it was matched with.
    """
    plt = _pyplot()
    fig, (ax_all, ax_zoom) = plt.subplots(1, 2, figsize=(11.0, 4.5), gridspec_kw={"width_ratios": [1.0, 1.2]})
    measured, predicted = np.asarray(match.measured), np.asarray(match.predicted)
    partner = np.asarray(getattr(match, "partner", np.zeros(0)))
    ax_all.scatter(measured.real, measured.imag, s=22, color="tab:blue", label="linearized closed loop")
    ax_all.scatter(predicted.real, predicted.imag, s=80, marker="x", color="tab:red", label="designed (gains)")
    ax_all.set_xscale("symlog", linthresh=10.0)
    _complex_axes(ax_all, f"{title}: all modes")
    ax_all.legend(fontsize=8, loc="best")
    (re_min, re_max), (im_min, im_max) = zoom if zoom is not None else _designed_window(predicted)
    inside = ((measured.real >= re_min) & (measured.real <= re_max) & (measured.imag >= im_min)
              & (measured.imag <= im_max))
    ax_zoom.scatter(measured[inside].real, measured[inside].imag, s=30, color="tab:blue",
                    label="linearized closed loop")
    ax_zoom.scatter(predicted.real, predicted.imag, s=110, marker="x", color="tab:red", label="designed (gains)")
    for p, q in zip(predicted, partner):
        ax_zoom.plot([p.real, q.real], [p.imag, q.imag], color="gray", lw=0.8)
    ax_zoom.set_xlim(re_min, re_max)
    ax_zoom.set_ylim(im_min, im_max)
    _complex_axes(ax_zoom, "zoom on the designed eigenvalues (gray: matched pairs)")
    ax_zoom.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return fig


def eigenvalue_sweep_figure(values, linearizations, parameter, units="", title=None, zoom=None, log_scale=True):
    """How the closed-loop eigenvalues move with a parameter.

    ``values[i]`` is the parameter of ``linearizations[i]`` (each an
    ``analysis.Linearization``). Dots: measured eigenvalues, coloured by the
    parameter; crosses: the designed ones. Left: all modes (symmetric-log real
    axis); right: ``zoom`` (default: around the designed eigenvalues).
    """
    plt = _pyplot()
    from matplotlib import cm, colors

    values = np.asarray(values, dtype=float)
    norm = colors.LogNorm(values.min(), values.max()) if log_scale and values.min() > 0 else \
        colors.Normalize(values.min(), values.max())
    colormap = cm.viridis
    fig, (ax_all, ax_zoom) = plt.subplots(1, 2, figsize=(11.5, 4.5), gridspec_kw={"width_ratios": [1.0, 1.2]},
                                          layout="constrained")
    predicted_all = np.concatenate([lin.predicted.designed for lin in linearizations])
    window = zoom if zoom is not None else _designed_window(predicted_all)
    for value, lin in zip(values, linearizations):
        color = colormap(norm(value))
        measured = np.asarray(lin.eigenvalues)
        designed = np.asarray(lin.predicted.designed)
        for ax in (ax_all, ax_zoom):
            ax.scatter(measured.real, measured.imag, s=18, color=color)
            ax.scatter(designed.real, designed.imag, s=70, marker="x", color=color, linewidths=1.2)
    ax_all.set_xscale("symlog", linthresh=10.0)
    label = f"{parameter} ({units})" if units else parameter
    _complex_axes(ax_all, "all modes (dots: linearized, crosses: designed)")
    ax_zoom.set_xlim(*window[0])
    ax_zoom.set_ylim(*window[1])
    _complex_axes(ax_zoom, "zoom on the designed eigenvalues")
    fig.colorbar(cm.ScalarMappable(norm=norm, cmap=colormap), ax=[ax_all, ax_zoom], label=label)
    if title:
        fig.suptitle(title)
    return fig


def constraint_residual_figure(log, units="m", labels=None, title="constraint residual"):
    """|C(r)| of every constraint row along the run (log scale). For a contact row it is the
    compression of the compliant contact (the rigid model of the paper has C = 0)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 3.2))
    residual = np.atleast_2d(np.asarray(log["constraint"]).T).T
    for i in range(residual.shape[1]):
        label = labels[i] if labels and i < len(labels) else f"C_{i + 1}"
        ax.semilogy(log["t"], np.abs(residual[:, i]) + 1e-15, lw=1.4, label=f"|{label}|")
    ax.set_xlabel("time t (s)")
    ax.set_ylabel(f"|C(r)| ({units})")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="best")
    ax.set_title(title)
    fig.tight_layout()
    return fig


def torque_figure(log, effort_limits, joint_names=None, units="N m", title="joint torques"):
    """Each actuator's torque against its effort limit (dashed, where finite), one panel per joint;
    the panel title gives the peak as a percentage of the limit."""
    plt = _pyplot()
    torque = np.asarray(log["torque"])
    limits = np.asarray(effort_limits, dtype=float)
    if limits.shape != (torque.shape[1],):
        raise ValueError(f"torque_figure: {torque.shape[1]} actuators but {limits.size} effort limits")
    n = torque.shape[1]
    columns = 1 if n <= 3 else 2
    rows = int(np.ceil(n / columns))
    fig, axes = plt.subplots(rows, columns, figsize=(7.5 if columns == 1 else 10.0, 1.9 * rows + 0.6), sharex=True,
                             squeeze=False)
    for i, ax in enumerate(axes.flat):
        if i >= n:
            ax.axis("off")
            continue
        name = joint_names[i] if joint_names and i < len(joint_names) else f"joint {i + 1}"
        ax.plot(log["t"], torque[:, i], lw=1.3, color="tab:blue")
        peak = float(np.max(np.abs(torque[:, i])))
        if np.isfinite(limits[i]):
            for sign in (-1, 1):
                ax.axhline(sign * limits[i], color="tab:red", ls="--", lw=0.9)
            ax.set_title(f"{name}: peak {100 * peak / limits[i]:.1f} % of the {limits[i]:g} {units} limit", fontsize=9)
            ax.set_ylim(-1.15 * max(limits[i], peak), 1.15 * max(limits[i], peak))
        else:
            ax.set_title(f"{name}: peak {peak:.3g} {units} (no limit)", fontsize=9)
        ax.set_ylabel(f"tau ({units})")
        ax.grid(alpha=0.3)
    for column in range(columns):
        # The lowest used panel of each column carries the time axis (the last row may have an empty panel).
        last_row = max(row for row in range(rows) if row * columns + column < n)
        axes[last_row, column].set_xlabel("time t (s)")
        axes[last_row, column].tick_params(labelbottom=True)
    fig.suptitle(f"{title} (dashed: effort limits)")
    fig.tight_layout()
    return fig
