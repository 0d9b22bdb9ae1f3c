"""The impedance meets its contact (analysis.environment): on a small curved workpiece the
tessellated hydroelastic contact has a stiffness and a damping along the surface, and the
unit-mass impedance (3.2-11) yields to them, as an impedance should. The linearized loop's roots are
then those of s^2 + (K_v - B_e) s + (K_p - K_e), with K_e and B_e measured by central differences
of the wrench sensor alone (not from the closed loop's Jacobian).

The UR10 (example-robot-data) on the 5 cm drum of tests/own_arm_cases.py: the designed pair (-3, -7)
is linearized at (-2.347, -7.855), 21.8 % off; K_e = +2.57 N/m and B_e = -0.20 N s/m along x predict
(-2.362, -7.840), within 0.6 % (measured 0.41 % worst over every designed eigenvalue).
"""

import logging
import re

import numpy as np
import own_arm_cases as cases
import pytest

from drake_hybrid.analysis.environment import impedance_loop, impedance_response, mass_factor_within
from drake_hybrid.analysis.linearization import linearize_continuous
from drake_hybrid.analysis.matching import predicted_match

logging.getLogger("drake").setLevel(logging.ERROR)


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("meshes")


def test_impedance_loop_roots_are_those_of_the_impedance_with_its_environment():
    """One row: s^2 + (K_v - B_e) s + (K_p - K_e) = 0; without the environment the designed roots."""
    K_v, K_p = np.array([[10.0]]), np.array([[21.0]])
    np.testing.assert_allclose(np.sort(impedance_loop(K_v, K_p).real), [-7.0, -3.0], rtol=1e-12)
    K_e, B_e = np.array([[2.5]]), np.array([[-0.5]])
    expected = np.roots([1.0, 10.0 + 0.5, 21.0 - 2.5])
    np.testing.assert_allclose(np.sort(impedance_loop(K_v, K_p, K_e, B_e).real), np.sort(expected.real), rtol=1e-12)


def test_the_mass_factor_is_the_smallest_that_keeps_the_roots_within_the_tolerance():
    """One row, (-3, -7) designed: B_e = -0.2 alone moves them 4.8 % (factor 1 at 5 %); B_e = -2 by
    41 %, and the factor found keeps them within 5 % while 2 % less does not; the held rows (here a
    second row whose environment no velocity-row mass can reach) keep their unit mass."""
    K_v, K_p = np.array([[10.0]]), np.array([[21.0]])
    alone = np.sort(impedance_loop(K_v, K_p).real)

    def miss(B_e, factor):
        coupled = np.sort(impedance_loop(K_v, K_p, np.zeros((1, 1)), np.array([[B_e]]), np.eye(1) / factor).real)
        return np.max(np.abs(coupled - alone) / np.abs(alone))

    assert mass_factor_within(K_v, K_p, np.zeros((1, 1)), np.array([[-0.2]]), np.eye(1), 0.05, 1) == 1.0
    factor = mass_factor_within(K_v, K_p, np.zeros((1, 1)), np.array([[-2.0]]), np.eye(1), 0.05, 1)
    assert miss(-2.0, factor) <= 0.05 < miss(-2.0, 0.98 * factor)
    held = np.diag([10.0, 45.0]), np.diag([21.0, 450.0])
    assert mass_factor_within(*held, np.zeros((2, 2)), np.diag([0.0, -100.0]), np.eye(2), 0.05, 1) is None


def test_the_mass_the_prediction_names_keeps_the_drums_roots_within_five_percent(cache):
    """The drum's shift names the impedance mass that would keep every designed root within 5 %
    (measured 5.1); linearized with it, the loop is within 5 % of the design (measured 4.94 %; Jaco 2
    4.91 %, xArm7 4.75 %: the mass is the smallest the prediction, within 0.4 % of these, allows)."""
    config = cases.config(cases.task("ur10", "cylinder", cache), "impedance-force")
    reason = linearize_continuous(config).shifts[0].reason
    factor = float(re.search(r"an impedance mass ([0-9.]+) times the current one", reason).group(1))
    assert 2.0 < factor < 20.0
    config.gains.impedance_mass = [factor]
    heavier = linearize_continuous(config)
    assert np.max(heavier.match.relative_error) <= 0.05
    assert np.max(heavier.shifted_match.relative_error) <= 0.01        # the prediction it came from (0.39 %)
    assert not heavier.shifts or "an impedance mass" not in heavier.shifts[0].reason


def test_the_contacts_stiffness_and_damping_predict_the_impedance_roots_on_a_small_drum(cache):
    config = cases.config(cases.task("ur10", "cylinder", cache), "impedance-force")
    result = linearize_continuous(config)
    # The impedance alone misses: the contact moves its pair (21.8 % measured).
    assert np.max(result.match.relative_error) > 0.15
    # Its contact's measured stiffness and damping predict where to.
    assert result.shifts and result.shifted_match is not None
    assert np.max(result.shifted_match.relative_error) < 0.01
    assert "stiffness and damping" in result.shifts[0].reason
    assert predicted_match(result) is result.shifted_match
    # The shifted design keeps every other designed eigenvalue: the shifts take the pair (-3, -7) of x.
    assert sorted(round(shift.designed.real) for shift in result.shifts) == [-7, -3]


def test_a_flat_workpiece_moves_no_designed_eigenvalue(cache):
    config = cases.config(cases.task("ur10", "plane", cache), "impedance-force")
    result = linearize_continuous(config)
    assert result.shifts == [] and result.shifted_match is None
    assert result.match.matched                     # within 0.16 % (docs/own_arms.md)


def test_impedance_response_to_a_force_step_is_the_designed_one():
    """F_v = F from rest, s^2 + 10 s + 21 = (s + 3)(s + 7): e_p'(t) = F (e^-3t - e^-7t) / 4; a second row
    without force stays at rest."""
    t = np.linspace(0.0, 2.0, 2001)
    force = np.column_stack([np.full_like(t, 0.5), np.zeros_like(t)])
    response = impedance_response(np.diag([10.0, 10.0]), np.diag([21.0, 21.0]), t, force, np.zeros(2), np.zeros(2))
    np.testing.assert_allclose(response[:, 0], 0.5 * (np.exp(-3 * t) - np.exp(-7 * t)) / 4, atol=1e-9)
    assert np.all(response[:, 1] == 0.0)
