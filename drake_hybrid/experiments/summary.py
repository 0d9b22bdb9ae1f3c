"""A run's summary as a typed record: ``RunSummary``, what ``simulation.summarize`` computes from a run's log
and ``SimulationResult.summary`` holds; ``summary.json`` is its ``to_json()``.

Read its figures as attributes (``result.summary.max_force_error_percent_after_5_time_constants``, each
row's ``result.summary.force_rows[0].final_error``); ``as_dict()`` is the same figures as the plain dict
summary.json holds (the same keys, in the same order; the rows, the impedance's check, the path's report
and the contact patch's as dicts), for code that picks figures by name (``summary.as_dict()[key]``) or hands them to a
function that takes the file's dict; ``RunSummary.from_dict`` reads such a dict, or a ``summary.json``
loaded with ``json.load``, back. docs/reference/outputs.md says what each field means.

A run that stops early (``simulation.RunStopped``) has ``status`` "fault", "error" or "interrupted",
``stop_time`` and ``stop_reason``; a figure it could not compute (a run stopped before it logged two
samples, a force figure after a sensor fault) is None, and null in summary.json.
"""

import dataclasses
import json
import math
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Optional

from drake_hybrid.experiments.metrics import ForceRowFigures, ImpedanceCheck, RowFigures
from drake_hybrid.experiments.patch_report import PatchReport
from drake_hybrid.experiments.path_report import PathReport


def json_safe(value: Any) -> Any:
    """``value`` with every non-finite float (NaN, inf: "never", "undefined") replaced by None, so
    that the file is valid JSON."""
    if isinstance(value, dict):
        return {key: json_safe(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(item) for item in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


@dataclass
class RunSummary:
    """A run's figures (summary.json; docs/reference/outputs.md): k velocity rows, m force rows, each row in
    its own units; % figures of the row's scale; times in s. Every field but the run's name, mode and
    duration is None where the run stopped before it could be computed."""
    task: str
    mode: str                                          # the control mode's value ("velocity-force", ...)
    duration: float                                    # the simulated time asked for (s)
    time_step: Optional[float] = None                  # the plant's step (s; 0: continuous)
    control_period: Optional[float] = None             # the controller's period (s; 0: continuous)
    velocity_dim: Optional[int] = None                 # k
    force_dim: Optional[int] = None                    # m
    gains: Optional[Dict[str, list]] = None            # the validated matrices as nested lists, by name
    predicted_eigenvalues: Optional[List[List[float]]] = None      # the designed ones, [real, imaginary] pairs
    design_time_constant: Optional[float] = None       # 1 / min |Re(lambda)| of the design (s)
    final_velocity_error: Optional[List[float]] = None
    final_force_error: Optional[List[float]] = None    # at the last sample with a valid wrench
    invalid_wrench_samples: Optional[int] = None       # samples whose measured wrench was not finite
    contact_time: Optional[float] = None               # when the law took over (s)
    # The worst row's figures, each row in % of its scale; settling counted from contact:
    final_velocity_error_percent: Optional[float] = None
    final_force_error_percent: Optional[float] = None
    max_velocity_error_percent_after_5_time_constants: Optional[float] = None
    max_force_error_percent_after_5_time_constants: Optional[float] = None
    velocity_settling_time_1_percent: Optional[float] = None       # inf: never within 1 %
    force_settling_time_1_percent: Optional[float] = None
    velocity_rows: Optional[List[RowFigures]] = None
    force_rows: Optional[List[ForceRowFigures]] = None     # also held, measured force
    impedance: Optional[ImpedanceCheck] = None         # impedance-force mode only
    max_constraint_residual: Optional[float] = None    # max |C(r)| over the run
    max_constraint_residual_after_contact: Optional[float] = None  # from contact on (to a job's lift-off)
    max_constraint_residual_rows_after_contact: Optional[List[Optional[float]]] = None
    constraint_units: Optional[List[str]] = None       # per row of C (None where the task names none)
    held: Optional[List[str]] = None                   # the force rows the controller holds itself
    max_torque_to_effort_limit: Optional[List[float]] = None       # per actuator
    wall_time: Optional[float] = None                  # s
    real_time_factor: Optional[float] = None
    command_scales: Optional[Dict[str, float]] = None  # "speed", "force": the largest command norms
    notes: Optional[List[str]] = None                  # the task's remarks on the run
    events: Optional[List[dict]] = None                # the run's phases (Task.run_events)
    start_in_contact: Optional[bool] = None
    start_force_command_step: Optional[List[float]] = None         # K_fi xi(0), per force row
    path: Optional[PathReport] = None                  # a path job's figures
    patch: Optional[PatchReport] = None                # a disc's contact patch (experiments.patch_report)
    status: Optional[str] = None                       # simulate's: "completed", "fault", "error", "interrupted"
    stop_time: Optional[float] = None                  # s
    stop_reason: Optional[str] = None

    def as_dict(self) -> Dict[str, Any]:
        """The summary as the plain dict summary.json holds: every field by name, in order, the rows, the
        impedance's check and the path's report as dicts (non-finite numbers kept: ``to_json`` writes them
        as null)."""
        return dataclasses.asdict(self)

    def to_json(self) -> str:
        """summary.json's text: ``as_dict()`` with every NaN and inf as null (valid JSON), indented."""
        return json.dumps(json_safe(self.as_dict()), indent=2, allow_nan=False)

    @classmethod
    def from_dict(cls, entries: Mapping[str, Any]) -> "RunSummary":
        """A summary from ``as_dict()``'s dict or a loaded summary.json (its rows, impedance check and path
        report typed again; a key that is no field is refused, as a TypeError)."""
        entries = dict(entries)
        for group in ("velocity_rows", "force_rows"):
            if entries.get(group) is not None:
                entries[group] = [RowFigures.from_dict(row) for row in entries[group]]
        if entries.get("impedance") is not None:
            entries["impedance"] = ImpedanceCheck(**entries["impedance"])
        if entries.get("path") is not None:
            entries["path"] = PathReport.from_dict(entries["path"])
        if entries.get("patch") is not None:
            entries["patch"] = PatchReport.from_dict(entries["patch"])
        return cls(**entries)
