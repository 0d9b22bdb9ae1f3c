"""Figures: every axis says its unit; the limits and the designed eigenvalues are drawn where they belong."""

from types import SimpleNamespace

import numpy as np
import pytest

from drake_hybrid.analysis.design import PredictedEigenvalues
from drake_hybrid.analysis.linearization import Linearization
from drake_hybrid.analysis.matching import match_eigenvalues
from drake_hybrid.viz import eigenvalue_plots, run_plots, sweep_plots


@pytest.fixture
def log():
    t = np.linspace(0.0, 1.0, 101)
    return {"t": t, "constraint": (1e-3 * np.exp(-t))[:, None],
            "torque": np.column_stack([40 + 5 * t, -3 + t, 0.1 * np.sin(t)])}


def _labels(fig):
    return [label for ax in fig.axes for label in (ax.get_xlabel(), ax.get_ylabel()) if label]


def test_constraint_residual_figure(log):
    """One row (a pad's compression): signed, on a linear axis. Rows of sizes four decades apart: |C| on
    a log axis, without a numeric floor."""
    fig = run_plots.constraint_residual_figure(log, units="m", labels=["C = y - h"], note="the contact's compression")
    ax = fig.axes[0]
    assert ax.get_yscale() == "linear" and ax.get_xlabel() == "time t (s)" and ax.get_ylabel() == "C(r) (m)"
    assert np.allclose(ax.lines[0].get_ydata(), log["constraint"][:, 0], rtol=1e-9)
    assert "the contact's compression" in ax.get_title()
    rows = dict(log, constraint=np.column_stack([log["constraint"][:, 0], 1e-7 * np.sin(10 * log["t"])]))
    ax = run_plots.constraint_residual_figure(rows, units="m^2 | m").axes[0]
    assert ax.get_yscale() == "log" and ax.get_ylabel() == "|C(r)| (m^2 | m)"
    assert np.isnan(ax.lines[1].get_ydata()[0])                      # C = 0 at t = 0 is not drawn at a floor
    assert "compression" not in ax.get_title()                        # a weld, say: the task's note says what C is


def test_constraint_residual_figure_draws_no_numeric_floor_and_names_a_dimensionless_row(log):
    """A row 1e-17 at t = 0 (a solved start) is not drawn and the log axis spans the measured values
    (at most 8 decades below their max), not 1e-17; a row in "1" reads "(no unit)", as the summary prints."""
    small = 1e-6 * (1.5 + np.sin(10 * log["t"]))
    small[0] = 1e-17
    rows = dict(log, constraint=np.column_stack([log["constraint"][:, 0], small]))
    ax = run_plots.constraint_residual_figure(rows, units="m | 1").axes[0]
    assert ax.get_yscale() == "log" and ax.get_ylabel() == "|C(r)| (m | no unit)"
    assert np.isnan(ax.lines[1].get_ydata()[0]) and np.isfinite(ax.lines[1].get_ydata()[1:]).all()
    assert ax.get_ylim()[0] >= 1e-8 * 1e-3 / 2
    assert [text.get_text() for text in ax.get_legend().get_texts()] == ["|C_1| (m)", "|C_2| (no unit)"]


def test_the_designed_decay_is_in_the_legend_when_row_0_has_none():
    """Row 0 commanded to zero with no designed error: the first decay drawn (row 1's) carries the label."""
    t = np.linspace(0.0, 1.0, 101)
    desired = np.column_stack([np.zeros_like(t), np.full_like(t, 0.5)])
    error = np.column_stack([1e-5 * np.cos(t), 0.5 * np.exp(-10 * t)])
    predicted = desired + np.column_stack([np.zeros_like(t), 0.5 * np.exp(-10 * t)])
    summary = {"task": "test", "mode": "velocity-force", "design_time_constant": 0.1, "contact_time": 0.0}
    fig = run_plots.tracking_figure({"t": t, "velocity": desired + error, "desired_velocity": desired}, summary,
                                    predicted, "velocity", labels=["psi-dot", "alpha-dot"], units="rad/s")
    ax_errors = fig.axes[1]
    dashed = [line for line in ax_errors.lines if line.get_linestyle() == "--" and line.get_color() == "k"]
    assert len(dashed) == 1 and dashed[0].get_label() == "designed error decay"
    assert "designed error decay" in {text.get_text() for text in ax_errors.get_legend().get_texts()}


