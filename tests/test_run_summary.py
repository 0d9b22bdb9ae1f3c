"""What a run reports: per-row errors in each row's units, settling and predictions from contact."""

import dataclasses
import json
import math
import re
from types import SimpleNamespace

import numpy as np
import pytest

from drake_hybrid.cli import main
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.experiments.metrics import ForceRowFigures, contact_time, row_errors, row_units, worst
from drake_hybrid.experiments.simulation import predicted_tracking, simulate
from drake_hybrid.experiments.summary import RunSummary
from drake_hybrid.report.run import residual_text, row_text
from drake_hybrid.tasks.registry import TASKS, get_task


def test_row_units_split_a_tasks_label_per_row():
    assert row_units("m/s | rad/s", 2) == ["m/s", "rad/s"]
    assert row_units("N", 3) == ["N", "N", "N"]
    for name, task in TASKS.items():
        labels = task.labels()
        config = task.default_config()
        space = task.constraint_space(config)
        for what, size in (("velocity", space.velocity_size), ("force", space.force_size)):
            parts = [p.strip() for p in labels[f"{what}_units"].split("|")]
            assert len(parts) in (1, size), (name, what, parts)       # one unit per row, or one for all
            assert all("(" not in p for p in parts), (name, what, parts)


def test_each_row_is_in_its_own_units_and_percent_of_its_own_command():
    """A 1 mm/s error on a 0.1 m/s row is 1 %, whatever the other rows do; a row commanded to zero is
    judged against the largest command in its units (a cross-track m/s row against the speed), else
    against the run's command scale: no row drops out of the headline."""
    t = np.linspace(0.0, 1.0, 101)
    desired = np.column_stack([np.full_like(t, 0.1), np.zeros_like(t), np.zeros_like(t)])     # m/s, m/s, rad/s
    error = np.column_stack([np.full_like(t, 1e-3), np.full_like(t, 3.2e-3), np.full_like(t, 5e-4)])
    rows = row_errors(t, error, desired, ["x-dot", "y-dot", "theta-dot"], ["m/s", "m/s", "rad/s"], since=0.0,
                      settle_after=0.5)
    assert rows[0].units == "m/s" and rows[0].final_error_percent == pytest.approx(1.0)
    assert rows[0].max_error_percent_after_5_time_constants == pytest.approx(1.0)
    assert rows[0].scale_of == "command" and rows[0].scale == pytest.approx(0.1)
    # the cross-track row, commanded zero: 3.2 mm/s is 3.2 % of the 0.1 m/s slide
    assert rows[1].scale_of == "rows in its units" and rows[1].final_error_percent == pytest.approx(3.2)
    assert rows[1].settling_time_1_percent == math.inf
    # no rad/s command: the run's command scale, |(0.1, 0, 0)|
    assert rows[2].scale_of == "run" and rows[2].final_error == pytest.approx(5e-4)
    assert rows[2].final_error_percent == pytest.approx(0.5)
    assert worst(rows, "max_error_percent_after_5_time_constants") == pytest.approx(3.2)


def test_the_summary_is_typed_and_its_dict_is_summary_json(tmp_path):
    """simulate's summary is a RunSummary read by attribute (its rows RowFigures, the force rows
    ForceRowFigures); as_dict() is summary.json's dict, key for key and in order, and from_dict reads it back."""
    result = simulate(get_task("window-washing").default_config(duration=0.05))
    summary = result.summary
    assert isinstance(summary, RunSummary) and summary.status == "completed" and summary.task == "window-washing"
    assert all(isinstance(row, ForceRowFigures) for row in summary.force_rows)
    assert not any(isinstance(row, ForceRowFigures) for row in summary.velocity_rows)
    written = json.loads(summary.to_json())
    assert list(written) == [field.name for field in dataclasses.fields(RunSummary)]
    assert list(written["force_rows"][0])[-2:] == ["held", "max_measured_force_after_contact"]
    assert "held" not in written["velocity_rows"][0]
    again = RunSummary.from_dict(summary.as_dict())
    assert again == summary and again.to_json() == summary.to_json()
    read = RunSummary.from_dict(written).force_rows[0]            # the file's inf ("never") reads None
    assert isinstance(read, ForceRowFigures) and read.final_error == summary.force_rows[0].final_error
    with pytest.raises(TypeError, match="no_such_key"):
        RunSummary.from_dict(dict(written, no_such_key=1))


