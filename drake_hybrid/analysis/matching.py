"""Measured closed-loop eigenvalues matched against the designed ones.

* ``match_eigenvalues``: pairs every designed eigenvalue with a distinct measured one (minimum total
  relative distance), reports the unmatched ones nearest 0 as the partners of the predicted zero
  eigenvalues and the rest as extra modes, and says whether every pair is within tolerance and no
  unmatched mode grows (``EigenvalueMatch``).
* ``shifted_design``, ``shift_indices``: the design with a task's predicted shifts
  (``tasks.task.EigenvalueShift``: physics the paper's model leaves out) in place of the designed values.
* ``predicted_match``: the match in which every miss is a predicted one (a task's shifted design,
  an unstable mode its diagnosis predicts), if any: what ``drake-hybrid analyze`` exits 0 on.
* ``nyquist_split``: the modes of a one-period map at the step's Nyquist frequency, set apart.

The designed eigenvalues come from ``analysis.design``, the measured ones from ``analysis.linearization``
(continuous) and ``analysis.discrete_linearization`` (sampled).
"""

from dataclasses import dataclass, field
from typing import Any, Dict, Iterable, Optional, Protocol, Tuple

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import linear_sum_assignment

from drake_hybrid.analysis.modes import explained_modes
from drake_hybrid.core.arguments import complex_vector, number, relative_tolerance
from drake_hybrid.core.errors import ArgumentError
from drake_hybrid.core.hints import Array
from drake_hybrid.tasks.task import EigenvalueShift


@dataclass
class EigenvalueMatch:
    predicted: np.ndarray
    measured: np.ndarray                               # all closed-loop eigenvalues
    partner: np.ndarray                                # measured eigenvalue matched to each predicted one
    relative_error: np.ndarray                         # |partner - predicted| / |predicted|
    tolerance: float
    matched: bool
    extra: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))   # measured, not matched
    unstable_extra: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    marginal_partners: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))  # nearest 0

    def as_dict(self) -> Dict[str, Any]:
        pairs = lambda values: [[float(np.real(v)), float(np.imag(v))] for v in values]
        return {"predicted": pairs(self.predicted), "closed_loop": pairs(self.measured),
                "matched_partners": pairs(self.partner), "relative_error": [float(e) for e in self.relative_error],
                "tolerance": self.tolerance, "matched": bool(self.matched), "extra_modes": pairs(self.extra),
                "marginal_modes": pairs(self.marginal_partners), "unstable_modes": pairs(self.unstable_extra)}


def match_eigenvalues(designed: ArrayLike, measured: ArrayLike, tolerance: float = 0.05, marginal: int = 0,
                      marginal_real: Optional[float] = None) -> EigenvalueMatch:
    """Pair each designed eigenvalue with a distinct measured one (Hungarian algorithm on the
    relative distance |mu - lambda| / |lambda|) and sort out the rest.

    The designed eigenvalues are the nonzero ones of ``analysis.design.predicted_eigenvalues``. The theory also
    predicts ``marginal`` zero eigenvalues (unregulated positions, frozen integrals): the
    ``marginal`` unmatched measured eigenvalues nearest to 0 are reported as their partners
    (``marginal_partners``); compliant contact may move them slightly either way. Every other
    unmatched eigenvalue is an extra mode (contact, filter, sampling, joint space).

    ``matched`` is True when every designed eigenvalue has a partner within ``tolerance`` and no
    unmatched eigenvalue (marginal or extra) has a real part above ``marginal_real`` (default
    ``tolerance`` times 1 1/s: slower than 5 % per second of growth is counted as marginal, not
    unstable).

    ArgumentError for ``designed`` and ``measured`` that are not vectors of finite numbers (``designed``
    nonzero, no more of them than measured), a ``marginal`` that is not an integer >= 0, a ``tolerance``
    outside (0, 1].
    """
    owner = "match_eigenvalues"
    tolerance = relative_tolerance(tolerance, "tolerance", owner)
    designed = complex_vector(designed, "designed", owner, nonzero=True)
    measured = complex_vector(measured, "measured", owner)
    marginal = number(marginal, "marginal", owner, low=0, integer=True, unit="zero eigenvalues")
    marginal_real = number(tolerance * 1.0 if marginal_real is None else marginal_real, "marginal_real", owner,
                           unit="1/s", allow_none=True)
    if designed.size > measured.size:
        raise ArgumentError(f"{owner}: measured has {measured.size} eigenvalues, fewer than the {designed.size} "
                            "designed ones")
    cost = np.abs(measured[None, :] - designed[:, None]) / np.abs(designed)[:, None]
    rows, cols = linear_sum_assignment(cost)
    order = np.argsort(rows)
    rows, cols = rows[order], cols[order]
    partner = measured[cols]
    relative_error = cost[rows, cols]
    rest = np.delete(measured, cols)
    by_size = np.argsort(np.abs(rest))
    marginal_partners = rest[by_size[:marginal]]
    extra = rest[by_size[marginal:]]
    unstable = rest[rest.real > marginal_real]
    matched = bool(np.all(relative_error <= tolerance) and unstable.size == 0)
    return EigenvalueMatch(predicted=designed, measured=measured, partner=partner, relative_error=relative_error,
                           tolerance=tolerance, matched=matched, extra=extra, unstable_extra=unstable,
                           marginal_partners=marginal_partners)