def test_a_held_force_row_is_drawn_as_measured_only():
    """A held row (no force loop): its measured force only, said to be held; no command, no error line."""
    t = np.linspace(0.0, 1.0, 101)
    desired = np.column_stack([np.full_like(t, 10.0), np.zeros_like(t)])
    force = desired + np.column_stack([0.1 * np.exp(-10 * t), 1e-3 * np.sin(t)])
    summary = {"task": "test", "mode": "velocity-force", "design_time_constant": 0.1, "contact_time": 0.0,
               "force_rows": [{"name": "normal", "held": False}, {"name": "orientation row 1", "held": True}]}
    fig = run_plots.tracking_figure({"t": t, "force": force, "desired_force": desired}, summary, desired, "force",
                                    labels=["normal", "orientation row 1"], units="N")
    ax_values, ax_errors = fig.axes
    values = [line.get_label() for line in ax_values.lines]
    assert "orientation row 1 (N): measured (held by the controller, no force loop)" in values
    assert "orientation row 1: commanded" not in values and "normal: commanded" in values
    assert not any("orientation" in line.get_label() for line in ax_errors.lines)


def test_the_paper_rows_velocity_figure_draws_the_true_rows_the_summary_reports():
    """With the paper's pseudo-velocity rows the velocity figure draws the true rows: measured = true command
    + velocity_error, commanded = true_desired_velocity, and a caption says what the controller was fed."""
    t = np.linspace(0.0, 1.0, 101)
    true_command = np.column_stack([np.zeros_like(t), np.full_like(t, 0.035)])
    error = np.column_stack([1e-5 * np.ones_like(t), -0.03 * np.ones_like(t)])
    pseudo = np.column_stack([np.zeros_like(t), 0.4 * t + 0.04])
    log = {"t": t, "velocity": pseudo + error, "desired_velocity": pseudo, "velocity_error": error,
           "true_desired_velocity": true_command}
    summary = {"task": "test", "mode": "velocity-force", "design_time_constant": 0.1, "contact_time": 0.0}
    predicted = pseudo + error[0] * np.exp(-10 * t)[:, None]
    fig = run_plots.tracking_figure(log, summary, predicted, "velocity", labels=["psi-dot", "t_1 . p-dot"],
                                    units="rad/s | m/s")
    ax_values = fig.axes[0]
    measured = next(line for line in ax_values.lines if line.get_label() == "t_1 . p-dot (m/s): measured")
    commanded = next(line for line in ax_values.lines if line.get_label() == "t_1 . p-dot: commanded")
    assert np.allclose(measured.get_ydata(), 0.005) and np.allclose(commanded.get_ydata(), 0.035)
    designed = [line for line in ax_values.lines if line.get_label() == "designed response"][0]
    assert np.allclose(designed.get_ydata(), true_command[:, 0] + error[0, 0] * np.exp(-10 * t))
    assert "pseudo-velocity" in ax_values.get_title() and ax_values.get_ylabel() == "velocity (rad/s | m/s)"


def test_the_stability_maps_colour_bar_can_be_read_between_decades():
    """SymLogNorm's own ticks are only +-10^k: the bar gets 1, 2, 5 ticks and its end, so -4.9 can be read."""
    rows = [{"x": x, "y": y, "worst_discrete_real": value, "stable_simulation": value < 0}
            for (x, y), value in zip([(1, 1), (2, 1), (1, 2), (2, 2)], [-4.9, -2.0, -0.3, 1.5])]
    fig = sweep_plots.stability_map_figure(rows, "x", "y")
    ticks = list(fig.axes[-1].get_yticks())
    assert ticks == [-4.9, -2.0, -1.0, 0.0, 1.0, 2.0, 4.9]


