"""A simulation's summary in words: the lines ``drake-hybrid simulate`` prints for a run (``run_lines``), and
the pieces they are made of, each callable on its own (a row's errors, the impedance's check, the
constraint's residual, the designed eigenvalues by row); and the line a sweep ends with (``sweep_lines``).

Each row is given in its own units and in % of its scale (``experiments.metrics.row_scales``), its worst
settled error with the time and the phase of the run it falls in (the task's ``run_events``), and the
numbers of the run's notes that name it. The figures are the summary's (``experiments.summary.RunSummary``);
nothing here computes one.
"""

import re
from typing import Any, Iterable, List, Mapping, Optional, Sequence

import numpy as np

from drake_hybrid.analysis.design import designed_eigenvalues_by_row
from drake_hybrid.control.controller import HybridController
from drake_hybrid.experiments.metrics import ForceRowFigures, ImpedanceCheck, RowFigures, display_unit
from drake_hybrid.experiments.patch_report import patch_text
from drake_hybrid.experiments.path_report import path_text
from drake_hybrid.experiments.simulation import SimulationResult
from drake_hybrid.experiments.summary import RunSummary
from drake_hybrid.experiments.sweep import SweepRun
from drake_hybrid.report.eigenvalues import format_eigenvalues

# What a row's % figures are of, in words, where it is not its own command (``metrics.row_scales``' sources).
SCALE_WORDS = {"rows in its units": "the largest command in its units",
               "run": "the run's command scale (speed or force)"}
IMPEDANCE_REALIZED = 2.0      # % of the command: a run this close to its driven impedance realizes it


def eigenvalues_by_row(controller: HybridController, summary: RunSummary) -> str:
    """" by row, velocity: 'x-dot' -10, 'theta-dot' -8; force: 'F' -10": each designed eigenvalue with its
    row (``summary``'s rows' names), or by loop when a gain couples the rows (``controller``: the run's
    ``HybridController``, its validated gains and mode)."""
    by_row = designed_eigenvalues_by_row(controller.validated_gains(), controller.mode, controller.kinematic_rows,
                                         controller.num_joints - controller.task_size)
    if by_row is None:
        assert summary.predicted_eigenvalues is not None       # a completed run's summary (run_lines')
        designed = np.array([complex(*e) for e in summary.predicted_eigenvalues])
        return f" (by loop: a gain couples the rows): {format_eigenvalues(designed)}"
    velocity, force, null_space = by_row
    assert summary.velocity_rows is not None and summary.force_rows is not None     # a completed run's
    text = (" by row, velocity: " + ", ".join(f"'{row.name}' {format_eigenvalues(values)}"
                                               for row, values in zip(summary.velocity_rows, velocity))
            + "; force: " + ", ".join(f"'{row.name}' {format_eigenvalues(values)}"
                                      + (" (held: -w_c, -2 w_c)" if row.held else "")
                                      for row, values in zip(summary.force_rows, force)))
    if null_space:
        text += f"; self-motion: {format_eigenvalues(np.array(null_space))} (-K_n per extra joint)"
    return text


def event_text(time: float, events: Optional[Iterable[Mapping[str, Any]]]) -> str:
    """Where ``time`` (s) falls among the run's phases (the summary's ``events``): inside a span, or within
    0.3 s after its edge or an instant; empty if nowhere near one (or only near phases that cause no error)."""
    for event in events or ():
        if not event.get("explains_errors", True):
            continue
        start, end = event["start"], event.get("end")
        if end is not None and start <= time <= end:
            return f", {time - start:.2f} s after the start of: {event['label']}"
        for edge, word in ((start, "the start"), (end, "the end")):
            if edge is not None and 0 <= time - edge <= 0.3:
                return f", {time - edge:.2f} s after {word if end is not None else 'the moment'} of: {event['label']}"
    return ""


def notes_on(name: str, notes: Optional[Iterable[str]]) -> List[int]:
    """The numbers (from 1) of the run's ``notes`` that name the row ``name`` (up to a comma or a parenthesis:
    "F" of "F, along E_f = [0 1 0]") as a word, e.g. "x-dot's error ...": the notes about that row."""
    short = re.split(r",| \(", name)[0].strip()
    pattern = re.compile(rf"(?<![\w/-]){re.escape(short)}(?![\w/-])")
    return [n + 1 for n, note in enumerate(notes or ()) if pattern.search(note)]


def row_text(row: RowFigures, events: Optional[Iterable[Mapping[str, Any]]] = (),
             notes: Optional[Iterable[str]] = ()) -> str:
    """One row's errors (a ``RowFigures``): absolute in its units, % of its scale (its command; for a row
    commanded to zero, the run's speed or force: ``metrics.row_scales``), settling from contact; when its
    settled max falls in or just after a phase of the run (``events``), that phase; the numbers of the
    run's ``notes`` that name the row (the ones that say why), if any. A held force row: its measured force."""
    units = row.units
    about = notes_on(row.name, notes)
    pointer = "" if not about else f"; see note{'s' if len(about) > 1 else ''} {', '.join(map(str, about))}"

    def amount(value, percent):
        if value is None:
            return "-"
        return f"{value:.3g} {units}" + (f" ({percent:.2f} %)" if percent is not None else "")

    if isinstance(row, ForceRowFigures) and row.held:
        measured = row.max_measured_force_after_contact
        return "held by the controller (no force commanded)" + (
            "" if measured is None else f"; measured force up to {measured:.3g} {units} after contact")
    command = f"command {row.command:.3g} {units}" if row.command > 0 else "command 0"
    final = None if row.final_error is None else abs(row.final_error)
    settled = amount(row.max_error_after_5_time_constants, row.max_error_percent_after_5_time_constants)
    when = row.max_error_time_after_5_time_constants
    if when is not None and row.max_error_after_5_time_constants:
        settled += f" at t = {when:.3f} s" + event_text(when, events)
    text = f"{command}; final error {amount(final, row.final_error_percent)}, settled max {settled}"
    settle = row.settling_time_1_percent
    if settle is not None:
        text += (f", within 1 % from {settle:.3f} s after contact on" if np.isfinite(settle)
                 else ", not within 1 % at the end")
    if row.scale_of in SCALE_WORDS:
        text += f" (% of {row.scale:.3g}, {SCALE_WORDS[row.scale_of]})"
    return text + pointer