def test_settling_is_counted_from_contact():
    """Off the surface the force error is 100 % until contact at 0.4 s, then decays as e^(-10 t')."""
    t = np.linspace(0.0, 1.5, 1501)
    phase = np.where(t < 0.4, int(ContactPhase.APPROACH), int(ContactPhase.CONTACT))[:, None]
    log = {"t": t, "contact_phase": phase}
    start = contact_time(log)
    assert start == pytest.approx(0.4)
    error = np.where(t < start, 10.0, 10.0 * np.exp(-10.0 * (t - start)))[:, None]
    (row,) = row_errors(t, error, np.full((t.size, 1), 10.0), ["F"], ["N"], since=start, settle_after=start + 0.5)
    assert row.settling_time_1_percent == pytest.approx(math.log(100) / 10.0, abs=2e-3)   # 0.46 s after contact
    assert row.max_error_percent_after_5_time_constants == pytest.approx(100 * math.exp(-5), rel=1e-2)
    assert contact_time({"t": t, "contact_phase": np.zeros((t.size, 1))}) == math.inf
    assert contact_time({"t": t}) == 0.0                      # no supervisor: the run starts in contact


def test_an_off_surface_start_is_summarized_and_predicted_from_contact():
    """Window washing 10 mm below the pane: the summary's figures start at contact (0.54 s), and the
    predicted exponentials start there, from the measured velocity error at contact (none before)."""
    config = get_task("window-washing").default_config()
    config.duration, config.start.force_integral, config.start.in_contact = 1.3, [], False
    result = simulate(config)
    summary, log = result.summary, result.log
    assert 0.5 < summary.contact_time < 0.6
    force = summary.force_rows[0]
    # The designed force loop settles to 1 % within 5 time constants of contact, not of t = 0.
    assert force.settling_time_1_percent < 5 * summary.design_time_constant
    assert summary.max_force_error_percent_after_5_time_constants < 1.0
    # C(r) before contact is the 10 mm gap; after it, the pad's compression (about 1 mm).
    assert summary.max_constraint_residual == pytest.approx(0.01, rel=0.05)
    assert summary.max_constraint_residual_after_contact < 2e-3
    velocity, force_prediction = predicted_tracking(result.scenario, config, log)
    at = int(np.argmax(log["t"] >= summary.contact_time))
    assert np.all(np.isnan(velocity[:at])) and np.all(np.isnan(force_prediction[:at]))
    np.testing.assert_allclose(velocity[at], log["velocity"][at], atol=1e-12)


@pytest.mark.slow
def test_the_grinding_default_says_it_ends_in_the_surge_after_the_rough_patch():
    """The default 3 s grinding run ends 0.2 s after the pad leaves the rough patch: the summary says
    so (and how long a run ending in steady sliding is), instead of a bare 26 % speed error."""
    result = simulate(get_task("grinding").default_config())
    edges, force, note = result.summary.notes
    assert "after the pad left the rough patch" in note and "--duration 3.8" in note and "x-dot's final error" in note
    # x-dot's settled max (75 %) is the impedance's answer to the patch's friction steps, and the note says so.
    assert "entering it" in edges and "leaving it" in edges and "peaking at 0.077 m/s" in edges
    x_dot = result.summary.velocity_rows[0]
    assert x_dot.units == "m/s" and x_dot.final_error_percent > 5
    # F's settled max (6.6 %) is the force loop's answer to the same steps, just after the pad leaves the patch
    # (the summary's event); away from the edges F stays within 1 %.
    (span,) = result.summary.events
    F = result.summary.force_rows[0]
    assert 0 <= F.max_error_time_after_5_time_constants - span["end"] < 0.3
    assert "(3.2-11)" in force and "leaving it" in force
    away = float(re.search(r"at most [\d.e-]+ N \(([\d.]+) %\)", force).group(1))
    assert away < 1.0 < F.max_error_percent_after_5_time_constants