def test_tracking_figure_has_every_line_in_a_legend_and_no_floor():
    """Per-row 1 % lines (only for rows with a command), the settling marker and the designed response in
    the legends; a zero error or a zero designed prediction is not drawn (no 1e-12 floor)."""
    t = np.linspace(0.0, 1.0, 101)
    desired = np.column_stack([np.full_like(t, 0.1), np.zeros_like(t)])
    actual = desired + np.column_stack([0.1 * np.exp(-10 * t), np.zeros_like(t)])
    actual[0, 0] = desired[0, 0]                                      # first sample equals the command
    log = {"t": t, "velocity": actual, "desired_velocity": desired}
    predicted = desired + np.column_stack([0.1 * np.exp(-10 * t), np.zeros_like(t)])
    summary = {"task": "test", "mode": "velocity-force", "design_time_constant": 0.1, "contact_time": 0.0}
    fig = run_plots.tracking_figure(log, summary, predicted, "velocity", labels=["x-dot", "theta-dot"],
                                    units="m/s | rad/s")
    ax_values, ax_errors = fig.axes
    for ax in (ax_values, ax_errors):
        legend = {text.get_text() for text in ax.get_legend().get_texts()}
        labeled = [line for line in ax.lines if not line.get_label().startswith("_")]
        assert {line.get_label() for line in labeled} == legend
        styles = {(line.get_color(), line.get_linestyle()) for line in labeled}
        for line in ax.lines:        # an unlabeled line repeats the style of one in the legend
            assert (line.get_color(), line.get_linestyle()) in styles, f"a line not in the legend: {ax.get_ylabel()}"
    legend = {text.get_text() for text in ax_errors.get_legend().get_texts()}
    assert "1 % of the x-dot command" in legend and "1 % of the theta-dot command" not in legend
    assert "5 design time constants" in legend and "|error| x-dot (m/s)" in legend
    assert ax_errors.get_ylabel() == "|velocity error| (m/s | rad/s)"
    for line in ax_errors.lines:
        if np.ptp(np.asarray(line.get_xdata(), dtype=float)) == 0:
            continue                                                  # a vertical marker (axes coordinates)
        y = np.asarray(line.get_ydata(), dtype=float)
        assert not np.any(y[np.isfinite(y)] < 1e-11), line.get_label()


@pytest.mark.parametrize("values", [[1e5, 5e5, 9e5], [0.001, 0.002, 0.004]])
def test_stability_map_cells_of_a_positive_parameter_stay_positive(values):
    edges, _ = sweep_plots._cell_edges(values)
    assert np.all(edges > 0)


def test_torque_figure_draws_the_limits(log):
    limits = [150.0, 80.0, 30.0]
    fig = run_plots.torque_figure(log, limits, joint_names=["shoulder", "elbow", "wrist"])
    panels = [ax for ax in fig.axes if ax.lines]
    assert len(panels) == 3
    for ax, limit, torque in zip(panels, limits, log["torque"].T):
        levels = sorted(line.get_ydata()[0] for line in ax.lines[1:])
        assert levels == [-limit, limit]
        assert f"{100 * np.max(np.abs(torque)) / limit:.1f} %" in ax.get_title()
        assert ax.get_ylabel() == "tau (N m)"
    assert "time t (s)" in _labels(fig)
    with pytest.raises(ValueError, match="3 actuators but 2 effort limits"):
        run_plots.torque_figure(log, [1.0, 2.0])


def test_torque_figure_with_seven_joints_labels_both_columns(log):
    seven = dict(log, torque=np.tile(log["torque"], (1, 3))[:, :7])
    fig = run_plots.torque_figure(seven, [87.0] * 4 + [12.0] * 3)
    assert [ax.get_xlabel() for ax in fig.axes].count("time t (s)") == 2


def _linearization(eigenvalues, designed):
    predicted = PredictedEigenvalues(velocity=np.array(designed[:-1], complex), force=np.array(designed[-1:], complex))
    match = match_eigenvalues(predicted.all, eigenvalues)
    return Linearization(A=np.zeros((0, 0)), eigenvalues=np.asarray(eigenvalues, complex), equilibrium_residual=0.0,
                         predicted=predicted, match=match, wall_time=0.0)


