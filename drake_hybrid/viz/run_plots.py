"""The figures of a run (matplotlib, Agg-safe); every axis says its unit.

* ``tracking_figure``: velocity and force tracking against the designed (predicted) exponential
  response.
* ``save_tracking_plots``: the tracking PNGs a run writes; ``save_run_plots`` adds the constraint
  residual and the torques.
* ``constraint_residual_figure``: C(r) along the run (what it measures: the task's note).
* ``torque_figure``: joint torques against the actuators' effort limits.
"""

import textwrap
from pathlib import Path

import numpy as np

from drake_hybrid.experiments.metrics import display_unit, row_units
from drake_hybrid.viz.figure_base import _measured_on_log, _positive, _pyplot, _set_log_limits

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