def test_the_impedance_step_peak_is_the_designed_impulse_response_at_its_largest():
    from drake_hybrid.tasks.builtin.grinding import impedance_step_peak

    # Roots -10 and -30 (K_v = 40, K_p = 300): (e^(-10 t) - e^(-30 t)) / 20, largest at t = ln 3 / 20.
    assert impedance_step_peak(40.0, 300.0) == pytest.approx((3 ** -0.5 - 3 ** -1.5) / 20, rel=1e-6)
    assert impedance_step_peak(20.0, 100.0) == pytest.approx(1 / (10 * math.e), rel=1e-6)    # double root -10


def test_impedance_grinding_explains_x_dots_error_at_the_rough_patchs_edges():
    """The default grinding run's x-dot 'settled max' (75 %) is the impedance yielding to the friction step
    at the patch's edges: the note gives that peak as (3.2-6) predicts it and as measured after each edge."""
    from drake_hybrid.tasks.builtin.grinding import friction_step_notes, impedance_step_peak

    t = np.arange(0.0, 3.0005, 1e-3)
    x = 0.85 + 0.1 * t                                                  # on the patch [1.05, 1.15] from 2 to 3 s
    response = lambda since: np.where(t >= since, (np.exp(-10 * (t - since)) - np.exp(-30 * (t - since))) / 20, 0)
    error = -4.0 * response(2.0) + 4.0 * response(2.6)                  # a 4 N step in, then out (at 2.6 s here)
    x[t >= 2.6] = 1.2                                                  # off the patch from 2.6 s
    (note,) = friction_step_notes(t, x, error, 0.1, 10.0, 40.0, 300.0, 1.05, 1.15, 0.5, 0.9)
    peak = 4.0 * impedance_step_peak(40.0, 300.0)
    assert f"(0.9 - 0.5) x 10 N = 4 N" in note and f"peaking at {peak:.3g} m/s (77 % of the command)" in note
    assert re.search(r"measured 0\.077 m/s \(77 %\) entering it \(t = 2\.00 s, peak at 2\.0[56] s\); "
                     r"0\.0\d+ m/s \(\d+ %\) leaving it \(t = 2\.60 s", note), note
    assert friction_step_notes(t, np.full_like(t, 0.5), error, 0.1, 10.0, 40.0, 300.0, 1.05, 1.15, 0.5, 0.9) == []


def _sphere_log(breakaway, end, force_error=0.357):
    """A grinding-on-the-sphere log: the path row (t_1 . p-dot, 0.035 m/s) still until ``breakaway``."""
    t = np.arange(0.0, end + 5e-4, 1e-3)
    desired = np.tile([0.0, 0.035, 0.0], (t.size, 1))
    velocity = np.where((t >= breakaway)[:, None], desired, 0.0)
    force_error = np.tile([force_error, 0.0, 0.0], (t.size, 1))
    return {"t": t, "desired_velocity": desired, "velocity": velocity, "force_error": force_error,
            "desired_force": np.tile([10.0, 0.0, 0.0], (t.size, 1))}


def test_the_sphere_grinding_note_names_the_phase_the_run_ends_in():
    from drake_hybrid.tasks.builtin.grinding import SPHERE_SETTLED_AFTER_SLIDING, sphere_phase_note

    (note,) = sphere_phase_note(_sphere_log(breakaway=0.562, end=3.0))
    assert "held the pad until t = 0.56 s" in note and "ends 2.44 s into sliding" in note
    assert "(3.57 %)" in note and "(3.2-11)" in note and "--duration 6 ends in steady sliding" in note
    (late,) = sphere_phase_note(_sphere_log(breakaway=0.562, end=0.562 + SPHERE_SETTLED_AFTER_SLIDING + 0.1))
    assert late.endswith("the run ends in steady sliding")
    (stuck,) = sphere_phase_note(_sphere_log(breakaway=5.0, end=3.0))
    assert "static friction holding the pad" in stuck and "0 % of the command" in stuck
    assert sphere_phase_note({**_sphere_log(0.5, 1.0), "desired_velocity": np.zeros((1001, 3))}) == []


