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


# ------------------------------------------------------------------------------------------------
# Sweeps: stability maps and Monte Carlo histograms (rows from drake_hybrid.sweep.read_results)
# ------------------------------------------------------------------------------------------------

SWEEP_LABELS = {
    "contact.pad_modulus": "pad modulus E (Pa)",
    "gains.force_proportional": "force gain K_fp",
    "gains.force_integral": "force gain K_fi (1/s)",
    "control_period": "control period h (s)",
    "time_step": "plant time step (s)",
    "worst_discrete_real": "worst Re log(mu)/h, sampled loop (1/s)",
    "worst_continuous_real": "worst Re(s), continuous loop (1/s)",
    "steady_force_error": "steady |e_f| (N)",
    "steady_velocity_error": "steady |e_p'| (velocity units)",
    "force_settling_time": "force settling time, 1 % (s)",
    "velocity_settling_time": "velocity settling time, 1 % (s)",
    "peak_force": "peak |F| (N)",
    "model_error.payload_mass_scale": "payload mass / model",
}


def _label(name):
    return SWEEP_LABELS.get(name, name)


def _cell_edges(values):
    """Edges of heatmap cells centred on sorted ``values`` (geometric when they span > 1 decade)."""
    values = np.asarray(values, dtype=float)
    if values.size == 1:
        return np.array([values[0] * 0.9, values[0] * 1.1]) if values[0] else np.array([-0.5, 0.5]), False
    logarithmic = bool(np.all(values > 0) and values[-1] / values[0] > 10)
    v = np.log10(values) if logarithmic else values
    middle = 0.5 * (v[1:] + v[:-1])
    edges = np.concatenate([[v[0] - (middle[0] - v[0])], middle, [v[-1] + (v[-1] - middle[-1])]])
    return (10 ** edges if logarithmic else edges), logarithmic


def stability_map_figure(rows, x, y, facet=None, color="worst_discrete_real", verdict="stable_simulation",
                         theory=None, title=None):
    """Heatmap of ``color`` over (x, y), one panel per value of ``facet``.

    Markers give the simulation's verdict per point (circle: stable, cross:
    not), a grey square a point whose simulation failed (see its ``error``).
    ``theory(x_values, y_values, facet_value)`` returns the theory's verdict on
    a fine grid (1 stable, 0 unstable, nan not admissible); its boundary is
    drawn where it changes, and a note says so where it does not."""
    from matplotlib.colors import SymLogNorm

    plt = _pyplot()
    facet_values = sorted({row[facet] for row in rows}) if facet else [None]
    fig, axes = plt.subplots(1, len(facet_values), figsize=(5.6 * len(facet_values) + 1.2, 4.8), squeeze=False)
    fig.subplots_adjust(bottom=0.2, top=0.82 if title and facet else 0.86)   # room for the legend and title
    values = np.array([np.nan if row.get(color) is None else row[color] for row in rows], dtype=float)
    limit = np.nanmax(np.abs(values)) if np.isfinite(values).any() else 1.0
    norm = SymLogNorm(linthresh=1.0, vmin=-limit, vmax=limit, base=10)
    image = None
    for ax, facet_value in zip(axes[0], facet_values):
        subset = [row for row in rows if facet is None or row[facet] == facet_value]
        xs, ys = sorted({row[x] for row in subset}), sorted({row[y] for row in subset})
        grid = np.full((len(ys), len(xs)), np.nan)
        for row in subset:
            if row.get(color) is not None:
                grid[ys.index(row[y]), xs.index(row[x])] = row[color]
        x_edges, x_log = _cell_edges(xs)
        y_edges, y_log = _cell_edges(ys)
        image = ax.pcolormesh(x_edges, y_edges, np.ma.masked_invalid(grid), cmap="RdBu_r", norm=norm)
        if x_log:
            ax.set_xscale("log")
        if y_log:
            ax.set_yscale("log")
        for row in subset:
            state = row.get(verdict)
            if state is None:
                ax.scatter(row[x], row[y], marker="s", s=40, color="0.5", edgecolor="k", zorder=3)
            else:
                style = dict(marker="o", facecolor="none", edgecolor="k") if state else dict(marker="x", color="k")
                ax.scatter(row[x], row[y], s=28, zorder=3, linewidths=1.2, **style)
        if theory is not None:
            fine_x = (np.geomspace if x_log else np.linspace)(xs[0], xs[-1], 40)
            fine_y = (np.geomspace if y_log else np.linspace)(ys[0], ys[-1], 40)
            verdicts = theory(fine_x, fine_y, facet_value)
            finite = verdicts[np.isfinite(verdicts)]
            if finite.size and finite.min() != finite.max():
                ax.contour(fine_x, fine_y, verdicts, levels=[0.5], colors="k", linewidths=2.0, linestyles="--")
                ax.plot([], [], "k--", lw=2.0, label="theory's boundary (rigid contact)")
                ax.legend(fontsize=7, loc="lower left")
            else:
                note = ("stable everywhere here" if finite.size and finite.min() == 1 else
                        "unstable everywhere here" if finite.size else "not defined here")
                if finite.size and finite.size < verdicts.size:
                    note += " (where the gains are admissible)"
                ax.text(0.5, 1.01, f"rigid-contact theory: {note};\nit has no boundary over "
                        f"{_label(x).split(' (')[0]} x {_label(y).split(' (')[0]}",
                        transform=ax.transAxes, fontsize=7, ha="center", va="bottom")
        ax.set_xlabel(_label(x))
        ax.set_ylabel(_label(y))
        ax.set_title(f"{_label(facet).split(' (')[0]} = {facet_value:g}" if facet else (title or ""), fontsize=10,
                     pad=24)
    colorbar = fig.colorbar(image, ax=axes[0].tolist(), shrink=0.9)
    colorbar.set_label(_label(color))
    handles = [plt.Line2D([], [], ls="", marker="o", mfc="none", mec="k", label="simulation: settles"),
               plt.Line2D([], [], ls="", marker="x", color="k", label="simulation: does not settle"),
               plt.Line2D([], [], ls="", marker="s", mfc="0.5", mec="k", label="failed (error recorded)")]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=8, frameon=False, bbox_to_anchor=(0.45, -0.01))
    if title and facet:
        fig.suptitle(title, fontsize=10)
    return fig


