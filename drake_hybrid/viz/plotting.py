"""Figures used by the CLI, the tutorials and the docs (matplotlib, Agg-safe).

* ``tracking_figure``: velocity and force tracking against the designed
  (predicted) exponential response.
* ``save_tracking_plots``: the tracking PNGs a run writes; ``save_run_plots``
  adds the constraint residual and the torques.
* ``eigenvalue_figure``: predicted against measured closed-loop eigenvalues
  (all of them, and a zoom on the designed ones).
* ``eigenvalue_sweep_figure``: how the measured eigenvalues move with a
  parameter (contact stiffness, a gain), against the design.
* ``constraint_residual_figure``: C(r) along the run (what it measures: the task's note).
* ``torque_figure``: joint torques against the actuators' effort limits.
* ``joint_servo_map_figure``: where the joint-servo hybrid controllers are unstable (issue 18).

Every axis says its unit.

Size: one module for every figure of the package, so that they share one look (axes, units,
the designed-prediction overlays); each function is one figure.
"""

import textwrap
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from matplotlib import cm, colors
from matplotlib.colors import SymLogNorm

from drake_hybrid.analysis.matching import nyquist_split
from drake_hybrid.experiments.metrics import display_unit, row_units
from drake_hybrid.experiments.sweep import theory_on_plane
from drake_hybrid.tasks.config import load_config

# Backends that need no display: kept as they are (Jupyter's inline backend reports "inline" or its
# module name, depending on the matplotlib version).
_HEADLESS_BACKENDS = ("agg", "pdf", "svg", "ps", "cairo", "inline", "module://matplotlib_inline.backend_inline",
                      "widget", "ipympl", "module://ipympl.backend_nbagg", "nbagg")


def _pyplot():
    """pyplot on a backend that needs no display (Agg unless a headless one is already set)."""
    if matplotlib.get_backend().lower() not in _HEADLESS_BACKENDS:
        plt.switch_backend("Agg")
    return plt


def _positive(values):
    """``values`` with zeros (and negative rounding) masked as NaN: a log axis shows no numeric floor."""
    values = np.asarray(values, dtype=float)
    return np.where(values > 0, values, np.nan)


_LOG_DECADES = 8          # a log axis of measured values spans at most this many decades below their max


def _measured_on_log(values, top):
    """``values`` (>= 0) to draw on a log axis whose largest measured value is ``top``: zeros and the
    numeric floor (below ``top`` / 10^(``_LOG_DECADES`` + 1), e.g. a solved start's 1e-15) masked as
    NaN, so that no floor is drawn as data."""
    values = _positive(values)
    return np.where(values >= top * 10.0 ** -(_LOG_DECADES + 1), values, np.nan) if np.isfinite(top) else values


def _set_log_limits(ax, measured):
    """Limits of a log axis: the measured values (``_measured_on_log``), at most ``_LOG_DECADES`` decades."""
    measured = np.asarray(measured, dtype=float)
    if np.isfinite(measured).any():
        top, bottom = np.nanmax(measured), np.nanmin(measured)
        ax.set_ylim(max(bottom, 10.0 ** -_LOG_DECADES * top) / 2, 2 * top)


ZERO_ROW_SCALES = {"rows in its units": "the largest command in its units", "run": "the run's command scale"}


def _tracking_axes(ax_values, ax_errors, t, actual, desired, predicted, labels, what, units=(), held=(), scales=()):
    held = set(held)
    errors = np.abs(actual - desired)
    errors[:, sorted(held)] = np.nan                # a held row has no command, hence no error to draw
    top = np.nanmax(errors) if np.isfinite(errors).any() else np.nan
    measured = _measured_on_log(errors, top)
    designed_labelled = False
    for i in range(actual.shape[1]):
        label = labels[i] if i < len(labels) else f"{what} {i + 1}"
        unit = f" ({units[i]})" if i < len(units) and units[i] else ""
        if i in held:
            ax_values.plot(t, actual[:, i], lw=1.6,
                           label=f"{label}{unit}: measured (held by the controller, no force loop)")
            continue
        line, = ax_values.plot(t, actual[:, i], lw=1.6, label=f"{label}{unit}: measured")
        color = line.get_color()
        ax_values.plot(t, desired[:, i], color=color, ls=":", lw=1.2, label=f"{label}: commanded")
        first = i == min(set(range(actual.shape[1])) - held)
        ax_values.plot(t, predicted[:, i], color="k", ls="--", lw=0.9, label="designed response" if first else None)
        ax_errors.semilogy(t, measured[:, i], color=color, lw=1.4, label=f"|error| {label}{unit}")
        designed_error = _positive(np.abs(predicted[:, i] - desired[:, i]))
        if np.isfinite(designed_error).any():          # a zero prediction (no error designed) is not drawn
            # The legend names the first decay drawn (row 0 may be commanded to zero: none drawn for it).
            ax_errors.semilogy(t, designed_error, color="k", ls="--", lw=0.9,
                               label=None if designed_labelled else "designed error decay")
            designed_labelled = True
        command = float(np.max(np.abs(desired[:, i])))
        scale, source = scales[i] if i < len(scales) else (None, None)
        if command > 0:
            ax_errors.axhline(0.01 * command, color=color, lw=0.8, ls="-.", label=f"1 % of the {label} command")
        elif source in ZERO_ROW_SCALES:        # a row commanded to zero: 1 % of the scale the summary judges it by
            ax_errors.axhline(0.01 * scale, color=color, lw=0.8, ls="-.",
                              label=f"1 % of {ZERO_ROW_SCALES[source]} ({label} commanded 0)")
    # The axis spans the measured errors (at most 8 decades): a designed decay far below them is cut.
    _set_log_limits(ax_errors, measured)
    ax_errors.set_xlabel("time t (s)")
    ax_values.grid(alpha=0.3)
    ax_errors.grid(alpha=0.3, which="both")