@pytest.mark.slow
def test_the_sphere_grinding_summary_says_when_the_pad_broke_away():
    """Measured, not assumed: the default sphere run's pad sticks for about half a second (the tangential
    impedance building mu F_n = 5 N at K_p = 300), then slides."""
    config = get_task("grinding").default_config({"workpiece": "sphere"})
    config.duration = 1.0
    result = simulate(config)
    (note,) = result.summary.notes
    breakaway = float(re.search(r"held the pad until t = ([0-9.]+) s", note).group(1))
    assert 0.3 < breakaway < 0.8 and "into sliding" in note
    config.contact.friction = 0.0                 # nothing to break away from, and no force error from it
    frictionless = simulate(config)
    assert frictionless.summary.notes == [] and frictionless.summary.final_force_error_percent < 0.1


@pytest.mark.slow
def test_the_crank_summary_prints_the_true_crank_rates_deviation_for_both_velocity_rows():
    """The README's 3.1 times: each crank run's note gives the true crank rate's deviation from the
    designed exponential, for Option A and for the paper's naive pseudo-velocity."""
    deviations = {}
    for rows in ("true", "paper"):
        config = get_task("crank-turning").default_config({"velocity_rows": rows})
        config.duration = 0.6
        (note,) = simulate(config).summary.notes
        deviations[rows] = float(re.search(r"deviates at most ([0-9.e+-]+) rad/s", note).group(1))
    assert deviations["true"] < 0.01 * 0.5
    assert deviations["paper"] > 3.0 * deviations["true"]


def test_grinding_on_the_sphere_labels_its_rows_as_the_sphere_task():
    grinding = get_task("grinding")
    config = grinding.default_config({"workpiece": "sphere"})
    rows = lambda labels: {key: value for key, value in labels.items() if not key.endswith("_note")}
    assert rows(grinding.labels(config)) == rows(get_task("sphere-polishing").labels())
    assert rows(grinding.labels(grinding.default_config())) == rows(get_task("window-washing").labels())
    # impedance/force (the default) says what its designed response leaves out; velocity/force has no such note
    assert "(3.2-6)" in grinding.labels(config)["velocity_note"]
    assert "velocity_note" not in grinding.labels(grinding.default_config().replace(mode="velocity-force"))


def test_the_settled_max_says_when_and_in_which_phase_of_the_run():
    """The row's worst error after the start's transient comes with its time, and the CLI names the run's
    phase it falls in or just after (the grinding force peak 0.007 s after the pad left the rough patch)."""
    t = np.arange(0.0, 3.0005, 1e-3)
    error = np.where(np.abs(t - 2.807) < 5e-4, 0.661, 0.03)[:, None]
    (row,) = row_errors(t, error, np.full((t.size, 1), 10.0), ["F"], ["N"], since=0.0, settle_after=0.5)
    assert row.max_error_time_after_5_time_constants == pytest.approx(2.807)
    events = [{"start": 1.67, "end": 2.80, "label": "pad on the rough patch (mu = 0.9)"}]
    assert "settled max 0.661 N (6.61 %) at t = 2.807 s, 0.01 s after the end of: pad on the rough patch" in \
        row_text(row, events)
    assert row_text(row, [{"start": 1.0, "end": None, "label": "x"}]).count("after") == 1   # only 'after contact'
    assert "switch" not in row_text(row, [{"start": 2.8, "end": None, "label": "switch", "explains_errors": False}])
    assert "0.01 s after the moment of: slip" in row_text(row, [{"start": 2.8, "end": None, "label": "slip"}])
    notes = ["x-dot's error at the rough patch's edges is the designed impedance yielding to the friction force",
             "F's error at the rough patch's edges is the force loop answering the friction force's step"]
    assert row_text(row, events, notes).endswith("pad on the rough patch (mu = 0.9), within 1 % from 2.808 s after "
                                                  "contact on; see note 2")