def shift_indices(designed: ArrayLike, shifts: Iterable[EigenvalueShift]) -> Dict[int, EigenvalueShift]:
    """{index in ``designed``: shift}: each ``tasks.task.EigenvalueShift`` takes one designed
    eigenvalue equal to its ``designed``, not yet taken; ValueError if there is none."""
    designed = np.asarray(designed, dtype=complex)
    taken = {}
    for shift in shifts:
        same = [i for i, value in enumerate(designed)
                if i not in taken and abs(value - shift.designed) <= 1e-9 * max(1.0, abs(shift.designed))]
        if not same:
            raise ValueError(f"a predicted shift of {shift.designed} matches no designed eigenvalue {designed}")
        taken[same[0]] = shift
    return taken


def nyquist_split(modes: ArrayLike, period: Optional[float]) -> Tuple[Array, Array]:
    """(modes, the ones at the discrete step's Nyquist frequency): for a one-period map of step ``period``
    (None: a continuous linearization, nothing to split), log(mu)/h of a real multiplier mu < 0 has
    imaginary part +-pi/h; such a mode has no conjugate partner (log's principal branch gives one sign)."""
    modes = np.asarray(modes, dtype=complex)
    if not period:
        return modes, modes[:0]
    at = np.abs(np.abs(modes.imag) - np.pi / period) <= 1e-6 * np.pi / period
    return modes[~at], modes[at]


def shifted_design(designed: ArrayLike, shifts: Iterable[EigenvalueShift]) -> Array:
    """The designed eigenvalues with, for each ``tasks.task.EigenvalueShift``, one equal designed
    eigenvalue replaced by the shift's prediction (order kept)."""
    corrected = np.array(designed, dtype=complex)
    for index, shift in shift_indices(designed, shifts).items():
        corrected[index] = shift.predicted
    return corrected


class MatchedLinearization(Protocol):
    """What ``predicted_match`` reads of a linearization's result (``analysis.linearization.Linearization``,
    ``analysis.discrete_linearization.DiscreteLinearization``): its ``match`` (and ``shifted_match`` and
    ``unstable_modes`` when it has them). A type for type hints."""

    @property
    def match(self) -> EigenvalueMatch: ...


def predicted_match(result: MatchedLinearization, tolerance: float = 0.05) -> Optional[EigenvalueMatch]:
    """The match of a linearization ``result`` in which every miss is a predicted one, or None.

    Tries the plain match, then the one against the task's shifted design (``shifted_match``); a
    match counts when every designed eigenvalue is within ``tolerance`` of its partner and every
    unstable extra mode is within ``tolerance`` of the prediction of its diagnosis
    (``result.unstable_modes``, ``analysis.modes.ModeDiagnosis.explained``). ``drake-hybrid analyze``
    exits 0 on it (``--strict``: only on a plain match)."""
    tolerance = relative_tolerance(tolerance, "tolerance", "predicted_match")
    diagnoses = getattr(result, "unstable_modes", [])
    for candidate in (result.match, getattr(result, "shifted_match", None)):
        if (candidate is not None and bool(np.all(candidate.relative_error <= tolerance))
                and explained_modes(candidate.unstable_extra, diagnoses, tolerance)):
            return candidate
    return None
