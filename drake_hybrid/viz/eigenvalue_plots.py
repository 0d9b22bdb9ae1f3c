"""Figures of the closed loop's eigenvalues (matplotlib, Agg-safe); every axis says its unit.

* ``eigenvalue_figure``: predicted against measured closed-loop eigenvalues (all of them, and a zoom
  on the designed ones).
* ``eigenvalue_sweep_figure``: how the measured eigenvalues move with a parameter (contact
  stiffness, a gain), against the design.
* ``joint_servo_map_figure``: where the joint-servo hybrid controllers (Raibert-Craig,
  Fisher-Mujtaba) are unstable over a 2R arm's configurations.
"""

import numpy as np
from matplotlib import cm, colors

from drake_hybrid.analysis.matching import nyquist_split
from drake_hybrid.viz.figure_base import _pyplot


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


def _shifted_rows(designed, partner, shifts):
    """{row: shift}: each ``EigenvalueShift`` on the row, among those with its designed value and not yet
    taken, whose linearized partner is nearest its prediction (the miss it explains)."""
    rows = {}
    for shift in shifts:
        same = [i for i in range(min(len(designed), len(partner))) if i not in rows
                and abs(designed[i] - shift.designed) <= 1e-9 * max(1.0, abs(shift.designed))]
        if same:
            rows[min(same, key=lambda i: abs(partner[i] - shift.predicted))] = shift
    return rows


def eigenvalue_figure(match, title="closed-loop eigenvalues", zoom=None, period=None, shifts=()):
    """Predicted (crosses) and measured (dots) eigenvalues in the complex plane.

    Left: every eigenvalue of the linearized closed loop (symmetric-log real
    axis: the contact, filter and joint-space modes are 100 times faster than
    the designed ones). For a sampled loop of step ``period`` (s), the modes at
    its Nyquist frequency (log(mu)/h of a multiplier mu < 0: imaginary part
    pi/h) are not drawn as ordinary modes: triangles on the top edge mark their
    real parts, off scale. Right: a zoom on the designed eigenvalues (``zoom`` =
    ((re_min, re_max), (im_min, im_max)), default: around them), each joined
    to the measured eigenvalue it was matched with; ``shifts`` (the task's
    ``EigenvalueShift`` predictions, e.g. a handle's inertia the paper leaves
    out) adds each shifted eigenvalue's predicted value.
    """
    plt = _pyplot()
    fig, (ax_all, ax_zoom) = plt.subplots(1, 2, figsize=(11.0, 4.5), gridspec_kw={"width_ratios": [1.0, 1.2]})
    measured, predicted = np.asarray(match.measured), np.asarray(match.predicted)
    partner = np.asarray(getattr(match, "partner", np.zeros(0)))
    _, nyquist = nyquist_split(measured, period)
    shown = measured[~np.isin(measured, nyquist)]
    ax_all.scatter(shown.real, shown.imag, s=22, color="tab:blue", label="linearized closed loop")
    ax_all.scatter(predicted.real, predicted.imag, s=80, marker="x", color="tab:red", label="designed (gains)")
    if nyquist.size:
        ax_all.scatter(nyquist.real, np.full(nyquist.size, 0.97), s=40, marker="^", facecolor="none",
                       edgecolor="tab:purple", transform=ax_all.get_xaxis_transform(), clip_on=False,
                       label=f"at the Nyquist frequency pi/h = {np.pi / period:.4g} rad/s\n(mu < 0): off scale, "
                             "drawn at their Re on the top edge")
    ax_all.set_xscale("symlog", linthresh=10.0)
    _complex_axes(ax_all, f"{title}: all modes")
    ax_all.legend(fontsize=8, loc="best")
    (re_min, re_max), (im_min, im_max) = zoom if zoom is not None else _designed_window(predicted)
    inside = ((measured.real >= re_min) & (measured.real <= re_max) & (measured.imag >= im_min)
              & (measured.imag <= im_max))
    ax_zoom.scatter(measured[inside].real, measured[inside].imag, s=30, color="tab:blue",
                    label="linearized closed loop")
    ax_zoom.scatter(predicted.real, predicted.imag, s=110, marker="x", color="tab:red", label="designed (gains)")
    shifted = _shifted_rows(predicted, partner, shifts)
    if shifted:
        values = np.array([shift.predicted for shift in shifted.values()], dtype=complex)
        ax_zoom.scatter(values.real, values.imag, s=70, marker="D", facecolor="none", edgecolor="tab:green",
                        linewidths=1.4, label="the task's prediction (physics beyond the paper's model)")
    for n, (p, q) in enumerate(zip(predicted, partner)):
        ax_zoom.annotate("", xy=(q.real, q.imag), xytext=(p.real, p.imag),
                         arrowprops=dict(arrowstyle="->", color="0.25", lw=1.2))
    if partner.size:
        ax_zoom.plot([], [], color="0.25", lw=1.2, label="designed -> its linearized partner")
        errors = np.abs(partner - predicted) / np.abs(predicted)
        rows = [f"{p.real:.3g}{p.imag:+.3g}j -> {q.real:.4g}{q.imag:+.4g}j  ({100 * e:.1f} %)" if abs(p.imag) > 1e-9
                else f"{p.real:.3g} -> {q.real:.4g}  ({100 * e:.1f} %)" for p, q, e in zip(predicted, partner, errors)]
        for i, shift in shifted.items():
            value = complex(shift.predicted)
            rows[i] += (f"; predicted {value.real:.4g}{value.imag:+.4g}j" if abs(value.imag) > 1e-9
                        else f"; predicted {value.real:.4g}")
        ax_zoom.text(0.98, 0.02, "designed -> linearized (rel. error)\n" + "\n".join(rows), transform=ax_zoom.transAxes,
                     ha="right", va="bottom", fontsize=7, family="monospace",
                     bbox=dict(boxstyle="round", facecolor="white", alpha=0.85, edgecolor="0.7"))
    ax_zoom.set_xlim(re_min, re_max)
    ax_zoom.set_ylim(im_min, im_max)
    _complex_axes(ax_zoom, "zoom on the designed eigenvalues")
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