def test_a_row_points_only_at_the_notes_that_name_it():
    """The default grinding run's notes name x-dot (its settled max at the patch's edges, its final error in
    the surge after the patch) and F; theta-dot, whose settled max also falls on the patch, is in none."""
    t = np.arange(0.0, 3.0005, 1e-3)
    error = np.where(np.abs(t - 1.7) < 5e-4, 0.07, np.where(t > 2.9, 0.026, 0.0))[:, None]
    (x_dot,) = row_errors(t, error, np.full((t.size, 1), 0.1), ["x-dot"], ["m/s"], since=0.0, settle_after=0.5)
    (theta_dot,) = row_errors(t, error, np.zeros((t.size, 1)), ["theta-dot"], ["rad/s"], since=0.0,
                              settle_after=0.5)
    (force,) = row_errors(t, error, np.full((t.size, 1), 10.0), ["F, along E_f = [0 1 0]"], ["N"], since=0.0,
                          settle_after=0.5)
    events = [{"start": 1.67, "end": 2.80, "label": "pad on the rough patch (mu = 0.9)"}]
    notes = ["x-dot's error at the rough patch's edges is the designed impedance yielding to the friction force "
             "(F_v, measured by the F/T sensor)",
             "F's error at the rough patch's edges is the force loop answering the friction force's step",
             "the run ends 0.20 s after the pad left the rough patch: so x-dot's final error is that transient's"]
    assert row_text(x_dot, events, notes).endswith("not within 1 % at the end; see notes 1, 3")
    assert "see note" not in row_text(theta_dot, events, notes)
    assert "0.03 s after the start of: pad on the rough patch" in row_text(theta_dot, events, notes)
    assert row_text(force, events, notes).endswith("; see note 2")


def test_impedance_grinding_explains_fs_error_at_the_rough_patchs_edges():
    """The default grinding run's force 'settled max' (6.6 %, 0.661 N) is the force loop's answer to the
    friction step at the patch's edges (3.2-11): the note names each edge's peak and the error away from them."""
    from drake_hybrid.tasks.builtin.grinding import force_step_note, rough_patch_events

    t = np.arange(0.0, 3.0005, 1e-3)
    on_patch = (t >= 1.67) & (t < 2.80)
    ring = lambda since, size: np.where(t >= since, size * np.exp(-20 * (t - since)) * np.cos(60 * (t - since)), 0)
    error = 0.03 + ring(1.67, 0.4) + ring(2.80, -0.63)
    note = force_step_note(t, error, 10.0, on_patch, 0.5)
    assert "(3.2-11)" in note and "0.43 N (4.3 %) entering it (peak at t = 1.67 s)" in note, note
    assert "0.6 N (6.0 %) leaving it (peak at t = 2.80 s)" in note, note      # |0.03 - 0.63|
    assert "away from the edges (t >= 0.50 s, 0.05 s before to 0.3 s after each) at most 0.03" in note, note
    assert force_step_note(t, error, 10.0, np.zeros_like(on_patch), 0.5) is None
    x = np.where(on_patch, 1.1, np.where(t < 1.67, 1.0, 1.2))
    (span,) = rough_patch_events(t, x, 1.05, 1.15, 0.9)
    assert span["start"] == pytest.approx(1.67) and span["end"] == pytest.approx(2.80)
    assert span["label"] == "pad on the rough patch (mu = 0.9)"
    assert rough_patch_events(t, np.full_like(t, 0.5), 1.05, 1.15, 0.9) == []


def test_the_sphere_grinding_breakaway_is_an_event():
    from drake_hybrid.tasks.builtin.grinding import sphere_breakaway

    assert sphere_breakaway(_sphere_log(breakaway=0.562, end=3.0)) == pytest.approx(0.562)
    assert sphere_breakaway(_sphere_log(breakaway=5.0, end=3.0)) is None            # still held at the end


def test_the_sphere_constraints_piece_switches_are_events():
    """(2.2-8) with the equator fix drops the component of (p - c) x a along the largest |a_k|: each change of
    piece along the run is an instant the plots mark (its orientation rows change basis there)."""
    from types import SimpleNamespace

    from drake_hybrid.tasks.task import piece_switches

    class Plant:
        def num_positions(self):                 # piece_switches checks the log's rows against it
            return 3

        def CreateDefaultContext(self):
            return {}

        def SetPositions(self, context, q):
            context["q"] = q

    kinematics = SimpleNamespace(evaluate=lambda context: SimpleNamespace(configuration=context["q"]))
    constraint = SimpleNamespace(pieces=[0, 1, 2], select=lambda x: int(np.argmax(np.abs(x))))
    scenario = SimpleNamespace(constraint_space=SimpleNamespace(constraint=constraint), controller_plant=Plant(),
                               controller=SimpleNamespace(kinematics=kinematics))
    t = np.arange(0.0, 1.0005, 0.1)
    q = np.array([[1.0, 0.5, 0.0]] * 4 + [[0.5, 1.0, 0.0]] * 3 + [[1.0, 0.5, 0.0]] * 4)
    events = piece_switches(scenario, {"t": t, "q": q})
    assert [event["start"] for event in events] == pytest.approx([0.4, 0.7])
    assert all(event["end"] is None and "switches piece" in event["label"] for event in events)
    assert not any(event["explains_errors"] for event in events)          # held rows' basis: no row's error
    one_piece = SimpleNamespace(constraint_space=SimpleNamespace(constraint=SimpleNamespace()))
    assert piece_switches(one_piece, {"t": t, "q": q}) == []


