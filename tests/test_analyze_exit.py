"""``drake-hybrid analyze``: every designed eigenvalue it misses is explained by the task's prediction
for it, and the exit code says whether the misses are the predicted ones (--strict: any miss fails)."""

import dataclasses

import numpy as np
import pytest

import drake_hybrid.cli as cli
from drake_hybrid.analysis.linearization import linearize_discrete, shifted_design
from drake_hybrid.scenario.task import EigenvalueShift
from drake_hybrid.scenario.tasks import get_task


@pytest.fixture(scope="module")
def crank_linearization():
    return linearize_discrete(get_task("crank-turning").default_config(), settle_time=0.5)


def test_the_crank_misses_only_what_the_handles_inertia_predicts(crank_linearization, monkeypatch, capsys):
    result = crank_linearization
    assert not result.match.matched                                   # the spin row is 5 % slow
    (shift,) = result.shifts
    assert shift.designed == -10.0 and -9.5 < shift.predicted.real < -9.3 and "inertia" in shift.reason
    assert result.shifted_match.matched
    monkeypatch.setattr(cli, "linearize_discrete", lambda *args, **kwargs: result)
    assert cli.main(["analyze", "crank-turning", "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "missed; predicted -9.4" in printed and "handle's spin inertia" in printed
    assert "matched as predicted" in printed
    assert cli.main(["analyze", "crank-turning", "--quiet", "--strict"]) == 1


def test_a_miss_without_a_prediction_exits_1(crank_linearization, monkeypatch, capsys):
    unexplained = dataclasses.replace(crank_linearization, shifts=[], shifted_match=None)
    monkeypatch.setattr(cli, "linearize_discrete", lambda *args, **kwargs: unexplained)
    assert cli.main(["analyze", "crank-turning", "--quiet"]) == 1
    assert "not matched" in capsys.readouterr().out


def test_shifted_design_replaces_one_equal_eigenvalue_per_shift():
    designed = np.array([-10.0, -10.0, -8.0], dtype=complex)
    shifted = shifted_design(designed, [EigenvalueShift(-10.0, -9.4, "a"), EigenvalueShift(-8.0, -7.0, "b")])
    np.testing.assert_array_equal(shifted, [-9.4, -10.0, -7.0])
    with pytest.raises(ValueError, match="matches no designed eigenvalue"):
        shifted_design(designed, [EigenvalueShift(-3.0, -2.0, "c")])
