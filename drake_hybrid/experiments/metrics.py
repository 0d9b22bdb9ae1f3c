"""Per-row error figures of a run: each row in its own units and in % of its command, settling from contact.

The one definition of a row's error that ``summary.json`` (``simulation.summarize``), the command line's
summary and the sweep's verdict (``sweep``) share; pure numpy on the logged arrays, no Drake. A row's
figures are a ``RowFigures`` (a force row's a ``ForceRowFigures``, which adds whether the controller holds
the row itself), the impedance's check an ``ImpedanceCheck``: typed records whose ``as_dict()`` is their
entry of ``summary.json``.

Arguments are checked at the call (``core.arguments``): times a nonempty vector of finite, nondecreasing
numbers; a group of rows an array of samples x rows (a vector is one row) with one sample per time and,
where several arrays describe the same rows (errors, commands, units, names), one column per row in each,
so that no row may drop out. NaN is allowed in the logged errors (a sample taken while the measured
wrench was invalid) and nowhere else. A mismatch is a one-line ArgumentError naming the argument.
"""

import dataclasses
import math
import numbers
from dataclasses import dataclass
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike

from drake_hybrid.analysis.environment import impedance_response
from drake_hybrid.control.gains import ValidatedGains
from drake_hybrid.control.phases import ContactPhase
from drake_hybrid.core.arguments import describe, number, numeric_array, text
from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.core.hints import Array