def joint_servo_map_figure(q1, q2, maps, marked=None, title=None, clip=10.0):
    """The largest real part of the joint-servo hybrid controllers over a 2R arm's configurations
    (``analysis.kinematic_instability.stability_map``): one panel per controller, the stability
    boundary in black, ``marked`` (rad) as a star. Colours clipped to +-``clip`` 1/s."""
    plt_ = _pyplot()
    names = {"raibert-craig": "Raibert-Craig (J^-1 S)", "fisher-mujtaba": "Fisher-Mujtaba ((S J)^+ S)"}
    fig, axes = plt_.subplots(1, len(maps), figsize=(5 * len(maps), 4.3), sharey=True, squeeze=False)
    x, y = np.degrees(q1), np.degrees(q2)
    for ax, (name, data) in zip(axes[0], maps.items()):
        mesh = ax.pcolormesh(x, y, np.clip(data, -clip, clip), cmap="coolwarm", vmin=-clip, vmax=clip, shading="auto")
        if np.nanmax(data) > 0 > np.nanmin(data):
            ax.contour(x, y, data, levels=[0.0], colors="k", linewidths=1.0)
        if marked is not None:
            ax.plot(*np.degrees(marked), "k*", markersize=12)
        ax.set_title(names.get(name, name))
        ax.set_xlabel("q1 (deg)")
    axes[0][0].set_ylabel("q2 (deg)")
    fig.colorbar(mesh, ax=list(axes[0]), label=f"largest real part (1/s), clipped to +-{clip:g}")
    if title:
        fig.suptitle(title, fontsize=9)
    return fig
