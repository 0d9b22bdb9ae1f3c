"""A job's figures (experiments.path_report, station.path_job.path_events) on a synthetic log whose
every number is known: the split of the path error along the surface and the normal, the settled and
transient windows per segment, the time off the surface, the lift-off."""

import numpy as np
import pytest

from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.experiments.path_report import before_lift_off, path_report, path_text
from drake_hybrid.station.path_job import path_events


def synthetic_log():
    """4 s at 1 ms: approach to 0.2 s, dwell to 0.5 s, two segments (0.5-1.5 s, 1.5-2.5 s), contact lost
    between 1.0 and 1.05 s, the path done at 2.5 s and the lift-off from 3.0 s."""
    t = np.arange(0.0, 4.0, 0.001)
    n = len(t)
    normal = np.tile([0.0, 0.6, 0.8], (n, 1))
    tangent = np.array([1.0, 0.0, 0.0])
    along = np.where(t < 1.5, 2e-4 + 1e-3 * (t < 0.6), 1e-4)         # m: a 1 mm transient at the first start
    error = along[:, None] * tangent - 9e-4 * normal                  # compressed 0.9 mm
    segment = np.where(t < 0.5, -1, np.where(t < 1.5, 0, np.where(t - 0.5 <= 2.0, 1, 2))).astype(float)
    t_path = t - 0.5
    arc = np.clip(t_path, 0, 2.0) * 0.05
    phase = np.full(n, float(ContactPhase.CONTACT))
    phase[t < 0.2] = ContactPhase.APPROACH
    phase[(t >= 1.0) & (t < 1.05)] = ContactPhase.APPROACH
    phase[t >= 3.0] = ContactPhase.HOLD
    force = np.full((n, 3), 0.0)
    force[:, 0] = 10.0                                                # the controller's row: its own reading
    measured = 10.0 + np.where(t < 1.5, 0.1, 0.05)                    # the sensor's: 1 % then 0.5 % high
    friction = 0.7 * np.array([1.0, 0.0, 0.0])                        # a tangential force: not a normal force
    wrench = np.column_stack([np.full((n, 3), 0.01), measured[:, None] * normal + friction])
    return {"t": t, "path_error": error, "reference_normal": normal, "wrench": wrench,
            "path_progress": np.column_stack([segment, arc, t_path]), "force": force,
            "desired_force": np.tile([10.0, 0.0, 0.0], (n, 1)), "contact_phase": phase[:, None],
            "lifting": (t >= 3.0).astype(float)[:, None], "path_done": (t_path > 2.0).astype(float)[:, None],
            "velocity_error": np.zeros((n, 3))}


def test_the_report_splits_the_error_and_finds_the_windows():
    report = path_report(synthetic_log(), design_time_constant=0.02, path_duration=2.0, path_length=0.1)
    assert report.completed and report.segments_run == 2
    assert report.first_contact_time == pytest.approx(0.2)
    assert report.path_start_time == pytest.approx(0.5) and report.lift_off_time == pytest.approx(3.0)
    assert report.max_path_error_along_normal_mm == pytest.approx(0.9)
    # Settled from each segment's start + 0.1 s: the first segment's 1 mm transient (to 0.6 s) is not in it.
    assert report.max_path_error_along_surface_mm == pytest.approx(0.2)
    assert report.first_segment_max_path_error_along_surface_mm == pytest.approx(1.2)
    assert report.line_change_max_path_error_along_surface_mm == pytest.approx(0.1)
    assert report.max_path_error_mm == pytest.approx(np.hypot(0.2, 0.9))
    # The force error is the sensor's normal force against the command, not the controller's own row.
    assert report.max_force_error_percent == pytest.approx(1.0)
    assert report.max_force_error_N == pytest.approx(0.1)
    assert [s.max_path_error_along_surface_mm for s in report.segments] == pytest.approx([0.2, 0.1])
    assert report.time_off_surface_s == pytest.approx(0.05, abs=1.5e-3) and report.contact_losses == 1
    assert any("0.050 s (1 contact losses)" in line for line in path_text(report))


def test_the_events_and_the_log_before_the_lift_off():
    log = synthetic_log()
    events = path_events(log)
    labels = [e["label"] for e in events]
    assert labels == ["guarded approach", "pressing at the path's first point (dwell)",
                      "a line change (segment start)", "lift-off"]
    assert events[2]["start"] == pytest.approx(1.5) and events[-1]["start"] == pytest.approx(3.0)
    cut = before_lift_off(log)
    assert cut["t"][-1] < 3.0 and len(cut["force"]) == len(cut["t"])


def test_the_force_error_is_the_measured_normal_force_against_the_command():
    """A controller row that misreads the contact (reading 10 N where the sensor measures 9.92 N along the
    normal: a constraint whose gradient is not the unit normal) shows as a 0.8 % force error; the sensor's own
    wrench (true_wrench) is read where a filter follows it."""
    log = synthetic_log()
    normal = log["reference_normal"]
    log["wrench"] = np.column_stack([np.zeros((len(log["t"]), 3)), 9.92 * normal])
    report = path_report(log, design_time_constant=0.02, path_duration=2.0, path_length=0.1)
    assert report.max_force_error_percent == pytest.approx(0.8)
    log["true_wrench"] = np.column_stack([np.zeros((len(log["t"]), 3)), 10.03 * normal])
    report = path_report(log, design_time_constant=0.02, path_duration=2.0, path_length=0.1)
    assert report.max_force_error_percent == pytest.approx(0.3)