@dataclass
class RowFigures:
    """One row's error figures (``row_errors``; an entry of summary.json's ``velocity_rows``), in the row's
    own units and in % of its scale; None where a figure cannot be computed (no sample that late, a held
    row, a sensor fault)."""
    name: str
    units: str
    command: float                                     # max |desired_i| over the run (0: commanded to zero)
    scale: Optional[float]                             # what the % figures are of (``row_scales``)
    scale_of: Optional[str]                            # "command", "rows in its units", "run" or "unit"
    final_error: Optional[float]                       # e_i at the last valid sample (signed)
    final_error_percent: Optional[float]
    max_error_after_5_time_constants: Optional[float]
    max_error_percent_after_5_time_constants: Optional[float]
    max_error_time_after_5_time_constants: Optional[float]     # s
    settling_time_1_percent: Optional[float]           # s from contact; inf: never within 1 %

    def as_dict(self) -> Dict[str, Any]:
        """The row as summary.json writes it (its fields, in order)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, entry: Mapping[str, Any]) -> "RowFigures":
        """A row from its summary.json entry: a ``ForceRowFigures`` where the entry says ``held``."""
        kind = ForceRowFigures if "held" in entry else RowFigures
        return kind(**entry)


@dataclass
class ForceRowFigures(RowFigures):
    """A force row's figures (summary.json's ``force_rows``): ``RowFigures`` and whether the controller
    holds the row itself (``held``: no force commanded, so its error figures are None) and the largest
    measured force along it after contact."""
    held: bool = False
    max_measured_force_after_contact: Optional[float] = None


@dataclass
class ImpedanceCheck:
    """How closely an impedance-force run realizes the designed impedance (``impedance_check``;
    summary.json's ``impedance``)."""
    max_difference: List[Optional[float]]              # per row, in its units
    max_difference_percent: Optional[float]            # the largest in % of its row's command
    max_tangential_force: List[float]                  # per row, max |F_v| over the settled window

    def as_dict(self) -> Dict[str, Any]:
        """The check as summary.json writes it."""
        return dataclasses.asdict(self)


def _times(times: Any, name: str, owner: str) -> Array:
    """A nonempty vector of finite, nondecreasing times (s)."""
    allowed = "a nonempty vector of finite nondecreasing times (s)"
    array = numeric_array(times, name, owner, what=allowed)
    if array.ndim != 1 or array.size == 0 or np.any(np.diff(array) < 0):
        raise ArgumentError(f"{owner}: {name} must be {allowed}, got {describe(times)}")
    return array


def _rows(values: Any, name: str, owner: str, samples: Optional[int] = None, columns: Optional[int] = None,
          nan: bool = False) -> Array:
    """``values`` as a float array of samples x rows (a vector: one row), NaN allowed if ``nan``; with
    ``samples``, one sample per time; with ``columns``, that many rows."""
    allowed = "an array of samples x rows of numbers" + ("" if nan else " (no NaN)")
    if values is None or isinstance(values, (str, bytes, dict, bool, np.bool_)) or not isinstance(
            values, (numbers.Real, list, tuple, np.ndarray)):
        raise ArgumentError(f"{owner}: {name} must be {allowed}, got {describe(values)}")
    try:
        array = np.array(values, dtype=float)
    except (TypeError, ValueError):
        raise ArgumentError(f"{owner}: {name} must be {allowed}, got {describe(values)}") from None
    if array.ndim == 1:
        array = array[:, None]
    if array.ndim != 2 or array.shape[0] == 0 or (not nan and np.isnan(array).any()):
        raise ArgumentError(f"{owner}: {name} must be {allowed} (at least one sample), got {describe(values)}")
    if samples is not None and array.shape[0] != samples:
        raise ArgumentError(f"{owner}: {name} must have one sample per time ({samples}), got {array.shape[0]}")
    if columns is not None and array.shape[1] != columns:
        raise ArgumentError(f"{owner}: {name} must have one column per row ({columns}, as the errors), got "
                            f"{array.shape[1]}: no row may drop out")
    return array


def _per_row(items: Any, name: str, owner: str, count: int) -> List[Any]:
    """``items`` (units, names) as a list of one entry per row."""
    if isinstance(items, (str, bytes)) or not hasattr(items, "__len__") or len(items) != count:
        got = f"{len(items)}: {list(items)!r:.80}" if hasattr(items, "__len__") and not isinstance(
            items, (str, bytes)) else describe(items)
        raise ArgumentError(f"{owner}: {name} must give one entry per row ({count}), got {got}")
    return list(items)


def settling_time(times: ArrayLike, error_norm: ArrayLike, bound: float) -> float:
    """First time after which ``error_norm`` stays at or below ``bound`` (inf if never): ``times`` nonempty,
    nondecreasing; ``error_norm`` one finite value (or inf) per time; ``bound`` a finite number >= 0."""
    owner = "settling_time"
    times = _times(times, "times", owner)
    error_norm = numeric_array(error_norm, "error_norm", owner, what="a vector of numbers (no NaN)", finite=False)
    if error_norm.shape != times.shape:
        raise ArgumentError(f"{owner}: error_norm must have one value per entry of times ({times.size}), got "
                            f"{describe(error_norm)}")
    bound = number(bound, "bound", owner, low=0.0)
    outside = np.nonzero(error_norm > bound)[0]
    if outside.size == 0:
        return float(times[0])
    if outside[-1] == len(times) - 1:
        return math.inf
    return float(times[outside[-1] + 1])


def contact_time(log: Mapping[str, Array], start_in_contact: bool = True) -> float:
    """When the hybrid law took over: the first sample in the CONTACT phase when a contact supervisor
    ran (``contact_phase`` logged), else the first sample (a start in contact)."""
    if not hasattr(log, "__contains__") or "t" not in log:
        raise ArgumentError(f"contact_time: log must be a run's log (a mapping with 't'), got {describe(log)}")
    t = _times(log["t"], "log['t']", "contact_time")
    if "contact_phase" in log:
        in_contact = np.nonzero(np.asarray(log["contact_phase"])[:, 0] == int(ContactPhase.CONTACT))[0]
        return float(t[in_contact[0]]) if in_contact.size else math.inf
    return float(t[0])


def row_units(units: str, count: int) -> List[str]:
    """Per-row units from a task's label string ("m/s | rad/s"; one unit for every row if single)."""
    parts = [part.strip() for part in str(units).split("|")]
    if len(parts) == count:
        return parts
    return [parts[-1] if i >= len(parts) else parts[i] for i in range(count)] if len(parts) > 1 else parts * count


def display_unit(unit: str) -> str:
    """A row's unit as the summary and the plots print it: "(no unit)" for a dimensionless row ("1")."""
    return "(no unit)" if str(unit).strip() == "1" else unit


def row_commands(desired: ArrayLike) -> Array:
    """Each row's command: max |desired_i| over the run (in the row's units; 0 for a row commanded to zero);
    ``desired`` samples x rows (a vector: one row)."""
    return np.max(np.abs(_rows(desired, "desired", "row_commands")), axis=0)


def run_scale(desired: ArrayLike) -> float:
    """The run's command scale: max over the samples of |desired| (the norm across the rows; the
    summary's ``command_scales``: the speed, the force)."""
    desired = _rows(desired, "desired", "run_scale")
    return float(np.max(np.linalg.norm(desired, axis=1))) if desired.size else 0.0


# A row's command below this fraction of the run's scale is the path's numerical noise, not a command (measured:
# a job along the sphere's meridian commands its spin row 3.1e-5 rad/s beside 0.05 m/s, which made the row's
# settled error read 37.5 % of it; a raster's cross row about 1e-7 m/s, tens of thousands of %): its % figures
# are of what a row commanded to zero is judged by.
COMMAND_FLOOR = 1e-3


def row_scales(desired: ArrayLike, units: Optional[Sequence[str]] = None,
               fallback: str = "run") -> Tuple[Array, List[str]]:
    """What each row's % figures are of (no row may drop out of the worst-row figures): its command
    (``row_commands``; below ``COMMAND_FLOOR`` of the run's scale, zero); for a row commanded to zero, the
    largest command of the rows in its units
    (``units``, one string per row: the cross-track m/s row of a slide against the slide's speed), else
    the run's scale (``run_scale``: the norm of the whole command, the speed or the force the run
    commands, the plots' scale; ``fallback="unit"`` skips it, as the sweep's verdict does to keep its
    tolerance in each row's units), else one of its units. Returns (scales, sources), each source
    "command", "rows in its units", "run" or "unit" (no % figure is given against a unit)."""
    commands, scale = row_commands(desired), run_scale(desired)
    commands = np.where(commands >= COMMAND_FLOOR * scale, commands, 0.0)
    fallback = text(fallback, "fallback", "row_scales", allowed=("run", "unit"))
    unit_of_row: List[Optional[str]] = (_per_row(units, "units", "row_scales", len(commands)) if units is not None
                                         else [None] * len(commands))
    scales, sources = [], []
    for command, unit in zip(commands, unit_of_row):
        same = [c for c, u in zip(commands, unit_of_row) if unit is not None and u == unit and c > 0]
        run = scale if fallback == "run" else 0.0
        for value, source in ((command, "command"), (max(same, default=0.0), "rows in its units"), (run, "run"),
                              (1.0, "unit")):
            if value > 0:
                scales.append(float(value))
                sources.append(source)
                break
    return np.array(scales), sources


def last_valid(values: ArrayLike) -> Optional[Array]:
    """The last row of ``values`` (samples x columns) without NaN (None if every row has one): a sample
    taken while the measured wrench was invalid reads NaN (control.law_system) and is no figure."""
    values = _rows(values, "values", "last_valid", nan=True)
    valid = np.nonzero(~np.isnan(values).any(axis=1))[0]
    return values[valid[-1]] if valid.size else None


def invalid_samples(values: ArrayLike) -> int:
    """How many samples (rows of ``values``) read NaN: taken while the measured wrench was invalid."""
    return int(np.isnan(_rows(values, "values", "invalid_samples", nan=True)).any(axis=1).sum())


def max_row_errors(t: ArrayLike, error: ArrayLike, desired: ArrayLike, after: float,
                   units: Optional[Sequence[str]] = None,
                   fallback: str = "run") -> List[Tuple[Optional[float], Optional[float]]]:
    """Per row, over t >= ``after``: (max |e_i| in the row's units, or None if no sample is that late;
    that in % of the row's scale, ``row_scales(desired, units, fallback)``: its command, or for a row
    commanded to zero the largest command in its units or the run's speed or force; None against one
    of its units). The one definition of a row's error that ``row_errors`` (summary.json) and the
    sweep's verdict share. Samples that read NaN (the wrench invalid then) are left out."""
    owner = "max_row_errors"
    t = _times(t, "t", owner)
    error = _rows(error, "error", owner, samples=t.size, nan=True)
    desired = _rows(desired, "desired", owner, columns=error.shape[1])
    if units is not None:
        _per_row(units, "units", owner, error.shape[1])
    window = t >= number(after, "after", owner, unit="s", allow_infinite=True)
    figures = []
    scales, sources = row_scales(desired, units, fallback)
    for e, scale, source in zip(np.abs(error).T, scales, sources):
        values = e[window & ~np.isnan(e)]
        worst = float(np.max(values)) if values.size else None
        figures.append((worst, None if worst is None or source == "unit" else 100.0 * worst / float(scale)))
    return figures


def row_errors(t: ArrayLike, error: ArrayLike, desired: ArrayLike, names: Sequence[str], units: Sequence[str],
               since: float, settle_after: float) -> List[RowFigures]:
    """Per-row error figures (a list of ``RowFigures``), each in the row's own units and in % of that row's scale
    (``row_scales``): its command, or, for a row commanded to zero, the largest command in its units,
    else the run's scale (the speed or the force the run commands: the cross-track row of a slide
    against the slide's speed), so that no row drops out of the worst-row figures.

    ``names``: at most one per row (a row without one is called "row i"); ``units``: one per row.
    ``since``: when the law took over (contact); ``settle_after``: when the design says the
    transient is over (contact + 5 design time constants). Settling times (within 1 % of the scale)
    are counted from ``since``. Samples that read NaN (the measured wrench invalid then: no
    measurement) are left out of every figure.
    """
    owner = "row_errors"
    t = _times(t, "t", owner)
    error = _rows(error, "error", owner, samples=t.size, nan=True)
    desired = _rows(desired, "desired", owner, columns=error.shape[1])
    units = _per_row(units, "units", owner, error.shape[1])
    if isinstance(names, (str, bytes)) or not hasattr(names, "__len__") or len(names) > error.shape[1]:
        raise ArgumentError(f"{owner}: names must be a list of at most one name per row ({error.shape[1]}; a row "
                            f"without one is called 'row i'), got {describe(names)}")
    since = number(since, "since", owner, unit="s", allow_infinite=True)
    settle_after = number(settle_after, "settle_after", owner, unit="s", allow_infinite=True)
    rows = []
    commands = row_commands(desired)
    scales, sources = row_scales(desired, units)
    settled = max_row_errors(t, error, desired, settle_after, units)
    last = last_valid(error)                   # the final figures: the last sample that is a measurement
    for i in range(error.shape[1]):
        e, command, scale = np.abs(error[:, i]), float(commands[i]), float(scales[i])
        valid = ~np.isnan(e)
        late = (t >= settle_after) & valid
        worst_time = float(t[late][np.argmax(e[late])]) if late.any() else None
        if np.isfinite(since):
            active = (t >= since) & valid
            settle = settling_time(t[active], e[active], 0.01 * scale) - since if active.any() else None
        else:
            settle = None
        final_error = None if last is None else float(last[i])
        final_percent = None if final_error is None or sources[i] == "unit" else 100.0 * abs(final_error) / scale
        rows.append(RowFigures(name=names[i] if i < len(names) else f"row {i + 1}", units=units[i],
                               command=command, scale=scale, scale_of=sources[i], final_error=final_error,
                               final_error_percent=final_percent,
                               max_error_after_5_time_constants=settled[i][0],
                               max_error_percent_after_5_time_constants=settled[i][1],
                               max_error_time_after_5_time_constants=worst_time,
                               settling_time_1_percent=settle))
    return rows


def max_after(values: ArrayLike, window: ArrayLike) -> List[Optional[float]]:
    """Per column, max |values| over the samples in ``window`` that do not read NaN (a list of floats,
    None where there is none)."""
    magnitudes: Array = np.abs(_rows(values, "values", "max_after", nan=True))
    window = np.asarray(window)
    if window.dtype != bool or window.shape != (magnitudes.shape[0],):
        raise ArgumentError(f"max_after: window must be a boolean mask of one entry per sample "
                            f"({magnitudes.shape[0]}), got {describe(window)}")
    magnitudes = magnitudes[window]
    return [float(np.max(column[~np.isnan(column)])) if np.any(~np.isnan(column)) else None
            for column in magnitudes.T]


def worst(rows: Iterable[RowFigures], key: str) -> Optional[float]:
    """The largest figure ``key`` (a field of ``RowFigures``) over the rows that have it (None if none has)."""
    values = [getattr(row, key) for row in rows if getattr(row, key) is not None]
    return max(values) if values else None


def impedance_check(log: Mapping[str, Array], gains: ValidatedGains, since: float,
                    settle_after: float) -> Optional[ImpedanceCheck]:
    """Impedance-force mode: how closely the run realizes the designed impedance (3.2-11), whatever its
    measured F_v does. The impedance is driven by the run's logged F_v from its logged errors at
    ``since`` (contact; ``analysis.environment.impedance_response``) and compared with the run's
    velocity errors from ``settle_after`` on, an ``ImpedanceCheck``: ``max_difference`` per row, in its
    units; ``max_difference_percent`` the largest in % of its row's command (None if no row has a
    command); ``max_tangential_force`` per row, max |F_v|.

    The caller checks the mode (every log has position errors, zeros outside position and impedance
    mode). None without position errors, with the paper's pseudo-velocity rows (the log's errors are
    then the true rows'), or without a sample that late."""
    since = number(since, "since", "impedance_check", unit="s", allow_infinite=True)
    settle_after = number(settle_after, "settle_after", "impedance_check", unit="s", allow_infinite=True)
    t = np.asarray(log["t"], dtype=float)
    if "position_error" not in log or "true_desired_velocity" in log or not np.any(t >= settle_after):
        return None
    first = int(np.argmax(t >= since))
    predicted = impedance_response(gains.velocity, gains.position, t[first:] - t[first],
                                   log["tangential_force"][first:], log["position_error"][first],
                                   log["velocity_error"][first], gains.impedance_inverse_mass)
    difference = np.zeros_like(np.asarray(log["velocity_error"], dtype=float))
    difference[first:] = predicted - log["velocity_error"][first:]
    # % of each commanded row's own command; a row commanded to zero has its absolute figure only
    figures = max_row_errors(t, difference, log["desired_velocity"], settle_after, fallback="unit")
    percents = [percent for _, percent in figures if percent is not None]
    return ImpedanceCheck(max_difference=[worst for worst, _ in figures],
                          max_difference_percent=max(percents) if percents else None,
                          max_tangential_force=np.max(np.abs(np.asarray(log["tangential_force"])[t >= settle_after]),
                                                      axis=0).tolist())
