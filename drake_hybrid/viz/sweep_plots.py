"""Figures of a sweep (matplotlib, Agg-safe), from the rows of its results table
(``experiments.sweep_results.read_results``): stability maps over two parameters, with the
rigid-contact theory's boundary, and Monte Carlo histograms; ``save_sweep_plots`` writes those a
sweep spec asks for. Every axis says its unit.
"""

from pathlib import Path

import numpy as np
from matplotlib.colors import SymLogNorm

from drake_hybrid.experiments.theory_verdict import theory_on_plane
from drake_hybrid.tasks.config import load_config
from drake_hybrid.viz.figure_base import _pyplot

SWEEP_LABELS = {
    "contact.pad_modulus": "pad modulus E (Pa)",
    "gains.force_proportional": "force gain K_fp",
    "gains.force_integral": "force gain K_fi (1/s)",
    "control_period": "control period h (s)",
    "time_step": "plant time step (s)",
    "worst_discrete_real": "worst Re log(mu)/h, sampled loop (1/s)",
    "worst_continuous_real": "worst Re(s), continuous loop (1/s)",
    "steady_force_error": "steady |e_f|, worst row (its units: steady_force_row)",
    "steady_velocity_error": "steady |e_p'|, worst row (its units: steady_velocity_row)",
    "force_settling_time": "force settling time, 1 % (s)",
    "velocity_settling_time": "velocity settling time, 1 % (s)",
    "peak_force": "peak |F_i|, worst row (its units: peak_force_row)",
    "model_error.payload_mass_scale": "payload mass / model",
}


def _label(name):
    return SWEEP_LABELS.get(name, name)


def _cell_edges(values):
    """Edges of heatmap cells centred on sorted ``values`` (geometric when they span > 1 decade)."""
    values = np.asarray(values, dtype=float)
    if values.size == 1:
        return np.array([values[0] * 0.9, values[0] * 1.1]) if values[0] else np.array([-0.5, 0.5]), False
    positive = bool(np.all(values > 0))
    logarithmic = positive and values[-1] / values[0] > 10

    def edges_of(v):
        middle = 0.5 * (v[1:] + v[:-1])
        return np.concatenate([[v[0] - (middle[0] - v[0])], middle, [v[-1] + (v[-1] - middle[-1])]])

    edges = 10 ** edges_of(np.log10(values)) if logarithmic else edges_of(values)
    if positive and edges[0] <= 0:      # a positive parameter (a modulus, a period): no cell below zero
        logarithmic = True
        edges = 10 ** edges_of(np.log10(values))
    return edges, logarithmic


def _symlog_ticks(limit, linthresh=1.0):
    """Readable colour-bar ticks for a SymLogNorm over [-limit, limit]: 0, and 1, 2, 5 (fewer when the range
    spans more decades) times each power of ten from ``linthresh`` up to ``limit``, and the bar's end (two
    digits), with both signs."""
    decades = max(0, int(np.ceil(np.log10(max(limit, linthresh) / linthresh))))
    subs = (1, 2, 5) if decades <= 1 else (1, 3) if decades <= 3 else (1,)
    positive = [value for value in (linthresh * m * 10.0 ** d for d in range(decades + 1) for m in subs)
                if value <= limit]
    end = float(f"{limit:.2g}")                        # the bar's end, so that its extreme is read too
    if not positive or (positive[-1] < 0.8 * limit and end <= limit):
        positive.append(end)
    return [-value for value in reversed(positive)] + [0.0] + positive


def stability_map_figure(rows, x, y, facet=None, color="worst_discrete_real", verdict="stable_simulation",
                         theory=None, title=None):
    """Heatmap of ``color`` over (x, y), one panel per value of ``facet``.

    Markers give the simulation's verdict per point (circle: stable, cross:
    not), a grey square a point whose simulation failed (see its ``error``).
    ``theory(x_values, y_values, facet_value)`` returns the theory's verdict on
    a fine grid (1 stable, 0 unstable, nan not admissible); its boundary is
    drawn where it changes, and a note says so where it does not."""
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
    ticks = _symlog_ticks(limit)                       # SymLogNorm's own ticks: only +-10^k, too few to read
    colorbar.set_ticks(ticks)
    colorbar.set_ticklabels([f"{tick:g}" for tick in ticks])
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
    plt = _pyplot()
    out = Path(out_dir)
    paths = []
    if "x" in spec.map and "y" in spec.map:
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