def monte_carlo_figure(rows, metrics=("steady_force_error", "steady_velocity_error", "force_settling_time",
                                      "velocity_settling_time", "peak_force", "worst_discrete_real"), group=None):
    """Histograms of ``metrics`` over the Monte Carlo points, one colour per value of ``group``."""
    plt = _pyplot()
    columns = 3
    lines = int(np.ceil(len(metrics) / columns))
    fig, axes = plt.subplots(lines, columns, figsize=(4.2 * columns, 3.2 * lines), squeeze=False)
    groups = sorted({row[group] for row in rows}) if group else [None]
    for ax, metric in zip(axes.ravel(), metrics):
        for value in groups:
            data = np.array([row[metric] for row in rows if (group is None or row[group] == value)
                             and row.get(metric) is not None], dtype=float)
            never = int(np.sum(np.isinf(data)))             # a settling time of inf: never settled
            data = data[np.isfinite(data)]
            label = f"{_label(group).split(' (')[0]} = {value:g} (n = {data.size})" if group else f"n = {data.size}"
            if never:
                label += f"; {never} never"
            ax.hist(data, bins=20, alpha=0.6, label=label)
        ax.set_xlabel(_label(metric), fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    for ax in axes.ravel()[len(metrics):]:
        ax.set_visible(False)
    fig.tight_layout()
    return fig


def save_sweep_plots(rows, spec, out_dir, base_config=None):
    """The spec's stability map (``map: {x, y, facet}``) and, with random axes, the Monte Carlo
    histograms, as PNGs in ``out_dir``; returns their paths."""
    from drake_hybrid.sweep import theory_on_plane

    plt = _pyplot()
    out = Path(out_dir)
    paths = []
    if "x" in spec.map and "y" in spec.map:
        from drake_hybrid.scenarios import load_config

        base = base_config or load_config(path=out / "base_config.yaml")
        x, y, facet = spec.map["x"], spec.map["y"], spec.map.get("facet")
        theory = lambda xs, ys, facet_value: theory_on_plane(
            base, x, y, xs, ys, fixed={facet: facet_value} if facet else None)
        fig = stability_map_figure(rows, x, y, facet=facet, color=spec.map.get("color", "worst_discrete_real"),
                                   theory=theory)
        paths.append(out / "stability_map.png")
        fig.savefig(paths[-1], dpi=130)
        plt.close(fig)
    if any(not axis.is_grid for axis in spec.parameters):
        grid_axes = [axis.path for axis in spec.parameters if axis.is_grid]
        fig = monte_carlo_figure(rows, group=grid_axes[0] if grid_axes else None)
        paths.append(out / "monte_carlo.png")
        fig.savefig(paths[-1], dpi=130)
        plt.close(fig)
    return paths
