"""``drake-hybrid analyze``: every designed eigenvalue it misses is explained by the task's prediction
for it, and the exit code says whether the misses are the predicted ones (--strict: any miss fails)."""

import dataclasses
import json
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

import drake_hybrid.cli as cli
from drake_hybrid.analysis.derivatives import DerivativeMismatchWarning, JacobianCheck
from drake_hybrid.analysis.discrete_linearization import linearize_discrete
from drake_hybrid.analysis.matching import match_eigenvalues, shifted_design
from drake_hybrid.report.eigenvalues import judge_eigenvalues
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.tasks.task import EigenvalueShift


@pytest.fixture(scope="module")
def crank_linearization():
    return linearize_discrete(get_task("crank-turning").default_config(), settle_time=0.5)


def test_the_crank_misses_only_what_the_handles_inertia_predicts(crank_linearization, monkeypatch, capsys):
    result = crank_linearization
    assert not result.match.matched                                   # the spin row is 5 % slow
    (shift,) = result.shifts
    assert shift.designed == -10.0 and -9.5 < shift.predicted.real < -9.3 and "inertia" in shift.reason
    assert result.shifted_match.matched
    monkeypatch.setattr("drake_hybrid.analysis.discrete_linearization.linearize_discrete",
                        lambda *args, **kwargs: result)
    assert cli.main(["analyze", "crank-turning", "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "missed; predicted -9.4" in printed and "handle's spin inertia" in printed
    assert "matched as predicted" in printed
    assert ("Jacobian: the one-period map's, by central differences (a sampled loop has no AutoDiffXd Jacobian "
            "to check it against); eigenvalues from it") in printed
    assert cli.main(["analyze", "crank-turning", "--quiet", "--strict"]) == 1


def test_the_verdict_is_the_reports_callable_without_the_command_line(crank_linearization):
    """report.eigenvalues.judge_eigenvalues is what analyze prints and exits with: a notebook gets the same
    verdict, lines and --json payload."""
    config = get_task("crank-turning").default_config()
    report = judge_eigenvalues(crank_linearization, config, continuous=False, velocity_dim=2, force_dim=4)
    assert report.exit_code == 0 and report.matched_as_predicted and not crank_linearization.match.matched
    assert report.verdict.endswith("no other mode unstable: matched as predicted")
    assert any("missed; predicted -9.4" in line for line in report.lines())
    payload = report.as_dict()
    assert payload["matched_as_predicted"] is True and payload["method"] == "discrete" and payload["force_dim"] == 4
    strict = judge_eigenvalues(crank_linearization, config, False, 2, 4, strict=True)
    assert strict.exit_code == 1 and strict.verdict.endswith("(--strict: counted as a miss)")


def test_a_miss_without_a_prediction_exits_1(crank_linearization, monkeypatch, capsys):
    unexplained = dataclasses.replace(crank_linearization, shifts=[], shifted_match=None)
    monkeypatch.setattr("drake_hybrid.analysis.discrete_linearization.linearize_discrete",
                        lambda *args, **kwargs: unexplained)
    assert cli.main(["analyze", "crank-turning", "--quiet"]) == 1
    assert "not matched" in capsys.readouterr().out


def test_shifted_design_replaces_one_equal_eigenvalue_per_shift():
    designed = np.array([-10.0, -10.0, -8.0], dtype=complex)
    shifted = shifted_design(designed, [EigenvalueShift(-10.0, -9.4, "a"), EigenvalueShift(-8.0, -7.0, "b")])
    np.testing.assert_array_equal(shifted, [-9.4, -10.0, -7.0])
    with pytest.raises(ValueError, match="matches no designed eigenvalue"):
        shifted_design(designed, [EigenvalueShift(-3.0, -2.0, "c")])


def _impedance_crank_result():
    """The impedance-mode crank's figures as `analyze` finds them (h = 0.5 ms): the spin pair -8, -2 moved to
    -10.49, -1.892 (predicted -10.38, -1.892), four force eigenvalues near -10, and modes of negative
    multipliers at the step's Nyquist frequency pi/h."""
    designed = np.array([-8, -8, -2, -2, -10, -10, -10, -10], dtype=complex)
    nyquist = np.pi / 5e-4
    measured = np.array([-10.49, -8.014, -1.892, -2.004, -10.05, -10.05, -10.06, -10.06, -1.6e-7, 9.0e-6,
                         -1.634e4 + 1j * nyquist, -8719 + 1j * nyquist, -2292 - 896.8j, -2292 + 896.8j, -1402])
    shifts = [EigenvalueShift(-8.0, -10.38, "spin pair"), EigenvalueShift(-2.0, -1.892, "spin pair")]
    return SimpleNamespace(
        match=match_eigenvalues(designed, measured, marginal=2),
        shifted_match=match_eigenvalues(shifted_design(designed, shifts), measured, marginal=2), shifts=shifts,
        period=5e-4, equilibrium_residual=1e-7, wall_time=0.2, unstable_modes=[], jacobian_check=None,
        step_check=None)


def test_analyze_says_which_deviation_figure_is_which(monkeypatch, capsys, tmp_path):
    """The table pairs -8 with the -10.49 mode the prediction identifies (31.1 %); plain nearest pairing
    gives -8 a force mode near -10 (25.6 %), the figure docs/baselines.md quotes. Both printed, each named."""
    result = _impedance_crank_result()
    monkeypatch.setattr("drake_hybrid.analysis.discrete_linearization.linearize_discrete",
                        lambda *args, **kwargs: result)
    out = tmp_path / "eigenvalues.json"
    assert cli.main(["analyze", "crank-turning", "--mode", "impedance-force", "--quiet", "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "-10.49    31.125 %  missed; predicted -10.38" in printed
    raw = 100 * max(result.match.relative_error)
    assert 25 < raw < 26                                   # -8 paired with a force mode near -10
    assert (f"worst deviation from the design: {100 * 2.49 / 8:.2f} % with each designed eigenvalue paired as the "
            f"task's prediction pairs it (the table above); {raw:.2f} % paired by nearest distance alone") in printed
    payload = json.loads(out.read_text())
    assert 100 * max(payload["relative_error"]) == pytest.approx(raw)
    assert max(payload["paired_by_prediction"]["relative_error"]) == pytest.approx(2.49 / 8)


def test_modes_at_the_steps_nyquist_frequency_are_named_as_such(monkeypatch, capsys):
    monkeypatch.setattr("drake_hybrid.analysis.discrete_linearization.linearize_discrete",
                        lambda *args, **kwargs: _impedance_crank_result())
    assert cli.main(["analyze", "crank-turning", "--mode", "impedance-force", "--quiet"]) == 0
    printed = capsys.readouterr().out
    (other,) = [line for line in printed.splitlines() if "other modes" in line]
    assert "6283j" not in other and "-2292+896.8j" in other
    (nyquist,) = [line for line in printed.splitlines() if "Nyquist" in line]
    assert "pi/h = 6283 1/s" in nyquist and "-1.634e+04+6283j, -8719+6283j" in nyquist


def test_analyze_prints_the_jacobian_checks_line_instead_of_a_python_warning(monkeypatch, capsys):
    """Where the Jacobian check replaces AutoDiffXd's columns (the sphere's pole path, a box workpiece), the
    linearization warns (DerivativeMismatchWarning) for library users; the command line prints the check's
    own line (how closely AutoDiffXd agrees, which columns were replaced, which A the eigenvalues come
    from) and no Python warning."""
    designed = np.array([-10.0, -8.0, -10.0], dtype=complex)
    check = JacobianCheck(max_relative_error=1.0, max_absolute_error=2e6, worst_column=0, worst_state="plant joint1_q",
                          tolerance=1e-3, epsilon=1e-5, used="autodiff with 1 column(s) from central differences",
                          evaluations=28, replaced=["plant joint1_q"], largest_entry=2.8e7)

    def linearize(*args, **kwargs):
        warnings.warn(DerivativeMismatchWarning("the closed loop: the AutoDiffXd state Jacobian disagrees"))
        return SimpleNamespace(match=match_eigenvalues(designed, np.array([-10.0, -8.0, -9.97, 1e-12, -1e-10, -1257]),
                                                       marginal=2),
                               shifted_match=None, shifts=[], equilibrium_residual=1e-10, wall_time=0.1,
                               unstable_modes=[], jacobian_check=check, step_check=None)

    monkeypatch.setattr("drake_hybrid.analysis.linearization.linearize_continuous", linearize)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert cli.main(["analyze", "window-washing", "--quiet"]) == 0
    assert not [w for w in caught if issubclass(w.category, DerivativeMismatchWarning)]
    captured = capsys.readouterr()
    assert "Warning" not in captured.err + captured.out
    (line,) = [line for line in captured.out.splitlines() if "Jacobian check" in line]
    assert "differ from central differences by at most 1 of the column's size (tolerance 0.001" in line
    assert "replaced by central differences: plant joint1_q" in line
    assert line.endswith("eigenvalues from AutoDiffXd's A with 1 column(s) from central differences")


def test_analyze_says_which_sampled_loop_it_linearized(monkeypatch, capsys):
    """The crank's linearization runs the controller at the plant's 0.5 ms step without a low-pass; simulate
    ticks it every 1 ms: the output says both."""
    monkeypatch.setattr("drake_hybrid.analysis.discrete_linearization.linearize_discrete",
                        lambda *args, **kwargs: _impedance_crank_result())
    assert cli.main(["analyze", "crank-turning", "--mode", "impedance-force", "--quiet"]) == 0
    (line,) = [line for line in capsys.readouterr().out.splitlines() if "sampled loop linearized" in line]
    assert ("the sampled loop linearized at the plant's step h = 0.5 ms, with the controller at that rate "
            "(every update at the same instants: one map per step) and no wrench low-pass; simulate runs the "
            "controller every 1 ms (control_period), no low-pass either") in line
