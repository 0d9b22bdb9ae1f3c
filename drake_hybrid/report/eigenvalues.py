"""``drake-hybrid analyze``'s judgement of a linearization: the designed eigenvalues against the linearized
ones, the verdict and its exit code, the lines it prints and its ``--json`` payload.

``judge_eigenvalues(result, config, ...)`` takes what ``analysis.linearization.linearize_continuous`` or
``linearize_discrete`` returned and gives an ``EigenvalueReport``:

* matched: every designed eigenvalue within the tolerance of its linearized partner and no other mode
  unstable (exit code 0);
* matched as predicted: every miss within the tolerance of the task's prediction for it (a designed
  eigenvalue the task predicts shifted, an unstable mode its diagnosis predicts: ``predicted_match``);
  exit code 0, or 1 with ``strict``;
* not matched: unstable modes, or misses nothing predicts (exit code 1).

With predicted shifts the table pairs each designed eigenvalue as the prediction pairs it (``paired``);
``--json``'s ``relative_error`` stays the pairing by nearest distance.
"""

from dataclasses import dataclass
from typing import Any, Dict, Iterable, List, Optional, Union

import numpy as np

from drake_hybrid.analysis.discrete_linearization import DiscreteLinearization
from drake_hybrid.analysis.linearization import Linearization
from drake_hybrid.analysis.matching import EigenvalueMatch, nyquist_split, predicted_match, shift_indices
from drake_hybrid.control.gains import ControlMode
from drake_hybrid.core.hints import Array
from drake_hybrid.tasks.config import ScenarioConfig
from drake_hybrid.tasks.task import EigenvalueShift

# A linearization ``judge_eigenvalues`` judges: ``linearize_continuous``'s or the discrete loop's.
LinearizationResult = Union[Linearization, DiscreteLinearization]


def format_eigenvalues(values: Iterable[complex]) -> str:
    """Eigenvalues as the command line prints them: "-10, -8.5+3j" (4 significant figures; real when the
    imaginary part is below 1e-9)."""
    return ", ".join(f"{v.real:.4g}{v.imag:+.4g}j" if abs(v.imag) > 1e-9 else f"{v.real:.4g}" for v in values)


def sampled_loop_text(config: ScenarioConfig, period: float) -> str:
    """What ``linearize_discrete`` linearized (``period``: its step, the plant's) against what ``simulate`` runs."""
    low_pass = getattr(config.sensor, "bandwidth_hz", 0.0)
    simulated = (f"simulate runs the controller every {config.control_period * 1e3:g} ms (control_period)"
                 + (f" with a {low_pass:g} Hz wrench low-pass" if low_pass > 0 else ", no low-pass either"))
    return (f"the sampled loop linearized at the plant's step h = {period * 1e3:g} ms, with the controller at that "
            f"rate (every update at the same instants: one map per step) and no wrench low-pass; {simulated}")


