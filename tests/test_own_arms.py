"""Issue 12's acceptance figures on arms the package does not ship (tests/own_arm_cases.py): nine of
the 27 (arm, shape, mode) cases, a Latin square, so every arm meets every shape and every mode and
every shape every mode. docs/own_arms.py runs all 27 and writes docs/own_arms.md.

Per case: errors after five design time constants <= 2 % (velocity and force, % of the command),
every designed eigenvalue within 5 % of its linearized partner, no real part above 0.01 1/s, and
the Jacobian check in the linearization's output. Nothing is tuned per robot but its frames.

Known failures, kept visible (strict xfail: they fail the run the day they pass). The tessellated
contact has a stiffness along the surface that the design does not have, and SAP's damping a drag
(docs/drake_notes.md):
- impedance-force on the 5 cm cylinder and sphere: the unit-mass impedance yields to both, as
  designed: its roots move (4.4-23 % in the matrix) and its velocity errors are 6.6-27 %;
- position-force on the 5 cm sphere (and the xArm7's cylinder, not in this square): the law splits
  the wrench, which the linearization's 200 Hz low-pass delays, with the current E(x), which has
  already turned (analysis.wrench_lag): the cancellation of F_v leaves -S D sT/(1 + sT) on the
  velocity rows, about a velocity gain K_v + T S D, D ~ -F/rho. The pair (-3, -7) of the UR10
  moves to (-3.23, -6.50); the prediction says (-3.22, -6.52). It is the constraint's curvature,
  not the tessellation (a fourfold finer workpiece or pad mesh does not move it), and it vanishes
  as T goes to 0 (at 1 kHz the pair is 1.3 % off).
"""

import logging

import numpy as np
import pytest

import own_arm_cases as cases
from drake_hybrid.analysis.linearization import linearize_continuous

logging.getLogger("drake").setLevel(logging.ERROR)

KNOWN = {
    ("cylinder", "impedance-force"): "the unit-mass impedance yields to the tessellated contact's stiffness",
    ("sphere", "impedance-force"): "the unit-mass impedance yields to the tessellated contact's stiffness",
    ("sphere", "position-force"): "the (-3, -7) pair 7.6-12 % off: the lagged wrench split with the turned E(x)",
}


def _case(arm, shape, mode):
    reason = KNOWN.get((shape, mode))
    marks = [pytest.mark.xfail(strict=True, reason=reason)] if reason else []
    return pytest.param(arm, shape, mode, marks=marks, id=f"{arm}-{shape}-{mode}")


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("meshes")


@pytest.mark.slow
@pytest.mark.parametrize("arm, shape, mode", [_case(*case) for case in cases.latin_square()])
def test_own_arm_on_own_surface(arm, shape, mode, cache):
    figures = cases.run(arm, shape, mode, cache)
    assert "Jacobian check" in figures["jacobian_check"]
    assert figures["max_real_part"] <= cases.MAX_REAL_PART, figures
    assert figures["velocity_error_percent"] <= cases.MAX_ERROR_PERCENT, figures
    assert figures["force_error_percent"] <= cases.MAX_ERROR_PERCENT, figures
    assert figures["eigenvalue_error"] <= cases.EIGENVALUE_TOLERANCE, figures


def test_the_latin_square_covers_every_pair():
    square = cases.latin_square()
    assert len(square) == 9
    for a, b in ((0, 1), (0, 2), (1, 2)):
        assert len({(case[a], case[b]) for case in square}) == 9


@pytest.mark.slow
def test_the_wrench_lag_predicts_the_moved_pair(cache):
    """UR10, 5 cm sphere, position-force: the design misses by more than 5 %, the wrench-lag
    prediction (analysis.wrench_lag) is met within 1 %."""
    linearization = linearize_continuous(cases.config(cases.task("ur10", "sphere", cache), "position-force"))
    assert np.max(linearization.match.relative_error) > cases.EIGENVALUE_TOLERANCE
    assert linearization.wrench_lag is not None and linearization.wrench_lag.lag > 0
    assert np.max(linearization.wrench_lag_match.relative_error) <= 0.01, linearization.wrench_lag_match.as_dict()
