"""A job's figures: how closely the pad followed its path over the workpiece, at what force, and how
long it was off the surface (``summary.json``'s ``path``, the printout, the plots).

From the log of a path job (``station.path_job``: ``path_error`` = c - c_d, ``reference_normal``,
``path_progress`` = [segment, arc length, t_path], the measured wrench, the commanded force, the
supervisor's ``contact_phase`` and ``lifting``):

* the path error, the distance of the pad centre from its reference point (mm): in all, along the
  surface (its part in the tangent plane: where on the workpiece the pad is) and along the normal
  (the compliant contact's compression: the reference lies on C = 0, the pressed pad inside it);
* the force error along the path, |F_n - F_d| in N and in % of F_d: F_n the normal force measured by the
  sensor (``normal_force``: the logged wrench, the sensor's own, along the surface's outward normal), F_d
  the path's command; not the controller's own force row, so that a row that misreads the contact (a
  constraint whose gradient is not the unit normal) shows here as a force error;
* both per segment (a stroke from rest to rest: a raster line, the step to the next one), over its
  *settled* part (from the segment's start + five design time constants to its end) and over its
  first five time constants (the transient at the line change; in the first segment, the approach's
  landing, still settling when the path starts after its dwell);
* the time off the surface: how long the supervisor was out of CONTACT between the first contact and
  the lift-off, and how often contact was lost;
* the job's timeline: first contact, the path's start and end, the lift-off, and how much of the
  path was run.

``path_report`` returns them as a ``PathReport`` (its ``segments`` a list of ``SegmentReport``), whose
``as_dict()`` is summary.json's ``path``; ``path_text`` prints it. Pure numpy on the logged arrays, no Drake.
"""

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Optional, Tuple

import numpy as np

from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.core.hints import Array


@dataclass
class SegmentReport:
    """One segment's figures (a stroke from rest to rest): its settled part (from its start + five design
    time constants to its end) and its first five time constants (the transient); mm, %, s."""
    segment: int
    start: float
    end: float
    max_path_error_mm: Optional[float]
    max_path_error_along_surface_mm: Optional[float]
    max_force_error_percent: Optional[float]
    transient_max_path_error_along_surface_mm: Optional[float]
    transient_max_force_error_percent: Optional[float]


@dataclass
class PathReport:
    """A job's figures (the module docstring; summary.json's ``path``, docs/reference/outputs.md): distances in
    mm, times in s, None where no sample falls in the window."""
    length_m: float
    duration_s: float
    segments_run: int
    completed: bool
    arc_length_reached_m: float
    first_contact_time: Optional[float]
    path_start_time: Optional[float]
    path_end_time: Optional[float]
    lift_off_time: Optional[float]
    settle_time_per_segment_s: float
    # Over every segment's settled part (its start + 5 design time constants to its end):
    max_path_error_mm: Optional[float]
    max_path_error_along_surface_mm: Optional[float]
    max_path_error_along_normal_mm: Optional[float]
    max_force_error_N: Optional[float]
    max_force_error_percent: Optional[float]
    # Over the first 5 design time constants of the segments after the first (the line changes), and of
    # the first (the approach's landing is still settling there):
    line_change_max_path_error_along_surface_mm: Optional[float]
    line_change_max_force_error_percent: Optional[float]
    first_segment_max_path_error_along_surface_mm: Optional[float]
    first_segment_max_force_error_percent: Optional[float]
    time_off_surface_s: float
    contact_losses: int
    segments: List[SegmentReport]

    def as_dict(self) -> Dict[str, Any]:
        """The report as summary.json writes it (its fields in order, each segment a dict)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any]) -> "PathReport":
        """A report from summary.json's ``path``."""
        return cls(**dict(entry, segments=[SegmentReport(**segment) for segment in entry["segments"]]))


def _first(mask, t):
    index = np.nonzero(mask)[0]
    return float(t[index[0]]) if index.size else None