def _mark_events(axes, events):
    """The run's phases (``summary["events"]``: a span shaded, an instant a dashed line), one colour and
    one legend entry per label."""
    colors = {}
    for event in events or ():
        first = event["label"] not in colors
        color = colors.setdefault(event["label"], f"C{(len(colors) + 5) % 10}")
        for ax in axes:
            label = event["label"] if ax is axes[-1] and first else None
            if event.get("end") is None:
                ax.axvline(event["start"], color=color, lw=1.0, ls="--", label=label)
            else:
                ax.axvspan(event["start"], event["end"], color=color, alpha=0.12, lw=0, label=label)


def _start_text(log, summary, what):
    """What the first samples of a start in contact are (the start solved to press with F_d; xi(0)'s
    step of the first force command), for the force figure; None where there is nothing to say."""
    if what != "force" or not summary.get("start_in_contact"):
        return None
    text = "t = 0: the start presses with the commanded force (solved for it)"
    step = np.abs(np.asarray(summary.get("start_force_command_step") or [], dtype=float))
    if step.size and np.max(step) > 0:
        row = int(np.argmax(step))
        rows = summary.get("force_rows") or []
        name, unit = (rows[row]["name"], rows[row]["units"]) if row < len(rows) else (f"row {row + 1}", "")
        text += (f"; the start's force integral xi(0) adds K_fi xi(0) = {step[row]:.3g} {unit} to the first "
                 f"command of {name}: the contact answers within milliseconds, then the designed decay")
    velocity = np.asarray(log.get("desired_velocity", np.zeros((1, 0))))
    if velocity.size and np.max(np.abs(velocity[0])) > 0 and np.max(np.abs(log["velocity"][0])) == 0:
        text += "; the velocity command steps from rest"
    return text


def tracking_figure(log, summary, predicted, what, labels=(), units="", note=None):
    """Measured, commanded and designed ``what`` ("velocity" or "force") and the error on a log scale.

    Every row in its own units; the designed response starts at contact (``summary["contact_time"]``);
    dash-dot lines: 1 % of each row's command (of a row commanded to zero: 1 % of the scale the summary
    judges it by, ``metrics.row_scales``); dotted: contact + five design time constants; shaded
    spans and dashed lines: the run's phases (``summary["events"]``). Under the title: what the force's
    first samples are (a start in contact), and ``note`` (the task's words on its transients).

    A held row (``summary["force_rows"][i]["held"]``: no force loop) shows its measured value only. With
    the paper's pseudo-velocity rows (the log has ``true_desired_velocity``) the velocity figure shows
    the true rows the summary reports (``labels``: the task's ``velocity_error`` labels)."""
    plt = _pyplot()
    fig, (ax_values, ax_errors) = plt.subplots(2, 1, figsize=(7.5, 6.0), sharex=True)
    actual, desired = log[what], log[f"desired_{what}"]
    pseudo = what == "velocity" and "true_desired_velocity" in log
    if pseudo:
        # The paper's pseudo-velocity rows (collect_log): their error is the true rows' (docs/theory.md §6), the
        # summary's rows; drawn as those: true velocity = true command + error, the designed decay about it.
        actual, desired = log["true_desired_velocity"] + log["velocity_error"], log["true_desired_velocity"]
        predicted = np.asarray(predicted) - log["desired_velocity"] + desired
    held = [i for i, row in enumerate(summary.get(f"{what}_rows") or []) if row.get("held")]
    units_per_row = row_units(units or "", actual.shape[1])
    scales = [(row.get("scale"), row.get("scale_of")) for row in summary.get(f"{what}_rows") or []]
    _tracking_axes(ax_values, ax_errors, log["t"], actual, desired, predicted, labels, what, units_per_row, held,
                   scales)
    unit_text = " | ".join(dict.fromkeys(u for u in units_per_row if u))
    ax_values.set_ylabel(f"{what} ({unit_text})" if unit_text else what)
    ax_errors.set_ylabel(f"|{what} error| ({unit_text})" if unit_text else f"|{what} error|")
    contact = float(summary.get("contact_time", 0.0))
    if contact > float(log["t"][0]) and np.isfinite(contact):
        for ax in (ax_values, ax_errors):
            ax.axvline(contact, color="tab:green", lw=0.9, ls="-", label="contact" if ax is ax_errors else None)
    ax_errors.axvline(contact + 5 * summary["design_time_constant"], color="gray", lw=0.8, ls=":",
                      label="contact + 5 design time constants" if contact > 0 else "5 design time constants")
    _mark_events((ax_values, ax_errors), summary.get("events"))
    ax_values.legend(fontsize=7, loc="best")
    ax_errors.legend(fontsize=7, loc="best")
    title = f"{summary['task']} ({summary['mode']}): {what} tracking vs. the designed exponential"
    fed = ("the controller was fed the paper's E_p rows with their pseudo-velocity, whose error is the true rows' "
           "(docs/theory.md §6): drawn here, as the summary reports them, the true rows against the true command"
           if pseudo else None)
    caption = "\n".join(textwrap.fill(text, 120) for text in (fed, _start_text(log, summary, what), note) if text)
    ax_values.set_title(title + ("\n" + caption if caption else ""), fontsize=10 if not caption else 7.5)
    fig.tight_layout()
    return fig