def test_eigenvalue_figures():
    measured = [-10.0, -8.03, -9.97, -1257.0, -19.3 + 111.7j, -19.3 - 111.7j]
    linearization = _linearization(measured, [-10.0, -8.0, -10.0])
    fig = eigenvalue_plots.eigenvalue_figure(linearization.match)
    assert len(fig.axes) == 2
    for ax in fig.axes:
        assert ax.get_xlabel() == "Re(s) (1/s)" and ax.get_ylabel() == "Im(s) (rad/s)"
    assert fig.axes[0].get_xscale() == "symlog"
    (re_min, re_max), (im_min, im_max) = fig.axes[1].get_xlim(), fig.axes[1].get_ylim()
    assert re_min < -10 < 0 < re_max and im_min < 0 < im_max
    # A sampled loop's modes at its Nyquist frequency (Im = pi/h) are marked off scale, not drawn as modes; a
    # task's predicted shift is drawn and written next to the miss it explains.
    period = 5e-4
    shift = SimpleNamespace(designed=-8.0 + 0j, predicted=-8.05 + 0j)
    sampled = _linearization(measured + [-1645 + np.pi / period * 1j], [-10.0, -8.0, -10.0])
    fig = eigenvalue_plots.eigenvalue_figure(sampled.match, period=period, shifts=[shift])
    ax_all, ax_zoom = fig.axes
    assert ax_all.get_ylim()[1] < 1000
    legend = [text.get_text() for text in ax_all.get_legend().get_texts()]
    assert any(text.startswith("at the Nyquist frequency pi/h = 6283 rad/s") for text in legend)
    assert "-8 -> -8.03  (0.4 %); predicted -8.05" in ax_zoom.texts[-1].get_text()
    sweep = eigenvalue_plots.eigenvalue_sweep_figure([1e6, 5e6],
                                                     [linearization, _linearization(measured, [-10.0, -8.0, -10.0])],
                                                     "pad modulus E", units="Pa")
    assert any(ax.get_ylabel() == "pad modulus E (Pa)" for ax in sweep.axes)        # the colour bar


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_the_cli_writes_every_figure(tmp_path):
    from drake_hybrid.cli import main

    out = tmp_path / "run"
    assert main(["simulate", "window-washing", "--duration", "0.2", "--out", str(out), "--no-progress"]) == 0
    for name in ("velocity_tracking", "force_tracking", "constraint_residual", "torques"):
        assert (out / f"{name}.png").stat().st_size > 10_000, name
    figure = tmp_path / "eigenvalues.png"
    assert main(["analyze", "window-washing", "--plot", str(figure)]) == 0
    assert figure.stat().st_size > 10_000


def test_tracking_figure_marks_the_runs_phases_and_explains_the_start():
    """A phase of the run (a span) is shaded on both axes and named in the legend; the force figure of a
    start in contact says what its first samples are, with the step xi(0) adds to the first command."""
    t = np.linspace(0.0, 3.0, 301)
    desired = np.full((t.size, 1), -10.0)
    log = {"t": t, "force": desired + 0.1, "desired_force": desired, "velocity": np.zeros((t.size, 1)),
           "desired_velocity": np.full((t.size, 1), 0.1)}
    summary = {"task": "test", "mode": "impedance-force", "design_time_constant": 0.1, "contact_time": 0.0,
               "events": [{"start": 1.67, "end": 2.8, "label": "pad on the rough patch (mu = 0.9)"}],
               "start_in_contact": True, "start_force_command_step": [3.0],
               "force_rows": [{"name": "F", "units": "N"}]}
    fig = run_plots.tracking_figure(log, summary, desired, "force", labels=["F"], units="N", note="a task's note")
    ax_values, ax_errors = fig.axes
    for ax in (ax_values, ax_errors):
        spans = [patch for patch in ax.patches if patch.get_x() == pytest.approx(1.67)]
        assert len(spans) == 1 and spans[0].get_width() == pytest.approx(1.13)
    assert "pad on the rough patch (mu = 0.9)" in {text.get_text() for text in ax_errors.get_legend().get_texts()}
    title = ax_values.get_title().replace("\n", " ")
    assert "presses with the commanded force" in title and "K_fi xi(0) = 3 N" in title, title
    assert "velocity command steps from rest" in title and "a task's note" in title
    instants = [{"start": start, "end": None, "label": "a switch"} for start in (0.7, 1.2)]
    fig = run_plots.tracking_figure(log, dict(summary, events=instants), desired, "force", labels=["F"], units="N")
    legend = [text.get_text() for text in fig.axes[1].get_legend().get_texts()]
    assert legend.count("a switch") == 1                               # one entry for several instants
    assert sum(np.ptp(line.get_xdata()) == 0 and line.get_xdata()[0] in (0.7, 1.2) for line in fig.axes[1].lines) == 2
    velocity = run_plots.tracking_figure(log, summary, np.full((t.size, 1), 0.1), "velocity", labels=["x-dot"])
    assert "\n" not in velocity.axes[0].get_title()                   # the start's words are the force figure's