def impedance_text(check: ImpedanceCheck) -> str:
    """The impedance's check (an ``ImpedanceCheck``) in one line: the run against the designed impedance
    driven by its measured F_v, and whether the run realizes it (within ``IMPEDANCE_REALIZED`` %)."""
    forces = ", ".join(f"{force:.3g}" for force in check.max_tangential_force)
    percent = check.max_difference_percent
    agreement = (f"within {percent:.2g} % of the command" if percent is not None else
                 "within " + ", ".join(f"{d:.3g}" for d in check.max_difference) + " (rows' units)")
    verdict = ("the rows' errors above are the designed impedance's answer to its start and to F_v"
               if percent is not None and percent <= IMPEDANCE_REALIZED else
               "the run does not realize the designed impedance that closely (contact transients, saturation, a "
               "model error?)")
    return (f"impedance (3.2-11) driven by the measured F_v (settled max |F_v| per row: {forces}): the velocity "
            f"errors it predicts are {agreement} of the measured ones (settled): {verdict}")


def residual_text(summary: RunSummary) -> str:
    """max |C(r)| after contact in C's units: one figure if every row has the same unit, else one per row."""
    residual = summary.max_constraint_residual_after_contact
    if residual is None:
        return "no contact made"
    units, rows = summary.constraint_units, summary.max_constraint_residual_rows_after_contact
    if not units or not rows:
        return f"max |C(r)| after contact {residual:.3g} (in the units of C's rows)"
    if len(set(units)) == 1:
        return f"max |C(r)| after contact {residual:.3g} {display_unit(units[0])}"
    figures = ", ".join(f"{value:.3g} {display_unit(unit)}" for value, unit in zip(rows, units))
    return f"max |C_i(r)| after contact, per row of C: {figures}"


def run_lines(result: SimulationResult) -> List[str]:
    """The lines ``drake-hybrid simulate`` prints for a completed run (a ``SimulationResult``): what ran, the
    designed eigenvalues by row, each row's errors, the invalid wrench samples, the impedance's check, the
    constraint's residual, a job's path and the run's notes, numbered."""
    s = result.summary
    # A completed run (simulate's result, not stopped): its scenario and every figure read here are there.
    assert result.scenario is not None and s.contact_time is not None and s.design_time_constant is not None
    assert s.velocity_rows is not None and s.force_rows is not None
    lines = [f"{s.task} ({s.mode}), {s.duration:.2f} s simulated in {s.wall_time:.1f} s "
             f"(real-time factor {s.real_time_factor:.2f})",
             f"  designed eigenvalues{eigenvalues_by_row(result.scenario.controller, s)}"
             f" (slowest time constant {s.design_time_constant:.3f} s)"]
    start = s.contact_time
    since = "from t = 0" if start == 0 else f"from contact at t = {start:.3f} s"
    lines.append(f"  errors per row, in its own units and in % of its command ({since}; 'settled': after contact "
                 f"+ 5 design time constants, t >= {start + 5 * s.design_time_constant:.3f} s):")
    for what, rows in (("velocity", s.velocity_rows), ("force", s.force_rows)):
        lines += [f"    {what} {row.name}: {row_text(row, s.events, s.notes)}" for row in rows]
    if s.invalid_wrench_samples:
        lines.append(f"  {s.invalid_wrench_samples} logged sample(s) with an invalid measured wrench (a sensor "
                     "dropout): the force figures leave them out (their F, e_f and F_v read NaN in log.npz)")
    if s.impedance is not None:
        lines.append(f"  {impedance_text(s.impedance)}")
    lines.append(f"  {residual_text(s)}")
    lines += [f"  {line}" for line in (path_text(s.path) if s.path is not None else ())]
    lines += [f"  {line}" for line in (patch_text(s.patch) if s.patch is not None else ())]
    lines += [f"  note {n}: {note}" for n, note in enumerate(s.notes or [], start=1)]
    return lines


def _where(workers):
    """Where a sweep ran, in the command line's terms (``SweepRun.workers``: "serial", "local:N" or an address)."""
    if workers == "serial":
        return "serially in this process (--workers 0)"
    if workers.startswith("local:"):
        return f"on {workers.split(':', 1)[1]} local Dask worker processes (--workers)"
    return f"on the Dask scheduler at {workers} (--scheduler)"


def sweep_lines(task_name: str, run: SweepRun, rows: Sequence[Mapping[str, Any]]) -> List[str]:
    """The lines ``drake-hybrid sweep`` prints: how many points ran and where (``run``: a ``SweepRun``), how
    many of the table's ``rows`` (``read_results``) are stable and failed, and the table's path."""
    stable = sum(1 for row in rows if row.get("stable"))
    if run.evaluated:
        done = f"{run.evaluated} of {run.points} points evaluated in {run.wall_time:.1f} s {_where(run.workers)}"
    else:
        done = f"nothing to run: all {run.points} points already in the table"
    return [f"{task_name}: {done}; {len(rows)} in the table, {stable} stable, {run.failures} with errors",
            f"  wrote {run.results_path}"]