def save_tracking_plots(log, summary, predicted_velocity, predicted_force, out_dir, labels=None):
    """Write velocity_tracking.png and force_tracking.png; returns their paths."""
    plt = _pyplot()
    labels = labels or {}
    out = Path(out_dir)
    paths = []
    for what, predicted in (("velocity", predicted_velocity), ("force", predicted_force)):
        # The paper's pseudo-velocity rows are drawn as the true rows (tracking_figure): in those rows' terms.
        true_rows = what == "velocity" and "true_desired_velocity" in log and "velocity_error" in labels
        fig = tracking_figure(log, summary, predicted, what, labels.get("velocity_error" if true_rows else what, ()),
                              units=labels.get("velocity_error_units" if true_rows else f"{what}_units", ""),
                              note=labels.get(f"{what}_note"))
        path = out / f"{what}_tracking.png"
        fig.savefig(path, dpi=120)
        plt.close(fig)
        paths.append(path)
    return paths


def save_run_plots(log, effort_limits, out_dir, constraint_units="m", joint_names=None, constraint_note=None):
    """Write constraint_residual.png and torques.png; returns their paths."""
    plt = _pyplot()
    out = Path(out_dir)
    paths = []
    residual = constraint_residual_figure(log, units=constraint_units, note=constraint_note)
    for name, fig in (("constraint_residual", residual),
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


def constraint_residual_figure(log, units="m", labels=None, title="constraint residual", note=None):
    """C(r) of every constraint row along the run: 0 on the paper's rigid constraint; what the simulated
    one makes of it is the task's to say (``note``, its labels' ``constraint_note``: e.g. a compliant
    contact's compression, a steady offset while pressing, and the gap before contact; a compliant weld's
    stretch; rows the controller holds). Signed on a linear axis, unless the rows' sizes differ by more
    than two decades: then |C| on a log axis spanning the measured values (no numeric floor drawn)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 3.4))
    residual = np.atleast_2d(np.asarray(log["constraint"]).T).T
    sizes = np.max(np.abs(residual), axis=0)
    sizes = sizes[sizes > 0]
    logarithmic = sizes.size > 1 and sizes.max() / sizes.min() > 100
    units_per_row = [display_unit(unit) for unit in row_units(units or "", residual.shape[1])]
    magnitudes = _measured_on_log(np.abs(residual), sizes.max() if sizes.size else np.nan)
    for i in range(residual.shape[1]):
        label = labels[i] if labels and i < len(labels) else f"C_{i + 1}"
        unit = f" {units_per_row[i]}" if units_per_row[i].startswith("(") else f" ({units_per_row[i]})"
        unit = unit if units_per_row[i] else ""
        if logarithmic:
            ax.plot(log["t"], magnitudes[:, i], lw=1.4, label=f"|{label}|{unit}")
        else:
            ax.plot(log["t"], residual[:, i], lw=1.4, label=f"{label}{unit}")
    ax.set_xlabel("time t (s)")
    unit_text = " | ".join(dict.fromkeys(u.strip("()") for u in units_per_row if u))
    name = "|C(r)|" if logarithmic else "C(r)"
    if logarithmic:
        ax.set_yscale("log")
        _set_log_limits(ax, magnitudes)
    else:
        ax.axhline(0.0, color="k", lw=0.6)
    ax.set_ylabel(f"{name} ({unit_text})" if unit_text else name)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="best")
    heading = f"{title} (C = 0 on the paper's rigid constraint)"
    ax.set_title(heading + ("\n" + textwrap.fill(note, 110) if note else ""), fontsize=9 if not note else 7.5)
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


# ------------------------------------------------------------------------------------------------
# Sweeps: stability maps and Monte Carlo histograms (rows from drake_hybrid.experiments.sweep.read_results)
# ------------------------------------------------------------------------------------------------

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