@dataclass
class EigenvalueReport:
    """A linearization judged against its design (``judge_eigenvalues``; the module docstring)."""
    result: LinearizationResult     # the linearization (match, shifted_match, shifts, period, checks, ...)
    config: ScenarioConfig      # the config linearized
    mode: ControlMode
    continuous: bool            # linearize_continuous's (else the discrete loop's one-period map)
    velocity_dim: int           # k
    force_dim: int              # m
    tolerance: float            # relative
    strict: bool
    paired: EigenvalueMatch     # the match the table pairs by (the prediction's, else the match)
    errors: Array               # each designed eigenvalue's relative error from its partner in ``paired``
    shifted: Dict[int, EigenvalueShift]      # index of a designed eigenvalue -> the task's shift for it
    predicted_by: Optional[EigenvalueMatch]  # the match that explains every miss (``predicted_match``), or None
    verdict: str                # the verdict's line
    exit_code: int              # 0: matched (as predicted, without ``strict``); 1: not

    @property
    def period(self) -> Optional[float]:
        """The discrete loop's step (s), None for the continuous loop."""
        return getattr(self.result, "period", None)

    @property
    def matched_as_predicted(self) -> bool:
        """Matched, or every miss within the tolerance of its prediction."""
        return bool(self.result.match.matched or self.predicted_by is not None)

    def lines(self) -> List[str]:
        """The lines ``drake-hybrid analyze`` prints: the method, the table of designed against linearized
        eigenvalues with each predicted miss, the predictions, the other modes, the worst deviations, the
        verdict, the unstable modes' diagnoses and the Jacobian's checks."""
        result, match, shown, shifted = self.result, self.result.match, self.paired, self.shifted
        period = self.period
        if self.continuous:
            how = "Linearize of the continuous closed loop"
        else:
            assert period is not None                # the discrete loop's step
            how = (f"Jacobian of the discrete closed loop's one-period map (h = {period * 1e3:g} ms), "
                   "eigenvalues log(mu)/h,")
        lines = [f"{self.config.task} ({self.mode.value}): {how} at a contact equilibrium (residual "
                 f"{result.equilibrium_residual:.2g}; the linearization itself took {result.wall_time:.2f} s)"]
        if period:
            lines.append(f"  {sampled_loop_text(self.config, period)}")
        lines.append(f"  {'designed':>22}  {'linearized':>22}  rel. error")
        for i, (p, q, error) in enumerate(zip(match.predicted, shown.partner, self.errors)):
            line = f"  {format_eigenvalues([p]):>22}  {format_eigenvalues([q]):>22}  {100 * error:8.3f} %"
            if i in shifted and error > self.tolerance:
                line += (f"  missed; predicted {format_eigenvalues([shifted[i].predicted])} "
                         f"({100 * shown.relative_error[i]:.2f} % from it): see [{sorted(shifted).index(i) + 1}]")
            lines.append(line)
        for n, i in enumerate(sorted(shifted)):
            # one reason per run of shifts that share it (an impedance's rows meeting one contact)
            following = sorted(shifted)[n + 1] if n + 1 < len(shifted) else None
            last = following is None or shifted[following].reason != shifted[i].reason
            lines.append(f"  [{n + 1}] {format_eigenvalues([shifted[i].designed])} -> "
                         f"{format_eigenvalues([shifted[i].predicted])}" + (f": {shifted[i].reason}" if last else ";"))
        lines.append(f"  marginal (theory: {len(match.marginal_partners)} x 0, unregulated positions): "
                     f"{format_eigenvalues(match.marginal_partners)}")
        other, nyquist = nyquist_split(match.extra, period)
        lines.append(f"  other modes (contact, filter, sampling, joint space): "
                     f"{format_eigenvalues(np.sort_complex(other))}")
        if nyquist.size:
            assert period is not None                # nyquist_split finds modes only at a step's frequency
            lines.append(f"  at the step's Nyquist frequency pi/h = {np.pi / period:.4g} 1/s (multipliers mu < 0, "
                         "which log(mu)/h maps to ln|mu|/h +- j pi/h: real modes that change sign every step, none of "
                         f"them designed): {format_eigenvalues(np.sort_complex(nyquist))}")
        if result.shifted_match is not None:
            raw, paired = 100 * np.max(match.relative_error), 100 * np.max(self.errors)
            if abs(raw - paired) >= 0.005:
                lines.append(f"  worst deviation from the design: {paired:.2f} % with each designed eigenvalue paired "
                             f"as the task's prediction pairs it (the table above); {raw:.2f} % paired by nearest "
                             "distance alone (--json's relative_error; the figure docs/baselines.md quotes)")
        lines.append(f"  {self.verdict}")
        lines += [f"  {diagnosis.summary()}" for diagnosis in getattr(result, "unstable_modes", [])]
        check = getattr(result, "jacobian_check", None)
        lines.append(f"  {check.summary()}" if check is not None else
                     "  Jacobian: the one-period map's, by central differences (a sampled loop has no AutoDiffXd "
                     "Jacobian to check it against); eigenvalues from it")
        step_check = getattr(result, "step_check", None)
        if step_check is not None:
            lines.append(f"  {step_check.summary()}")
        return lines

    def as_dict(self) -> Dict[str, Any]:
        """``--json``'s payload: the match (``EigenvalueMatch.as_dict``), the predicted shifts, the pairing by
        prediction, the Nyquist frequency, whether it matched as predicted, the gains and the run's checks."""
        result, check, step_check = self.result, getattr(self.result, "jacobian_check", None), getattr(
            self.result, "step_check", None)
        payload = result.match.as_dict()
        payload["predicted_shifts"] = [{"designed": [float(np.real(x.designed)), float(np.imag(x.designed))],
                                        "predicted": [float(np.real(x.predicted)), float(np.imag(x.predicted))],
                                        "reason": x.reason} for x in result.shifts]
        if result.shifted_match is not None:
            payload["paired_by_prediction"] = {"partners": [[float(np.real(q)), float(np.imag(q))]
                                                            for q in self.paired.partner],
                                               "relative_error": [float(e) for e in self.errors]}
        if self.period:
            payload["nyquist_frequency"] = float(np.pi / self.period)
        payload["matched_as_predicted"] = self.matched_as_predicted
        payload.update({"gains": self.config.gains.as_lists(self.velocity_dim, self.force_dim, self.mode),
                        "mode": self.mode.value, "method": "continuous" if self.continuous else "discrete",
                        "velocity_dim": self.velocity_dim, "force_dim": self.force_dim, "task": self.config.task,
                        "equilibrium_residual": result.equilibrium_residual, "wall_time": result.wall_time,
                        "jacobian_check": check.as_dict() if check is not None else {"used": "central differences"},
                        "unstable_modes": [d.as_dict() for d in getattr(result, "unstable_modes", [])],
                        "step_check": step_check.as_dict() if step_check is not None else None})
        return payload