def _max_or_none(values):
    values = np.asarray(values, dtype=float)
    return float(np.max(values)) if values.size else None


def _largest(segments, key):
    """The largest ``key`` over ``segments`` that have it (None if none has)."""
    return _max_or_none([getattr(s, key) for s in segments if getattr(s, key) is not None])


def lift_off_time(log: Mapping[str, Array]) -> Optional[float]:
    """When the lift-off began (the supervisor's ``lifting``), or None."""
    if "lifting" not in log:
        return None
    return _first(np.asarray(log["lifting"])[:, 0] > 0.5, np.asarray(log["t"]))


def before_lift_off(log: Mapping[str, Array]) -> Mapping[str, Array]:
    """``log`` cut at the lift-off (every array's samples before it); the log itself without one."""
    lift = lift_off_time(log)
    if lift is None:
        return log
    end = int(np.searchsorted(np.asarray(log["t"]), lift))
    samples = len(log["t"])
    return {key: (value[:end] if hasattr(value, "__len__") and len(value) == samples else value)
            for key, value in log.items()}


def error_parts(log: Mapping[str, Array]) -> Tuple[Array, Array, Array]:
    """(total, along the surface, along the normal) distances of the pad centre from its reference (m)."""
    error = np.asarray(log["path_error"], dtype=float)
    normal = np.asarray(log["reference_normal"], dtype=float)
    along_normal = np.sum(error * normal, axis=1)
    tangential = error - along_normal[:, None] * normal
    return np.linalg.norm(error, axis=1), np.linalg.norm(tangential, axis=1), np.abs(along_normal)


def normal_force(log: Mapping[str, Array]) -> Array:
    """The normal force the sensor measured (N, per sample): the force of its wrench on the robot (the
    sensor's own, ``true_wrench``, where faults, a filter or a conditioner follow it; else ``wrench``) along
    the surface's outward unit normal at the path's reference point (``reference_normal``). The pad is
    within the path error along the surface of that point (hundredths of a millimetre once settled), so the
    normal there is the true normal at the pad to an angle of that error times the surface's curvature."""
    wrench = np.asarray(log["true_wrench"] if "true_wrench" in log else log["wrench"], dtype=float)
    return np.sum(wrench[:, 3:] * np.asarray(log["reference_normal"], dtype=float), axis=1)