def test_a_held_row_prints_as_held_with_its_measured_force_not_as_an_error():
    """A row the controller holds kinematically (no force loop, no force commanded) has no force error to
    report; what it shows is the force measured along it."""
    held = ForceRowFigures(name="orientation row 1", units="N", command=0.0, scale=None, scale_of=None,
                           final_error=None, final_error_percent=None, max_error_after_5_time_constants=None,
                           max_error_percent_after_5_time_constants=None, max_error_time_after_5_time_constants=None,
                           settling_time_1_percent=None, held=True, max_measured_force_after_contact=0.00153)
    assert row_text(held) == ("held by the controller (no force commanded); measured force up to 0.00153 N "
                              "after contact")
    held.max_measured_force_after_contact = None                  # a sensor fault: nothing measured to report
    assert row_text(held) == "held by the controller (no force commanded)"
    tracked = dataclasses.replace(held, held=False, command=10.0, final_error=0.5, final_error_percent=5.0)
    assert row_text(tracked).startswith("command 10 N; final error 0.5 N (5.00 %)")


def test_the_sphere_summary_lists_its_held_rows_and_their_measured_force(tmp_path, capsys):
    """Sphere polishing: the orientation rows 2 and 3 are held by the controller (a point contact cannot
    hold them); summary.json names them and their largest measured force after contact, the command line
    prints them as held."""
    out = tmp_path / "run"
    assert main(["simulate", "sphere-polishing", "--duration", "0.05", "--no-plots", "--quiet", "--out",
                     str(out)]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["held"] == ["orientation row 1", "orientation row 2"]
    log = np.load(out / "log.npz")
    after = log["t"] >= summary["contact_time"]
    for i, row in enumerate(summary["force_rows"]):
        assert row["held"] == (i in (1, 2))
        assert row["max_measured_force_after_contact"] == pytest.approx(np.abs(log["force"][after, i]).max())
        # No command, so no error: a held row's error figures are null, not a measured 0.
        errors = [key for key in row if "error" in key or key == "settling_time_1_percent"]
        assert len(errors) == 6
        assert all(row[key] is None for key in errors) if row["held"] else row["final_error_percent"] is not None
        if row["held"]:
            assert (f"force {row['name']}: held by the controller (no force commanded); measured force up to "
                    f"{row['max_measured_force_after_contact']:.3g} N after contact") in printed
    assert "normal force: command 10 N; final error" in printed
    # C's rows are all in m on the sphere: one figure, with its unit.
    assert summary["constraint_units"] == ["m", "m", "m"]
    assert f"max |C(r)| after contact {summary['max_constraint_residual_after_contact']:.3g} m\n" in printed


def test_the_constraint_residual_is_printed_in_cs_units():
    one = RunSummary(task="window-washing", mode="velocity-force", duration=1.0,
                     max_constraint_residual_after_contact=8.4e-4, constraint_units=["m"],
                     max_constraint_residual_rows_after_contact=[8.4e-4])
    assert residual_text(one) == "max |C(r)| after contact 0.00084 m"
    crank = dataclasses.replace(one, max_constraint_residual_after_contact=1.5e-5,
                                constraint_units=["m^2", "m", "1", "m"],
                                max_constraint_residual_rows_after_contact=[1.5e-5, 2e-6, 3e-7, 4e-6])
    assert residual_text(crank) == ("max |C_i(r)| after contact, per row of C: 1.5e-05 m^2, 2e-06 m, "
                                    "3e-07 (no unit), 4e-06 m")
    custom = dataclasses.replace(one, constraint_units=None)        # a task that names no units for C
    assert residual_text(custom) == "max |C(r)| after contact 0.00084 (in the units of C's rows)"
    assert residual_text(dataclasses.replace(one, max_constraint_residual_after_contact=None)) == "no contact made"


def test_the_paper_rows_are_labelled_as_pseudo_velocities_in_their_mixed_units():
    """The paper's E_p rows are pseudo-velocities: the crank's row 2 is -Y x-dot + X y-dot + phi-dot
    (m^2/s plus rad/s), the sphere's rows 2 and 3 t_i . p-dot + beta_i . (phi-dot, theta-dot) with beta_i
    in 1/m (m/s plus rad/m/s). Their error, E_t r-dot - r-dot_td, is the true rows', in the true rows'
    units; the true-velocity rows keep their own units."""
    crank, sphere = get_task("crank-turning"), get_task("sphere-polishing")
    paper = crank.labels(crank.default_config({"velocity_rows": "paper"}))
    assert row_units(paper["velocity_units"], 2) == ["rad/s", "m^2/s + rad/s"]
    assert paper["velocity"][1].startswith("pseudo-velocity")
    assert row_units(paper["velocity_error_units"], 2) == ["rad/s", "rad/s"]
    assert paper["velocity_error"][1].startswith("alpha-dot (crank)")
    assert row_units(crank.labels(crank.default_config())["velocity_units"], 2) == ["rad/s", "rad/s"]
    assert "velocity_error" not in crank.labels(crank.default_config())
    paper = sphere.labels(sphere.default_config({"velocity_rows": "paper", "chart": "euler"}))
    assert row_units(paper["velocity_units"], 3) == ["rad/s", "m/s + rad/m/s", "m/s + rad/m/s"]
    assert all(name.startswith("pseudo-velocity") for name in paper["velocity"][1:])
    assert row_units(paper["velocity_error_units"], 3) == ["rad/s", "m/s", "m/s"]
    assert row_units(sphere.labels(sphere.default_config())["velocity_units"], 3) == ["rad/s", "m/s", "m/s"]


def test_the_crank_paper_rows_error_is_reported_against_the_true_command_in_rad_per_s():
    """With velocity_rows=paper the controller is fed the pseudo-velocity (0.519 at the start, mixed units)
    but its error e_p' is the true crank rate's (PseudoVelocitySource): the summary's row is alpha-dot's,
    in rad/s, in % of the true 0.5 rad/s command."""
    config = get_task("crank-turning").default_config({"velocity_rows": "paper"})
    config.duration = 0.05
    result = simulate(config)
    log, (spin, rate) = result.log, result.summary.velocity_rows
    np.testing.assert_array_equal(log["true_desired_velocity"], np.tile([0.0, 0.5], (log["t"].size, 1)))
    assert np.max(log["desired_velocity"][:, 1]) > 0.505                  # the pseudo-velocity, not the command
    assert rate.name.startswith("alpha-dot (crank)") and rate.units == "rad/s" and rate.command == 0.5
    assert rate.final_error_percent == pytest.approx(100 * abs(log["velocity_error"][-1, 1]) / 0.5)
    assert spin.units == "rad/s" and spin.command == 0.0
    assert "true_desired_velocity" not in simulate(get_task("crank-turning").default_config(duration=0.05)).log


@pytest.mark.slow
def test_the_sphere_paper_rows_note_gives_the_measured_shortfall_and_why():
    """README: with the paper's (3.3-11) rows t_1 . p-dot ends 84 % short of its command after 0.6 s; the
    run's note says so (the printed row's figure) and why (docs/theory.md §6), as the crank's does."""
    config = get_task("sphere-polishing").default_config({"velocity_rows": "paper", "chart": "euler"})
    config.duration = 0.6
    summary = simulate(config).summary
    (note,) = summary.notes
    row = summary.velocity_rows[1]
    shortfall = float(re.search(r"t_1 . p-dot ends ([0-9]+) % short of its", note).group(1))
    assert shortfall == pytest.approx(abs(row.final_error_percent), abs=0.5) and row.final_error < 0
    assert 80 < shortfall < 90 and "pseudo-velocity" in note and "docs/theory.md §6" in note
    default = get_task("sphere-polishing").default_config()
    assert get_task("sphere-polishing").run_notes(SimpleNamespace(config=default), {"t": np.zeros(2)}, 0.1) == []