def judge_eigenvalues(result: LinearizationResult, config: ScenarioConfig, continuous: bool, velocity_dim: int,
                      force_dim: int, tolerance: float = 0.05, strict: bool = False) -> EigenvalueReport:
    """Judge a linearization (``result``: ``linearize_continuous``'s or ``linearize_discrete``'s, of ``config``)
    against its design within the relative ``tolerance``: an ``EigenvalueReport`` (the module docstring);
    ``strict`` counts a predicted miss as a miss (exit code 1)."""
    match = result.match
    mode = ControlMode.parse(config.mode)
    # With the task's predicted shifts (physics the paper's model leaves out), pair against those.
    shown = result.shifted_match or match
    shifted = shift_indices(match.predicted, result.shifts)
    errors = np.abs(shown.partner - match.predicted) / np.abs(match.predicted)
    percent = f"{100 * tolerance:g} %"
    predicted_by = predicted_match(result, tolerance)
    if match.matched:
        verdict, code = f"every designed eigenvalue within {percent}, no other mode unstable: matched", 0
    elif predicted_by is not None:
        parts = []
        if predicted_by is result.shifted_match and np.any(errors > tolerance):
            parts.append(f"{int(np.sum(errors > tolerance))} designed eigenvalue(s) missed by more than "
                         f"{percent}, each within {percent} of the task's prediction for it")
        if predicted_by.unstable_extra.size:
            parts.append(f"{predicted_by.unstable_extra.size} unstable mode(s), each within {percent} of its "
                         "predicted value (below)")
        verdict = ", ".join(parts) + ", no other mode unstable: matched as predicted"
        code = 1 if strict else 0
        if strict:
            verdict += " (--strict: counted as a miss)"
    else:
        unexplained = "unstable modes" if match.unstable_extra.size else f"misses beyond {percent} not predicted"
        verdict, code = f"not matched: {unexplained}", 1
    return EigenvalueReport(result=result, config=config, mode=mode, continuous=continuous,
                            velocity_dim=velocity_dim, force_dim=force_dim, tolerance=tolerance, strict=strict,
                            paired=shown, errors=errors, shifted=shifted, predicted_by=predicted_by,
                            verdict=verdict, exit_code=code)