def path_report(log: Mapping[str, Array], design_time_constant: float, path_duration: float, path_length: float,
                force_row: int = 0) -> PathReport:
    """The job's figures (module docstring), a ``PathReport`` (distances in mm, times in s); ``force_row``: the
    row of the logged ``desired_force`` that commands the normal force."""
    t = np.asarray(log["t"], dtype=float)
    segment, arc, t_path = (np.asarray(log["path_progress"], dtype=float)[:, i] for i in range(3))
    total, tangential, normal = (1000.0 * e for e in error_parts(log))
    force = normal_force(log)
    desired = np.asarray(log["desired_force"], dtype=float)[:, force_row]
    force_error = np.abs(force - desired)
    phase = np.asarray(log["contact_phase"], dtype=float)[:, 0] if "contact_phase" in log else np.full(
        t.shape, float(ContactPhase.CONTACT))
    lift = lift_off_time(log)
    on_path = (t_path >= 0) & (t_path <= path_duration) & (t < (lift if lift is not None else math.inf))
    tau5 = 5.0 * float(design_time_constant)
    segments = []
    settled_all = np.zeros(t.shape, dtype=bool)
    for index in np.unique(segment[on_path & (segment >= 0)]).astype(int):
        samples = on_path & (segment == index)
        start, end = float(t[samples][0]), float(t[samples][-1])
        settled = samples & (t >= start + tau5)
        transient = samples & (t < start + tau5)
        settled_all |= settled
        percent = 100.0 * force_error / np.maximum(np.abs(desired), 1e-12)
        segments.append(SegmentReport(
            segment=int(index), start=start, end=end,
            max_path_error_mm=_max_or_none(total[settled]),
            max_path_error_along_surface_mm=_max_or_none(tangential[settled]),
            max_force_error_percent=_max_or_none(percent[settled]),
            transient_max_path_error_along_surface_mm=_max_or_none(tangential[transient]),
            transient_max_force_error_percent=_max_or_none(percent[transient]),
        ))
    percent = 100.0 * force_error / np.maximum(np.abs(desired), 1e-12)
    contact = _first(phase == float(ContactPhase.CONTACT), t)
    # Off the surface: out of CONTACT between the first contact and the lift-off (or the end).
    window = (t >= contact) & (t < (lift if lift is not None else math.inf)) if contact is not None else np.zeros(
        t.shape, dtype=bool)
    dt = np.diff(t, append=t[-1])
    off = window & (phase != float(ContactPhase.CONTACT))
    losses = int(np.sum(np.diff((phase[window] == float(ContactPhase.CONTACT)).astype(int)) < 0))
    reached = float(np.max(arc[t_path >= 0])) if np.any(t_path >= 0) else 0.0
    return PathReport(
        length_m=float(path_length), duration_s=float(path_duration), segments_run=len(segments),
        completed=bool(reached >= path_length - 1e-6), arc_length_reached_m=reached,
        first_contact_time=contact, path_start_time=_first(t_path >= 0, t),
        path_end_time=_first(t_path > path_duration, t), lift_off_time=lift,
        settle_time_per_segment_s=tau5,
        max_path_error_mm=_max_or_none(total[settled_all]),
        max_path_error_along_surface_mm=_max_or_none(tangential[settled_all]),
        max_path_error_along_normal_mm=_max_or_none(normal[settled_all]),
        max_force_error_N=_max_or_none(force_error[settled_all]),
        max_force_error_percent=_max_or_none(percent[settled_all]),
        line_change_max_path_error_along_surface_mm=_largest(segments[1:],
                                                             "transient_max_path_error_along_surface_mm"),
        line_change_max_force_error_percent=_largest(segments[1:], "transient_max_force_error_percent"),
        first_segment_max_path_error_along_surface_mm=_largest(segments[:1],
                                                               "transient_max_path_error_along_surface_mm"),
        first_segment_max_force_error_percent=_largest(segments[:1], "transient_max_force_error_percent"),
        time_off_surface_s=float(np.sum(dt[off])), contact_losses=losses,
        segments=segments,
    )


def path_text(report: PathReport) -> List[str]:
    """The printout's lines for a job's ``report`` (a ``PathReport``)."""
    def mm(value):
        return "n/a" if value is None else f"{value:.3f} mm"

    def pct(value):
        return "n/a" if value is None else f"{value:.2f} %"

    run = ("completed" if report.completed else
           f"NOT completed: reached {report.arc_length_reached_m:.3f} m")
    lines = [f"path: {report.length_m:.3f} m in {report.segments_run} segments, {run}"
             f"; first contact at t = {report.first_contact_time}, lift-off at t = {report.lift_off_time}",
             f"  settled (each segment from its start + {report.settle_time_per_segment_s:.2f} s): path error "
             f"{mm(report.max_path_error_mm)} (along the surface {mm(report.max_path_error_along_surface_mm)}, "
             f"along the normal {mm(report.max_path_error_along_normal_mm)}: the pad's compression), normal force "
             f"error {pct(report.max_force_error_percent)}",
             f"  at the line changes (each later segment's first {report.settle_time_per_segment_s:.2f} s): path "
             f"error along the surface {mm(report.line_change_max_path_error_along_surface_mm)}, force error "
             f"{pct(report.line_change_max_force_error_percent)}; after the approach (the first segment's): "
             f"{mm(report.first_segment_max_path_error_along_surface_mm)}, "
             f"{pct(report.first_segment_max_force_error_percent)}",
             f"  off the surface between the first contact and the lift-off: {report.time_off_surface_s:.3f} s "
             f"({report.contact_losses} contact losses)"]
    return lines
