"""A flat tool's contact patch over a run: how centred, how flat and how even the pressure was
(``summary.json``'s ``patch``, the printout).

From the log's ``patch`` (``systems.contact_patch.PATCH_FIELDS``, held between the sensor's updates) and the
controller's force rows: the figures at the end (before a job's lift-off) and their worst over the settled
part of the run, from the first contact + five design time constants on (for a job, to the path's end; its
worst over the path's run, from the path's start, too: the tool moving over the workpiece). The tilt is
against the real surface's normal under the tool (``systems.contact_patch``); the normal force is the
patch's pressure resultant, against the command on the force row. ``patch_report`` returns a
``PatchReport`` (None without a ``patch`` log), ``patch_text`` prints it. Pure numpy on the logged arrays.
"""

import math
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Optional

import numpy as np

from drake_hybrid.core.hints import Array
from drake_hybrid.experiments.path_report import lift_off_time
from drake_hybrid.systems.contact_patch import PATCH_FIELDS

_COLUMN = {name: index for index, name in enumerate(PATCH_FIELDS)}


@dataclass
class PatchReport:
    """The patch's figures (the module docstring; summary.json's ``patch``): mm, deg, kPa, N, %; None where no
    sample falls in the window (or none touched)."""
    settled_from: Optional[float]                    # s: first contact + five design time constants
    final_cop_offset_mm: Optional[float]             # the centre of pressure from the tool's axis, at the end
    max_cop_offset_mm_settled: Optional[float]
    final_tilt_deg: Optional[float]                  # the tool's axis against the real surface's normal
    max_tilt_deg_settled: Optional[float]
    final_area_fraction: Optional[float]             # the patch's area over the tool's face (1)
    min_area_fraction_settled: Optional[float]
    final_peak_pressure_kpa: Optional[float]
    final_mean_pressure_kpa: Optional[float]
    final_normal_force: Optional[float]              # N, the pressure's resultant
    max_normal_force_error_percent_settled: Optional[float]   # against the force row's command
    path_max_cop_offset_mm: Optional[float] = None   # a job's: over the path's run (from its start to its end)
    path_max_tilt_deg: Optional[float] = None
    path_min_area_fraction: Optional[float] = None
    path_max_normal_force_error_percent: Optional[float] = None

    def as_dict(self) -> Dict[str, Any]:
        return dict(self.__dict__)

    @classmethod
    def from_dict(cls, entries: Mapping[str, Any]) -> "PatchReport":
        return cls(**entries)


def _worst(values: Array, mask: Array, largest: bool = True, scale: float = 1.0) -> Optional[float]:
    chosen = values[mask]
    chosen = chosen[np.isfinite(chosen)]
    if not chosen.size:
        return None
    return float((np.max(chosen) if largest else np.min(chosen)) * scale)


def _last(values: Array, mask: Array, scale: float = 1.0) -> Optional[float]:
    indices = np.nonzero(mask & np.isfinite(values))[0]
    return float(values[indices[-1]] * scale) if indices.size else None


def patch_report(log: Mapping[str, Array], design_time_constant: float, contact_time: float,
                 force_row: int = 0) -> Optional[PatchReport]:
    """The ``PatchReport`` of a run's ``log`` (its ``patch``, ``force``, ``desired_force`` and ``t``; a job's
    ``path_progress`` and ``lifting``: a held path's ``path_done`` is 1 from the start, so the end is the
    lift-off's start, not the path's end), settled from ``contact_time`` + 5 ``design_time_constant``;
    ``force_row`` the row of the normal force. None without a ``patch`` log."""
    if "patch" not in log:
        return None
    t, patch = np.asarray(log["t"]), np.asarray(log["patch"])
    touching = patch[:, _COLUMN["normal_force"]] > 0
    lift = lift_off_time(log)
    before_lift = np.ones(len(t), dtype=bool) if lift is None else t < lift
    settled_from = contact_time + 5 * design_time_constant if math.isfinite(contact_time) else math.inf
    settled = (t >= settled_from) & before_lift
    command = np.asarray(log["desired_force"])[:, force_row]
    force = patch[:, _COLUMN["normal_force"]]
    with np.errstate(divide="ignore", invalid="ignore"):
        force_error = np.where(np.abs(command) > 0, 100 * np.abs(force - np.abs(command)) / np.abs(command), np.nan)
    column = lambda name: patch[:, _COLUMN[name]]
    end = before_lift & touching
    report = PatchReport(
        settled_from=float(settled_from) if math.isfinite(settled_from) else None,
        final_cop_offset_mm=_last(column("cop_offset"), end, 1e3),
        max_cop_offset_mm_settled=_worst(column("cop_offset"), settled, scale=1e3),
        final_tilt_deg=_last(column("tilt"), end, 180 / math.pi),
        max_tilt_deg_settled=_worst(column("tilt"), settled, scale=180 / math.pi),
        final_area_fraction=_last(column("area_fraction"), end),
        min_area_fraction_settled=_worst(column("area_fraction"), settled, largest=False),
        final_peak_pressure_kpa=_last(column("peak_pressure"), end, 1e-3),
        final_mean_pressure_kpa=_last(column("mean_pressure"), end, 1e-3),
        final_normal_force=_last(force, end),
        max_normal_force_error_percent_settled=_worst(force_error, settled))
    if "path_progress" in log:
        on_path = (np.asarray(log["path_progress"])[:, 2] >= 0) & before_lift
        report.path_max_cop_offset_mm = _worst(column("cop_offset"), on_path, scale=1e3)
        report.path_max_tilt_deg = _worst(column("tilt"), on_path, scale=180 / math.pi)
        report.path_min_area_fraction = _worst(column("area_fraction"), on_path, largest=False)
        report.path_max_normal_force_error_percent = _worst(force_error, on_path)
    return report


def patch_text(report: PatchReport) -> List[str]:
    """The printout's lines for a run's contact ``report`` (a ``PatchReport``)."""
    def number(value, unit, digits=3):
        return "n/a" if value is None else f"{value:.{digits}f}{unit}"

    def percent(value):
        return "n/a" if value is None else f"{100 * value:.1f} %"

    lines = [f"contact patch at the end: centre of pressure {number(report.final_cop_offset_mm, ' mm')} from the "
             f"tool's axis, tilt {number(report.final_tilt_deg, ' deg')} against the real surface, "
             f"{percent(report.final_area_fraction)} of the face in contact, pressure peak "
             f"{number(report.final_peak_pressure_kpa, ' kPa', 1)} / mean "
             f"{number(report.final_mean_pressure_kpa, ' kPa', 1)}, normal force "
             f"{number(report.final_normal_force, ' N')}",
             f"  settled (from t = {number(report.settled_from, ' s', 2)}): centre of pressure within "
             f"{number(report.max_cop_offset_mm_settled, ' mm')}, tilt within "
             f"{number(report.max_tilt_deg_settled, ' deg')}, "
             f"at least {percent(report.min_area_fraction_settled)} of the face, normal force within "
             f"{number(report.max_normal_force_error_percent_settled, ' %', 2)}"]
    if report.path_max_cop_offset_mm is not None or report.path_min_area_fraction is not None:
        lines.append(f"  along the path: centre of pressure within {number(report.path_max_cop_offset_mm, ' mm')}, "
                     f"tilt within {number(report.path_max_tilt_deg, ' deg')}, at least "
                     f"{percent(report.path_min_area_fraction)} of the face, normal force within "
                     f"{number(report.path_max_normal_force_error_percent, ' %', 2)}")
    return lines
